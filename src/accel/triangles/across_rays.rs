//! The watertight test of one triangle against up to eight rays at once: the rays of a
//! packet that reach a leaf together, side by side in the lanes of [`F32x8`] (eight per AVX
//! instruction where the CPU has AVX2), instead of one ray against the four triangles of a
//! pack; and against sixteen at once where the CPU has AVX-512 ([`sixteen`], for leaves
//! handed more than eight rays, as primary packets' leaves mostly are).
//!
//! Why: a packet's leaf visits test many rays against the same few triangles; across rays,
//! a triangle's vertices are loaded once and broadcast, and eight rays share each
//! instruction (four in a pack test, often with dead lanes). Which way a leaf is tested is
//! free to choose, because both compute the same bits: each lane performs, for its ray and
//! triangle, exactly the IEEE operations of one lane of [`ShearedRay::intersect_pack`] in
//! the same order (no fused multiply-add), including the f64 recomputation of an edge
//! function that is exactly zero. `tests::across_rays_equals_one_ray_at_a_time` checks it on
//! every CPU, in the baseline copy and the AVX2 copy where there is one.
//!
//! The rays of a group must share the axis permutation of Woop et al. (the axis where the
//! direction is largest, and its sign). A group is either eight of a packet's own rays
//! (rays 8g to 8g + 7) that share one, tested in place with the rays outside the leaf's box
//! masked off (the `live` lanes), or a list of rays that [`runs_by_permutation`] orders so;
//! either way [`ShearedLanes::of_rays`] makes the group's lanes.

use glam::Vec2;

use super::{ShearedRay, ShearedRows, TrianglePack, intersect_beyond_f32};
use crate::accel::wide::PACKET;
use crate::simd::F32x8;

/// Rays per group.
pub const RAYS: usize = 8;

/// Up to [`RAYS`] rays sharing one axis permutation, as lanes.
#[derive(Clone, Copy)]
pub struct ShearedLanes {
    /// The shared permutation `kx, ky, kz`.
    k: [usize; 3],
    /// Per axis (unpermuted), each ray's origin.
    origin: [F32x8; 3],
    /// `dx / dz, dy / dz, 1 / dz` of each ray (permuted axes).
    shear: [F32x8; 3],
    /// Lanes that hold a ray.
    live: u32,
}

/// What one triangle's test against a group found: the lanes (rays) hit, with distance and
/// barycentrics.
pub struct LaneHits {
    pub mask: u32,
    pub t: [f32; RAYS],
    pub bary: [Vec2; RAYS],
}

impl ShearedLanes {
    /// The group of `rays` (at most [`RAYS`], all with the same permutation; lanes past
    /// their number hold copies of the first, masked off).
    ///
    /// # Panics
    /// If `rays` is empty or longer than [`RAYS`] (debug builds also check the permutation).
    #[inline(always)]
    pub fn gather<'a>(rays: impl ExactSizeIterator<Item = &'a ShearedRay> + Clone) -> ShearedLanes {
        let n = rays.len();
        assert!((1..=RAYS).contains(&n), "{n} rays in a lane group");
        let mut first = rays.clone();
        let k = first.next().expect("at least one ray").k.map(usize::from);
        let mut group = ShearedLanes {
            k,
            origin: [F32x8::splat(0.0); 3],
            shear: [F32x8::splat(0.0); 3],
            live: (1u32 << n) - 1,
        };
        let mut lane = 0;
        let mut last = None;
        for ray in rays {
            debug_assert_eq!(
                ray.k.map(usize::from),
                k,
                "rays of a lane group share their permutation"
            );
            group.fill_lane(lane, ray);
            last = Some(ray);
            lane += 1;
        }
        let last = last.expect("at least one ray");
        for lane in n..RAYS {
            group.fill_lane(lane, last);
        }
        group
    }

    /// The rays `chunk` of `sheared` (indices, 1 to [`RAYS`] of them, sharing one
    /// permutation) as a group, the same lanes [`ShearedLanes::gather`] makes. In the AVX2
    /// copy each ray's 32 bytes are loaded whole and the eight are transposed in registers:
    /// built lane by lane, the rows were written as scalars and read back as vectors, which
    /// stalls on store forwarding (the hottest lines of a primary packet's leaf test).
    #[inline(always)]
    pub fn of_rays<const AVX: bool>(sheared: &[ShearedRay], chunk: &[u8]) -> ShearedLanes {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            assert!(
                (1..=RAYS).contains(&chunk.len()),
                "{} rays in a lane group",
                chunk.len()
            );
            let last = chunk[chunk.len() - 1] as usize;
            let rays: [&ShearedRay; RAYS] =
                std::array::from_fn(|l| &sheared[chunk.get(l).map_or(last, |&r| r as usize)]);
            debug_assert!(rays.iter().all(|r| r.k == rays[0].k), "one permutation");
            // SAFETY: `AVX` is true only in a kernel copy `simd::dispatch` runs where the CPU
            // has AVX2.
            let (origin, shear) = unsafe { transposed::rows(&rays) };
            return ShearedLanes {
                k: rays[0].k.map(usize::from),
                origin,
                shear,
                live: (1u32 << chunk.len()) - 1,
            };
        }
        ShearedLanes::gather(chunk.iter().map(|&r| &sheared[r as usize]))
    }

    /// The rays `at..at + len` of a packet (`len` 1 to [`RAYS`], `at` a multiple of
    /// [`RAYS`]) sharing the permutation `k`, read whole from the packet's rows (filled by
    /// `ShearedRay::fill_with_rows`): the lanes [`ShearedLanes::of_rays`] makes of those
    /// rays (lanes past `len` repeat the last ray in both), without a transpose.
    #[inline(always)]
    pub fn of_row_block(rows: &ShearedRows, k: [u8; 3], at: usize, len: usize) -> ShearedLanes {
        assert!(
            (1..=RAYS).contains(&len) && at % RAYS == 0 && at + RAYS <= PACKET,
            "rays {at}..{} of a packet",
            at + len
        );
        let block = |row: &[f32; PACKET]| F32x8(row[at..at + RAYS].try_into().expect("eight rays"));
        ShearedLanes {
            k: k.map(usize::from),
            origin: rows.origin().each_ref().map(block),
            shear: rows.shear().each_ref().map(block),
            live: (1u32 << len) - 1,
        }
    }

    #[inline(always)]
    fn fill_lane(&mut self, lane: usize, ray: &ShearedRay) {
        for axis in 0..3 {
            self.origin[axis].0[lane] = ray.origin[axis];
            self.shear[axis].0[lane] = ray.shear[axis];
        }
    }

    /// Vertex `i` of triangle `lane` relative to each ray's origin, sheared into the ray's
    /// frame: `(x, y)` in the ray's plane and `z` along it (one lane of `intersect_pack`).
    #[inline(always)]
    fn sheared_vertex<const AVX: bool>(
        &self,
        pack: &TrianglePack,
        i: usize,
        lane: usize,
    ) -> (F32x8, F32x8, F32x8) {
        let [kx, ky, kz] = self.k;
        let [sx, sy, _] = self.shear;
        let v = &pack.v[i];
        let z = F32x8::splat(v[kz][lane]).sub::<AVX>(self.origin[kz]);
        let x = F32x8::splat(v[kx][lane])
            .sub::<AVX>(self.origin[kx])
            .sub::<AVX>(sx.mul::<AVX>(z));
        let y = F32x8::splat(v[ky][lane])
            .sub::<AVX>(self.origin[ky])
            .sub::<AVX>(sy.mul::<AVX>(z));
        (x, y, z)
    }

    /// Tests triangle `lane` of `pack` against the rays of the group in the lanes `live`
    /// (`u32::MAX`: every ray of the group); a ray's hit counts when `t` lies in `[0,
    /// t_max)` of that ray's lane.
    #[inline(always)]
    pub fn intersect<const AVX: bool>(
        &self,
        pack: &TrianglePack,
        lane: usize,
        t_max: &F32x8,
        live: u32,
    ) -> LaneHits {
        let live = live & self.live;
        // Plain functions, not closures: a closure is compiled on its own, without the AVX2
        // copy's target features, and then cannot inline the AVX operations.
        let (ax, ay, az) = self.sheared_vertex::<AVX>(pack, 0, lane);
        let (bx, by, bz) = self.sheared_vertex::<AVX>(pack, 1, lane);
        let (cx, cy, cz) = self.sheared_vertex::<AVX>(pack, 2, lane);
        let mut u = edge_function::<AVX>(cx, by, cy, bx);
        let mut v = edge_function::<AVX>(ax, cy, ay, cx);
        let mut w = edge_function::<AVX>(bx, ay, by, ax);
        let sz = self.shear[2];
        let zero = F32x8::splat(0.0);
        let on_edge =
            (u.eq_mask::<AVX>(zero) | v.eq_mask::<AVX>(zero) | w.eq_mask::<AVX>(zero)) & live;
        if on_edge != 0 {
            // Exactly on an edge in f32: decided in f64 (rare), as the pack test does.
            let mut bits = on_edge;
            while bits != 0 {
                let l = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                u.0[l] = edge_function_f64(cx.0[l], by.0[l], cy.0[l], bx.0[l]);
                v.0[l] = edge_function_f64(ax.0[l], cy.0[l], ay.0[l], cx.0[l]);
                w.0[l] = edge_function_f64(bx.0[l], ay.0[l], by.0[l], ax.0[l]);
            }
        }
        let negative = u.lt_mask::<AVX>(zero) | v.lt_mask::<AVX>(zero) | w.lt_mask::<AVX>(zero);
        let positive = u.gt_mask::<AVX>(zero) | v.gt_mask::<AVX>(zero) | w.gt_mask::<AVX>(zero);
        let det = u.add::<AVX>(v).add::<AVX>(w);
        let t_scaled = u
            .mul::<AVX>(sz.mul::<AVX>(az))
            .add::<AVX>(v.mul::<AVX>(sz.mul::<AVX>(bz)))
            .add::<AVX>(w.mul::<AVX>(sz.mul::<AVX>(cz)));
        let inside = !(negative & positive) & det.ne_mask::<AVX>(zero) & live;
        let mut hits = LaneHits {
            mask: 0,
            t: [0.0; RAYS],
            bary: [Vec2::ZERO; RAYS],
        };
        if inside == 0 {
            return hits;
        }
        let inverse = F32x8::splat(1.0).div::<AVX>(det);
        let t = t_scaled.mul::<AVX>(inverse);
        let (v, w) = (v.mul::<AVX>(inverse), w.mul::<AVX>(inverse));
        // Lanes whose distance or determinant left f32's range: decided in f64, as the pack
        // test decides them.
        let finite = det.sub::<AVX>(det).eq_mask::<AVX>(zero)
            & t_scaled.sub::<AVX>(t_scaled).eq_mask::<AVX>(zero);
        // `0 <= t < t_max` with `t` finite, per lane in one vector (the scalar test's
        // ordered comparisons: a NaN or infinite `t` is refused as it was lane by lane).
        let accepted = finite
            & zero.le_mask::<AVX>(t)
            & t.lt_mask::<AVX>(*t_max)
            & t.sub::<AVX>(t).eq_mask::<AVX>(zero);
        let mut bits = inside & (accepted | !finite);
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            // Each path writes its own answer: an `Option` of both paths' answers went
            // through the stack and stalled on reading its pieces back.
            if finite & (1 << l) != 0 {
                hits.mask |= 1 << l;
                hits.t[l] = t.0[l];
                hits.bary[l] = Vec2::new(v.0[l], w.0[l]);
            } else {
                let origin = self.origin.map(|axis| axis.0[l]);
                let shear = self.shear.map(|axis| axis.0[l]);
                let k = self.k.map(|axis| axis as u8);
                if let Some((t, bary)) =
                    intersect_beyond_f32(origin, shear, k, pack, lane, t_max.0[l])
                {
                    hits.mask |= 1 << l;
                    hits.t[l] = t;
                    hits.bary[l] = bary;
                }
            }
        }
        hits
    }
}

/// The rays `rays` (indices into `sheared`) in runs that share an axis permutation: the
/// rays in that order (`rays` itself when they all share one, as a packet's rays mostly do;
/// else sorted into `buffer`) and each run's length. Callers cut each run into groups of
/// [`RAYS`] for [`ShearedLanes::of_rays`]. (Data, not a callback: a closure is compiled
/// without the AVX2 copy's target features and could not inline the tests it would run.)
#[inline(always)]
pub fn runs_by_permutation<'a>(
    sheared: &[ShearedRay; PACKET],
    rays: &'a [u8],
    buffer: &'a mut [u8; PACKET],
) -> (&'a [u8], [usize; PERMUTATIONS]) {
    let mut sizes = [0usize; PERMUTATIONS];
    let Some(&r0) = rays.first() else {
        return (rays, sizes);
    };
    // Compared as words (the axes and the zero filler; ray numbers are below PACKET): a
    // primary packet's leaves ask this of every ray they are handed.
    let axes = sheared[usize::from(r0) % PACKET].axes_word();
    if rays
        .iter()
        .all(|&r| sheared[usize::from(r) % PACKET].axes_word() == axes)
    {
        sizes[0] = rays.len();
        return (rays, sizes);
    }
    // A counting sort: each permutation's count, where its run starts, then each ray into
    // its run's next place (ray order kept within a run).
    for &r in rays {
        sizes[sheared[r as usize].permutation()] += 1;
    }
    let mut next = [0usize; PERMUTATIONS];
    for p in 1..PERMUTATIONS {
        next[p] = next[p - 1] + sizes[p - 1];
    }
    for &r in rays {
        let p = sheared[r as usize].permutation();
        buffer[next[p]] = r;
        next[p] += 1;
    }
    (&buffer[..rays.len()], sizes)
}

/// `values[chunk[l]]` in lane `l` (the last one repeated past the chunk's end): a ray
/// group's limits. In the AVX2 copy the vector is built in a register (written lane by lane
/// to memory and read back whole, it stalls on store forwarding, as [`ShearedLanes::of_rays`]
/// explains; a gather instruction was slower still).
#[inline(always)]
pub fn lanes_of<const AVX: bool>(values: &[f32; PACKET], chunk: &[u8]) -> F32x8 {
    let last = chunk[chunk.len() - 1];
    let index: [u8; RAYS] = std::array::from_fn(|l| chunk.get(l).copied().unwrap_or(last));
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: as in `ShearedLanes::of_rays`.
        return unsafe { transposed::from_indices(values, index) };
    }
    F32x8(index.map(|r| values[r as usize]))
}

/// [`lanes_of`] for a block of up to sixteen rays `chunk` (indices into `values`) in two
/// groups of eight lanes, lanes past the block holding its last ray's value: the lanes
/// `sixteen::hits_in_leaf` reads the block's rays in.
#[cfg(target_arch = "x86_64")]
pub fn block_lanes_of<const AVX: bool>(values: &[f32; PACKET], chunk: &[u8]) -> [F32x8; 2] {
    let (low, high) = chunk.split_at(chunk.len().min(RAYS));
    // A block of eight or fewer: its last ray in every lane of the second group.
    let high = if high.is_empty() {
        &chunk[chunk.len() - 1..]
    } else {
        high
    };
    [lanes_of::<AVX>(values, low), lanes_of::<AVX>(values, high)]
}

/// The six axis permutations of a sheared ray ([`ShearedRay::permutation`]).
const PERMUTATIONS: usize = 6;

/// Ray constants moved into vectors in registers (AVX2).
#[cfg(target_arch = "x86_64")]
mod transposed {
    use std::arch::x86_64::*;

    use super::super::ShearedRay;
    use super::{PACKET, RAYS};
    use crate::simd::F32x8;

    /// The origins and shears of eight rays as rows (`origin[axis]` lane `l` is ray `l`'s).
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn rows(rays: &[&ShearedRay; RAYS]) -> ([F32x8; 3], [F32x8; 3]) {
        // SAFETY: a `ShearedRay` is 32 initialised bytes (no padding: its `filler`), 32-byte
        // aligned (`repr(C, align(32))`), its first six floats its origin and shear; the
        // last two lanes (the tie offset; the axes and the filler) are loaded and dropped.
        let r = rays.map(|ray| unsafe { _mm256_load_ps((ray as *const ShearedRay).cast()) });
        // The textbook 8 x 8 transpose: pairs, quads, then halves.
        let t0 = _mm256_unpacklo_ps(r[0], r[1]);
        let t1 = _mm256_unpackhi_ps(r[0], r[1]);
        let t2 = _mm256_unpacklo_ps(r[2], r[3]);
        let t3 = _mm256_unpackhi_ps(r[2], r[3]);
        let t4 = _mm256_unpacklo_ps(r[4], r[5]);
        let t5 = _mm256_unpackhi_ps(r[4], r[5]);
        let t6 = _mm256_unpacklo_ps(r[6], r[7]);
        let t7 = _mm256_unpackhi_ps(r[6], r[7]);
        let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
        let u1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
        let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
        let u3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
        let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
        let u5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
        let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
        let u7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
        let column = [
            _mm256_permute2f128_ps::<0x20>(u0, u4),
            _mm256_permute2f128_ps::<0x20>(u1, u5),
            _mm256_permute2f128_ps::<0x20>(u2, u6),
            _mm256_permute2f128_ps::<0x20>(u3, u7),
            _mm256_permute2f128_ps::<0x31>(u0, u4),
            _mm256_permute2f128_ps::<0x31>(u1, u5),
        ];
        let row = |c: usize| {
            let mut out = F32x8::default();
            // SAFETY: `F32x8` is 32 bytes, 32-byte aligned.
            unsafe { _mm256_store_ps(out.0.as_mut_ptr(), column[c]) };
            out
        };
        ([row(0), row(1), row(2)], [row(3), row(4), row(5)])
    }

    /// `values[index[l]]` in lane `l`, built in a register.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn from_indices(values: &[f32; PACKET], index: [u8; RAYS]) -> F32x8 {
        // Wrapped into `values` (a no-op for a packet's ray numbers): no bounds checks.
        const _: () = assert!(PACKET.is_power_of_two());
        let v = index.map(|r| values[r as usize & (PACKET - 1)]);
        let mut out = F32x8::default();
        // SAFETY: `out` is 32 bytes, 32-byte aligned.
        unsafe {
            _mm256_store_ps(
                out.0.as_mut_ptr(),
                _mm256_setr_ps(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]),
            )
        };
        out
    }
}

/// The test across sixteen rays at once where the CPU has AVX-512: per lane the operations
/// of [`ShearedLanes::intersect`] in the same order on the same operands, so the same bits.
/// A whole leaf is tested in one call (a call per triangle, or 16-lane values passed
/// through memory, cost more than the wider test saved).
#[cfg(target_arch = "x86_64")]
pub mod sixteen {
    use std::arch::x86_64::*;

    use glam::Vec2;

    use super::super::{
        LANES, PackedTriangles, ShearedRay, ShearedRows, TrianglePack, intersect_beyond_f32,
    };
    use super::{PACKET, RAYS, edge_function_f64};
    use crate::simd::F32x8;

    /// Rays per group.
    pub const WIDE: usize = 2 * RAYS;

    /// Tests each triangle of the leaf `first_pack`, `count` against the rays `chunk`
    /// (indices into `sheared`, 1 to [`WIDE`] of them, sharing one permutation) whose bits
    /// are set in `live` (bit `l` for `chunk[l]`), ray `l` of the chunk cut at lane `l` of
    /// `cut` (its limit, as [`block_lanes_of`] lays a packet's limits out: a copy, so the
    /// caller's limits are free for `hit` to lower); calls `hit(l, slot, source, t, bary)`
    /// for every such ray and triangle that cross, in the leaf's order, until `hit`
    /// returns false for a ray (an any-hit query that has stopped it): that ray is tested
    /// no further, and the leaf ends when no ray is left. Returns the rays of `live` still
    /// live (`hit` is never called for a ray after it returned false for it).
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub unsafe fn hits_in_leaf(
        triangles: &PackedTriangles,
        sheared: &[ShearedRay; PACKET],
        chunk: &[u8],
        live: u16,
        cut: &[F32x8; 2],
        first_pack: u32,
        count: u32,
        mut hit: impl FnMut(usize, u32, u32, f32, Vec2) -> bool,
    ) -> u16 {
        assert!(
            (1..=WIDE).contains(&chunk.len()),
            "{} rays in a lane group",
            chunk.len()
        );
        let last = chunk[chunk.len() - 1] as usize;
        let index = |l: usize| chunk.get(l).map_or(last, |&r| r as usize);
        let ray = |l: usize| &sheared[index(l)];
        let k = ray(0).k.map(usize::from);
        debug_assert!((0..WIDE).all(|l| ray(l).k == ray(0).k), "one permutation");
        // Two groups of eight, each transposed in registers (`ShearedLanes::of_rays`), then
        // joined: built lane by lane through memory, the rows stall on store forwarding.
        let half = |from: usize| std::array::from_fn::<_, RAYS, _>(|l| ray(from + l));
        // SAFETY: AVX-512F implies AVX2.
        let (low, high) = unsafe {
            (
                super::transposed::rows(&half(0)),
                super::transposed::rows(&half(RAYS)),
            )
        };
        let join = |lo: &F32x8, hi: &F32x8| {
            // SAFETY: `F32x8` is 32 bytes, 32-byte aligned.
            let (lo, hi) =
                unsafe { (_mm256_load_ps(lo.0.as_ptr()), _mm256_load_ps(hi.0.as_ptr())) };
            _mm512_castpd_ps(_mm512_insertf64x4::<1>(
                _mm512_castpd256_pd512(_mm256_castps_pd(lo)),
                _mm256_castps_pd(hi),
            ))
        };
        let cut = join(&cut[0], &cut[1]);
        let group = Group {
            k,
            origin: [0, 1, 2].map(|axis| join(&low.0[axis], &high.0[axis])),
            shear: [0, 1, 2].map(|axis| join(&low.1[axis], &high.1[axis])),
            cut,
        };
        let live = live & ((1u32 << chunk.len()) - 1) as u16;
        group.test_leaf(triangles, live, first_pack, count, &mut hit)
    }

    /// [`hits_in_leaf`] for the rays `at..at + len` of a packet (`len` 1 to [`WIDE`], `at`
    /// a multiple of [`WIDE`]) sharing the permutation `k`, their frames taken from the
    /// packet's rows (`rows`, filled by `ShearedRay::fill_with_rows` with the frames
    /// `hits_in_leaf` would read) and their limits from `cut` (a copy of the packet's
    /// limits `at..at + WIDE`, so they are free for `hit` to lower): the same lanes, so
    /// the same tests and calls (lanes past `len` are never live).
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub unsafe fn hits_in_leaf_of_rows(
        triangles: &PackedTriangles,
        rows: &ShearedRows,
        k: [u8; 3],
        at: usize,
        len: usize,
        live: u16,
        cut: &[f32; WIDE],
        first_pack: u32,
        count: u32,
        mut hit: impl FnMut(usize, u32, u32, f32, Vec2) -> bool,
    ) -> u16 {
        assert!(
            (1..=WIDE).contains(&len) && at % WIDE == 0 && at + WIDE <= PACKET,
            "rays {at}..{} of a packet",
            at + len
        );
        let [origin, shear] = [rows.origin(), rows.shear()];
        // SAFETY: `at + WIDE <= PACKET` (asserted), so each load reads sixteen floats of its
        // row; unaligned loads need no alignment.
        let load = |row: &[f32; PACKET]| unsafe { _mm512_loadu_ps(row.as_ptr().add(at)) };
        let group = Group {
            k: k.map(usize::from),
            origin: origin.each_ref().map(load),
            shear: shear.each_ref().map(load),
            // SAFETY: sixteen floats; unaligned loads need no alignment.
            cut: unsafe { _mm512_loadu_ps(cut.as_ptr()) },
        };
        let live = live & ((1u32 << len) - 1) as u16;
        group.test_leaf(triangles, live, first_pack, count, &mut hit)
    }

    /// Up to sixteen rays of one permutation as vector rows, and their limits.
    struct Group {
        k: [usize; 3],
        origin: [__m512; 3],
        shear: [__m512; 3],
        cut: __m512,
    }

    impl Group {
        /// Each triangle of the leaf `first_pack`, `count` against the rays `live`, in the
        /// leaf's order, until no ray is left (see [`hits_in_leaf`]); returns the rays still
        /// live.
        #[inline]
        #[target_feature(enable = "avx512f")]
        fn test_leaf(
            &self,
            triangles: &PackedTriangles,
            mut live: u16,
            first_pack: u32,
            count: u32,
            hit: &mut impl FnMut(usize, u32, u32, f32, Vec2) -> bool,
        ) -> u16 {
            let first_pack = first_pack as usize;
            let packs = (count as usize).div_ceil(LANES);
            for pack in &triangles.packs[first_pack..first_pack + packs] {
                for lane in 0..pack.live as usize {
                    live = self.intersect(live, pack, lane, hit);
                    if live == 0 {
                        return 0;
                    }
                }
            }
            live
        }

        #[inline]
        #[target_feature(enable = "avx512f")]
        fn sheared_vertex(&self, pack: &TrianglePack, i: usize, lane: usize) -> [__m512; 3] {
            let [kx, ky, kz] = self.k;
            let v = &pack.v[i];
            let z = _mm512_sub_ps(_mm512_set1_ps(v[kz][lane]), self.origin[kz]);
            let x = _mm512_sub_ps(
                _mm512_sub_ps(_mm512_set1_ps(v[kx][lane]), self.origin[kx]),
                _mm512_mul_ps(self.shear[0], z),
            );
            let y = _mm512_sub_ps(
                _mm512_sub_ps(_mm512_set1_ps(v[ky][lane]), self.origin[ky]),
                _mm512_mul_ps(self.shear[1], z),
            );
            [x, y, z]
        }

        /// The triangle `lane` of `pack` against the rays `live` (bit `l` for lane `l`):
        /// `hit` for each that crosses it; returns the rays still live (those `hit` did
        /// not stop).
        #[inline]
        #[target_feature(enable = "avx512f")]
        fn intersect(
            &self,
            mut live: u16,
            pack: &TrianglePack,
            lane: usize,
            hit: &mut impl FnMut(usize, u32, u32, f32, Vec2) -> bool,
        ) -> u16 {
            let [ax, ay, az] = self.sheared_vertex(pack, 0, lane);
            let [bx, by, bz] = self.sheared_vertex(pack, 1, lane);
            let [cx, cy, cz] = self.sheared_vertex(pack, 2, lane);
            let edge = |p: __m512, q: __m512, r: __m512, s: __m512| {
                _mm512_sub_ps(_mm512_mul_ps(p, q), _mm512_mul_ps(r, s))
            };
            let mut u = edge(cx, by, cy, bx);
            let mut v = edge(ax, cy, ay, cx);
            let mut w = edge(bx, ay, by, ax);
            let zero = _mm512_setzero_ps();
            // A vector's sixteen lanes, for the paths that take rays one by one.
            let row = |x: __m512| {
                let mut out = [0.0f32; WIDE];
                // SAFETY: `out` holds sixteen floats.
                unsafe { _mm512_storeu_ps(out.as_mut_ptr(), x) };
                out
            };
            let is_zero = |x: __m512| _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(x, zero);
            let on_edge = (is_zero(u) | is_zero(v) | is_zero(w)) & live;
            if on_edge != 0 {
                // Exactly on an edge in f32: decided in f64 (rare), as the pack test does.
                let [ax, ay, bx, by, cx, cy] = [ax, ay, bx, by, cx, cy].map(row);
                let (mut ur, mut vr, mut wr) = (row(u), row(v), row(w));
                let mut bits = on_edge;
                while bits != 0 {
                    let l = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    ur[l] = edge_function_f64(cx[l], by[l], cy[l], bx[l]);
                    vr[l] = edge_function_f64(ax[l], cy[l], ay[l], cx[l]);
                    wr[l] = edge_function_f64(bx[l], ay[l], by[l], ax[l]);
                }
                // SAFETY: sixteen floats each.
                unsafe {
                    u = _mm512_loadu_ps(ur.as_ptr());
                    v = _mm512_loadu_ps(vr.as_ptr());
                    w = _mm512_loadu_ps(wr.as_ptr());
                }
            }
            let lt = |x: __m512| _mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, zero);
            let gt = |x: __m512| _mm512_cmp_ps_mask::<_CMP_GT_OQ>(x, zero);
            let negative = lt(u) | lt(v) | lt(w);
            let positive = gt(u) | gt(v) | gt(w);
            let det = _mm512_add_ps(_mm512_add_ps(u, v), w);
            let inside =
                !(negative & positive) & _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(det, zero) & live;
            if inside == 0 {
                return live;
            }
            let sz = self.shear[2];
            let t_scaled = _mm512_add_ps(
                _mm512_add_ps(
                    _mm512_mul_ps(u, _mm512_mul_ps(sz, az)),
                    _mm512_mul_ps(v, _mm512_mul_ps(sz, bz)),
                ),
                _mm512_mul_ps(w, _mm512_mul_ps(sz, cz)),
            );
            let inverse = _mm512_div_ps(_mm512_set1_ps(1.0), det);
            let t = _mm512_mul_ps(t_scaled, inverse);
            let (bv, bw) = (_mm512_mul_ps(v, inverse), _mm512_mul_ps(w, inverse));
            let finite = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(_mm512_sub_ps(det, det), zero)
                & _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(_mm512_sub_ps(t_scaled, t_scaled), zero);
            // `0 <= t < cut` with `t` finite, per lane in one mask (the scalar test's
            // ordered comparisons: a NaN or infinite `t` is refused as it was lane by lane).
            let accepted = finite
                & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(zero, t)
                & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(t, self.cut)
                & _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(_mm512_sub_ps(t, t), zero);
            let (t, bv, bw, cut) = (row(t), row(bv), row(bw), row(self.cut));
            let mut bits = inside & (accepted | !finite);
            while bits != 0 {
                let l = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let (slot, source) = (pack.first_slot + lane as u32, pack.source[lane]);
                // Two calls rather than one on an `Option` of both paths' answers: that
                // went through the stack and stalled on reading its pieces back.
                let goes_on = if finite & (1 << l) != 0 {
                    hit(l, slot, source, t[l], Vec2::new(bv[l], bw[l]))
                } else {
                    let t_max = cut[l];
                    let origin = self.origin.map(|axis| row(axis)[l]);
                    let shear = self.shear.map(|axis| row(axis)[l]);
                    let k = self.k.map(|axis| axis as u8);
                    match intersect_beyond_f32(origin, shear, k, pack, lane, t_max) {
                        Some((t, bary)) => hit(l, slot, source, t, bary),
                        None => true,
                    }
                };
                if !goes_on {
                    live &= !(1 << l);
                }
            }
            live
        }
    }
}

/// `p q - r s`, one of Woop's edge functions.
#[inline(always)]
fn edge_function<const AVX: bool>(p: F32x8, q: F32x8, r: F32x8, s: F32x8) -> F32x8 {
    p.mul::<AVX>(q).sub::<AVX>(r.mul::<AVX>(s))
}

/// An edge function recomputed in f64 and rounded once (for a lane where it was exactly 0).
#[inline(always)]
pub(super) fn edge_function_f64(p: f32, q: f32, r: f32, s: f32) -> f32 {
    (p as f64 * q as f64 - r as f64 * s as f64) as f32
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;

    use super::*;
    use crate::simd;

    /// Runs `intersect` in one copy (a kernel, so the AVX2 copy runs where there is one).
    struct Intersect<'a> {
        group: &'a ShearedLanes,
        pack: &'a TrianglePack,
        lane: usize,
        t_max: F32x8,
        live: u32,
    }

    impl simd::Kernel for Intersect<'_> {
        type Output = LaneHits;
        #[inline(always)]
        fn run<const AVX2: bool>(self) -> LaneHits {
            self.group
                .intersect::<AVX2>(self.pack, self.lane, &self.t_max, self.live)
        }
    }

    fn xorshift(state: &mut u64) -> f32 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        (*state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    }

    /// Tests each triangle of `pack` across the rays `rays` (ray `r` cut at `limits[r]`),
    /// grouped by permutation, in every copy (baseline always, AVX2 where the CPU has it),
    /// and checks every lane against the ray alone against the pack: mask, distance and
    /// barycentric bits, and no hit past the group. Returns how many ray-triangle pairs
    /// were compared and the distance of every hit.
    fn check_against_each_ray_alone(
        rays: &[ShearedRay],
        limits: &[f32],
        pack: &TrianglePack,
        round: usize,
    ) -> (usize, Vec<f32>) {
        let (mut compared, mut distances) = (0, Vec::new());
        for code in 0..6 {
            let members: Vec<usize> = (0..rays.len())
                .filter(|&i| rays[i].permutation() == code)
                .collect();
            if members.is_empty() {
                continue;
            }
            let group = ShearedLanes::gather(members.iter().map(|&i| &rays[i]));
            let t_max = F32x8(std::array::from_fn(|l| {
                limits[members[l.min(members.len() - 1)]]
            }));
            for lane in 0..4 {
                // Every lane, or some (a packet's fixed group with rays outside the leaf).
                let live = if round % 3 == 0 {
                    (0x9e37_79b9u32.wrapping_mul((round * 4 + lane) as u32 + 1) >> 13) & 0xff
                } else {
                    u32::MAX
                };
                let run = |avx2: bool| {
                    let k = Intersect {
                        group: &group,
                        pack,
                        lane,
                        t_max,
                        live,
                    };
                    if avx2 {
                        simd::run_avx2_if_available(k)
                    } else {
                        Some(simd::run_baseline(k))
                    }
                };
                for hits in [run(false), run(true)].into_iter().flatten() {
                    for (l, &r) in members.iter().enumerate() {
                        let alone = rays[r].intersect_pack(pack, 4, limits[r]);
                        let hit_alone = alone.mask & (1 << lane) != 0 && live & (1 << l) != 0;
                        assert_eq!(
                            hits.mask & (1 << l) != 0,
                            hit_alone,
                            "round {round} ray {r} lane {lane}"
                        );
                        if hit_alone {
                            assert_eq!(hits.t[l].to_bits(), alone.t[lane].to_bits());
                            assert_eq!(hits.bary[l].x.to_bits(), alone.bary[lane].x.to_bits());
                            assert_eq!(hits.bary[l].y.to_bits(), alone.bary[lane].y.to_bits());
                            distances.push(alone.t[lane]);
                        }
                        compared += 1;
                    }
                    assert_eq!(
                        hits.mask >> members.len(),
                        0,
                        "lanes past the group hit nothing"
                    );
                }
            }
        }
        (compared, distances)
    }

    /// Random triangles against random rays, grouped by permutation: every lane of every
    /// copy (baseline always, AVX2 where the CPU has it) finds exactly what the ray finds
    /// alone against the pack (mask, distance and barycentric bits). Includes rays through
    /// shared vertices and edges (the f64 recomputation) and rays with limits.
    #[test]
    fn across_rays_equals_one_ray_at_a_time() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || xorshift(&mut s);
        let (mut compared, mut hit, mut edges) = (0, 0, 0);
        for round in 0..400 {
            let mut pack = TrianglePack::default();
            // A fan around one shared vertex: rays aimed at it cross exact edges.
            let centre = Vec3A::new(next(), next(), next() - 3.0);
            for lane in 0..4 {
                let a = centre + Vec3A::new(next(), next(), next()) * 2.0;
                let b = centre + Vec3A::new(next(), next(), next()) * 2.0;
                pack.set(lane, &[centre, a, b]);
            }
            let origin = Vec3A::new(next(), next(), next()) * 0.5;
            let rays: Vec<ShearedRay> = (0..RAYS)
                .map(|i| {
                    let target = if round % 3 == 0 && i % 2 == 0 {
                        centre
                    } else {
                        centre + Vec3A::new(next(), next(), next()) * 1.5
                    };
                    let o = if round % 2 == 0 {
                        origin
                    } else {
                        origin + Vec3A::new(next(), next(), next())
                    };
                    ShearedRay::new(o, target - o)
                })
                .collect();
            let limits: [f32; RAYS] =
                std::array::from_fn(|i| if i % 3 == 0 { 2.5 } else { f32::INFINITY });
            let (n, distances) = check_against_each_ray_alone(&rays, &limits, &pack, round);
            compared += n;
            hit += distances.len();
            edges += usize::from(round % 3 == 0);
        }
        assert!(
            compared > 10_000 && hit > 1_000 && edges > 100,
            "{compared} compared, {hit} hits"
        );
    }

    /// Runs `of_rays` and `lanes_of` on one chunk in one copy (a kernel, so the AVX2 copy
    /// runs where there is one).
    struct OfRays<'a> {
        sheared: &'a [ShearedRay; PACKET],
        values: &'a [f32; PACKET],
        chunk: &'a [u8],
    }

    impl simd::Kernel for OfRays<'_> {
        type Output = (ShearedLanes, F32x8);
        #[inline(always)]
        fn run<const AVX2: bool>(self) -> (ShearedLanes, F32x8) {
            (
                ShearedLanes::of_rays::<AVX2>(self.sheared, self.chunk),
                lanes_of::<AVX2>(self.values, self.chunk),
            )
        }
    }

    /// A packet's rays of mixed permutations, any subset of them: the runs hold every ray
    /// once, each run one permutation, in ray order within it; and every chunk's lanes and
    /// limits, in each copy (the transposed and gathered ones in the AVX2 copy), are the
    /// bits `gather` and a lane-by-lane read give.
    #[test]
    fn lane_groups_from_a_packet_equal_the_lane_by_lane_ones() {
        let mut s = 0x51a7_3c2d_9e11_04b7u64;
        let mut next = || xorshift(&mut s);
        let mut chunks = 0;
        for round in 0..300 {
            let sheared: [ShearedRay; PACKET] = std::array::from_fn(|_| {
                // Mostly one way (one permutation), sometimes any way.
                let d = if round % 2 == 0 {
                    Vec3A::new(next() * 0.3, next() * 0.3, -1.0)
                } else {
                    Vec3A::new(next(), next(), next())
                };
                ShearedRay::new(Vec3A::new(next(), next(), next()) * 10.0, d)
            });
            let values: [f32; PACKET] = std::array::from_fn(|_| next() * 100.0);
            let rays: Vec<u8> = (0..PACKET as u8)
                .filter(|_| round % 5 == 0 || next() > 0.0)
                .collect();
            let mut buffer = [0u8; PACKET];
            let (order, runs) = runs_by_permutation(&sheared, &rays, &mut buffer);
            let mut sorted = order.to_vec();
            sorted.sort_unstable();
            assert_eq!(sorted, rays, "round {round}: every ray once");
            let mut at = 0;
            for run in runs {
                let run_rays = &order[at..at + run];
                at += run;
                assert!(
                    run_rays.windows(2).all(|w| w[0] < w[1]),
                    "ray order in a run"
                );
                assert!(
                    run_rays
                        .iter()
                        .all(|&r| sheared[r as usize].k == sheared[run_rays[0] as usize].k),
                    "one permutation per run"
                );
                for chunk in run_rays.chunks(RAYS) {
                    let expected =
                        ShearedLanes::gather(chunk.iter().map(|&r| &sheared[r as usize]));
                    let limit = |l: usize| values[chunk[l.min(chunk.len() - 1)] as usize];
                    let kernel = || OfRays {
                        sheared: &sheared,
                        values: &values,
                        chunk,
                    };
                    let copies = [
                        Some(simd::run_baseline(kernel())),
                        simd::run_avx2_if_available(kernel()),
                    ];
                    for (lanes, limits) in copies.into_iter().flatten() {
                        assert_eq!(lanes.k, expected.k);
                        assert_eq!(lanes.live, expected.live);
                        for axis in 0..3 {
                            for l in 0..RAYS {
                                assert_eq!(
                                    lanes.origin[axis].0[l].to_bits(),
                                    expected.origin[axis].0[l].to_bits()
                                );
                                assert_eq!(
                                    lanes.shear[axis].0[l].to_bits(),
                                    expected.shear[axis].0[l].to_bits()
                                );
                            }
                        }
                        for l in 0..RAYS {
                            assert_eq!(limits.0[l].to_bits(), limit(l).to_bits(), "lane {l}");
                        }
                    }
                    chunks += 1;
                }
            }
            assert_eq!(at, rays.len());
        }
        assert!(chunks > 1_000, "{chunks} chunks");
    }

    /// A block of a packet's rows is the group [`ShearedLanes::of_rays`] makes of the same
    /// rays, in both copies, for every packet size and every block of eight in it.
    #[test]
    fn a_block_of_the_packets_rows_is_the_gathered_group() {
        let mut s = 0x6a09_e667_f3bc_c908u64;
        let mut next = || xorshift(&mut s);
        let bits = |g: &ShearedLanes| {
            let rows = g.origin.iter().chain(&g.shear);
            (
                g.k,
                g.live,
                rows.flat_map(|r| r.0.map(f32::to_bits)).collect::<Vec<_>>(),
            )
        };
        let mut compared = 0;
        for n in 1..=PACKET {
            // One direction's signs for all, so that blocks share their permutation.
            let rays: Vec<(Vec3A, Vec3A)> = (0..n)
                .map(|_| {
                    let o = Vec3A::new(next(), next(), next()) * 1e3;
                    (
                        o,
                        Vec3A::new(0.3 * next(), 0.3 * next(), -1.0 - next().abs()),
                    )
                })
                .collect();
            let mut sheared = [ShearedRay::default(); PACKET];
            let mut rows = super::super::ShearedRows::default();
            ShearedRay::fill_with_rows(&mut sheared, &mut rows, &rays);
            for at in (0..n).step_by(RAYS) {
                let len = RAYS.min(n - at);
                let chunk: Vec<u8> = (at..at + len).map(|r| r as u8).collect();
                let block = ShearedLanes::of_row_block(&rows, sheared[at].k(), at, len);
                assert_eq!(
                    bits(&block),
                    bits(&ShearedLanes::of_rays::<false>(&sheared, &chunk))
                );
                if simd::Isa::cpu_has_avx2() {
                    let avx2 = ShearedLanes::of_rays::<true>(&sheared, &chunk);
                    assert_eq!(bits(&block), bits(&avx2), "{n} rays, block at {at}");
                }
                compared += 1;
            }
        }
        assert_eq!(
            compared,
            (1..=PACKET).map(|n| n.div_ceil(RAYS)).sum::<usize>()
        );
    }

    /// Twelve triangles around a random centre (coordinates scaled by `scale`), half of them
    /// sharing the centre as a vertex: a leaf for the sixteen-ray tests. Returns the centre
    /// and the leaf, packed.
    #[cfg(target_arch = "x86_64")]
    fn leaf_around(
        next: &mut impl FnMut() -> f32,
        scale: f32,
    ) -> (Vec3A, super::super::PackedTriangles) {
        let centre = Vec3A::new(next(), next(), -3.0 + next()) * scale;
        let triangles: Vec<[Vec3A; 3]> = (0..12)
            .map(|i| {
                let a = centre + Vec3A::new(next(), next(), next()) * 2.0 * scale;
                let b = centre + Vec3A::new(next(), next(), next()) * 2.0 * scale;
                let first = if i % 2 == 0 { centre } else { a - b * 0.1 };
                [first, a, b]
            })
            .collect();
        let packed = super::super::PackedTriangles::pack(&triangles, std::iter::once((0, 12)));
        (centre, packed)
    }

    /// Limits for a packet's rays around a [`leaf_around`] of that `scale`: every third ray
    /// cut inside the leaf, the others unlimited.
    #[cfg(target_arch = "x86_64")]
    fn some_rays_cut(scale: f32) -> [f32; PACKET] {
        std::array::from_fn(|i| {
            if i % 3 == 0 {
                2.5 * scale
            } else {
                f32::INFINITY
            }
        })
    }

    /// The test across sixteen rays (AVX-512) against each ray alone, on leaves of three
    /// packs: fans around a shared vertex (exact edges, the f64 recomputation), random
    /// triangles, and triangles so far that f32 overflows (the f64 fallback); groups of 1 to
    /// 16 rays of one permutation, some cut short. Every hit (ray, slot, source, distance and
    /// barycentric bits) and no other.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn sixteen_rays_at_once_equal_each_ray_alone() {
        if !simd::Isa::cpu_has_avx512() {
            eprintln!("skipped: this CPU has no AVX-512");
            return;
        }
        let mut s = 0x7f4a_7c15_9e37_79b9u64;
        let mut next = || xorshift(&mut s);
        let (mut compared, mut hit, mut beyond) = (0usize, 0usize, 0usize);
        for round in 0..400 {
            let scale = [1.0f32, 1.0, 1.0, 1e20][round % 4];
            let (centre, packed) = leaf_around(&mut next, scale);
            let origin = Vec3A::new(next(), next(), next()) * 0.5;
            let sheared: [ShearedRay; PACKET] = std::array::from_fn(|i| {
                let target = if round % 3 == 0 && i % 2 == 0 {
                    centre
                } else {
                    centre + Vec3A::new(next(), next(), next()) * 1.5 * scale
                };
                let o = if round % 2 == 0 {
                    origin
                } else {
                    origin + Vec3A::new(next(), next(), next())
                };
                ShearedRay::new(o, target - o)
            });
            let limits = some_rays_cut(scale);
            let rays: Vec<u8> = (0..PACKET as u8).collect();
            let mut buffer = [0u8; PACKET];
            let (order, runs) = runs_by_permutation(&sheared, &rays, &mut buffer);
            let mut at = 0;
            for run in runs {
                let run_rays = &order[at..at + run];
                at += run;
                let size = 1 + round % sixteen::WIDE;
                for chunk in run_rays.chunks(size) {
                    // Every lane, or some (a packet's fixed group with some rays outside
                    // the leaf's box).
                    let live = if round % 5 == 0 {
                        (next() * 65536.0) as i32 as u16
                    } else {
                        u16::MAX
                    };
                    let mut found = Vec::new();
                    // SAFETY: the CPU has AVX-512F (checked above).
                    unsafe {
                        sixteen::hits_in_leaf(
                            &packed,
                            &sheared,
                            chunk,
                            live,
                            &block_lanes_of::<true>(&limits, chunk),
                            0,
                            12,
                            |l, slot, source, t, bary| {
                                found.push((
                                    l,
                                    slot,
                                    source,
                                    t.to_bits(),
                                    bary.x.to_bits(),
                                    bary.y.to_bits(),
                                ));
                                true
                            },
                        )
                    };
                    let mut expected = Vec::new();
                    for (l, &r) in chunk.iter().enumerate() {
                        if live & (1 << l) == 0 {
                            continue;
                        }
                        let r = r as usize;
                        for pack in &packed.packs {
                            let alone =
                                sheared[r].intersect_pack(pack, pack.live as usize, limits[r]);
                            for lane in 0..pack.live as usize {
                                if alone.mask & (1 << lane) != 0 {
                                    expected.push((
                                        l,
                                        pack.first_slot + lane as u32,
                                        pack.source[lane],
                                        alone.t[lane].to_bits(),
                                        alone.bary[lane].x.to_bits(),
                                        alone.bary[lane].y.to_bits(),
                                    ));
                                    beyond += usize::from(
                                        !(alone.t[lane] * 0.0).is_finite() || scale > 1.0,
                                    );
                                }
                                compared += 1;
                            }
                        }
                    }
                    found.sort_unstable();
                    expected.sort_unstable();
                    assert_eq!(found, expected, "round {round}");
                    hit += expected.len();
                }
            }
        }
        assert!(
            compared > 100_000 && hit > 5_000 && beyond > 500,
            "{compared} compared, {hit} hits, {beyond} far"
        );
    }

    /// A packet's fixed group of sixteen rays tested from the packet's rows
    /// ([`sixteen::hits_in_leaf_of_rows`]) makes the same calls in the same order, and
    /// leaves the same rays live, as the group gathered from the rays' frames
    /// ([`sixteen::hits_in_leaf`]): whole and partial groups, some lanes out, hits that
    /// stop their ray, and huge coordinates.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn a_group_from_the_packets_rows_tests_as_the_gathered_group() {
        if !simd::Isa::cpu_has_avx512() {
            eprintln!("skipped: this CPU has no AVX-512");
            return;
        }
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || xorshift(&mut s);
        let (mut groups, mut calls, mut stopped) = (0usize, 0usize, 0usize);
        for round in 0..300 {
            let scale = [1.0f32, 1.0, 1.0, 1e20][round % 4];
            let (centre, packed) = leaf_around(&mut next, scale);
            let n = 1 + round % PACKET;
            let origin = Vec3A::new(next(), next(), next()) * 0.5;
            let rays: Vec<(Vec3A, Vec3A)> = (0..n)
                .map(|_| {
                    let o = if round % 2 == 0 {
                        origin
                    } else {
                        origin + Vec3A::new(next(), next(), next())
                    };
                    (
                        o,
                        centre + Vec3A::new(next(), next(), next()) * 1.5 * scale - o,
                    )
                })
                .collect();
            let mut sheared = [ShearedRay::default(); PACKET];
            let mut rows = super::super::ShearedRows::default();
            ShearedRay::fill_with_rows(&mut sheared, &mut rows, &rays);
            let limits = some_rays_cut(scale);
            for at in (0..n).step_by(sixteen::WIDE) {
                let len = sixteen::WIDE.min(n - at);
                let k = sheared[at].k();
                if sheared[at..at + len].iter().any(|ray| ray.k() != k) {
                    continue;
                }
                let live = if round % 5 == 0 {
                    (next() * 65536.0) as i32 as u16
                } else {
                    u16::MAX
                };
                // A ray stops at its second hit (an any-hit query's stop, exercised).
                let run = |from_rows: bool| {
                    let mut found = Vec::new();
                    let mut seen = [0u8; sixteen::WIDE];
                    let hit = |l: usize, slot: u32, source: u32, t: f32, bary: glam::Vec2| {
                        found.push((
                            l,
                            slot,
                            source,
                            t.to_bits(),
                            bary.x.to_bits(),
                            bary.y.to_bits(),
                        ));
                        seen[l] += 1;
                        seen[l] < 2
                    };
                    let chunk: Vec<u8> = (at..at + len).map(|r| r as u8).collect();
                    // SAFETY: the CPU has AVX-512F (checked above).
                    let left = unsafe {
                        if from_rows {
                            sixteen::hits_in_leaf_of_rows(
                                &packed,
                                &rows,
                                k,
                                at,
                                len,
                                live,
                                limits[at..at + sixteen::WIDE].try_into().unwrap(),
                                0,
                                12,
                                hit,
                            )
                        } else {
                            sixteen::hits_in_leaf(
                                &packed,
                                &sheared,
                                &chunk,
                                live,
                                &block_lanes_of::<true>(&limits, &chunk),
                                0,
                                12,
                                hit,
                            )
                        }
                    };
                    (found, left)
                };
                let (gathered, from_rows) = (run(false), run(true));
                assert_eq!(
                    from_rows,
                    gathered,
                    "round {round}, rays {at}..{}",
                    at + len
                );
                groups += 1;
                calls += gathered.0.len();
                stopped += (live & ((1u32 << len) - 1) as u16 & !gathered.1).count_ones() as usize;
            }
        }
        assert!(
            groups > 300 && calls > 1_500 && stopped > 200,
            "{groups} groups, {calls} calls, {stopped} rays stopped"
        );
    }

    /// Triangles so large and far (1e13 to 1e37) that the f32 edge functions or distance
    /// overflow: both tests decide them in f64 and agree bit for bit, and the rays aimed at
    /// them hit (in f32 alone they were missed).
    #[test]
    fn huge_triangles_are_hit_and_agree_across_rays() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = || xorshift(&mut s);
        let (mut compared, mut hit) = (0, 0);
        for round in 0..120 {
            let scale = [1e13f32, 1e20, 1e30, 1e37][round % 4];
            let mut pack = TrianglePack::default();
            for lane in 0..4 {
                // A big triangle facing the origin, about `scale` away along -z.
                let centre = Vec3A::new(next() * 0.3, next() * 0.3, -1.0 - next().abs()) * scale;
                let tri = [
                    centre + Vec3A::new(-2.0, -2.0, next() * 0.1) * scale,
                    centre + Vec3A::new(2.0, -2.0, next() * 0.1) * scale,
                    centre + Vec3A::new(0.0, 2.0, next() * 0.1) * scale,
                ];
                pack.set(lane, &tri);
            }
            let rays: Vec<ShearedRay> = (0..RAYS)
                .map(|_| {
                    let d = Vec3A::new(next() * 0.4, next() * 0.4, -1.0);
                    ShearedRay::new(Vec3A::new(next(), next(), next()), d)
                })
                .collect();
            let limits = [f32::INFINITY; RAYS];
            let (n, distances) = check_against_each_ray_alone(&rays, &limits, &pack, round);
            for t in &distances {
                assert!(t.is_finite() && *t > 0.5 * scale, "t {t} at {scale}");
            }
            compared += n;
            hit += distances.len();
        }
        assert!(
            compared > 2_000 && hit > 500,
            "{compared} compared, {hit} hits"
        );
    }
}
