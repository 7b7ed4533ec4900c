//! Animation: keyframe sampling, the posed node hierarchy, and vertex deformation (morph
//! targets and skins) at a frame time.
//!
//! Invariant: evaluation is a pure function of (scene, selected clips, time): frame k never
//! depends on the frames rendered before it, which is what makes `--frames k..k+1`
//! reproduce frame k of a longer run byte for byte. By default all clips play together;
//! every clip holds its end values outside its key range (glTF leaves looping to the
//! application; mipray clamps).
//!
//! Per frame: [`Pose::evaluate`] (node world transforms, morph weights, joint matrices),
//! then for each drawn primitive for which [`primitive_deforms`] holds,
//! [`deform_primitive`] writes its vertices (object space for morph-only primitives, world
//! space for skinned ones); the other primitives are placed rigidly by `world_from_node`.

mod deform;
mod pose;
mod sample;
mod scale;
mod selection;

pub use deform::{VertexSpace, deform_primitive, primitive_deforms};
pub use pose::Pose;
pub use sample::{sample_channel, sample_rotation, sample_vec3};
pub use scale::{NodeShape, node_shapes};
pub use selection::{AnimationSelection, moving_nodes, select_animation};

use glam::Mat4;

use crate::scene::SceneDesc;

/// World transforms of every node at time `time_s` with all clips playing (indexed like
/// `SceneDesc::nodes`). Nodes not reachable from the scene roots keep the identity.
/// Allocates; a frame loop keeps a [`Pose`] instead.
pub fn node_world_transforms(scene: &SceneDesc, time_s: f32) -> Vec<Mat4> {
    let mut pose = Pose::default();
    pose.evaluate(scene, AnimationSelection::All, time_s);
    pose.world_from_node
}
