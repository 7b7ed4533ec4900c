//! `xformOpOrder` to a chain of nodes whose animation channels reproduce USD's interpolation.
//!
//! USD interpolates each op's attribute on its own (vectors and angles linearly, `orient`
//! by slerp) and then composes the ops; the frame loop interpolates a node's translation and
//! scale linearly and its rotation by slerp, then composes `T * R * S`. So each op becomes
//! pieces (a translation, a rotation about one axis or by a quaternion, a scale, or a fixed
//! matrix), and consecutive pieces are packed into one node while they come in `T, R, S`
//! order; the next piece starts a child node. Composing the chain is then USD's product, and
//! each channel interpolates exactly as USD interpolates the attribute:
//! - a single-axis angle interpolated linearly is a slerp between the two keys' rotations
//!   as long as they differ by less than half a turn; keys further apart get keys inserted
//!   (at most 90 degrees apart), which slerp exactly along the same line;
//! - `rotateXYZ` and its five siblings are three single-axis pieces (X applied first);
//! - `!invert!` inverts each piece and reverses their order; an inverted animated scale is
//!   exact at its samples only (USD interpolates the scale, then inverts);
//! - an animated `transform` (a 4x4 matrix, which USD interpolates entry by entry) becomes
//!   a translation, rotation and scale per sample: exact at the samples, a note says so.
//!
//! A rigid move therefore stays a rotation and translation of the shape the frame loop
//! tracks (`anim::node_shapes`): no `log2 P_b` is recomputed for it.

use glam::{DMat4, DQuat, DVec3, Mat4, Quat, Vec3};
use openusd::usd::Prim;

use super::values::{Reader, attr_path, dmat4, dquat, dvec3, scalar, tokens};
use crate::scene::{ChannelTarget, Trs};

/// The sentinel that makes a prim ignore its parents' transforms.
const RESET_XFORM_STACK: &str = "!resetXformStack!";
/// Prefix of an inverted op in `xformOpOrder`.
const INVERT: &str = "!invert!";
/// Largest angle between two keys of a single-axis rotation channel (degrees).
const MAX_KEY_ANGLE: f64 = 90.0;

/// A prim's local transform as nodes, outermost first (the prim's own node is the last).
#[derive(Debug, Default)]
pub(super) struct Chain {
    /// `!resetXformStack!`: the chain hangs from the stage root, not from the parent.
    pub resets: bool,
    pub nodes: Vec<ChainNode>,
}

/// One node of a chain: rest transform plus the channels animating it.
#[derive(Debug, Default, Clone)]
pub(super) struct ChainNode {
    pub local: Trs,
    pub matrix: Option<Mat4>,
    pub tracks: Vec<Track>,
    /// Which of T, R, S hold something (packing state).
    last_slot: Option<u8>,
}

/// One channel of a chain node (times in seconds).
#[derive(Debug, Clone)]
pub(super) struct Track {
    pub target: ChannelTarget,
    pub times: Vec<f32>,
    pub values: Vec<f32>,
    pub components: usize,
}

/// A value, or keys of it.
#[derive(Debug, Clone)]
enum Keyed<T> {
    Fixed(T),
    Keys(Vec<f32>, Vec<T>),
}

impl<T: Copy> Keyed<T> {
    fn map(&self, f: impl Fn(T) -> T) -> Keyed<T> {
        match self {
            Keyed::Fixed(v) => Keyed::Fixed(f(*v)),
            Keyed::Keys(t, v) => Keyed::Keys(t.clone(), v.iter().map(|&x| f(x)).collect()),
        }
    }
    fn first(&self) -> T {
        match self {
            Keyed::Fixed(v) => *v,
            Keyed::Keys(_, v) => v[0],
        }
    }
}

/// One elementary transform.
#[derive(Debug, Clone)]
enum Piece {
    Translate(Keyed<DVec3>),
    Rotate(Keyed<DQuat>),
    Scale(Keyed<DVec3>),
    Matrix(DMat4),
}

/// The prim's `xformOpOrder` as a chain of nodes (empty when it has none).
///
/// # Errors
/// An op with a value of the wrong type or a non-finite value, a singular op under
/// `!invert!`, `!resetXformStack!` anywhere but first; each names the attribute.
pub(super) fn chain(
    reader: &Reader,
    prim: &Prim,
    notes: &mut Vec<String>,
) -> Result<Chain, String> {
    let Some(order) = reader.default_value(prim, "xformOpOrder")? else {
        return Ok(Chain::default());
    };
    let order = tokens(&order).ok_or_else(|| {
        format!(
            "{}: expected a token array",
            attr_path(prim, "xformOpOrder")
        )
    })?;
    let mut chain = Chain::default();
    let mut pieces = Vec::new();
    for (i, op) in order.iter().enumerate() {
        if op == RESET_XFORM_STACK {
            if i != 0 {
                return Err(format!(
                    "{}: {RESET_XFORM_STACK} must come first, found at position {i}",
                    attr_path(prim, "xformOpOrder")
                ));
            }
            chain.resets = true;
            continue;
        }
        pieces.extend(op_pieces(reader, prim, op, notes)?);
    }
    chain.nodes = pack(&pieces);
    Ok(chain)
}

/// The pieces of one op, outermost first.
fn op_pieces(
    reader: &Reader,
    prim: &Prim,
    op: &str,
    notes: &mut Vec<String>,
) -> Result<Vec<Piece>, String> {
    let (inverted, name) = match op.strip_prefix(INVERT) {
        Some(name) => (true, name),
        None => (false, op),
    };
    let what = attr_path(prim, name);
    let Some(kind) = name
        .strip_prefix("xformOp:")
        .map(|k| k.split(':').next().unwrap_or(k))
    else {
        return Err(format!(
            "{what}: not an xformOp (xformOpOrder entries start with xformOp:)"
        ));
    };
    if !super::values::is_property_name(name) {
        return Err(format!(
            "{}: entry '{}' is not a property name (identifiers joined by ':')",
            attr_path(prim, "xformOpOrder"),
            op.escape_debug()
        ));
    }
    let samples = reader.samples(prim, name)?;
    let values: Vec<openusd::sdf::Value> = if samples.times.is_empty() {
        match reader.default_value(prim, name)? {
            Some(v) => vec![v],
            None => {
                notes.push(format!(
                    "{what} is listed in xformOpOrder but has no value; ignored"
                ));
                return Ok(Vec::new());
            }
        }
    } else {
        samples.values
    };
    let times = samples.times;
    fn keyed<T>(times: &[f32], vals: Vec<T>) -> Keyed<T> {
        if times.is_empty() {
            Keyed::Fixed(vals.into_iter().next().expect("one value"))
        } else {
            Keyed::Keys(times.to_vec(), vals)
        }
    }
    let bad = |v: &openusd::sdf::Value| {
        format!(
            "{what}: unexpected {} value for a {kind} op",
            super::values::kind(v)
        )
    };
    let finite3 = |v: DVec3| {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(format!("{what}: non-finite value {v}"))
        }
    };
    let vec3s = || -> Result<Vec<DVec3>, String> {
        values
            .iter()
            .map(|v| dvec3(v).ok_or_else(|| bad(v)).and_then(finite3))
            .collect()
    };
    let scalars = || -> Result<Vec<f64>, String> {
        values
            .iter()
            .map(|v| {
                let x = scalar(v).ok_or_else(|| bad(v))?;
                if x.is_finite() {
                    Ok(x)
                } else {
                    Err(format!("{what}: non-finite value {x}"))
                }
            })
            .collect()
    };
    let axis_of = |c: u8| match c {
        b'X' => DVec3::X,
        b'Y' => DVec3::Y,
        _ => DVec3::Z,
    };
    let component = |c: u8, x: f64, rest: f64| {
        let mut v = DVec3::splat(rest);
        v[(c - b'X') as usize] = x;
        v
    };
    let mut pieces = match kind {
        "translate" => vec![Piece::Translate(keyed(&times, vec3s()?))],
        "scale" => vec![Piece::Scale(keyed(&times, vec3s()?))],
        "translateX" | "translateY" | "translateZ" => {
            let c = kind.as_bytes()[9];
            vec![Piece::Translate(keyed(
                &times,
                scalars()?
                    .into_iter()
                    .map(|x| component(c, x, 0.0))
                    .collect(),
            ))]
        }
        "scaleX" | "scaleY" | "scaleZ" => {
            let c = kind.as_bytes()[5];
            vec![Piece::Scale(keyed(
                &times,
                scalars()?
                    .into_iter()
                    .map(|x| component(c, x, 1.0))
                    .collect(),
            ))]
        }
        "rotateX" | "rotateY" | "rotateZ" => {
            let axis = axis_of(kind.as_bytes()[6]);
            vec![axis_rotation(axis, &times, &scalars()?)]
        }
        "rotateXYZ" | "rotateXZY" | "rotateYXZ" | "rotateYZX" | "rotateZXY" | "rotateZYX" => {
            let angles = vec3s()?;
            // The first letter is applied first, so it is the innermost piece.
            kind.as_bytes()[6..9]
                .iter()
                .rev()
                .map(|&c| {
                    let i = (c - b'X') as usize;
                    let per_key: Vec<f64> = angles.iter().map(|a| a[i]).collect();
                    axis_rotation(axis_of(c), &times, &per_key)
                })
                .collect()
        }
        "orient" => {
            let quats = values
                .iter()
                .map(|v| {
                    let q = dquat(v).ok_or_else(|| bad(v))?;
                    let length = q.length();
                    if !(length.is_finite() && length > 1e-12) {
                        return Err(format!("{what}: invalid quaternion {q}"));
                    }
                    Ok(q / length)
                })
                .collect::<Result<Vec<_>, String>>()?;
            vec![Piece::Rotate(keyed(&times, quats))]
        }
        "transform" => {
            let matrices = values
                .iter()
                .map(|v| {
                    let m = dmat4(v).ok_or_else(|| bad(v))?;
                    if m.is_finite() {
                        Ok(m)
                    } else {
                        Err(format!("{what}: non-finite matrix"))
                    }
                })
                .collect::<Result<Vec<_>, String>>()?;
            if times.is_empty() {
                vec![Piece::Matrix(matrices[0])]
            } else {
                notes.push(format!(
                    "{what} is a time-sampled matrix: played as translation, rotation and scale keys (exact at its samples; USD interpolates the matrix entries, and any shear is dropped)"
                ));
                decomposed_keys(&times, &matrices)
            }
        }
        other => {
            return Err(format!("{what}: unknown xformOp kind '{other}'"));
        }
    };
    if inverted {
        let animated_scale = pieces
            .iter()
            .any(|p| matches!(p, Piece::Scale(Keyed::Keys(..))));
        if animated_scale {
            notes.push(format!(
                "{what} is an inverted animated scale: exact at its samples, interpolated as a scale between them"
            ));
        }
        pieces = pieces
            .iter()
            .rev()
            .map(|p| invert(p, &what))
            .collect::<Result<Vec<_>, String>>()?;
    }
    Ok(pieces)
}

/// A rotation about a fixed axis by `degrees` per key (one fixed value when `times` is
/// empty), keys inserted so that neighbours are at most [`MAX_KEY_ANGLE`] apart.
fn axis_rotation(axis: DVec3, times: &[f32], degrees: &[f64]) -> Piece {
    let quat = |deg: f64| DQuat::from_axis_angle(axis, deg.to_radians());
    if times.is_empty() {
        return Piece::Rotate(Keyed::Fixed(quat(degrees[0])));
    }
    let (mut out_times, mut out) = (Vec::new(), Vec::new());
    for k in 0..times.len() {
        if k > 0 {
            let (a, b) = (degrees[k - 1], degrees[k]);
            let steps = ((b - a).abs() / MAX_KEY_ANGLE).ceil().min(1e5) as usize;
            let (t0, t1) = (times[k - 1] as f64, times[k] as f64);
            for j in 1..steps {
                let u = j as f64 / steps as f64;
                let t = (t0 + (t1 - t0) * u) as f32;
                if t > *out_times.last().unwrap_or(&f32::NEG_INFINITY) && t < times[k] {
                    out_times.push(t);
                    out.push(quat(a + (b - a) * u));
                }
            }
        }
        out_times.push(times[k]);
        out.push(quat(degrees[k]));
    }
    Piece::Rotate(Keyed::Keys(out_times, out))
}

/// Translation, rotation and scale keys of time-sampled matrices.
fn decomposed_keys(times: &[f32], matrices: &[DMat4]) -> Vec<Piece> {
    let (mut t, mut r, mut s) = (Vec::new(), Vec::new(), Vec::new());
    for m in matrices {
        let (scale, rotation, translation) = m.to_scale_rotation_translation();
        let ok = scale.is_finite() && rotation.is_finite() && rotation.length() > 0.5;
        t.push(translation);
        r.push(if ok {
            rotation.normalize()
        } else {
            DQuat::IDENTITY
        });
        s.push(if scale.is_finite() {
            scale
        } else {
            DVec3::ZERO
        });
    }
    vec![
        Piece::Translate(Keyed::Keys(times.to_vec(), t)),
        Piece::Rotate(Keyed::Keys(times.to_vec(), r)),
        Piece::Scale(Keyed::Keys(times.to_vec(), s)),
    ]
}

/// The inverse of one piece.
fn invert(piece: &Piece, what: &str) -> Result<Piece, String> {
    Ok(match piece {
        Piece::Translate(k) => Piece::Translate(k.map(|v| -v)),
        Piece::Rotate(k) => Piece::Rotate(k.map(|q| q.conjugate())),
        Piece::Scale(k) => {
            let singular = match k {
                Keyed::Fixed(v) => v.min_element().abs() == 0.0 || v.x * v.y * v.z == 0.0,
                Keyed::Keys(_, vs) => vs.iter().any(|v| v.x * v.y * v.z == 0.0),
            };
            if singular {
                return Err(format!("{what}: cannot invert a scale with a zero factor"));
            }
            Piece::Scale(k.map(|v| DVec3::ONE / v))
        }
        Piece::Matrix(m) => {
            let det = m.determinant();
            let inverse = m.inverse();
            if det == 0.0 || !inverse.is_finite() {
                return Err(format!("{what}: cannot invert a singular matrix"));
            }
            Piece::Matrix(inverse)
        }
    })
}

/// Packs pieces (outermost first) into nodes: `T, R, S` in that order share a node, a fixed
/// matrix has a node of its own.
fn pack(pieces: &[Piece]) -> Vec<ChainNode> {
    let mut nodes: Vec<ChainNode> = Vec::new();
    for piece in pieces {
        let slot = match piece {
            Piece::Translate(_) => 0,
            Piece::Rotate(_) => 1,
            Piece::Scale(_) => 2,
            Piece::Matrix(_) => 3,
        };
        let fits = nodes.last().is_some_and(|n| {
            n.matrix.is_none() && slot < 3 && n.last_slot.is_none_or(|last| slot > last)
        });
        if !fits {
            nodes.push(ChainNode::default());
        }
        let node = nodes.last_mut().expect("pushed above");
        node.last_slot = Some(slot);
        match piece {
            Piece::Translate(k) => {
                node.local.translation = k.first().as_vec3();
                push_track(node, ChannelTarget::Translation, k, |v| {
                    v.as_vec3().to_array().to_vec()
                });
            }
            Piece::Scale(k) => {
                node.local.scale = k.first().as_vec3();
                push_track(node, ChannelTarget::Scale, k, |v| {
                    v.as_vec3().to_array().to_vec()
                });
            }
            Piece::Rotate(k) => {
                node.local.rotation = to_quat(k.first());
                push_track(node, ChannelTarget::Rotation, k, |q| {
                    to_quat(q).to_array().to_vec()
                });
            }
            Piece::Matrix(m) => {
                let matrix = m.as_mat4();
                node.matrix = Some(matrix);
                node.local = decompose(&matrix);
            }
        }
    }
    nodes
}

fn push_track<T: Copy>(
    node: &mut ChainNode,
    target: ChannelTarget,
    keyed: &Keyed<T>,
    flat: impl Fn(T) -> Vec<f32>,
) {
    if let Keyed::Keys(times, values) = keyed {
        let values: Vec<f32> = values.iter().flat_map(|&v| flat(v)).collect();
        let components = values.len() / times.len().max(1);
        node.tracks.push(Track {
            target,
            times: times.clone(),
            values,
            components,
        });
    }
}

fn to_quat(q: DQuat) -> Quat {
    let q = q.as_quat().normalize();
    if q.is_finite() { q } else { Quat::IDENTITY }
}

/// TRS of a matrix (kept beside the exact matrix); a singular matrix keeps no rotation.
pub(super) fn decompose(matrix: &Mat4) -> Trs {
    let (scale, rotation, translation) = matrix.to_scale_rotation_translation();
    let rotation = if rotation.is_finite() && rotation.length() > 0.5 {
        rotation.normalize()
    } else {
        Quat::IDENTITY
    };
    Trs {
        translation,
        rotation,
        scale: if scale.is_finite() { scale } else { Vec3::ZERO },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn product(nodes: &[ChainNode]) -> Mat4 {
        nodes.iter().fold(Mat4::IDENTITY, |m, n| {
            m * n.matrix.unwrap_or_else(|| n.local.to_mat4())
        })
    }

    #[test]
    fn trs_in_order_shares_a_node_and_out_of_order_starts_another() {
        let t = Piece::Translate(Keyed::Fixed(DVec3::new(1.0, 2.0, 3.0)));
        let r = Piece::Rotate(Keyed::Fixed(DQuat::from_rotation_z(0.5)));
        let s = Piece::Scale(Keyed::Fixed(DVec3::new(2.0, 3.0, 4.0)));
        assert_eq!(pack(&[t.clone(), r.clone(), s.clone()]).len(), 1);
        let nodes = pack(&[s.clone(), t.clone(), r.clone()]);
        assert_eq!(nodes.len(), 2);
        let expected = Mat4::from_scale(Vec3::new(2.0, 3.0, 4.0))
            * Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0))
            * Mat4::from_rotation_z(0.5);
        assert!(product(&nodes).abs_diff_eq(expected, 1e-5));
    }

    #[test]
    fn large_angle_steps_get_keys_that_slerp_along_the_same_axis() {
        let Piece::Rotate(Keyed::Keys(times, quats)) =
            axis_rotation(DVec3::Y, &[0.0, 1.0], &[0.0, 360.0])
        else {
            panic!("keys expected");
        };
        assert_eq!(times.len(), 5);
        for (t, q) in times.iter().zip(&quats) {
            let expected = DQuat::from_rotation_y((360.0 * *t as f64).to_radians());
            assert!(q.dot(expected).abs() > 1.0 - 1e-9, "{t}: {q} vs {expected}");
        }
    }

    #[test]
    fn inverted_pieces_undo_the_op() {
        let pieces = vec![
            Piece::Translate(Keyed::Fixed(DVec3::new(1.0, -2.0, 0.5))),
            Piece::Rotate(Keyed::Fixed(DQuat::from_rotation_x(0.3))),
            Piece::Scale(Keyed::Fixed(DVec3::new(2.0, 4.0, 0.5))),
        ];
        let inverse: Vec<Piece> = pieces
            .iter()
            .rev()
            .map(|p| invert(p, "x").unwrap())
            .collect();
        let mut all = pieces.clone();
        all.extend(inverse);
        assert!(product(&pack(&all)).abs_diff_eq(Mat4::IDENTITY, 1e-5));
        assert!(invert(&Piece::Scale(Keyed::Fixed(DVec3::new(1.0, 0.0, 1.0))), "x").is_err());
        assert!(invert(&Piece::Matrix(DMat4::ZERO), "x").is_err());
    }
}
