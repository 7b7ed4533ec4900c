//! Triangles laid out for the hit test: four at a time, vertex coordinates as
//! structure-of-arrays lanes, leaf by leaf in slot order, tested with the watertight ray/triangle
//! algorithm of Woop, Benthin and Wald (JCGT 2013).
//!
//! Why watertight: Möller-Trumbore decides each triangle's edges on its own, so a ray
//! through a shared edge can be rejected by both neighbours (the unit test of a jittered
//! grid lost 9% of rays aimed at vertices and edge midpoints). Woop's test shears each
//! vertex into the ray's frame once and evaluates the edge functions on those shared
//! values, so two triangles see a shared edge with bit-identical inputs and cannot both
//! reject a point on it; an exactly-zero edge function is recomputed in f64, as the paper
//! does. Why four at a time: a leaf holds up to eight triangles, and four lanes of SSE2
//! (glam `Vec4`) test a pack for little more than the cost of one.
//!
//! Each leaf's triangles fill whole packs (a leaf of 5 takes two packs, the second with one
//! live lane), so a leaf is a run of packs and no pack straddles two leaves.

use std::ops::Range;

use glam::{Vec2, Vec3A, Vec4};
use obvhs::aabb::Aabb;

use crate::accel::wide::PACKET;

mod across_rays;
#[cfg(target_arch = "x86_64")]
mod two_packs;

#[cfg(target_arch = "x86_64")]
pub use across_rays::block_lanes_of;
#[cfg(target_arch = "x86_64")]
pub use across_rays::sixteen;
pub use across_rays::{RAYS, ShearedLanes, lanes_of, runs_by_permutation};

/// Triangles per pack.
pub const LANES: usize = 4;

/// Four triangles: `v[vertex][axis][lane]`, with the slot of lane 0 (lanes hold consecutive
/// slots), the number of live lanes and each lane's source triangle beside them, so a leaf
/// test reads nothing else (the source decides ties; read from a separate array it was a
/// cache miss per hit, 16% of the leaf test in a primary-ray profile).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(16))]
pub struct TrianglePack {
    v: [[[f32; LANES]; 3]; 3],
    source: [u32; LANES],
    first_slot: u32,
    live: u32,
}

impl TrianglePack {
    fn set(&mut self, lane: usize, tri: &[Vec3A; 3]) {
        for (vertex, p) in tri.iter().enumerate() {
            for axis in 0..3 {
                self.v[vertex][axis][lane] = p[axis];
            }
        }
    }

    /// `|e1 x e2|^2` of every lane's triangle in `f64` (padding lanes too), the bits
    /// `lod::cross_squared` gives each: the same operations in the same order, four lanes
    /// side by side so the compiler can take them in vectors (the `log2 P_b` pass of a
    /// deforming mesh was bound by this arithmetic, one triangle at a time).
    #[inline(always)]
    pub fn cross_squared(&self) -> [f64; LANES] {
        let c = |vertex: usize, axis: usize| self.v[vertex][axis].map(f64::from);
        let (x0, y0, z0) = (c(0, 0), c(0, 1), c(0, 2));
        let (x1, y1, z1) = (c(1, 0), c(1, 1), c(1, 2));
        let (x2, y2, z2) = (c(2, 0), c(2, 1), c(2, 2));
        let mut out = [0.0; LANES];
        for l in 0..LANES {
            // e1 = p1 - p0, e2 = p2 - p0; cross as glam's `DVec3::cross`, dot as `dot`.
            let (ax, ay, az) = (x1[l] - x0[l], y1[l] - y0[l], z1[l] - z0[l]);
            let (bx, by, bz) = (x2[l] - x0[l], y2[l] - y0[l], z2[l] - z0[l]);
            let cx = ay * bz - by * az;
            let cy = az * bx - bz * ax;
            let cz = ax * by - bx * ay;
            out[l] = (cx * cx) + (cy * cy) + (cz * cz);
        }
        out
    }

    /// The union of its live lanes' padded boxes (a leaf's box is the union over its packs).
    ///
    /// Each lane's [`padded_box`](crate::accel::padded_box) is computed for the four lanes at once, on the lanes as
    /// the pack holds them: the same operations in the same order per lane (`min`, `max`,
    /// `abs`, the largest component as `max_element` takes it, the pad), so the same bits;
    /// gathering each lane's vertices into vectors first was most of a leaf box's cost.
    /// The union then goes through the live lanes in order, as before (the vector `min`
    /// and `max` treat a NaN by position, so the order is kept).
    #[inline]
    pub fn live_box(&self) -> Aabb {
        let v = |vertex: usize, axis: usize| Vec4::from_array(self.v[vertex][axis]);
        let low = [0, 1, 2].map(|axis| v(0, axis).min(v(1, axis)).min(v(2, axis)));
        let high = [0, 1, 2].map(|axis| v(0, axis).max(v(1, axis)).max(v(2, axis)));
        let larger = |axis: usize| low[axis].abs().max(high[axis].abs());
        let magnitude = larger(0).max(larger(1)).max(larger(2));
        let pad = magnitude * 2f32.powi(-20) + f32::MIN_POSITIVE * 8.0;
        let low = low.map(|l| (l - pad).to_array());
        let high = high.map(|h| (h + pad).to_array());
        (0..self.live as usize).fold(Aabb::empty(), |a, lane| {
            a.union(&Aabb::new(
                Vec3A::new(low[0][lane], low[1][lane], low[2][lane]),
                Vec3A::new(high[0][lane], high[1][lane], high[2][lane]),
            ))
        })
    }

    #[inline]
    fn get(&self, lane: usize) -> [Vec3A; 3] {
        std::array::from_fn(|vertex| {
            Vec3A::new(
                self.v[vertex][0][lane],
                self.v[vertex][1][lane],
                self.v[vertex][2][lane],
            )
        })
    }
}

/// The packs of every leaf, and where each slot lives.
#[derive(Default, Clone)]
pub struct PackedTriangles {
    packs: Vec<TrianglePack>,
    /// Per slot: `pack * LANES + lane`.
    lane_of_slot: Vec<u32>,
}

impl PackedTriangles {
    /// Packs the triangles of `leaves` (`(first slot, count)`, covering every slot once),
    /// each slot its own source.
    #[cfg(test)]
    pub fn pack(positions: &[[Vec3A; 3]], leaves: impl Iterator<Item = (u32, u32)>) -> Self {
        let mut packed = PackedTriangles {
            lane_of_slot: vec![0; positions.len()],
            ..Default::default()
        };
        for (first, count) in leaves {
            packed.push_leaf(|slot| (positions[slot as usize], slot), first, count);
        }
        packed
    }

    /// No packs yet for `slots` slots, with room for exactly the packs of leaves of `counts`
    /// triangles (each leaf fills whole packs): pushing them never reallocates, and the
    /// array keeps no spare capacity (growing by doubling left up to half of it unused).
    pub fn with_pack_capacity(counts: impl Iterator<Item = u32>, slots: usize) -> Self {
        let packs: usize = counts.map(|c| (c as usize).div_ceil(LANES)).sum();
        PackedTriangles {
            packs: Vec::with_capacity(packs),
            lane_of_slot: vec![0; slots],
        }
    }

    /// Packs held.
    #[cfg(test)]
    pub fn pack_count(&self) -> usize {
        self.packs.len()
    }

    /// Packs the array has room for.
    #[cfg(test)]
    pub fn pack_capacity(&self) -> usize {
        self.packs.capacity()
    }

    /// Appends the packs of the leaf of `count` slots from `first` (`triangle(slot)`: the
    /// slot's vertices and its source triangle, which hits report for the tie rule);
    /// returns its first pack (what the tree stores for the leaf).
    pub fn push_leaf(
        &mut self,
        triangle: impl Fn(u32) -> ([Vec3A; 3], u32),
        first: u32,
        count: u32,
    ) -> u32 {
        let first_pack = self.packs.len() as u32;
        for start in (first..first + count).step_by(LANES) {
            let live = (first + count - start).min(LANES as u32);
            let pack = self.packs.len() as u32;
            let mut p = TrianglePack {
                first_slot: start,
                live,
                ..Default::default()
            };
            for lane in 0..live {
                let slot = start + lane;
                let (tri, source) = triangle(slot);
                p.set(lane as usize, &tri);
                p.source[lane as usize] = source;
                self.lane_of_slot[slot as usize] = pack * LANES as u32 + lane;
            }
            self.packs.push(p);
        }
        first_pack
    }

    /// The packs of the leaf of `count` slots from slot `first` (a leaf's first slot is
    /// lane 0 of its first pack).
    #[inline]
    pub fn leaf_packs(&self, first: u32, count: u32) -> &[TrianglePack] {
        let pack = self.lane_of_slot[first as usize] as usize / LANES;
        &self.packs[pack..pack + (count as usize).div_ceil(LANES)]
    }

    /// The union of the padded boxes of the leaf of `count` slots from slot `first`.
    #[inline]
    pub fn leaf_box(&self, first: u32, count: u32) -> Aabb {
        self.leaf_packs(first, count)
            .iter()
            .fold(Aabb::empty(), |a, p| a.union(&p.live_box()))
    }

    /// How many slots the packs hold.
    pub fn slots(&self) -> usize {
        self.lane_of_slot.len()
    }

    /// Writes `tri` into slot `slot`'s lane.
    pub fn set_triangle(&mut self, slot: u32, tri: &[Vec3A; 3]) {
        let at = self.lane_of_slot[slot as usize] as usize;
        self.packs[at / LANES].set(at % LANES, tri);
    }

    /// Slot `slot`'s pack and its lane there.
    #[inline(always)]
    fn pack_and_lane(&self, slot: u32) -> (&TrianglePack, usize) {
        let at = self.lane_of_slot[slot as usize] as usize;
        (&self.packs[at / LANES], at % LANES)
    }

    /// The stored triangle of `slot` (the bits that were written).
    #[inline]
    pub fn triangle(&self, slot: u32) -> [Vec3A; 3] {
        let (pack, lane) = self.pack_and_lane(slot);
        pack.get(lane)
    }

    /// The stored triangle of `slot` and the source triangle its lane reports for ties
    /// (what the builder's `triangle(slot)` gave, see [`PackedTriangles::push_leaf`]).
    #[inline]
    pub fn triangle_and_source(&self, slot: u32) -> ([Vec3A; 3], u32) {
        let (pack, lane) = self.pack_and_lane(slot);
        (pack.get(lane), pack.source[lane])
    }

    /// [`TrianglePack::cross_squared`] of slot `slot`'s pack, with the slots its live lanes
    /// hold: lane `i` holds slot `slots.start + i` (a pack's live lanes are consecutive
    /// slots).
    #[inline(always)]
    pub fn pack_cross_squared(&self, slot: u32) -> (Range<u32>, [f64; LANES]) {
        let (pack, _) = self.pack_and_lane(slot);
        let slots = pack.first_slot..pack.first_slot + pack.live;
        (slots, pack.cross_squared())
    }

    /// Slot `slot`'s pack, or `None` when out of range.
    #[inline(always)]
    fn pack_of_slot(&self, slot: u32) -> Option<&TrianglePack> {
        let &at = self.lane_of_slot.get(slot as usize)?;
        self.packs.get(at as usize / LANES)
    }

    /// Hints the cache to load slot `slot`'s pack (no effect when out of range).
    #[inline]
    pub fn prefetch_slot(&self, slot: u32) {
        if let Some(pack) = self.pack_of_slot(slot) {
            crate::simd::prefetch_ptr(pack);
        }
    }

    /// Hints the cache to load where slot `slot`'s pack is (its `lane_of_slot` entry), the
    /// read [`Self::prefetch_slot_pack`] depends on (no effect when out of range).
    #[inline(always)]
    pub fn prefetch_pack_index(&self, slot: u32) {
        crate::simd::prefetch(&self.lane_of_slot, slot as usize);
    }

    /// Hints the cache to load all the lines of slot `slot`'s pack (no effect when out of
    /// range): what a leaf box reads.
    #[inline(always)]
    pub fn prefetch_slot_pack(&self, slot: u32) {
        if let Some(pack) = self.pack_of_slot(slot) {
            // 176 bytes from a 16-byte boundary: three or four lines, its first and last
            // bytes' and those 64 and 128 bytes on.
            let start = (pack as *const TrianglePack).cast::<u8>();
            for offset in [0, 64, 128, size_of::<TrianglePack>() - 1] {
                crate::simd::prefetch_ptr(start.wrapping_add(offset));
            }
        }
    }

    /// Every slot's triangle, in slot order.
    pub fn triangles_in_slot_order(&self) -> Vec<[Vec3A; 3]> {
        (0..self.slots() as u32).map(|s| self.triangle(s)).collect()
    }

    /// Access to single slots from concurrent tasks (see [`SlotLanes`]).
    pub fn slot_lanes(&mut self) -> SlotLanes<'_> {
        SlotLanes {
            packs: self.packs.as_mut_ptr(),
            lane_of_slot: &self.lane_of_slot,
            _packs: std::marker::PhantomData,
        }
    }

    /// Tests the `count` triangles of the leaf whose packs start at `first_pack` and calls
    /// `hit(slot, source, t, bary)` for each one the ray crosses with `t` in `[0, t_max)`,
    /// pack by pack, lane by lane, until `hit` returns false (then returns false). In the
    /// AVX2 copy (`AVX`) a leaf of two packs is tested in one pass of eight lanes
    /// (`two_packs`), with the same hits in the same order.
    #[inline(always)]
    pub fn hits_in_leaf<const AVX: bool>(
        &self,
        ray: &ShearedRay,
        first_pack: u32,
        count: u32,
        t_max: f32,
        mut hit: impl FnMut(u32, u32, f32, Vec2) -> bool,
    ) -> bool {
        let first_pack = first_pack as usize;
        let packs = &self.packs[first_pack..first_pack + (count as usize).div_ceil(LANES)];
        #[cfg(target_arch = "x86_64")]
        if let (true, [low, high]) = (AVX, packs) {
            // SAFETY: `AVX` is true only in the copy `simd::dispatch` runs where the CPU has
            // AVX2 (and in tests that check the CPU first).
            let found = unsafe { two_packs::intersect(ray, [low, high], t_max) };
            let mut mask = found.mask;
            while mask != 0 {
                let l = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let (pack, lane) = (if l < LANES { low } else { high }, l % LANES);
                let slot = pack.first_slot + lane as u32;
                let bary = Vec2::new(found.u[l], found.v[l]);
                if !hit(slot, pack.source[lane], found.t[l], bary) {
                    return false;
                }
            }
            return true;
        }
        for pack in packs {
            let found = ray.intersect_pack(pack, pack.live as usize, t_max);
            let mut mask = found.mask;
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let slot = pack.first_slot + lane as u32;
                if !hit(slot, pack.source[lane], found.t[lane], found.bary[lane]) {
                    return false;
                }
            }
        }
        true
    }
}

/// Reads and writes of single slots' lanes from concurrent tasks (the frame update writes
/// moved triangles straight into the packs, on several threads, in source order: slots
/// scattered over the packs, two tasks possibly in two lanes of one pack).
///
/// Sound because a slot's access ([`Self::get`], [`Self::set`]) goes through the raw
/// pointer to one `f32` of its lane at a time (no reference to a whole pack is formed),
/// lanes of distinct slots are distinct memory (`lane_of_slot` is one-to-one), and the
/// caller keeps each slot to one task at a time. The one whole-pack access,
/// [`Self::rewrite_pack`], reads and stores every lane of a pack's vertex rows, dead lanes
/// included: its caller keeps every slot of that pack to its one task.
pub struct SlotLanes<'a> {
    packs: *mut TrianglePack,
    lane_of_slot: &'a [u32],
    _packs: std::marker::PhantomData<&'a mut [TrianglePack]>,
}

// SAFETY: the pointer comes from an exclusive borrow held for 'a; the contracts of `get` and
// `set` keep every slot to one task at a time (distinct slots never share a float), and
// that of `rewrite_pack` keeps a whole pack to one task.
unsafe impl Sync for SlotLanes<'_> {}

impl SlotLanes<'_> {
    /// How many slots there are.
    pub fn slots(&self) -> usize {
        self.lane_of_slot.len()
    }

    /// The pack and lane of `slot` (panics when out of range).
    #[inline]
    fn lane(&self, slot: u32) -> (*mut TrianglePack, usize) {
        let at = self.lane_of_slot[slot as usize] as usize;
        // SAFETY: `lane_of_slot` holds only lanes of packs that exist (`push_leaf`).
        (unsafe { self.packs.add(at / LANES) }, at % LANES)
    }

    /// Slot `slot`'s triangle.
    ///
    /// # Safety
    /// No task may write `slot` at the same time.
    #[inline]
    pub unsafe fn get(&self, slot: u32) -> [Vec3A; 3] {
        let (pack, lane) = self.lane(slot);
        // SAFETY: in bounds; element reads through the pointer, no reference to the pack.
        std::array::from_fn(|vertex| unsafe {
            Vec3A::new(
                (*pack).v[vertex][0][lane],
                (*pack).v[vertex][1][lane],
                (*pack).v[vertex][2][lane],
            )
        })
    }

    /// Writes `tri` into slot `slot`'s lane.
    ///
    /// # Safety
    /// No other task may read or write `slot` at the same time.
    #[inline]
    pub unsafe fn set(&self, slot: u32, tri: &[Vec3A; 3]) {
        let (pack, lane) = self.lane(slot);
        for (vertex, p) in tri.iter().enumerate() {
            for axis in 0..3 {
                // SAFETY: in bounds; this lane's floats belong to this slot alone.
                unsafe { (*pack).v[vertex][axis][lane] = p[axis] };
            }
        }
    }

    /// The box of the leaf of `count` slots from slot `first` (`PackedTriangles::leaf_box`,
    /// the same bits), read through the lanes.
    ///
    /// # Safety
    /// No task may write any of the leaf's slots at the same time (its packs hold its
    /// slots alone, so the packs are then read by this task only).
    #[inline]
    pub unsafe fn leaf_box(&self, first: u32, count: u32) -> Aabb {
        let pack = self.lane_of_slot[first as usize] as usize / LANES;
        (pack..pack + (count as usize).div_ceil(LANES)).fold(Aabb::empty(), |a, p| {
            // SAFETY: `lane_of_slot` holds only lanes of packs that exist and a leaf's packs
            // follow its first (`push_leaf`); no task writes them now (the caller's
            // contract), so a shared reference to each is sound.
            a.union(&unsafe { &*self.packs.add(p) }.live_box())
        })
    }

    /// How many live lanes the pack whose lane 0 holds slot `slot` has (`None` when `slot`
    /// lies in another lane): the slots `slot..slot + live` [`Self::rewrite_pack`] writes.
    #[inline]
    pub fn pack_from(&self, slot: u32) -> Option<u32> {
        let (pack, lane) = self.lane(slot);
        // SAFETY: in bounds; `live` is written by the build alone, never through the lanes,
        // so reading it races with nothing.
        (lane == 0).then(|| unsafe { (*pack).live })
    }

    /// Writes `tri[lane]` into each of the first `live` lanes of the pack whose lane 0
    /// holds slot `first` (its other lanes are read and stored back with their own bits)
    /// and returns two lane masks (bit
    /// `l` for lane `l`): the lanes whose bits changed (so -0 and 0 differ and a NaN equals
    /// itself, as the write's moved test has it), and those of them with a non-finite
    /// vertex. The same bits [`Self::set`] stores lane by lane; whole lanes are read,
    /// compared and stored as vectors (lane by lane, each slot's nine scalar reads and
    /// stores were the hottest part of a deforming mesh's write).
    ///
    /// # Safety
    /// No other task may read or write any part of that pack's vertex rows (any of its
    /// slots) at the same time, and `live` is at most its live lanes ([`Self::pack_from`]).
    #[inline(always)]
    pub unsafe fn rewrite_pack(
        &self,
        first: u32,
        live: u32,
        tri: &[[Vec3A; 3]; LANES],
    ) -> (u32, u32) {
        let (pack, lane) = self.lane(first);
        debug_assert_eq!(lane, 0, "slot {first} does not begin a pack");
        debug_assert!(live as usize <= LANES);
        // SAFETY: in bounds, and the pack's lanes are this task's alone (the contract).
        unsafe { rewrite_lanes(&raw mut (*pack).v, live, tri) }
    }

    /// Hints the cache to load the lines of slot `slot`'s lane (no effect when out of range).
    #[inline]
    pub fn prefetch(&self, slot: u32) {
        if let Some(&at) = self.lane_of_slot.get(slot as usize) {
            // SAFETY: in bounds (`lane`); only the address is formed, nothing is read.
            let (pack, lane) = (
                unsafe { self.packs.add(at as usize / LANES) },
                at as usize % LANES,
            );
            // The lane's nine floats lie on three or four of the pack's lines: per vertex,
            // its x and z (y lies between them). Hinting only the pack's first line left the
            // others to miss when the write read the lane (a million skinned triangles'
            // posing and writing ~5% faster with all of them hinted, AMD EPYC VM).
            for vertex in 0..3 {
                for axis in [0, 2] {
                    // SAFETY: in bounds; only the address is formed, nothing is read.
                    crate::simd::prefetch_ptr(unsafe { &raw const (*pack).v[vertex][axis][lane] });
                }
            }
        }
    }
}

/// [`SlotLanes::rewrite_pack`] on the pack's vertex lanes `v`: per vertex, the four
/// triangles' vertices turned into lanes (a 4x4 transpose), blended with the old lanes
/// past `live`, compared bit for bit and stored.
///
/// # Safety
/// `v` must point to a pack's vertex lanes that no other task accesses meanwhile.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn rewrite_lanes(
    v: *mut [[[f32; LANES]; 3]; 3],
    live: u32,
    tri: &[[Vec3A; 3]; LANES],
) -> (u32, u32) {
    use std::arch::x86_64::*;
    let live_bits = (1u32 << live) - 1;
    // SAFETY: SSE2 is part of x86_64; `v` is a pack's (16-byte aligned, `TrianglePack`) and
    // this task's alone (the contract), so its lanes can be loaded and stored whole.
    unsafe {
        let lanes = _mm_setr_epi32(0, 1, 2, 3);
        let written = _mm_castsi128_ps(_mm_cmplt_epi32(lanes, _mm_set1_epi32(live as i32)));
        let magnitude = _mm_castsi128_ps(_mm_set1_epi32(i32::MAX));
        let infinity = _mm_set1_ps(f32::INFINITY);
        let mut changed = _mm_setzero_si128();
        let mut finite = _mm_castps_si128(written);
        for (vertex, lanes_of_vertex) in (*v).iter_mut().enumerate() {
            let [r0, r1, r2, r3] = tri.map(|t| __m128::from(t[vertex]));
            let (t0, t1) = (_mm_unpacklo_ps(r0, r1), _mm_unpacklo_ps(r2, r3));
            let (t2, t3) = (_mm_unpackhi_ps(r0, r1), _mm_unpackhi_ps(r2, r3));
            let axes = [
                _mm_movelh_ps(t0, t1),
                _mm_movehl_ps(t1, t0),
                _mm_movelh_ps(t2, t3),
            ];
            for (axis, lane) in axes.into_iter().zip(lanes_of_vertex.iter_mut()) {
                let old = _mm_load_ps(lane.as_ptr());
                let new = _mm_or_ps(_mm_and_ps(written, axis), _mm_andnot_ps(written, old));
                let same = _mm_cmpeq_epi32(_mm_castps_si128(new), _mm_castps_si128(old));
                changed = _mm_or_si128(changed, _mm_xor_si128(same, _mm_set1_epi32(-1)));
                let bounded = _mm_cmplt_ps(_mm_and_ps(new, magnitude), infinity);
                finite = _mm_and_si128(finite, _mm_castps_si128(bounded));
                _mm_store_ps(lane.as_mut_ptr(), new);
            }
        }
        let changed = _mm_movemask_ps(_mm_castsi128_ps(changed)) as u32 & live_bits;
        let finite = _mm_movemask_ps(_mm_castsi128_ps(finite)) as u32;
        (changed, changed & !finite)
    }
}

/// [`SlotLanes::rewrite_pack`] lane by lane: the version for targets other than x86_64,
/// and the reference the x86_64 one is tested against.
///
/// # Safety
/// As the x86_64 version.
#[cfg(any(test, not(target_arch = "x86_64")))]
#[inline(always)]
unsafe fn rewrite_lanes_by_lane(
    v: *mut [[[f32; LANES]; 3]; 3],
    live: u32,
    tri: &[[Vec3A; 3]; LANES],
) -> (u32, u32) {
    let (mut changed, mut nonfinite) = (0, 0);
    // SAFETY: the contract: the lanes are this task's alone.
    let v = unsafe { &mut *v };
    for (l, t) in tri.iter().enumerate().take(live as usize) {
        let mut same = true;
        for vertex in 0..3 {
            for axis in 0..3 {
                same &= v[vertex][axis][l].to_bits() == t[vertex][axis].to_bits();
                v[vertex][axis][l] = t[vertex][axis];
            }
        }
        if !same {
            changed |= 1 << l;
            if !t.iter().all(|p| p.is_finite()) {
                nonfinite |= 1 << l;
            }
        }
    }
    (changed, nonfinite)
}

/// [`SlotLanes::rewrite_pack`] where there is no x86_64 SSE2: lane by lane.
#[cfg(not(target_arch = "x86_64"))]
use rewrite_lanes_by_lane as rewrite_lanes;

impl PackedTriangles {
    /// [`PackedTriangles::hits_in_leaf`] for a group of rays at once: each triangle of the
    /// leaf is tested across the rays of `rays` in the lanes `live` (`u32::MAX`: all; the
    /// same answers as each ray alone), and `hit(lane, slot, source, t, bary)` is called for
    /// every such ray and triangle that cross with `t` in `[0, t_max)` of that ray's lane,
    /// in the leaf's order, until `hit` returns false for a lane (an any-hit query that has
    /// stopped its ray): that lane is tested no further, and the leaf ends when no lane is
    /// left. Returns the lanes of `live` still live (`hit` is never called for a lane after
    /// it returned false for it).
    #[inline(always)]
    pub fn hits_in_leaf_across<const AVX: bool>(
        &self,
        rays: &ShearedLanes,
        mut live: u32,
        first_pack: u32,
        count: u32,
        t_max: &crate::simd::F32x8,
        mut hit: impl FnMut(usize, u32, u32, f32, Vec2) -> bool,
    ) -> u32 {
        let first_pack = first_pack as usize;
        let packs = (count as usize).div_ceil(LANES);
        for pack in &self.packs[first_pack..first_pack + packs] {
            for lane in 0..pack.live as usize {
                let found = rays.intersect::<AVX>(pack, lane, t_max, live);
                let mut mask = found.mask;
                while mask != 0 {
                    let l = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let slot = pack.first_slot + lane as u32;
                    if !hit(l, slot, pack.source[lane], found.t[l], found.bary[l]) {
                        live &= !(1 << l);
                    }
                }
                if live == 0 {
                    return 0;
                }
            }
        }
        live
    }
}

/// A ray in the frame of Woop et al.: the axis where the direction is largest becomes z, and
/// a shear maps the direction to (0, 0, 1). (`Default`: an all-zero placeholder for unused
/// packet slots, never tested.)
///
/// Kept as scalars (32 bytes) and splatted where a pack test uses them, for the reason
/// `RayBoxes` is: packets make 64 of them at a time.
#[derive(Clone, Copy, Default)]
#[repr(C, align(32))]
pub struct ShearedRay {
    origin: [f32; 3],
    /// `(dx / dz, dy / dz, 1 / dz)` in the permuted axes.
    shear: [f32; 3],
    /// The origin's part of [`ShearedRay::tie_limit`]'s margin.
    tie_offset: f32,
    /// Axes: `kx`, `ky`, `kz` (chosen so that the winding is kept).
    k: [u8; 3],
    /// Zero. It fills the last byte, so that the struct has no padding and its 32 bytes can
    /// be loaded as one vector ([`ShearedLanes::of_rays`]).
    filler: u8,
}

const _: () = assert!(std::mem::size_of::<ShearedRay>() == 32);

/// Relative margin of [`ShearedRay::tie_limit`].
const TIE_MARGIN: f32 = 1.0 / 2_097_152.0;

/// [`ShearedRay::new`] of four rays, one ray a lane (SSE2): per lane the same comparisons,
/// selections and IEEE operations on the same operands, so the same bits (the axes are
/// picked by masks instead of indices; the maximum of the origin's magnitudes is taken in
/// `Vec3A::max_element`'s order, which matters only for NaN).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn sheared_four(rays: &[(Vec3A, Vec3A); 4], out: &mut [ShearedRay; 4]) {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64. The stores write the 32 bytes of each `ShearedRay`
    // (`repr(C)`, align 32, no padding: origin, shear, tie offset, then the three axis
    // bytes and the zero filler as one little-endian word), and any bits are valid there.
    unsafe {
        let transpose = crate::simd::transpose4;
        let [ox, oy, oz, _] = transpose(rays.map(|(o, _)| __m128::from(o)));
        let [dx, dy, dz, _] = transpose(rays.map(|(_, d)| __m128::from(d)));
        let magnitude = |v: __m128| _mm_and_ps(v, _mm_castsi128_ps(_mm_set1_epi32(i32::MAX)));
        let (ax, ay, az) = (magnitude(dx), magnitude(dy), magnitude(dz));
        let select = |mask: __m128, yes: __m128, no: __m128| {
            _mm_or_ps(_mm_and_ps(mask, yes), _mm_andnot_ps(mask, no))
        };
        // `kz`: x where its magnitude is the largest (the first of equals), else y where
        // it is at least z's, else z; `kx`, `ky` the next two, swapped where `d[kz] < 0`.
        let x_first = _mm_and_ps(_mm_cmpge_ps(ax, ay), _mm_cmpge_ps(ax, az));
        let y_first = _mm_andnot_ps(x_first, _mm_cmpge_ps(ay, az));
        let pick = |on_x: __m128, on_y: __m128, on_z: __m128| {
            select(x_first, on_x, select(y_first, on_y, on_z))
        };
        let d_kz = pick(dx, dy, dz);
        let (d_next, d_after) = (pick(dy, dz, dx), pick(dz, dx, dy));
        let down = _mm_cmplt_ps(d_kz, _mm_setzero_ps());
        let d_kx = select(down, d_after, d_next);
        let d_ky = select(down, d_next, d_after);
        let shear_x = _mm_div_ps(d_kx, d_kz);
        let shear_y = _mm_div_ps(d_ky, d_kz);
        let shear_z = _mm_div_ps(_mm_set1_ps(1.0), d_kz);
        let largest = _mm_max_ps(_mm_max_ps(magnitude(ox), magnitude(oy)), magnitude(oz));
        let tie_offset = _mm_mul_ps(largest, _mm_set1_ps(TIE_MARGIN));
        let int = |v: i32| _mm_castsi128_ps(_mm_set1_epi32(v));
        let kz = pick(int(0), int(1), int(2));
        let (next, after) = (pick(int(1), int(2), int(0)), pick(int(2), int(0), int(1)));
        let kx = _mm_castps_si128(select(down, after, next));
        let ky = _mm_castps_si128(select(down, next, after));
        let k = _mm_or_si128(
            _mm_or_si128(kx, _mm_slli_epi32::<8>(ky)),
            _mm_slli_epi32::<16>(_mm_castps_si128(kz)),
        );
        let low = transpose([ox, oy, oz, shear_x]);
        let high = transpose([shear_y, shear_z, tie_offset, _mm_castsi128_ps(k)]);
        for (ray, (low, high)) in out.iter_mut().zip(low.into_iter().zip(high)) {
            let at = (ray as *mut ShearedRay).cast::<f32>();
            _mm_store_ps(at, low);
            _mm_store_ps(at.add(4), high);
        }
    }
}

/// [`sheared_four`] of eight rays in AVX's eight lanes (ray `l` in lane `l`): per lane the
/// same comparisons, selections and IEEE operations on the same operands, so the same bits.
///
/// Why: half the instructions a ray of [`sheared_four`]'s (its three divisions above all),
/// for every packet a frame traces.
///
/// Returns the frames as rows too (origin x, y, z, then the three shears; lane `l` for ray
/// `l`), what [`ShearedRows`] keeps.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn sheared_eight(
    rays: &[(Vec3A, Vec3A); 8],
    out: &mut [ShearedRay; 8],
) -> [std::arch::x86_64::__m256; 6] {
    use std::arch::x86_64::*;
    // Rays `j` and `4 + j` in the low and high halves of row `j`, transposed in each half:
    // lane `l` of each result holds ray `l`'s component.
    let transpose =
        |v: [__m128; 8]| transpose_halves([0, 1, 2, 3].map(|j| _mm256_set_m128(v[4 + j], v[j])));
    let [ox, oy, oz, _] = transpose(rays.map(|(o, _)| __m128::from(o)));
    let [dx, dy, dz, _] = transpose(rays.map(|(_, d)| __m128::from(d)));
    let magnitude = |v: __m256| _mm256_and_ps(v, _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX)));
    let (ax, ay, az) = (magnitude(dx), magnitude(dy), magnitude(dz));
    let select = |mask: __m256, yes: __m256, no: __m256| {
        _mm256_or_ps(_mm256_and_ps(mask, yes), _mm256_andnot_ps(mask, no))
    };
    let ge = |a: __m256, b: __m256| _mm256_cmp_ps::<_CMP_GE_OQ>(a, b);
    // As `sheared_four` picks them.
    let x_first = _mm256_and_ps(ge(ax, ay), ge(ax, az));
    let y_first = _mm256_andnot_ps(x_first, ge(ay, az));
    let pick = |on_x: __m256, on_y: __m256, on_z: __m256| {
        select(x_first, on_x, select(y_first, on_y, on_z))
    };
    let d_kz = pick(dx, dy, dz);
    let (d_next, d_after) = (pick(dy, dz, dx), pick(dz, dx, dy));
    let down = _mm256_cmp_ps::<_CMP_LT_OQ>(d_kz, _mm256_setzero_ps());
    let d_kx = select(down, d_after, d_next);
    let d_ky = select(down, d_next, d_after);
    let shear_x = _mm256_div_ps(d_kx, d_kz);
    let shear_y = _mm256_div_ps(d_ky, d_kz);
    let shear_z = _mm256_div_ps(_mm256_set1_ps(1.0), d_kz);
    let largest = _mm256_max_ps(_mm256_max_ps(magnitude(ox), magnitude(oy)), magnitude(oz));
    let tie_offset = _mm256_mul_ps(largest, _mm256_set1_ps(TIE_MARGIN));
    let int = |v: i32| _mm256_castsi256_ps(_mm256_set1_epi32(v));
    let kz = pick(int(0), int(1), int(2));
    let (next, after) = (pick(int(1), int(2), int(0)), pick(int(2), int(0), int(1)));
    let kx = _mm256_castps_si256(select(down, after, next));
    let ky = _mm256_castps_si256(select(down, next, after));
    let k = _mm256_or_si256(
        _mm256_or_si256(kx, _mm256_slli_epi32::<8>(ky)),
        _mm256_slli_epi32::<16>(_mm256_castps_si256(kz)),
    );
    let low = transpose_halves([ox, oy, oz, shear_x]);
    let high = transpose_halves([shear_y, shear_z, tie_offset, _mm256_castsi256_ps(k)]);
    for j in 0..4 {
        // Ray `j`: both rows' low halves; ray `4 + j`: their high halves.
        let (first, second) = (
            _mm256_permute2f128_ps::<0x20>(low[j], high[j]),
            _mm256_permute2f128_ps::<0x31>(low[j], high[j]),
        );
        // SAFETY: `ShearedRay` is `repr(C)`, 32 bytes, 32-byte aligned, without padding
        // (origin, shear, tie offset, then the three axis bytes and the zero filler as one
        // little-endian word), and any bits are valid there.
        unsafe {
            _mm256_store_ps((&mut out[j] as *mut ShearedRay).cast::<f32>(), first);
            _mm256_store_ps((&mut out[4 + j] as *mut ShearedRay).cast::<f32>(), second);
        }
    }
    [ox, oy, oz, shear_x, shear_y, shear_z]
}

/// The 4x4 transpose of `rows` in each 128-bit half (as `simd::transpose4` in each).
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx")]
fn transpose_halves(
    [a, b, c, d]: [std::arch::x86_64::__m256; 4],
) -> [std::arch::x86_64::__m256; 4] {
    use std::arch::x86_64::*;
    let (ab_low, cd_low) = (_mm256_unpacklo_ps(a, b), _mm256_unpacklo_ps(c, d));
    let (ab_high, cd_high) = (_mm256_unpackhi_ps(a, b), _mm256_unpackhi_ps(c, d));
    [
        _mm256_shuffle_ps::<0x44>(ab_low, cd_low),
        _mm256_shuffle_ps::<0xee>(ab_low, cd_low),
        _mm256_shuffle_ps::<0x44>(ab_high, cd_high),
        _mm256_shuffle_ps::<0xee>(ab_high, cd_high),
    ]
}

/// What a pack test found: the lanes hit, with their distance and barycentrics.
pub struct PackHits {
    pub mask: u32,
    pub t: [f32; LANES],
    pub bary: [Vec2; LANES],
}

impl ShearedRay {
    /// The ray's frame: `kz` the axis of the direction's largest magnitude (the first
    /// of equals), `kx` and `ky` the next two in cyclic order, swapped when the direction
    /// points down `kz` (so the winding is kept).
    ///
    /// Chosen by arithmetic and table lookups rather than branches: a packet of scattered
    /// rays (bounces, shadow rays from bounce hits) mispredicted them ray after ray.
    #[inline(always)]
    pub fn new(origin: Vec3A, direction: Vec3A) -> ShearedRay {
        let d = direction.to_array();
        let [ax, ay, az] = direction.abs().to_array();
        let x_first = (ax >= ay) & (ax >= az);
        let y_first = ay >= az;
        // 0 when x comes first, else 1 for y or 2 for z.
        let kz = usize::from(!x_first) * (1 + usize::from(!y_first));
        const NEXT: [usize; 3] = [1, 2, 0];
        const AFTER_NEXT: [usize; 3] = [2, 0, 1];
        let (next, after) = (NEXT[kz], AFTER_NEXT[kz]);
        let down = usize::from(d[kz] < 0.0);
        // Swapped when pointing down: `kx` is `after` then, `ky` is `next`.
        let kx = next ^ ((next ^ after) * down);
        let ky = after ^ ((next ^ after) * down);
        // The three quotients in one vector division (the same IEEE quotients as three
        // scalar ones, which were the hottest line of making a packet's rays).
        let quotients = Vec4::new(d[kx], d[ky], 1.0, 1.0) / Vec4::new(d[kz], d[kz], d[kz], 1.0);
        let shear = [quotients.x, quotients.y, quotients.z];
        ShearedRay {
            origin: origin.to_array(),
            k: [kx, ky, kz].map(|axis| axis as u8),
            shear,
            tie_offset: origin.abs().max_element() * TIE_MARGIN,
            filler: 0,
        }
    }

    /// [`ShearedRay::new`] of each of `rays` into `out` (as many as the shorter holds),
    /// four rays at a time on x86-64 ([`sheared_four`]) and eight in the AVX2 copy
    /// ([`sheared_eight`]), the same bits.
    ///
    /// Why: a packet makes the frames of its 64 rays before its walk, and one at a time
    /// (a division, and the axes picked lane by lane) that was about 63 of a primary ray's
    /// 615 instructions on BART Kitchen (four at a time: about 29 in the AVX2 copy; eight
    /// at a time took 29 M instructions off a Kitchen frame of 2,979 M).
    ///
    /// In the copy [`crate::simd::dispatch`] chooses: the same operations, which the AVX2
    /// copy encodes with three operands (SSE2's copy spends a move on most of them).
    #[inline]
    pub fn fill(out: &mut [ShearedRay], rays: &[(Vec3A, Vec3A)]) {
        crate::simd::dispatch(FillFrames {
            out,
            rays,
            rows: None,
        })
    }

    /// [`ShearedRay::fill`] of a packet's rays (at most [`PACKET`]), their frames also kept
    /// as rows in `rows` (see [`ShearedRows`]).
    #[inline]
    pub fn fill_with_rows(out: &mut [ShearedRay], rows: &mut ShearedRows, rays: &[(Vec3A, Vec3A)]) {
        crate::simd::dispatch(FillFrames {
            out,
            rays,
            rows: Some(rows),
        })
    }
}

/// The origins and shears of a packet's rays as rows (`origin[axis][ray]`,
/// `shear[i][ray]`, the same bits as each [`ShearedRay`]'s), 64-byte aligned: a group of
/// eight or sixteen consecutive rays loads its rows whole ([`ShearedLanes::of_row_block`],
/// [`across_rays::sixteen`]).
///
/// Why: built from the frames at every leaf a group entered (8 x 8 transposes, and a gather
/// of the limits for sixteen rays), the rows took about a tenth of a leaf test; the packet's
/// frames are made eight rays at a time in lanes, which are these rows, so keeping them
/// costs six stores per eight rays.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub struct ShearedRows {
    origin: [[f32; PACKET]; 3],
    shear: [[f32; PACKET]; 3],
}

impl Default for ShearedRows {
    fn default() -> Self {
        ShearedRows {
            origin: [[0.0; PACKET]; 3],
            shear: [[0.0; PACKET]; 3],
        }
    }
}

impl ShearedRows {
    /// The origins' rows (`[axis][ray]`).
    #[inline(always)]
    pub fn origin(&self) -> &[[f32; PACKET]; 3] {
        &self.origin
    }

    /// The shears' rows (`[i][ray]`, in the frame's order: `dx / dz`, `dy / dz`, `1 / dz`).
    #[inline(always)]
    pub fn shear(&self) -> &[[f32; PACKET]; 3] {
        &self.shear
    }

    /// Whether the rows `at..end` hold the frames `sheared[at..end]` (for debug checks: the
    /// rows are filled by `ShearedRay::fill_with_rows`, and a walk must not read rows of
    /// another packet).
    pub fn hold(&self, sheared: &[ShearedRay; PACKET], at: usize, end: usize) -> bool {
        (at..end).all(|r| {
            (0..3).all(|i| {
                self.origin[i][r].to_bits() == sheared[r].origin[i].to_bits()
                    && self.shear[i][r].to_bits() == sheared[r].shear[i].to_bits()
            })
        })
    }

    /// Copies ray `len - 1`'s rows into the slots from `len` to the end of its group of
    /// sixteen (nothing when `len` is 0).
    #[inline(always)]
    fn repeat_last_to_group_end(&mut self, len: usize) {
        let Some(last) = len.checked_sub(1) else {
            return;
        };
        for row in self.origin.iter_mut().chain(&mut self.shear) {
            let value = row[last];
            row[len..len.next_multiple_of(16).min(PACKET)].fill(value);
        }
    }

    /// Ray `r`'s rows from its frame.
    #[inline(always)]
    fn set(&mut self, r: usize, frame: &ShearedRay) {
        for i in 0..3 {
            self.origin[i][r] = frame.origin[i];
            self.shear[i][r] = frame.shear[i];
        }
    }
}

/// [`ShearedRay::fill`] as a [`crate::simd::Kernel`].
struct FillFrames<'a> {
    out: &'a mut [ShearedRay],
    rays: &'a [(Vec3A, Vec3A)],
    /// Where the frames are also kept as rows ([`ShearedRay::fill_with_rows`]).
    rows: Option<&'a mut ShearedRows>,
}

impl crate::simd::Kernel for FillFrames<'_> {
    type Output = ();

    #[inline(always)]
    fn run<const AVX2: bool>(self) {
        let (out, rays, mut rows) = (self.out, self.rays, self.rows);
        let n = out.len().min(rays.len());
        if rows.is_some() {
            assert!(n <= PACKET, "{n} rays for one packet's rows");
        }
        let (out, rays) = (&mut out[..n], &rays[..n]);
        #[cfg(target_arch = "x86_64")]
        let eights = if AVX2 {
            for (group, (out, rays)) in out
                .chunks_exact_mut(8)
                .zip(rays.chunks_exact(8))
                .enumerate()
            {
                // SAFETY: `AVX2` is true only in the copy `simd::dispatch` runs where the
                // CPU has AVX2 (and in tests that check the CPU first).
                let lanes = unsafe {
                    sheared_eight(
                        rays.try_into().expect("eight rays"),
                        out.try_into().expect("eight frames"),
                    )
                };
                if let Some(rows) = rows.as_deref_mut() {
                    let at = 8 * group;
                    let [ox, oy, oz, sx, sy, sz] = lanes;
                    let [o0, o1, o2] = &mut rows.origin;
                    let [s0, s1, s2] = &mut rows.shear;
                    let targets = [(o0, ox), (o1, oy), (o2, oz), (s0, sx), (s1, sy), (s2, sz)];
                    for (row, lane) in targets {
                        let slots: &mut [f32; 8] =
                            (&mut row[at..at + 8]).try_into().expect("eight slots");
                        // SAFETY: AVX is part of AVX2 (see above); an unaligned store of
                        // eight floats into eight.
                        unsafe { std::arch::x86_64::_mm256_storeu_ps(slots.as_mut_ptr(), lane) };
                    }
                }
            }
            n - n % 8
        } else {
            0
        };
        #[cfg(not(target_arch = "x86_64"))]
        let eights = 0;
        #[cfg(target_arch = "x86_64")]
        let (out, rays, n) = (&mut out[eights..], &rays[eights..], n - eights);
        #[cfg(target_arch = "x86_64")]
        let done = {
            for (out, rays) in out.chunks_exact_mut(4).zip(rays.chunks_exact(4)) {
                sheared_four(
                    rays.try_into().expect("four rays"),
                    out.try_into().expect("four frames"),
                );
            }
            n - n % 4
        };
        #[cfg(not(target_arch = "x86_64"))]
        let done = 0;
        for (out, &(origin, direction)) in out[done..].iter_mut().zip(&rays[done..]) {
            *out = ShearedRay::new(origin, direction);
        }
        if let Some(rows) = rows {
            // The rays not made eight at a time, then the slots to the end of the last
            // group of sixteen repeating the last ray (as a group test's lanes past its
            // rays do).
            for (k, frame) in out.iter().enumerate() {
                rows.set(eights + k, frame);
            }
            rows.repeat_last_to_group_end(eights + n);
        }
    }
}

impl ShearedRay {
    /// The limit a closest-hit query keeps after a hit at `t`, so that boxes where an exact
    /// tie may hide are still visited: `t` plus 2^-21 (4 ulps of f32) of `t` and of the
    /// origin's largest coordinate. Box entry distances and hit distances are both
    /// computed from coordinates minus the origin, so their rounding scales with the larger
    /// of the two (one ulp of `t` alone let exact ties seen from 1e5 away go by visit order;
    /// 2^-23 already sufficed in the test). A margin only costs extra visits: a hit past `t`
    /// is never taken over it. Rays nearly parallel to a box face can round its entry
    /// distance further than this; such ties may still be decided by visit order.
    #[inline(always)]
    pub fn tie_limit(&self, t: f32) -> f32 {
        t * (1.0 + TIE_MARGIN) + self.tie_offset
    }

    /// The axes and the filler as one word: equal for two rays exactly when their axes are
    /// (the filler is always zero).
    #[inline(always)]
    pub fn axes_word(&self) -> u32 {
        u32::from_le_bytes([self.k[0], self.k[1], self.k[2], self.filler])
    }

    /// The frame's axes `kx`, `ky`, `kz`.
    #[inline(always)]
    pub fn k(&self) -> [u8; 3] {
        self.k
    }

    /// Which of the six axis permutations the ray's frame uses (rays that share it can be
    /// tested together, [`ShearedLanes`]).
    #[inline(always)]
    pub fn permutation(&self) -> usize {
        let [kx, _, kz] = self.k.map(usize::from);
        kz * 2 + usize::from(kx != (kz + 1) % 3)
    }

    /// Tests the first `live` lanes of `pack`.
    #[inline(always)]
    fn intersect_pack(&self, pack: &TrianglePack, live: usize, t_max: f32) -> PackHits {
        let [kx, ky, kz] = self.k.map(usize::from);
        let [sx, sy, sz] = self.shear.map(Vec4::splat);
        let origin = self.origin.map(Vec4::splat);
        // Vertex `i` relative to the origin, sheared: (x, y) in the ray's plane and z along it.
        let sheared = |i: usize| {
            let v = &pack.v[i];
            let z = Vec4::from_array(v[kz]) - origin[kz];
            let x = Vec4::from_array(v[kx]) - origin[kx] - sx * z;
            let y = Vec4::from_array(v[ky]) - origin[ky] - sy * z;
            (x, y, z)
        };
        let (ax, ay, az) = sheared(0);
        let (bx, by, bz) = sheared(1);
        let (cx, cy, cz) = sheared(2);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        let live_mask = (1u32 << live) - 1;
        let zero = Vec4::ZERO;
        let on_edge = (u.cmpeq(zero) | v.cmpeq(zero) | w.cmpeq(zero)).bitmask() & live_mask;
        if on_edge != 0 {
            // Exactly on an edge in f32: decide it in f64 (rare), as the paper prescribes.
            let (mut u4, mut v4, mut w4) = (u.to_array(), v.to_array(), w.to_array());
            let (ax, ay, bx, by, cx, cy) = (
                ax.to_array(),
                ay.to_array(),
                bx.to_array(),
                by.to_array(),
                cx.to_array(),
                cy.to_array(),
            );
            let mut bits = on_edge;
            while bits != 0 {
                let l = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let f = |a: f32, b: f32, c: f32, d: f32| {
                    (a as f64 * b as f64 - c as f64 * d as f64) as f32
                };
                u4[l] = f(cx[l], by[l], cy[l], bx[l]);
                v4[l] = f(ax[l], cy[l], ay[l], cx[l]);
                w4[l] = f(bx[l], ay[l], by[l], ax[l]);
            }
            (u, v, w) = (
                Vec4::from_array(u4),
                Vec4::from_array(v4),
                Vec4::from_array(w4),
            );
        }
        let negative = u.cmplt(zero) | v.cmplt(zero) | w.cmplt(zero);
        let positive = u.cmpgt(zero) | v.cmpgt(zero) | w.cmpgt(zero);
        let det = u + v + w;
        let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
        let inside = !(negative & positive).bitmask() & det.cmpne(zero).bitmask() & live_mask;
        let mut hits = PackHits {
            mask: 0,
            t: [0.0; LANES],
            bary: [Vec2::ZERO; LANES],
        };
        if inside == 0 {
            return hits;
        }
        let inverse = Vec4::ONE / det;
        let t = (t_scaled * inverse).to_array();
        let (v, w) = ((v * inverse).to_array(), (w * inverse).to_array());
        // Lanes whose distance or determinant left f32's range (only for vertices beyond
        // about 1e12 from the origin): decided in f64 instead. `x - x` is zero exactly when
        // `x` is finite (infinity and NaN give NaN): one subtraction and compare per vector.
        #[allow(clippy::eq_op)]
        let finite = ((det - det).cmpeq(zero) & (t_scaled - t_scaled).cmpeq(zero)).bitmask();
        let mut bits = inside;
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let found = if finite & (1 << l) != 0 {
                (t[l] >= 0.0 && t[l] < t_max && t[l].is_finite())
                    .then(|| (t[l], Vec2::new(v[l], w[l])))
            } else {
                intersect_beyond_f32(self.origin, self.shear, self.k, pack, l, t_max)
            };
            if let Some((t, bary)) = found {
                hits.mask |= 1 << l;
                hits.t[l] = t;
                hits.bary[l] = bary;
            }
        }
        hits
    }
}

/// The sheared test of one ray and one triangle in f64, for the rare pair whose f32
/// determinant or distance left f32's range (vertices beyond about 1e12 from the ray's
/// origin: the distance's numerator grows as the cube of the coordinates). The ray is given
/// as [`ShearedRay`] holds it (`origin` unpermuted, `shear` and `k` permuted), the triangle
/// as lane `lane` of `pack`. The sheared vertices are computed in f32 exactly as the f32
/// tests compute them, then each edge function is a difference of two exact products in
/// f64, rounded once, so its sign is right. The pack test and the test across rays both
/// call this with the same operands, so they still agree bit for bit.
#[cold]
#[inline(never)]
pub(super) fn intersect_beyond_f32(
    origin: [f32; 3],
    shear: [f32; 3],
    k: [u8; 3],
    pack: &TrianglePack,
    lane: usize,
    t_max: f32,
) -> Option<(f32, Vec2)> {
    let [kx, ky, kz] = k.map(usize::from);
    let [sx, sy, sz] = shear;
    let sheared = |i: usize| {
        let v = &pack.v[i];
        let z = v[kz][lane] - origin[kz];
        let x = v[kx][lane] - origin[kx] - sx * z;
        let y = v[ky][lane] - origin[ky] - sy * z;
        [x, y, z].map(f64::from)
    };
    let [a, b, c] = [sheared(0), sheared(1), sheared(2)];
    let u = c[0] * b[1] - c[1] * b[0];
    let v = a[0] * c[1] - a[1] * c[0];
    let w = b[0] * a[1] - b[1] * a[0];
    let negative = u < 0.0 || v < 0.0 || w < 0.0;
    let positive = u > 0.0 || v > 0.0 || w > 0.0;
    let det = u + v + w;
    if (negative && positive) || det == 0.0 || !det.is_finite() {
        return None;
    }
    let sz = f64::from(sz);
    let t_scaled = u * (sz * a[2]) + v * (sz * b[2]) + w * (sz * c[2]);
    let t = (t_scaled / det) as f32;
    (t >= 0.0 && t < t_max && t.is_finite())
        .then(|| (t, Vec2::new((v / det) as f32, (w / det) as f32)))
}

/// One triangle against one ray, the same arithmetic as one lane of a pack (tests compare
/// the tree's answers with this applied to every triangle).
pub fn intersect(tri: &[Vec3A; 3], origin: Vec3A, direction: Vec3A) -> Option<(f32, Vec2)> {
    let mut pack = TrianglePack::default();
    pack.set(0, tri);
    let hits = ShearedRay::new(origin, direction).intersect_pack(&pack, 1, f32::INFINITY);
    (hits.mask & 1 != 0).then(|| (hits.t[0], hits.bary[0]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::flat::padded_box;
    use crate::accel::wide::test_support::xorshift;

    /// The frame as first written, with branches: what `ShearedRay::new`'s arithmetic
    /// choice must give.
    fn frame_by_branches(direction: Vec3A) -> ([u8; 3], [f32; 3]) {
        let abs = direction.abs();
        let kz = if abs.x >= abs.y && abs.x >= abs.z {
            0
        } else if abs.y >= abs.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if direction[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let shear = [
            direction[kx] / direction[kz],
            direction[ky] / direction[kz],
            1.0 / direction[kz],
        ];
        ([kx, ky, kz].map(|a| a as u8), shear)
    }

    /// Direction components for the frame tests: ties, signed zeros, tiny, huge, infinite
    /// and NaN.
    const HARD_COMPONENTS: [f32; 12] = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        2.0,
        -2.0,
        0.5,
        1e-30,
        -3e38,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
    ];

    #[test]
    fn the_ray_frame_chosen_without_branches_is_the_branching_one() {
        // The hard components in every position.
        let values = HARD_COMPONENTS;
        let mut checked = 0;
        for &x in &values {
            for &y in &values {
                for &z in &values {
                    let direction = Vec3A::new(x, y, z);
                    let ray = ShearedRay::new(Vec3A::new(1.0, -2.0, 3.0), direction);
                    let (k, shear) = frame_by_branches(direction);
                    assert_eq!(ray.k, k, "{direction}");
                    assert_eq!(
                        ray.shear.map(f32::to_bits),
                        shear.map(f32::to_bits),
                        "{direction}"
                    );
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, values.len().pow(3));
    }

    /// Every field of a frame, as bits.
    fn frame_bits(ray: &ShearedRay) -> ([u32; 3], [u32; 3], u32, [u8; 3], u8) {
        (
            ray.origin.map(f32::to_bits),
            ray.shear.map(f32::to_bits),
            ray.tie_offset.to_bits(),
            ray.k,
            ray.filler,
        )
    }

    /// Frames made eight (the AVX2 copy) or four at a time are each ray's own, bit for bit:
    /// every direction of the test above (ties, signed zeros, tiny, huge, infinite and NaN
    /// components) from origins with ties, signed zeros, huge and NaN coordinates, in runs
    /// of every length up to seventeen (eights, then a four, then the last rays of a run
    /// one at a time).
    #[test]
    fn frames_made_four_or_eight_at_a_time_are_each_rays_own() {
        let values = HARD_COMPONENTS;
        let origins = [
            Vec3A::new(1.0, -2.0, 3.0),
            Vec3A::new(-0.0, 0.0, -0.0),
            Vec3A::new(-5.0, 5.0, 4.0),
            Vec3A::new(1e30, -3e38, 7.0),
            Vec3A::new(f32::NAN, 2.0, -9.0),
            Vec3A::new(3.0, f32::NAN, f32::INFINITY),
        ];
        let mut rays = Vec::new();
        for &x in &values {
            for &y in &values {
                for &z in &values {
                    let origin = origins[rays.len() % origins.len()];
                    rays.push((origin, Vec3A::new(x, y, z)));
                }
            }
        }
        let mut compared = 0;
        for run in 1..=17 {
            for group in rays.chunks(run) {
                // Both copies of the kernel, and the dispatched one.
                let mut baseline = vec![ShearedRay::default(); run];
                crate::simd::run_baseline(FillFrames {
                    out: &mut baseline,
                    rays: group,
                    rows: None,
                });
                let mut avx2 = vec![ShearedRay::default(); run];
                let ran = crate::simd::run_avx2_if_available(FillFrames {
                    out: &mut avx2,
                    rays: group,
                    rows: None,
                });
                let mut dispatched = vec![ShearedRay::default(); run];
                ShearedRay::fill(&mut dispatched, group);
                for (k, &(origin, direction)) in group.iter().enumerate() {
                    let alone = frame_bits(&ShearedRay::new(origin, direction));
                    let copies = [&baseline, &avx2, &dispatched];
                    for (copy, made) in copies.iter().enumerate() {
                        assert_eq!(
                            frame_bits(&made[k]),
                            alone,
                            "copy {copy}: {origin} {direction}"
                        );
                    }
                    compared += usize::from(ran.is_some());
                }
            }
        }
        // The AVX2 copy ran wherever the CPU has AVX2 (the suite's machines do).
        assert!(!crate::simd::Isa::cpu_has_avx2() || compared == 17 * rays.len());
    }

    /// A packet's rows hold each ray's frame, bit for bit, in both copies of the kernel and
    /// for every packet size, and the slots to the end of the last group of sixteen repeat
    /// the last ray; slots past that keep what was there.
    #[test]
    fn a_packets_rows_are_its_frames() {
        let values = HARD_COMPONENTS;
        let rays: Vec<(Vec3A, Vec3A)> = (0..PACKET)
            .map(|i| {
                let v = |k: usize| values[(i * 7 + k * 3) % values.len()];
                (
                    Vec3A::new(v(0), -v(1), 3.0 + i as f32),
                    Vec3A::new(v(2), v(3), v(4)),
                )
            })
            .collect();
        let mut compared = 0;
        for n in 1..=PACKET {
            let group = &rays[..n];
            let mut copies = Vec::new();
            let (mut frames, mut rows) = (vec![ShearedRay::default(); n], ShearedRows::default());
            crate::simd::run_baseline(FillFrames {
                out: &mut frames,
                rays: group,
                rows: Some(&mut rows),
            });
            copies.push((frames, rows));
            let (mut frames, mut rows) = (vec![ShearedRay::default(); n], ShearedRows::default());
            let ran = crate::simd::run_avx2_if_available(FillFrames {
                out: &mut frames,
                rays: group,
                rows: Some(&mut rows),
            });
            if ran.is_some() {
                copies.push((frames, rows));
            }
            for (copy, (frames, rows)) in copies.iter().enumerate() {
                let padded = n.next_multiple_of(16).min(PACKET);
                for r in 0..PACKET {
                    let frame = &frames[r.min(n - 1)];
                    for i in 0..3 {
                        let (origin, shear) = if r < padded {
                            (frame.origin[i].to_bits(), frame.shear[i].to_bits())
                        } else {
                            (0, 0)
                        };
                        assert_eq!(
                            rows.origin()[i][r].to_bits(),
                            origin,
                            "copy {copy}, {n} rays, ray {r}"
                        );
                        assert_eq!(
                            rows.shear()[i][r].to_bits(),
                            shear,
                            "copy {copy}, {n} rays, ray {r}"
                        );
                    }
                    compared += 1;
                }
            }
        }
        let copies = 1 + usize::from(crate::simd::Isa::cpu_has_avx2());
        assert_eq!(compared, copies * PACKET * PACKET);
    }

    fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> [Vec3A; 3] {
        [a, b, c].map(Vec3A::from)
    }

    /// A pack's four squared cross products are the bits `lod::cross_squared` gives each
    /// lane's triangle alone: ordinary, degenerate, tiny, huge and mixed-magnitude ones.
    #[test]
    fn pack_cross_squared_equals_the_per_triangle_value_bit_for_bit() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let mut triangles = vec![
            tri([0.0; 3], [0.0; 3], [0.0; 3]),
            tri([1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [3.0, 6.0, 9.0]),
            tri([1e-30, 0.0, 0.0], [0.0, 1e-30, 0.0], [0.0, 0.0, 1e-30]),
            tri([3e38, -3e38, 1.0], [-3e38, 3e38, 2.0], [1e20, 1e-20, -3e38]),
            tri(
                [1e7, 1e7, 1e7],
                [1e7 + 1.0, 1e7, 1e7],
                [1e7, 1e7 + 1.0, 1e7],
            ),
        ];
        for scale in [1e-6, 1.0, 1e6] {
            for _ in 0..40 {
                let mut v = || [next() * scale, next() * scale, next() * scale];
                let (a, b, c) = (v(), v(), v());
                triangles.push(tri(a, b, c));
            }
        }
        let packed = PackedTriangles::pack(&triangles, [(0, triangles.len() as u32)].into_iter());
        for slot in 0..triangles.len() as u32 {
            let (held, lanes) = packed.pack_cross_squared(slot);
            assert!(held.contains(&slot));
            let expected = crate::lod::cross_squared(triangles[slot as usize]);
            assert_eq!(
                lanes[(slot - held.start) as usize].to_bits(),
                expected.to_bits(),
                "triangle {slot}"
            );
        }
    }

    #[test]
    fn distance_and_barycentrics_rebuild_the_hit_point() {
        let t = tri([-1.0, -1.0, -5.0], [2.0, -1.0, -6.0], [0.0, 3.0, -4.0]);
        for (o, d) in [
            (Vec3A::ZERO, Vec3A::new(0.1, 0.2, -1.0).normalize()),
            (
                Vec3A::new(0.5, 0.5, -10.0),
                Vec3A::new(-0.05, 0.1, 1.0).normalize(),
            ),
            (Vec3A::new(-3.0, 0.0, -5.0), Vec3A::new(1.0, 0.0, 0.0)),
        ] {
            let (dist, bary) = intersect(&t, o, d).expect("the ray crosses the triangle");
            let on_ray = o + d * dist;
            let from_bary = t[0] * (1.0 - bary.x - bary.y) + t[1] * bary.x + t[2] * bary.y;
            assert!(
                (on_ray - from_bary).length() < 1e-5,
                "{on_ray} vs {from_bary}"
            );
            assert!(bary.x >= 0.0 && bary.y >= 0.0 && bary.x + bary.y <= 1.0);
        }
        // Behind the origin, parallel to the plane, and beside the triangle: no hit.
        assert!(intersect(&t, Vec3A::ZERO, Vec3A::new(0.1, 0.2, 1.0).normalize()).is_none());
        assert!(intersect(&t, Vec3A::new(10.0, 0.0, -5.0), Vec3A::X).is_none());
        assert!(intersect(&t, Vec3A::new(0.0, 9.0, 0.0), Vec3A::NEG_Z).is_none());
        // A degenerate (zero-area) triangle is never hit, not even on its own line.
        let flat = tri([0.0, 0.0, -2.0], [1.0, 0.0, -2.0], [2.0, 0.0, -2.0]);
        assert!(intersect(&flat, Vec3A::new(0.5, 0.0, 0.0), Vec3A::NEG_Z).is_none());
    }

    #[test]
    fn each_lane_of_a_pack_answers_as_the_triangle_alone_and_dead_lanes_never_hit() {
        let tris = [
            tri([-1.0, -1.0, -2.0], [1.0, -1.0, -2.0], [0.0, 1.0, -2.0]),
            tri([-1.0, -1.0, -3.0], [1.0, -1.0, -3.0], [0.0, 1.0, -3.0]),
            tri([5.0, 5.0, -3.0], [6.0, 5.0, -3.0], [5.0, 6.0, -3.0]),
            tri([-2.0, -2.0, -1.0], [2.0, -2.0, -1.5], [0.0, 2.0, -1.2]),
        ];
        let positions: Vec<[Vec3A; 3]> = tris.to_vec();
        // One leaf of three: the fourth triangle is left out, its lane dead.
        let packed = PackedTriangles::pack(&positions, [(0, 3), (3, 1)].into_iter());
        assert_eq!(packed.packs.len(), 2);
        let ray = ShearedRay::new(Vec3A::new(0.0, 0.0, 1.0), Vec3A::NEG_Z);
        let mut seen = Vec::new();
        packed.hits_in_leaf::<false>(&ray, 0, 3, f32::INFINITY, |slot, source, t, bary| {
            assert_eq!(source, slot);
            assert_eq!(
                Some((t, bary)),
                intersect(
                    &tris[slot as usize],
                    Vec3A::new(0.0, 0.0, 1.0),
                    Vec3A::NEG_Z
                )
            );
            seen.push(slot);
            true
        });
        assert_eq!(seen, vec![0, 1]);
        // The limit cuts the farther one; stopping early is reported.
        let mut near = Vec::new();
        packed.hits_in_leaf::<false>(&ray, 0, 3, 3.5, |slot, _, _, _| {
            near.push(slot);
            true
        });
        assert_eq!(near, vec![0]);
        assert!(!packed.hits_in_leaf::<false>(&ray, 0, 3, f32::INFINITY, |_, _, _, _| false));
    }

    /// A leaf of two packs reports, in the AVX2 copy's eight-lane test, the same hits in the
    /// same order as pack by pack, and stops after the same hit.
    #[test]
    fn a_leaf_of_two_packs_reports_the_same_hits_in_either_copy() {
        if !crate::simd::Isa::cpu_has_avx2() {
            println!("skipped: this CPU has no AVX2");
            return;
        }
        // Seven triangles stacked along the ray (some missed, one with a shared edge on the
        // ray's line) and one more leaf after them.
        let layer = |x: f32, z: f32| tri([x - 1.0, -1.0, z], [x + 1.0, -1.0, z], [x, 1.0, z]);
        let mut positions: Vec<[Vec3A; 3]> = (0..7)
            .map(|i| layer(if i == 3 { 5.0 } else { 0.0 }, -1.0 - i as f32))
            .collect();
        positions[5] = tri([0.0, -1.0, -6.0], [2.0, -1.0, -6.0], [0.0, 1.0, -6.0]);
        positions.push(layer(0.0, -9.0));
        let packed = PackedTriangles::pack(&positions, [(0, 7), (7, 1)].into_iter());
        assert_eq!(packed.packs.len(), 3);
        let hits = |avx: bool, ray: &ShearedRay, stop_after: usize| {
            let mut seen = Vec::new();
            let mut record = |slot: u32, source: u32, t: f32, bary: Vec2| {
                seen.push((
                    slot,
                    source,
                    t.to_bits(),
                    bary.x.to_bits(),
                    bary.y.to_bits(),
                ));
                seen.len() < stop_after
            };
            let finished = if avx {
                packed.hits_in_leaf::<true>(ray, 0, 7, f32::INFINITY, &mut record)
            } else {
                packed.hits_in_leaf::<false>(ray, 0, 7, f32::INFINITY, &mut record)
            };
            (finished, seen)
        };
        for origin in [
            Vec3A::new(0.0, 0.0, 1.0),
            Vec3A::new(0.0, -0.5, 1.0),
            Vec3A::new(0.3, 0.2, 1.0),
        ] {
            let ray = ShearedRay::new(origin, Vec3A::new(0.01, 0.0, -1.0));
            let all = hits(false, &ray, usize::MAX);
            assert!(all.1.len() >= 5, "{origin}: only {} hits", all.1.len());
            for stop_after in [1, 2, 5, usize::MAX] {
                assert_eq!(hits(true, &ray, stop_after), hits(false, &ray, stop_after));
            }
        }
    }

    #[test]
    fn updates_land_in_the_lane_of_their_slot() {
        let mut positions: Vec<[Vec3A; 3]> = (0..11)
            .map(|i| {
                tri(
                    [i as f32, 0.0, 0.0],
                    [i as f32 + 1.0, 0.0, 0.0],
                    [i as f32, 1.0, 0.0],
                )
            })
            .collect();
        let mut packed = PackedTriangles::pack(&positions, [(0, 5), (5, 6)].into_iter());
        assert_eq!(packed.packs.len(), 4);
        for (slot, p) in positions.iter().enumerate() {
            assert_eq!(packed.triangle(slot as u32), *p);
        }
        positions[7] = tri([9.0; 3], [8.0; 3], [7.0; 3]);
        packed.set_triangle(7, &positions[7]);
        assert_eq!(packed.triangle(7), positions[7]);
        // Through the concurrent access, every slot at once (two tasks share pack 1).
        for p in &mut positions {
            *p = p.map(|v| v * 2.0);
        }
        let lanes = packed.slot_lanes();
        assert_eq!(lanes.slots(), 11);
        std::thread::scope(|scope| {
            for half in [0..5u32, 5..11] {
                let (lanes, positions) = (&lanes, &positions);
                scope.spawn(move || {
                    for slot in half {
                        // SAFETY: each slot is in one half only.
                        unsafe { lanes.set(slot, &positions[slot as usize]) };
                        assert_eq!(unsafe { lanes.get(slot) }, positions[slot as usize]);
                    }
                });
            }
        });
        assert_eq!(packed.triangles_in_slot_order(), positions);
        // A leaf's box is the union of its packs' live lanes (dead lanes left out).
        let leaf_box = |first, count, slots: std::ops::Range<usize>| {
            let from_packs = packed.leaf_box(first, count);
            let direct = positions[slots]
                .iter()
                .fold(Aabb::empty(), |a, t| a.union(&padded_box(t)));
            assert_eq!((from_packs.min, from_packs.max), (direct.min, direct.max));
        };
        leaf_box(0, 5, 0..5);
        leaf_box(5, 6, 5..11);
    }

    /// A whole pack rewritten at once stores what lane-by-lane writes store, keeps its dead
    /// lanes, and reports as changed exactly the lanes whose bits differ (a signed zero's
    /// flip counts, a NaN rewritten with the same bits does not) and, of those, the ones
    /// with a non-finite vertex.
    #[test]
    fn a_pack_rewritten_at_once_matches_lane_by_lane_writes_bit_for_bit() {
        let start: Vec<[Vec3A; 3]> = (0..7)
            .map(|i| {
                let f = i as f32;
                let mut t = tri([f, 0.0, -0.0], [f + 1.0, 0.5, 0.0], [f, 1.0, 2.0]);
                if i == 2 {
                    t[1].y = f32::NAN;
                }
                t
            })
            .collect();
        // Leaves of 4 and 3: the second pack has a dead lane.
        let mut packed = PackedTriangles::pack(&start, [(0, 4), (4, 3)].into_iter());
        let mut expected = start.clone();
        // Lane 0 unchanged; lane 1: -0 -> +0 (a change of bits); lane 2: the same NaN
        // (unchanged); lane 3: an infinity (changed, non-finite); lanes 4..7: moved, one
        // to a NaN.
        expected[1][0].z = 0.0;
        expected[3][2].x = f32::INFINITY;
        expected[4] = expected[4].map(|v| v + Vec3A::splat(0.25));
        expected[5] = tri([1e30, -1e30, 3.0], [f32::MIN_POSITIVE; 3], [-0.0; 3]);
        expected[6][0].y = f32::NAN;
        let dead_before = packed.packs[1]
            .v
            .map(|vertex| vertex.map(|axis| axis[3].to_bits()));
        let lanes = packed.slot_lanes();
        let pack_of = |first: usize, live: usize| {
            let mut t = [[Vec3A::splat(f32::NAN); 3]; LANES];
            t[..live].copy_from_slice(&expected[first..first + live]);
            t
        };
        assert_eq!(lanes.pack_from(0), Some(4));
        assert_eq!(lanes.pack_from(4), Some(3));
        assert_eq!(lanes.pack_from(5), None);
        // SAFETY: one thread.
        let first = unsafe { lanes.rewrite_pack(0, 4, &pack_of(0, 4)) };
        let second = unsafe { lanes.rewrite_pack(4, 3, &pack_of(4, 3)) };
        assert_eq!(first, (0b1010, 0b1000));
        assert_eq!(second, (0b111, 0b100));
        let bits = |t: &[[Vec3A; 3]]| -> Vec<[[u32; 3]; 3]> {
            t.iter()
                .map(|t| t.map(|v| v.to_array().map(f32::to_bits)))
                .collect()
        };
        assert_eq!(bits(&packed.triangles_in_slot_order()), bits(&expected));
        let dead_after = packed.packs[1]
            .v
            .map(|vertex| vertex.map(|axis| axis[3].to_bits()));
        assert_eq!(dead_after, dead_before, "the dead lane is kept");
    }

    /// The vector rewrite of a pack equals the lane-by-lane one (the version other targets
    /// compile) in every stored bit and both masks, for every live count, on rows that mix
    /// unchanged lanes, signed zeros, NaNs of other payloads, infinities and subnormals.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn a_pack_rewritten_as_vectors_equals_the_lane_by_lane_rewrite() {
        let hard = [
            0.0,
            -0.0,
            1.5,
            -3.25e7,
            f32::NAN,
            f32::from_bits(0x7fc0_1234),
            f32::from_bits(0xffc0_0001),
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE / 4.0,
            f32::MAX,
        ];
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        for case in 0..4000 {
            let old: [[[f32; LANES]; 3]; 3] = std::array::from_fn(|_| {
                std::array::from_fn(|_| std::array::from_fn(|_| hard[next() as usize % hard.len()]))
            });
            // Most lanes written with their own bits or one component changed, so the
            // unchanged and changed cases both occur.
            let tri: [[Vec3A; 3]; LANES] = std::array::from_fn(|lane| {
                std::array::from_fn(|vertex| {
                    Vec3A::from_array(std::array::from_fn(|axis| match next() % 8 {
                        0 | 1 => hard[next() as usize % hard.len()],
                        _ => old[vertex][axis][lane],
                    }))
                })
            });
            let live = 1 + case % LANES as u32;
            let (mut by_vectors, mut by_lane) = (old, old);
            // SAFETY: local arrays, one thread, 16-byte aligned by `Aligned`.
            let (vectors, lanes) = unsafe {
                let mut a = Aligned(by_vectors);
                let r = rewrite_lanes(&raw mut a.0, live, &tri);
                by_vectors = a.0;
                (r, rewrite_lanes_by_lane(&raw mut by_lane, live, &tri))
            };
            let bits = |v: &[[[f32; LANES]; 3]; 3]| v.map(|r| r.map(|a| a.map(f32::to_bits)));
            assert_eq!(vectors, lanes, "case {case}, live {live}");
            assert_eq!(
                bits(&by_vectors),
                bits(&by_lane),
                "case {case}, live {live}"
            );
        }
    }

    /// Vertex rows aligned as a pack's are.
    #[repr(C, align(16))]
    struct Aligned([[[f32; LANES]; 3]; 3]);

    /// A pack's box, computed four lanes at once, is the union of its live lanes'
    /// [`padded_box`]es bit for bit, in lane order (and a leaf's, of its packs' in order),
    /// also on hard values: signed zeros,
    /// tiny and huge coordinates, infinities and NaN (whose `min` and `max` depend on
    /// the order). So is a leaf's box read through the concurrent lanes.
    #[test]
    fn a_pack_box_is_the_union_of_its_lanes_padded_boxes_bit_for_bit() {
        let hard = [
            0.0,
            -0.0,
            1.0,
            -3.5,
            1e-38,
            -1e-45,
            3e38,
            -3e38,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            123_456.79,
        ];
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        let bits = |a: &Aabb| {
            (
                a.min.to_array().map(f32::to_bits),
                a.max.to_array().map(f32::to_bits),
            )
        };
        let mut with_nan = 0;
        for round in 0..3000 {
            let count = 1 + round % 9;
            let coordinate = |r: u64| {
                if r.is_multiple_of(3) {
                    hard[(r >> 8) as usize % hard.len()]
                } else {
                    ((r >> 16) as f32 / 65536.0 - 30_000.0)
                        * [1.0, 1e-6, 1e4][(r >> 4) as usize % 3]
                }
            };
            let triangles: Vec<[Vec3A; 3]> = (0..count)
                .map(|_| {
                    std::array::from_fn(|_| {
                        Vec3A::new(coordinate(next()), coordinate(next()), coordinate(next()))
                    })
                })
                .collect();
            with_nan += usize::from(triangles.iter().flatten().any(|v| v.is_nan()));
            let mut packed = PackedTriangles::pack(&triangles, [(0, count as u32)].into_iter());
            // Per pack of four lanes in order, then the packs in order (with a NaN the
            // grouping shows).
            let union = |boxes: &mut dyn Iterator<Item = Aabb>| {
                boxes.fold(Aabb::empty(), |a, b| a.union(&b))
            };
            let want = union(
                &mut triangles
                    .chunks(LANES)
                    .map(|pack| union(&mut pack.iter().map(padded_box))),
            );
            let got = packed.leaf_box(0, count as u32);
            assert_eq!(bits(&got), bits(&want), "{triangles:?}");
            let lanes = packed.slot_lanes();
            // SAFETY: no other task uses these lanes.
            let through_lanes = unsafe { lanes.leaf_box(0, count as u32) };
            assert_eq!(bits(&through_lanes), bits(&want));
        }
        assert!(with_nan > 100, "{with_nan}");
    }
}
