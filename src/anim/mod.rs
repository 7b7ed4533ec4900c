//! Animation: keyframe sampling and the node hierarchy evaluated at a frame time.
//!
//! Invariant: evaluation is a pure function of (scene, time): frame k never depends on the
//! frames rendered before it, which is what makes `--frames k..k+1` reproduce frame k of a
//! longer run byte for byte. All clips play together and hold their end values outside their
//! key range (glTF leaves looping to the application; mipray clamps).

mod sample;
mod selection;

pub use sample::{sample_channel, sample_rotation, sample_vec3};
pub use selection::{AnimationSelection, select_animation};

use glam::{Mat4, Quat, Vec3};

use crate::scene::{ChannelTarget, SceneDesc, Trs};

/// World transforms of every node at time `time_s` (indexed like `SceneDesc::nodes`).
/// Nodes not reachable from the scene roots keep the identity.
pub fn node_world_transforms(scene: &SceneDesc, time_s: f32) -> Vec<Mat4> {
    let locals = animated_local_transforms(scene, time_s);
    let mut world = vec![Mat4::IDENTITY; scene.nodes.len()];
    let mut stack: Vec<(usize, Mat4)> = scene.roots.iter().map(|&r| (r, Mat4::IDENTITY)).collect();
    while let Some((node, parent_from_world)) = stack.pop() {
        let world_from_node = parent_from_world * locals[node];
        world[node] = world_from_node;
        for &child in &scene.nodes[node].children {
            stack.push((child, world_from_node));
        }
    }
    world
}

/// Each node's local matrix with every animation channel applied at `time_s`.
fn animated_local_transforms(scene: &SceneDesc, time_s: f32) -> Vec<Mat4> {
    let mut trs: Vec<Trs> = scene.nodes.iter().map(|n| n.local).collect();
    let mut animated = vec![false; scene.nodes.len()];
    for animation in &scene.animations {
        for channel in &animation.channels {
            let Some(local) = trs.get_mut(channel.node) else { continue };
            match channel.target {
                ChannelTarget::Translation => local.translation = sample_vec3(channel, time_s),
                ChannelTarget::Rotation => local.rotation = sample_rotation(channel, time_s),
                ChannelTarget::Scale => local.scale = sample_vec3(channel, time_s),
                ChannelTarget::Weights => continue,
            }
            animated[channel.node] = true;
        }
    }
    scene
        .nodes
        .iter()
        .zip(trs.iter().zip(&animated))
        .map(|(node, (local, &is_animated))| match node.matrix {
            // A matrix node is never a channel target (glTF spec); the loader drops such
            // channels, so the exact matrix is kept rather than its decomposition.
            Some(m) if !is_animated => m,
            _ => local.to_mat4(),
        })
        .collect()
}

/// Decomposes a matrix into TRS (used by loaders for matrix nodes).
pub fn decompose(m: Mat4) -> Trs {
    let (scale, rotation, translation) = m.to_scale_rotation_translation();
    let rotation = if rotation.is_finite() { rotation.normalize() } else { Quat::IDENTITY };
    let scale = if scale.is_finite() { scale } else { Vec3::ONE };
    Trs { translation, rotation, scale }
}
