//! Uniform scale of each node's world transform, tracked exactly through the hierarchy.
//!
//! A triangle placed by a similarity transform keeps its shape, so its `log2 P_b` is the
//! object-space constant plus `log2 s`. Measuring `s` from the composed f32 matrix would
//! jitter in the last bits as the node rotates; instead `s` is the product, in f64, of the
//! exact local scale factors along the node's chain, which a pure rotation never touches.

use glam::{Mat3, Vec3};

use super::{AnimationSelection, sample_vec3};
use crate::scene::{ChannelTarget, SceneDesc};

/// Per node: `Some(s)` when its world transform is a similarity with uniform scale `s`
/// (every node on its chain scales uniformly), `None` otherwise. Nodes not reachable from the
/// roots get `None`.
pub fn node_uniform_scales(
    scene: &SceneDesc,
    selection: AnimationSelection,
    time_s: f32,
) -> Vec<Option<f64>> {
    let local = local_uniform_scales(scene, selection, time_s);
    let mut world = vec![None; scene.nodes.len()];
    let mut stack: Vec<(usize, Option<f64>)> =
        scene.roots.iter().map(|&r| (r, Some(1.0))).collect();
    while let Some((node, parent)) = stack.pop() {
        let s = parent.zip(local[node]).map(|(a, b)| a * b);
        world[node] = s;
        for &child in &scene.nodes[node].children {
            stack.push((child, s));
        }
    }
    world
}

/// Each node's own uniform scale factor at `time_s`, `None` when it scales non-uniformly.
fn local_uniform_scales(
    scene: &SceneDesc,
    selection: AnimationSelection,
    time_s: f32,
) -> Vec<Option<f64>> {
    let mut scales: Vec<Vec3> = scene.nodes.iter().map(|n| n.local.scale).collect();
    for animation in selection.clips(scene) {
        for channel in animation
            .channels
            .iter()
            .filter(|c| c.target == ChannelTarget::Scale)
        {
            if let Some(s) = scales.get_mut(channel.node) {
                *s = sample_vec3(channel, time_s);
            }
        }
    }
    scene
        .nodes
        .iter()
        .zip(scales)
        .map(|(node, scale)| match node.matrix {
            Some(m) => matrix_uniform_scale(Mat3::from_mat4(m)),
            None => uniform(scale),
        })
        .collect()
}

/// `|s|` when all three factors have the same magnitude (a negative factor is a reflection,
/// which keeps areas), and `s` is finite and non-zero.
fn uniform(scale: Vec3) -> Option<f64> {
    let a = scale.abs();
    (a.x == a.y && a.y == a.z && a.x.is_finite() && a.x > 0.0).then_some(a.x as f64)
}

/// The uniform scale of a (static) matrix node's linear part, if it is a similarity.
fn matrix_uniform_scale(l: Mat3) -> Option<f64> {
    let l = l.as_dmat3();
    let g = l.transpose() * l;
    let s2 = (g.x_axis.x + g.y_axis.y + g.z_axis.z) / 3.0;
    if !(s2.is_finite() && s2 > 0.0) {
        return None;
    }
    let err = (g - glam::DMat3::from_diagonal(glam::DVec3::splat(s2)))
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    (err <= 1e-5 * s2).then(|| s2.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{NodeDesc, Trs};
    use glam::{Mat4, Quat};

    fn node(scale: Vec3, children: Vec<usize>) -> NodeDesc {
        NodeDesc {
            local: Trs {
                scale,
                rotation: Quat::from_rotation_z(0.7),
                ..Default::default()
            },
            children,
            ..Default::default()
        }
    }

    #[test]
    fn chain_multiplies_uniform_factors_and_stops_at_non_uniform() {
        let scene = SceneDesc {
            nodes: vec![
                node(Vec3::splat(2.0), vec![1, 2]),
                node(Vec3::splat(-1.5), vec![]),
                node(Vec3::new(1.0, 2.0, 1.0), vec![3]),
                node(Vec3::ONE, vec![]),
            ],
            roots: vec![0],
            ..Default::default()
        };
        let s = node_uniform_scales(&scene, AnimationSelection::All, 0.0);
        assert_eq!(s, vec![Some(2.0), Some(3.0), None, None]);
    }

    #[test]
    fn matrix_nodes_use_their_similarity_scale() {
        let m = Mat4::from_scale_rotation_translation(
            Vec3::splat(4.0),
            Quat::from_rotation_x(1.0),
            Vec3::ONE,
        );
        let scene = SceneDesc {
            nodes: vec![NodeDesc {
                matrix: Some(m),
                ..Default::default()
            }],
            roots: vec![0],
            ..Default::default()
        };
        assert!(
            (node_uniform_scales(&scene, AnimationSelection::All, 0.0)[0].unwrap() - 4.0).abs()
                < 1e-6
        );
    }
}
