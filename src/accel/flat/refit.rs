//! Refitting the flat tree to moved triangles (already written into its packs): the leaf
//! boxes of what moved, then the inner boxes (a partial refit walks up from each moved
//! leaf; past a share of the leaves a full sweep is cheaper, subtree by subtree on all
//! threads for large trees). The topology is kept;
//! whether to rebuild instead is `accel::policy`'s decision.

use rayon::prelude::*;

use std::borrow::Cow;
use std::ops::Range;

use super::{Accel, Leaf, PARALLEL_REFIT_MIN, SAH_INTERSECTION_COST, SAH_TRAVERSAL_COST};
use crate::accel::triangles::{PackedTriangles, SlotLanes};
use crate::accel::wide::{LeafLanes, Parts, WideBvh};

/// Leaves per parallel task of a full refit (a leaf takes ~20 ns).
const REFIT_CHUNK_LEAVES: usize = 1024;

/// Which refit ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefitKind {
    /// Nothing moved.
    None,
    /// Only the leaves of moved triangles and their ancestors.
    Partial,
    /// Every leaf and inner node.
    Full,
}

/// A partial refit walks up from each moved leaf; past this share of leaves a full sweep
/// is cheaper.
const PARTIAL_REFIT_MAX_SHARE: f64 = 0.1;

impl Accel {
    /// Refits the boxes to the moved triangles `moved_slots` (BVH order) after their new
    /// vertices were written ([`Accel::set_triangle`], [`Accel::slot_lanes`]). The tree's
    /// topology is kept.
    pub fn refit(&mut self, moved_slots: &[u32]) -> RefitKind {
        self.refit_listing(moved_slots.len(), || moved_slots.into())
    }

    /// [`Accel::refit`] for `moved` moved triangles that `list` lists (any order, each
    /// once) when a partial refit needs them; a full refit does not call it.
    pub fn refit_listing<'a>(
        &mut self,
        moved: usize,
        list: impl FnOnce() -> Cow<'a, [u32]>,
    ) -> RefitKind {
        let written = self.leaf_boxes_written.take();
        if moved == 0 || self.leaves.is_empty() {
            return RefitKind::None;
        }
        let kind = if moved as f64 > PARTIAL_REFIT_MAX_SHARE * self.leaves.len() as f64 {
            // The full refit takes the cost on its way up.
            let leaves = match written {
                Some(run) => {
                    self.set_straddling_leaf_boxes(run);
                    LeafPass::Set
                }
                None => LeafPass::FromPacks,
            };
            self.cost = self.refit_full(self.slots() >= PARALLEL_REFIT_MIN, leaves);
            RefitKind::Full
        } else {
            // A writer that set leaf boxes set them to what this recomputes; the walk up
            // from each moved leaf compares the ancestors' boxes, not the leaf's, so it
            // still goes up from a leaf whose box was set already.
            let moved_slots = list();
            debug_assert_eq!(moved_slots.len(), moved);
            self.refit_partial(&moved_slots);
            self.cost = self.sah_cost();
            RefitKind::Partial
        };
        kind
    }

    /// Refits every leaf and inner box (on rayon's threads when `parallel`: each box is a
    /// pure function of its triangles, so the split changes no bit); returns the refitted
    /// tree's SAH cost ([`Accel::sah_cost`]).
    ///
    /// Each leaf's box is taken from its packs (which the update wrote: the packs are the
    /// only copy of the positions) and written straight into its lane (a list of boxes then
    /// a serial pass of scattered lane writes cost as much again). In parallel the tree is
    /// cut into subtrees ([`RefitSplit`]), and each task sets its subtree's leaves and then
    /// refits its inner lanes while they are in its cache; the nodes above them come last.
    /// (Leaves on all threads and then every inner lane on one took 9.6 ms of a million
    /// skinned triangles' refit, 5 of them the serial inner pass; by subtrees, 7.1 ms.)
    /// Sequentially, leaves in slot order, then the inner lanes. Either way the inner pass
    /// takes the SAH cost on the way (a second walk over the nodes was ~2 ms of a million
    /// triangles' refit).
    ///
    /// With [`LeafPass::Set`] the leaf boxes are left as they are (all set already).
    pub(in crate::accel) fn refit_full(&mut self, parallel: bool, leaves: LeafPass) -> f32 {
        if leaves == LeafPass::Set {
            return self.refit_inner_only(parallel);
        }
        if let Some(split) = split_for(&self.refit_split, &self.wide, &self.leaves, parallel) {
            let (leaves, packs) = (&self.leaves, &self.triangles);
            let set_leaves = |part: Option<usize>, lanes: &LeafLanes| {
                let order = split.leaves(part);
                for (k, &index) in order.iter().enumerate() {
                    prefetch_leaf_ahead(order, k, leaves, packs, lanes);
                    let leaf = &leaves[index as usize];
                    let aabb = packs.leaf_box(leaf.first, leaf.count);
                    // SAFETY: every leaf has its own lane, and each leaf is in one part (or
                    // above them all), which one task sets.
                    unsafe { lanes.set_leaf_box(leaf.lane, &aabb) };
                }
            };
            let cost = self.wide.refit_in_parts(
                &split.parts,
                set_leaves,
                SAH_TRAVERSAL_COST,
                SAH_INTERSECTION_COST,
            );
            return cost.unwrap_or_else(|| self.one_leaf_cost());
        }
        let chunk = if parallel {
            REFIT_CHUNK_LEAVES
        } else {
            self.leaves.len().max(1)
        };
        let lanes = self.wide.leaf_lanes_writer();
        let (leaves, packs) = (&self.leaves, &self.triangles);
        let refresh = |leaves: &[Leaf]| {
            for leaf in leaves {
                let aabb = packs.leaf_box(leaf.first, leaf.count);
                // SAFETY: every leaf has its own lane (`Leaf::lane` is one-to-one), and each
                // leaf is in one chunk.
                unsafe { lanes.set_leaf_box(leaf.lane, &aabb) };
            }
        };
        if parallel {
            leaves.par_chunks(chunk).for_each(refresh);
        } else {
            leaves.chunks(chunk).for_each(refresh);
        }
        let cost = self
            .wide
            .refit_inner(SAH_TRAVERSAL_COST, SAH_INTERSECTION_COST);
        cost.unwrap_or_else(|| self.one_leaf_cost())
    }

    /// The inner boxes of a full refit whose leaf boxes are all set: in parallel, subtree
    /// by subtree as [`Accel::refit_full`] takes them, with no leaf to set.
    fn refit_inner_only(&mut self, parallel: bool) -> f32 {
        let cost = match split_for(&self.refit_split, &self.wide, &self.leaves, parallel) {
            Some(split) => self.wide.refit_in_parts(
                &split.parts,
                |_, _: &LeafLanes| {},
                SAH_TRAVERSAL_COST,
                SAH_INTERSECTION_COST,
            ),
            None => self
                .wide
                .refit_inner(SAH_TRAVERSAL_COST, SAH_INTERSECTION_COST),
        };
        cost.unwrap_or_else(|| self.one_leaf_cost())
    }

    /// Sets the box of every leaf that straddles two runs of `run` slots (the leaves a
    /// run writer could not set: their slots were written by two tasks).
    fn set_straddling_leaf_boxes(&mut self, run: u32) {
        let lanes = self.wide.leaf_lanes_writer();
        let slots = self.leaf_of_slot.len() as u32;
        for boundary in (run..slots).step_by(run as usize) {
            let leaf = &self.leaves[self.leaf_of_slot[boundary as usize] as usize];
            if leaf.first < boundary {
                let aabb = self.triangles.leaf_box(leaf.first, leaf.count);
                // SAFETY: one task (this one) sets lanes here.
                unsafe { lanes.set_leaf_box(leaf.lane, &aabb) };
            }
        }
    }

    /// Updates each moved triangle's leaf box, then the leaf's ancestors up to the first
    /// whose box comes out unchanged.
    pub(in crate::accel) fn refit_partial(&mut self, moved_slots: &[u32]) {
        for &slot in moved_slots {
            let leaf = self.leaves[self.leaf_of_slot[slot as usize] as usize];
            let aabb = self.leaf_box(&leaf);
            self.wide.refit_leaf(leaf.lane, &aabb);
        }
    }
}

/// The cut of the tree a parallel full refit works in (`cell`, made by the first such
/// refit), or `None` for a sequential refit or a tree too small to cut. A function of the
/// fields, not of the accel, so the tree can be refitted while the cut is borrowed.
fn split_for<'a>(
    cell: &'a std::sync::OnceLock<Option<RefitSplit>>,
    wide: &WideBvh,
    leaves: &[Leaf],
    parallel: bool,
) -> Option<&'a RefitSplit> {
    parallel
        .then(|| cell.get_or_init(|| RefitSplit::new(wide, leaves)).as_ref())
        .flatten()
}

/// Where a full refit's leaf boxes come from.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(in crate::accel) enum LeafPass {
    /// Each leaf's packs.
    FromPacks,
    /// Already set: a run writer set those inside its runs, the refit those between them.
    Set,
}

/// Sets leaf boxes from concurrent writers of runs of slots, each while its run's packs are
/// in its cache ([`Accel::slot_lanes_and_leaf_boxes`]).
pub struct RunLeafBoxes<'a> {
    pub(in crate::accel) leaves: &'a [Leaf],
    pub(in crate::accel) leaf_of_slot: &'a [u32],
    pub(in crate::accel) lanes: LeafLanes<'a>,
}

impl RunLeafBoxes<'_> {
    /// Sets the box of every leaf whose slots all lie in `slots`, from `packs` (the same
    /// bits a refit takes from them); a leaf that begins before `slots` or ends after it
    /// is left to the refit.
    ///
    /// # Safety
    /// No other task may write the slots in `slots`, or set the boxes of leaves inside
    /// them, at the same time; `packs` must be the lanes handed out with these boxes.
    pub unsafe fn set_inside(&self, packs: &SlotLanes, slots: Range<u32>) {
        let end = slots.end.min(self.leaf_of_slot.len() as u32);
        // A scout runs `LANE_AHEAD` leaves ahead, hinting the lines of their lanes: the
        // lanes lie in tree order, scattered over the nodes, and each store would miss.
        let mut scout = slots.start;
        for _ in 0..LANE_AHEAD {
            scout = self.hint_lane(scout, end);
        }
        let mut slot = slots.start;
        while slot < end {
            scout = self.hint_lane(scout, end);
            let leaf = &self.leaves[self.leaf_of_slot[slot as usize] as usize];
            let leaf_end = leaf.first + leaf.count;
            if leaf.first >= slots.start && leaf_end <= end {
                // SAFETY: the leaf's slots lie in `slots`, which no other task writes, and
                // its lane is set by the one task that owns them.
                unsafe {
                    self.lanes
                        .set_leaf_box(leaf.lane, &packs.leaf_box(leaf.first, leaf.count))
                };
            }
            slot = leaf_end;
        }
    }

    /// Hints the lines of the lane of the leaf at `slot` (before `end`); returns the slot
    /// after that leaf.
    #[inline(always)]
    fn hint_lane(&self, slot: u32, end: u32) -> u32 {
        if slot >= end {
            return slot;
        }
        let leaf = &self.leaves[self.leaf_of_slot[slot as usize] as usize];
        self.lanes.prefetch_leaf_lane(leaf.lane);
        leaf.first + leaf.count
    }
}

/// How many leaves ahead [`RunLeafBoxes::set_inside`] hints lanes.
const LANE_AHEAD: usize = 16;

/// How many leaves apart the parallel refit's hints go (see [`prefetch_leaf_ahead`]).
const LEAF_AHEAD: usize = 16;

/// Hints what the leaf pass of a part will read and write for the leaves further down its
/// list `order` (from `k`): a part's leaves lie in subtree order, so each of its dependent
/// accesses (the leaf, where its first pack is, the pack; the leaf's lane) would miss. Each
/// is hinted one step after the read it depends on was hinted, [`LEAF_AHEAD`] leaves apart.
#[inline(always)]
fn prefetch_leaf_ahead(
    order: &[u32],
    k: usize,
    leaves: &[Leaf],
    packs: &PackedTriangles,
    lanes: &LeafLanes,
) {
    if let Some(&far) = order.get(k + 3 * LEAF_AHEAD) {
        crate::simd::prefetch(leaves, far as usize);
    }
    if let Some(&mid) = order.get(k + 2 * LEAF_AHEAD) {
        let leaf = &leaves[mid as usize];
        packs.prefetch_pack_index(leaf.first);
        lanes.prefetch_leaf_lane(leaf.lane);
    }
    if let Some(&near) = order.get(k + LEAF_AHEAD) {
        packs.prefetch_slot_pack(leaves[near as usize].first);
    }
}

/// Parts of the wide tree for its parallel full refit (a part's nodes are refitted by one
/// task, leaves first, while they are in its cache), and each part's leaves.
pub(in crate::accel) struct RefitSplit {
    parts: Parts,
    /// Every leaf's index in `Accel::leaves`, grouped by the part whose nodes hold it, those
    /// above the parts last (a subtree's leaves are not one run of slot order: obvhs lays
    /// its leaves' primitive ranges out in the order it made them, not depth first).
    by_part: Vec<u32>,
    /// Per part, then for the nodes above the parts: its run of `by_part`.
    leaf_ranges: Vec<Range<usize>>,
}

/// Most nodes per part: a sixty-fourth of the tree (enough parts to balance a few dozen
/// threads), at least this many.
const PART_MIN_NODES: usize = 64;

impl RefitSplit {
    fn new(wide: &WideBvh, leaves: &[Leaf]) -> Option<RefitSplit> {
        let parts = wide.parts((wide.node_count() / 64).max(PART_MIN_NODES))?;
        // The leaves grouped by part (a counting sort; in slot order within each part),
        // those above the parts last: group `parts.len()`. Group g's count goes to
        // `starts[g + 2]`, its cursor is `starts[g + 1]`, and its run ends up
        // `starts[g]..starts[g + 1]`.
        let part_of = |leaf: &Leaf| parts.part_of_lane(leaf.lane).unwrap_or(parts.len());
        let mut starts = vec![0usize; parts.len() + 3];
        for leaf in leaves {
            starts[part_of(leaf) + 2] += 1;
        }
        for p in 2..starts.len() {
            starts[p] += starts[p - 1];
        }
        let mut by_part = vec![0u32; leaves.len()];
        for (i, leaf) in leaves.iter().enumerate() {
            let at = &mut starts[part_of(leaf) + 1];
            by_part[*at] = i as u32;
            *at += 1;
        }
        Some(RefitSplit {
            leaf_ranges: (0..=parts.len())
                .map(|p| starts[p]..starts[p + 1])
                .collect(),
            parts,
            by_part,
        })
    }

    /// How many parts the tree is cut into.
    #[cfg(test)]
    pub(in crate::accel) fn part_count(&self) -> usize {
        self.parts.len()
    }

    /// The leaves of part `p` (`None`: of the nodes above the parts), as indices into
    /// `Accel::leaves`.
    pub(in crate::accel) fn leaves(&self, part: Option<usize>) -> &[u32] {
        let range = self.leaf_ranges[part.unwrap_or(self.parts.len())].clone();
        &self.by_part[range]
    }
}
