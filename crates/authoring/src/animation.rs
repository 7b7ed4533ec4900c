//! Keyframed node animation: channels of translation, rotation, scale or morph-target
//! weight keys with glTF's LINEAR, STEP or CUBICSPLINE interpolation.
//!
//! Invariants checked by the builder: key times are non-negative and strictly increasing;
//! each channel has `times.len() * values_per_key()` values; rotation values are unit
//! quaternions (x, y, z, w); a node property is driven by at most one channel of an
//! animation.

use glam::{Quat, Vec3};

use super::handles::NodeId;

/// The node property an animation channel drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AnimatedProperty {
    /// The node's `translation` (3 numbers per key).
    Translation,
    /// The node's `rotation`, a unit quaternion x, y, z, w (4 numbers per key).
    Rotation,
    /// The node's `scale` (3 numbers per key).
    Scale,
    /// The morph-target `weights` of the node's mesh (`targets` numbers per key, one per
    /// morph target; the node's mesh must have exactly that many targets).
    Weights {
        /// Morph targets of the node's mesh, > 0.
        targets: usize,
    },
}

impl AnimatedProperty {
    /// Numbers per key value: 3 for translation and scale, 4 for a quaternion, one per
    /// morph target for weights.
    pub fn components(self) -> usize {
        match self {
            AnimatedProperty::Rotation => 4,
            AnimatedProperty::Weights { targets } => targets,
            _ => 3,
        }
    }
}

/// How values between keys are computed (glTF sampler interpolation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Interpolation {
    /// Linear for translation and scale, spherical linear (slerp) for rotation.
    Linear,
    /// The previous key's value until the next key.
    Step,
    /// Cubic Hermite; each key stores in-tangent, value, out-tangent.
    CubicSpline,
}

/// One keyframe track of one node property.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// The node whose property is driven.
    pub node: NodeId,
    /// Which of its properties.
    pub property: AnimatedProperty,
    /// How values between keys are computed.
    pub interpolation: Interpolation,
    /// Key times in seconds: non-negative, strictly increasing.
    pub times: Vec<f32>,
    /// Flat key values: `times.len() * property.components()` numbers, three times that for
    /// [`Interpolation::CubicSpline`] (in-tangent, value, out-tangent per key).
    pub values: Vec<f32>,
}

impl Channel {
    /// A translation track; for CUBICSPLINE `keys` holds in-tangent, value, out-tangent
    /// for each time.
    pub fn translation(
        node: NodeId,
        interpolation: Interpolation,
        times: Vec<f32>,
        keys: &[Vec3],
    ) -> Self {
        let values = keys.iter().flat_map(|v| v.to_array()).collect();
        Channel {
            node,
            property: AnimatedProperty::Translation,
            interpolation,
            times,
            values,
        }
    }

    /// A rotation track of quaternions (x, y, z, w); for CUBICSPLINE `keys` holds
    /// in-tangent, value, out-tangent for each time. Values (not tangents) are normalized.
    pub fn rotation(
        node: NodeId,
        interpolation: Interpolation,
        times: Vec<f32>,
        keys: &[Quat],
    ) -> Self {
        let is_value = |i: usize| interpolation != Interpolation::CubicSpline || i % 3 == 1;
        let values = keys
            .iter()
            .enumerate()
            .flat_map(|(i, q)| if is_value(i) { q.normalize() } else { *q }.to_array())
            .collect();
        Channel {
            node,
            property: AnimatedProperty::Rotation,
            interpolation,
            times,
            values,
        }
    }

    /// A scale track; for CUBICSPLINE `keys` holds in-tangent, value, out-tangent for each
    /// time.
    pub fn scale(
        node: NodeId,
        interpolation: Interpolation,
        times: Vec<f32>,
        keys: &[Vec3],
    ) -> Self {
        Channel {
            property: AnimatedProperty::Scale,
            ..Channel::translation(node, interpolation, times, keys)
        }
    }

    /// A morph-weights track for a node whose mesh has `targets` morph targets: `values`
    /// holds `targets` weights per key time (for CUBICSPLINE, the in-tangents, the weights
    /// and the out-tangents of each key, `targets` numbers each).
    pub fn weights(
        node: NodeId,
        interpolation: Interpolation,
        times: Vec<f32>,
        targets: usize,
        values: Vec<f32>,
    ) -> Self {
        Channel {
            node,
            property: AnimatedProperty::Weights { targets },
            interpolation,
            times,
            values,
        }
    }

    /// Numbers stored per key time (3 per value for CUBICSPLINE's tangents and value).
    pub fn values_per_key(&self) -> usize {
        let per_value = self.property.components();
        match self.interpolation {
            Interpolation::CubicSpline => 3 * per_value,
            _ => per_value,
        }
    }

    /// Time of the last key (0 when there is none).
    pub fn duration(&self) -> f32 {
        self.times.last().copied().unwrap_or(0.0)
    }
}

/// A named set of channels played together.
#[derive(Debug, Clone, PartialEq)]
pub struct Animation {
    /// Shown by viewers; need not be unique.
    pub name: String,
    /// The tracks, at most one per node property.
    pub channels: Vec<Channel>,
}

impl Animation {
    /// Time of the last key over all channels.
    pub fn duration(&self) -> f32 {
        self.channels
            .iter()
            .map(Channel::duration)
            .fold(0.0, f32::max)
    }
}
