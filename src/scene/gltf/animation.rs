//! Animations: every channel as flat keyframe data, exactly as glTF stores it.
//!
//! Invariants of each channel that comes out: key times finite and non-decreasing,
//! `values.len() == times.len() * components` (three times that for CUBICSPLINE: in-tangent,
//! value, out-tangent per key), all values finite. Channels targeting a matrix node (which
//! the spec forbids) or morph weights of a node without morph targets are skipped with a note.

use gltf::accessor::Dimensions;
use gltf::animation::{Interpolation as GltfInterpolation, Property};

use super::accessor::{Integers, read_floats};
use super::buffers::Buffers;
use crate::scene::{AnimationDesc, ChannelDesc, ChannelTarget, Interpolation, NodeDesc};

/// Loads every animation.
pub(super) fn load_animations(
    document: &gltf::Document,
    buffers: &Buffers,
    nodes: &[NodeDesc],
    notes: &mut Vec<String>,
) -> Result<Vec<AnimationDesc>, String> {
    let mut animations = Vec::with_capacity(document.animations().len());
    for animation in document.animations() {
        let mut channels = Vec::new();
        for channel in animation.channels() {
            let what = format!(
                "animation {} channel {}",
                animation.index(),
                channel.index()
            );
            if let Some(desc) = load_channel(&channel, buffers, nodes, &what, notes)? {
                channels.push(desc);
            }
        }
        animations.push(AnimationDesc {
            name: animation.name().unwrap_or_default().to_string(),
            channels,
        });
    }
    Ok(animations)
}

/// One channel, or `None` when its target cannot be animated (noted).
fn load_channel(
    channel: &gltf::animation::Channel,
    buffers: &Buffers,
    nodes: &[NodeDesc],
    what: &str,
    notes: &mut Vec<String>,
) -> Result<Option<ChannelDesc>, String> {
    let node = channel.target().node();
    if nodes[node.index()].matrix.is_some() {
        notes.push(format!(
            "{what} targets node {}, which has a matrix; skipped",
            node.index()
        ));
        return Ok(None);
    }
    let target = channel_target(channel.target().property());
    let components = match target {
        ChannelTarget::Translation | ChannelTarget::Scale => 3,
        ChannelTarget::Rotation => 4,
        ChannelTarget::Weights => match morph_target_count(&node) {
            0 => {
                notes.push(format!(
                    "{what} animates weights of node {}, which has no morph targets; skipped",
                    node.index()
                ));
                return Ok(None);
            }
            count => count,
        },
    };
    let sampler = channel.sampler();
    let interpolation = interpolation(sampler.interpolation());
    let times = read_key_times(&sampler.input(), buffers, what)?;
    let values = read_key_values(&sampler.output(), buffers, what, target)?;
    let per_key = if interpolation == Interpolation::CubicSpline {
        3 * components
    } else {
        components
    };
    if values.len() != times.len() * per_key {
        return Err(format!(
            "{what}: accessor {} has {} output numbers, expected {} keys x {per_key}",
            sampler.output().index(),
            values.len(),
            times.len()
        ));
    }
    if target == ChannelTarget::Rotation {
        note_zero_rotation_keys(&values, per_key, what, notes);
    }
    Ok(Some(ChannelDesc {
        node: node.index(),
        target,
        interpolation,
        times,
        values,
        components,
    }))
}

/// Notes a rotation channel's keys of zero length (all four numbers zero): glTF requires
/// unit quaternions, and such a key has no direction, so where a frame's rotation comes out
/// without one `anim::sample_rotation` gives the identity (under LINEAR, throughout both
/// spans next to the key). Keys of any other length keep their direction
/// (`anim::sample`'s `unit_quaternion`). `per_key`: numbers per key (4, or 12 for CUBICSPLINE, whose
/// key value is the middle 4).
fn note_zero_rotation_keys(values: &[f32], per_key: usize, what: &str, notes: &mut Vec<String>) {
    let value_at = if per_key == 12 { 4 } else { 0 };
    let zero = values
        .chunks_exact(per_key)
        .filter(|key| key[value_at..value_at + 4].iter().all(|&c| c == 0.0))
        .count();
    if zero > 0 {
        notes.push(format!(
            "{what}: {zero} rotation key(s) have zero length (glTF requires unit quaternions); \
             a frame whose rotation has no direction there uses the identity"
        ));
    }
}

fn channel_target(property: Property) -> ChannelTarget {
    match property {
        Property::Translation => ChannelTarget::Translation,
        Property::Rotation => ChannelTarget::Rotation,
        Property::Scale => ChannelTarget::Scale,
        Property::MorphTargetWeights => ChannelTarget::Weights,
    }
}

fn interpolation(interpolation: GltfInterpolation) -> Interpolation {
    match interpolation {
        GltfInterpolation::Step => Interpolation::Step,
        GltfInterpolation::Linear => Interpolation::Linear,
        GltfInterpolation::CubicSpline => Interpolation::CubicSpline,
    }
}

/// Morph target count of the node's mesh (all its primitives must agree, per the spec;
/// the first one is taken).
fn morph_target_count(node: &gltf::Node) -> usize {
    node.mesh()
        .and_then(|mesh| mesh.primitives().next())
        .map_or(0, |primitive| primitive.morph_targets().len())
}

/// Key times: finite and non-decreasing, in seconds.
fn read_key_times(
    accessor: &gltf::Accessor,
    buffers: &Buffers,
    what: &str,
) -> Result<Vec<f32>, String> {
    let label = format!("key times of {what}");
    let times = read_floats(
        accessor,
        buffers,
        &label,
        Dimensions::Scalar,
        Integers::Rejected,
    )?;
    check_finite(&times, accessor, &label)?;
    for (i, pair) in times.windows(2).enumerate() {
        if pair[1] < pair[0] {
            return Err(format!(
                "accessor {} ({label}): time {} at key {} is before {} at key {i}",
                accessor.index(),
                pair[1],
                i + 1,
                pair[0]
            ));
        }
    }
    Ok(times)
}

/// Key values, flat; rotations and weights may be normalized integers.
fn read_key_values(
    accessor: &gltf::Accessor,
    buffers: &Buffers,
    what: &str,
    target: ChannelTarget,
) -> Result<Vec<f32>, String> {
    let label = format!("key values of {what}");
    let (dimensions, integers) = match target {
        ChannelTarget::Translation | ChannelTarget::Scale => (Dimensions::Vec3, Integers::Rejected),
        ChannelTarget::Rotation => (Dimensions::Vec4, Integers::Normalized),
        ChannelTarget::Weights => (Dimensions::Scalar, Integers::Normalized),
    };
    let values = read_floats(accessor, buffers, &label, dimensions, integers)?;
    check_finite(&values, accessor, &label)?;
    Ok(values)
}

fn check_finite(values: &[f32], accessor: &gltf::Accessor, label: &str) -> Result<(), String> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!(
            "accessor {} ({label}) has a non-finite number at {i}",
            accessor.index()
        )),
        None => Ok(()),
    }
}
