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

/// The part of segment j (keys j..j+3, curve from key j+1 to key j+2) the reference ever
/// evaluates: times `[lo, hi)`, curve parameters `[u0, u1]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentUse {
    pub segment: usize,
    pub lo: f64,
    pub hi: f64,
    pub u0: f64,
    pub u1: f64,
}

/// Which segments the reference evaluates, and where: for `t` inside `(t_1, t_n-2)` it takes
/// the first segment j with `t < t_j+2`, so segment j is used on
/// `[max(t_j+1, max_{i<j} t_i+2), t_j+2)` (clipped to the valid range). With increasing
/// times that is `[t_j+1, t_j+2)` and zero-length segments are never used. Times that go
/// back (Robots' `gun_rot` tracks restart at 42 after 48) make later segments start where
/// the earlier ones end, possibly part-way (`u0 > 0`).
pub fn segment_uses(times: &[f32]) -> Vec<SegmentUse> {
    let n = times.len();
    if n < 4 {
        return Vec::new();
    }
    let t = |i: usize| times[i] as f64;
    let (first, last) = (t(1), t(n - 2));
    let mut reached = first;
    let mut uses = Vec::new();
    for j in 0..n - 3 {
        let (t1, t2) = (t(j + 1), t(j + 2));
        let lo = t1.max(reached);
        let hi = t2.min(last);
        reached = reached.max(t2);
        if hi > lo && t2 > t1 {
            let dt = t2 - t1;
            uses.push(SegmentUse {
                segment: j,
                lo,
                hi,
                u0: (lo - t1) / dt,
                u1: (hi - t1) / dt,
            });
        }
    }
    uses
}

/// Keys of a channel assembled from segment pieces: per key its time and the data of the
/// piece ending there (`end`) and of the piece starting there (`start`). A piece that
/// continues the previous one (next segment, from `u0 = 0`, same time) shares its key;
/// otherwise both keys are kept at the same time (the later one wins there: a jump).
struct KeyPlan<T> {
    times: Vec<f32>,
    /// (incoming data, value, outgoing data) per key.
    keys: Vec<(Option<T>, T, Option<T>)>,
}

impl<T: Copy> KeyPlan<T> {
    fn new() -> Self {
        KeyPlan {
            times: Vec::new(),
            keys: Vec::new(),
        }
    }

    fn push(&mut self, time: f64, incoming: Option<T>, value: T, outgoing: Option<T>) {
        self.times.push(time as f32);
        self.keys.push((incoming, value, outgoing));
    }

    /// The last key's time and value, `None` while the plan is empty.
    fn end(&self) -> Option<(f64, T)> {
        Some((*self.times.last()? as f64, self.keys.last()?.1))
    }
}

/// Converts a KB position/scale track (n >= 4 keys) into a CUBICSPLINE channel on `node`
/// (see the module docs and [`segment_uses`]). Returns `None` for fewer than 4 keys.
pub fn position_channel(
    keys: &[PositionKey],
    node: usize,
    target: ChannelTarget,
) -> Option<ChannelDesc> {
    let n = keys.len();
    if n < 4 {
        return None;
    }
    let times: Vec<f32> = keys.iter().map(|k| k.time).collect();
    let value = |i: usize| keys[i].value.as_dvec3();
    // Hermite data of segment j: P1, P2, Tout, Tin (per unit of u).
    let hermite = |j: usize| {
        let k = &keys[j..j + 4];
        let t = [0, 1, 2, 3].map(|i| k[i].time as f64);
        let p = [0, 1, 2, 3].map(|i| k[i].value.as_dvec3());
        let ((out0, out1), (in0, in1)) = kb_weights(t, k[1].tcb, k[2].tcb);
        let d = p[2] - p[1];
        let tout = out0 * (p[1] - p[0]) + out1 * d;
        let tin = in0 * d + in1 * (p[3] - p[2]);
        (p[1], p[2], tout, tin)
    };
    let eval = |(p1, p2, tout, tin): (DVec3, DVec3, DVec3, DVec3), u: f64| {
        let (u2, u3) = (u * u, u * u * u);
        let value = (2.0 * u3 - 3.0 * u2 + 1.0) * p1
            + (u3 - 2.0 * u2 + u) * tout
            + (-2.0 * u3 + 3.0 * u2) * p2
            + (u3 - u2) * tin;
        let derivative = (6.0 * u2 - 6.0 * u) * p1
            + (3.0 * u2 - 4.0 * u + 1.0) * tout
            + (-6.0 * u2 + 6.0 * u) * p2
            + (3.0 * u2 - 2.0 * u) * tin;
        (value, derivative)
    };
    let mut plan: KeyPlan<DVec3> = KeyPlan::new();
    let uses = segment_uses(&times);
    let mut previous: Option<SegmentUse> = None;
    for s in &uses {
        let h = hermite(s.segment);
        // du per second: the sampler multiplies tangents by the key interval.
        let scale = (s.u1 - s.u0) / (s.hi - s.lo);
        let (v0, d0) = eval(h, s.u0);
        let (v1, d1) = eval(h, s.u1);
        let continues = previous.is_some_and(|p| {
            p.segment + 1 == s.segment && s.u0 == 0.0 && p.u1 == 1.0 && p.hi == s.lo
        });
        match plan.keys.last_mut() {
            Some(last) if continues => last.2 = Some(d0 * scale),
            _ => plan.push(s.lo, None, v0, Some(d0 * scale)),
        }
        plan.push(s.hi, Some(d1 * scale), v1, None);
        previous = Some(*s);
    }
    // Clamp values: t <= t_1 is segment 0 at u = 0, t >= t_n-2 the last segment at u = 1.
    let first = (times[1] as f64, value(1));
    let last = (times[n - 2] as f64, value(n - 2));
    match plan.end() {
        None => {
            plan.push(first.0, None, first.1, None);
            if last.0 > first.0 || last.1 != first.1 {
                plan.push(last.0.max(first.0), None, last.1, None);
            }
        }
        Some((end_t, end_v)) => {
            if plan.times[0] as f64 != first.0 || plan.keys[0].1 != first.1 {
                plan.times.insert(0, first.0 as f32);
                plan.keys.insert(0, (None, first.1, None));
            }
            if end_t != last.0 || end_v != last.1 {
                plan.push(last.0.max(end_t), None, last.1, None);
            }
        }
    }
    let mut values = Vec::with_capacity(plan.keys.len() * 9);
    for (incoming, v, outgoing) in &plan.keys {
        for x in [
            incoming.unwrap_or(DVec3::ZERO),
            *v,
            outgoing.unwrap_or(DVec3::ZERO),
        ] {
            values.extend_from_slice(&x.as_vec3().to_array());
        }
    }
    Some(ChannelDesc {
        node,
        target,
        interpolation: Interpolation::CubicSpline,
        times: plan.times,
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

/// Per segment, after the reference's hemisphere alignment (written back to the keys, so
/// later segments see flipped keys): `(q1, q2, a, b)`, the squad of key j+1 to key j+2.
/// Empty for fewer than 4 keys.
pub fn squad_segments(keys: &[RotationKey]) -> Vec<(DQuat, DQuat, DQuat, DQuat)> {
    let n = keys.len();
    if n < 4 {
        return Vec::new();
    }
    let mut q: Vec<DQuat> = keys.iter().map(key_quaternion).collect();
    let mut segments = Vec::with_capacity(n - 3);
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
        let a = q1 * quat_exp(0.5 * (tout - l));
        let b = q2 * quat_exp(0.5 * (l - tin));
        segments.push((q1, q2, a, b));
    }
    segments
}

/// Converts a `rot` track (n >= 4 keys) into a SQUAD rotation channel on `node`. Returns the
/// channel and whether a segment had to be approximated (the reference enters it part-way
/// because earlier keys have later times; squad pieces cannot be cut exactly, so such a
/// piece is played in full over its time range; the BART data has none).
pub fn rotation_channel(keys: &[RotationKey], node: usize) -> Option<(ChannelDesc, bool)> {
    let segments = squad_segments(keys);
    if segments.is_empty() {
        return None;
    }
    let n = keys.len();
    let times: Vec<f32> = keys.iter().map(|k| k.time).collect();
    let mut plan: KeyPlan<DQuat> = KeyPlan::new();
    let mut approximated = false;
    let mut previous: Option<SegmentUse> = None;
    for s in segment_uses(&times) {
        let (q1, q2, a, b) = segments[s.segment];
        approximated |= s.u0 != 0.0 || s.u1 != 1.0;
        let continues = previous.is_some_and(|p| p.segment + 1 == s.segment && p.hi == s.lo);
        match plan.keys.last_mut() {
            Some(last) if continues && s.u0 == 0.0 => last.2 = Some(a),
            _ => plan.push(s.lo, None, q1, Some(a)),
        }
        plan.push(s.hi, Some(b), q2, None);
        previous = Some(s);
    }
    let first_q = segments[0].0;
    let last_q = segments[segments.len() - 1].1;
    let (first_t, last_t) = (times[1] as f64, times[n - 2] as f64);
    match plan.end() {
        None => {
            plan.push(first_t, None, first_q, None);
            plan.push(last_t.max(first_t), None, last_q, None);
        }
        Some((end, end_q)) => {
            if plan.times[0] as f64 != first_t || plan.keys[0].1 != first_q {
                plan.times.insert(0, first_t as f32);
                plan.keys.insert(0, (None, first_q, None));
            }
            if end != last_t || end_q != last_q {
                plan.push(last_t.max(end), None, last_q, None);
            }
        }
    }
    let mut values = Vec::with_capacity(plan.keys.len() * 12);
    for (incoming, q, outgoing) in &plan.keys {
        for x in [incoming.unwrap_or(*q), *q, outgoing.unwrap_or(*q)] {
            values.extend_from_slice(&x.as_quat().to_array());
        }
    }
    let channel = ChannelDesc {
        node,
        target: ChannelTarget::Rotation,
        interpolation: Interpolation::Squad,
        times: plan.times,
        values,
        components: 4,
    };
    Some((channel, approximated))
}
