//! Nodes, the scene hierarchy and what nodes carry besides meshes: cameras and lights.
//!
//! Invariant on success: the children lists form a forest (every node has at most one
//! parent and no node is its own ancestor), and the roots are parentless and distinct,
//! so `SceneDesc::visit_nodes` visits each reachable node exactly once.

use glam::{Mat4, Quat, Vec3};

use super::morph;
use crate::scene::{CameraDesc, LightDesc, LightKind, NodeDesc, Trs};

/// Loads every node; `camera_of` maps glTF camera indices to `SceneDesc::cameras`
/// (unsupported cameras map to `None`).
pub(super) fn load_nodes(
    document: &gltf::Document,
    camera_of: &[Option<usize>],
) -> Result<Vec<NodeDesc>, String> {
    let nodes = document
        .nodes()
        .map(|node| {
            let (local, matrix) = node_transform(&node)?;
            Ok(NodeDesc {
                name: node.name().unwrap_or_default().to_string(),
                local,
                matrix,
                children: node.children().map(|child| child.index()).collect(),
                mesh: node.mesh().map(|mesh| mesh.index()),
                camera: node
                    .camera()
                    .and_then(|camera| camera_of.get(camera.index()).copied().flatten()),
                light: node.light().map(|light| light.index()),
                skin: node.skin().map(|skin| skin.index()),
                weights: morph::node_weights(&node)?,
            })
        })
        .collect::<Result<Vec<_>, String>>()?;
    check_forest(&nodes)?;
    Ok(nodes)
}

/// The node's rest transform: TRS as given (rotation normalized), or a matrix kept exactly
/// together with its decomposition.
fn node_transform(node: &gltf::Node) -> Result<(Trs, Option<Mat4>), String> {
    let what = format!("node {}", node.index());
    match node.transform() {
        gltf::scene::Transform::Matrix { matrix } => {
            let matrix = Mat4::from_cols_array_2d(&matrix);
            if !matrix.is_finite() {
                return Err(format!("{what} has a non-finite matrix"));
            }
            Ok((decompose(&matrix), Some(matrix)))
        }
        gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            let translation = Vec3::from(translation);
            let scale = Vec3::from(scale);
            if !translation.is_finite() || !scale.is_finite() {
                return Err(format!("{what} has a non-finite translation or scale"));
            }
            let rotation = Quat::from_array(rotation);
            let length = rotation.length();
            if !length.is_finite() || length < 1e-6 {
                return Err(format!(
                    "{what} has an invalid rotation quaternion {rotation:?}"
                ));
            }
            Ok((
                Trs {
                    translation,
                    rotation: rotation / length,
                    scale,
                },
                None,
            ))
        }
    }
}

/// TRS of a matrix; a singular matrix (zero scale) has no rotation, so it keeps identity.
fn decompose(matrix: &Mat4) -> Trs {
    let (scale, rotation, translation) = matrix.to_scale_rotation_translation();
    let rotation = if rotation.is_finite() && rotation.length() > 0.5 {
        rotation.normalize()
    } else {
        Quat::IDENTITY
    };
    let scale = if scale.is_finite() { scale } else { Vec3::ZERO };
    Trs {
        translation,
        rotation,
        scale,
    }
}

/// Checks that children lists form a forest: no node with two parents, no cycle.
fn check_forest(nodes: &[NodeDesc]) -> Result<(), String> {
    let parents = parent_of(nodes)?;
    // With at most one parent per node, a cycle is exactly a set of nodes that no
    // parentless node reaches.
    let mut reached = vec![false; nodes.len()];
    let mut stack: Vec<usize> = (0..nodes.len()).filter(|&i| parents[i].is_none()).collect();
    while let Some(i) = stack.pop() {
        reached[i] = true;
        stack.extend(&nodes[i].children);
    }
    match reached.iter().position(|&r| !r) {
        Some(i) => Err(format!("node {i} is part of a cycle of children")),
        None => Ok(()),
    }
}

/// Each node's parent; an error if a node is listed as a child twice.
fn parent_of(nodes: &[NodeDesc]) -> Result<Vec<Option<usize>>, String> {
    let mut parents: Vec<Option<usize>> = vec![None; nodes.len()];
    for (parent, node) in nodes.iter().enumerate() {
        for &child in &node.children {
            let slot = parents
                .get_mut(child)
                .ok_or_else(|| format!("node {parent} has unknown child {child}"))?;
            if let Some(first) = *slot {
                return Err(format!(
                    "node {child} has two parents (nodes {first} and {parent})"
                ));
            }
            *slot = Some(parent);
        }
    }
    Ok(parents)
}

/// Root nodes of the rendered scene: the default scene, else scene 0, else (a file with
/// no scenes) every parentless node.
pub(super) fn scene_roots(
    document: &gltf::Document,
    nodes: &[NodeDesc],
) -> Result<Vec<usize>, String> {
    let parents = parent_of(nodes)?;
    let Some(scene) = document
        .default_scene()
        .or_else(|| document.scenes().next())
    else {
        return Ok((0..nodes.len()).filter(|&i| parents[i].is_none()).collect());
    };
    let mut roots = Vec::new();
    for node in scene.nodes() {
        let i = node.index();
        if let Some(parent) = parents[i] {
            return Err(format!(
                "scene {} lists node {i}, which is a child of node {parent}",
                scene.index()
            ));
        }
        if roots.contains(&i) {
            return Err(format!("scene {} lists node {i} twice", scene.index()));
        }
        roots.push(i);
    }
    Ok(roots)
}

/// Perspective cameras, and for each glTF camera its index among them (orthographic
/// cameras are skipped with a note).
pub(super) fn load_cameras(
    document: &gltf::Document,
    notes: &mut Vec<String>,
) -> Result<(Vec<CameraDesc>, Vec<Option<usize>>), String> {
    let mut cameras = Vec::new();
    let mut camera_of = Vec::new();
    for camera in document.cameras() {
        match camera.projection() {
            gltf::camera::Projection::Perspective(p) => {
                let (yfov, znear) = (p.yfov(), p.znear());
                if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(format!(
                        "camera {} has yfov {yfov}, outside (0, pi)",
                        camera.index()
                    ));
                }
                if !(znear > 0.0 && znear.is_finite()) {
                    return Err(format!(
                        "camera {} has znear {znear}, which must be positive",
                        camera.index()
                    ));
                }
                cameras.push(CameraDesc { yfov, znear });
                camera_of.push(Some(cameras.len() - 1));
            }
            gltf::camera::Projection::Orthographic(_) => {
                notes.push(format!(
                    "camera {} is orthographic, which is not supported; skipped",
                    camera.index()
                ));
                camera_of.push(None);
            }
        }
    }
    Ok((cameras, camera_of))
}

/// `KHR_lights_punctual` lights, by light index.
pub(super) fn load_lights(document: &gltf::Document) -> Result<Vec<LightDesc>, String> {
    let Some(lights) = document.lights() else {
        return Ok(Vec::new());
    };
    lights.map(|light| light_desc(&light)).collect()
}

fn light_desc(light: &gltf::khr_lights_punctual::Light) -> Result<LightDesc, String> {
    let what = format!("light {}", light.index());
    let color = Vec3::from(light.color());
    let intensity = light.intensity();
    if !color.is_finite() || !intensity.is_finite() || intensity < 0.0 || color.min_element() < 0.0
    {
        return Err(format!(
            "{what} has an invalid colour {color} or intensity {intensity}"
        ));
    }
    let range = light.range();
    if let Some(r) = range.filter(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(format!("{what} has range {r}, which must be positive"));
    }
    let kind = match light.kind() {
        gltf::khr_lights_punctual::Kind::Point => LightKind::Point,
        gltf::khr_lights_punctual::Kind::Directional => LightKind::Directional,
        gltf::khr_lights_punctual::Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            if !inner_cone_angle.is_finite() || !outer_cone_angle.is_finite() {
                return Err(format!("{what} has non-finite cone angles"));
            }
            // Spec: 0 <= inner < outer <= pi/2; clamp mildly invalid files into that.
            let outer_cone = outer_cone_angle.clamp(0.0, std::f32::consts::FRAC_PI_2);
            LightKind::Spot {
                inner_cone: inner_cone_angle.clamp(0.0, outer_cone),
                outer_cone,
            }
        }
    };
    Ok(LightDesc {
        kind,
        color,
        intensity,
        range,
        inverse_square: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node_with_children(children: &[usize]) -> NodeDesc {
        NodeDesc {
            children: children.to_vec(),
            ..Default::default()
        }
    }

    #[test]
    fn forests_pass_and_cycles_or_shared_children_fail() {
        let forest = [
            node_with_children(&[1, 2]),
            node_with_children(&[]),
            node_with_children(&[]),
        ];
        assert!(check_forest(&forest).is_ok());
        let cycle = [
            node_with_children(&[]),
            node_with_children(&[2]),
            node_with_children(&[1]),
        ];
        assert!(check_forest(&cycle).unwrap_err().contains("cycle"));
        let shared = [
            node_with_children(&[2]),
            node_with_children(&[2]),
            node_with_children(&[]),
        ];
        assert!(check_forest(&shared).unwrap_err().contains("two parents"));
        let own = [node_with_children(&[0])];
        assert!(check_forest(&own).is_err());
    }

    #[test]
    fn singular_matrix_decomposes_without_nan() {
        let trs = decompose(&Mat4::from_scale(Vec3::new(0.0, 1.0, 1.0)));
        assert!(trs.rotation.is_finite() && trs.scale.is_finite() && trs.translation.is_finite());
    }
}
