//! The pose of a scene at one time: every node's world transform, every node's effective
//! morph weights and every skin's joint matrices.
//!
//! Invariant: [`Pose::evaluate`] is a pure function of (scene, selection, time); the
//! previous contents of a reused `Pose` only lend their allocations. Evaluation order is
//! fixed (channels in file order, nodes depth first), so the same inputs give the same bits.

use glam::Mat4;

use super::sample::{sample_channel, sample_rotation, sample_vec3};
use super::selection::AnimationSelection;
use crate::scene::{ChannelTarget, SceneDesc, Trs};

/// A scene posed at one time. Create once (`Pose::default()`) and re-`evaluate` per frame:
/// its vectors are cleared and refilled, not reallocated.
#[derive(Debug, Default, Clone)]
pub struct Pose {
    /// Per node (indexed like `SceneDesc::nodes`): world from node. Nodes not reachable from
    /// the scene roots keep the identity.
    pub world_from_node: Vec<Mat4>,
    /// Per node: the effective morph weights of its mesh (empty when it has no mesh or the
    /// mesh has no morph targets): an animated weights channel if the selection has one,
    /// else the node's `weights`, else the mesh's default `weights`.
    pub morph_weights: Vec<Vec<f32>>,
    /// Per skin (indexed like `SceneDesc::skins`), per joint: world from the mesh's bind
    /// space, `world_from_node[joint] * inverse_bind_matrix`.
    pub joint_matrices: Vec<Vec<Mat4>>,
    /// Each node's local TRS with the channels applied (also what its shape is read from,
    /// `Pose::node_shapes`, so each channel is sampled once per frame).
    pub(super) local: Vec<Trs>,
    /// Scratch: whether a channel drove the node's TRS (a matrix node keeps its exact
    /// matrix otherwise).
    animated: Vec<bool>,
    /// Scratch: depth-first traversal stack of (node, world from parent).
    stack: Vec<(usize, Mat4)>,
    /// Scratch: a weights channel sampled before it is copied into `morph_weights`.
    sampled: Vec<f32>,
}

impl Pose {
    /// Poses `scene` at `time_s` with the selected clips (each clamped at its ends).
    pub fn evaluate(&mut self, scene: &SceneDesc, selection: AnimationSelection, time_s: f32) {
        self.rest(scene);
        self.apply_channels(scene, selection, time_s);
        self.compose_world(scene);
        self.compute_joint_matrices(scene);
    }

    /// The first (skin, joint) whose joint matrix is not finite, if any: a pose that
    /// overflowed (e.g. huge animated scales). `deform_primitive` keeps its output finite
    /// by falling back for such vertices; a caller that wants to reject the frame instead
    /// checks this.
    pub fn nonfinite_joint(&self) -> Option<(usize, usize)> {
        self.joint_matrices
            .iter()
            .enumerate()
            .find_map(|(s, matrices)| matrices.iter().position(|m| !m.is_finite()).map(|j| (s, j)))
    }

    /// Rest TRS and rest morph weights (node override, else mesh default).
    fn rest(&mut self, scene: &SceneDesc) {
        let n = scene.nodes.len();
        self.local.clear();
        self.local.extend(scene.nodes.iter().map(|node| node.local));
        self.animated.clear();
        self.animated.resize(n, false);
        self.morph_weights.resize_with(n, Vec::new);
        self.morph_weights.truncate(n);
        for (weights, node) in self.morph_weights.iter_mut().zip(&scene.nodes) {
            weights.clear();
            let mesh_weights = node
                .mesh
                .and_then(|m| scene.meshes.get(m))
                .map_or(&[][..], |mesh| &mesh.weights);
            match &node.weights {
                // An override of the wrong length (not from the loader) is ignored.
                Some(w) if w.len() == mesh_weights.len() => weights.extend_from_slice(w),
                _ => weights.extend_from_slice(mesh_weights),
            }
        }
    }

    /// Samples every channel of the selected clips into the local TRS and morph weights;
    /// later channels overwrite earlier ones.
    fn apply_channels(&mut self, scene: &SceneDesc, selection: AnimationSelection, t: f32) {
        for channel in selection.clips(scene).iter().flat_map(|a| &a.channels) {
            let node = channel.node;
            let Some(local) = self.local.get_mut(node) else {
                continue;
            };
            match channel.target {
                ChannelTarget::Translation => local.translation = sample_vec3(channel, t),
                ChannelTarget::Rotation => local.rotation = sample_rotation(channel, t),
                ChannelTarget::Scale => local.scale = sample_vec3(channel, t),
                ChannelTarget::Weights => {
                    let weights = &mut self.morph_weights[node];
                    // A channel sized unlike the mesh's targets (not from the loader)
                    // drives the targets both have.
                    self.sampled.clear();
                    self.sampled.resize(channel.components, 0.0);
                    sample_channel(channel, t, &mut self.sampled);
                    for (w, s) in weights.iter_mut().zip(&self.sampled) {
                        *w = *s;
                    }
                    continue;
                }
            }
            self.animated[node] = true;
        }
    }

    /// World transforms from the roots down, parents before children.
    fn compose_world(&mut self, scene: &SceneDesc) {
        self.world_from_node.clear();
        self.world_from_node
            .resize(scene.nodes.len(), Mat4::IDENTITY);
        self.stack.clear();
        self.stack
            .extend(scene.roots.iter().rev().map(|&r| (r, Mat4::IDENTITY)));
        while let Some((node, world_from_parent)) = self.stack.pop() {
            let desc = &scene.nodes[node];
            let parent_from_node = match desc.matrix {
                // A matrix node is never a channel target (glTF spec; the loader drops such
                // channels), so the exact matrix is kept rather than its decomposition.
                Some(m) if !self.animated[node] => m,
                _ => self.local[node].to_mat4(),
            };
            let world_from_node = world_from_parent * parent_from_node;
            self.world_from_node[node] = world_from_node;
            self.stack
                .extend(desc.children.iter().rev().map(|&c| (c, world_from_node)));
        }
    }

    fn compute_joint_matrices(&mut self, scene: &SceneDesc) {
        self.joint_matrices.resize_with(scene.skins.len(), Vec::new);
        self.joint_matrices.truncate(scene.skins.len());
        for (matrices, skin) in self.joint_matrices.iter_mut().zip(&scene.skins) {
            matrices.clear();
            matrices.extend(skin.joints.iter().enumerate().map(|(j, &node)| {
                let world_from_joint = self
                    .world_from_node
                    .get(node)
                    .copied()
                    .unwrap_or(Mat4::IDENTITY);
                let inverse_bind = skin
                    .inverse_bind_matrices
                    .get(j)
                    .copied()
                    .unwrap_or(Mat4::IDENTITY);
                world_from_joint * inverse_bind
            }));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{
        AnimationDesc, ChannelDesc, Interpolation, MeshDesc, NodeDesc, PrimitiveDesc, SkinDesc,
    };
    use glam::{Quat, Vec3};

    fn weights_channel(node: usize, interpolation: Interpolation, values: &[f32]) -> ChannelDesc {
        ChannelDesc {
            node,
            target: ChannelTarget::Weights,
            interpolation,
            times: vec![0.0, 1.0],
            values: values.to_vec(),
            components: 2,
        }
    }

    /// Nodes 0 and 1 draw a 2-target mesh; node 1 overrides the weights; node 2 is a joint
    /// child of node 0.
    fn scene() -> SceneDesc {
        let mut scene = SceneDesc::default();
        scene.meshes.push(MeshDesc {
            name: "m".into(),
            primitives: vec![PrimitiveDesc::default()],
            weights: vec![0.25, 0.5],
        });
        scene.nodes.push(NodeDesc {
            mesh: Some(0),
            children: vec![2],
            local: Trs {
                translation: Vec3::X,
                ..Default::default()
            },
            ..Default::default()
        });
        scene.nodes.push(NodeDesc {
            mesh: Some(0),
            weights: Some(vec![1.0, 2.0]),
            ..Default::default()
        });
        scene.nodes.push(NodeDesc {
            local: Trs {
                translation: Vec3::Y,
                rotation: Quat::from_rotation_z(1.0),
                ..Default::default()
            },
            ..Default::default()
        });
        scene.roots = vec![0, 1];
        scene.skins.push(SkinDesc {
            joints: vec![2, 0],
            inverse_bind_matrices: vec![Mat4::from_translation(-Vec3::Y), Mat4::IDENTITY],
            ..Default::default()
        });
        scene
    }

    #[test]
    fn weights_precedence_is_channel_then_node_then_mesh() {
        let mut scene = scene();
        let mut pose = Pose::default();
        pose.evaluate(&scene, AnimationSelection::All, 0.0);
        assert_eq!(
            pose.morph_weights,
            vec![vec![0.25, 0.5], vec![1.0, 2.0], vec![]]
        );
        scene.animations.push(AnimationDesc {
            name: "w".into(),
            channels: vec![
                weights_channel(0, Interpolation::Linear, &[0.0, 0.0, 1.0, 3.0]),
                weights_channel(1, Interpolation::Step, &[5.0, 6.0, 7.0, 8.0]),
            ],
        });
        pose.evaluate(&scene, AnimationSelection::All, 0.5);
        assert_eq!(
            pose.morph_weights,
            vec![vec![0.5, 1.5], vec![5.0, 6.0], vec![]]
        );
        // A selection without the clip falls back to the rest weights.
        pose.evaluate(&scene, AnimationSelection::One(1), 0.5);
        assert_eq!(pose.morph_weights[1], vec![1.0, 2.0]);
    }

    #[test]
    fn joint_matrices_are_world_from_joint_times_inverse_bind() {
        let scene = scene();
        let mut pose = Pose::default();
        pose.evaluate(&scene, AnimationSelection::All, 0.0);
        let world_joint = Mat4::from_translation(Vec3::X)
            * Mat4::from_rotation_translation(Quat::from_rotation_z(1.0), Vec3::Y);
        assert!(pose.world_from_node[2].abs_diff_eq(world_joint, 1e-6));
        let expected = world_joint * Mat4::from_translation(-Vec3::Y);
        assert!(pose.joint_matrices[0][0].abs_diff_eq(expected, 1e-6));
        assert_eq!(pose.joint_matrices[0][1], Mat4::from_translation(Vec3::X));
        assert_eq!(pose.nonfinite_joint(), None);
    }

    #[test]
    fn reevaluating_reuses_allocations_and_depends_only_on_the_inputs() {
        let mut scene = scene();
        scene.animations.push(AnimationDesc {
            name: "w".into(),
            channels: vec![weights_channel(0, Interpolation::CubicSpline, &[0.0; 12])],
        });
        let mut pose = Pose::default();
        pose.evaluate(&scene, AnimationSelection::All, 0.3);
        let first = pose.clone();
        let pointers = (
            pose.world_from_node.as_ptr(),
            pose.morph_weights[0].as_ptr(),
            pose.joint_matrices[0].as_ptr(),
        );
        pose.evaluate(&scene, AnimationSelection::All, 0.9);
        pose.evaluate(&scene, AnimationSelection::All, 0.3);
        assert_eq!(pose.world_from_node, first.world_from_node);
        assert_eq!(pose.morph_weights, first.morph_weights);
        assert_eq!(pose.joint_matrices, first.joint_matrices);
        let again = (
            pose.world_from_node.as_ptr(),
            pose.morph_weights[0].as_ptr(),
            pose.joint_matrices[0].as_ptr(),
        );
        assert_eq!(pointers, again);
    }
}
