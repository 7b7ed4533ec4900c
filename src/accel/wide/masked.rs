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

// Ray masks are one bit per ray.
const _: () = assert!(PACKET <= 64);

impl WideBvh {
    /// Walks the tree once for the rays `rays` (at most [`PACKET`]), ray `r` with limit
    /// `limits[r]`: each leaf is handed, once, the rays that entered it (in ray order) as
    /// `leaf.visit(rays, leaf_ref, count, limits)`. A leaf stops a ray by setting its limit
    /// below 0; stopped rays enter nothing more, and the walk returns when all have stopped.
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
            let entering: Vec<u8> = (0..n as u8).collect();
            leaf.visit::<false>(&entering, first, count, limits);
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
        let live = |limits: &[f32; PACKET]| {
            (0..rays.len()).fold(0u64, |m, r| m | (u64::from(limits[r] >= 0.0) << r))
        };
        let mut alive = all & live(limits);
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
                    alive &= live(limits);
                    if alive == 0 {
                        return;
                    }
                }
                ChildRef::Node(index) => {
                    let node = &self.nodes[index as usize];
                    let mut entered_by = [0u64; WIDTH];
                    let mut bits = mask;
                    let (first_near, first_lanes) = {
                        let r = bits.trailing_zeros() as usize;
                        rays[r].enter::<AVX>(node, limits[r])
                    };
                    let mut lanes_of = first_lanes;
                    loop {
                        let r = bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        while lanes_of != 0 {
                            let lane = lanes_of.trailing_zeros() as usize;
                            lanes_of &= lanes_of - 1;
                            entered_by[lane] |= 1 << r;
                        }
                        if bits == 0 {
                            break;
                        }
                        let next = bits.trailing_zeros() as usize;
                        lanes_of = rays[next].enter::<AVX>(node, limits[next]).1;
                    }
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
