//! Masked packet traversal: a packet of rays walks the tree together, each node fetched
//! once for all of them, but every ray tests each node alone (its own slab test, the single
//! ray's arithmetic) and a subtree is carried with the mask of the rays that entered it.
//!
//! Why: a single ray's walk is bound by the latency of fetching nodes (a node is four cache
//! lines, and BART Kitchen's tree does not fit in L2), not by its arithmetic. Rays that
//! travel together, such as a tile's shadow rays toward one light, fetch the nodes they share
//! once. Unlike the interval test of `packet`, which bounds rays from one origin, this needs
//! no shared point and prunes exactly: each ray reaches exactly the leaves it reaches alone,
//! so an any-hit query finds the same answer, and a ray that stops (its limit set negative)
//! drops out of every mask from then on. The walk ends when every ray has stopped.
//!
//! Any-hit walks take the children most of the mask's rays enter first (ties in lane order,
//! the binary tree's left-to-right order): an occluder found there stops the most rays, and
//! their answer does not depend on the order of visits. On BART Kitchen's shadow rays from
//! bounce hits that was 7-9% faster than lane order alone; nearest first (as closest-hit
//! walks go) was 13% slower. Closest-hit walks take them by the least
//! entry distance among the rays that enter each (the child some ray reaches first is walked
//! next). Ordering by the first ray's distances alone, as this walk did before, handed BART
//! Kitchen's mirror rays 5% more ray-leaf tests and 10% more leaf visits. A closest-hit
//! leaf never stops a ray ([`GatheredLeaf::STOPS_RAYS`]), so the walk does not look for
//! stopped rays after it.
//! A closest-hit walk's limits shrink as hits are found, so a leaf popped after other
//! leaves were visited has its box tested again for the rays of its mask with their current
//! limits (as the single-ray walk culls a popped entry by its entry distance): the rays
//! that can no longer reach it are not handed to it.
//!
//! Where the CPU has AVX-512, a node in the mask of at least 16 rays is tested the other way
//! round: per child, sixteen rays per instruction (`across_rays`), each ray's slab test in
//! the textbook form `(plane - origin) * inverse`, whose masks are those of the ray's own
//! test (see `RayBoxes::slabs`). On BART Kitchen's recorded rays that made
//! shadow packets about 2.5% faster and mirror packets about 4.5%: the walk waits on node
//! fetches more than on the test.
//!
//! A subtree that at most [`ALONE_MAX_RAYS`] of the packet's rays enter is handed to each of
//! them in turn, to walk alone (`WideBvh::walk`, the single ray's walk and its order
//! of visits), as Embree's hybrid packet walks switch to single rays below a few active
//! ones. Past the first levels a bounce's rays part ways, and a node with a mask of two or
//! three rays cost the masked walk a test per ray plus the masks' bookkeeping (gathering,
//! transposing, a 24-byte stack entry per child) for little sharing; the rays walking a
//! subtree one after another still find its nodes in the cache the first one brought
//! them into. Each ray still reaches exactly the leaves its own walk reaches, now by that
//! walk. On BART Kitchen frame 400's recorded rays (one thread, AVX-512 copy, eight
//! alternated rounds) mirror packets traced 12% more rays a second and shadow packets 1%
//! more (9% and 8.5% in five earlier rounds), and whole frames took 3.5% less time.

use std::mem::MaybeUninit;

use super::node::ChildRef;
use super::walk::{INLINE_STACK, LeafVisit, RayBoxes, StackEntry, lanes_near_to_far};
use super::{EMPTY, GatheredLeaf, Lanes, PACKET, WIDTH, WideBvh};
use crate::simd;

/// A pending subtree of a masked walk: the child (as in `WideNode::child`), its leaf count,
/// the rays that entered it, and where its box is (lane `lane` of node `parent`) with how
/// many leaves the walk had visited when it was pushed (`pushed_at`).
#[derive(Clone, Copy)]
struct MaskedEntry {
    child: u32,
    count: u32,
    rays: u64,
    parent: u32,
    lane: u16,
    pushed_at: u16,
}

// Ray masks are one bit per ray; a ray's mask of lanes is one byte.
const _: () = assert!(PACKET <= 64 && PACKET % 8 == 0 && WIDTH == 8);

impl WideBvh {
    /// Walks the tree once for the rays `rays` (at most [`PACKET`]), ray `r` with limit
    /// `limits[r]`: each leaf is handed, once, the rays that entered it (in ray order) as
    /// `leaf.visit(rays, leaf_ref, count, limits)`. A leaf stops a ray it is handed by
    /// setting its limit below 0; stopped rays enter nothing more, and the walk returns when
    /// all have stopped. (A leaf changes only the limits of the rays it is handed: after a
    /// leaf, only they are checked for a stop.)
    ///
    /// Each ray reaches exactly the leaves [`WideBvh::traverse_unordered`] reaches for it
    /// alone (with the same limit), and no other.
    pub fn traverse_masked(
        &self,
        rays: &[RayBoxes],
        limits: &mut [f32; PACKET],
        leaf: impl GatheredLeaf,
    ) {
        self.traverse_masked_in::<false>(rays, limits, leaf, ALONE_MAX_RAYS)
    }

    /// [`WideBvh::traverse_masked`] taking children nearest first as the first ray of each
    /// mask sees them (closest-hit queries).
    pub fn traverse_masked_ordered(
        &self,
        rays: &[RayBoxes],
        limits: &mut [f32; PACKET],
        leaf: impl GatheredLeaf,
    ) {
        self.traverse_masked_in::<true>(rays, limits, leaf, ALONE_MAX_RAYS)
    }

    /// The masked walk, handing a subtree entered by at most `alone_max` rays to each of them
    /// to walk alone (0: never; the tests compare both ways).
    fn traverse_masked_in<const ORDERED: bool>(
        &self,
        rays: &[RayBoxes],
        limits: &mut [f32; PACKET],
        leaf: impl GatheredLeaf,
        alone_max: u32,
    ) {
        let n = rays.len().min(PACKET);
        if n == 0 {
            return;
        }
        let all = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
        let mut leaf = leaf;
        if let Some((first, count)) = self.root_leaf {
            let entering: [u8; PACKET] = std::array::from_fn(|r| r as u8);
            leaf.visit::<false>(&entering[..n], first, count, limits);
            return;
        }
        if self.nodes.is_empty() {
            return;
        }
        let needed = self.depth * WIDTH + 1;
        let mut inline = [const { MaybeUninit::uninit() }; 128];
        let mut heap;
        let stack: &mut [MaybeUninit<MaskedEntry>] = if needed <= inline.len() {
            &mut inline
        } else {
            heap = vec![MaybeUninit::uninit(); needed];
            &mut heap
        };
        simd::dispatch(MaskedWalk::<_, ORDERED> {
            bvh: self,
            stack,
            rays: &rays[..n],
            limits,
            all,
            leaf: &mut leaf,
            alone_max,
        })
    }

    #[inline(always)]
    fn walk_masked<const AVX: bool, const ORDERED: bool, L: GatheredLeaf>(
        &self,
        stack: &mut [MaybeUninit<MaskedEntry>],
        rays: &[RayBoxes],
        limits: &mut [f32; PACKET],
        all: u64,
        leaf: &mut L,
        alone_max: u32,
    ) {
        // Of the rays in `rays`, those not stopped: eight rays per step (one vector compare
        // and mask where the compiler vectorises it), skipping groups of eight with no ray
        // in `rays`.
        let live = |limits: &[f32; PACKET], rays: u64| {
            let mut live = 0u64;
            for (group, eight) in limits.chunks_exact(8).enumerate() {
                if (rays >> (8 * group)) & 0xff == 0 {
                    continue;
                }
                let bits = (0..8).fold(0u64, |m, k| m | (u64::from(eight[k] >= 0.0) << k));
                live |= bits << (8 * group);
            }
            live & rays
        };
        // With AVX-512, a node visited by many rays tests them sixteen at a time per child
        // (`across_rays`) instead of one ray at a time over the eight children.
        let across = (AVX && rays.len() >= ACROSS_MIN_RAYS as usize && simd::avx512())
            .then(|| RayColumns::of(rays));
        let mut alive = live(limits, all);
        stack[0] = MaybeUninit::new(MaskedEntry {
            child: 0,
            count: 0,
            rays: alive,
            parent: 0,
            lane: 0,
            pushed_at: 0,
        });
        let mut top = 1usize;
        let mut entering = [0u8; PACKET];
        // Leaves visited so far (wrapping: compared only for equality; a walk that visits
        // a multiple of 65,536 leaves between a push and its pop skips that re-test, which
        // costs only the leaf visit the re-test would have spared).
        let mut leaves_visited = 0u16;
        // The stack of a ray walking a subtree alone. It holds what a whole walk needs; a tree
        // too deep for it (pathological inputs) keeps every subtree masked.
        let mut alone_stack = [const { MaybeUninit::<StackEntry>::uninit() }; INLINE_STACK];
        let alone_max = if self.depth * (WIDTH - 1) < INLINE_STACK {
            alone_max
        } else {
            0
        };
        while top > 0 {
            top -= 1;
            // SAFETY: entries below `top` were all written before.
            let entry = unsafe { stack[top].assume_init() };
            let mut mask = entry.rays & alive;
            if mask == 0 {
                continue;
            }
            match ChildRef::decode(entry.child, entry.count) {
                ChildRef::Leaf { first, count } => {
                    // Closest-hit: a ray that found a hit since the leaf was pushed may no
                    // longer reach its box (a sixth of the leaf visits on BART Kitchen's
                    // mirror rays); its box is tested again with the current limits, as the
                    // single-ray walk culls a popped entry by its distance.
                    if ORDERED && entry.pushed_at != leaves_visited {
                        let parent = &self.nodes[entry.parent as usize];
                        let lane = usize::from(entry.lane);
                        mask = match &across {
                            #[cfg(target_arch = "x86_64")]
                            Some(columns) if mask.count_ones() >= ACROSS_MIN_RAYS => {
                                // SAFETY: as for the node test below.
                                unsafe {
                                    across_rays::rays_by_lane::<false>(
                                        parent,
                                        columns,
                                        limits,
                                        mask,
                                        1 << lane,
                                    )
                                    .0[lane]
                                }
                            }
                            _ => {
                                let mut still = 0u64;
                                let mut bits = mask;
                                while bits != 0 {
                                    let r = bits.trailing_zeros() as usize;
                                    bits &= bits - 1;
                                    let lanes = rays[r].enter::<AVX>(parent, limits[r]).1;
                                    still |= u64::from((lanes >> lane) & 1) << r;
                                }
                                still
                            }
                        };
                        if mask == 0 {
                            continue;
                        }
                    }
                    leaves_visited = leaves_visited.wrapping_add(1);
                    let mut k = 0;
                    let mut bits = mask;
                    while bits != 0 {
                        entering[k] = bits.trailing_zeros() as u8;
                        bits &= bits - 1;
                        k += 1;
                    }
                    leaf.visit::<AVX>(&entering[..k], first, count, limits);
                    if L::STOPS_RAYS {
                        // Only the rays just handed to the leaf can have stopped. Read one
                        // by one: the leaf has just stored their limits one by one, and a
                        // vector read of them waits for those stores to drain.
                        for &r in &entering[..k] {
                            let limit = limits[usize::from(r)];
                            let stopped = limit < 0.0 || limit.is_nan();
                            alive &= !(u64::from(stopped) << r);
                        }
                        if alive == 0 {
                            return;
                        }
                    }
                }
                ChildRef::Node(index) => {
                    if mask.count_ones() <= alone_max {
                        alive &= !self.walk_each_alone::<AVX, ORDERED, L>(
                            &mut alone_stack,
                            rays,
                            limits,
                            leaf,
                            mask,
                            index,
                        );
                        // Limits may have shrunk: pending leaves are tested again when popped.
                        leaves_visited = leaves_visited.wrapping_add(1);
                        if L::STOPS_RAYS && alive == 0 {
                            return;
                        }
                        continue;
                    }
                    let node = &self.nodes[index as usize];
                    // Per lane, the rays that enter it and (closest-hit walks) the nearest
                    // of their entry distances.
                    let (entered_by, nearest) = match &across {
                        #[cfg(target_arch = "x86_64")]
                        Some(columns) if mask.count_ones() >= ACROSS_MIN_RAYS => {
                            // SAFETY: `across` is made only where `simd::avx512()`, which
                            // holds only where the CPU has AVX-512F.
                            unsafe {
                                across_rays::rays_by_lane::<ORDERED>(
                                    node,
                                    columns,
                                    limits,
                                    mask,
                                    u32::MAX,
                                )
                            }
                        }
                        _ => {
                            // Per ray, the lanes it enters (zero for the rays not in the mask).
                            let mut lanes_of = [0u8; PACKET];
                            let mut nearest = Lanes::splat(f32::INFINITY);
                            let mut bits = mask;
                            while bits != 0 {
                                let r = bits.trailing_zeros() as usize;
                                bits &= bits - 1;
                                lanes_of[r] = if ORDERED {
                                    let (near, lanes) =
                                        rays[r].enter_keeping_entered::<AVX>(node, limits[r]);
                                    nearest = nearest.min::<AVX>(near);
                                    lanes as u8
                                } else {
                                    rays[r].enter::<AVX>(node, limits[r]).1 as u8
                                };
                            }
                            let by_lane = if mask.count_ones() >= TRANSPOSE_MIN_RAYS {
                                rays_by_lane(&lanes_of, mask)
                            } else {
                                rays_by_lane_one_by_one(&lanes_of, mask)
                            };
                            (by_lane, nearest)
                        }
                    };
                    let mut push = |lane: usize, top: &mut usize| {
                        if entered_by[lane] != 0 && node.child[lane] != EMPTY {
                            stack[*top] = MaybeUninit::new(MaskedEntry {
                                child: node.child[lane],
                                count: node.count[lane],
                                rays: entered_by[lane],
                                parent: index,
                                lane: lane as u16,
                                pushed_at: leaves_visited,
                            });
                            *top += 1;
                        }
                    };
                    let entered = (0..WIDTH)
                        .filter(|&lane| entered_by[lane] != 0)
                        .fold(0u32, |m, lane| m | 1 << lane);
                    let (order, count) = if ORDERED {
                        // By the nearest entry among each lane's rays, so the lane some ray
                        // reaches first is walked next.
                        lanes_near_to_far::<true>(nearest, entered)
                    } else {
                        // By how many rays enter each lane, most first (ties in lane order):
                        // an occluder found there stops the most rays.
                        let fewer = Lanes(std::array::from_fn(|lane| {
                            (PACKET as u32 - entered_by[lane].count_ones()) as f32
                        }));
                        lanes_near_to_far::<false>(fewer, entered)
                    };
                    // Pushed last first, so the first is walked next.
                    for &lane in order[..count].iter().rev() {
                        push(lane, &mut top);
                    }
                }
            }
        }
    }

    /// Each ray of `mask` walks the subtree of node `index` alone (the single ray's walk),
    /// its leaves handed to `leaf` for it alone. Returns the rays that stopped (any hit).
    #[inline(always)]
    fn walk_each_alone<const AVX: bool, const ORDERED: bool, L: GatheredLeaf>(
        &self,
        stack: &mut [MaybeUninit<StackEntry>],
        rays: &[RayBoxes],
        limits: &mut [f32; PACKET],
        leaf: &mut L,
        mask: u64,
        index: u32,
    ) -> u64 {
        let mut stopped = 0u64;
        let mut bits = mask;
        while bits != 0 {
            let r = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let limit = limits[r];
            let one = OneRayLeaf {
                leaf: &mut *leaf,
                ray: r as u8,
                limits: &mut *limits,
            };
            self.walk::<ORDERED, AVX>(stack, &rays[r], limit, one, ChildRef::Node(index));
            if L::STOPS_RAYS {
                let limit = limits[r];
                stopped |= u64::from(limit < 0.0 || limit.is_nan()) << r;
            }
        }
        stopped
    }
}

/// At most this many rays in a node's mask: each of them walks the node's subtree alone (see
/// the module's head). On BART Kitchen frame 400's mirror and shadow packets, thresholds of
/// 4, 8 and 15 rays all beat the masked walk; 8 was at least as fast as the others in the
/// timings, while instruction counts kept falling up to 15 (the sixteen-ray node test takes
/// over from 16 on).
const ALONE_MAX_RAYS: u32 = 8;

/// One ray of a masked walk walking a subtree alone, as a [`LeafVisit`]: each leaf it
/// reaches is handed to the packet's leaf for that ray alone, with the ray's limit.
struct OneRayLeaf<'a, L> {
    leaf: &'a mut L,
    ray: u8,
    limits: &'a mut [f32; PACKET],
}

impl<L: GatheredLeaf> LeafVisit for OneRayLeaf<'_, L> {
    #[inline(always)]
    fn visit<const AVX: bool>(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool {
        let r = usize::from(self.ray);
        self.limits[r] = *t_max;
        self.leaf
            .visit::<AVX>(std::slice::from_ref(&self.ray), first, count, self.limits);
        let limit = self.limits[r];
        *t_max = limit;
        // A stopped ray (any hit) ends its walk; a closest-hit limit never goes below 0.
        !(L::STOPS_RAYS && (limit < 0.0 || limit.is_nan()))
    }
}

/// From this many rays in a node's mask on (and in the packet), the node is tested sixteen
/// rays at a time where the CPU has AVX-512 ([`across_rays::rays_by_lane`]).
const ACROSS_MIN_RAYS: u32 = 16;

/// The packet's ray constants as columns (ray `r` at index `r`), for the node test across
/// rays: origins and inverse directions (the layout of `RayPacket`'s, taken here from the
/// masked walk's `RayBoxes`).
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct RayColumns {
    origin: [[f32; PACKET]; 3],
    inverse: [[f32; PACKET]; 3],
}

impl RayColumns {
    fn of(rays: &[RayBoxes]) -> RayColumns {
        let mut columns = RayColumns {
            origin: [[0.0; PACKET]; 3],
            inverse: [[0.0; PACKET]; 3],
        };
        for (r, ray) in rays.iter().enumerate().take(PACKET) {
            let (origin, inverse) = ray.constants();
            for axis in 0..3 {
                columns.origin[axis][r] = origin[axis];
                columns.inverse[axis][r] = inverse[axis];
            }
        }
        columns
    }
}

/// The node test across rays: for each child, sixteen rays per AVX-512 instruction.
#[cfg(target_arch = "x86_64")]
mod across_rays {
    use std::arch::x86_64::*;

    use super::{PACKET, RayColumns, WIDTH};
    use crate::accel::wide::{EMPTY, Lanes, ROBUST_FAR, WideNode};

    /// Per lane of `node`, the mask of the rays of `rays` that enter it: what
    /// [`super::rays_by_lane`] makes from each ray's `RayBoxes::enter`, bit for bit. Per ray
    /// the textbook slab test `(plane - origin) * inverse`, sixteen rays per instruction;
    /// `RayBoxes::slabs` computes `(origin - plane) * -inverse`, the same numbers (its
    /// entry distances can differ only in the sign of a zero, which the masks and the
    /// nearest distance's uses do not see).
    /// Only the lanes in `lanes` (bit `lane`) are tested; the others get no rays (a popped
    /// leaf's box is tested again as one lane of its parent, and testing all eight cost it
    /// eight times the work). Lanes without a child get no rays (the walk skips them either
    /// way). With `NEAREST`,
    /// also per lane the least entry distance of those rays (+infinity where none enters),
    /// else +infinity.
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn rays_by_lane<const NEAREST: bool>(
        node: &WideNode,
        columns: &RayColumns,
        limits: &[f32; PACKET],
        rays: u64,
        lanes: u32,
    ) -> ([u64; WIDTH], Lanes) {
        let mut by_lane = [0u64; WIDTH];
        let mut nearest = [_mm512_set1_ps(f32::INFINITY); WIDTH];
        for group in 0..PACKET / 16 {
            let in_group = (rays >> (16 * group)) as u16;
            if in_group == 0 {
                continue;
            }
            let at = 16 * group;
            // SAFETY (loads): `at + 16 <= PACKET`, within each column.
            let column = |c: &[f32; PACKET]| unsafe { _mm512_loadu_ps(c[at..].as_ptr()) };
            let origin = [0, 1, 2].map(|axis| column(&columns.origin[axis]));
            let inverse = [0, 1, 2].map(|axis| column(&columns.inverse[axis]));
            // A ray whose inverse is negative meets the upper plane first (`RayBoxes::new`
            // decides `front` by the same compare).
            let negative =
                inverse.map(|i| _mm512_cmp_ps_mask::<_CMP_LT_OQ>(i, _mm512_setzero_ps()));
            let limit = column(limits);
            for (lane, (by, nearest)) in by_lane.iter_mut().zip(&mut nearest).enumerate() {
                if node.child[lane] == EMPTY || lanes & (1 << lane) == 0 {
                    continue;
                }
                let mut near = _mm512_set1_ps(0.0);
                let mut far = _mm512_set1_ps(f32::INFINITY);
                for axis in 0..3 {
                    let lower = _mm512_set1_ps(node.bounds[axis][lane]);
                    let upper = _mm512_set1_ps(node.bounds[axis + 3][lane]);
                    let front = _mm512_mask_blend_ps(negative[axis], lower, upper);
                    let back = _mm512_mask_blend_ps(negative[axis], upper, lower);
                    let t_front = _mm512_mul_ps(_mm512_sub_ps(front, origin[axis]), inverse[axis]);
                    let t_back = _mm512_mul_ps(_mm512_sub_ps(back, origin[axis]), inverse[axis]);
                    near = _mm512_max_ps(near, t_front);
                    far = _mm512_min_ps(far, t_back);
                }
                let far = _mm512_min_ps(_mm512_mul_ps(far, _mm512_set1_ps(ROBUST_FAR)), limit);
                let entered = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(in_group, near, far);
                *by |= u64::from(entered) << at;
                if NEAREST {
                    *nearest = _mm512_mask_min_ps(*nearest, entered, *nearest, near);
                }
            }
        }
        let nearest = if NEAREST {
            // The minimum of a set of non-NaN floats, whatever the order of reduction.
            Lanes(std::array::from_fn(|lane| {
                _mm512_reduce_min_ps(nearest[lane])
            }))
        } else {
            Lanes::splat(f32::INFINITY)
        };
        (by_lane, nearest)
    }
}

/// From this many rays in a node's mask on, [`rays_by_lane`] transposes their lane masks;
/// fewer (scattered bounce rays) are taken one by one.
const TRANSPOSE_MIN_RAYS: u32 = 8;

/// [`rays_by_lane`] ray by ray, lane by lane.
#[inline(always)]
fn rays_by_lane_one_by_one(lanes_of: &[u8; PACKET], rays: u64) -> [u64; WIDTH] {
    let mut by_lane = [0u64; WIDTH];
    let mut bits = rays;
    while bits != 0 {
        let r = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        let mut lanes = lanes_of[r];
        while lanes != 0 {
            by_lane[lanes.trailing_zeros() as usize] |= 1 << r;
            lanes &= lanes - 1;
        }
    }
    by_lane
}

/// Per lane, the mask of the rays that enter it, from each ray's mask of lanes
/// (`lanes_of[r]`, zero for rays outside `rays`): a transpose of a 64 x 8 bit matrix, eight
/// rays at a time as an 8 x 8 block in one `u64` (Hacker's Delight, `transpose8`), instead
/// of a loop over each ray's lanes (a branch per lane entered).
#[inline(always)]
fn rays_by_lane(lanes_of: &[u8; PACKET], rays: u64) -> [u64; WIDTH] {
    let mut by_lane = [0u64; WIDTH];
    for group in 0..PACKET / 8 {
        if (rays >> (8 * group)) & 0xff == 0 {
            continue;
        }
        // Byte k, bit l: ray 8 * group + k enters lane l.
        let block: [u8; 8] = lanes_of[8 * group..8 * group + 8].try_into().unwrap();
        let mut x = u64::from_le_bytes(block);
        let t = (x ^ (x >> 7)) & 0x00AA_00AA_00AA_00AA;
        x ^= t ^ (t << 7);
        let t = (x ^ (x >> 14)) & 0x0000_CCCC_0000_CCCC;
        x ^= t ^ (t << 14);
        let t = (x ^ (x >> 28)) & 0x0000_0000_F0F0_F0F0;
        x ^= t ^ (t << 28);
        // Now byte l, bit k: ray 8 * group + k enters lane l.
        for (lane, by) in by_lane.iter_mut().enumerate() {
            *by |= ((x >> (8 * lane)) & 0xff) << (8 * group);
        }
    }
    by_lane
}

/// One masked walk as a [`simd::Kernel`] (see `walk::Walk`).
struct MaskedWalk<'a, G, const ORDERED: bool> {
    bvh: &'a WideBvh,
    stack: &'a mut [MaybeUninit<MaskedEntry>],
    rays: &'a [RayBoxes],
    limits: &'a mut [f32; PACKET],
    all: u64,
    leaf: &'a mut G,
    alone_max: u32,
}

impl<G: GatheredLeaf, const ORDERED: bool> simd::Kernel for MaskedWalk<'_, G, ORDERED> {
    type Output = ();

    #[inline(always)]
    fn run<const AVX2: bool>(self) {
        self.bvh.walk_masked::<AVX2, ORDERED, G>(
            self.stack,
            self.rays,
            self.limits,
            self.all,
            self.leaf,
            self.alone_max,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::wide::WideNode;
    use crate::accel::wide::test_support::xorshift;
    use glam::Vec3A;

    /// The AVX-512 node test across rays gives each lane exactly the rays that
    /// `RayBoxes::enter` (in the AVX2 copy and the baseline) lets in, and the least entry
    /// distance among them that each ray's own test gives, over random nodes
    /// (with unused lanes, flat and point boxes) and rays (axis-parallel ones, origins on a
    /// box's planes, huge coordinates, limits negative, zero and infinite).
    #[test]
    fn the_node_test_across_rays_is_each_ray_s_own() {
        if !crate::simd::Isa::cpu_has_avx512() || !crate::simd::Isa::cpu_has_avx2() {
            eprintln!("skipped: this CPU has no AVX-512F");
            return;
        }
        let mut next = xorshift(0x0123_4567_89AB_CDEF);
        let mut unit = crate::accel::wide::test_support::uniform(7, -1.0, 2.0);
        let mut checked = 0usize;
        for round in 0..1000 {
            let scale = [1.0f32, 1e3, 1e-3, 3e7][round % 4];
            let mut node = WideNode::UNUSED;
            for lane in 0..WIDTH {
                if next().is_multiple_of(5) {
                    continue; // unused: EMPTY child, inverted box
                }
                let a = Vec3A::new(unit(), unit(), unit()) * scale;
                let mut b = Vec3A::new(unit(), unit(), unit()) * scale;
                match next() % 6 {
                    0 => b = a,     // a point
                    1 => b.x = a.x, // flat
                    _ => {}
                }
                let (lo, hi) = (a.min(b), a.max(b));
                for axis in 0..3 {
                    node.bounds[axis][lane] = lo[axis];
                    node.bounds[axis + 3][lane] = hi[axis];
                }
                node.child[lane] = lane as u32;
            }
            let rays: Vec<RayBoxes> = (0..PACKET)
                .map(|r| {
                    let mut origin = Vec3A::new(unit(), unit(), unit()) * scale * 2.0;
                    if r % 7 == 0 {
                        // On the planes of some used lane's box.
                        let lane = (next() % WIDTH as u64) as usize;
                        origin.x = node.bounds[0][lane];
                        origin.y = node.bounds[4][lane];
                    }
                    // Mostly aimed near some lane's box, so that many rays enter lanes.
                    let lane = (next() % WIDTH as u64) as usize;
                    let centre = Vec3A::new(
                        node.bounds[0][lane] + node.bounds[3][lane],
                        node.bounds[1][lane] + node.bounds[4][lane],
                        node.bounds[2][lane] + node.bounds[5][lane],
                    ) * 0.5;
                    let jitter = Vec3A::new(unit(), unit(), unit()) * 0.1;
                    let mut direction = if centre.is_finite() && r % 3 != 0 {
                        (centre - origin).normalize_or_zero() + jitter
                    } else {
                        Vec3A::new(unit(), unit(), unit())
                    };
                    match r % 5 {
                        0 => direction.y = 0.0,
                        1 => (direction.x, direction.z) = (0.0, -0.0),
                        _ => {}
                    }
                    RayBoxes::new(origin, direction)
                })
                .collect();
            let mut limits = [0f32; PACKET];
            for (r, limit) in limits.iter_mut().enumerate() {
                *limit = match r % 6 {
                    0 => f32::INFINITY,
                    1 => -1.0,
                    2 => 0.0,
                    _ => unit().abs() * scale * 3.0,
                };
            }
            let mask = match round % 3 {
                0 => u64::MAX,
                1 => next() | 1,
                _ => next() & 0xFFFF_0000_FFFF_0000 | 1 << 16,
            };
            let columns = RayColumns::of(&rays);
            // SAFETY: the CPU has AVX-512F (checked above).
            let (across, nearest) = unsafe {
                across_rays::rays_by_lane::<true>(&node, &columns, &limits, mask, u32::MAX)
            };
            let (unordered, no_nearest) = unsafe {
                across_rays::rays_by_lane::<false>(&node, &columns, &limits, mask, u32::MAX)
            };
            assert_eq!(unordered, across);
            assert_eq!(no_nearest.0, [f32::INFINITY; WIDTH]);
            // Asked about some lanes only: those lanes' rays and distances, none elsewhere.
            let some = (next() & 0xff) as u32;
            // SAFETY: as above.
            let (only, only_nearest) =
                unsafe { across_rays::rays_by_lane::<true>(&node, &columns, &limits, mask, some) };
            for lane in 0..WIDTH {
                if some & (1 << lane) != 0 {
                    assert_eq!(only[lane], across[lane], "round {round}, lane {lane}");
                    assert_eq!(only_nearest.0[lane], nearest.0[lane], "round {round}");
                } else {
                    assert_eq!(only[lane], 0, "round {round}, lane {lane} not asked about");
                    assert_eq!(only_nearest.0[lane], f32::INFINITY, "round {round}");
                }
            }
            for avx in [false, true] {
                let mut lanes_of = [0u8; PACKET];
                let mut expected_nearest = [f32::INFINITY; WIDTH];
                for r in 0..PACKET {
                    if mask & (1 << r) != 0 {
                        let (near, lanes) = if avx {
                            crate::simd::run_avx2_if_available(EnterKernel(
                                &rays[r], &node, limits[r],
                            ))
                            .unwrap()
                        } else {
                            rays[r].enter_keeping_entered::<false>(&node, limits[r])
                        };
                        lanes_of[r] = lanes as u8;
                        for (lane, nearest) in expected_nearest.iter_mut().enumerate() {
                            if node.child[lane] != EMPTY {
                                *nearest = nearest.min(near.0[lane]);
                            }
                        }
                    }
                }
                let mut expected = rays_by_lane(&lanes_of, mask);
                for (lane, e) in expected.iter_mut().enumerate() {
                    if node.child[lane] == EMPTY {
                        *e = 0;
                    }
                }
                assert_eq!(across, expected, "round {round}, avx {avx}");
                // Equal as numbers (a minimum over +0 and -0 may keep either sign, which
                // orders lanes alike).
                assert_eq!(nearest.0, expected_nearest, "round {round}, avx {avx}");
            }
            checked += across
                .iter()
                .map(|m| m.count_ones() as usize)
                .sum::<usize>();
        }
        // Not a vacuous comparison: many rays entered many lanes.
        assert!(checked > 5_000, "{checked}");
    }

    /// One ray's `enter_keeping_entered` in the AVX2 copy.
    struct EnterKernel<'a>(&'a RayBoxes, &'a WideNode, f32);

    impl crate::simd::Kernel for EnterKernel<'_> {
        type Output = (Lanes, u32);
        #[inline(always)]
        fn run<const AVX2: bool>(self) -> (Lanes, u32) {
            self.0.enter_keeping_entered::<AVX2>(self.1, self.2)
        }
    }

    /// Handing small masks to single-ray walks changes how a packet walks, not where each
    /// ray goes: over a tree of scattered boxes, for packets that stay together near the
    /// root and part below it (bundles) and packets scattered from the start, with limits
    /// finite and infinite, every ray is handed exactly the leaves its own unordered walk
    /// reaches, whether subtrees go to single rays never, at [`ALONE_MAX_RAYS`], or
    /// always below the root; the near-first walk too while no leaf shrinks a limit; and a
    /// leaf that stops a ray (any hit) stops exactly the rays whose own walks reach it.
    #[test]
    fn rays_walking_subtrees_alone_reach_what_they_reach_in_the_packet() {
        use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::builder::build_bvh2};
        let mut unit = crate::accel::wide::test_support::uniform(11, 0.0, 1.0);
        let boxes: Vec<Aabb> = (0..3000)
            .map(|_| {
                let low = Vec3A::new(unit(), unit(), unit()) * 100.0;
                Aabb::new(low, low + Vec3A::new(unit(), unit(), unit()) * 3.0)
            })
            .collect();
        let mut params = BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 2;
        let binary = build_bvh2(&boxes, params, &mut std::time::Duration::default());
        let bvh = WideBvh::collapse(&binary, |first, _| first);
        assert!(bvh.depth >= 3, "a tree too shallow to part a packet");
        // A leaf blocks (stops a ray, when the walk stops rays) where its first slot is a
        // multiple of 7.
        let blocks = |first: u32| first % 7 == 0;
        let (mut shared_visits, mut lone_visits, mut visits, mut stops) = (0, 0, 0, 0);
        for packet in 0..24 {
            let scattered = packet % 3 == 0;
            let spread = [0.2f32, 1.0, 5.0][packet % 3];
            let aim = Vec3A::new(unit(), unit(), unit()) * 100.0;
            let eye = Vec3A::new(unit() * 100.0, unit() * 100.0, -40.0);
            let pairs: Vec<(Vec3A, Vec3A)> = (0..PACKET)
                .map(|r| {
                    let jitter = Vec3A::new(unit(), unit(), unit()) - 0.5;
                    if scattered {
                        let origin = Vec3A::new(unit(), unit(), unit()) * 100.0;
                        (origin, jitter)
                    } else {
                        let (x, y) = ((r % 8) as f32, (r / 8) as f32);
                        let origin = eye + Vec3A::new(x, y, 0.0) * spread;
                        (origin, aim - eye + jitter * spread * 2.0)
                    }
                })
                .collect();
            let rays: Vec<RayBoxes> = pairs.iter().map(|&(o, d)| RayBoxes::new(o, d)).collect();
            let limit_of = |r: usize| if r % 4 == 1 { 60.0 } else { f32::INFINITY };
            // Each ray's own walk: the leaves it reaches, and whether one of them blocks.
            let expected: Vec<Vec<u32>> = (0..PACKET)
                .map(|r| {
                    let mut reached = Vec::new();
                    bvh.traverse_unordered(&rays[r], limit_of(r), |first, _, _: &mut f32| {
                        reached.push(first);
                        true
                    });
                    reached.sort_unstable();
                    reached
                })
                .collect();
            for alone_max in [0, ALONE_MAX_RAYS, PACKET as u32 - 1] {
                for ordered in [false, true] {
                    let mut reached = vec![Vec::new(); PACKET];
                    let mut limits: [f32; PACKET] = std::array::from_fn(limit_of);
                    let leaf = |entering: &[u8], first: u32, _: u32, _: &mut [f32; PACKET]| {
                        if entering.len() > 1 {
                            shared_visits += 1;
                        } else {
                            lone_visits += 1;
                        }
                        for &r in entering {
                            reached[usize::from(r)].push(first);
                        }
                    };
                    if ordered {
                        bvh.traverse_masked_in::<true>(&rays, &mut limits, leaf, alone_max);
                    } else {
                        bvh.traverse_masked_in::<false>(&rays, &mut limits, leaf, alone_max);
                    }
                    for (r, reached) in reached.iter_mut().enumerate() {
                        reached.sort_unstable();
                        assert_eq!(
                            *reached, expected[r],
                            "packet {packet}, ray {r}, alone at {alone_max}, ordered {ordered}"
                        );
                        visits += reached.len();
                    }
                }
                // Any hit: a blocking leaf stops the rays it is handed.
                let mut limits: [f32; PACKET] = std::array::from_fn(limit_of);
                let leaf = |entering: &[u8], first: u32, _: u32, limits: &mut [f32; PACKET]| {
                    if blocks(first) {
                        for &r in entering {
                            limits[usize::from(r)] = -1.0;
                        }
                    }
                };
                bvh.traverse_masked_in::<false>(&rays, &mut limits, leaf, alone_max);
                for r in 0..PACKET {
                    let blocked = expected[r].iter().any(|&first| blocks(first));
                    assert_eq!(
                        limits[r] < 0.0,
                        blocked,
                        "packet {packet}, ray {r}, alone at {alone_max}"
                    );
                    stops += usize::from(blocked);
                }
            }
        }
        // Not vacuous: rays reached many leaves, many leaves were shared by several rays
        // (the masked walk) and many handed to one (walks alone), and some rays stopped
        // while others went on.
        assert!(visits > 20_000, "{visits} leaf visits");
        assert!(
            shared_visits > 1_000 && lone_visits > 1_000,
            "{shared_visits} / {lone_visits}"
        );
        assert!(
            stops > 300 && stops < 3 * 24 * PACKET - 300,
            "{stops} stops"
        );
    }

    #[test]
    fn rays_by_lane_transposes_every_ray_s_lanes() {
        // Deterministic pseudo-random masks, with whole groups of rays left out.
        let mut next = xorshift(0x9E37_79B9_7F4A_7C15);
        for round in 0..200 {
            let rays = match round % 4 {
                0 => u64::MAX,
                1 => next() & 0x00FF_FF00_0000_FFFF,
                _ => next(),
            };
            let mut lanes_of = [0u8; PACKET];
            for (r, lanes) in lanes_of.iter_mut().enumerate() {
                if rays & (1 << r) != 0 {
                    *lanes = next() as u8;
                }
            }
            let mut expected = [0u64; WIDTH];
            for (r, &lanes) in lanes_of.iter().enumerate() {
                for (lane, e) in expected.iter_mut().enumerate() {
                    if lanes & (1 << lane) != 0 {
                        *e |= 1 << r;
                    }
                }
            }
            assert_eq!(rays_by_lane(&lanes_of, rays), expected, "round {round}");
            assert_eq!(
                rays_by_lane_one_by_one(&lanes_of, rays),
                expected,
                "round {round}"
            );
        }
    }
}
