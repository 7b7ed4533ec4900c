//! Keyframe sampling: STEP, LINEAR (slerp for rotations) and CUBICSPLINE (glTF 2.0 Appendix C),
//! plus SQUAD for rotations (BART/AFF `rot` tracks, see [`squad`]).
//!
//! Times outside the key range clamp to the first / last key. Duplicate key times are
//! allowed: the later key wins from its time on (a jump), never a division by zero.

use glam::{Quat, Vec3, Vec4};

use crate::scene::{ChannelDesc, Interpolation};

/// Where `t` falls among the keys: the interval start index and the fraction in it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct KeySpan {
    index: usize,
    /// In [0, 1]; 0 when clamped before the first key or at a duplicate time.
    fraction: f32,
    /// Interval length in seconds (0 when clamped).
    dt: f32,
}

fn locate(times: &[f32], t: f32) -> KeySpan {
    let last = times.len().saturating_sub(1);
    if times.is_empty() || !(t > times[0]) {
        return KeySpan {
            index: 0,
            fraction: 0.0,
            dt: 0.0,
        };
    }
    if t >= times[last] {
        return KeySpan {
            index: last,
            fraction: 0.0,
            dt: 0.0,
        };
    }
    // First key strictly after t; the interval is [next - 1, next].
    let next = times.partition_point(|&k| k <= t);
    let index = next - 1;
    let dt = times[next] - times[index];
    let fraction = if dt > 0.0 {
        ((t - times[index]) / dt).clamp(0.0, 1.0)
    } else {
        0.0
    };
    KeySpan {
        index,
        fraction,
        dt,
    }
}

/// Samples a channel into `out` (`channel.components` numbers) at time `t`.
pub fn sample_channel(channel: &ChannelDesc, t: f32, out: &mut [f32]) {
    let n = channel.components;
    debug_assert_eq!(out.len(), n);
    if channel.times.is_empty() || n == 0 {
        return;
    }
    let span = locate(&channel.times, t);
    let keys = channel.times.len();
    match channel.interpolation {
        Interpolation::CubicSpline => {
            // Per key: in-tangent, value, out-tangent, each `n` numbers.
            let value = |k: usize, j: usize| channel.values[(3 * k + 1) * n + j];
            let in_tangent = |k: usize, j: usize| channel.values[3 * k * n + j];
            let out_tangent = |k: usize, j: usize| channel.values[(3 * k + 2) * n + j];
            if span.dt == 0.0 || span.index + 1 >= keys {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = value(span.index, j);
                }
                return;
            }
            let (s, dt, k) = (span.fraction, span.dt, span.index);
            let s2 = s * s;
            let s3 = s2 * s;
            let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
            let h10 = s3 - 2.0 * s2 + s;
            let h01 = -2.0 * s3 + 3.0 * s2;
            let h11 = s3 - s2;
            for (j, o) in out.iter_mut().enumerate() {
                *o = h00 * value(k, j)
                    + h10 * dt * out_tangent(k, j)
                    + h01 * value(k + 1, j)
                    + h11 * dt * in_tangent(k + 1, j);
            }
        }
        Interpolation::Squad => {
            // Per key: in-control b_k, value q_k, out-control a_k, each `n` numbers.
            let quat = |k: usize, slot: usize| {
                let base = (3 * k + slot) * n;
                Quat::from_slice(&channel.values[base..base + 4])
            };
            if n != 4 || span.dt == 0.0 || span.fraction == 0.0 || span.index + 1 >= keys {
                let base = (3 * span.index + 1) * n;
                out.copy_from_slice(&channel.values[base..base + n]);
                return;
            }
            let k = span.index;
            let q = squad(
                quat(k, 1),
                quat(k + 1, 1),
                quat(k, 2),
                quat(k + 1, 0),
                span.fraction,
            );
            out.copy_from_slice(&q.to_array());
        }
        Interpolation::Step | Interpolation::Linear => {
            let a = &channel.values[span.index * n..(span.index + 1) * n];
            let linear = channel.interpolation == Interpolation::Linear;
            if !linear || span.fraction == 0.0 || span.index + 1 >= keys {
                out.copy_from_slice(a);
                return;
            }
            let b = &channel.values[(span.index + 1) * n..(span.index + 2) * n];
            for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
                *o = x + (y - x) * span.fraction;
            }
        }
    }
}

/// Samples a translation or scale channel.
pub fn sample_vec3(channel: &ChannelDesc, t: f32) -> Vec3 {
    let mut v = [0.0; 3];
    sample_channel(channel, t, &mut v);
    Vec3::from(v)
}

/// Samples a rotation channel: slerp between keys for LINEAR (the glTF rule), the
/// normalised Hermite spline for CUBICSPLINE.
pub fn sample_rotation(channel: &ChannelDesc, t: f32) -> Quat {
    let quat_at = |k: usize| {
        let stride = if matches!(
            channel.interpolation,
            Interpolation::CubicSpline | Interpolation::Squad
        ) {
            3
        } else {
            1
        };
        let base = (k * stride + stride / 2) * 4;
        Quat::from_vec4(Vec4::from_slice(&channel.values[base..base + 4]))
    };
    let q = if channel.interpolation == Interpolation::Linear && !channel.times.is_empty() {
        let span = locate(&channel.times, t);
        let Some(a) = unit_quaternion(quat_at(span.index)) else {
            return Quat::IDENTITY;
        };
        if span.fraction == 0.0 || span.index + 1 >= channel.times.len() {
            a
        } else {
            let Some(b) = unit_quaternion(quat_at(span.index + 1)) else {
                return Quat::IDENTITY;
            };
            a.slerp(b, span.fraction)
        }
    } else {
        let mut v = [0.0; 4];
        sample_channel(channel, t, &mut v);
        Quat::from_array(v)
    };
    unit_quaternion(q).unwrap_or(Quat::IDENTITY)
}

/// `q` at unit length: `Quat::normalize`'s bits wherever its squared length is a normal
/// `f32` (every key a valid file holds); a quaternion so long or so short that the squared
/// length overflows or underflows is first divided by its largest component, so it keeps
/// its direction. `None` where there is no direction: all zeros (glTF forbids it, the
/// loader notes it) or a non-finite component.
pub fn unit_quaternion(q: Quat) -> Option<Quat> {
    let unit = q.normalize();
    if unit.is_finite() && unit != Quat::from_xyzw(0.0, 0.0, 0.0, 0.0) {
        return Some(unit);
    }
    let v = Vec4::from(q);
    let largest = v.abs().max_element();
    if !(largest > 0.0 && largest.is_finite()) {
        return None;
    }
    let unit = Quat::from_vec4(v / largest).normalize();
    unit.is_finite().then_some(unit)
}

/// Slerp as the BART reference (Eberly's) computes it: no hemisphere flip (the shorter arc
/// is the caller's business), and when `sin(angle) < 1e-6` the first argument unchanged.
pub fn slerp_no_flip(p: Quat, q: Quat, u: f32) -> Quat {
    let angle = p.dot(q).clamp(-1.0, 1.0).acos();
    let sin = angle.sin();
    if sin < 1e-6 {
        return p;
    }
    let a = ((1.0 - u) * angle).sin() / sin;
    let b = (u * angle).sin() / sin;
    Quat::from_vec4(Vec4::from(p) * a + Vec4::from(q) * b)
}

/// Spherical quadrangle interpolation between keys `q1` and `q2` with controls `a` (outgoing
/// at `q1`) and `b` (incoming at `q2`):
/// `slerp(slerp(q1, q2, u), slerp(a, b, u), 2u(1-u))`, with [`slerp_no_flip`].
pub fn squad(q1: Quat, q2: Quat, a: Quat, b: Quat, u: f32) -> Quat {
    slerp_no_flip(
        slerp_no_flip(q1, q2, u),
        slerp_no_flip(a, b, u),
        2.0 * u * (1.0 - u),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::ChannelTarget;

    #[test]
    fn unit_quaternions_keep_their_direction_at_any_length() {
        let q = Quat::from_xyzw(0.1, -0.2, 0.3, 0.9);
        // The usual case: exactly `normalize`'s bits.
        assert_eq!(unit_quaternion(q), Some(q.normalize()));
        for scale in [1e-30f32, 1e-37, 1e20, 3e38] {
            let scaled = Quat::from_vec4(Vec4::from(q) * scale);
            let unit = unit_quaternion(scaled).unwrap_or_else(|| panic!("{scale}"));
            assert!(unit.is_normalized(), "{scale}: {unit}");
            assert!(unit.angle_between(q.normalize()) < 1e-3, "{scale}: {unit}");
        }
        assert_eq!(unit_quaternion(Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)), None);
        assert_eq!(
            unit_quaternion(Quat::from_xyzw(0.0, f32::NAN, 0.0, 1.0)),
            None
        );
        assert_eq!(
            unit_quaternion(Quat::from_xyzw(0.0, f32::INFINITY, 0.0, 1.0)),
            None
        );
    }

    #[test]
    fn rotation_keys_without_a_direction_give_the_identity_and_huge_keys_their_own() {
        let quarter = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
        let huge = Vec4::from(quarter) * 1e30;
        for (interpolation, values) in [
            (
                Interpolation::Linear,
                [[0.0; 4], quarter.to_array()].concat(),
            ),
            (Interpolation::Step, [[0.0; 4], quarter.to_array()].concat()),
        ] {
            let c = channel(interpolation, &[0.0, 1.0], &values, 4);
            assert_eq!(
                sample_rotation(&c, 0.0),
                Quat::IDENTITY,
                "{interpolation:?}"
            );
            assert!(
                sample_rotation(&c, 1.0).angle_between(quarter) < 1e-6,
                "{interpolation:?}"
            );
        }
        // Linear: the span next to a zero key has no direction to turn from.
        let c = channel(
            Interpolation::Linear,
            &[0.0, 1.0],
            &[[0.0; 4], quarter.to_array()].concat(),
            4,
        );
        assert_eq!(sample_rotation(&c, 0.5), Quat::IDENTITY);
        // A key whose squared length overflows f32 is the rotation it points to.
        let c = channel(
            Interpolation::Linear,
            &[0.0, 1.0],
            &[Quat::IDENTITY.to_array(), huge.to_array()].concat(),
            4,
        );
        assert!(sample_rotation(&c, 1.0).angle_between(quarter) < 1e-5);
        let half = Quat::from_rotation_z(std::f32::consts::FRAC_PI_4);
        assert!(sample_rotation(&c, 0.5).angle_between(half) < 1e-5);
    }

    fn channel(
        interpolation: Interpolation,
        times: &[f32],
        values: &[f32],
        n: usize,
    ) -> ChannelDesc {
        ChannelDesc {
            node: 0,
            target: ChannelTarget::Translation,
            interpolation,
            times: times.to_vec(),
            values: values.to_vec(),
            components: n,
        }
    }

    #[test]
    fn linear_equals_keys_at_key_times_and_clamps_outside() {
        let c = channel(
            Interpolation::Linear,
            &[1.0, 2.0, 4.0],
            &[0.0, 10.0, 30.0],
            1,
        );
        let at = |t| {
            let mut v = [0.0];
            sample_channel(&c, t, &mut v);
            v[0]
        };
        assert_eq!(at(1.0), 0.0);
        assert_eq!(at(2.0), 10.0);
        assert_eq!(at(4.0), 30.0);
        assert_eq!(at(3.0), 20.0);
        assert_eq!(at(-5.0), 0.0);
        assert_eq!(at(99.0), 30.0);
        assert_eq!(at(f32::NAN), 0.0);
    }

    #[test]
    fn step_holds_previous_key() {
        let c = channel(Interpolation::Step, &[0.0, 1.0], &[5.0, 7.0], 1);
        let mut v = [0.0];
        sample_channel(&c, 0.999, &mut v);
        assert_eq!(v[0], 5.0);
        sample_channel(&c, 1.0, &mut v);
        assert_eq!(v[0], 7.0);
    }

    #[test]
    fn duplicate_key_times_jump_without_nan() {
        let c = channel(
            Interpolation::Linear,
            &[0.0, 1.0, 1.0, 2.0],
            &[0.0, 1.0, 5.0, 6.0],
            1,
        );
        let mut v = [0.0];
        sample_channel(&c, 1.0, &mut v);
        assert_eq!(v[0], 5.0);
        sample_channel(&c, 0.5, &mut v);
        assert_eq!(v[0], 0.5);
        sample_channel(&c, 1.5, &mut v);
        assert_eq!(v[0], 5.5);
    }

    #[test]
    fn cubic_spline_hits_values_and_follows_tangents() {
        // Keys at 0 and 2 with values 0 and 1, zero tangents: smoothstep in between.
        let c = channel(
            Interpolation::CubicSpline,
            &[0.0, 2.0],
            &[9.0, 0.0, 0.0, 0.0, 1.0, 9.0],
            1,
        );
        let mut v = [0.0];
        sample_channel(&c, 0.0, &mut v);
        assert_eq!(v[0], 0.0);
        sample_channel(&c, 2.0, &mut v);
        assert_eq!(v[0], 1.0);
        sample_channel(&c, 1.0, &mut v);
        assert!((v[0] - 0.5).abs() < 1e-6);
        // Out-tangent 1 per second at key 0, value 0 at both ends: positive bump.
        let c = channel(
            Interpolation::CubicSpline,
            &[0.0, 1.0],
            &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            1,
        );
        sample_channel(&c, 0.5, &mut v);
        assert!((v[0] - 0.125).abs() < 1e-6, "{}", v[0]);
    }

    #[test]
    fn squad_with_key_controls_is_slerp_and_clamps() {
        // Controls equal to the keys: squad reduces to slerp between the keys.
        let a = Quat::IDENTITY;
        let b = Quat::from_rotation_z(1.0);
        let mut values = Vec::new();
        for q in [a, a, a, b, b, b] {
            values.extend_from_slice(&q.to_array());
        }
        let mut c = channel(Interpolation::Squad, &[1.0, 3.0], &values, 4);
        c.target = ChannelTarget::Rotation;
        let q = sample_rotation(&c, 2.0);
        assert!(q.angle_between(Quat::from_rotation_z(0.5)) < 1e-5);
        assert!(sample_rotation(&c, 0.0).angle_between(a) < 1e-6);
        assert!(sample_rotation(&c, 9.0).angle_between(b) < 1e-6);
        assert!(sample_rotation(&c, 3.0).angle_between(b) < 1e-6);
        // No hemisphere flip: from q to -q (the same rotation) stays put at u = 0 and 1.
        let q = Quat::from_rotation_x(0.3);
        assert_eq!(slerp_no_flip(q, q, 0.5), q);
    }

    #[test]
    fn rotation_slerps_shortest_arc() {
        let a = Quat::IDENTITY;
        let b = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        let values: Vec<f32> = a.to_array().into_iter().chain(b.to_array()).collect();
        let mut c = channel(Interpolation::Linear, &[0.0, 1.0], &values, 4);
        c.target = ChannelTarget::Rotation;
        let q = sample_rotation(&c, 0.5);
        let expected = Quat::from_rotation_y(std::f32::consts::FRAC_PI_4);
        assert!(q.angle_between(expected) < 1e-5);
    }
}
