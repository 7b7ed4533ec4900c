//! Refitting the flat tree to moved triangles: the packs and leaf boxes of what moved, then
//! the inner boxes (a partial refit walks up from each moved leaf; past a share of the
//! leaves a full sweep, on all threads for large trees, is cheaper). The topology is kept;
//! whether to rebuild instead is `accel::policy`'s decision.

use rayon::prelude::*;

use super::{Accel, Leaf, PARALLEL_REFIT_MIN, leaf_box};
use crate::geometry::FrameTriangles;

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
    /// Refits the boxes to the moved triangles `moved_slots` (BVH order) after their
    /// positions changed in `triangles`. The tree's topology is kept.
    pub fn refit(&mut self, triangles: &FrameTriangles, moved_slots: &[u32]) -> RefitKind {
        if moved_slots.is_empty() || self.leaves.is_empty() {
            return RefitKind::None;
        }
        let kind = if moved_slots.len() as f64 > PARTIAL_REFIT_MAX_SHARE * self.leaves.len() as f64
        {
            self.refit_full(triangles, triangles.len() >= PARALLEL_REFIT_MIN);
            RefitKind::Full
        } else {
            self.refit_partial(triangles, moved_slots);
            RefitKind::Partial
        };
        self.cost = self.sah_cost();
        kind
    }

    /// Refits every leaf and inner box (on rayon's threads when `parallel`: each box is a
    /// pure function of its triangles, so the split changes no bit).
    pub(in crate::accel) fn refit_full(&mut self, triangles: &FrameTriangles, parallel: bool) {
        let positions = &triangles.positions;
        self.triangles.update_all(positions, parallel);
        // Leaves in slot order (their triangles read in order), each box written straight
        // into its lane: a list of boxes then a serial pass of scattered lane writes cost
        // as much again.
        let box_of = |leaf: &Leaf| (leaf.lane, leaf_box(positions, leaf.first, leaf.count));
        if parallel {
            let lanes = self.wide.leaf_lanes_writer();
            self.leaves.par_iter().with_min_len(512).for_each(|leaf| {
                let (lane, aabb) = box_of(leaf);
                // SAFETY: every leaf has its own lane (`Leaf::lane` is one-to-one).
                unsafe { lanes.set_leaf_box(lane, &aabb) };
            });
        } else {
            for leaf in &self.leaves {
                let (lane, aabb) = box_of(leaf);
                self.wide.set_leaf_box(lane, &aabb);
            }
        }
        self.wide.refit_inner();
    }

    /// Updates each moved triangle's pack lane and leaf box, then the leaf's ancestors up to
    /// the first whose box comes out unchanged.
    pub(in crate::accel) fn refit_partial(
        &mut self,
        triangles: &FrameTriangles,
        moved_slots: &[u32],
    ) {
        for &slot in moved_slots {
            let positions = &triangles.positions;
            self.triangles.update(slot, &positions[slot as usize]);
            let leaf = self.leaves[self.leaf_of_slot[slot as usize] as usize];
            let aabb = leaf_box(positions, leaf.first, leaf.count);
            self.wide.refit_leaf(leaf.lane, &aabb);
        }
    }
}
