//! Morph targets: each primitive's POSITION/NORMAL deltas, the mesh's default weights and
//! a node's weights override.
//!
//! Invariants on success: every primitive of a mesh has the same number of targets (glTF
//! requires it; animation channels and weights are sized by it), `MeshDesc::weights` and a
//! node's `weights` have exactly that length, and every delta and weight is finite with one
//! delta per vertex. TANGENT deltas are not loaded (the renderer uses no tangents). Nothing
//! is applied here: the base geometry stays un-morphed and `anim::deform_primitive` adds the
//! deltas for each frame's weights.

use super::buffers::Buffers;
use super::mesh::read_attribute_vec3s;
use crate::scene::MorphTargetDesc;

/// The mesh's morph target count; an error if its primitives disagree.
pub(super) fn target_count(mesh: &gltf::Mesh) -> Result<usize, String> {
    let mut primitives = mesh.primitives();
    let Some(first) = primitives.next() else {
        return Ok(0);
    };
    let count = first.morph_targets().len();
    for primitive in primitives {
        let other = primitive.morph_targets().len();
        if other != count {
            return Err(format!(
                "mesh {} primitive {} has {other} morph targets but primitive 0 has {count}; glTF requires the same number",
                mesh.index(),
                primitive.index()
            ));
        }
    }
    Ok(count)
}

/// The mesh's default weights: its `weights` (one per target, finite) or zeros.
pub(super) fn default_weights(mesh: &gltf::Mesh) -> Result<Vec<f32>, String> {
    let count = target_count(mesh)?;
    match mesh.weights() {
        None => Ok(vec![0.0; count]),
        Some(weights) => {
            check_weights(weights, count, &format!("mesh {}", mesh.index()))?;
            Ok(weights.to_vec())
        }
    }
}

/// A node's `weights` override for its mesh's targets (`None` when it has none; ignored
/// on a node without a mesh, which glTF does not allow).
pub(super) fn node_weights(node: &gltf::Node) -> Result<Option<Vec<f32>>, String> {
    let (Some(weights), Some(mesh)) = (node.weights(), node.mesh()) else {
        return Ok(None);
    };
    let count = target_count(&mesh)?;
    check_weights(
        weights,
        count,
        &format!("node {} (mesh {})", node.index(), mesh.index()),
    )?;
    Ok(Some(weights.to_vec()))
}

fn check_weights(weights: &[f32], count: usize, what: &str) -> Result<(), String> {
    if weights.len() != count {
        return Err(format!(
            "{what} has {} morph weights but {count} morph targets",
            weights.len()
        ));
    }
    match weights.iter().position(|w| !w.is_finite()) {
        Some(i) => Err(format!("{what}: morph weight {i} is not finite")),
        None => Ok(()),
    }
}

/// The primitive's targets in file order; NORMAL deltas only when the primitive keeps its
/// normals (`has_normals`), since there is nothing to displace otherwise.
pub(super) fn read_targets(
    primitive: &gltf::Primitive,
    buffers: &Buffers,
    what: &str,
    vertex_count: usize,
    has_normals: bool,
) -> Result<Vec<MorphTargetDesc>, String> {
    primitive
        .morph_targets()
        .enumerate()
        .map(|(index, target)| {
            let what = format!("{what} morph target {index}");
            let read = |accessor: Option<gltf::Accessor>, semantic| {
                accessor
                    .map(|a| read_attribute_vec3s(&a, buffers, semantic, &what, vertex_count))
                    .transpose()
            };
            Ok(MorphTargetDesc {
                positions: read(target.positions(), "POSITION")?,
                normals: if has_normals {
                    read(target.normals(), "NORMAL")?
                } else {
                    None
                },
            })
        })
        .collect()
}
