//! Refitting the flat tree to moved triangles (already written into its packs): the leaf
//! boxes of what moved, then the inner boxes (a partial refit walks up from each moved
//! leaf; past a share of the leaves a full sweep, on all threads for large trees, is
//! cheaper). The topology is kept;
//! whether to rebuild instead is `accel::policy`'s decision.

use rayon::prelude::*;

use super::{Accel, Leaf, PARALLEL_REFIT_MIN, SAH_INTERSECTION_COST, SAH_TRAVERSAL_COST};

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
        if moved_slots.is_empty() || self.leaves.is_empty() {
            return RefitKind::None;
        }
        let kind = if moved_slots.len() as f64 > PARTIAL_REFIT_MAX_SHARE * self.leaves.len() as f64
        {
            // The full refit takes the cost on its way up.
            self.cost = self.refit_full(self.slots() >= PARALLEL_REFIT_MIN);
            RefitKind::Full
        } else {
            self.refit_partial(moved_slots);
            self.cost = self.sah_cost();
            RefitKind::Partial
        };
        kind
    }

    /// Refits every leaf and inner box (on rayon's threads when `parallel`: each box is a
    /// pure function of its triangles, so the split changes no bit); returns the refitted
    /// tree's SAH cost ([`Accel::sah_cost`]).
    ///
    /// Leaves in slot order, each box taken from its packs (which the update wrote: the
    /// packs are the only copy of the positions) and written straight into its lane (a list
    /// of boxes then a serial pass of scattered lane writes cost as much again). Then the
    /// inner lanes, which take the SAH cost on the way (a second walk over the nodes was
    /// ~2 ms of a million triangles' refit).
    pub(in crate::accel) fn refit_full(&mut self, parallel: bool) -> f32 {
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
