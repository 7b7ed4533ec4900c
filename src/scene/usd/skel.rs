//! UsdSkel onto the renderer's skins and morph targets.
//!
//! - A `Skeleton`'s joints become nodes under the skeleton's node, parented by their paths
//!   (`A`, `A/B`, ...). A joint the bound `SkelAnimation` drives gets its `translations`,
//!   `rotations` and `scales` as channels (USD interpolates each array element linearly,
//!   quaternions by slerp, as the channels do); any other joint keeps its `restTransforms`.
//! - A mesh bound to the skeleton (`skel:skeleton`, inherited) gets a skin over those joint
//!   nodes whose inverse bind matrices are `inverse(bindTransform) * geomBindTransform`,
//!   so the frame loop's `world(joint) * inverse bind * p` is UsdSkel's
//!   `skelToWorld * jointSkel * inverse(bind) * geomBind * p` (the mesh's own transform is
//!   ignored, as for glTF skins and in UsdSkel). `primvars:skel:jointIndices` and
//!   `jointWeights` (any `elementSize`, `vertex` or `constant` interpolation) are folded to the
//!   four largest weights per point, rescaled to the point's total (as for glTF); a mesh's own
//!   `skel:joints` order is mapped to the skeleton's.
//! - Blend shapes (`skel:blendShapes`, `skel:blendShapeTargets`, sparse `pointIndices`
//!   included) become morph targets, animated by the animation's `blendShapeWeights`;
//!   in-between shapes are ignored (noted).
//!
//! Errors name the prim: a joint index past the skeleton's joints, weights or indices of
//! the wrong count, non-finite values, an animation whose arrays do not match its joints.

use std::collections::HashMap;

use glam::{DMat4, Quat, Vec3};
use openusd::sdf::Value;
use openusd::usd::Prim;

use super::Builder;
use super::values::{
    attr_path, dmat4, dmat4s, first_nonfinite, floats, ints, quats, tokens, vec3s,
};
use super::xform::decompose;
use crate::scene::{ChannelDesc, ChannelTarget, Interpolation, MorphTargetDesc, SkinDesc};

/// A skeleton's joints as nodes.
pub(super) struct Skeleton {
    /// Node of each joint, in the skeleton's `joints` order.
    pub joints: Vec<usize>,
    pub names: Vec<String>,
    /// `bindTransforms` (column-vector form).
    pub bind: Vec<DMat4>,
    /// The bound animation's prim, if any.
    pub animation: Option<Prim>,
    pub node: usize,
}

/// A skinned mesh waiting for its skeleton.
pub(super) struct PendingMesh {
    pub prim: Prim,
    pub mesh: usize,
    pub node: usize,
    /// Per primitive: the point of each vertex.
    pub point_of_vertex: Vec<Vec<u32>>,
}

/// The first target of relationship `name` on `prim` or its closest ancestor that has one
/// (UsdSkel bindings are inherited down namespace).
fn inherited_target(
    b: &Builder,
    prim: &Prim,
    name: &str,
) -> Result<Option<openusd::sdf::Path>, String> {
    let mut current = Some(prim.path().clone());
    while let Some(path) = current {
        if path == openusd::sdf::Path::abs_root() {
            break;
        }
        let p = b.reader.stage.prim(path.clone());
        if let Some(target) = b.reader.targets(&p, name)?.into_iter().next() {
            return Ok(Some(target));
        }
        current = path.parent();
    }
    Ok(None)
}

/// Whether the mesh is bound to a skeleton and has joint influences.
pub(super) fn is_bound(b: &mut Builder, prim: &Prim) -> Result<bool, String> {
    let bound = inherited_target(b, prim, "skel:skeleton")?.is_some()
        && b.reader.has_value(prim, "primvars:skel:jointIndices")?;
    if bound && !under_skel_root(b, prim)? {
        // UsdSkel skins only below a SkelRoot; elsewhere the mesh's own points hold (a
        // baked result often keeps the binding it was baked from).
        b.notes.push(format!(
            "{}: bound to a skeleton but not below a SkelRoot, so not skinned (as in UsdSkel): its own points are used",
            prim.path().as_str()
        ));
        return Ok(false);
    }
    Ok(bound)
}

/// Whether `prim` lies below (or is) a `SkelRoot`.
fn under_skel_root(b: &Builder, prim: &Prim) -> Result<bool, String> {
    let mut current = Some(prim.path().clone());
    while let Some(path) = current {
        if path == openusd::sdf::Path::abs_root() {
            break;
        }
        let ancestor = b.reader.stage.prim(path.clone());
        let type_name = ancestor
            .type_name()
            .map_err(|e| format!("{}: {e:#}", path.as_str()))?;
        if type_name.is_some_and(|t| t.as_str() == "SkelRoot") {
            return Ok(true);
        }
        current = path.parent();
    }
    Ok(false)
}

/// Adds the skeleton's joint nodes (and their animation channels) under `node`.
pub(super) fn add_skeleton(b: &mut Builder, prim: &Prim, node: usize) -> Result<(), String> {
    let path = prim.path().as_str().to_string();
    let reader = &b.reader;
    let names = match reader.default_value(prim, "joints")? {
        Some(v) => {
            tokens(&v).ok_or_else(|| format!("{}: expected token[]", attr_path(prim, "joints")))?
        }
        None => Vec::new(),
    };
    let matrices = |name: &str| -> Result<Vec<DMat4>, String> {
        let Some(v) = reader.default_value(prim, name)? else {
            return Ok(vec![DMat4::IDENTITY; names.len()]);
        };
        let m =
            dmat4s(&v).ok_or_else(|| format!("{}: expected matrix4d[]", attr_path(prim, name)))?;
        if m.len() != names.len() {
            return Err(format!(
                "{}: {} matrices for {} joints",
                attr_path(prim, name),
                m.len(),
                names.len()
            ));
        }
        if let Some(i) = m.iter().position(|m| !m.is_finite()) {
            return Err(format!(
                "{}: matrix {i} is not finite",
                attr_path(prim, name)
            ));
        }
        Ok(m)
    };
    let bind = matrices("bindTransforms")?;
    let rest = matrices("restTransforms")?;
    let animation = match inherited_target(b, prim, "skel:animationSource")? {
        Some(target) => {
            let anim = b.reader.stage.prim(target.clone());
            if !anim.is_valid().unwrap_or(false) {
                return Err(format!(
                    "{path}: skel:animationSource targets {}, which does not exist",
                    target.as_str()
                ));
            }
            Some(anim)
        }
        None => None,
    };
    // Joint nodes, parents before children (a parent path is listed before its children in
    // valid files; any other order is an error).
    let mut index_of: HashMap<&str, usize> = HashMap::new();
    let mut joints = Vec::with_capacity(names.len());
    for (j, name) in names.iter().enumerate() {
        let parent = match name.rsplit_once('/') {
            Some((parent, _)) => match index_of.get(parent) {
                Some(&p) => joints[p],
                None => {
                    return Err(format!(
                        "{path}: joint {j} '{name}' is listed before its parent '{parent}' (or the parent is missing)"
                    ));
                }
            },
            None => node,
        };
        if index_of.insert(name.as_str(), j).is_some() {
            return Err(format!("{path}: joint '{name}' is listed twice"));
        }
        let n = b.add_node(Some(parent), format!("{path} joint {name}"));
        let m = rest[j].as_mat4();
        b.nodes[n].local = decompose(&m);
        b.nodes[n].matrix = Some(m);
        joints.push(n);
    }
    if let Some(anim) = &animation {
        animate_joints(b, anim, &names, &joints)?;
    }
    b.skeletons.insert(
        path,
        Skeleton {
            joints,
            names,
            bind,
            animation,
            node,
        },
    );
    Ok(())
}

/// Channels for the joints `anim` drives.
fn animate_joints(
    b: &mut Builder,
    anim: &Prim,
    names: &[String],
    joints: &[usize],
) -> Result<(), String> {
    let reader = &b.reader;
    let anim_joints = match reader.default_value(anim, "joints")? {
        Some(v) => {
            tokens(&v).ok_or_else(|| format!("{}: expected token[]", attr_path(anim, "joints")))?
        }
        None => return Ok(()),
    };
    let index: HashMap<&str, usize> = names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    let mut target = Vec::with_capacity(anim_joints.len());
    for name in &anim_joints {
        // Joints the skeleton does not have are ignored, as UsdSkel does.
        target.push(index.get(name.as_str()).map(|&j| joints[j]));
    }
    let count = anim_joints.len();
    // Per attribute: times and, per key, one value per animation joint.
    let read = |name: &str,
                convert: &dyn Fn(&Value) -> Option<Vec<[f32; 4]>>|
     -> Result<Option<(Vec<f32>, Vec<Vec<[f32; 4]>>)>, String> {
        let samples = reader.samples(anim, name)?;
        let (times, values) = if samples.times.is_empty() {
            match reader.default_value(anim, name)? {
                Some(v) => (Vec::new(), vec![v]),
                None => return Ok(None),
            }
        } else {
            (samples.times, samples.values)
        };
        let mut keys = Vec::with_capacity(values.len());
        for v in &values {
            let k = convert(v)
                .ok_or_else(|| format!("{}: unexpected value type", attr_path(anim, name)))?;
            if k.len() != count {
                return Err(format!(
                    "{}: {} values for the animation's {count} joints",
                    attr_path(anim, name),
                    k.len()
                ));
            }
            if k.iter().any(|x| x.iter().any(|c| !c.is_finite())) {
                return Err(format!("{}: a value is not finite", attr_path(anim, name)));
            }
            keys.push(k);
        }
        Ok(Some((times, keys)))
    };
    let as3 = |v: &Value| vec3s(v).map(|a| a.into_iter().map(|p| [p.x, p.y, p.z, 0.0]).collect());
    let as4 =
        |v: &Value| quats(v).map(|a| a.into_iter().map(|q| q.normalize().to_array()).collect());
    let translations = read("translations", &as3)?;
    let rotations = read("rotations", &as4)?;
    let scales = read("scales", &as3)?;
    let mut channels = Vec::new();
    for (a, node) in target.iter().enumerate() {
        let Some(node) = *node else { continue };
        let rest = b.nodes[node].local;
        let mut local = rest;
        let mut animated = false;
        for (data, target, components) in [
            (&translations, ChannelTarget::Translation, 3),
            (&rotations, ChannelTarget::Rotation, 4),
            (&scales, ChannelTarget::Scale, 3),
        ] {
            let Some((times, keys)) = data else { continue };
            animated = true;
            let first = keys[0][a];
            match target {
                ChannelTarget::Translation => {
                    local.translation = Vec3::new(first[0], first[1], first[2])
                }
                ChannelTarget::Scale => local.scale = Vec3::new(first[0], first[1], first[2]),
                _ => local.rotation = Quat::from_array(first),
            }
            if times.len() > 1 {
                channels.push(ChannelDesc {
                    node,
                    target,
                    interpolation: Interpolation::Linear,
                    times: times.clone(),
                    values: keys
                        .iter()
                        .flat_map(|k| k[a][..components].to_vec())
                        .collect(),
                    components,
                });
            }
        }
        if animated {
            // The animation replaces the rest pose: TRS, no exact rest matrix.
            b.nodes[node].local = local;
            b.nodes[node].matrix = None;
        }
    }
    b.channels.extend(channels);
    Ok(())
}

/// Skins (and blend shapes) of every bound mesh.
pub(super) fn bind_meshes(b: &mut Builder) -> Result<(), String> {
    let pending = std::mem::take(&mut b.skinned);
    for mesh in pending {
        bind_mesh(b, &mesh)?;
    }
    Ok(())
}

fn bind_mesh(b: &mut Builder, pending: &PendingMesh) -> Result<(), String> {
    let prim = &pending.prim;
    let path = prim.path().as_str().to_string();
    let Some(target) = inherited_target(b, prim, "skel:skeleton")? else {
        return Ok(());
    };
    let Some(skeleton) = b.skeletons.get(target.as_str()) else {
        return Err(format!(
            "{path}: skel:skeleton targets {}, which is not a Skeleton of the stage",
            target.as_str()
        ));
    };
    let reader = &b.reader;
    let joint_count = skeleton.joints.len();
    // The mesh's own joint order, mapped to the skeleton's.
    let remap: Option<Vec<usize>> = match reader.default_value(prim, "skel:joints")? {
        Some(v) => {
            let own = tokens(&v)
                .ok_or_else(|| format!("{}: expected token[]", attr_path(prim, "skel:joints")))?;
            Some(
                own.iter()
                    .map(|name| {
                        skeleton
                            .names
                            .iter()
                            .position(|n| n == name)
                            .ok_or_else(|| {
                                format!(
                                    "{}: joint '{name}' is not a joint of {}",
                                    attr_path(prim, "skel:joints"),
                                    target.as_str()
                                )
                            })
                    })
                    .collect::<Result<_, String>>()?,
            )
        }
        None => None,
    };
    let local_count = remap.as_ref().map_or(joint_count, Vec::len);
    let points = influences_per_point(b, prim, local_count, &path)?;
    if reader
        .static_value(prim, "primvars:skel:skinningMethod")?
        .as_ref()
        .and_then(super::values::token)
        .is_some_and(|method| method != "classicLinear")
    {
        b.notes.push(format!(
            "{path}: skinningMethod other than classicLinear (dual quaternion) is skinned with linear blending"
        ));
    }
    let geom_bind = match reader.static_value(prim, "primvars:skel:geomBindTransform")? {
        Some(v) => dmat4(&v).filter(|m| m.is_finite()).ok_or_else(|| {
            format!(
                "{}: expected a finite matrix4d",
                attr_path(prim, "primvars:skel:geomBindTransform")
            )
        })?,
        None => DMat4::IDENTITY,
    };
    let mut inverse_bind = Vec::with_capacity(joint_count);
    for (j, bind) in skeleton.bind.iter().enumerate() {
        let inverse = bind.inverse();
        if bind.determinant() == 0.0 || !inverse.is_finite() {
            return Err(format!(
                "{}: bindTransforms[{j}] is singular",
                target.as_str()
            ));
        }
        inverse_bind.push((inverse * geom_bind).as_mat4());
    }
    let skin = SkinDesc {
        name: target.as_str().to_string(),
        joints: skeleton.joints.clone(),
        inverse_bind_matrices: inverse_bind,
        skeleton: Some(skeleton.node),
    };
    let animation = skeleton.animation.clone();
    b.skins.push(skin);
    let skin_index = b.skins.len() - 1;
    b.nodes[pending.node].skin = Some(skin_index);
    let mesh = &mut b.meshes[pending.mesh];
    for (primitive, vertex_points) in mesh.primitives.iter_mut().zip(&pending.point_of_vertex) {
        let mut joints = Vec::with_capacity(vertex_points.len());
        let mut weights = Vec::with_capacity(vertex_points.len());
        for &p in vertex_points {
            let (j, w) = points[p as usize];
            let j = match &remap {
                Some(map) => j.map(|k| map[k as usize] as u16),
                None => j,
            };
            joints.push(j);
            weights.push(w);
        }
        primitive.joints = Some(joints);
        primitive.weights = Some(weights);
    }
    blend_shapes(b, pending, animation.as_ref())
}

/// Per point: four joint indices (into the mesh's joint order) and weights.
#[allow(clippy::type_complexity)]
fn influences_per_point(
    b: &Builder,
    prim: &Prim,
    joint_count: usize,
    path: &str,
) -> Result<Vec<([u16; 4], [f32; 4])>, String> {
    let reader = &b.reader;
    let indices_name = "primvars:skel:jointIndices";
    let weights_name = "primvars:skel:jointWeights";
    let indices = reader
        .static_value(prim, indices_name)?
        .as_ref()
        .and_then(ints)
        .ok_or_else(|| format!("{}: expected int[]", attr_path(prim, indices_name)))?;
    let weights = reader
        .static_value(prim, weights_name)?
        .as_ref()
        .and_then(floats)
        .ok_or_else(|| format!("{}: expected float[]", attr_path(prim, weights_name)))?;
    let element_size = reader
        .attr_int_metadata(prim, indices_name, "elementSize")
        .unwrap_or(1);
    let weight_size = reader
        .attr_int_metadata(prim, weights_name, "elementSize")
        .unwrap_or(element_size);
    if element_size < 1 || weight_size != element_size {
        return Err(format!(
            "{path}: jointIndices and jointWeights have elementSize {element_size} and {weight_size}"
        ));
    }
    let size = element_size as usize;
    if indices.len() != weights.len() || indices.len() % size != 0 {
        return Err(format!(
            "{path}: {} joint indices and {} joint weights do not pair up in groups of {size}",
            indices.len(),
            weights.len()
        ));
    }
    let point_count = mesh_point_count(b, prim)?;
    let constant = reader
        .attr_token_metadata(prim, indices_name, "interpolation")
        .as_deref()
        == Some("constant");
    let groups = indices.len() / size;
    if (constant && groups != 1) || (!constant && groups != point_count) {
        return Err(format!(
            "{path}: {groups} groups of joint influences for {} points",
            if constant { 1 } else { point_count }
        ));
    }
    let mut out = Vec::with_capacity(point_count);
    for p in 0..point_count {
        let g = if constant { 0 } else { p };
        let mut pairs: Vec<(u16, f32)> = Vec::with_capacity(size);
        for k in g * size..(g + 1) * size {
            let (j, w) = (indices[k], weights[k]);
            if !(w.is_finite()) || w < 0.0 {
                return Err(format!(
                    "{path}: joint weight {k} ({w}) is not a finite non-negative number"
                ));
            }
            if w == 0.0 {
                continue;
            }
            if j < 0 || j as usize >= joint_count {
                return Err(format!(
                    "{path}: joint index {j} at point {p} is outside the skeleton's {joint_count} joints"
                ));
            }
            pairs.push((j as u16, w));
        }
        out.push(fold_influences(pairs));
    }
    Ok(out)
}

/// The four largest weights, rescaled to the total of all (as the glTF loader folds sets).
fn fold_influences(mut pairs: Vec<(u16, f32)>) -> ([u16; 4], [f32; 4]) {
    let total: f32 = pairs.iter().map(|p| p.1).sum();
    pairs.sort_by(|a, b| b.1.total_cmp(&a.1));
    pairs.truncate(4);
    let kept: f32 = pairs.iter().map(|p| p.1).sum();
    let scale = if kept > 0.0 { total / kept } else { 1.0 };
    let (mut joints, mut weights) = ([0u16; 4], [0f32; 4]);
    for (slot, (j, w)) in pairs.into_iter().enumerate() {
        joints[slot] = j;
        weights[slot] = w * scale;
    }
    (joints, weights)
}

fn mesh_point_count(b: &Builder, prim: &Prim) -> Result<usize, String> {
    Ok(b.reader
        .static_value(prim, "points")?
        .as_ref()
        .and_then(vec3s)
        .map_or(0, |p| p.len()))
}

/// Morph targets from the mesh's blend shapes, and the weights channel from the animation.
fn blend_shapes(
    b: &mut Builder,
    pending: &PendingMesh,
    animation: Option<&Prim>,
) -> Result<(), String> {
    let prim = &pending.prim;
    let path = prim.path().as_str().to_string();
    let reader = &b.reader;
    let Some(names) = reader.default_value(prim, "skel:blendShapes")? else {
        return Ok(());
    };
    let names = tokens(&names)
        .ok_or_else(|| format!("{}: expected token[]", attr_path(prim, "skel:blendShapes")))?;
    let targets = reader.targets(prim, "skel:blendShapeTargets")?;
    if targets.len() != names.len() {
        return Err(format!(
            "{path}: {} blend shape names but {} skel:blendShapeTargets",
            names.len(),
            targets.len()
        ));
    }
    let point_count = mesh_point_count(b, prim)?;
    let mut per_point: Vec<(Vec<Vec3>, Option<Vec<Vec3>>)> = Vec::new();
    let mut inbetweens = 0;
    for target in &targets {
        let shape = b.reader.stage.prim(target.clone());
        let what = target.as_str();
        if !shape.is_valid().unwrap_or(false) {
            return Err(format!("{path}: blend shape {what} does not exist"));
        }
        let offsets = match b.reader.static_value(&shape, "offsets")? {
            Some(v) => vec3s(&v).ok_or_else(|| format!("{what}.offsets: expected vector3f[]"))?,
            None => Vec::new(),
        };
        let normal_offsets = b
            .reader
            .static_value(&shape, "normalOffsets")?
            .as_ref()
            .and_then(vec3s);
        if first_nonfinite(&offsets).is_some()
            || normal_offsets
                .as_deref()
                .is_some_and(|n| first_nonfinite(n).is_some())
        {
            return Err(format!("{what}: an offset is not finite"));
        }
        let indices = b
            .reader
            .static_value(&shape, "pointIndices")?
            .as_ref()
            .and_then(ints);
        let scatter = |values: &[Vec3]| -> Result<Vec<Vec3>, String> {
            let mut out = vec![Vec3::ZERO; point_count];
            match &indices {
                Some(indices) => {
                    if indices.len() != values.len() {
                        return Err(format!(
                            "{what}: {} pointIndices for {} offsets",
                            indices.len(),
                            values.len()
                        ));
                    }
                    for (k, (&i, &v)) in indices.iter().zip(values).enumerate() {
                        let slot = usize::try_from(i).ok().and_then(|i| out.get_mut(i)).ok_or_else(|| {
                            format!("{what}: pointIndices[{k}] = {i} is outside the mesh's {point_count} points")
                        })?;
                        *slot = v;
                    }
                }
                None => {
                    if values.len() != point_count {
                        return Err(format!(
                            "{what}: {} offsets for {point_count} points",
                            values.len()
                        ));
                    }
                    out.copy_from_slice(values);
                }
            }
            Ok(out)
        };
        let positions = scatter(&offsets)?;
        let normals = normal_offsets.as_deref().map(scatter).transpose()?;
        if shape
            .property_names()
            .map(|n| n.iter().any(|n| n.as_str().starts_with("inbetweens:")))
            .unwrap_or(false)
        {
            inbetweens += 1;
        }
        per_point.push((positions, normals));
    }
    if inbetweens > 0 {
        b.notes.push(format!(
            "{path}: {inbetweens} blend shape(s) have in-between shapes, which are ignored"
        ));
    }
    let mesh = &mut b.meshes[pending.mesh];
    for (primitive, vertex_points) in mesh.primitives.iter_mut().zip(&pending.point_of_vertex) {
        primitive.morph_targets = per_point
            .iter()
            .map(|(positions, normals)| MorphTargetDesc {
                positions: Some(
                    vertex_points
                        .iter()
                        .map(|&p| positions[p as usize])
                        .collect(),
                ),
                normals: match (normals, &primitive.normals) {
                    (Some(n), Some(_)) => {
                        Some(vertex_points.iter().map(|&p| n[p as usize]).collect())
                    }
                    _ => None,
                },
            })
            .collect();
    }
    mesh.weights = vec![0.0; names.len()];
    let Some(anim) = animation else {
        return Ok(());
    };
    let reader = &b.reader;
    let Some(anim_names) = reader
        .default_value(anim, "blendShapes")?
        .as_ref()
        .and_then(tokens)
    else {
        return Ok(());
    };
    let slot: Vec<Option<usize>> = names
        .iter()
        .map(|n| anim_names.iter().position(|a| a == n))
        .collect();
    let samples = reader.samples(anim, "blendShapeWeights")?;
    let (times, values) = if samples.times.is_empty() {
        match reader.default_value(anim, "blendShapeWeights")? {
            Some(v) => (vec![0.0], vec![v]),
            None => return Ok(()),
        }
    } else {
        (samples.times, samples.values)
    };
    let mut flat = Vec::with_capacity(times.len() * names.len());
    for v in &values {
        let w = floats(v)
            .ok_or_else(|| format!("{}: expected float[]", attr_path(anim, "blendShapeWeights")))?;
        if w.len() != anim_names.len() || w.iter().any(|x| !x.is_finite()) {
            return Err(format!(
                "{}: {} finite weights expected, one per blend shape",
                attr_path(anim, "blendShapeWeights"),
                anim_names.len()
            ));
        }
        flat.extend(slot.iter().map(|s| s.map_or(0.0, |i| w[i])));
    }
    if times.len() == 1 {
        b.meshes[pending.mesh].weights = flat;
        return Ok(());
    }
    b.channels.push(ChannelDesc {
        node: pending.node,
        target: ChannelTarget::Weights,
        interpolation: Interpolation::Linear,
        times,
        values: flat,
        components: names.len(),
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn influences_keep_the_four_largest_rescaled_to_the_total() {
        let (j, w) = fold_influences(vec![(0, 0.1), (1, 0.3), (2, 0.2), (3, 0.25), (4, 0.15)]);
        assert_eq!(j, [1, 3, 2, 4]);
        let sum: f32 = w.iter().sum();
        assert!((sum - 1.0).abs() < 1e-6);
        assert!((w[0] / w[1] - 0.3 / 0.25).abs() < 1e-6);
        assert_eq!(fold_influences(vec![]), ([0; 4], [0.0; 4]));
    }
}
