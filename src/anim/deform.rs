//! Vertex deformation: morph targets, then linear blend skinning (glTF 2.0 §3.7.2.2 Morph
//! Targets, §3.7.3 Skins).
//!
//! For a vertex with base position `p`, base normal `n`, morph weights `w_i` and deltas
//! `dp_i`, `dn_i`:
//! - morph: `p' = p + sum_i w_i dp_i`, `n' = normalize(n + sum_i w_i dn_i)` (the base
//!   normal when that sum is zero);
//! - skin: `M = sum_k weight_k * joint_matrix[joint_k]` over the vertex's four influences,
//!   `p'' = M p'` in world space (glTF: the skinned node's own transform is ignored, the
//!   joints place the mesh), `n'' = normalize(cofactor(M3) n')` where `M3` is the upper 3x3
//!   of `M` and `cofactor(M3) = det(M3) M3^-T` — the exact inverse transpose up to a positive
//!   scale once multiplied by `sign(det)`, so it is right for any invertible blend (shears and
//!   non-uniform scales included), costs three cross products, and needs no division.
//!
//! A point-cache primitive (`PrimitiveDesc::point_cache`) instead takes its vertices from
//! the two cache samples around the cache position its node's one morph weight holds, a
//! vertex equal in both samples copied unchanged (`sample_point_cache`); nothing else applies.
//!
//! Weights are used as given (glTF requires them to sum to 1; they are not renormalised).
//! Fallbacks that keep every output finite, given the loader's finite inputs:
//! - skin weights summing to 0: the vertex stays rigidly attached to its node,
//!   `world_from_node * p'` (as if unskinned);
//! - a non-finite blended matrix (a joint matrix overflowed; see
//!   [`Pose::nonfinite_joint`](super::Pose::nonfinite_joint)) or a non-finite skinned
//!   position: the same rigid placement; if that is not finite either, `p'` itself;
//! - a morphed position that overflows: the base position;
//! - a normal that comes out zero or non-finite: the previous stage's normal (morph: the
//!   base normal; skin: `normalize(M3 n')`, else `n'` unchanged).
//!
//! Every vertex is computed with a fixed summation order (targets in file order, influences
//! in slot order) from its own inputs only, so results are bit-identical across calls and
//! thread counts: skinning of large meshes runs in vertex chunks on rayon's threads.

use glam::{Mat3A, Mat4, Vec3, Vec3A, Vec4};
use rayon::prelude::*;

use super::Pose;
use crate::scene::{PrimitiveDesc, SceneDesc};
use crate::simd;

/// The space `deform_primitive` wrote its vertices in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VertexSpace {
    /// The node's object space: the caller applies `world_from_node` (morph-only and
    /// rigid primitives).
    Object,
    /// World space (skinned primitives): the caller applies nothing.
    World,
}

/// Whether the primitive drawn by `node` needs [`deform_primitive`] for its geometry: it is
/// skinned (the node has a skin and the primitive has joints), or it has morph targets (even
/// with all-zero or static weights: the loader no longer bakes default weights into the base
/// positions). Otherwise its base positions, placed by `world_from_node`, are its geometry
/// at every time. The answer does not depend on time.
///
/// # Panics
/// If `node`, `mesh` or `primitive` is out of range.
pub fn primitive_deforms(scene: &SceneDesc, node: usize, mesh: usize, primitive: usize) -> bool {
    let desc = &scene.meshes[mesh].primitives[primitive];
    !desc.morph_targets.is_empty()
        || desc.point_cache.is_some()
        || skin_of(scene, node, desc).is_some()
}

/// Writes the primitive's vertices for `pose` into `positions` and `normals` (cleared first;
/// `normals` stays empty when the primitive has no normals) and returns their space:
/// [`VertexSpace::World`] when skinned, else [`VertexSpace::Object`]. Morph targets use
/// `pose.morph_weights[node]`; skinning uses the joint matrices of the node's skin. Normals
/// are unit length (zero where one degenerates). A primitive that does not deform comes out
/// as its base geometry in object space.
///
/// Pure function of its inputs; every output is finite (see the module docs for the
/// fallbacks). `pose` must have been evaluated for `scene`.
///
/// # Panics
/// If `node`, `mesh` or `primitive` is out of range, or `pose` is for another scene.
pub fn deform_primitive(
    scene: &SceneDesc,
    pose: &Pose,
    node: usize,
    mesh: usize,
    primitive: usize,
    positions: &mut Vec<Vec3>,
    normals: &mut Vec<Vec3>,
) -> VertexSpace {
    let desc = &scene.meshes[mesh].primitives[primitive];
    let morph_weights = &pose.morph_weights[node];
    let morphs = desc
        .morph_targets
        .iter()
        .zip(morph_weights)
        .any(|(t, &w)| w != 0.0 && (t.positions.is_some() || t.normals.is_some()));
    let skinned = skin_of(scene, node, desc).map(|(skin, influences)| {
        let skinning = Skinning {
            joint_matrices: &pose.joint_matrices[skin],
            world_from_node: pose.world_from_node[node],
        };
        (skinning, influences)
    });
    if let Some(cache) = &desc.point_cache {
        let position = morph_weights.first().copied().unwrap_or(0.0);
        sample_point_cache(desc, cache, position, positions, normals);
        return VertexSpace::Object;
    }
    if let (Some((skinning, influences)), false) = (&skinned, morphs) {
        // Skinned straight from the rest vertices: no copy of them first, and no morph pass
        // that would change nothing (two passes over every vertex, a third of the time).
        positions.resize(desc.positions.len(), Vec3::ZERO);
        let rest_normals = desc.normals.as_deref().unwrap_or_default();
        normals.resize(rest_normals.len(), Vec3::ZERO);
        skinning.apply(
            *influences,
            Some((&desc.positions, rest_normals)),
            positions,
            normals,
        );
        return VertexSpace::World;
    }
    positions.clear();
    positions.extend_from_slice(&desc.positions);
    normals.clear();
    if let Some(base) = &desc.normals {
        normals.extend_from_slice(base);
    }
    apply_morph(desc, morph_weights, positions, normals);
    match skinned {
        Some((skinning, influences)) => {
            skinning.apply(influences, None, positions, normals);
            VertexSpace::World
        }
        None => VertexSpace::Object,
    }
}

/// The point cache's vertices at cache position `s` (module docs of
/// [`PointCacheDesc`](crate::scene::PointCacheDesc)): sample `k = floor(s)` blended towards
/// sample `k + 1` by `u = s - k`, a vertex equal in both samples copied from sample `k`
/// unchanged (so its bits do not depend on `u`). `s` is clamped to the samples (NaN: 0). A
/// blend that overflows keeps sample `k`'s vertex; a normal that degenerates, sample `k`'s.
/// A cache whose samples do not match the primitive (not from a loader) gives the base
/// vertices.
fn sample_point_cache(
    desc: &PrimitiveDesc,
    cache: &crate::scene::PointCacheDesc,
    s: f32,
    positions: &mut Vec<Vec3>,
    normals: &mut Vec<Vec3>,
) {
    positions.clear();
    normals.clear();
    let count = desc.positions.len();
    let last = cache.positions.len().saturating_sub(1);
    let s = if s.is_nan() {
        0.0
    } else {
        s.clamp(0.0, last as f32)
    };
    let k = (s.floor() as usize).min(last);
    let u = s - k as f32;
    fn sample(samples: &[Vec<Vec3>], i: usize, count: usize) -> Option<&[Vec3]> {
        samples
            .get(i)
            .map(Vec::as_slice)
            .filter(|v| v.len() == count)
    }
    let (Some(a), b) = (
        sample(&cache.positions, k, count),
        sample(&cache.positions, k + 1, count).filter(|_| u > 0.0),
    ) else {
        positions.extend_from_slice(&desc.positions);
        normals.extend_from_slice(desc.normals.as_deref().unwrap_or_default());
        return;
    };
    match b {
        None => positions.extend_from_slice(a),
        Some(b) => positions.extend(a.iter().zip(b).map(|(&a, &b)| {
            let p = a + (b - a) * u;
            if a == b || !p.is_finite() { a } else { p }
        })),
    }
    let Some(base) = &desc.normals else { return };
    let cached = cache.normals.as_deref().and_then(|n| {
        let a = sample(n, k, count)?;
        Some((a, sample(n, k + 1, count).filter(|_| u > 0.0)))
    });
    match cached {
        None => normals.extend_from_slice(base),
        Some((a, None)) => normals.extend_from_slice(a),
        Some((a, Some(b))) => normals.extend(a.iter().zip(b).map(|(&a, &b)| {
            if a == b {
                a
            } else {
                (a + (b - a) * u).try_normalize().unwrap_or(a)
            }
        })),
    }
}

/// A skinned primitive's per-vertex joint indices and weights.
#[derive(Clone, Copy)]
struct Influences<'a> {
    joints: &'a [[u16; 4]],
    weights: &'a [[f32; 4]],
}

/// The node's skin index and the primitive's influences, when the primitive is skinned.
fn skin_of<'a>(
    scene: &SceneDesc,
    node: usize,
    primitive: &'a PrimitiveDesc,
) -> Option<(usize, Influences<'a>)> {
    let skin = scene.nodes[node].skin.filter(|&s| s < scene.skins.len())?;
    match (&primitive.joints, &primitive.weights) {
        (Some(joints), Some(weights)) => Some((skin, Influences { joints, weights })),
        _ => None,
    }
}

/// Adds the weighted morph deltas, then renormalises the normals.
fn apply_morph(
    primitive: &PrimitiveDesc,
    weights: &[f32],
    positions: &mut [Vec3],
    normals: &mut [Vec3],
) {
    let mut moved = false;
    for (target, &w) in primitive.morph_targets.iter().zip(weights) {
        if w == 0.0 {
            continue;
        }
        if let Some(deltas) = &target.positions {
            add_weighted(positions, deltas, w);
        }
        if let Some(deltas) = &target.normals {
            add_weighted(normals, deltas, w);
            moved = true;
        }
    }
    for (p, base) in positions.iter_mut().zip(&primitive.positions) {
        if !p.is_finite() {
            *p = *base;
        }
    }
    if moved && let Some(base) = &primitive.normals {
        normalize_or(normals, base);
    }
}

/// Each normal normalised, the bits of `Vec3::try_normalize`, or its `base` entry where
/// that fails (pairs past the shorter slice are left alone). The reciprocal lengths are
/// taken a block at a time in one loop the compiler puts in vectors, as skinning's are
/// ([`SkinRange`]).
fn normalize_or(normals: &mut [Vec3], base: &[Vec3]) {
    let mut rcp = [0f32; NORMAL_BLOCK];
    for (block, base) in normals
        .chunks_mut(NORMAL_BLOCK)
        .zip(base.chunks(NORMAL_BLOCK))
    {
        for (r, n) in rcp.iter_mut().zip(block.iter()) {
            *r = length_recip(n.x, n.y, n.z);
        }
        for ((n, base), &r) in block.iter_mut().zip(base).zip(&rcp) {
            *n = if scales_to_unit(r) { *n * r } else { *base };
        }
    }
}

fn add_weighted(values: &mut [Vec3], deltas: &[Vec3], weight: f32) {
    for (value, delta) in values.iter_mut().zip(deltas) {
        *value += weight * *delta;
    }
}

/// What linear blend skinning of one primitive reads from the pose.
struct Skinning<'a> {
    joint_matrices: &'a [Mat4],
    /// The skinned node's transform, used only for the rigid fallback.
    world_from_node: Mat4,
}

/// Below this many vertices skinning stays on the calling thread: a vertex takes tens of
/// ns, less than rayon's split and join of a small job.
const PARALLEL_MIN_VERTICES: usize = 8192;

/// Vertices per parallel skinning task (large enough to amortise the task, small enough
/// to balance two to a few dozen threads on a million-vertex mesh).
const SKIN_CHUNK: usize = 4096;

impl Skinning<'_> {
    /// Skins every vertex of `positions` and `normals` in place, or, with `rest` (positions
    /// and normals, the latter as many as `normals` holds), skins the rest vertices into
    /// them; past [`PARALLEL_MIN_VERTICES`] in chunks on rayon's threads. Each vertex is a
    /// pure function of its own inputs, so the split changes no bit.
    fn apply(
        &self,
        influences: Influences,
        rest: Option<(&[Vec3], &[Vec3])>,
        positions: &mut [Vec3],
        normals: &mut [Vec3],
    ) {
        let rigid_normals = cofactor(Mat3A::from_mat4(self.world_from_node));
        let skin_range = |first: usize, positions: &mut [Vec3], normals: &mut [Vec3]| {
            simd::dispatch(SkinRange {
                skinning: self,
                influences,
                rest,
                rigid_normals: &rigid_normals,
                first,
                positions,
                normals,
            })
        };
        if positions.len() < PARALLEL_MIN_VERTICES {
            skin_range(0, positions, normals);
            return;
        }
        // Normals are either one per vertex or absent (empty): split them alike or not at all.
        let chunks = positions.par_chunks_mut(SKIN_CHUNK).enumerate();
        if normals.is_empty() {
            chunks.for_each(|(c, positions)| skin_range(c * SKIN_CHUNK, positions, &mut []));
        } else {
            chunks
                .zip(normals.par_chunks_mut(SKIN_CHUNK))
                .for_each(|((c, positions), normals)| {
                    skin_range(c * SKIN_CHUNK, positions, normals)
                });
        }
    }

    /// One vertex: the blended joint matrix, or the rigid fallback (module docs).
    #[inline(always)]
    fn skin_vertex(
        &self,
        joints: &[u16; 4],
        weights: &[f32; 4],
        rigid_normals: &NormalTransform,
        position: Vec3,
        normal: Option<Vec3>,
    ) -> (Vec3, Option<Vec3>) {
        let (p, transform) = self.skin_position(joints, weights, rigid_normals, position);
        let n = match (normal, transform) {
            (Some(n), Some((normal_from_object, m))) => {
                Some(transform_normal(&normal_from_object, m, n))
            }
            (n, _) => n,
        };
        (p, n)
    }

    /// One vertex's position and the map its normal goes through (`None`: the position
    /// could not be placed and the vertex is kept as it was, normal included), so a run can
    /// transform many normals before it normalises them together ([`SkinRange`]).
    ///
    /// Written for the instruction count of a million-vertex loop: the three reasons to
    /// fall back (weights summing to zero, a non-finite blend, a non-finite position) are
    /// one test after the position is computed, the blend's finiteness is one vector test
    /// ([`all_finite`]), and the position is transformed as a `Vec3A` (the same operations
    /// as `transform_point3`, so the same bits).
    #[inline(always)]
    fn skin_position(
        &self,
        joints: &[u16; 4],
        weights: &[f32; 4],
        rigid_normals: &NormalTransform,
        position: Vec3,
    ) -> (Vec3, Option<(NormalTransform, Mat3A)>) {
        let (blended, total) = self.blend(joints, weights);
        let p = blended.transform_point3a(Vec3A::from(position));
        if total != 0.0 && all_finite(&blended) && p.is_finite() {
            let m = Mat3A::from_mat4(blended);
            return (Vec3::from(p), Some((cofactor(m), m)));
        }
        let p = self.world_from_node.transform_point3(position);
        if !p.is_finite() {
            return (position, None);
        }
        let m = Mat3A::from_mat4(self.world_from_node);
        (p, Some((*rigid_normals, m)))
    }

    /// `sum_k weight_k * joint_matrix[joint_k]` and `sum_k weight_k`, over the influences of
    /// non-zero weight. Joints past the skin's end (impossible after loading) are skipped.
    #[inline(always)]
    fn blend(&self, joints: &[u16; 4], weights: &[f32; 4]) -> (Mat4, f32) {
        let mut sum = Mat4::ZERO;
        let mut total = 0.0;
        for (&j, &w) in joints.iter().zip(weights) {
            if w == 0.0 {
                continue;
            }
            let Some(m) = self.joint_matrices.get(usize::from(j)) else {
                continue;
            };
            sum += *m * w;
            total += w;
        }
        (sum, total)
    }
}

/// A run of vertices skinned as [`Skinning::skin_vertex`] skins one (positions by
/// [`Skinning::skin_position`], normals normalised a block at a time, the same bits),
/// compiled once per SIMD copy (`simd::dispatch`): the loop is the same code, but the AVX2
/// copy encodes glam's 4-wide operations with three operands, about a tenth fewer
/// instructions per vertex.
struct SkinRange<'a, 'b> {
    skinning: &'a Skinning<'a>,
    influences: Influences<'a>,
    /// Rest positions and normals to skin from, indexed from `first`; `None`: in place.
    rest: Option<(&'a [Vec3], &'a [Vec3])>,
    rigid_normals: &'a NormalTransform,
    /// The index of `positions[0]` in the primitive.
    first: usize,
    positions: &'b mut [Vec3],
    /// One per position, or empty.
    normals: &'b mut [Vec3],
}

impl simd::Kernel for SkinRange<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn run<const AVX2: bool>(self) {
        let SkinRange {
            skinning,
            influences: Influences { joints, weights },
            rest,
            rigid_normals,
            first,
            positions,
            normals,
        } = self;
        let count = positions.len();
        let range = first..first + count;
        let (joints, weights) = (&joints[range.clone()], &weights[range.clone()]);
        // The rest vertices of this run, read straight into the skinning (no copy into the
        // outputs first); in place, the outputs are the inputs.
        let rest = rest.map(|(p, n)| (&p[range.clone()], n.get(range.clone()).unwrap_or_default()));
        let input = |k: usize, positions: &[Vec3], normals: &[Vec3]| match rest {
            Some((p, n)) => (p[k], n.get(k).copied()),
            None => (positions[k], normals.get(k).copied()),
        };
        // Normals are skinned where there is one to read and a place to write it (`apply`'s
        // contract gives one per vertex or none, on both sides): the first `with_normals`
        // vertices. The others' positions alone; their normals, if any, are left alone.
        let with_normals = match rest {
            Some((_, rest_normals)) if rest_normals.len() < count => 0,
            _ => count.min(normals.len()),
        };
        for k in with_normals..count {
            let (from, _) = input(k, positions, normals);
            positions[k] = skinning
                .skin_position(&joints[k], &weights[k], rigid_normals, from)
                .0;
        }
        // Blocks of vertices: skinned, their normals transformed but not yet normalised
        // (kept side by side, axis by axis), then their lengths' reciprocals taken in one
        // loop the compiler puts in vectors, then scaled. One vertex at a time, the square
        // root and division were ~1 ms of a million-vertex mesh's skinning on two threads.
        // `unit_or_none` takes the same operations per vertex, so the bits are the same.
        let mut kept = [(Vec3::ZERO, Vec3::ZERO); NORMAL_BLOCK];
        let mut axes = [[0f32; NORMAL_BLOCK]; 3];
        let mut rcp = [0f32; NORMAL_BLOCK];
        for start in (0..with_normals).step_by(NORMAL_BLOCK) {
            let len = NORMAL_BLOCK.min(with_normals - start);
            for b in 0..len {
                let k = start + b;
                let (from, from_normal) = input(k, positions, normals);
                let normal = from_normal.unwrap_or_default();
                // The inputs, for a normal that needs the fallbacks (in place, the outputs
                // overwrite them).
                kept[b] = (from, normal);
                let (p, transform) =
                    skinning.skin_position(&joints[k], &weights[k], rigid_normals, from);
                positions[k] = p;
                // A vertex kept as it was has its normal as it was: NaN here sends it to
                // the fallback below, which gives exactly that.
                let oriented = transform.map_or(Vec3A::NAN, |(normal_from_object, _)| {
                    oriented_normal(&normal_from_object, Vec3A::from(normal))
                });
                for axis in 0..3 {
                    axes[axis][b] = oriented[axis];
                }
            }
            // All the block's entries (past `len`, the last block's are stale and unused):
            // a fixed count the compiler unrolls into vectors.
            let [x, y, z] = &axes;
            for b in 0..NORMAL_BLOCK {
                rcp[b] = length_recip(x[b], y[b], z[b]);
            }
            for b in 0..len {
                let k = start + b;
                let r = rcp[b];
                normals[k] = if scales_to_unit(r) {
                    Vec3::new(x[b] * r, y[b] * r, z[b] * r)
                } else {
                    // Rare (a degenerate map, or a vertex kept as it was): the one-vertex
                    // code again, with its fallbacks. Given a normal it returns one.
                    let (from, normal) = kept[b];
                    let (_, n) = skinning.skin_vertex(
                        &joints[k],
                        &weights[k],
                        rigid_normals,
                        from,
                        Some(normal),
                    );
                    n.unwrap_or(normal)
                };
            }
        }
    }
}

/// Vertices [`SkinRange`] skins before it normalises their normals together.
const NORMAL_BLOCK: usize = 64;

/// Whether every entry of `m` is finite, in one vector test: `x * 0` is zero for a finite
/// `x` and NaN otherwise, and a NaN survives the sums.
#[inline(always)]
fn all_finite(m: &Mat4) -> bool {
    let zeros = m.x_axis * 0.0 + m.y_axis * 0.0 + m.z_axis * 0.0 + m.w_axis * 0.0;
    zeros.cmpeq(Vec4::ZERO).all()
}

/// `v` scaled to unit length, or `None` when its length's reciprocal is not a positive
/// finite number (zero, huge or non-finite `v`): `Vec3A::try_normalize` with the test
/// written as two compares.
#[inline(always)]
fn unit_or_none(v: Vec3A) -> Option<Vec3A> {
    let rcp = v.length_recip();
    scales_to_unit(rcp).then(|| v * rcp)
}

/// `1 / |(x, y, z)|` with the operations of glam's `Vec3::length_recip` and
/// `Vec3A::length_recip`, in their order: `(x x + y y) + z z`, its square root, 1 / it (so
/// a loop over many takes them in vectors with the same bits).
#[inline(always)]
fn length_recip(x: f32, y: f32, z: f32) -> f32 {
    1.0 / ((x * x + y * y) + z * z).sqrt()
}

/// Whether a vector times its reciprocal length `rcp` is a unit vector: `rcp` is a positive
/// finite number (`try_normalize`'s test, as two compares).
#[inline(always)]
fn scales_to_unit(rcp: f32) -> bool {
    rcp > 0.0 && rcp < f32::INFINITY
}

/// A linear map's normal transform and the sign of its determinant ([`cofactor`]).
type NormalTransform = (Mat3A, f32);

/// The normal transform of a linear map `m` and its sign: `(cofactor(m), sign(det m))`,
/// where `cofactor(m) = det(m) * m^-T` has columns `c1 x c2`, `c2 x c0`, `c0 x c1`.
#[inline(always)]
fn cofactor(m: Mat3A) -> NormalTransform {
    let cofactor = Mat3A::from_cols(
        m.y_axis.cross(m.z_axis),
        m.z_axis.cross(m.x_axis),
        m.x_axis.cross(m.y_axis),
    );
    let det = m.x_axis.dot(cofactor.x_axis);
    (cofactor, if det < 0.0 { -1.0 } else { 1.0 })
}

/// `sign * cofactor * n`, the normal before it is normalised.
#[inline(always)]
fn oriented_normal(normal_from_object: &NormalTransform, n: Vec3A) -> Vec3A {
    let (cofactor, sign) = *normal_from_object;
    // The sign as a negation: `-v` is `sign * v` bit for bit, one instruction fewer.
    let transformed = cofactor * n;
    if sign < 0.0 {
        -transformed
    } else {
        transformed
    }
}

/// `normalize(sign * cofactor * n)`; when that degenerates (singular map), `normalize(m n)`;
/// failing that, `n` normalized, or zero (so skinned normals are always unit or zero, as
/// world-space normals must be: they are not placed again).
#[inline(always)]
fn transform_normal(normal_from_object: &NormalTransform, m: Mat3A, n: Vec3) -> Vec3 {
    let n = Vec3A::from(n);
    let out = unit_or_none(oriented_normal(normal_from_object, n))
        .or_else(|| unit_or_none(m * n))
        .unwrap_or_else(|| n.normalize_or_zero());
    Vec3::from(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    /// Past `PARALLEL_MIN_VERTICES` the vertex chunks run on several threads: every vertex
    /// must equal the one skinned alone, bit for bit (fallbacks included), in place or
    /// from the rest vertices.
    #[test]
    fn chunked_skinning_equals_skinning_vertex_by_vertex() {
        let joint_matrices = [
            Mat4::from_rotation_z(0.3) * Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0)),
            Mat4::from_scale(Vec3::new(1.5, 0.5, -2.0)),
            Mat4::from_quat(Quat::from_rotation_x(-1.1)),
        ];
        let skinning = Skinning {
            joint_matrices: &joint_matrices,
            world_from_node: Mat4::from_translation(Vec3::new(0.0, -4.0, 1.0)),
        };
        let count = 3 * PARALLEL_MIN_VERTICES + 123;
        let positions: Vec<Vec3> = (0..count)
            .map(|v| Vec3::new(v as f32 * 0.001, (v % 17) as f32, -(v as f32).sqrt()))
            .collect();
        let normals: Vec<Vec3> = (0..count)
            .map(|v| Vec3::new(1.0, (v % 5) as f32, 0.5).normalize())
            .collect();
        let joints: Vec<[u16; 4]> = (0..count).map(|v| [(v % 3) as u16, 2, 0, 1]).collect();
        // Every 11th vertex has zero weights: the rigid fallback.
        let weights: Vec<[f32; 4]> = (0..count)
            .map(|v| match v % 11 {
                0 => [0.0; 4],
                k => [0.5, k as f32 * 0.04, 0.1, 0.0],
            })
            .collect();
        let influences = Influences {
            joints: &joints,
            weights: &weights,
        };
        let (mut chunked, mut chunked_normals) = (positions.clone(), normals.clone());
        skinning.apply(influences, None, &mut chunked, &mut chunked_normals);
        // Skinned from the rest vertices into other buffers: the same bits.
        let (mut from_rest, mut from_rest_normals) =
            (vec![Vec3::NAN; count], vec![Vec3::NAN; count]);
        skinning.apply(
            influences,
            Some((&positions, &normals)),
            &mut from_rest,
            &mut from_rest_normals,
        );
        let bits = |v: &[Vec3]| -> Vec<[u32; 3]> {
            v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
        };
        assert!(bits(&from_rest) == bits(&chunked));
        assert!(bits(&from_rest_normals) == bits(&chunked_normals));
        let rigid_normals = cofactor(Mat3A::from_mat4(skinning.world_from_node));
        for v in 0..count {
            let (p, n) = skinning.skin_vertex(
                &joints[v],
                &weights[v],
                &rigid_normals,
                positions[v],
                Some(normals[v]),
            );
            let n = n.unwrap();
            assert_eq!(
                p.to_array().map(f32::to_bits),
                chunked[v].to_array().map(f32::to_bits)
            );
            assert_eq!(
                n.to_array().map(f32::to_bits),
                chunked_normals[v].to_array().map(f32::to_bits)
            );
        }
        // Without normals the positions are the same.
        let mut no_normals = positions.clone();
        skinning.apply(influences, None, &mut no_normals, &mut []);
        assert!(no_normals == chunked);
    }

    /// The vertex skinning as first written, with glam's own tests (`Mat4::is_finite`,
    /// `try_normalize`, a sign multiplied in): `skin_vertex` is written for speed and must
    /// give these bits, fallbacks included.
    fn reference_skin_vertex(
        skinning: &Skinning,
        joints: &[u16; 4],
        weights: &[f32; 4],
        position: Vec3,
        normal: Vec3,
    ) -> (Vec3, Vec3) {
        let mut sum = Mat4::ZERO;
        let mut total = 0.0;
        for (&j, &w) in joints.iter().zip(weights) {
            if w == 0.0 {
                continue;
            }
            let Some(m) = skinning.joint_matrices.get(usize::from(j)) else {
                continue;
            };
            sum += *m * w;
            total += w;
        }
        let transform = |(c, sign): (Mat3A, f32), m: Mat3A, n: Vec3| {
            let n = Vec3A::from(n);
            Vec3::from(
                (sign * (c * n))
                    .try_normalize()
                    .or_else(|| (m * n).try_normalize())
                    .unwrap_or_else(|| n.normalize_or_zero()),
            )
        };
        let cofactor_and_sign = |m: Mat3A| {
            let c = Mat3A::from_cols(
                m.y_axis.cross(m.z_axis),
                m.z_axis.cross(m.x_axis),
                m.x_axis.cross(m.y_axis),
            );
            (
                c,
                if m.x_axis.dot(c.x_axis) < 0.0 {
                    -1.0
                } else {
                    1.0
                },
            )
        };
        let blended = (total != 0.0 && sum.is_finite()).then_some(sum);
        match blended
            .map(|m| (m, m.transform_point3(position)))
            .filter(|(_, p)| p.is_finite())
        {
            Some((m, p)) => {
                let m3 = Mat3A::from_mat4(m);
                (p, transform(cofactor_and_sign(m3), m3, normal))
            }
            None => {
                let w = skinning.world_from_node;
                let p = w.transform_point3(position);
                if p.is_finite() {
                    let m3 = Mat3A::from_mat4(w);
                    (p, transform(cofactor_and_sign(m3), m3, normal))
                } else {
                    (position, normal)
                }
            }
        }
    }

    /// Hard joints, weights, positions and normals: non-finite entries anywhere in a joint
    /// matrix (its bottom row included, which the position never reads), overflowing
    /// blends and positions, zero and negative-zero weights, joints past the skin's end,
    /// mirrored and singular maps, zero, tiny, huge and non-finite normals.
    #[test]
    fn skin_vertex_gives_the_reference_bits_on_hard_inputs() {
        let mut bottom_row_inf = Mat4::from_rotation_z(0.4);
        bottom_row_inf.x_axis.w = f32::INFINITY;
        let mut one_nan = Mat4::from_scale(Vec3::splat(2.0));
        one_nan.z_axis.y = f32::NAN;
        let joint_matrices = [
            Mat4::from_rotation_z(0.3) * Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0)),
            Mat4::from_scale(Vec3::new(1.5, 0.5, -2.0)),
            Mat4::from_scale(Vec3::new(1.0, 0.0, 1.0)),
            Mat4::from_scale(Vec3::splat(3e38)),
            bottom_row_inf,
            one_nan,
            Mat4::from_translation(Vec3::splat(f32::MAX)),
            Mat4::ZERO,
        ];
        let worlds = [
            Mat4::from_translation(Vec3::new(0.0, -4.0, 1.0)),
            Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0)),
            Mat4::from_scale(Vec3::splat(1e30)),
        ];
        let positions = [
            Vec3::new(0.5, -1.0, 2.0),
            Vec3::ZERO,
            Vec3::splat(1e30),
            Vec3::new(-0.0, 0.0, -0.0),
            Vec3::new(f32::INFINITY, 0.0, 1.0),
        ];
        let normals = [
            Vec3::new(0.0, 0.6, 0.8),
            Vec3::ZERO,
            Vec3::splat(1e-30),
            Vec3::splat(3e38),
            Vec3::new(f32::NAN, 0.0, 1.0),
        ];
        let weight_sets = [
            [1.0, 0.0, 0.0, 0.0],
            [0.5, 0.5, 0.0, 0.0],
            [0.0, -0.0, 0.0, 0.0],
            [0.25, 0.25, 0.25, 0.25],
            [-0.5, 1.5, 0.0, 0.0],
            [1.0, 1.0, 1.0, 1.0],
        ];
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut cases = 0;
        let mut fell_back = 0;
        for world_from_node in worlds {
            let skinning = Skinning {
                joint_matrices: &joint_matrices,
                world_from_node,
            };
            let rigid = cofactor(Mat3A::from_mat4(world_from_node));
            // Every case of this map as one mesh's vertices, and what `skin_vertex` gave.
            let mut mesh = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            let mut expected = (Vec::new(), Vec::new());
            for a in 0..joint_matrices.len() as u16 + 1 {
                for b in [0, 1, 2, 3, 4, 5, 6, 7, 99] {
                    let joints = [a, b, (a + 1) % 8, 3];
                    for weights in weight_sets {
                        for (&position, &normal) in positions
                            .iter()
                            .zip(normals.iter().cycle().skip(usize::from(a)))
                        {
                            let (p, n) = skinning.skin_vertex(
                                &joints,
                                &weights,
                                &rigid,
                                position,
                                Some(normal),
                            );
                            let (rp, rn) = reference_skin_vertex(
                                &skinning, &joints, &weights, position, normal,
                            );
                            assert_eq!(
                                (bits(p), bits(n.unwrap())),
                                (bits(rp), bits(rn)),
                                "joints {joints:?}, weights {weights:?}, position {position}, normal {normal}"
                            );
                            // Without a normal the position is the same.
                            let (alone, none) =
                                skinning.skin_vertex(&joints, &weights, &rigid, position, None);
                            assert!(bits(alone) == bits(p) && none.is_none());
                            mesh.0.push(joints);
                            mesh.1.push(weights);
                            mesh.2.push(position);
                            mesh.3.push(normal);
                            expected.0.push(bits(p));
                            expected.1.push(bits(rn));
                            cases += 1;
                            fell_back += usize::from(
                                bits(p) == bits(world_from_node.transform_point3(position)),
                            );
                        }
                    }
                }
            }
            // The same vertices skinned as a mesh, in blocks whose normals are normalised
            // together, in place and from rest vertices: the same bits, fallbacks included.
            let (joints, weights, positions, normals) = &mesh;
            let influences = Influences { joints, weights };
            let (mut in_place, mut in_place_normals) = (positions.clone(), normals.clone());
            skinning.apply(influences, None, &mut in_place, &mut in_place_normals);
            let (mut from_rest, mut from_rest_normals) = (
                vec![Vec3::NAN; positions.len()],
                vec![Vec3::NAN; positions.len()],
            );
            skinning.apply(
                influences,
                Some((positions, normals)),
                &mut from_rest,
                &mut from_rest_normals,
            );
            let all_bits = |v: &[Vec3]| v.iter().map(|&p| bits(p)).collect::<Vec<_>>();
            assert!(all_bits(&in_place) == expected.0 && all_bits(&from_rest) == expected.0);
            assert!(
                all_bits(&in_place_normals) == expected.1
                    && all_bits(&from_rest_normals) == expected.1
            );
            // Normals on one side only: the positions as before, the normals written only
            // where there is one to read and a place to write it, the others left alone.
            let short = normals.len() / 2 + 7;
            let (mut some, mut some_normals) = (positions.clone(), normals[..short].to_vec());
            skinning.apply(influences, None, &mut some, &mut some_normals);
            assert!(
                all_bits(&some) == expected.0 && all_bits(&some_normals) == expected.1[..short]
            );
            let mut untouched = vec![Vec3::ONE; positions.len()];
            let mut no_rest_normals = vec![Vec3::NAN; positions.len()];
            skinning.apply(
                influences,
                Some((positions, &[])),
                &mut no_rest_normals,
                &mut untouched,
            );
            assert!(all_bits(&no_rest_normals) == expected.0);
            assert!(untouched.iter().all(|&n| n == Vec3::ONE));
        }
        // The cases reach both the blend and the fallbacks.
        assert!(
            fell_back > 100 && fell_back < cases - 100,
            "{fell_back} of {cases}"
        );
    }

    /// Morphed normals normalised a block at a time: `try_normalize`'s bits or the base
    /// normal, on zero, tiny, huge, non-finite and ordinary normals, over several blocks
    /// and a short base.
    #[test]
    fn morphed_normals_normalise_as_try_normalize_does() {
        let hard = [
            Vec3::new(0.0, 0.6, 0.8),
            Vec3::ZERO,
            Vec3::new(-0.0, 0.0, -0.0),
            Vec3::splat(1e-30),
            Vec3::splat(1e-20),
            Vec3::splat(3e38),
            Vec3::new(f32::MAX, 0.0, 0.0),
            Vec3::new(f32::NAN, 0.0, 1.0),
            Vec3::new(f32::INFINITY, 1.0, 0.0),
            Vec3::new(1.0, -2.0, 3.0),
            Vec3::new(3e-39, 0.0, 0.0),
        ];
        let normals: Vec<Vec3> = (0..300)
            .map(|k| hard[k % hard.len()] * (1.0 + k as f32 * 0.37))
            .collect();
        let base: Vec<Vec3> = (0..290).map(|k| Vec3::new(k as f32, 1.0, -1.0)).collect();
        let mut ours = normals.clone();
        normalize_or(&mut ours, &base);
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut fell_back = 0;
        for k in 0..normals.len() {
            let expected = match base.get(k) {
                Some(&b) => normals[k].try_normalize().unwrap_or(b),
                None => normals[k],
            };
            assert_eq!(bits(ours[k]), bits(expected), "normal {k}: {}", normals[k]);
            fell_back += usize::from(k < base.len() && bits(ours[k]) == bits(base[k]));
        }
        assert!(fell_back > 50 && fell_back < 250, "{fell_back}");
    }

    #[test]
    fn cofactor_is_the_inverse_transpose_up_to_a_positive_scale() {
        let m = Mat3A::from_cols(
            Vec3A::new(2.0, 0.3, 0.0),
            Vec3A::new(-0.5, 1.0, 0.2),
            Vec3A::new(0.1, 0.0, -3.0),
        );
        let (c, sign) = cofactor(m);
        assert!(m.determinant() < 0.0 && sign == -1.0);
        let reference = m.inverse().transpose();
        for n in [Vec3::X, Vec3::new(0.3, -1.0, 2.0).normalize()] {
            let ours = transform_normal(&(c, sign), m, n);
            let expected = (reference * n).normalize();
            assert!(ours.abs_diff_eq(expected, 1e-6), "{ours} vs {expected}");
        }
        // A rotation maps normals like vectors.
        let r = Mat3A::from_quat(Quat::from_rotation_y(0.7));
        let n = Vec3::new(0.0, 0.6, 0.8);
        assert!(transform_normal(&cofactor(r), r, n).abs_diff_eq(r * n, 1e-6));
        // A singular map (flattened z) still gives a unit normal.
        let flat = Mat3A::from_diagonal(Vec3::new(1.0, 1.0, 0.0));
        let out = transform_normal(&cofactor(flat), flat, Vec3::new(1.0, 0.0, 1.0).normalize());
        assert!((out.length() - 1.0).abs() < 1e-6 && out.is_finite());
    }

    /// A point cache blends the two samples around the cache position; a vertex equal in
    /// both keeps its bits whatever the blend, so only moving vertices change.
    #[test]
    fn point_cache_blends_samples_and_keeps_unmoved_vertices_bit_identical() {
        use crate::scene::{MeshDesc, NodeDesc, PointCacheDesc};
        let moved = Vec3::new(0.1, 0.7, -0.3);
        let samples = vec![
            vec![Vec3::new(1.0, 2.0, 3.0), moved, Vec3::ZERO],
            vec![Vec3::new(1.0, 2.0, 3.0), moved, Vec3::new(1.0, 0.0, 0.0)],
            vec![Vec3::new(2.0, 2.0, 3.0), moved, Vec3::new(1.0, 0.0, 0.0)],
        ];
        let scene = SceneDesc {
            meshes: vec![MeshDesc {
                primitives: vec![PrimitiveDesc {
                    positions: samples[0].clone(),
                    indices: vec![0, 1, 2],
                    point_cache: Some(PointCacheDesc {
                        positions: samples.clone(),
                        normals: None,
                    }),
                    ..Default::default()
                }],
                weights: vec![0.0],
                ..Default::default()
            }],
            nodes: vec![NodeDesc {
                mesh: Some(0),
                ..Default::default()
            }],
            roots: vec![0],
            ..Default::default()
        };
        assert!(primitive_deforms(&scene, 0, 0, 0));
        let at = |s: f32| {
            let mut pose = Pose::default();
            pose.evaluate(&scene, crate::anim::AnimationSelection::All, 0.0);
            pose.morph_weights[0] = vec![s];
            let (mut p, mut n) = (Vec::new(), Vec::new());
            let space = deform_primitive(&scene, &pose, 0, 0, 0, &mut p, &mut n);
            assert_eq!(space, VertexSpace::Object);
            p
        };
        assert_eq!(at(0.0), samples[0]);
        assert_eq!(at(2.0), samples[2]);
        assert_eq!(at(7.0), samples[2], "clamped past the last sample");
        assert_eq!(at(f32::NAN), samples[0]);
        let quarter = at(0.25);
        assert_eq!(quarter[2], Vec3::new(0.25, 0.0, 0.0));
        for s in [0.1f32, 0.33, 0.9, 1.0, 1.4] {
            let p = at(s);
            // Vertex 1 never moves: the same bits at every position.
            assert_eq!(
                p[1].to_array().map(f32::to_bits),
                moved.to_array().map(f32::to_bits)
            );
        }
        // Between samples 1 and 2 vertex 2 does not move, vertex 0 does.
        assert_eq!(at(1.3)[2], at(1.8)[2]);
        assert_ne!(at(1.3)[0], at(1.8)[0]);
    }
}
