//! Packets of coherent rays walking the wide tree together (ranged traversal, Wald et al.
//! 2007 and Overbeck et al. 2008), with two tests that decide for many rays at once:
//!
//! - **Interval test per node** (Wald, Boulos and Shirley 2007, "Ray tracing deformable
//!   scenes using dynamic bounding volume hierarchies"): when every ray of the packet starts
//!   at one point (a pinhole camera's primary rays) and runs the same way along an axis, the
//!   slab distances of all its rays lie between those of the smallest and the largest
//!   inverse direction component. One SIMD slab test with those bounds tells which of a
//!   node's eight children no ray of the packet can enter; the others are walked, nearest
//!   bound first, with no ray-by-ray test above the leaves. (Packets from several origins
//!   fall back to ranged traversal: each child carried from the first ray that enters it.)
//!   It is exact in floating point, not only in real numbers: with one shared origin every
//!   ray computes the same `plane - origin`, and a product rounded to nearest is monotonic
//!   in each factor, so each ray's rounded distance lies between the rounded bounds.
//!   Two kinds of packet from several origins get such bounds from a point they nearly
//!   share, with every box grown by a margin that covers how far they miss it and any
//!   rounding: occlusion rays whose segments end near one point (a tile's shadow rays toward
//!   a point light; [`RayPacket::set_converging`]) and rays whose lines pass through one
//!   point behind them (a tile's rays off a plane mirror; [`RayPacket::set_with_apex`]).
//! - **Eight or sixteen rays per box at a leaf**: the rays of the packet are kept as
//!   structure of arrays too, and a leaf's box is tested against eight rays per SIMD slab
//!   test (sixteen where the CPU has AVX-512). The arithmetic is the scalar test's (the
//!   nearer of the two planes is the front one), so each ray takes the same decision it
//!   would take alone.
//!
//! Neither test changes which leaves a ray reaches among those it can hit: they only prune
//! boxes no ray enters, so a packet finds bit for bit what each of its rays finds alone.

use std::mem::MaybeUninit;

use glam::{Vec3A, Vec4};

use super::node::Plane;
use super::walk::{INLINE_STACK, safe_inverse4};
use super::{EMPTY, LEAF, Lanes, PACKET, ROBUST_FAR, RayBoxes, WIDTH, WideBvh, WideNode};
use crate::simd::{self, F32x8};

/// The rays of a packet for the walk, as structure of arrays (four rays per SIMD test at a
/// leaf; one ray's splatted slab constants are made when a walk needs them), and the
/// interval bounds when they apply.
pub struct RayPacket {
    /// `origin[axis][ray]`, `inverse[axis][ray]`; slots at or past `len` hold whatever an
    /// earlier packet left there (never reported: the walk masks them).
    origin: [[f32; PACKET]; 3],
    inverse: [[f32; PACKET]; 3],
    frustum: Option<Frustum>,
    len: usize,
}

/// Bounds on the slab distances of every ray of a packet sharing one origin (or of the
/// reversed segments of occlusion rays converging on one point, with boxes grown by a
/// margin: [`Frustum::converging`]).
#[derive(Clone, Copy)]
struct Frustum {
    /// Per axis, the origin the front planes and the back planes are measured from: both
    /// the shared origin, or moved by the margin so that each box is tested grown by it
    /// (the front plane moved back, the back plane moved out).
    front_origin: [Lanes; 3],
    back_origin: [Lanes; 3],
    /// The limit the bounds are tested against when it is not the packet's own (the
    /// reversed segments' end, 1).
    fixed_limit: Option<f32>,
    /// Where the rays' searches start and what their limits are shifted by, in the bounds'
    /// distances: 0 for rays from the bounds' origin; for rays that start ahead of an apex
    /// behind them, the least and the largest distance from the apex
    /// to a ray's origin (see [`ApexBounds`]).
    start: f32,
    limit_shift: f32,
    /// Per axis, the smallest and largest inverse direction component over the packet.
    inverse_min: [Lanes; 3],
    inverse_max: [Lanes; 3],
    /// Per axis, the `bounds` rows of the planes met first and last (as in `RayBoxes`).
    front: [Plane; 3],
    back: [Plane; 3],
    /// Bit `axis` set when every ray runs the same way along it; the other axes bound
    /// nothing (their rays meet the planes in different orders).
    agreeing: u32,
    /// Bit `axis` set where a box must also overlap `[reach_low, reach_high]` along it: the
    /// extent of converging segments (grown by their margin) along the axes they do not
    /// agree on, which the slab bounds leave open.
    reaching: u32,
    reach_low: [f32; 3],
    reach_high: [f32; 3],
}

impl RayPacket {
    /// The packet of `rays` (`(origin, direction)`, at most [`PACKET`]).
    #[inline]
    pub fn new(rays: &[(Vec3A, Vec3A)]) -> RayPacket {
        let mut packet = RayPacket {
            origin: [[0.0; PACKET]; 3],
            inverse: [[0.0; PACKET]; 3],
            frustum: None,
            len: 0,
        };
        packet.set(rays);
        packet
    }

    /// Refills the packet with `rays` (at most [`PACKET`]; more are ignored).
    #[inline]
    pub fn set(&mut self, rays: &[(Vec3A, Vec3A)]) {
        self.set_rays(rays);
        self.frustum = Frustum::of(&self.origin, &self.inverse, self.len);
    }

    /// Refills the packet with the occlusion rays `rays` (at most [`PACKET`]), ray `r`
    /// searched up to `t_max[r]`, and gives it interval bounds when their segments converge
    /// on one point (a tile's shadow rays toward a point light): see
    /// [`Frustum::converging`]. Returns whether it has them; without them the walk is the
    /// ranged one (a packet from several origins), and the masked walk suits such rays
    /// better.
    ///
    /// In the copy [`simd::dispatch`] chooses: the same operations, which the AVX2 copy
    /// encodes with three operands (SSE2's copy spends a move on most of them, and spills).
    #[inline]
    pub fn set_converging(&mut self, rays: &[(Vec3A, Vec3A)], t_max: &[f32]) -> bool {
        simd::dispatch(SetConverging {
            packet: self,
            rays,
            t_max,
        })
    }

    /// Refills the packet with `rays` (at most [`PACKET`]) and gives it interval bounds when
    /// they share one origin, or when their lines pass through one point behind their
    /// origins and lie close enough together to share leaves (see [`ApexBounds::over_rows`];
    /// `extent`: the largest coordinate of the tree's boxes; `leaf_side`: the typical
    /// side of its leaf boxes, [`super::LeafSides::typical`]). Returns whether it has
    /// bounds.
    #[inline]
    pub fn set_with_apex(&mut self, rays: &[(Vec3A, Vec3A)], extent: f32, leaf_side: f32) -> bool {
        let rays = &rays[..rays.len().min(PACKET)];
        let bits = |o: Vec3A| o.to_array().map(f32::to_bits);
        let one_origin = rays
            .first()
            .is_some_and(|&(first, _)| rays.iter().all(|&(o, _)| bits(o) == bits(first)));
        if one_origin {
            self.set(rays);
            return self.frustum.is_some();
        }
        simd::dispatch(SetWithApex {
            packet: self,
            rays,
            extent,
            leaf_side,
        })
    }

    /// The rays' slab constants, without interval bounds.
    #[inline(always)]
    fn set_rays(&mut self, rays: &[(Vec3A, Vec3A)]) {
        self.set_rows(rays);
        self.invert_directions();
    }

    /// [`RayPacket::set_rows`], with the slots from `len` to the end of the last group of
    /// eight repeating ray 0 (the bounds are decided from the rows eight rays at a time).
    #[inline(always)]
    fn set_padded_rows(&mut self, rays: &[(Vec3A, Vec3A)]) {
        self.set_rows(rays);
        let len = self.len;
        for row in self.origin.iter_mut().chain(&mut self.inverse) {
            repeat_first_to_group_end(row, len);
        }
    }

    /// The rays' origins and directions as rows, the directions in `inverse` (see
    /// [`RayPacket::invert_directions`]).
    #[inline(always)]
    fn set_rows(&mut self, rays: &[(Vec3A, Vec3A)]) {
        let len = rays.len().min(PACKET);
        self.len = len;
        // Four rays at a time: their origins and directions transposed into rows (x86-64).
        #[cfg(target_arch = "x86_64")]
        let whole = {
            for (group, four) in rays[..len].chunks_exact(4).enumerate() {
                let at = group * 4;
                let origins = simd::transpose4([0, 1, 2, 3].map(|k| four[k].0.into()));
                let directions = simd::transpose4([0, 1, 2, 3].map(|k| four[k].1.into()));
                for axis in 0..3 {
                    Vec4::from(origins[axis]).write_to_slice(&mut self.origin[axis][at..at + 4]);
                    Vec4::from(directions[axis])
                        .write_to_slice(&mut self.inverse[axis][at..at + 4]);
                }
            }
            len / 4 * 4
        };
        #[cfg(not(target_arch = "x86_64"))]
        let whole = 0;
        for (i, &(origin, direction)) in rays[..len].iter().enumerate().skip(whole) {
            for axis in 0..3 {
                self.origin[axis][i] = origin[axis];
                self.inverse[axis][i] = direction[axis];
            }
        }
    }

    /// Inverts the directions [`RayPacket::set_rows`] left in `inverse`, four at a time (the
    /// same IEEE division as one at a time; a last, partial group inverts whatever its slots
    /// past `len` hold: no ray reads them).
    #[inline(always)]
    fn invert_directions(&mut self) {
        for row in &mut self.inverse {
            for group in row[..self.len.next_multiple_of(4)].chunks_exact_mut(4) {
                safe_inverse4(Vec4::from_slice(group)).write_to_slice(group);
            }
        }
    }

    /// Ray `r`'s slab constants.
    #[inline(always)]
    pub fn ray(&self, r: usize) -> RayBoxes {
        let at = |a: &[[f32; PACKET]; 3]| [a[0][r], a[1][r], a[2][r]];
        RayBoxes::from_inverse(at(&self.origin), at(&self.inverse))
    }

    /// The rays from `first` on that enter lane `lane` of `node` before their limits: bit `r`
    /// for ray `r`. Eight rays are tested at once ([`F32x8`]), or sixteen in the AVX2 copy
    /// where the CPU has AVX-512 ([`sixteen_rays`]: the same operations lane by lane, so the
    /// same rays).
    #[inline(always)]
    fn entering<const AVX: bool>(
        &self,
        node: &WideNode,
        lane: usize,
        first: usize,
        limits: &[f32; PACKET],
    ) -> u64 {
        #[cfg(target_arch = "x86_64")]
        if AVX && simd::avx512() {
            // SAFETY: `simd::avx512()` holds only where the CPU has AVX-512F.
            return unsafe { sixteen_rays::entering(self, node, lane, first, limits) };
        }
        self.entering_by_eight::<AVX>(node, lane, first, limits)
    }

    /// Calls `each(ray, &mut limit)` for every ray from `first` on that enters lane `lane`
    /// of `node` before its limit ([`RayPacket::entering`]), in ray order, after all of
    /// them are tested; returns whether any did. (`each` changes only the limit of the ray
    /// it is handed, so testing all before handing any changes no ray's test.)
    #[inline(always)]
    fn enter_leaf<const AVX: bool>(
        &self,
        node: &WideNode,
        lane: usize,
        first: usize,
        limits: &mut [f32; PACKET],
        mut each: impl FnMut(usize, &mut f32),
    ) -> bool {
        let entering = self.entering::<AVX>(node, lane, first, limits);
        let mut bits = entering;
        while bits != 0 {
            let r = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            each(r, &mut limits[r]);
        }
        entering != 0
    }

    /// [`RayPacket::entering`] eight rays at a time.
    #[inline(always)]
    fn entering_by_eight<const AVX: bool>(
        &self,
        node: &WideNode,
        lane: usize,
        first: usize,
        limits: &[f32; PACKET],
    ) -> u64 {
        let lower = [0, 1, 2].map(|axis| F32x8::splat(node.bounds[axis][lane]));
        let upper = [0, 1, 2].map(|axis| F32x8::splat(node.bounds[axis + 3][lane]));
        // The group loop written out: as a closure handed to `entering_by_groups` the test
        // was compiled on its own, without the AVX2 copy's target features.
        let mut entering = 0u64;
        for at in (first / 8 * 8..self.len).step_by(8) {
            entering |= u64::from(self.enter_box::<AVX>(&lower, &upper, at, limits)) << at;
        }
        self.from_first(entering, first)
    }

    /// The rays of `entering` from `first` on and below `len`: rays before `first` are not
    /// the subtree's; slots past `len` are no rays.
    #[inline(always)]
    fn from_first(&self, entering: u64, first: usize) -> u64 {
        entering & rays_below(self.len) & !rays_below(first)
    }

    /// The group loop of a leaf's box test, `WIDTH_OF_GROUP` rays per group: `enter(at,
    /// limits)` gives the mask of the rays from `at` that enter the box; the rays from
    /// `first` on (and below `len`) among them, as a mask over the packet.
    #[inline(always)]
    fn entering_by_groups<const WIDTH_OF_GROUP: usize>(
        &self,
        first: usize,
        limits: &[f32; PACKET],
        mut enter: impl FnMut(usize, &[f32; PACKET]) -> u32,
    ) -> u64 {
        let mut entering = 0u64;
        for group in first / WIDTH_OF_GROUP..self.len.div_ceil(WIDTH_OF_GROUP) {
            let at = group * WIDTH_OF_GROUP;
            entering |= u64::from(enter(at, limits)) << at;
        }
        self.from_first(entering, first)
    }

    /// The slab test of one box (`lower`, `upper`, splatted) for the eight rays from `at`:
    /// bit `k` set when ray `at + k` enters it before its limit. Per ray the arithmetic of
    /// the scalar test: the nearer of the two planes is the front one.
    #[inline(always)]
    fn enter_box<const AVX: bool>(
        &self,
        lower: &[F32x8; 3],
        upper: &[F32x8; 3],
        at: usize,
        limits: &[f32; PACKET],
    ) -> u32 {
        let eight = |row: &[f32; PACKET]| F32x8(row[at..at + 8].try_into().expect("8 lanes"));
        let mut near = F32x8::splat(0.0);
        let mut far = F32x8::splat(f32::INFINITY);
        for axis in 0..3 {
            let origin = eight(&self.origin[axis]);
            let inverse = eight(&self.inverse[axis]);
            let t_lower = lower[axis].sub::<AVX>(origin).mul::<AVX>(inverse);
            let t_upper = upper[axis].sub::<AVX>(origin).mul::<AVX>(inverse);
            near = near.max::<AVX>(t_lower.min::<AVX>(t_upper));
            far = far.min::<AVX>(t_lower.max::<AVX>(t_upper));
        }
        let limit = eight(limits);
        near.le_mask::<AVX>(far.mul::<AVX>(F32x8::splat(ROBUST_FAR)).min::<AVX>(limit))
    }
}

/// A leaf's box tested against sixteen rays of a packet per AVX-512 instruction.
#[cfg(target_arch = "x86_64")]
mod sixteen_rays {
    use std::arch::x86_64::*;

    use super::{PACKET, ROBUST_FAR, RayPacket, WideNode};

    /// [`RayPacket::entering`] sixteen rays at a time: per ray, `enter_box`'s operations
    /// in the same order on the same operands (`_mm512_min_ps` and `_mm512_max_ps` pick
    /// between NaN and zero operands as their AVX2 forms do), so the same rays enter.
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn entering(
        packet: &RayPacket,
        node: &WideNode,
        lane: usize,
        first: usize,
        limits: &[f32; PACKET],
    ) -> u64 {
        let lower = [0, 1, 2].map(|axis| _mm512_set1_ps(node.bounds[axis][lane]));
        let upper = [0, 1, 2].map(|axis| _mm512_set1_ps(node.bounds[axis + 3][lane]));
        let robust_far = _mm512_set1_ps(ROBUST_FAR);
        packet.entering_by_groups::<16>(first, limits, |at, limits| {
            // SAFETY (loads): `at + 16 <= PACKET`, within each row.
            let sixteen = |row: &[f32; PACKET]| unsafe { _mm512_loadu_ps(row[at..].as_ptr()) };
            let mut near = _mm512_set1_ps(0.0);
            let mut far = _mm512_set1_ps(f32::INFINITY);
            for axis in 0..3 {
                let origin = sixteen(&packet.origin[axis]);
                let inverse = sixteen(&packet.inverse[axis]);
                let t_lower = _mm512_mul_ps(_mm512_sub_ps(lower[axis], origin), inverse);
                let t_upper = _mm512_mul_ps(_mm512_sub_ps(upper[axis], origin), inverse);
                near = _mm512_max_ps(near, _mm512_min_ps(t_lower, t_upper));
                far = _mm512_min_ps(far, _mm512_max_ps(t_lower, t_upper));
            }
            let ceiling = _mm512_min_ps(_mm512_mul_ps(far, robust_far), sixteen(limits));
            u32::from(_mm512_cmp_ps_mask::<_CMP_LE_OQ>(near, ceiling))
        })
    }
}

/// [`RayPacket::set_with_apex`] for rays from several origins, as a [`simd::Kernel`].
struct SetWithApex<'a> {
    packet: &'a mut RayPacket,
    rays: &'a [(Vec3A, Vec3A)],
    extent: f32,
    leaf_side: f32,
}

impl simd::Kernel for SetWithApex<'_> {
    type Output = bool;

    #[inline(always)]
    fn run<const AVX2: bool>(self) -> bool {
        let (packet, rays) = (self.packet, self.rays);
        packet.frustum = None;
        let Some(apex) = ApexBounds::apex_of(rays) else {
            // Without bounds the packet walks masked, which never reads the rows.
            packet.len = 0;
            return false;
        };
        // The rows first (the directions in `inverse` until inverted): the bounds are
        // decided from them eight rays at a time. Padded with ray 0 to a whole group.
        packet.set_padded_rows(rays);
        let len = packet.len;
        let bounds = ApexBounds::over_rows::<AVX2>(
            apex,
            &packet.origin,
            &packet.inverse,
            len,
            self.extent,
            self.leaf_side,
        );
        let Some(bounds) = bounds else {
            packet.len = 0;
            return false;
        };
        packet.invert_directions();
        packet.frustum = bounds.frustum(&packet.inverse, len);
        packet.frustum.is_some()
    }
}

/// [`RayPacket::set_converging`] as a [`simd::Kernel`].
struct SetConverging<'a> {
    packet: &'a mut RayPacket,
    rays: &'a [(Vec3A, Vec3A)],
    t_max: &'a [f32],
}

impl simd::Kernel for SetConverging<'_> {
    type Output = bool;

    #[inline(always)]
    fn run<const AVX2: bool>(self) -> bool {
        let (packet, rays, t_max) = (self.packet, self.rays, self.t_max);
        let len = rays.len().min(t_max.len()).min(PACKET);
        // The rows first (the directions in `inverse` until inverted): the bounds are made
        // from them eight rays at a time. Padded with ray 0 to a whole group of eight.
        packet.set_padded_rows(&rays[..len]);
        let mut limits = [0.0f32; PACKET];
        limits[..len].copy_from_slice(&t_max[..len]);
        repeat_first_to_group_end(&mut limits, len);
        packet.frustum = Frustum::converging::<AVX2>(&packet.origin, &packet.inverse, &limits, len);
        if packet.frustum.is_some() {
            packet.invert_directions();
        } else {
            // Without bounds the packet walks masked, which never reads the rows.
            packet.len = 0;
        }
        packet.frustum.is_some()
    }
}

impl Frustum {
    /// The bounds of the first `len` rays of a packet (`origin[axis][ray]`,
    /// `inverse[axis][ray]`), or `None` when they do not share one origin (or a direction
    /// is NaN).
    fn of(
        origin: &[[f32; PACKET]; 3],
        inverse: &[[f32; PACKET]; 3],
        len: usize,
    ) -> Option<Frustum> {
        if len == 0 {
            return None;
        }
        for row in origin {
            // Every bit compared without an early exit, so the compiler takes it in vectors.
            let o = row[0].to_bits();
            if row[..len]
                .iter()
                .fold(0, |differ, v| differ | (v.to_bits() ^ o))
                != 0
            {
                return None;
            }
        }
        let shared = [0, 1, 2].map(|axis| Lanes::splat(origin[axis][0]));
        Frustum::over_inverses(shared, shared, inverse, len)
    }

    /// Bounds over the segments of occlusion rays `rays` (`(origin, direction)`, ray `r`
    /// searched for `t` in `[0, t_max[r]]`) walked backwards from one point, or `None` when
    /// they do not converge closely enough for the bounds to prune.
    ///
    /// Why it is exact: the apex `a` is the middle of the segments' far ends, each within
    /// `spread` of it per axis. Ray `r` backwards is `a + s (o_r - a)`, `s` in `[0, 1]`; at
    /// `s = 1 - u` it is within `u * spread` of the forward ray's point at `u * t_max[r]`, so
    /// every point of the forward segment lies within `spread` of the backward one. The
    /// bounds test each box grown by a margin of `spread` plus `2^-16` of the largest
    /// coordinate or length involved, which is more than 30 times what rounding can move a
    /// box test (a few units in the last place of those values, and the robust far factor
    /// of the forward ray's own test). So a box a ray's own slab test enters is entered by
    /// the grown box's backward segment in real numbers, whose rounded slab distances lie
    /// within the bounds (one shared origin, as in [`Frustum::of`]): the test never drops a
    /// box a ray enters. The leaves' boxes are still tested by each ray forward, as alone.
    ///
    /// Takes the rays as rows (`origin[axis][ray]`, `direction[axis][ray]`, `t_max[ray]`),
    /// the slots of the last group of eight past `len` repeating ray 0, and works eight rays
    /// at a time ([`Lanes`]; one AVX instruction per operation in the AVX2 copy): the setup
    /// is per packet, and four rays at a time in SSE2 it took 57 instructions a ray, an
    /// eighth of a shadow ray's walk.
    #[inline(always)]
    fn converging<const AVX: bool>(
        origin: &[[f32; PACKET]; 3],
        direction: &[[f32; PACKET]; 3],
        t_max: &[f32; PACKET],
        len: usize,
    ) -> Option<Frustum> {
        let len = len.min(PACKET);
        if len == 0 {
            return None;
        }
        let groups = len.next_multiple_of(Lanes::LANES);
        let eight = |row: &[f32; PACKET], at: usize| {
            Lanes(row[at..at + Lanes::LANES].try_into().expect("eight slots"))
        };
        let (mut low, mut high) = (
            [Lanes::splat(f32::INFINITY); 3],
            [Lanes::splat(f32::NEG_INFINITY); 3],
        );
        let (mut origin_low, mut origin_high) = (low, high);
        // The largest magnitude of the origins, of the ends and of the reaches. `x.max(largest)`
        // keeps `largest` where `x` is NaN (SSE's and AVX's `max`), so each stays free of NaN;
        // NaN and infinite ends are caught by `unsound`, which `end - end` makes NaN for them.
        let mut largest = [Lanes::splat(0.0); 3];
        let mut unsound = Lanes::splat(0.0);
        for at in (0..groups).step_by(Lanes::LANES) {
            let t = eight(t_max, at);
            for axis in 0..3 {
                let o = eight(&origin[axis], at);
                let reach = eight(&direction[axis], at).mul::<AVX>(t);
                let end = o.add::<AVX>(reach);
                low[axis] = low[axis].min::<AVX>(end);
                high[axis] = high[axis].max::<AVX>(end);
                origin_low[axis] = origin_low[axis].min::<AVX>(o);
                origin_high[axis] = origin_high[axis].max::<AVX>(o);
                largest[0] = o.abs::<AVX>().max::<AVX>(largest[0]);
                largest[1] = end.abs::<AVX>().max::<AVX>(largest[1]);
                largest[2] = reach.abs::<AVX>().max::<AVX>(largest[2]);
                unsound = unsound.add::<AVX>(end.sub::<AVX>(end));
            }
        }
        let scale = largest[0]
            .max::<AVX>(largest[1])
            .max::<AVX>(largest[2])
            .max_lane();
        // Infinite or NaN ends (a directional light's rays have no end). A NaN origin is
        // caught below too: its row inverts to NaN, which `over_inverses` refuses.
        if !(scale < f32::MAX) || unsound.ne_mask::<AVX>(Lanes::splat(0.0)) != 0 {
            return None;
        }
        let reduce = |rows: [Lanes; 3], f: fn(Lanes) -> f32| Vec3A::from(rows.map(f));
        let (low, high) = (reduce(low, Lanes::min_lane), reduce(high, Lanes::max_lane));
        let origin_low = reduce(origin_low, Lanes::min_lane);
        let origin_high = reduce(origin_high, Lanes::max_lane);
        let apex = (low + high) * 0.5;
        let margin = (high - low).max_element() * 0.5 + scale * CONVERGING_SLACK;
        // The reversed segments' directions, `origin - apex`, as rows; eight rays at a time
        // with them, the shortest segment and the spread of the unit directions.
        let mut backwards = [[0.0f32; PACKET]; 3];
        let (mut spread_low, mut spread_high) = (
            [Lanes::splat(f32::INFINITY); 3],
            [Lanes::splat(f32::NEG_INFINITY); 3],
        );
        let mut shortest = Lanes::splat(f32::INFINITY);
        for at in (0..groups).step_by(Lanes::LANES) {
            let b =
                [0, 1, 2].map(|axis| eight(&origin[axis], at).sub::<AVX>(Lanes::splat(apex[axis])));
            let squared = b[0]
                .mul::<AVX>(b[0])
                .add::<AVX>(b[1].mul::<AVX>(b[1]))
                .add::<AVX>(b[2].mul::<AVX>(b[2]));
            let length = squared.sqrt::<AVX>();
            shortest = shortest.min::<AVX>(length);
            for axis in 0..3 {
                let unit = b[axis].div::<AVX>(length);
                spread_low[axis] = spread_low[axis].min::<AVX>(unit);
                spread_high[axis] = spread_high[axis].max::<AVX>(unit);
                backwards[axis][at..at + Lanes::LANES]
                    .copy_from_slice(&b[axis].safe_inverse::<AVX>().0);
            }
        }
        let shortest = shortest.min_lane();
        let spread =
            [0, 1, 2].map(|axis| spread_high[axis].max_lane() - spread_low[axis].min_lane());
        // Rays whose far ends scatter (directional lights, rays from several bounces) or
        // whose directions fan out: their bounds would keep nearly every box.
        let fans_out = spread.into_iter().fold(0.0f32, f32::max) > CONVERGING_SPREAD_MAX;
        if !(margin <= shortest * CONVERGING_MARGIN_MAX) || fans_out {
            return None;
        }
        let splat = [0, 1, 2].map(|axis| Lanes::splat(apex[axis]));
        let mut frustum = Frustum::over_inverses(splat, splat, &backwards, len)?;
        frustum.grow(apex, margin);
        frustum.fixed_limit = Some(1.0 + CONVERGING_SLACK);
        // Every point of a forward segment lies within `margin` of its backward one, which
        // lies between the apex and the ray's origin: inside the box of the origins and the
        // ends, grown by the margin.
        frustum.reaching = !frustum.agreeing & 0b111;
        frustum.reach_low = (origin_low.min(low) - Vec3A::splat(margin)).to_array();
        frustum.reach_high = (origin_high.max(high) + Vec3A::splat(margin)).to_array();
        Some(frustum)
    }

    /// Measures the front and back planes from `apex` moved by `margin`, so that every box
    /// is tested grown by it.
    #[inline(always)]
    fn grow(&mut self, apex: Vec3A, margin: f32) {
        for axis in 0..3 {
            // Positive along the axis: the lower plane is the front one; grown, it moves
            // down by the margin, which is measuring it from `apex + margin`.
            let up = self.front[axis].row() == axis;
            let (front, back) = if up {
                (apex[axis] + margin, apex[axis] - margin)
            } else {
                (apex[axis] - margin, apex[axis] + margin)
            };
            self.front_origin[axis] = Lanes::splat(front);
            self.back_origin[axis] = Lanes::splat(back);
        }
    }

    /// The bounds of the first `len` inverse directions of `inverse[axis][ray]` from the
    /// given front and back origins, or `None` when one is NaN.
    #[inline(always)]
    fn over_inverses(
        front_origin: [Lanes; 3],
        back_origin: [Lanes; 3],
        inverse: &[[f32; PACKET]; 3],
        len: usize,
    ) -> Option<Frustum> {
        let mut frustum = Frustum {
            front_origin,
            back_origin,
            fixed_limit: None,
            start: 0.0,
            limit_shift: 0.0,
            inverse_min: [Lanes::splat(0.0); 3],
            inverse_max: [Lanes::splat(0.0); 3],
            front: [Plane::LowX; 3],
            back: [Plane::LowX; 3],
            agreeing: 0,
            reaching: 0,
            reach_low: [f32::NEG_INFINITY; 3],
            reach_high: [f32::INFINITY; 3],
        };
        // Four at a time; the slots of a last, partial group repeat ray 0.
        let whole = len / 4 * 4;
        let tail = Vec4::new(0.0, 1.0, 2.0, 3.0).cmplt(Vec4::splat((len - whole) as f32));
        for axis in 0..3 {
            let row = &inverse[axis];
            let first = Vec4::splat(row[0]);
            let (mut min, mut max) = (first, first);
            // Bit k: some (every) group has a negative inverse in lane k; lanes past `len`
            // count as negative for `every` and not for `some`.
            let (mut some_negative, mut every_negative, mut nan) = (0, 0b1111, 0);
            let mut take = |v: Vec4, live: u32| {
                min = min.min(v);
                max = max.max(v);
                let negative = v.cmplt(Vec4::ZERO).bitmask();
                some_negative |= negative & live;
                every_negative &= negative | !live;
                nan |= v.cmpne(v).bitmask();
            };
            // By whole chunks, not a stepped range: a stepped range's iterator and the
            // slices' bounds checks cost about 2.6 instructions a primary ray here.
            for four in row[..whole].chunks_exact(4) {
                take(Vec4::from_slice(four), 0b1111);
            }
            if whole < len {
                let v = Vec4::select(tail, Vec4::from_slice(&row[whole..whole + 4]), first);
                take(v, tail.bitmask());
            }
            if nan != 0 {
                return None;
            }
            frustum.inverse_min[axis] = Lanes::splat(min.min_element());
            frustum.inverse_max[axis] = Lanes::splat(max.max_element());
            // As `RayBoxes`: a negative inverse meets the upper plane first.
            let all_negative = every_negative & 0b1111 == 0b1111;
            frustum.front[axis] = Plane::of(axis, all_negative);
            frustum.back[axis] = Plane::of(axis, !all_negative);
            if some_negative == 0 || all_negative {
                frustum.agreeing |= 1 << axis;
            }
        }
        Some(frustum)
    }

    /// The lanes of `node` that some ray of the packet may enter before `t_max` (the
    /// largest limit of the packet's rays). A lane left out is entered by no ray.
    #[inline(always)]
    fn may_enter<const AVX: bool>(&self, node: &WideNode, t_max: f32) -> (Lanes, u32) {
        let mut near = Lanes::splat(self.start);
        let mut far = Lanes::splat(f32::INFINITY);
        for axis in 0..3 {
            if self.agreeing & (1 << axis) == 0 {
                continue;
            }
            let front = Lanes(*node.plane(self.front[axis])).sub::<AVX>(self.front_origin[axis]);
            let back = Lanes(*node.plane(self.back[axis])).sub::<AVX>(self.back_origin[axis]);
            let (low, high) = (self.inverse_min[axis], self.inverse_max[axis]);
            near = near.max::<AVX>(front.mul::<AVX>(low).min::<AVX>(front.mul::<AVX>(high)));
            far = far.min::<AVX>(back.mul::<AVX>(low).max::<AVX>(back.mul::<AVX>(high)));
        }
        let far = far
            .mul::<AVX>(Lanes::splat(ROBUST_FAR))
            .min::<AVX>(Lanes::splat(
                self.fixed_limit.unwrap_or(t_max + self.limit_shift),
            ));
        let mut may = near.le_mask::<AVX>(far);
        if self.reaching != 0 {
            for axis in 0..3 {
                if self.reaching & (1 << axis) != 0 {
                    let (low, high) = (Lanes(node.bounds[axis]), Lanes(node.bounds[axis + 3]));
                    may &= low.le_mask::<AVX>(Lanes::splat(self.reach_high[axis]))
                        & Lanes::splat(self.reach_low[axis]).le_mask::<AVX>(high);
                }
            }
        }
        (near, may)
    }
}

/// Where the lines of a packet's rays meet behind their origins, and how far the bounds
/// from there must reach ([`ApexBounds::over_rows`]): decided from the rays alone, so a packet
/// without such a point makes none of its slab constants.
struct ApexBounds {
    apex: Vec3A,
    /// How far apart neighbouring rays start (see [`ApexBounds::over_rows`]).
    #[cfg_attr(not(test), allow(dead_code))]
    spacing: f32,
    /// How much every box is grown.
    margin: f32,
    /// The bounds' distances start here, and the packet's limit is shifted by `limit_shift`.
    start: f32,
    limit_shift: f32,
}

impl ApexBounds {
    /// [`ApexBounds::apex_of`], then [`ApexBounds::over_rows`] on the rows of `rays`.
    #[cfg(test)]
    fn behind(rays: &[(Vec3A, Vec3A)], extent: f32, leaf_side: f32) -> Option<ApexBounds> {
        let apex = ApexBounds::apex_of(rays)?;
        let mut packet = RayPacket::new(&[]);
        packet.set_padded_rows(rays);
        let len = packet.len;
        Self::over_rows::<false>(
            apex,
            &packet.origin,
            &packet.inverse,
            len,
            extent,
            leaf_side,
        )
    }

    /// Where the lines of the packet's rays `rays` may meet: where the first and last
    /// rays' lines pass closest, if three rays between them pass near it, behind their
    /// origins (`None` otherwise, and for fewer than two rays).
    #[inline(always)]
    fn apex_of(rays: &[(Vec3A, Vec3A)]) -> Option<Vec3A> {
        let len = rays.len().min(PACKET);
        if len < 2 {
            return None;
        }
        let ((first, first_d), (last, last_d)) = (rays[0], rays[len - 1]);
        let apex = closest_point_of_lines(first, first_d, last, last_d)?;
        // Most bounce packets have no such point: three rays between the two reject them
        // before the pass over every ray.
        let near_the_apex = |r: usize| {
            let (o, d) = rays[r];
            let from_apex = o - apex;
            let along = from_apex.dot(d) / d.length_squared();
            let offset = (from_apex - d * along).abs().max_element();
            along > 0.0 && offset <= along * d.length() * CONVERGING_MARGIN_MAX
        };
        [len / 4, len / 2, 3 * len / 4]
            .into_iter()
            .all(near_the_apex)
            .then_some(apex)
    }

    /// Bounds from `apex` for rays from several origins whose lines pass (nearly) through
    /// it, behind them: a tile's rays reflected by a plane mirror, which leave it as if from
    /// the camera's mirror image, decided from the packet's own (forward) rays; `extent` is
    /// the largest coordinate of the scene's boxes. `None` when some ray's line does not
    /// pass near `apex`, it is not behind every origin, the rays fan out, or neighbouring
    /// rays start more than [`APEX_SPACING_MAX_LEAVES`] times `leaf_side` (the tree's
    /// typical leaf) apart.
    ///
    /// Why the spacing: the interval walk tests every ray of the packet against each leaf
    /// box its bounds reach. That pays while neighbouring rays are closer than a leaf is
    /// wide, so that most rays enter the leaves the bounds reach; a packet whose rays lie
    /// several leaves apart reaches many leaves that one or two of its rays enter, and walks
    /// masked (each ray its own leaves) for fewer instructions. Counted on recorded mirror
    /// rays (`mipray bench --rays`, callgrind), BART Robots frame 100's took 1,223
    /// instructions a ray with every apex packet bounded and 1,100 with none, and 956-963
    /// with the spacing capped at 1.5 to 4 leaves; BART Kitchen's and Museum's, whose apex
    /// packets are nearly all below 1 leaf, did not change. The cap sits in the middle of
    /// that flat range. The spacing is the rays' spread of directions times the distance
    /// from the apex to the nearest origin (the packet's width where its rays start),
    /// over the square root of the ray count (a packet is a square block of pixels).
    ///
    /// Why it is exact: with the apex `a` found where the first and last rays' lines pass
    /// closest, ray `r` is `a + e_r + (c_r + t) d_r`, `c_r` the distance along `d_r` from
    /// the apex to its origin and `e_r` the origin's offset from the line through the apex.
    /// Per axis its slab distances are those of a ray from `a + e_r` shifted by `c_r`, the
    /// same shift on every axis, so it enters a box for `t` in `[0, limit]` exactly when that
    /// ray enters it for distances in `[c_r, c_r + limit]`; and that ray enters the box
    /// only if the ray from `a` along `d_r` enters it grown by `|e_r|`. The bounds grow
    /// every box by the largest offset plus `2^-16` of the largest coordinate involved (far
    /// above rounding, as in [`Frustum::converging`]) and bound the distances from `a` by
    /// the packet's inverse directions, starting at the least `c_r` and ending at the
    /// largest `c_r` plus the packet's limit.
    ///
    /// Decided in two steps: [`ApexBounds::apex_of`] finds the point from the rays (and
    /// rejects most packets on three of them), then [`ApexBounds::over_rows`] checks every
    /// ray and measures the bounds, eight rays at a time (one pass over rays per packet
    /// that has an apex: one ray at a time it cost BART Robots' mirror rays about 45
    /// instructions a ray, Kitchen's 34).
    ///
    /// Takes the first `len` rays of the rows `origin[axis][ray]` and
    /// `direction[axis][ray]` (the slots of the last group of eight past `len` repeating
    /// ray 0), eight rays at a time ([`Lanes`]).
    /// A ray whose distance along its direction from the apex is not finite (a zero or
    /// overflowing direction) gives `None`.
    #[inline(always)]
    fn over_rows<const AVX: bool>(
        apex: Vec3A,
        origin: &[[f32; PACKET]; 3],
        direction: &[[f32; PACKET]; 3],
        len: usize,
        extent: f32,
        leaf_side: f32,
    ) -> Option<ApexBounds> {
        let len = len.min(PACKET);
        let eight = |row: &[f32; PACKET], at: usize| {
            Lanes(row[at..at + Lanes::LANES].try_into().expect("eight slots"))
        };
        let dot = |a: [Lanes; 3], b: [Lanes; 3]| {
            a[0].mul::<AVX>(b[0])
                .add::<AVX>(a[1].mul::<AVX>(b[1]))
                .add::<AVX>(a[2].mul::<AVX>(b[2]))
        };
        let (mut offset, mut scale) = (Lanes::splat(0.0), Lanes::splat(0.0));
        let (mut nearest, mut farthest) = (Lanes::splat(f32::INFINITY), Lanes::splat(0.0));
        let (mut spread_low, mut spread_high) = (
            [Lanes::splat(f32::INFINITY); 3],
            [Lanes::splat(f32::NEG_INFINITY); 3],
        );
        // Stays 0 while every distance along is finite (`x - x` is NaN for the others).
        let mut unsound = Lanes::splat(0.0);
        for at in (0..len.next_multiple_of(Lanes::LANES)).step_by(Lanes::LANES) {
            let o = [0, 1, 2].map(|axis| eight(&origin[axis], at));
            let d = [0, 1, 2].map(|axis| eight(&direction[axis], at));
            let from_apex = [0, 1, 2].map(|axis| o[axis].sub::<AVX>(Lanes::splat(apex[axis])));
            let squared = dot(d, d);
            let along = dot(from_apex, d).div::<AVX>(squared);
            unsound = unsound.add::<AVX>(along.sub::<AVX>(along));
            nearest = nearest.min::<AVX>(along);
            farthest = farthest.max::<AVX>(along);
            let length = squared.sqrt::<AVX>();
            for axis in 0..3 {
                let off = from_apex[axis].sub::<AVX>(d[axis].mul::<AVX>(along));
                offset = offset.max::<AVX>(off.abs::<AVX>());
                scale = scale.max::<AVX>(o[axis].abs::<AVX>());
                let unit = d[axis].div::<AVX>(length);
                spread_low[axis] = spread_low[axis].min::<AVX>(unit);
                spread_high[axis] = spread_high[axis].max::<AVX>(unit);
            }
        }
        if unsound.ne_mask::<AVX>(Lanes::splat(0.0)) != 0 {
            return None;
        }
        let (offset, nearest, farthest) =
            (offset.max_lane(), nearest.min_lane(), farthest.max_lane());
        let scale = scale.max_lane().max(extent).max(apex.abs().max_element());
        let margin = offset + scale * CONVERGING_SLACK;
        let spread = (0..3)
            .map(|axis| spread_high[axis].max_lane() - spread_low[axis].min_lane())
            .fold(0.0f32, f32::max);
        let fans_out = !(spread <= CONVERGING_SPREAD_MAX);
        let spacing = spread * nearest / (len as f32).sqrt();
        let apart = !(spacing <= APEX_SPACING_MAX_LEAVES * leaf_side);
        // Behind every origin, and far enough behind that the grown boxes stay narrow.
        if !(nearest > 0.0 && margin <= nearest * CONVERGING_MARGIN_MAX && scale < f32::MAX)
            || fans_out
            || apart
        {
            return None;
        }
        // Rounding of `along` is covered by the margin in space, not in distance: widen
        // the distances by the same relative slack.
        Some(ApexBounds {
            apex,
            spacing,
            margin,
            start: nearest * (1.0 - CONVERGING_SLACK) - margin,
            limit_shift: farthest * (1.0 + CONVERGING_SLACK) + margin,
        })
    }

    /// The bounds over the first `len` of the packet's inverse directions
    /// (`inverse[axis][ray]`), or `None` when one is NaN.
    fn frustum(&self, inverse: &[[f32; PACKET]; 3], len: usize) -> Option<Frustum> {
        let splat = [0, 1, 2].map(|axis| Lanes::splat(self.apex[axis]));
        let mut frustum = Frustum::over_inverses(splat, splat, inverse, len)?;
        frustum.grow(self.apex, self.margin);
        frustum.start = self.start;
        frustum.limit_shift = self.limit_shift;
        Some(frustum)
    }
}

/// The point halfway between the closest points of the lines `p + s u` and `q + t v`
/// (`None` for lines too close to parallel to place it, or values that are not finite).
fn closest_point_of_lines(p: Vec3A, u: Vec3A, q: Vec3A, v: Vec3A) -> Option<Vec3A> {
    let w = p - q;
    let (a, b, c) = (u.dot(u), u.dot(v), v.dot(v));
    let (d, e) = (u.dot(w), v.dot(w));
    let denominator = a * c - b * b;
    if !(denominator > 1e-6 * a * c) {
        return None;
    }
    let s = (b * e - c * d) / denominator;
    let t = (a * e - b * d) / denominator;
    let point = ((p + u * s) + (q + v * t)) * 0.5;
    point.is_finite().then_some(point)
}

/// Repeats `row[0]` in the slots from `len` to the end of its group of eight ([`Lanes`]),
/// so that a pass eight (or four) at a time over the first `len` slots sees only their
/// values.
#[inline(always)]
fn repeat_first_to_group_end(row: &mut [f32; PACKET], len: usize) {
    let first = row[0];
    row[len..len.next_multiple_of(Lanes::LANES).min(PACKET)].fill(first);
}

/// The margin of [`Frustum::converging`] beyond the spread of the segments' ends, as a
/// fraction of the largest coordinate or length involved (2^-16).
const CONVERGING_SLACK: f32 = 1.0 / 65536.0;

// The bounds' passes take whole groups of eight slots.
const _: () = assert!(PACKET % Lanes::LANES == 0);

/// Rays from an apex behind them get bounds only when neighbouring rays start at most this
/// many typical leaf sides apart ([`ApexBounds::over_rows`]).
const APEX_SPACING_MAX_LEAVES: f32 = 2.0;

/// Converging rays get bounds only when the margin is at most this fraction of the
/// shortest segment: beyond it the grown boxes keep most of what a ray alone would skip.
const CONVERGING_MARGIN_MAX: f32 = 1.0 / 16.0;

/// Converging rays get bounds only when their unit directions differ by at most this much
/// along every axis. Measured on BART Kitchen frame 400 (a tile's shadow rays toward its
/// light): bounds from a spread of 0.05 to 0.15 traced the primary hits' shadow rays 1.7x
/// faster than the masked walk, and wider spreads (shadow rays of mirrored hits) lost to it.
const CONVERGING_SPREAD_MAX: f32 = 0.1;

/// A pending subtree of a packet walk: the child (as in [`WideNode::child`]) with its leaf
/// count, the first ray of the packet that enters it, and the node and lane holding its box
/// (a leaf's rays test that box before its triangles).
#[derive(Clone, Copy)]
struct PacketEntry {
    child: u32,
    count: u32,
    first: u32,
    node: u32,
    lane: u32,
}

impl WideBvh {
    /// Walks the tree once for a packet of rays. With one origin, the interval test picks
    /// the children to walk; otherwise a subtree is carried with the first ray of the packet
    /// that enters it, found by testing the rays in order from the parent's first ray. At a
    /// leaf every ray from the first on tests the leaf's box with its own limit, and those
    /// inside call `leaf(ray, leaf_ref, count, &mut limit)`; `limits[r]` is ray `r`'s limit.
    ///
    /// Every ray reaches every leaf whose box it enters before its limit (a ray that enters
    /// a child is never before that child's first ray), so a closest-hit leaf finds exactly
    /// what [`WideBvh::traverse`] finds for each ray alone.
    pub fn traverse_packet(
        &self,
        packet: &RayPacket,
        limits: &mut [f32; PACKET],
        leaf: impl FnMut(usize, u32, u32, &mut f32),
    ) {
        self.traverse_packet_with(packet, limits, EachRay(leaf));
    }

    /// [`WideBvh::traverse_packet`] calling the leaf once with all the rays that enter it:
    /// [`GatheredLeaf::visit_entering`] with their mask (by default listed in ray order for
    /// `leaf(rays, leaf_ref, count, limits)`). For leaves whose work is cheaper for many
    /// rays together than one ray at a time (a top-level leaf: the rays enter its instance
    /// as a packet of their own; a triangle leaf: each triangle tested across the rays).
    pub fn traverse_packet_gathered(
        &self,
        packet: &RayPacket,
        limits: &mut [f32; PACKET],
        leaf: impl GatheredLeaf,
    ) {
        self.traverse_packet_with(packet, limits, Gathered(leaf));
    }

    #[inline(always)]
    fn traverse_packet_with(
        &self,
        packet: &RayPacket,
        limits: &mut [f32; PACKET],
        mut leaf: impl PacketLeaf,
    ) {
        let n = packet.len;
        if let Some((first, count)) = self.root_leaf {
            leaf.enter_all::<false>(n, first, count, limits);
            return;
        }
        if self.nodes.is_empty() || n == 0 {
            return;
        }
        let needed = self.depth * WIDTH + 1;
        if needed <= INLINE_STACK * 2 {
            let mut stack = [const { MaybeUninit::uninit() }; INLINE_STACK * 2];
            self.walk_packet_on(&mut stack, packet, limits, &mut leaf);
        } else {
            let mut stack = vec![MaybeUninit::uninit(); needed];
            self.walk_packet_on(&mut stack, packet, limits, &mut leaf);
        }
    }

    /// [`WideBvh::walk_packet`] in the copy [`simd::dispatch`] chooses.
    #[inline(always)]
    fn walk_packet_on(
        &self,
        stack: &mut [MaybeUninit<PacketEntry>],
        packet: &RayPacket,
        limits: &mut [f32; PACKET],
        leaf: &mut impl PacketLeaf,
    ) {
        simd::dispatch(PacketWalk {
            bvh: self,
            stack,
            packet,
            limits,
            leaf,
        })
    }

    #[inline(always)]
    fn walk_packet<const AVX: bool>(
        &self,
        stack: &mut [MaybeUninit<PacketEntry>],
        packet: &RayPacket,
        limits: &mut [f32; PACKET],
        leaf: &mut impl PacketLeaf,
    ) {
        let n = packet.len;
        // The largest limit of the packet: the interval test's `t_max`. Limits only
        // shrink, so a stale value is still a bound; it is renewed after leaves (below).
        let largest_limit = |limits: &[f32; PACKET]| largest(&limits[..n]);
        let mut packet_limit = largest_limit(limits);
        let mut limit_stale = false;
        stack[0] = MaybeUninit::new(PacketEntry {
            child: 0,
            count: 0,
            first: 0,
            node: 0,
            lane: 0,
        });
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            // SAFETY: entries below `top` were all written before.
            let entry = unsafe { stack[top].assume_init() };
            let first = entry.first as usize;
            if entry.child & LEAF != 0 {
                let parent = &self.nodes[entry.node as usize];
                let (leaf_ref, count) = (entry.child & !LEAF, entry.count);
                let any = leaf.enter::<AVX>(
                    packet,
                    parent,
                    entry.lane as usize,
                    first,
                    leaf_ref,
                    count,
                    limits,
                );
                // The packet's limit is renewed at the next node, not here: consecutive
                // leaves share one renewal, and the leaf's own stores to the limits have
                // drained by then (read back at once, they stalled the vector read).
                limit_stale |= any;
                continue;
            }
            if limit_stale {
                limit_stale = false;
                packet_limit = largest_limit(limits);
                if packet_limit < 0.0 {
                    // Every ray is done (any-hit queries mark a finished ray with a
                    // negative limit); closest-hit limits never go below 0.
                    return;
                }
            }
            let node = &self.nodes[entry.child as usize];
            let mut push = |lane: usize, first: u32, top: &mut usize| {
                stack[*top] = MaybeUninit::new(PacketEntry {
                    child: node.child[lane],
                    count: node.count[lane],
                    first,
                    node: entry.child,
                    lane: lane as u32,
                });
                *top += 1;
            };
            if let Some(frustum) = &packet.frustum {
                // One origin: the interval test alone decides which children the packet
                // walks, far to near by where the packet can first enter them, each from the
                // parent's first ray. Searching for each child's first ray cost more than
                // the leaf tests it spared (8% of a primary-ray frame).
                let (near, may) = frustum.may_enter::<AVX>(node, packet_limit);
                let (lanes, count) =
                    super::walk::lanes_near_to_far::<false>(near, used_lanes(node) & may);
                for &lane in lanes[..count].iter().rev() {
                    push(lane, first as u32, &mut top);
                }
                continue;
            }
            // Rays from several origins: the first ray decides the order; later rays only
            // claim children it missed, and a child is carried from the first that enters it.
            let used = used_lanes(node);
            let (near, entered) = packet.ray(first).enter::<AVX>(node, limits[first]);
            let mut first_of = [first as u32; WIDTH];
            let mut missed = used & !entered;
            let mut r = first + 1;
            while missed != 0 && r < n {
                let (_, m) = packet.ray(r).enter::<AVX>(node, limits[r]);
                let mut claimed = m & missed;
                missed &= !claimed;
                while claimed != 0 {
                    let lane = claimed.trailing_zeros() as usize;
                    claimed &= claimed - 1;
                    first_of[lane] = r as u32;
                }
                r += 1;
            }
            // Children the first ray missed go deepest (visited last), then the entered ones
            // far to near, so the nearest is popped next.
            let mut bits = used & !entered & !missed;
            while bits != 0 {
                let lane = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                push(lane, first_of[lane], &mut top);
            }
            let (lanes, count) = super::walk::lanes_near_to_far::<false>(near, entered);
            for &lane in lanes[..count].iter().rev() {
                push(lane, first_of[lane], &mut top);
            }
        }
    }
}

/// One packet walk as a [`simd::Kernel`] (see `walk::Walk`).
struct PacketWalk<'a, P> {
    bvh: &'a WideBvh,
    stack: &'a mut [MaybeUninit<PacketEntry>],
    packet: &'a RayPacket,
    limits: &'a mut [f32; PACKET],
    leaf: &'a mut P,
}

impl<P: PacketLeaf> simd::Kernel for PacketWalk<'_, P> {
    type Output = ();

    #[inline(always)]
    fn run<const AVX2: bool>(self) {
        self.bvh
            .walk_packet::<AVX2>(self.stack, self.packet, self.limits, self.leaf)
    }
}

/// What a packet walk does at a leaf (the box of lane `lane` of `node`): the rays from
/// `first` on that enter the box before their limits run the leaf; returns whether any did.
trait PacketLeaf {
    #[allow(clippy::too_many_arguments)]
    fn enter<const AVX: bool>(
        &mut self,
        packet: &RayPacket,
        node: &WideNode,
        lane: usize,
        first: usize,
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) -> bool;

    /// The leaf of a one-leaf tree (no box kept): every ray of the `n` runs it.
    fn enter_all<const AVX: bool>(
        &mut self,
        n: usize,
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    );
}

/// A leaf run once with every ray of a packet inside its box: `visit(rays, leaf_ref, count,
/// limits)` with the rays in ray order, or, from the packet walk, `visit_entering` with
/// their mask (which lists them for `visit` unless the leaf takes the mask). `AVX` is true
/// in the walk's AVX2 copy, so a leaf test that computes across rays can use
/// [`crate::simd::F32x8`]'s AVX operations. Closures implement it (ignoring `AVX`).
pub trait GatheredLeaf {
    /// Whether `visit` may stop a ray (set its limit below 0, as any-hit leaves do). A
    /// masked walk looks for stopped rays after each leaf only where it may: closest-hit
    /// limits never go below 0, and reading them back right after the leaf stored them
    /// stalls. (A leaf that stops a ray anyway is still exact: a negative limit enters no
    /// box; the walk only ends later.)
    const STOPS_RAYS: bool = true;

    fn visit<const AVX: bool>(
        &mut self,
        rays: &[u8],
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    );

    /// [`GatheredLeaf::visit`] for the rays of the mask `entering` (bit `r` for ray `r`,
    /// not 0), as the packet walk finds them; by default listed in ray order and visited.
    /// A leaf that tests rays in fixed groups of lanes can take the mask as it is.
    #[inline(always)]
    fn visit_entering<const AVX: bool>(
        &mut self,
        entering: u64,
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        let mut buffer = [0u8; PACKET];
        let rays = listed(entering, &mut buffer);
        self.visit::<AVX>(rays, leaf_ref, count, limits);
    }
}

/// The rays of the mask `rays` (bit `r` for ray `r`) as a list in ray order, in `buffer`.
#[inline(always)]
pub fn listed(rays: u64, buffer: &mut [u8; PACKET]) -> &[u8] {
    let mut n = 0;
    let mut bits = rays;
    while bits != 0 {
        buffer[n] = bits.trailing_zeros() as u8;
        bits &= bits - 1;
        n += 1;
    }
    &buffer[..n]
}

impl<F: FnMut(&[u8], u32, u32, &mut [f32; PACKET])> GatheredLeaf for F {
    #[inline(always)]
    fn visit<const AVX: bool>(
        &mut self,
        rays: &[u8],
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        self(rays, leaf_ref, count, limits)
    }
}

/// The leaf run ray by ray, as each ray is found inside the box.
struct EachRay<F>(F);

impl<F: FnMut(usize, u32, u32, &mut f32)> PacketLeaf for EachRay<F> {
    #[inline(always)]
    fn enter<const AVX: bool>(
        &mut self,
        packet: &RayPacket,
        node: &WideNode,
        lane: usize,
        first: usize,
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) -> bool {
        packet.enter_leaf::<AVX>(node, lane, first, limits, |r, limit| {
            (self.0)(r, leaf_ref, count, limit)
        })
    }

    fn enter_all<const AVX: bool>(
        &mut self,
        n: usize,
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        for (r, limit) in limits.iter_mut().enumerate().take(n) {
            (self.0)(r, leaf_ref, count, limit);
        }
    }
}

// Ray indices of a gathered leaf are bytes.
const _: () = assert!(PACKET <= 256);

/// The leaf run once with every ray inside the box. A ray's box test reads only its own
/// limit, which only its own leaf work lowers, so gathering the rays first decides for
/// each what [`EachRay`] decides.
struct Gathered<F>(F);

impl<G: GatheredLeaf> PacketLeaf for Gathered<G> {
    #[inline(always)]
    fn enter<const AVX: bool>(
        &mut self,
        packet: &RayPacket,
        node: &WideNode,
        lane: usize,
        first: usize,
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) -> bool {
        let entering = packet.entering::<AVX>(node, lane, first, limits);
        if entering != 0 {
            self.0
                .visit_entering::<AVX>(entering, leaf_ref, count, limits);
        }
        entering != 0
    }

    fn enter_all<const AVX: bool>(
        &mut self,
        n: usize,
        leaf_ref: u32,
        count: u32,
        limits: &mut [f32; PACKET],
    ) {
        let rays: [u8; PACKET] = std::array::from_fn(|r| r as u8);
        if n > 0 {
            self.0.visit::<AVX>(&rays[..n], leaf_ref, count, limits);
        }
    }
}

/// The rays `0..n` of a packet as a mask (bit `r` for ray `r`; `n` up to [`PACKET`]).
#[inline(always)]
pub fn rays_below(n: usize) -> u64 {
    if n >= 64 { u64::MAX } else { (1u64 << n) - 1 }
}

const _: () = assert!(PACKET == 64, "a packet's rays are the bits of a u64");

/// The lanes of `node` that hold a child.
#[inline(always)]
fn used_lanes(node: &WideNode) -> u32 {
    (0..WIDTH).fold(0, |m, lane| {
        m | (((node.child[lane] != EMPTY) as u32) << lane)
    })
}

/// The largest of `values`, ignoring NaN (`NEG_INFINITY` for none): what a fold with
/// `f32::max` gives, but for the sign of a zero maximum (a walk reads a limit only by
/// comparison, where the two zeros are equal).
///
/// Why not that fold: `f32::max` must return the other operand where one is NaN, so the
/// compiler follows each vector maximum with a NaN test and a blend, and ends with a chain
/// of eight scalar steps of the same; renewing a packet's limit that way took 4% of the
/// samples of BART Kitchen's first-bounce shadow packets on an Intel Xeon VM. A comparison
/// (`b > a`, false for NaN) is one maximum instruction; eight running maxima (a packet's
/// limits come in rows of eight) and a tree for the last three steps take a third of that
/// (docs/benchmark-log.md).
#[inline(always)]
fn largest(values: &[f32]) -> f32 {
    let larger = |a: f32, b: f32| if b > a { b } else { a };
    let mut most = [f32::NEG_INFINITY; 8];
    let rows = values.chunks_exact(8);
    let rest = rows.remainder();
    for row in rows {
        let row: &[f32; 8] = row.try_into().expect("a row of eight");
        for (most, &value) in most.iter_mut().zip(row) {
            *most = larger(*most, value);
        }
    }
    for &value in rest {
        most[0] = larger(most[0], value);
    }
    let four = [0, 1, 2, 3].map(|i| larger(most[i], most[i + 4]));
    larger(larger(four[0], four[2]), larger(four[1], four[3]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::aabb::Aabb;

    /// A xorshift stream of floats in [-2, 2).
    fn stream(mut seed: u64) -> impl FnMut() -> f32 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 4.0 - 2.0
        }
    }

    /// `largest` is the fold with `f32::max` on every length a packet has, with NaN, both
    /// infinities, negative (stopped) limits and zeros among the values: the same value,
    /// and a zero of either sign where the fold gives a zero.
    #[test]
    fn largest_is_the_fold_with_max() {
        let mut next = stream(0x1a2b_3c4d);
        let specials = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0, -1.0];
        for len in 0..=PACKET {
            for trial in 0..20 {
                let values: Vec<f32> = (0..len)
                    .map(|i| {
                        let v = next();
                        if (i + trial) % 7 == 0 {
                            specials[(i + trial) % specials.len()]
                        } else if trial % 5 == 0 {
                            f32::NAN
                        } else {
                            v
                        }
                    })
                    .collect();
                let fold = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                let got = largest(&values);
                assert!(!got.is_nan(), "{values:?}");
                assert_eq!(got, fold, "{values:?}");
            }
        }
        assert_eq!(largest(&[]), f32::NEG_INFINITY);
        assert_eq!(largest(&[f32::NAN; 64]), f32::NEG_INFINITY);
    }

    fn random_node(next: &mut impl FnMut() -> f32) -> WideNode {
        let mut node = WideNode::UNUSED;
        for lane in 0..WIDTH {
            let a = Vec3A::new(next(), next(), next()) * 3.0;
            let b = a + Vec3A::new(next(), next(), next()).abs() * 1.5;
            node.set_box(lane, &Aabb::new(a, b));
            node.child[lane] = lane as u32 + 1;
        }
        node
    }

    /// Packets of a camera's rays (one origin), with directions that agree in sign, that
    /// straddle an axis, that have zero components of both signs, and rays from several
    /// origins (no interval bounds).
    fn packets(next: &mut impl FnMut() -> f32) -> Vec<Vec<(Vec3A, Vec3A)>> {
        let eye = Vec3A::new(next(), next(), 8.0);
        let aim = |x: f32, y: f32| (eye, Vec3A::new(x, y, -1.0).normalize());
        let block: Vec<_> = (0..64)
            .map(|i| aim(0.3 + (i % 8) as f32 * 0.02, -0.2 + (i / 8) as f32 * 0.02))
            .collect();
        let straddling: Vec<_> = (0..64)
            .map(|i| aim(-0.3 + (i % 8) as f32 * 0.08, -0.3 + (i / 8) as f32 * 0.08))
            .collect();
        let zeros: Vec<_> = (0..37)
            .map(|i| {
                let x = [0.0, -0.0, 0.01, -0.01][i % 4];
                (eye, Vec3A::new(x, (i / 4) as f32 * 0.05 - 0.2, -1.0))
            })
            .collect();
        let scattered: Vec<_> = (0..50)
            .map(|_| {
                let o = Vec3A::new(next(), next(), next()) * 4.0;
                (o, Vec3A::new(next(), next(), next()) - o * 0.3)
            })
            .collect();
        vec![block, straddling, zeros, scattered]
    }

    /// Each ray's slab constants in the packet's rows (made four rays at a time where they
    /// can be) are those the ray makes alone (origin and inverse bits; its planes follow
    /// from the inverse's signs), for packets of every length from the test's
    /// sets (zero components of both signs included), refilled over longer packets.
    #[test]
    fn a_packets_rows_hold_each_rays_own_constants() {
        let mut next = stream(0x51ab_c0de_77aa_1234);
        let sets = packets(&mut next);
        let mut packet = RayPacket::new(&sets[0]);
        let mut compared = 0;
        for rays in &sets {
            for len in (0..=rays.len().min(PACKET)).rev() {
                packet.set(&rays[..len]);
                assert_eq!(packet.len, len);
                for (r, &(origin, direction)) in rays[..len].iter().enumerate() {
                    let (alone, mine) = (RayBoxes::new(origin, direction), packet.ray(r));
                    let bits = |ray: &RayBoxes| {
                        let (o, inv) = ray.constants();
                        (o.map(f32::to_bits), inv.map(f32::to_bits))
                    };
                    assert_eq!(bits(&mine), bits(&alone), "ray {r} of {len}");
                    compared += 1;
                }
            }
        }
        assert!(compared > 5_000, "{compared}");
    }

    /// The rays of a mask over a packet, in ray order.
    fn rays_of(mask: u64) -> impl Iterator<Item = usize> {
        (0..PACKET).filter(move |&r| mask & (1 << r) != 0)
    }

    /// The rays from `first` on that enter lane `lane` of `node` (with `limits`), as each
    /// copy of the leaf box test this CPU can run finds them: `(copy, rays)` for the
    /// baseline, then AVX2 and AVX-512 where the CPU has them.
    fn entered_by_every_copy(
        packet: &RayPacket,
        node: &WideNode,
        lane: usize,
        first: usize,
        limits: &[f32; PACKET],
    ) -> Vec<(&'static str, Vec<usize>)> {
        let run = |test: &dyn Fn(&mut [f32; PACKET], &mut Vec<usize>)| {
            let (mut copy, mut found) = (*limits, Vec::new());
            test(&mut copy, &mut found);
            found
        };
        let mut copies = vec![(
            "baseline",
            run(&|l, found| {
                found.extend(rays_of(
                    packet.entering_by_eight::<false>(node, lane, first, l),
                ));
            }),
        )];
        if crate::simd::Isa::cpu_has_avx2() {
            copies.push((
                "AVX2",
                run(&|l, found| {
                    found.extend(rays_of(
                        packet.entering_by_eight::<true>(node, lane, first, l),
                    ));
                }),
            ));
        }
        #[cfg(target_arch = "x86_64")]
        if crate::simd::Isa::cpu_has_avx512() {
            copies.push((
                "AVX-512",
                run(&|l, found| {
                    // SAFETY: the CPU has AVX-512F (checked just above).
                    let entering = unsafe { sixteen_rays::entering(packet, node, lane, first, l) };
                    found.extend(rays_of(entering));
                }),
            ));
        }
        copies
    }

    /// A box of no thickness (an axis-aligned quad's) met head-on at exactly a ray's limit:
    /// the boundary case of the leaf box test (entry distance equal to the limit counts as
    /// entered), in every copy of the test, against each ray alone.
    #[test]
    fn a_leaf_box_met_exactly_at_the_limit_is_entered_in_every_copy() {
        let mut node = WideNode::UNUSED;
        let quad = Aabb::new(Vec3A::new(-1.0, -1.0, 2.0), Vec3A::new(1.0, 1.0, 2.0));
        node.set_box(3, &quad);
        node.child[3] = 1;
        let rays: Vec<_> = (0..40)
            .map(|i| (Vec3A::new(-0.9 + i as f32 * 0.045, 0.25, 5.0), Vec3A::NEG_Z))
            .collect();
        let packet = RayPacket::new(&rays);
        // The quad is 3 away: even rays stop exactly there, odd ones just short of it.
        let mut limits = [0.0; PACKET];
        for (r, limit) in limits.iter_mut().enumerate() {
            *limit = if r % 2 == 0 { 3.0 } else { 3.0f32.next_down() };
        }
        let alone: Vec<usize> = (0..rays.len())
            .filter(|&r| packet.ray(r).enter::<false>(&node, limits[r]).1 & (1 << 3) != 0)
            .collect();
        assert_eq!(alone, (0..rays.len()).step_by(2).collect::<Vec<_>>());
        for first in [0, 5, 17, 39] {
            let want: Vec<usize> = alone.iter().copied().filter(|&r| r >= first).collect();
            for (copy, found) in entered_by_every_copy(&packet, &node, 3, first, &limits) {
                assert_eq!(found, want, "{copy}, from ray {first}");
            }
        }
    }

    #[test]
    fn eight_rays_at_a_leaf_decide_as_each_ray_alone() {
        let mut next = stream(0x9e3779b97f4a7c15);
        let mut entered = 0;
        let (mut tested_avx2, mut tested_avx512) = (0, 0);
        for _ in 0..200 {
            let node = random_node(&mut next);
            for rays in packets(&mut next) {
                let packet = RayPacket::new(&rays);
                let mut limits = [0.0; PACKET];
                for limit in &mut limits {
                    *limit = next().abs() * 12.0;
                }
                let first = (next().abs() * 10.0) as usize % rays.len();
                for lane in 0..WIDTH {
                    let alone: Vec<usize> = (first..rays.len())
                        .filter(|&r| {
                            packet.ray(r).enter::<false>(&node, limits[r]).1 & (1 << lane) != 0
                        })
                        .collect();
                    for (copy, found) in entered_by_every_copy(&packet, &node, lane, first, &limits)
                    {
                        assert_eq!(found, alone, "the {copy} copy of the leaf box test");
                        match copy {
                            "AVX2" => tested_avx2 += 1,
                            "AVX-512" => tested_avx512 += 1,
                            _ => entered += found.len(),
                        }
                    }
                }
            }
        }
        assert!(
            entered > 1000,
            "only {entered} entries: the test means little"
        );
        // Which copies this CPU could compare (the baseline copy always runs).
        println!("AVX2 copy compared {tested_avx2} times, AVX-512 copy {tested_avx512} times");
    }

    #[test]
    fn the_interval_test_never_drops_a_box_a_ray_enters_and_drops_some() {
        let mut next = stream(0x2545f4914f6cdd1d);
        let (mut dropped, mut kept) = (0, 0);
        for _ in 0..300 {
            let node = random_node(&mut next);
            for rays in packets(&mut next) {
                let packet = RayPacket::new(&rays);
                let limit = next().abs() * 10.0;
                let Some(frustum) = &packet.frustum else {
                    continue;
                };
                let (_, may) = frustum.may_enter::<false>(&node, limit);
                let any = (0..rays.len())
                    .fold(0, |m, r| m | packet.ray(r).enter::<false>(&node, limit).1);
                assert_eq!(any & !may, 0, "a lane some ray enters was dropped");
                dropped += (((1 << WIDTH) - 1) & !may).count_ones();
                kept += may.count_ones();
            }
        }
        assert!(
            dropped > 500 && kept > 100,
            "dropped {dropped}, kept {kept}"
        );
    }

    /// Shadow rays from surface points toward a point light, as the integrator makes them:
    /// origin lifted off the surface along a normal, unit direction taken from the surface
    /// point, search ending short of the light. `scale` moves the whole scene (huge
    /// coordinates); `axis_aligned` puts the light straight above one of the points (a ray
    /// with zero x and z components).
    fn shadow_rays(
        next: &mut impl FnMut() -> f32,
        scale: f32,
        axis_aligned: bool,
    ) -> (Vec<(Vec3A, Vec3A)>, Vec<f32>) {
        let offset = Vec3A::splat(scale);
        let patch = offset + Vec3A::new(next(), next(), next());
        let light = if axis_aligned {
            patch + Vec3A::new(0.0, 6.0 + next().abs(), 0.0)
        } else {
            patch + Vec3A::new(next() * 2.0, 6.0 + next().abs(), next() * 2.0)
        };
        let normal = Vec3A::new(next(), 2.0, next()).normalize();
        // The integrator's offset: 1e-5 plus 2^-17 of the coordinates' magnitude.
        let epsilon = 1e-5 + (patch.abs().max_element()) * 2f32.powi(-17);
        let count = 1 + (next().abs() * 31.5) as usize;
        let (mut rays, mut limits) = (Vec::new(), Vec::new());
        for i in 0..count {
            let point = if i == 0 {
                patch
            } else {
                patch + Vec3A::new(next(), next() * 0.1, next()) * 0.1
            };
            let offset = light - point;
            let distance = offset.length();
            rays.push((point + normal * epsilon, offset / distance));
            limits.push(distance * (1.0 - 1e-4) - epsilon);
        }
        (rays, limits)
    }

    /// A node whose boxes lie on or against the rays' segments: around a point of a
    /// segment, with a face through that point, through a ray's origin, or flat.
    fn node_along(
        next: &mut impl FnMut() -> f32,
        rays: &[(Vec3A, Vec3A)],
        limits: &[f32],
    ) -> WideNode {
        let mut node = WideNode::UNUSED;
        for lane in 0..WIDTH {
            let r = (next().abs() * 1000.0) as usize % rays.len();
            let (origin, direction) = rays[r];
            let u = [0.0, 1.0, next().abs() * 0.5][lane % 3];
            let point = origin + direction * (limits[r] * u);
            let size = Vec3A::new(next(), next(), next()).abs() * 0.05;
            let (low, high) = match lane % 4 {
                0 => (point - size, point + size),
                1 => (point, point + size),
                2 => (point - size, point),
                _ => (point - size * Vec3A::X, point + size * Vec3A::X),
            };
            // Pushed off the segment by a sliver now and then: near misses.
            let sliver = Vec3A::new(next(), next(), next()) * 1e-3 * (lane % 2) as f32;
            node.set_box(lane, &Aabb::new(low + sliver, high + sliver));
            node.child[lane] = lane as u32 + 1;
        }
        node
    }

    /// The lanes `frustum` keeps of `node` for a packet limit `limit`, after checking that
    /// they include every lane one of `rays` (ray `r` with limit `limits[r]`) enters by its
    /// own slab test, and that the AVX2 copy keeps the same lanes.
    fn assert_bounds_keep_entered_lanes(
        frustum: &Frustum,
        node: &WideNode,
        rays: &[(Vec3A, Vec3A)],
        limits: &[f32],
        limit: f32,
    ) -> u32 {
        let (_, may) = frustum.may_enter::<false>(node, limit);
        let any = rays.iter().zip(limits).fold(0, |m, (&(o, d), &t)| {
            m | RayBoxes::new(o, d).enter::<false>(node, t).1
        });
        assert_eq!(any & !may, 0, "a lane some ray enters was dropped");
        if crate::simd::Isa::cpu_has_avx2() {
            assert_eq!(frustum.may_enter::<true>(node, limit).1, may);
        }
        may
    }

    #[test]
    fn converging_bounds_never_drop_a_box_a_ray_enters_and_drop_some() {
        let mut next = stream(0x6a09e667f3bcc908);
        let (mut dropped, mut kept, mut bounded, mut by_extent) = (0, 0, 0, 0);
        for round in 0..2000 {
            // Far from the origin: coordinates 1e4 times the packet's size (at 1e5 the
            // margin's share of the coordinates outgrows a shadow ray of a few units, and
            // such packets walk masked).
            let scale = [0.0, 1e4, -8e3, 0.0][round % 4];
            let (rays, limits) = shadow_rays(&mut next, scale, round % 5 == 0);
            let mut packet = RayPacket::new(&[]);
            if !packet.set_converging(&rays, &limits) {
                continue;
            }
            bounded += 1;
            let frustum = packet.frustum.as_ref().unwrap();
            let slabs_alone = Frustum {
                reaching: 0,
                ..*frustum
            };
            for _ in 0..4 {
                let node = node_along(&mut next, &rays, &limits);
                let may = assert_bounds_keep_entered_lanes(frustum, &node, &rays, &limits, 0.0);
                dropped += (((1 << WIDTH) - 1) & !may).count_ones();
                kept += may.count_ones();
                // Lanes only the segments' extent drops (along the axes the rays do not
                // agree on: a light straight above the patch).
                let by_slabs = slabs_alone.may_enter::<false>(&node, 0.0).1;
                by_extent += (by_slabs & !may).count_ones();
            }
        }
        assert!(
            bounded > 1000 && dropped > 500 && kept > 5000 && by_extent > 30,
            "bounded {bounded}, dropped {dropped}, kept {kept}, by extent {by_extent}"
        );
    }

    /// A tile's rays off a plane mirror: an eye's rays through a block of directions, cut
    /// at a mirror plane through `patch` with normal `normal` and reflected, so that every
    /// line passes through the eye's image behind the mirror. `scale` moves it all far
    /// from the origin.
    fn mirrored_rays(next: &mut impl FnMut() -> f32, scale: f32) -> Vec<(Vec3A, Vec3A)> {
        let offset = Vec3A::splat(scale);
        let eye = offset + Vec3A::new(next(), next(), next());
        let normal = Vec3A::new(next() * 0.3, 1.0, next() * 0.3).normalize();
        let patch = eye + Vec3A::new(next(), -3.0 - next().abs(), next());
        let aim = Vec3A::new(next() * 0.3, -1.0, next() * 0.3);
        let count = 2 + (next().abs() * 31.0) as usize;
        (0..count)
            .map(|i| {
                let jitter = Vec3A::new((i % 8) as f32, 0.0, (i / 8) as f32) * 0.01;
                let d = (aim + jitter).normalize();
                let t = (patch - eye).dot(normal) / d.dot(normal);
                let hit = eye + d * t;
                (hit, d - normal * (2.0 * d.dot(normal)))
            })
            .collect()
    }

    #[test]
    fn bounds_from_an_apex_behind_never_drop_a_box_a_ray_enters_and_drop_some() {
        let mut next = stream(0x3c6ef372fe94f82b);
        let (mut dropped, mut kept, mut bounded) = (0, 0, 0);
        for round in 0..2000 {
            let scale = [0.0, 1e4, -8e3, 0.0][round % 4];
            let rays = mirrored_rays(&mut next, scale);
            let extent = scale.abs() + 10.0;
            let mut packet = RayPacket::new(&[]);
            if !packet.set_with_apex(&rays, extent, f32::INFINITY) {
                continue;
            }
            bounded += 1;
            let frustum = packet.frustum.as_ref().unwrap();
            let limit = [f32::INFINITY, 4.0, next().abs() * 3.0][round % 3];
            // Boxes are placed along the first 8 units; the rays search as far as `limit`.
            let limits = vec![limit.min(8.0); rays.len()];
            let searched = vec![limit; rays.len()];
            for k in 0..4 {
                let node = if k < 3 {
                    node_along(&mut next, &rays, &limits)
                } else {
                    // Boxes all around the mirror, most of them off the rays.
                    let mut node = random_node(&mut next);
                    for lane in 0..WIDTH {
                        let b = node.lane_box(lane);
                        node.set_box(lane, &Aabb::new(b.min + rays[0].0, b.max + rays[0].0));
                    }
                    node
                };
                let may = assert_bounds_keep_entered_lanes(frustum, &node, &rays, &searched, limit);
                dropped += (((1 << WIDTH) - 1) & !may).count_ones();
                kept += may.count_ones();
            }
        }
        assert!(
            bounded > 1000 && dropped > 500 && kept > 5000,
            "bounded {bounded}, dropped {dropped}, kept {kept}"
        );
    }

    /// Rays whose lines meet ahead of them (toward a light), off a curved mirror, or
    /// scattered get no bounds from an apex; one origin keeps its own bounds.
    #[test]
    fn only_rays_from_an_apex_behind_them_get_its_bounds() {
        let mut next = stream(0x510e527fade682d1);
        let mirrored = mirrored_rays(&mut next, 0.0);
        assert!(RayPacket::new(&[]).set_with_apex(&mirrored, 10.0, f32::INFINITY));
        let ahead: Vec<(Vec3A, Vec3A)> = mirrored.iter().map(|&(o, d)| (o, -d)).collect();
        assert!(!RayPacket::new(&[]).set_with_apex(&ahead, 10.0, f32::INFINITY));
        let centre = Vec3A::new(0.0, -5.0, 0.0);
        let curved: Vec<(Vec3A, Vec3A)> = (0..40)
            .map(|i| {
                let d = Vec3A::new((i % 8) as f32 * 0.02 - 0.08, -1.0, (i / 8) as f32 * 0.02)
                    .normalize();
                let to_centre = centre;
                let b = d.dot(to_centre);
                let t = b - (b * b - to_centre.length_squared() + 4.0).sqrt();
                let hit = d * t;
                let n = (hit - centre).normalize();
                (hit, d - n * (2.0 * d.dot(n)))
            })
            .collect();
        assert!(!RayPacket::new(&[]).set_with_apex(&curved, 10.0, f32::INFINITY));
        let eye = [
            (Vec3A::ZERO, Vec3A::X),
            (Vec3A::ZERO, Vec3A::new(1.0, 0.1, 0.0)),
        ];
        assert!(RayPacket::new(&[]).set_with_apex(&eye, 10.0, f32::INFINITY));
    }

    /// A mirror's packet keeps its bounds while neighbouring rays start within
    /// [`APEX_SPACING_MAX_LEAVES`] leaf sides of each other, and walks masked beyond: the
    /// same rays against trees of smaller and smaller leaves. A tree without leaf boxes
    /// (side 0) bounds none.
    #[test]
    fn an_apex_packet_is_bounded_only_where_its_rays_share_leaves() {
        let mut next = stream(0x9b05688c2b3e6c1f);
        let mut bounded = 0;
        for _ in 0..50 {
            let rays = mirrored_rays(&mut next, 0.0);
            let bounds = ApexBounds::behind(&rays, 10.0, f32::INFINITY);
            let Some(bounds) = bounds else { continue };
            bounded += 1;
            let spacing = bounds.spacing;
            assert!(spacing > 0.0 && spacing.is_finite(), "spacing {spacing}");
            let side = spacing / APEX_SPACING_MAX_LEAVES;
            assert!(RayPacket::new(&[]).set_with_apex(&rays, 10.0, side * 1.01));
            assert!(!RayPacket::new(&[]).set_with_apex(&rays, 10.0, side * 0.99));
            assert!(!RayPacket::new(&[]).set_with_apex(&rays, 10.0, 0.0));
        }
        assert!(
            bounded > 20,
            "only {bounded} of 50 mirrored packets had an apex"
        );
    }

    /// Rays that do not converge (scattered, or parallel toward a directional light with no
    /// end) get no bounds, so they walk masked.
    #[test]
    fn only_converging_occlusion_rays_get_bounds() {
        let mut next = stream(0xbb67ae8584caa73b);
        let (rays, limits) = shadow_rays(&mut next, 0.0, false);
        assert!(RayPacket::new(&[]).set_converging(&rays, &limits));
        let infinite = vec![f32::INFINITY; rays.len()];
        assert!(!RayPacket::new(&[]).set_converging(&rays, &infinite));
        let scattered: Vec<(Vec3A, Vec3A)> = (0..40)
            .map(|_| {
                let o = Vec3A::new(next(), next(), next()) * 4.0;
                (
                    o,
                    (Vec3A::new(next(), next(), next()) - o * 0.3).normalize(),
                )
            })
            .collect();
        assert!(!RayPacket::new(&[]).set_converging(&scattered, &[5.0; 40]));
        let nan = vec![f32::NAN; rays.len()];
        assert!(!RayPacket::new(&[]).set_converging(&rays, &nan));
        assert!(!RayPacket::new(&[]).set_converging(&[], &[]));
    }

    /// What a packet's bounds hold, as bits (for comparing two packets' bounds).
    fn bounds_bits(packet: &RayPacket) -> Option<Vec<u32>> {
        let f = packet.frustum.as_ref()?;
        let lanes = |rows: &[Lanes; 3]| rows.iter().map(|l| l.0[0].to_bits()).collect::<Vec<_>>();
        let mut bits = lanes(&f.front_origin);
        bits.extend(lanes(&f.back_origin));
        bits.extend(lanes(&f.inverse_min));
        bits.extend(lanes(&f.inverse_max));
        bits.extend(f.reach_low.iter().chain(&f.reach_high).map(|v| v.to_bits()));
        bits.extend([
            f.agreeing,
            f.reaching,
            f.fixed_limit.unwrap_or(-1.0).to_bits(),
        ]);
        bits.extend([f.start.to_bits(), f.limit_shift.to_bits()]);
        bits.extend(f.front.iter().chain(&f.back).map(|p| p.row() as u32));
        Some(bits)
    }

    /// The bounds are made four rays at a time with the last group padded by ray 0: a
    /// packet of any length gets the same bounds whatever an earlier, larger packet left
    /// in its slots, the same in every SIMD copy, and the same for its rays in another order
    /// (the bounds are a fold over the rays). One broken ray anywhere (a NaN or infinite
    /// limit, a NaN direction or origin) takes the bounds away.
    #[test]
    fn converging_bounds_depend_only_on_the_packets_own_rays() {
        let mut next = stream(0x3c6ef372fe94f82b);
        let (mut bounded, mut refused) = (0, 0);
        for _ in 0..60 {
            let (rays, limits) = shadow_rays(&mut next, 0.0, false);
            let fresh = |rays: &[(Vec3A, Vec3A)], limits: &[f32]| {
                let mut packet = RayPacket::new(&[]);
                let has = packet.set_converging(rays, limits);
                assert_eq!(has, packet.frustum.is_some());
                bounds_bits(&packet)
            };
            let alone = fresh(&rays, &limits);
            // Each SIMD copy of the setup makes the same bounds.
            let copy = |avx2: bool| {
                let mut packet = RayPacket::new(&[]);
                let kernel = SetConverging {
                    packet: &mut packet,
                    rays: &rays,
                    t_max: &limits,
                };
                if avx2 {
                    crate::simd::run_avx2_if_available(kernel)?;
                } else {
                    crate::simd::run_baseline(kernel);
                }
                Some(bounds_bits(&packet))
            };
            assert_eq!(copy(false), Some(alone.clone()));
            if let Some(avx2) = copy(true) {
                assert_eq!(avx2, alone);
            }
            // Slots filled first by 64 rays from elsewhere, pointing every way.
            let stale: Vec<(Vec3A, Vec3A)> = (0..PACKET)
                .map(|_| {
                    let d = Vec3A::new(next(), next(), next()) + Vec3A::splat(1e-3);
                    (Vec3A::new(next(), next(), next()) * 50.0, d)
                })
                .collect();
            let mut reused = RayPacket::new(&stale);
            reused.set_converging(&stale, &[1e3; PACKET]);
            reused.set_converging(&rays, &limits);
            assert_eq!(bounds_bits(&reused), alone, "{} rays", rays.len());
            // The rays reversed after the first: the same folds, the same bounds.
            let mut reordered = vec![rays[0]];
            reordered.extend(rays[1..].iter().rev());
            let mut reordered_limits = vec![limits[0]];
            reordered_limits.extend(limits[1..].iter().rev());
            assert_eq!(fresh(&reordered, &reordered_limits), alone);
            if alone.is_none() {
                continue;
            }
            bounded += 1;
            let r = (next().abs() * rays.len() as f32) as usize % rays.len();
            for broken in 0..4 {
                let (mut rays, mut limits) = (rays.clone(), limits.clone());
                match broken {
                    0 => limits[r] = f32::NAN,
                    1 => limits[r] = f32::INFINITY,
                    2 => rays[r].1.y = f32::NAN,
                    _ => rays[r].0.z = f32::NAN,
                }
                assert!(
                    fresh(&rays, &limits).is_none(),
                    "ray {r} broken by {broken}"
                );
                refused += 1;
            }
        }
        assert!(
            bounded > 20 && refused > 80,
            "{bounded} bounded, {refused} refused"
        );
    }

    /// The node tests are checked on every CPU: the baseline copy's slab test against the
    /// scalar test of each lane's box alone (`RayBoxes::enters_box`), and where the CPU has
    /// AVX2, the AVX2 copy's node tests (a ray's slab test, a packet's interval test) against
    /// the baseline's, bit for bit.
    #[test]
    fn node_tests_of_every_copy_agree_with_the_scalar_reference() {
        let bits = |(near, mask): (Lanes, u32)| (near.0.map(f32::to_bits), mask);
        let avx2 = crate::simd::Isa::cpu_has_avx2();
        let mut next = stream(0x853c49e6748fea9b);
        let (mut rays, mut bounded, mut entered) = (0, 0, 0);
        for _ in 0..200 {
            let node = random_node(&mut next);
            for set in packets(&mut next) {
                let packet = RayPacket::new(&set);
                let limit = next().abs() * 12.0;
                for r in 0..set.len() {
                    let ray = packet.ray(r);
                    let (_, mask) = ray.enter::<false>(&node, limit);
                    let scalar = (0..WIDTH).fold(0, |m, lane| {
                        m | ((ray.enters_box(&node.lane_box(lane), limit) as u32) << lane)
                    });
                    assert_eq!(mask, scalar, "baseline slab test against the scalar one");
                    entered += mask.count_ones();
                    if avx2 {
                        assert_eq!(
                            bits(ray.enter::<true>(&node, limit)),
                            bits(ray.enter::<false>(&node, limit))
                        );
                    }
                    rays += 1;
                }
                if let Some(frustum) = &packet.frustum
                    && avx2
                {
                    assert_eq!(
                        bits(frustum.may_enter::<true>(&node, limit)),
                        bits(frustum.may_enter::<false>(&node, limit))
                    );
                    bounded += 1;
                }
            }
        }
        assert!(
            rays > 10000 && entered > 1000,
            "{rays} rays, {entered} lanes entered"
        );
        if avx2 {
            assert!(bounded > 300, "{bounded} packets");
        } else {
            println!(
                "this CPU has no AVX2: the baseline node tests were checked against the scalar reference only"
            );
        }
    }

    /// The interval bounds of packets of every length (whole and partial groups of four)
    /// and sign pattern (all negative, all positive, mixed, signed zeros) are those of a
    /// scalar fold over the packet's rays alone.
    #[test]
    fn interval_bounds_of_every_length_are_a_fold_over_the_rays() {
        let mut next = stream(0x1f2e_3d4c);
        for len in 1..=PACKET {
            for pattern in 0..4 {
                let mut inverse = [[0.0f32; PACKET]; 3];
                for row in &mut inverse {
                    for (r, value) in row.iter_mut().enumerate() {
                        let magnitude = next().abs() + 0.1;
                        *value = match pattern {
                            0 => -magnitude,
                            1 => magnitude,
                            2 => next().signum() * magnitude,
                            // Zeros of both signs among negatives (zero counts as not negative).
                            _ => [-magnitude, -0.0, 0.0, -magnitude][r % 4],
                        };
                    }
                    // Past `len`: values that would change every bound if they were read.
                    for value in &mut row[len..] {
                        *value = if next() < 0.0 { 1e30 } else { -1e30 };
                    }
                }
                let origin = [Lanes::splat(0.5); 3];
                let frustum =
                    Frustum::over_inverses(origin, origin, &inverse, len).expect("no NaN");
                for axis in 0..3 {
                    let row = &inverse[axis][..len];
                    let min = row.iter().copied().fold(f32::INFINITY, f32::min);
                    let max = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                    let negative = row.iter().filter(|v| **v < 0.0).count();
                    let case = format!("len {len}, pattern {pattern}, axis {axis}");
                    assert_eq!(frustum.inverse_min[axis].0[0], min, "{case}");
                    assert_eq!(frustum.inverse_max[axis].0[0], max, "{case}");
                    let down = usize::from(negative == len);
                    assert_eq!(frustum.front[axis].row(), axis + 3 * down, "{case}");
                    assert_eq!(frustum.back[axis].row(), axis + 3 * (1 - down), "{case}");
                    let agreeing = negative == 0 || negative == len;
                    assert_eq!(frustum.agreeing & (1 << axis) != 0, agreeing, "{case}");
                }
            }
        }
        let mut nan = [[1.0f32; PACKET]; 3];
        nan[1][36] = f32::NAN;
        let origin = [Lanes::splat(0.0); 3];
        assert!(Frustum::over_inverses(origin, origin, &nan, 37).is_none());
        assert!(Frustum::over_inverses(origin, origin, &nan, 36).is_some());
    }

    #[test]
    fn only_packets_from_one_origin_get_interval_bounds() {
        let mut next = stream(7);
        let sets = packets(&mut next);
        let bounded: Vec<bool> = sets
            .iter()
            .map(|rays| RayPacket::new(rays).frustum.is_some())
            .collect();
        assert_eq!(bounded, [true, true, true, false]);
        // The straddling packet runs both ways along x and y: only z bounds it.
        let straddling = RayPacket::new(&sets[1]).frustum.unwrap();
        assert_eq!(straddling.agreeing, 0b100);
    }
}
