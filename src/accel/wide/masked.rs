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
//! Any-hit walks take children in lane order (the binary tree's left-to-right order): their
//! answer does not depend on the order of visits. Closest-hit walks take them nearest first
//! as the first ray of the mask sees them (its limit shrinks early; the other rays follow
//! its order, which in a coherent packet is nearly theirs).

use std::mem::MaybeUninit;

use super::node::ChildRef;
use super::walk::{RayBoxes, lanes_near_to_far};
use super::{EMPTY, GatheredLeaf, PACKET, WIDTH, WideBvh};
use crate::simd;

/// A pending subtree of a masked walk: the child (as in `WideNode::child`), its leaf count,
/// and the rays that entered it.
#[derive(Clone, Copy)]
struct MaskedEntry {
    child: u32,
    count: u32,
    rays: u64,
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
        self.traverse_masked_in::<false>(rays, limits, leaf)
    }

    /// [`WideBvh::traverse_masked`] taking children nearest first as the first ray of each
    /// mask sees them (closest-hit queries).
    pub fn traverse_masked_ordered(
        &self,
        rays: &[RayBoxes],
        limits: &mut [f32; PACKET],
        leaf: impl GatheredLeaf,
    ) {
        self.traverse_masked_in::<true>(rays, limits, leaf)
    }

    fn traverse_masked_in<const ORDERED: bool>(
        &self,
        rays: &[RayBoxes],
        limits: &mut [f32; PACKET],
        leaf: impl GatheredLeaf,
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
        })
    }

    #[inline(always)]
    fn walk_masked<const AVX: bool, const ORDERED: bool>(
        &self,
        stack: &mut [MaybeUninit<MaskedEntry>],
        rays: &[RayBoxes],
        limits: &mut [f32; PACKET],
        all: u64,
        leaf: &mut impl GatheredLeaf,
    ) {
        // Of the rays in `rays`, those not stopped: eight rays per step (one vector compare
        // and mask where the compiler vectorises it), skipping groups of eight with no ray
        // in `rays` (a leaf's rays are often one or two groups of the packet).
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
        let mut alive = live(limits, all);
        stack[0] = MaybeUninit::new(MaskedEntry {
            child: 0,
            count: 0,
            rays: alive,
        });
        let mut top = 1usize;
        let mut entering = [0u8; PACKET];
        while top > 0 {
            top -= 1;
            // SAFETY: entries below `top` were all written before.
            let entry = unsafe { stack[top].assume_init() };
            let mask = entry.rays & alive;
            if mask == 0 {
                continue;
            }
            match ChildRef::decode(entry.child, entry.count) {
                ChildRef::Leaf { first, count } => {
                    let mut k = 0;
                    let mut bits = mask;
                    while bits != 0 {
                        entering[k] = bits.trailing_zeros() as u8;
                        bits &= bits - 1;
                        k += 1;
                    }
                    leaf.visit::<AVX>(&entering[..k], first, count, limits);
                    // Only the rays just handed to the leaf can have stopped.
                    alive &= !mask | live(limits, mask);
                    if alive == 0 {
                        return;
                    }
                }
                ChildRef::Node(index) => {
                    let node = &self.nodes[index as usize];
                    // Per ray, the lanes it enters (zero for the rays not in the mask).
                    let mut lanes_of = [0u8; PACKET];
                    let mut bits = mask;
                    let (first_near, first_lanes) = {
                        let r = bits.trailing_zeros() as usize;
                        rays[r].enter::<AVX>(node, limits[r])
                    };
                    lanes_of[bits.trailing_zeros() as usize] = first_lanes as u8;
                    bits &= bits - 1;
                    while bits != 0 {
                        let r = bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        lanes_of[r] = rays[r].enter::<AVX>(node, limits[r]).1 as u8;
                    }
                    let entered_by = if mask.count_ones() >= TRANSPOSE_MIN_RAYS {
                        rays_by_lane(&lanes_of, mask)
                    } else {
                        rays_by_lane_one_by_one(&lanes_of, mask)
                    };
                    let mut push = |lane: usize, top: &mut usize| {
                        if entered_by[lane] != 0 && node.child[lane] != EMPTY {
                            stack[*top] = MaybeUninit::new(MaskedEntry {
                                child: node.child[lane],
                                count: node.count[lane],
                                rays: entered_by[lane],
                            });
                            *top += 1;
                        }
                    };
                    if ORDERED {
                        // Lanes the first ray misses go deepest (walked last), then its
                        // entered lanes far to near, so its nearest is walked next.
                        for lane in 0..WIDTH {
                            if first_lanes & (1 << lane) == 0 {
                                push(lane, &mut top);
                            }
                        }
                        let (order, count) = lanes_near_to_far::<true>(first_near, first_lanes);
                        for &lane in order[..count].iter().rev() {
                            push(lane, &mut top);
                        }
                    } else {
                        // Pushed last lane first, so the lowest lane is walked next.
                        for lane in (0..WIDTH).rev() {
                            push(lane, &mut top);
                        }
                    }
                }
            }
        }
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
}

impl<G: GatheredLeaf, const ORDERED: bool> simd::Kernel for MaskedWalk<'_, G, ORDERED> {
    type Output = ();

    #[inline(always)]
    fn run<const AVX2: bool>(self) {
        self.bvh.walk_masked::<AVX2, ORDERED>(
            self.stack,
            self.rays,
            self.limits,
            self.all,
            self.leaf,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::wide::test_support::xorshift;

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
