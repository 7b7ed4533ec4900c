//! Skins: joints and inverse bind matrices, each primitive's joint influences
//! (`JOINTS_n`/`WEIGHTS_n`), and the check that a skinned node's mesh only names joints
//! its skin has.
//!
//! Invariants on success: every skin has one finite inverse bind matrix per joint
//! (identity when the file gives none); a primitive's `joints` and `weights` are both set or
//! both not, one entry per vertex, with finite non-negative weights; and every primitive of a
//! mesh drawn by a node with a skin has all its joint indices below that skin's joint count.
//! Nothing is applied here: `anim::deform_primitive` blends the joint matrices per frame.

use glam::Mat4;
use gltf::accessor::{DataType, Dimensions};

use super::accessor::{Integers, read_floats, read_joint_indices};
use super::buffers::Buffers;
use super::mesh::{check_count, is_loaded};
use crate::scene::{MeshDesc, NodeDesc, SkinDesc};

/// Loads every skin.
pub(super) fn load_skins(
    document: &gltf::Document,
    buffers: &Buffers,
) -> Result<Vec<SkinDesc>, String> {
    document
        .skins()
        .map(|skin| load_skin(&skin, buffers))
        .collect()
}

fn load_skin(skin: &gltf::Skin, buffers: &Buffers) -> Result<SkinDesc, String> {
    let joints: Vec<usize> = skin.joints().map(|joint| joint.index()).collect();
    let inverse_bind_matrices = match skin.inverse_bind_matrices() {
        None => vec![Mat4::IDENTITY; joints.len()],
        Some(accessor) => read_inverse_bind_matrices(&accessor, buffers, skin, joints.len())?,
    };
    Ok(SkinDesc {
        name: skin.name().unwrap_or_default().to_string(),
        joints,
        inverse_bind_matrices,
        skeleton: skin.skeleton().map(|node| node.index()),
    })
}

/// One finite MAT4 per joint (glTF allows a longer accessor; the extra ones are unused).
fn read_inverse_bind_matrices(
    accessor: &gltf::Accessor,
    buffers: &Buffers,
    skin: &gltf::Skin,
    joint_count: usize,
) -> Result<Vec<Mat4>, String> {
    let what = format!("inverseBindMatrices of skin {}", skin.index());
    let flat = read_floats(
        accessor,
        buffers,
        &what,
        Dimensions::Mat4,
        Integers::Rejected,
    )?;
    let matrices: Vec<Mat4> = flat.chunks_exact(16).map(Mat4::from_cols_slice).collect();
    if matrices.len() < joint_count {
        return Err(format!(
            "accessor {} ({what}) has {} matrices but the skin has {joint_count} joints",
            accessor.index(),
            matrices.len()
        ));
    }
    if let Some(i) = matrices.iter().position(|m| !m.is_finite()) {
        return Err(format!(
            "accessor {} ({what}) has a non-finite matrix at element {i}",
            accessor.index()
        ));
    }
    Ok(matrices[..joint_count].to_vec())
}

/// One `JOINTS_n`/`WEIGHTS_n` pair: per vertex, four joint indices and their weights.
type InfluenceSet = (Vec<[u16; 4]>, Vec<[f32; 4]>);

/// A primitive's joint influences, folded into four per vertex.
pub(super) struct Influences {
    pub joints: Vec<[u16; 4]>,
    pub weights: Vec<[f32; 4]>,
    /// How many `JOINTS_n`/`WEIGHTS_n` sets the file had (more than 1 means folded).
    pub sets: usize,
}

/// Reads every `JOINTS_n`/`WEIGHTS_n` pair (`None` when the primitive has none).
pub(super) fn read_influences(
    primitive: &gltf::Primitive,
    buffers: &Buffers,
    what: &str,
    vertex_count: usize,
) -> Result<Option<Influences>, String> {
    let mut sets = Vec::new();
    for set in 0.. {
        let joints = primitive.get(&gltf::Semantic::Joints(set));
        let weights = primitive.get(&gltf::Semantic::Weights(set));
        let (joints, weights) = match (joints, weights) {
            (None, None) => break,
            (Some(joints), Some(weights)) => (joints, weights),
            (Some(_), None) => return Err(format!("{what} has JOINTS_{set} but no WEIGHTS_{set}")),
            (None, Some(_)) => return Err(format!("{what} has WEIGHTS_{set} but no JOINTS_{set}")),
        };
        let joints_label = format!("JOINTS_{set} of {what}");
        let joint_indices = read_joint_indices(&joints, buffers, &joints_label)?;
        check_count(joint_indices.len(), vertex_count, &joints, &joints_label)?;
        let weight_values = read_weights(&weights, buffers, &format!("WEIGHTS_{set} of {what}"))?;
        check_count(
            weight_values.len(),
            vertex_count,
            &weights,
            &format!("WEIGHTS_{set} of {what}"),
        )?;
        sets.push((joint_indices, weight_values));
    }
    if sets.is_empty() {
        return Ok(None);
    }
    let set_count = sets.len();
    let (joints, weights) = if set_count == 1 {
        sets.pop().unwrap_or_default()
    } else {
        fold_influences(&sets, vertex_count)
    };
    Ok(Some(Influences {
        joints,
        weights,
        sets: set_count,
    }))
}

/// A `WEIGHTS_n` accessor: float, or normalized unsigned byte/short converted to [0, 1];
/// every weight finite and non-negative.
fn read_weights(
    accessor: &gltf::Accessor,
    buffers: &Buffers,
    label: &str,
) -> Result<Vec<[f32; 4]>, String> {
    if !matches!(
        accessor.data_type(),
        DataType::F32 | DataType::U8 | DataType::U16
    ) {
        return Err(format!(
            "accessor {} ({label}) has component type {:?}; weights must be float or normalized unsigned byte or short",
            accessor.index(),
            accessor.data_type()
        ));
    }
    let flat = read_floats(
        accessor,
        buffers,
        label,
        Dimensions::Vec4,
        Integers::Normalized,
    )?;
    if let Some(i) = flat.iter().position(|w| !(w.is_finite() && *w >= 0.0)) {
        return Err(format!(
            "accessor {} ({label}) has weight {} at element {}; weights must be finite and non-negative",
            accessor.index(),
            flat[i],
            i / 4
        ));
    }
    Ok(flat
        .chunks_exact(4)
        .map(|w| [w[0], w[1], w[2], w[3]])
        .collect())
}

/// Keeps each vertex's 4 largest influences over all sets (ties: the earlier set and slot
/// first) and, when a non-zero weight was dropped, rescales the kept ones to the vertex's
/// total weight over all sets (1 in a valid file).
fn fold_influences(sets: &[InfluenceSet], vertex_count: usize) -> InfluenceSet {
    let mut joints = Vec::with_capacity(vertex_count);
    let mut weights = Vec::with_capacity(vertex_count);
    let mut all: Vec<(u16, f32)> = Vec::with_capacity(4 * sets.len());
    for v in 0..vertex_count {
        all.clear();
        for (set_joints, set_weights) in sets {
            all.extend(set_joints[v].iter().copied().zip(set_weights[v]));
        }
        let total: f32 = all.iter().map(|(_, w)| w).sum();
        // Stable sort: equal weights keep file order.
        all.sort_by(|a, b| b.1.total_cmp(&a.1));
        let kept: f32 = all[..4].iter().map(|(_, w)| w).sum();
        let scale = if all[4..].iter().any(|(_, w)| *w > 0.0) && kept > 0.0 {
            total / kept
        } else {
            1.0
        };
        joints.push([0, 1, 2, 3].map(|k| all[k].0));
        weights.push([0, 1, 2, 3].map(|k| all[k].1 * scale));
    }
    (joints, weights)
}

/// Checks every node that draws a skinned mesh: a node with a skin must only see joint
/// indices below the skin's joint count (an error naming node and mesh otherwise). A mesh
/// with joints drawn without a skin, or a skin on a mesh without joints, is drawn rigidly
/// with a note.
pub(super) fn check_skinned_nodes(
    document: &gltf::Document,
    nodes: &[NodeDesc],
    meshes: &[MeshDesc],
    skins: &[SkinDesc],
    notes: &mut Vec<String>,
) -> Result<(), String> {
    let (mut unskinned, mut jointless) = (0, 0);
    // Meshes some node draws with its skin (each counted once below).
    let mut skinned_meshes = std::collections::BTreeSet::new();
    for (n, node) in nodes.iter().enumerate() {
        let Some(m) = node.mesh else { continue };
        let mesh = &meshes[m];
        let has_joints = mesh.primitives.iter().any(|p| p.joints.is_some());
        let Some(s) = node.skin else {
            unskinned += usize::from(has_joints);
            continue;
        };
        if !has_joints {
            jointless += 1;
            continue;
        }
        skinned_meshes.insert(m);
        let joint_count = skins[s].joints.len();
        let sources = document
            .meshes()
            .nth(m)
            .map(|mesh| {
                mesh.primitives()
                    .filter(|p| is_loaded(p.mode()))
                    .map(|p| p.index())
                    .collect::<Vec<_>>()
            })
            .unwrap_or_default();
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let Some(joints) = &primitive.joints else {
                continue;
            };
            let bad = joints.iter().enumerate().find_map(|(v, j)| {
                j.iter()
                    .find(|&&j| usize::from(j) >= joint_count)
                    .map(|&j| (v, j))
            });
            if let Some((vertex, joint)) = bad {
                return Err(format!(
                    "node {n} ({:?}) draws mesh {m} ({:?}) with skin {s}, which has {joint_count} joints, but primitive {} has joint index {joint} at vertex {vertex}",
                    node.name,
                    mesh.name,
                    sources.get(p).copied().unwrap_or(p)
                ));
            }
        }
    }
    if unskinned > 0 {
        notes.push(format!(
            "{unskinned} node(s) draw a mesh with JOINTS/WEIGHTS but have no skin; drawn without skinning"
        ));
    }
    if jointless > 0 {
        notes.push(format!(
            "{jointless} node(s) have a skin but draw a mesh without JOINTS/WEIGHTS; drawn without skinning"
        ));
    }
    // glTF requires each vertex's weights to sum to 1; one whose weights are all zero
    // (non-negative, so a zero sum means every one is zero) cannot be skinned and follows
    // its node (`anim::deform`'s fallback).
    let unweighted: usize = skinned_meshes
        .iter()
        .flat_map(|&m| &meshes[m].primitives)
        .filter_map(|p| p.weights.as_ref())
        .map(|weights| {
            weights
                .iter()
                .filter(|w| w.iter().all(|&w| w == 0.0))
                .count()
        })
        .sum();
    if unweighted > 0 {
        notes.push(format!(
            "{unweighted} skinned vertex(es) have joint weights summing to zero; they follow their node unskinned"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folding_keeps_the_four_largest_and_rescales_to_the_total() {
        let sets = vec![
            (vec![[0, 1, 2, 3]], vec![[0.4, 0.1, 0.05, 0.05]]),
            (vec![[4, 5, 6, 7]], vec![[0.3, 0.1, 0.0, 0.0]]),
        ];
        let (joints, weights) = fold_influences(&sets, 1);
        // Largest: 0.4 (j0), 0.3 (j4), 0.1 (j1, set 0 first), 0.1 (j5); dropped 0.05 + 0.05.
        assert_eq!(joints[0], [0, 4, 1, 5]);
        let kept = 0.4f32 + 0.3 + 0.1 + 0.1;
        let expected = [0.4, 0.3, 0.1, 0.1].map(|w: f32| w * (1.0 / kept));
        for (w, e) in weights[0].iter().zip(expected) {
            assert!((w - e).abs() < 1e-6, "{:?} vs {expected:?}", weights[0]);
        }
        // Nothing non-zero dropped: weights are kept exactly.
        let sets = vec![
            (vec![[0, 1, 0, 0]], vec![[0.5, 0.25, 0.0, 0.0]]),
            (vec![[2, 0, 0, 0]], vec![[0.25, 0.0, 0.0, 0.0]]),
        ];
        let (joints, weights) = fold_influences(&sets, 1);
        assert_eq!(joints[0][..3], [0, 1, 2]);
        assert_eq!(weights[0], [0.5, 0.25, 0.25, 0.0]);
    }
}
