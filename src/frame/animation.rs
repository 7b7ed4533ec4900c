//! The animation state of the frame loop, and its step (*animate*): the scene posed at this
//! frame's time and at the previous frame's, each node's shape, and each instance's
//! placement now and before.
//!
//! Each channel is sampled once per frame: [`Pose::evaluate`] samples them into local
//! transforms, and the shapes are read from those same values ([`Pose::node_shapes`]).
//! Everything here is a pure function of the time (the previous frame's values are only
//! kept, for the dirty step to compare against).

use glam::Mat4;

use super::posed::VertexSource;
use super::setup::FrameSetup;
use crate::anim::{NodeShape, Pose};

/// One instance's placement in one frame.
#[derive(Debug, Clone, Copy)]
pub(super) struct InstanceState {
    pub world_from_object: Mat4,
    /// The placement's shape (uniform scale and axis stretch), exact through the hierarchy
    /// (see `anim::node_shapes`); `None` for a shear, a stretch under a rotation, or a
    /// skinned/morphed primitive (then only its world vertices tell its shape).
    pub shape: Option<NodeShape>,
}

/// This frame's pose, shapes and instance placements, and the previous frame's.
pub(super) struct AnimationState {
    pose: Pose,
    previous_pose: Pose,
    /// Per node: this frame's shape.
    shapes: Vec<Option<NodeShape>>,
    /// Per instance: this frame's placement.
    instances: Vec<InstanceState>,
    /// Per instance: the previous frame's placement (empty before the second frame).
    previous_instances: Vec<InstanceState>,
}

impl AnimationState {
    /// Before the first frame; `pose` only lends its buffers.
    pub fn new(pose: Pose) -> AnimationState {
        AnimationState {
            pose,
            previous_pose: Pose::default(),
            shapes: Vec::new(),
            instances: Vec::new(),
            previous_instances: Vec::new(),
        }
    }

    /// Animate: poses the scene at `time_s` with the selected clips, keeping the previous
    /// pose; reads every node's shape from it and places every instance.
    pub fn advance(&mut self, setup: &FrameSetup, time_s: f32) {
        std::mem::swap(&mut self.pose, &mut self.previous_pose);
        self.pose
            .evaluate(&setup.scene, setup.settings.animation, time_s);
        self.pose.node_shapes(&setup.scene, &mut self.shapes);
        std::mem::swap(&mut self.instances, &mut self.previous_instances);
        self.instances.clear();
        // A deforming instance has no shape key: its `log2 P_b` always comes from its world
        // vertices.
        let placed = setup
            .geometry
            .instances
            .iter()
            .zip(&setup.deforms)
            .map(|(inst, &source)| InstanceState {
                world_from_object: self.pose.world_from_node[inst.node as usize],
                shape: match source {
                    VertexSource::Deformed => None,
                    VertexSource::Placed => self.shapes[inst.node as usize],
                },
            });
        self.instances.extend(placed);
    }

    /// The scene posed at this frame's time.
    pub fn pose(&self) -> &Pose {
        &self.pose
    }

    /// The scene posed at the previous frame's time.
    pub fn previous_pose(&self) -> &Pose {
        &self.previous_pose
    }

    /// Per instance: this frame's placement.
    pub fn instances(&self) -> &[InstanceState] {
        &self.instances
    }

    /// Per instance: the previous frame's placement (valid from the second frame on).
    pub fn previous_instances(&self) -> &[InstanceState] {
        &self.previous_instances
    }
}
