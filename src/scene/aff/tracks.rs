//! BART keyframe tracks (`k` blocks) converted exactly into animation channels.
//!
//! **Positions and scales** (Kochanek-Bartels, FORMAT.md 1.4): segment j (keys j..j+3)
//! is the cubic Hermite curve from `P1` to `P2` with outgoing tangent `Tout` at `P1` and
//! incoming tangent `Tin` at `P2`, over `[t1, t2]`. A glTF CUBICSPLINE channel evaluates
//! `h00 p_k + h10 dt m_out_k + h01 p_k+1 + h11 dt m_in_k+1` with `dt = t2 - t1`, so storing
//! `m_out = Tout / dt` at key j+1 and `m_in = Tin / dt` at key j+2 gives the same curve. Only
//! keys 1..n-2 become channel keys (the end keys only shape tangents), so the sampler's clamp
//! outside the key range is the reference's clamp to `[t_1, t_n-2]`. A zero-length segment
//! (duplicate time) stores zero tangents and is never evaluated: at the duplicated time the
//! sampler takes the later key (an instant jump), as the reference does ("the first segment
//! with t < t_j+2").
//!
//! **Rotations** (FORMAT.md 1.4): keys become unit quaternions (axis normalised, degrees to
//! radians, angles not reduced), each segment aligns the hemisphere of its second key with
//! its first (written back to the key), and the squad controls `a` (at the first key of the
//! segment) and `b` (at the second) are computed with the KB weights in the log domain. The
//! channel is [`Interpolation::Squad`]: per key `b_k, q_k, a_k`.
//!
//! Precomputation runs in f64; channels store f32.

use glam::{DQuat, DVec3, Vec3};

use crate::scene::{ChannelDesc, ChannelTarget, Interpolation};

/// Tension, continuity, bias of a key.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Tcb {
    pub tension: f32,
    pub continuity: f32,
    pub bias: f32,
}

/// A `transl` or `scale` key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionKey {
    pub time: f32,
    pub value: Vec3,
    pub tcb: Tcb,
}

/// A `rot` key: rotation of `angle_deg` degrees about `axis` (not necessarily unit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationKey {
    pub time: f32,
    pub axis: Vec3,
    pub angle_deg: f32,
    pub tcb: Tcb,
}

/// A `visibility` key: the flag holds from `time` to the next key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisibilityKey {
    pub time: f32,
    pub visible: bool,
}

/// All motions of one `k name { ... }` block.
#[derive(Debug, Clone, Default)]
pub struct KeyBlock {
    pub translation: Option<Vec<PositionKey>>,
    pub rotation: Option<Vec<RotationKey>>,
    pub scale: Option<Vec<PositionKey>>,
    pub visibility: Option<Vec<VisibilityKey>>,
}

/// The KB weights of one segment: `(out0, out1)` for the outgoing tangent at key 1 and
/// `(in0, in1)` for the incoming tangent at key 2 (FORMAT.md 1.4). A zero denominator (three
/// keys at one time, never in the data) gives zero weights instead of a division by zero.
fn kb_weights(t: [f64; 4], tcb1: Tcb, tcb2: Tcb) -> ((f64, f64), (f64, f64)) {
    let ratio = |num: f64, den: f64| if den != 0.0 { num / den } else { 0.0 };
    let adj0 = ratio(2.0 * (t[2] - t[1]), t[2] - t[0]);
    let adj1 = ratio(2.0 * (t[2] - t[1]), t[3] - t[1]);
    let (t1, c1, b1) = (
        tcb1.tension as f64,
        tcb1.continuity as f64,
        tcb1.bias as f64,
    );
    let (t2, c2, b2) = (
        tcb2.tension as f64,
        tcb2.continuity as f64,
        tcb2.bias as f64,
    );
    let out0 = 0.5 * adj0 * (1.0 - t1) * (1.0 + c1) * (1.0 + b1);
    let out1 = 0.5 * adj0 * (1.0 - t1) * (1.0 - c1) * (1.0 - b1);
    let in0 = 0.5 * adj1 * (1.0 - t2) * (1.0 - c2) * (1.0 + b2);
    let in1 = 0.5 * adj1 * (1.0 - t2) * (1.0 + c2) * (1.0 - b2);
    ((out0, out1), (in0, in1))
}

/// Converts a KB position/scale track (n >= 4 keys, non-decreasing times) into a CUBICSPLINE
/// channel on `node`. Returns `None` for fewer than 4 keys.
pub fn position_channel(
    keys: &[PositionKey],
    node: usize,
    target: ChannelTarget,
) -> Option<ChannelDesc> {
    let n = keys.len();
    if n < 4 {
        return None;
    }
    let m = n - 2; // channel keys: source keys 1..=n-2
    let mut in_tangents = vec![DVec3::ZERO; m];
    let mut out_tangents = vec![DVec3::ZERO; m];
    for j in 0..n - 3 {
        let k = &keys[j..j + 4];
        let t = [0, 1, 2, 3].map(|i| k[i].time as f64);
        let p = [0, 1, 2, 3].map(|i| k[i].value.as_dvec3());
        let ((out0, out1), (in0, in1)) = kb_weights(t, k[1].tcb, k[2].tcb);
        let d = p[2] - p[1];
        let tout = out0 * (p[1] - p[0]) + out1 * d;
        let tin = in0 * d + in1 * (p[3] - p[2]);
        let dt = t[2] - t[1];
        if dt > 0.0 {
            out_tangents[j] = tout / dt;
            in_tangents[j + 1] = tin / dt;
        }
    }
    let mut values = Vec::with_capacity(m * 9);
    for c in 0..m {
        for v in [
            in_tangents[c],
            keys[c + 1].value.as_dvec3(),
            out_tangents[c],
        ] {
            values.extend_from_slice(&v.as_vec3().to_array());
        }
    }
    Some(ChannelDesc {
        node,
        target,
        interpolation: Interpolation::CubicSpline,
        times: keys[1..n - 1].iter().map(|k| k.time).collect(),
        values,
        components: 3,
    })
}

/// `log((cos φ, sin φ·n)) = (0, φ·n)`; the vector part unchanged when `|sin φ| < 1e-6`.
fn quat_log(q: DQuat) -> DVec3 {
    let v = DVec3::new(q.x, q.y, q.z);
    if q.w.abs() < 1.0 {
        let angle = q.w.acos();
        let sin = angle.sin();
        if sin.abs() >= 1e-6 {
            return v * (angle / sin);
        }
    }
    v
}

/// `exp((0, φ·n)) = (cos φ, sin φ·n)`.
fn quat_exp(v: DVec3) -> DQuat {
    let angle = v.length();
    let sin = angle.sin();
    let coeff = if sin.abs() >= 1e-6 { sin / angle } else { 1.0 };
    let u = v * coeff;
    DQuat::from_xyzw(u.x, u.y, u.z, angle.cos())
}

/// The key quaternion `(cos θ/2, sin θ/2 · axis)` with the axis normalised (a zero axis
/// gives the identity).
pub fn key_quaternion(key: &RotationKey) -> DQuat {
    let axis = key.axis.as_dvec3();
    let Some(axis) = axis.try_normalize() else {
        return DQuat::IDENTITY;
    };
    let half = (key.angle_deg as f64).to_radians() * 0.5;
    let v = axis * half.sin();
    DQuat::from_xyzw(v.x, v.y, v.z, half.cos())
}

/// The rotation keys after the reference's hemisphere alignment, with the squad controls:
/// per source key 1..=n-2, `(b, q, a)`. `None` for fewer than 4 keys.
pub fn squad_keys(keys: &[RotationKey]) -> Option<Vec<(DQuat, DQuat, DQuat)>> {
    let n = keys.len();
    if n < 4 {
        return None;
    }
    let mut q: Vec<DQuat> = keys.iter().map(key_quaternion).collect();
    let mut a = vec![DQuat::IDENTITY; n];
    let mut b = vec![DQuat::IDENTITY; n];
    for j in 0..n - 3 {
        if q[j + 1].dot(q[j + 2]) < 0.0 {
            q[j + 2] = -q[j + 2];
        }
        let (q0, q1, q2, q3) = (q[j], q[j + 1], q[j + 2], q[j + 3]);
        let t = [0, 1, 2, 3].map(|i| keys[j + i].time as f64);
        let ((out0, out1), (in0, in1)) = kb_weights(t, keys[j + 1].tcb, keys[j + 2].tcb);
        let l = quat_log(q1.inverse() * q2);
        let tout = out1 * l + out0 * quat_log(q0.inverse() * q1);
        let tin = in0 * l + in1 * quat_log(q2.inverse() * q3);
        a[j + 1] = q1 * quat_exp(0.5 * (tout - l));
        b[j + 2] = q2 * quat_exp(0.5 * (l - tin));
    }
    // The first channel key has no incoming segment and the last no outgoing one: their
    // unused controls are the keys themselves.
    b[1] = q[1];
    a[n - 2] = q[n - 2];
    Some((1..n - 1).map(|k| (b[k], q[k], a[k])).collect())
}

/// Converts a `rot` track (n >= 4 keys) into a SQUAD rotation channel on `node`.
pub fn rotation_channel(keys: &[RotationKey], node: usize) -> Option<ChannelDesc> {
    let controls = squad_keys(keys)?;
    let mut values = Vec::with_capacity(controls.len() * 12);
    for (b, q, a) in controls {
        for x in [b, q, a] {
            values.extend_from_slice(&x.as_quat().to_array());
        }
    }
    Some(ChannelDesc {
        node,
        target: ChannelTarget::Rotation,
        interpolation: Interpolation::Squad,
        times: keys[1..keys.len() - 1].iter().map(|k| k.time).collect(),
        values,
        components: 4,
    })
}
