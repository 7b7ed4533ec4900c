//! One ray walking the wide tree.
//!
//! Closest-hit traversal is near-first: the children a ray enters are sorted by entry
//! distance, the nearest is visited next, the others go on a stack with their entry
//! distance, and an entry whose distance is already beyond the closest hit so far is dropped
//! when popped. Queries whose answer does not depend on the order of visits (shadow rays:
//! any opaque hit, or every glass surface) skip the sort and take children in lane order
//! ([`WideBvh::traverse_unordered`]), which traced BART Kitchen's shadow rays 1.4x faster.
//! The traversal is generic over what a leaf does (closest hit, any hit, or a top-level
//! tree entering instances), so every kind of ray shares this one loop, and it is a
//! `simd::Kernel`: compiled once for the x86-64 baseline and once for AVX2.
//!
//! Robustness: far distances are widened ([`super::ROBUST_FAR`]) so rounding never drops a
//! box a ray grazes, and inverse directions are kept finite ([`safe_inverse4`]) so no slab
//! distance is NaN.

use std::mem::MaybeUninit;

use glam::{Vec3A, Vec4};
use obvhs::aabb::Aabb;

use super::Lanes;
use super::node::{ChildRef, Plane, WideNode};
use super::{ROBUST_FAR, WIDTH, WideBvh};
use crate::simd;

/// What a walk does at a leaf: `visit(first, count, &mut t_max)` may shrink `t_max` and
/// returns false to stop the walk. `AVX` is the walk's copy ([`simd::Kernel`]), so the leaf
/// test may use AVX where it is true. Closures implement it (and ignore `AVX`); a query
/// whose leaf work should be compiled into the walk itself (the closest-hit and any-hit leaf
/// tests, into the AVX2 copy) implements it on a struct with an `#[inline(always)]` method,
/// which a closure cannot carry.
pub trait LeafVisit {
    fn visit<const AVX: bool>(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool;
}

impl<F: FnMut(u32, u32, &mut f32) -> bool> LeafVisit for F {
    #[inline(always)]
    fn visit<const AVX: bool>(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool {
        self(first, count, t_max)
    }
}

/// A pending subtree: child reference, leaf count, entry distance.
pub(super) type StackEntry = (u32, u32, f32);

/// Stack entries a traversal keeps on the machine stack; deeper trees use a heap stack.
pub(super) const INLINE_STACK: usize = 128;

/// The ray constants of the slab test (`Default`: an all-zero placeholder for unused
/// packet slots, never walked).
///
/// Kept as scalars, half a cache line per ray, and splatted across the lanes where they
/// are used (a broadcast load costs what a vector load does): a masked packet makes 64 of
/// them per walk, and splatted ahead (240 bytes each) they filled a third of a 48 KB L1 with
/// stores before the walk began.
#[derive(Clone, Copy, Default)]
#[repr(C, align(32))]
pub struct RayBoxes {
    origin: [f32; 3],
    /// `-1 / direction` per axis (the safe inverse, negated): see [`RayBoxes::slabs`].
    negated_inverse: [f32; 3],
    /// Per axis, the plane the ray meets first and last (`bounds` rows): lower then upper
    /// when it runs toward higher coordinates. Indices, not branches, in the node test.
    front: [Plane; 3],
    back: [Plane; 3],
}

const _: () = assert!(std::mem::size_of::<RayBoxes>() == 32);

impl RayBoxes {
    #[inline(always)]
    pub fn new(origin: Vec3A, direction: Vec3A) -> RayBoxes {
        // The three inverses in one vector division (the same IEEE quotients as three
        // scalar ones; a packet's masked walk makes 64 rays' constants at a time).
        let inverse = safe_inverse4(direction.extend(1.0));
        let [x, y, z, _] = (-inverse).to_array();
        RayBoxes::with_negated(
            origin.to_array(),
            [x, y, z],
            inverse.cmplt(Vec4::ZERO).bitmask(),
        )
    }

    /// The constants from the origin and the (safe) inverse direction.
    #[inline(always)]
    pub(super) fn from_inverse(origin: [f32; 3], inverse: [f32; 3]) -> RayBoxes {
        let negative = (0..3).fold(0, |m, axis| m | (u32::from(inverse[axis] < 0.0) << axis));
        RayBoxes::with_negated(origin, inverse.map(|i| -i), negative)
    }

    /// The constants from the origin and the negated inverse direction, with bit `axis` of
    /// `negative` set where the inverse is negative along `axis` (higher bits ignored).
    #[inline(always)]
    fn with_negated(origin: [f32; 3], negated_inverse: [f32; 3], negative: u32) -> RayBoxes {
        let (front, back) = Plane::met_first_and_last(negative);
        RayBoxes {
            origin,
            negated_inverse,
            front,
            back,
        }
    }

    /// The ray's origin and (safe) inverse direction, as made by [`RayBoxes::from_inverse`]
    /// (negating is exact: the same bits).
    #[inline(always)]
    pub(super) fn constants(&self) -> ([f32; 3], [f32; 3]) {
        (self.origin, self.negated_inverse.map(|i| -i))
    }

    /// Entry distances of the node's children and the mask of those the ray enters before
    /// `t_max` (bit `lane`); `AVX` only inside the AVX2 copy of a walk ([`Lanes`]).
    #[inline(always)]
    pub(super) fn enter<const AVX: bool>(&self, node: &WideNode, t_max: f32) -> (Lanes, u32) {
        let (near, far) = self.slabs::<AVX>(node, t_max);
        (near, near.le_mask::<AVX>(far))
    }

    /// [`RayBoxes::enter`] with +infinity as the entry distance of the lanes not entered
    /// (so distances of several rays can be merged by a minimum).
    #[inline(always)]
    pub(super) fn enter_keeping_entered<const AVX: bool>(
        &self,
        node: &WideNode,
        t_max: f32,
    ) -> (Lanes, u32) {
        let (near, far) = self.slabs::<AVX>(node, t_max);
        near.kept_where_le::<AVX>(far)
    }

    /// The entry distance and the exit limit of each lane's box (the exit already cut at
    /// `t_max`): the ray enters a lane where `near <= far`.
    ///
    /// A plane's distance is `(origin - plane) * -inverse`: the bits of `(plane - origin) *
    /// inverse` (negating is exact, and rounding to nearest is symmetric in sign), but for
    /// the sign of a zero where the origin and the plane are the same number, and the sign
    /// of a NaN; no comparison sees either, and the near-to-far order ignores the sign.
    /// Written so, the plane is the subtrahend and its load folds into the subtraction: six
    /// instructions fewer in a test of about forty.
    ///
    /// The exit starts as x's back plane, not as the minimum of it and +infinity: that
    /// minimum is its second operand whatever it holds (NaN included), in both copies.
    #[inline(always)]
    fn slabs<const AVX: bool>(&self, node: &WideNode, t_max: f32) -> (Lanes, Lanes) {
        let (t_front, mut far) = self.plane_distances::<AVX>(node, 0);
        let mut near = Lanes::splat(0.0).max::<AVX>(t_front);
        for axis in 1..3 {
            let (t_front, t_back) = self.plane_distances::<AVX>(node, axis);
            near = near.max::<AVX>(t_front);
            far = far.min::<AVX>(t_back);
        }
        let far = far
            .mul::<AVX>(Lanes::splat(ROBUST_FAR))
            .min::<AVX>(Lanes::splat(t_max));
        (near, far)
    }

    /// The distances to the planes the ray meets first and last along `axis`, per lane.
    #[inline(always)]
    fn plane_distances<const AVX: bool>(&self, node: &WideNode, axis: usize) -> (Lanes, Lanes) {
        let front = Lanes(*node.plane(self.front[axis]));
        let back = Lanes(*node.plane(self.back[axis]));
        let origin = Lanes::splat(self.origin[axis]);
        let negated = Lanes::splat(self.negated_inverse[axis]);
        let t_front = origin.sub::<AVX>(front).mul::<AVX>(negated);
        let t_back = origin.sub::<AVX>(back).mul::<AVX>(negated);
        (t_front, t_back)
    }
}

impl RayBoxes {
    /// Whether the ray enters `aabb` before `t_max`: the slab test of one lane, for a box
    /// kept outside a node (the lone leaf of a one-leaf tree keeps none).
    #[inline(always)]
    pub fn enters_box(&self, aabb: &Aabb, t_max: f32) -> bool {
        let mut near = 0.0f32;
        let mut far = f32::INFINITY;
        let bounds = [aabb.min, aabb.max];
        for axis in 0..3 {
            let (origin, negated) = (self.origin[axis], self.negated_inverse[axis]);
            let front = bounds[self.front[axis].row() / 3][axis];
            let back = bounds[self.back[axis].row() / 3][axis];
            near = near.max((origin - front) * negated);
            far = far.min((origin - back) * negated);
        }
        near <= (far * ROBUST_FAR).min(t_max)
    }
}

/// [`safe_inverse4`] of one value: the reference the tests hold it to.
#[cfg(test)]
pub(super) fn safe_inverse(x: f32) -> f32 {
    if x.abs() < 1e-30 {
        1e30f32.copysign(x)
    } else {
        1.0 / x
    }
}

/// `1 / x` of four values, kept finite and signed for zero and tiny components so that
/// slab distances are never NaN (`0 * inf`); 1e30 still puts an axis-parallel ray's far
/// plane beyond any scene. Bit for bit the scalar formula (`safe_inverse` in the tests) of
/// each value.
#[inline(always)]
pub(super) fn safe_inverse4(x: Vec4) -> Vec4 {
    let tiny = x.abs().cmplt(Vec4::splat(1e-30));
    Vec4::select(tiny, Vec4::splat(1e30).copysign(x), Vec4::ONE / x)
}

impl WideBvh {
    /// Walks the tree near-first along a ray, calling `leaf(leaf_ref, count, &mut t_max)` for
    /// every leaf it enters before `t_max`. The leaf may shrink `t_max` (closest hit: later
    /// boxes beyond it are skipped) or return false to stop (any hit). Returns false when a
    /// leaf stopped the walk.
    #[inline(always)]
    pub fn traverse(&self, ray: &RayBoxes, t_max: f32, leaf: impl LeafVisit) -> bool {
        self.traverse_in::<true>(ray, t_max, leaf)
    }

    /// [`WideBvh::traverse`] for queries whose answer does not depend on the order of
    /// visits (any hit, every hit): children are taken in lane order, not sorted.
    #[inline(always)]
    pub fn traverse_unordered(&self, ray: &RayBoxes, t_max: f32, leaf: impl LeafVisit) -> bool {
        self.traverse_in::<false>(ray, t_max, leaf)
    }

    #[inline(always)]
    fn traverse_in<const ORDERED: bool>(
        &self,
        ray: &RayBoxes,
        t_max: f32,
        leaf: impl LeafVisit,
    ) -> bool {
        if let Some((first, count)) = self.root_leaf {
            let mut leaf = leaf;
            let mut t = t_max;
            // A tree of one leaf: no walk, so no SIMD copy chosen; the baseline test.
            return leaf.visit::<false>(first, count, &mut t);
        }
        if self.nodes.is_empty() {
            return true;
        }
        let needed = self.depth * (WIDTH - 1) + 1;
        if needed <= INLINE_STACK {
            // Left uninitialised: zeroing 1.5 KiB per ray showed as 7% of a primary-ray
            // profile (memset), and `walk` only reads entries it wrote.
            let mut stack = [const { MaybeUninit::uninit() }; INLINE_STACK];
            self.walk_on::<ORDERED>(&mut stack, ray, t_max, leaf)
        } else {
            // Only trees deeper than ~18 wide levels (pathological inputs) pay this.
            let mut stack = vec![MaybeUninit::uninit(); needed];
            self.walk_on::<ORDERED>(&mut stack, ray, t_max, leaf)
        }
    }

    /// [`WideBvh::walk`] in the copy [`simd::dispatch`] chooses.
    #[inline(always)]
    fn walk_on<const ORDERED: bool>(
        &self,
        stack: &mut [MaybeUninit<StackEntry>],
        ray: &RayBoxes,
        t_max: f32,
        leaf: impl LeafVisit,
    ) -> bool {
        simd::dispatch(Walk::<_, ORDERED> {
            bvh: self,
            stack,
            ray,
            t_max,
            leaf,
        })
    }

    /// The traversal loop. The stack holds at most `depth * (WIDTH - 1) + 1` entries: each
    /// level pushes at most `WIDTH - 1` siblings.
    ///
    /// The walk covers the subtree `start`: the root for a ray's own query, a node for a ray
    /// of a masked walk that walks that subtree alone.
    #[inline(always)]
    pub(super) fn walk<const ORDERED: bool, const AVX: bool>(
        &self,
        stack: &mut [MaybeUninit<StackEntry>],
        ray: &RayBoxes,
        mut t_max: f32,
        mut leaf: impl LeafVisit,
        start: ChildRef,
    ) -> bool {
        let mut top = 0usize;
        let mut current = start;
        loop {
            match current {
                ChildRef::Node(index) => {
                    let node = &self.nodes[index as usize];
                    let (near, mask) = ray.enter::<AVX>(node, t_max);
                    if mask != 0 {
                        current = if ORDERED {
                            push_far_take_near(node, near, mask, stack, &mut top)
                        } else {
                            push_rest_take_first(node, near, mask, stack, &mut top)
                        };
                        continue;
                    }
                }
                ChildRef::Leaf { first, count } => {
                    if !leaf.visit::<AVX>(first, count, &mut t_max) {
                        return false;
                    }
                }
            }
            // Pop the nearest pending subtree that still starts before the closest hit.
            loop {
                if top == 0 {
                    return true;
                }
                top -= 1;
                // SAFETY: entries below `top` were all written by `push_far_take_near`.
                let (child, count, near) = unsafe { stack[top].assume_init() };
                if near <= t_max {
                    current = ChildRef::decode(child, count);
                    break;
                }
            }
        }
    }
}

/// One walk as a [`simd::Kernel`]: the loop, its node tests and the leaf callback are all
/// inlined into each copy (the leaf's own arithmetic only changes encoding in the AVX2 copy:
/// no fused multiply-add is formed, so it rounds as the baseline does).
struct Walk<'a, L, const ORDERED: bool> {
    bvh: &'a WideBvh,
    stack: &'a mut [MaybeUninit<StackEntry>],
    ray: &'a RayBoxes,
    t_max: f32,
    leaf: L,
}

impl<L: LeafVisit, const ORDERED: bool> simd::Kernel for Walk<'_, L, ORDERED> {
    type Output = bool;

    #[inline(always)]
    fn run<const AVX2: bool>(self) -> bool {
        self.bvh.walk::<ORDERED, AVX2>(
            self.stack,
            self.ray,
            self.t_max,
            self.leaf,
            ChildRef::Node(0),
        )
    }
}

/// The lanes set in `mask` ordered by increasing `near` distance, and how many there are;
/// among equal distances the higher lane comes first when `HIGH_LANE_FIRST`, else the lower.
///
/// Branch-free: each lane's key is its distance's bits (non-negative floats order as
/// integers) with the lane's tie rank in the three lowest bits, lanes not set sort last,
/// and a sorting network orders the eight keys ([`sort_eight`]); two entered lanes, the
/// most common case after one, take a single comparison, and three or four the keys of
/// those lanes alone in a network of four ([`sort_four`]). The insertion sort this replaces
/// branched on every comparison and mispredicted often (its compare was the hottest line
/// of single-ray traversal). Distances within eight ulps may come out in either order,
/// which only changes the order of visits, never what a query finds.
///
/// Why the tie rank matters: a ray leaving a surface starts inside many boxes, all entered
/// at 0. Single rays keep the insertion sort's order among them (higher lane first): lower
/// lane first made BART Robots frames 10% slower. Packets, whose interval bound is 0 for
/// every box holding the camera, go lower lane first (14% faster on BART Kitchen's primary
/// rays than the other way).
#[inline(always)]
pub(super) fn lanes_near_to_far<const HIGH_LANE_FIRST: bool>(
    near: Lanes,
    mask: u32,
) -> ([usize; WIDTH], usize) {
    const RANK: u32 = WIDTH as u32 - 1;
    let near = near.0;
    // The rank is its own inverse: it turns a key's low bits back into the lane.
    let rank = tie_rank::<HIGH_LANE_FIRST>;
    let key = |lane: usize| sort_key::<HIGH_LANE_FIRST>(&near, lane);
    let n = mask.count_ones() as usize;
    let mut lanes = [0; WIDTH];
    if n <= 1 {
        // The one lane (or none: the count says so, and lane 0 is never read).
        lanes[0] = mask.trailing_zeros() as usize % WIDTH;
        return (lanes, n);
    }
    if n == 2 {
        let a = mask.trailing_zeros() as usize;
        let b = (mask & (mask - 1)).trailing_zeros() as usize;
        let a_first = key(a) < key(b);
        lanes[0] = if a_first { a } else { b };
        lanes[1] = if a_first { b } else { a };
        return (lanes, 2);
    }
    if n <= 4 {
        // Three or four lanes (n is at least 3 here): their keys gathered by the mask's
        // bits and sorted by a network of four (five exchanges), not the eight keys of
        // every lane by nineteen.
        let mut rest = mask;
        let mut next_key = || {
            let lane = rest.trailing_zeros() as usize;
            rest &= rest.wrapping_sub(1);
            key(lane)
        };
        let mut keys = [next_key(), next_key(), next_key(), u32::MAX];
        if n == 4 {
            keys[3] = next_key();
        }
        sort_four(&mut keys);
        for (lane, k) in lanes.iter_mut().zip(keys).take(n) {
            *lane = rank(k & RANK) as usize;
        }
        return (lanes, n);
    }
    let mut keys: [u32; WIDTH] = std::array::from_fn(|lane| {
        if mask & (1 << lane) != 0 {
            key(lane)
        } else {
            u32::MAX
        }
    });
    sort_eight(&mut keys);
    for (lane, k) in lanes.iter_mut().zip(keys) {
        *lane = rank(k & RANK) as usize;
    }
    (lanes, n)
}

/// The key [`lanes_near_to_far`] orders lane `lane` by: its entry distance's bits with the
/// lane's [`tie_rank`] in the three lowest bits.
#[inline(always)]
fn sort_key<const HIGH_LANE_FIRST: bool>(near: &[f32; WIDTH], lane: usize) -> u32 {
    let lane = lane % WIDTH;
    // `& 0x7fff_ffff`: a -0.0 entry distance sorts as 0.
    let distance = near[lane].to_bits() & (0x7fff_ffff & !(WIDTH as u32 - 1));
    distance | tie_rank::<HIGH_LANE_FIRST>(lane as u32)
}

/// Where lane `lane` (below [`WIDTH`]) comes among lanes of equal distance, lowest first:
/// the higher lane first when `HIGH_LANE_FIRST`, else the lower. Its own inverse.
#[inline(always)]
const fn tie_rank<const HIGH_LANE_FIRST: bool>(lane: u32) -> u32 {
    if HIGH_LANE_FIRST {
        WIDTH as u32 - 1 - lane
    } else {
        lane
    }
}

/// Sorts four keys with a sorting network of 5 exchanges, the fewest possible.
/// `tests::the_four_key_network_sorts_every_zero_one_input` checks it.
#[inline(always)]
fn sort_four(k: &mut [u32; 4]) {
    exchange(k, 0, 1);
    exchange(k, 2, 3);
    exchange(k, 0, 2);
    exchange(k, 1, 3);
    exchange(k, 1, 2);
}

/// Sorts eight keys with a sorting network of 19 exchanges, the fewest possible (Knuth,
/// TAOCP vol. 3, 5.3.4), spelled out so that it compiles to straight-line minimum and
/// maximum instructions (a loop over a table of pairs was not unrolled).
/// `tests::the_eight_key_network_sorts_every_zero_one_input` checks it.
#[inline(always)]
fn sort_eight(k: &mut [u32; 8]) {
    exchange(k, 0, 2);
    exchange(k, 1, 3);
    exchange(k, 4, 6);
    exchange(k, 5, 7);
    exchange(k, 0, 4);
    exchange(k, 1, 5);
    exchange(k, 2, 6);
    exchange(k, 3, 7);
    exchange(k, 0, 1);
    exchange(k, 2, 3);
    exchange(k, 4, 5);
    exchange(k, 6, 7);
    exchange(k, 2, 4);
    exchange(k, 3, 5);
    exchange(k, 1, 4);
    exchange(k, 3, 6);
    exchange(k, 1, 2);
    exchange(k, 3, 4);
    exchange(k, 5, 6);
}

/// One comparator of a sorting network: keys `i` and `j` put in order (straight-line
/// minimum and maximum, no branch).
#[inline(always)]
fn exchange<const N: usize>(k: &mut [u32; N], i: usize, j: usize) {
    let (a, b) = (k[i], k[j]);
    k[i] = a.min(b);
    k[j] = a.max(b);
}

/// Of the entered children (`mask`, not zero), returns the nearest and pushes the others
/// so that the next nearest is popped first: the order [`lanes_near_to_far`] gives, higher
/// lane first among equal distances.
///
/// One child and two (together most of a closest-hit walk's nodes) take their own paths:
/// two children are one comparison of their keys and one push, where going through the
/// general ordering wrote its lane list to memory and pushed from it in a loop (BART
/// Kitchen's single mirror rays: 1,464 instructions a ray against 1,542, and about 2%
/// faster). Lanes are taken `% WIDTH` (they are below it already) so that the compiler
/// drops their range checks.
#[inline(always)]
fn push_far_take_near(
    node: &WideNode,
    near: Lanes,
    mask: u32,
    stack: &mut [MaybeUninit<StackEntry>],
    top: &mut usize,
) -> ChildRef {
    let first = mask.trailing_zeros() as usize % WIDTH;
    let rest = mask & mask.wrapping_sub(1);
    if rest == 0 {
        return ChildRef::decode(node.child[first], node.count[first]);
    }
    let distances = near.0;
    let mut push = |lane: usize| {
        let lane = lane % WIDTH;
        stack[*top] = MaybeUninit::new((node.child[lane], node.count[lane], distances[lane]));
        *top += 1;
    };
    if rest & rest.wrapping_sub(1) == 0 {
        let second = rest.trailing_zeros() as usize % WIDTH;
        let first_nearer =
            sort_key::<true>(&distances, first) < sort_key::<true>(&distances, second);
        let (nearer, farther) = if first_nearer {
            (first, second)
        } else {
            (second, first)
        };
        push(farther);
        return ChildRef::decode(node.child[nearer], node.count[nearer]);
    }
    let (lanes, n) = lanes_near_to_far::<true>(near, mask);
    for &farther in lanes[1..n].iter().rev() {
        push(farther);
    }
    let lane = lanes[0] % WIDTH;
    ChildRef::decode(node.child[lane], node.count[lane])
}

/// Of the entered children (`mask`), returns the first in lane order and pushes the others.
#[inline(always)]
fn push_rest_take_first(
    node: &WideNode,
    near: Lanes,
    mask: u32,
    stack: &mut [MaybeUninit<StackEntry>],
    top: &mut usize,
) -> ChildRef {
    let distances = near.0;
    let lane = mask.trailing_zeros() as usize;
    let mut rest = mask & (mask - 1);
    while rest != 0 {
        let other = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        stack[*top] = MaybeUninit::new((node.child[other], node.count[other], distances[other]));
        *top += 1;
    }
    ChildRef::decode(node.child[lane], node.count[lane])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::wide::test_support::*;
    use crate::accel::wide::walk::RayBoxes;
    use glam::Vec3A;
    use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::builder::build_bvh2};
    use std::time::Duration;

    #[test]
    fn rays_reach_exactly_the_boxes_they_cross() {
        let binary = build(37);
        let wide = WideBvh::collapse(&binary, |first, _| first);
        // Straight down through box 5 (x in [10, 11]) only; between boxes nothing.
        let slots = reached(&wide, Vec3A::new(10.5, 5.0, 0.5), Vec3A::NEG_Y);
        assert_eq!(slots.len(), 1);
        let b = binary.primitive_indices[slots[0] as usize];
        assert_eq!(b, 5);
        assert!(reached(&wide, Vec3A::new(11.5, 5.0, 0.5), Vec3A::NEG_Y).is_empty());
    }

    #[test]
    fn unordered_walks_reach_the_same_leaves() {
        let binary = build(300);
        let wide = WideBvh::collapse(&binary, |first, _| first);
        let walk = |unordered: bool, origin: Vec3A, direction: Vec3A, t_max: f32| {
            let mut out = Vec::new();
            let ray = RayBoxes::new(origin, direction);
            let leaf = |first: u32, count: u32, _: &mut f32| {
                out.extend(first..first + count);
                true
            };
            if unordered {
                wide.traverse_unordered(&ray, t_max, leaf);
            } else {
                wide.traverse(&ray, t_max, leaf);
            }
            out.sort();
            out
        };
        let mut reached = 0;
        for k in 0..500 {
            let f = |i: u32| ((k * 7 + i).wrapping_mul(2654435761) >> 8) as f32 / 16777216.0;
            // Along the row of boxes, both ways, slightly tilted.
            let origin = Vec3A::new(f(0) * 620.0 - 10.0, f(1), f(2));
            let along = if k % 2 == 0 { 1.0 } else { -1.0 };
            let direction = Vec3A::new(along, (f(4) - 0.5) * 0.02, (f(5) - 0.5) * 0.02);
            let t_max = if k % 3 == 0 {
                f(6) * 100.0
            } else {
                f32::INFINITY
            };
            let ordered = walk(false, origin, direction, t_max);
            assert_eq!(walk(true, origin, direction, t_max), ordered);
            reached += ordered.len();
        }
        assert!(
            reached > 200,
            "only {reached} leaves reached: the test means little"
        );
    }

    #[test]
    fn closest_first_walk_skips_boxes_beyond_the_limit() {
        let binary = build(64);
        let wide = WideBvh::collapse(&binary, |first, _| first);
        let ray = RayBoxes::new(Vec3A::new(-5.0, 0.5, 0.5), Vec3A::X);
        // A leaf that sets the limit at its first box's entry: only boxes that start before
        // it are visited afterwards, and the first box reached is the nearest one.
        let mut visited = Vec::new();
        wide.traverse(
            &ray,
            f32::INFINITY,
            |first: u32, _: u32, t_max: &mut f32| {
                let b = binary.primitive_indices[first as usize];
                visited.push(b);
                *t_max = (*t_max).min(5.0 + b as f32 * 2.0 + 1.0);
                true
            },
        );
        assert_eq!(visited, vec![0]);
    }

    #[test]
    fn axis_parallel_rays_never_see_nan() {
        let wide = WideBvh::collapse(&build(8), |first, _| first);
        // The origin on a box plane along a zero direction component.
        assert_eq!(
            reached(&wide, Vec3A::new(0.0, 0.0, -3.0), Vec3A::Z).len(),
            1
        );
        assert_eq!(
            reached(&wide, Vec3A::new(0.0, 0.0, -3.0), -Vec3A::Z).len(),
            0
        );
    }

    /// The sorting network hands out every entered lane once, nearest first.
    #[test]
    fn entered_lanes_come_out_nearest_first() {
        let mut next = xorshift(0x9e3779b97f4a7c15);
        let mut counts = [0; WIDTH + 1];
        for _ in 0..20000 {
            let (r, s) = (next(), next());
            // Distances over many magnitudes, with zeros (both signs) and exact repeats.
            let near: [f32; WIDTH] = std::array::from_fn(|i| match (r >> (8 * i)) & 7 {
                0 => 0.0,
                1 => -0.0,
                2 => 1.5,
                _ => f32::from_bits(((s >> (4 * i)) as u32 & 0x3fff_ffff) + 0x0080_0000),
            });
            let mask = (next() & 0xff) as u32;
            let (lanes, n) = if r & 1 == 0 {
                lanes_near_to_far::<true>(Lanes(near), mask)
            } else {
                lanes_near_to_far::<false>(Lanes(near), mask)
            };
            counts[n] += 1;
            let mut sorted: Vec<usize> = lanes[..n].to_vec();
            sorted.sort_unstable();
            let expected: Vec<usize> = (0..WIDTH).filter(|l| mask & (1 << l) != 0).collect();
            assert_eq!(sorted, expected, "every entered lane once, no other");
            for pair in lanes[..n].windows(2) {
                let (a, b) = (near[pair[0]].abs(), near[pair[1]].abs());
                // Ordered, up to the eight ulps the lane bits take.
                assert!(
                    a.to_bits() >> 3 <= b.to_bits() >> 3,
                    "{near:?} {mask:b} -> {lanes:?}"
                );
            }
        }
        assert!(
            counts.iter().all(|&c| c > 0),
            "every entered count: {counts:?}"
        );
    }

    /// A node's entered children are taken and pushed in the order [`lanes_near_to_far`]
    /// gives (higher lane first among equal keys), whatever their number: the nearest is
    /// returned, the others pop nearest first, every entered lane once.
    #[test]
    fn entered_children_are_taken_then_popped_nearest_first() {
        let mut next = xorshift(0x2545f4914f6cdd1d);
        let mut node = WideNode::UNUSED;
        for lane in 0..WIDTH {
            node.child[lane] = 100 + lane as u32;
        }
        for _ in 0..4000 {
            let r = next();
            // Few distinct distances, so ties (and +-0) are common.
            let near: [f32; WIDTH] = std::array::from_fn(|i| match (r >> (4 * i)) & 7 {
                0 => 0.0,
                1 => -0.0,
                k => k as f32 * 0.25,
            });
            for mask in 1..(1u32 << WIDTH) {
                let mut stack = [const { MaybeUninit::uninit() }; WIDTH];
                let mut top = 0;
                let taken = push_far_take_near(&node, Lanes(near), mask, &mut stack, &mut top);
                let mut order = vec![taken];
                while top > 0 {
                    top -= 1;
                    // SAFETY: the entries below `top` were written by the call above.
                    let (child, count, distance) = unsafe { stack[top].assume_init() };
                    let lane = (child - 100) as usize;
                    assert_eq!(distance.to_bits(), near[lane].to_bits());
                    order.push(ChildRef::decode(child, count));
                }
                let (lanes, n) = lanes_near_to_far::<true>(Lanes(near), mask);
                let expected: Vec<ChildRef> = lanes[..n]
                    .iter()
                    .map(|&lane| ChildRef::Node(100 + lane as u32))
                    .collect();
                assert_eq!(order, expected, "{near:?} {mask:08b}");
            }
        }
    }

    /// Every copy of the walk is checked on every CPU: the baseline copy against a scalar
    /// reference (with a fixed limit it visits exactly the leaves whose box the ray enters,
    /// each once), and the AVX2 copy, where the CPU has AVX2, against the baseline copy
    /// (the same leaves in the same order with the same limits, as closest-hit limits
    /// shrink at leaves). Boxes scattered in 3D, rays from inside and outside them, some
    /// axis-parallel.
    #[test]
    fn every_walk_copy_visits_what_the_scalar_reference_enters() {
        let mut next = uniform(0x2545f4914f6cdd1d, -10.0, 20.0);
        let scattered: Vec<Aabb> = (0..700)
            .map(|_| {
                let a = Vec3A::new(next(), next(), next());
                Aabb::new(a, a + Vec3A::new(next(), next(), next()).abs() * 0.5)
            })
            .collect();
        let mut params = BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 2;
        let binary = build_bvh2(&scattered, params, &mut Duration::default());
        let wide = WideBvh::collapse(&binary, |first, _| first);
        let leaf_boxes: Vec<(u32, Aabb)> = binary
            .nodes
            .iter()
            .filter(|n| n.is_leaf())
            .map(|n| (n.first_index, *n.aabb()))
            .collect();
        let (mut visits, mut compared_with_avx2) = (0, 0);
        for k in 0..400 {
            let origin = Vec3A::new(next(), next(), next()) * 1.2;
            let mut direction = Vec3A::new(next(), next(), next());
            if k % 5 == 0 {
                direction.y = 0.0;
            }
            let ray = RayBoxes::new(origin, direction);
            // (copy, ordered, shrinking limit) -> the visits, as (first, count, limit bits)
            let walk = |avx2: bool, ordered: bool, shrink: bool| {
                let mut seen = Vec::new();
                let leaf = |first: u32, count: u32, t: &mut f32| {
                    seen.push((first, count, t.to_bits()));
                    if shrink {
                        *t *= 0.9; // a closest hit shrinking the limit
                    }
                    true
                };
                let mut stack = [const { MaybeUninit::uninit() }; INLINE_STACK];
                let stack = &mut stack[..];
                let ray = &ray;
                let ran = match (avx2, ordered) {
                    (false, true) => Some(simd::run_baseline(Walk::<_, true> {
                        bvh: &wide,
                        stack,
                        ray,
                        t_max: 40.0,
                        leaf,
                    })),
                    (false, false) => Some(simd::run_baseline(Walk::<_, false> {
                        bvh: &wide,
                        stack,
                        ray,
                        t_max: 40.0,
                        leaf,
                    })),
                    (true, true) => simd::run_avx2_if_available(Walk::<_, true> {
                        bvh: &wide,
                        stack,
                        ray,
                        t_max: 40.0,
                        leaf,
                    }),
                    (true, false) => simd::run_avx2_if_available(Walk::<_, false> {
                        bvh: &wide,
                        stack,
                        ray,
                        t_max: 40.0,
                        leaf,
                    }),
                };
                ran.map(|_| seen)
            };
            let mut reference: Vec<u32> = leaf_boxes
                .iter()
                .filter(|(_, b)| ray.enters_box(b, 40.0))
                .map(|&(first, _)| first)
                .collect();
            reference.sort_unstable();
            for ordered in [true, false] {
                let baseline = walk(false, ordered, false).expect("the baseline copy always runs");
                let mut firsts: Vec<u32> = baseline.iter().map(|v| v.0).collect();
                firsts.sort_unstable();
                assert_eq!(
                    firsts, reference,
                    "ray {k}, ordered {ordered}: baseline against the scalar reference"
                );
                visits += baseline.len();
                for shrink in [false, true] {
                    let baseline =
                        walk(false, ordered, shrink).expect("the baseline copy always runs");
                    if let Some(avx2) = walk(true, ordered, shrink) {
                        assert_eq!(
                            avx2, baseline,
                            "ray {k}, ordered {ordered}, shrink {shrink}"
                        );
                        compared_with_avx2 += 1;
                    }
                }
            }
        }
        assert!(
            visits > 2000,
            "only {visits} leaf visits: the test means little"
        );
        if crate::simd::Isa::cpu_has_avx2() {
            assert_eq!(compared_with_avx2, 400 * 4);
        } else {
            println!(
                "this CPU has no AVX2: the baseline walk was checked against the scalar reference only"
            );
        }
    }

    /// The 0-1 principle: a network that sorts every sequence of zeros and ones sorts
    /// every sequence.
    #[test]
    fn the_eight_key_network_sorts_every_zero_one_input() {
        assert_sorts_every_zero_one_input(sort_eight);
    }

    #[test]
    fn the_four_key_network_sorts_every_zero_one_input() {
        assert_sorts_every_zero_one_input(sort_four);
    }

    /// `sort` orders each of the `2^N` sequences of zeros and ones.
    fn assert_sorts_every_zero_one_input<const N: usize>(sort: fn(&mut [u32; N])) {
        for bits in 0u32..(1 << N) {
            let mut keys: [u32; N] = std::array::from_fn(|i| (bits >> i) & 1);
            sort(&mut keys);
            assert!(
                keys.windows(2).all(|w| w[0] <= w[1]),
                "{bits:0width$b} -> {keys:?}",
                width = N
            );
        }
    }

    /// Every mask of entered lanes (so every count, the short paths' and the network's)
    /// comes out as a plain sort by distance (to eight ulps, as the keys hold it), then by
    /// the tie rule, orders it.
    #[test]
    fn every_mask_is_ordered_as_a_plain_sort_orders_it() {
        let mut seed = 7u32;
        for round in 0..64 {
            let near = Lanes(std::array::from_fn(|_| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                // Few distinct values, so that ties are common; zeros as a ray leaving a
                // surface sees them.
                if round % 2 == 0 {
                    (seed >> 29) as f32
                } else {
                    (seed >> 8) as f32 * 1e-3
                }
            }));
            for mask in 0u32..(1 << WIDTH) {
                for high_first in [true, false] {
                    let mut want: Vec<usize> =
                        (0..WIDTH).filter(|l| mask & (1 << l) != 0).collect();
                    // Distances as the keys take them: their bits less the lowest three.
                    let distance = |l: usize| near.0[l].to_bits() & 0x7fff_fff8;
                    want.sort_by(|&a, &b| {
                        distance(a).cmp(&distance(b)).then(if high_first {
                            b.cmp(&a)
                        } else {
                            a.cmp(&b)
                        })
                    });
                    let (lanes, n) = if high_first {
                        lanes_near_to_far::<true>(near, mask)
                    } else {
                        lanes_near_to_far::<false>(near, mask)
                    };
                    assert_eq!(&lanes[..n], &want[..], "mask {mask:08b} near {:?}", near.0);
                }
            }
        }
    }

    #[test]
    fn equal_distances_come_out_in_the_chosen_lane_order() {
        let zeros = Lanes::splat(0.0);
        let all = (1 << WIDTH) - 1;
        let down: [usize; WIDTH] = std::array::from_fn(|i| WIDTH - 1 - i);
        let up: [usize; WIDTH] = std::array::from_fn(|i| i);
        assert_eq!(lanes_near_to_far::<true>(zeros, all), (down, WIDTH));
        assert_eq!(lanes_near_to_far::<false>(zeros, all), (up, WIDTH));
        let mut near = Lanes::splat(5.0);
        near.0[..4].copy_from_slice(&[2.0, 0.0, 1.0, 0.0]);
        let (lanes, n) = lanes_near_to_far::<true>(near, 0b1011);
        assert_eq!(&lanes[..n], &[3, 1, 0]);
        let (lanes, n) = lanes_near_to_far::<false>(near, 0b1010);
        assert_eq!(&lanes[..n], &[1, 3]);
        let (lanes, n) = lanes_near_to_far::<true>(near, 0b1010);
        assert_eq!(&lanes[..n], &[3, 1]);
    }

    #[test]
    fn four_inverses_at_once_equal_one_at_a_time() {
        let values = [
            0.0,
            -0.0,
            1e-31,
            -1e-31,
            1e-30,
            -1e-30,
            3.0,
            -0.7,
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        for group in values.chunks_exact(4) {
            let four = safe_inverse4(Vec4::from_slice(group)).to_array();
            for (x, inv) in group.iter().zip(four) {
                assert_eq!(inv.to_bits(), safe_inverse(*x).to_bits(), "1 / {x}");
            }
        }
    }

    /// A ray's constants made with one vector division and a sign table are those made
    /// one axis at a time (inverse bits and planes), for directions with zero, negative
    /// zero, tiny, huge, infinite and NaN components.
    #[test]
    fn ray_constants_equal_those_made_axis_by_axis() {
        let values = [
            0.0,
            -0.0,
            1e-31,
            -1e-31,
            -1e-30,
            0.3,
            -0.7,
            f32::MAX,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let origin = Vec3A::new(1.0, -2.0, 3.5);
        let mut compared = 0;
        for &x in &values {
            for &y in &values {
                for &z in &values {
                    let direction = Vec3A::new(x, y, z);
                    let ray = RayBoxes::new(origin, direction);
                    let inverse = [x, y, z].map(safe_inverse);
                    let (o, inv) = ray.constants();
                    assert_eq!(o, origin.to_array());
                    assert_eq!(
                        inv.map(f32::to_bits),
                        inverse.map(f32::to_bits),
                        "{direction}"
                    );
                    for axis in 0..3 {
                        let down = inverse[axis] < 0.0;
                        assert_eq!(ray.front[axis], Plane::of(axis, down), "{direction}");
                        assert_eq!(ray.back[axis], Plane::of(axis, !down), "{direction}");
                    }
                    let same = RayBoxes::from_inverse(origin.to_array(), inverse);
                    assert_eq!((same.front, same.back), (ray.front, ray.back));
                    compared += 1;
                }
            }
        }
        assert_eq!(compared, values.len().pow(3));
    }

    /// The node test takes a plane's distance as `(origin - plane) * -inverse`: its masks,
    /// and its entry distances up to the sign of a zero, are those of the textbook `(plane -
    /// origin) * inverse`, with the baseline operations and (where the CPU has AVX2) the
    /// AVX2 ones, for rays that start exactly on planes (where the zero's sign differs),
    /// origins far from zero, unused lanes, and directions with zero, tiny and huge
    /// components.
    #[test]
    fn the_node_test_answers_as_the_textbook_slab_test() {
        let mut next = uniform(0x9e3779b97f4a7c15, -2.0, 4.0);
        let avx2 = crate::simd::Isa::cpu_has_avx2();
        let components = [0.0, -0.0, 1e-31, -1e-31, 3e-38, 1e30, -0.5, 0.25, 1.0, -1.0];
        let (mut zero_distances, mut entered) = (0, 0);
        for round in 0..3000 {
            let mut node = WideNode::UNUSED;
            let far_away = if round % 7 == 0 { 1e6 } else { 0.0 };
            let origin = Vec3A::new(next(), next(), next()) + Vec3A::splat(far_away);
            // Lane 7 of odd rounds stays unused (infinite, inverted planes).
            let used = if round % 2 == 1 { WIDTH - 1 } else { WIDTH };
            for lane in 0..used {
                let a = Vec3A::new(next(), next(), next()) * 2.0 + Vec3A::splat(far_away);
                let b = a + Vec3A::new(next(), next(), next()).abs();
                let mut aabb = Aabb::new(a, b);
                // Most lanes share a plane with the origin on some axis.
                let axis = lane % 3;
                if lane % 4 != 3 {
                    if lane % 2 == 0 {
                        aabb.min[axis] = origin[axis];
                    } else {
                        aabb.max[axis] = origin[axis];
                    }
                    aabb.max[axis] = aabb.max[axis].max(aabb.min[axis]);
                }
                node.set_box(lane, &aabb);
            }
            // A third of the rays aimed at a box, the others with components from the list.
            let aimed = node.lane_box(round % used).center() - origin;
            let mut pick = |axis: usize| {
                let k = (next().abs() * 10.0) as usize;
                if round % 3 == 0 {
                    aimed[axis] + next() * 0.1
                } else {
                    components[k % components.len()]
                }
            };
            let direction = Vec3A::new(pick(0), pick(1), pick(2));
            let limit = if round % 5 == 0 {
                0.0
            } else {
                next().abs() * 8.0
            };
            let ray = RayBoxes::new(origin, direction);
            let inverse = direction.to_array().map(safe_inverse);
            // The textbook test, lane by lane.
            let mut expected_mask = 0u32;
            let mut expected_near = [0.0f32; WIDTH];
            for lane in 0..WIDTH {
                let (mut near, mut far) = (0.0f32, f32::INFINITY);
                for axis in 0..3 {
                    let (low, high) = (node.bounds[axis][lane], node.bounds[axis + 3][lane]);
                    let (front, back) = if inverse[axis] < 0.0 {
                        (high, low)
                    } else {
                        (low, high)
                    };
                    let t_front = (front - origin[axis]) * inverse[axis];
                    near = near.max(t_front);
                    far = far.min((back - origin[axis]) * inverse[axis]);
                    zero_distances += usize::from(t_front == 0.0);
                }
                expected_near[lane] = near;
                expected_mask |= u32::from(near <= (far * ROBUST_FAR).min(limit)) << lane;
            }
            let check = |(near, mask): (Lanes, u32), copy: &str| {
                assert_eq!(mask, expected_mask, "{copy}: {origin} {direction} {limit}");
                for lane in 0..WIDTH {
                    let (got, want) = (near.0[lane], expected_near[lane]);
                    assert!(
                        got == want,
                        "{copy}, lane {lane}: {got} against {want} ({origin} {direction})"
                    );
                }
            };
            check(ray.enter::<false>(&node, limit), "baseline");
            if avx2 {
                check(ray.enter::<true>(&node, limit), "AVX2");
            }
            entered += expected_mask.count_ones();
        }
        // Both answers exercised (3000 nodes of 8 lanes), and the case where the sign of a
        // zero distance differs between the two forms.
        assert!(
            zero_distances > 1000 && entered > 500 && entered < 20000,
            "{zero_distances} zero distances, {entered} lanes entered"
        );
    }

    /// A box kept outside the tree answers exactly as the same box in a node's lane.
    #[test]
    fn a_lone_box_answers_as_a_lane() {
        let mut next = uniform(12345, -2.0, 4.0);
        let mut agreed = [0; 2];
        for _ in 0..2000 {
            let a = Vec3A::new(next(), next(), next());
            let b = Vec3A::new(next(), next(), next());
            let aabb = Aabb::new(a.min(b), a.max(b));
            let mut node = WideNode::UNUSED;
            node.set_box(1, &aabb);
            // Aimed near the box; axis-parallel directions too (a zero component).
            let origin = Vec3A::new(next(), next(), next()) * 2.0;
            let mut d = (a + b) * 0.5 + Vec3A::new(next(), next(), next()) * 0.5 - origin;
            if next() > 1.0 {
                d.y = 0.0;
            }
            let ray = RayBoxes::new(origin, d);
            let limit = next().abs() * 3.0;
            let lane = ray.enter::<false>(&node, limit).1 & 0b10 != 0;
            assert_eq!(ray.enters_box(&aabb, limit), lane);
            agreed[lane as usize] += 1;
        }
        assert!(
            agreed[0] > 100 && agreed[1] > 100,
            "{agreed:?}: both answers exercised"
        );
    }
}
