//! One ray against a leaf of two packs (five to eight triangles) in the eight lanes of AVX:
//! the first pack's triangles in lanes 0 to 3, the second's in 4 to 7.
//!
//! Why: a leaf holds up to eight triangles, so a leaf of more than four is two packs, and
//! one ray tested them as two four-lane tests, each paying the ray's splats, the edge
//! functions' products, the masks and the division for four lanes. Here the two packs share
//! one pass in the AVX2 copy. Each lane performs exactly the IEEE operations of one lane of
//! [`ShearedRay::intersect_pack`] on the same operands, in the same order (no fused
//! multiply-add; the same ordered and unordered comparisons), including the f64
//! recomputation of an edge function that is exactly zero and the f64 test of a lane whose
//! distance left f32's range, so a leaf's hits are the same bits either way, reported in the
//! same order (the first pack's lanes, then the second's). `tests` compares the two on
//! random and degenerate triangles.

use std::arch::x86_64::*;

use super::across_rays::edge_function_f64;
use super::{LANES, ShearedRay, TrianglePack, intersect_beyond_f32};

/// Lanes of a two-pack test.
pub(super) const WIDE: usize = 2 * LANES;

/// What a two-pack test found: bit `l` of `mask` for lane `l % 4` of pack `l / 4`, with the
/// hit's distance and barycentrics in `t[l]`, `u[l]`, `v[l]` (other lanes hold anything).
pub(super) struct PairHits {
    pub mask: u32,
    pub t: [f32; WIDE],
    pub u: [f32; WIDE],
    pub v: [f32; WIDE],
}

/// The test of `ray` against the live lanes of `packs` with `t` in `[0, t_max)`: lane for
/// lane [`ShearedRay::intersect_pack`] of each pack. The rare lanes (an edge function of
/// exactly zero, a distance beyond f32's range) are finished out of line (cold), and the
/// common lanes are accepted by vector compares, so the common path is short. The function
/// itself stays a call from the walk: written as an always-inlined function whose AVX
/// intrinsics would inline into the walk's AVX2 copy, it left them as calls (the
/// closures carry no target features) and cost half again as many instructions a glass ray.
///
/// # Safety
/// The CPU must have AVX.
#[inline]
#[target_feature(enable = "avx")]
pub(super) unsafe fn intersect(
    ray: &ShearedRay,
    packs: [&TrianglePack; 2],
    t_max: f32,
) -> PairHits {
    let [kx, ky, kz] = ray.k.map(usize::from);
    let [sx, sy, sz] = ray.shear.map(|s| _mm256_set1_ps(s));
    let origin = ray.origin.map(|o| _mm256_set1_ps(o));
    // Coordinate `axis` of vertex `vertex` of the eight triangles.
    let row = |vertex: usize, axis: usize| {
        let [low, high] = packs.map(|p| &p.v[vertex][axis]);
        // SAFETY: each row is four f32 (16 bytes), read unaligned.
        unsafe { _mm256_set_m128(_mm_loadu_ps(high.as_ptr()), _mm_loadu_ps(low.as_ptr())) }
    };
    // Vertex `i` relative to the origin, sheared, as `intersect_pack` makes it:
    // `(v - o) - s * z` for x and y.
    let sheared = |i: usize| {
        let z = _mm256_sub_ps(row(i, kz), origin[kz]);
        let x = _mm256_sub_ps(_mm256_sub_ps(row(i, kx), origin[kx]), _mm256_mul_ps(sx, z));
        let y = _mm256_sub_ps(_mm256_sub_ps(row(i, ky), origin[ky]), _mm256_mul_ps(sy, z));
        (x, y, z)
    };
    let (ax, ay, az) = sheared(0);
    let (bx, by, bz) = sheared(1);
    let (cx, cy, cz) = sheared(2);
    let edge = |p, q, r, s| _mm256_sub_ps(_mm256_mul_ps(p, q), _mm256_mul_ps(r, s));
    let mut uvw = [
        edge(cx, by, cy, bx),
        edge(ax, cy, ay, cx),
        edge(bx, ay, by, ax),
    ];
    let live_mask = lanes_below(packs[0].live) | lanes_below(packs[1].live) << LANES;
    let zero = _mm256_setzero_ps();
    let is_zero = |x| mask_of(_mm256_cmp_ps::<_CMP_EQ_OQ>(x, zero));
    let on_edge = (is_zero(uvw[0]) | is_zero(uvw[1]) | is_zero(uvw[2])) & live_mask;
    if on_edge != 0 {
        edges_in_f64(&mut uvw, [ax, ay, bx, by, cx, cy], on_edge);
    }
    let [u, v, w] = uvw;
    let below = |x| mask_of(_mm256_cmp_ps::<_CMP_LT_OS>(x, zero));
    let above = |x| mask_of(_mm256_cmp_ps::<_CMP_GT_OS>(x, zero));
    let negative = below(u) | below(v) | below(w);
    let positive = above(u) | above(v) | above(w);
    let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
    let t_scaled = _mm256_add_ps(
        _mm256_add_ps(
            _mm256_mul_ps(u, _mm256_mul_ps(sz, az)),
            _mm256_mul_ps(v, _mm256_mul_ps(sz, bz)),
        ),
        _mm256_mul_ps(w, _mm256_mul_ps(sz, cz)),
    );
    // `cmpneq` is unordered, as `Vec4::cmpne`: a NaN determinant counts as non-zero here
    // and is sent to the f64 test by `finite` below.
    let nonzero = mask_of(_mm256_cmp_ps::<_CMP_NEQ_UQ>(det, zero));
    let inside = !(negative & positive) & nonzero & live_mask;
    let mut hits = PairHits {
        mask: 0,
        t: [0.0; WIDE],
        u: [0.0; WIDE],
        v: [0.0; WIDE],
    };
    if inside == 0 {
        return hits;
    }
    let inverse = _mm256_div_ps(_mm256_set1_ps(1.0), det);
    let t = _mm256_mul_ps(t_scaled, inverse);
    // SAFETY: each array holds eight f32.
    unsafe {
        _mm256_storeu_ps(hits.t.as_mut_ptr(), t);
        _mm256_storeu_ps(hits.u.as_mut_ptr(), _mm256_mul_ps(v, inverse));
        _mm256_storeu_ps(hits.v.as_mut_ptr(), _mm256_mul_ps(w, inverse));
    }
    // `x - x` is zero exactly when `x` is finite.
    let finite = is_zero(_mm256_sub_ps(det, det)) & is_zero(_mm256_sub_ps(t_scaled, t_scaled));
    // `intersect_pack`'s `t >= 0 && t < t_max && t.is_finite()`, ordered compares all (false
    // for NaN).
    let in_range = mask_of(_mm256_cmp_ps::<_CMP_GE_OQ>(t, zero))
        & mask_of(_mm256_cmp_ps::<_CMP_LT_OQ>(t, _mm256_set1_ps(t_max)))
        & is_zero(_mm256_sub_ps(t, t));
    hits.mask = inside & finite & in_range;
    let beyond = inside & !finite;
    if beyond != 0 {
        beyond_f32(ray, packs, t_max, beyond, &mut hits);
    }
    hits
}

/// The lanes' bits of a compare's result.
#[inline]
#[target_feature(enable = "avx")]
fn mask_of(m: __m256) -> u32 {
    _mm256_movemask_ps(m) as u32
}

/// Recomputes in f64 the edge functions `uvw` of the lanes `on_edge` (one of them exactly
/// zero in f32) from the sheared vertices `ax, ay, bx, by, cx, cy`, as `intersect_pack`
/// recomputes them.
#[cold]
#[inline(never)]
#[target_feature(enable = "avx")]
fn edges_in_f64(uvw: &mut [__m256; 3], vertices: [__m256; 6], on_edge: u32) {
    let lanes = |x: __m256| {
        let mut out = [0.0f32; WIDE];
        // SAFETY: `out` holds eight f32.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), x) };
        out
    };
    let [mut u, mut v, mut w] = uvw.map(lanes);
    let [ax, ay, bx, by, cx, cy] = vertices.map(lanes);
    let mut bits = on_edge;
    while bits != 0 {
        let l = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        u[l] = edge_function_f64(cx[l], by[l], cy[l], bx[l]);
        v[l] = edge_function_f64(ax[l], cy[l], ay[l], cx[l]);
        w[l] = edge_function_f64(bx[l], ay[l], by[l], ax[l]);
    }
    // SAFETY: each array holds eight f32.
    *uvw = [u, v, w].map(|x| unsafe { _mm256_loadu_ps(x.as_ptr()) });
}

/// Decides in f64 the lanes `beyond` (inside the triangle, with a determinant or distance
/// beyond f32's range), as `intersect_pack` decides them, into `hits`.
#[cold]
#[inline(never)]
fn beyond_f32(
    ray: &ShearedRay,
    packs: [&TrianglePack; 2],
    t_max: f32,
    beyond: u32,
    hits: &mut PairHits,
) {
    let mut bits = beyond;
    while bits != 0 {
        let l = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        let found = intersect_beyond_f32(
            ray.origin,
            ray.shear,
            ray.k,
            packs[l / LANES],
            l % LANES,
            t_max,
        );
        if let Some((t, bary)) = found {
            hits.mask |= 1 << l;
            (hits.t[l], hits.u[l], hits.v[l]) = (t, bary.x, bary.y);
        }
    }
}

/// The mask of a pack's first `live` lanes.
#[inline(always)]
fn lanes_below(live: u32) -> u32 {
    (1u32 << live) - 1
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;

    use super::*;
    use crate::accel::triangles::PackHits;
    use crate::accel::wide::test_support::uniform;

    /// A pack of `live` triangles: random ones, or (every third pack) triangles sharing
    /// edges and vertices on a grid the rays are aimed at, so edge functions of exactly zero
    /// and ties occur.
    fn pack(unit: &mut impl FnMut() -> f32, live: u32, on_grid: bool, scale: f32) -> TrianglePack {
        let mut p = TrianglePack {
            live,
            first_slot: 0,
            ..TrianglePack::default()
        };
        for lane in 0..live as usize {
            let tri: [Vec3A; 3] = if on_grid {
                let (x, y) = ((unit() * 4.0).floor(), (unit() * 4.0).floor());
                let z = 5.0;
                [
                    Vec3A::new(x, y, z),
                    Vec3A::new(x + 1.0, y, z),
                    Vec3A::new(x, y + 1.0, z),
                ]
            } else {
                std::array::from_fn(|_| {
                    Vec3A::new(unit(), unit(), unit() + 1.0) * scale
                        - Vec3A::new(0.5, 0.5, 0.0) * scale
                })
            };
            p.set(lane, &tri);
            p.source[lane] = lane as u32;
        }
        p
    }

    fn same(a: &PackHits, lanes: std::ops::Range<usize>, b: &PairHits) -> bool {
        lanes.enumerate().all(|(i, l)| {
            let (hit_a, hit_b) = (a.mask & (1 << i) != 0, b.mask & (1 << l) != 0);
            hit_a == hit_b
                && (!hit_a
                    || (a.t[i].to_bits() == b.t[l].to_bits()
                        && a.bary[i].x.to_bits() == b.u[l].to_bits()
                        && a.bary[i].y.to_bits() == b.v[l].to_bits()))
        })
    }

    #[test]
    fn two_packs_at_once_equal_each_pack_alone() {
        if !std::arch::is_x86_feature_detected!("avx") {
            println!("skipped: this CPU has no AVX");
            return;
        }
        let mut unit = uniform(0x2545_f491_4f6c_dd1d, 0.0, 1.0);
        let (mut hits, mut on_edges) = (0, 0);
        for round in 0..6000 {
            let on_grid = round % 3 == 0;
            // Huge coordinates every seventh round: distances beyond f32's range go to the
            // f64 test.
            let scale = if round % 7 == 0 { 3e13 } else { 1.0 };
            let live = [1 + round % 4, 1 + (round / 4) % 4].map(|l| l as u32);
            let packs = live.map(|l| pack(&mut unit, l, on_grid, scale));
            let origin = if on_grid {
                // Aimed at grid points and edge midpoints.
                let (x, y) = ((unit() * 8.0).floor() / 2.0, (unit() * 8.0).floor() / 2.0);
                Vec3A::new(x, y, 0.0)
            } else {
                Vec3A::new(unit() - 0.5, unit() - 0.5, 0.0) * 0.2
            };
            let direction = if on_grid {
                Vec3A::Z
            } else {
                Vec3A::new(unit() - 0.5, unit() - 0.5, 1.0)
            };
            let ray = ShearedRay::new(origin, direction);
            let t_max = if round % 5 == 0 {
                4.0 * scale
            } else {
                f32::INFINITY
            };
            let alone = packs.map(|p| ray.intersect_pack(&p, p.live as usize, t_max));
            // SAFETY: the CPU has AVX (checked above).
            let both = unsafe { intersect(&ray, [&packs[0], &packs[1]], t_max) };
            assert!(
                same(&alone[0], 0..LANES, &both) && same(&alone[1], LANES..WIDE, &both),
                "round {round}: pack by pack {:b} {:b}, both at once {:b}",
                alone[0].mask,
                alone[1].mask,
                both.mask
            );
            hits += both.mask.count_ones();
            on_edges += u32::from(on_grid && both.mask != 0);
        }
        // The comparison means something only if many lanes hit, some on shared edges.
        assert!(
            hits > 1000 && on_edges > 100,
            "{hits} hits, {on_edges} on the grid"
        );
    }
}
