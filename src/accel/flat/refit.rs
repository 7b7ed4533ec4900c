//! Refitting the flat tree to moved triangles: the packs and leaf boxes of what moved, then
//! the inner boxes (a partial refit walks up from each moved leaf; past a share of the
//! leaves a full sweep, on all threads for large trees, is cheaper). The topology is kept;
//! whether to rebuild instead is `accel::policy`'s decision.

use rayon::prelude::*;

use obvhs::aabb::Aabb;

use super::{
    Accel, Leaf, PARALLEL_REFIT_MIN, SAH_INTERSECTION_COST, SAH_TRAVERSAL_COST, leaf_box,
    padded_box,
};
use crate::accel::triangles::{LANES, TrianglePack};
use crate::geometry::FrameTriangles;

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
    /// Refits the boxes to the moved triangles `moved_slots` (BVH order) after their
    /// positions changed in `triangles`. The tree's topology is kept.
    pub fn refit(&mut self, triangles: &FrameTriangles, moved_slots: &[u32]) -> RefitKind {
        if moved_slots.is_empty() || self.leaves.is_empty() {
            return RefitKind::None;
        }
        let kind = if moved_slots.len() as f64 > PARTIAL_REFIT_MAX_SHARE * self.leaves.len() as f64
        {
            // The full refit takes the cost on its way up.
            self.cost = self.refit_full(triangles, triangles.len() >= PARALLEL_REFIT_MIN);
            RefitKind::Full
        } else {
            self.refit_partial(triangles, moved_slots);
            self.cost = self.sah_cost();
            RefitKind::Partial
        };
        kind
    }

    /// Refits every leaf and inner box (on rayon's threads when `parallel`: each box is a
    /// pure function of its triangles, so the split changes no bit); returns the refitted
    /// tree's SAH cost ([`Accel::sah_cost`]).
    ///
    /// Leaves in slot order, each in one go: its packs copied from the positions and its
    /// box taken from the values just copied (one read of each position, not one for the
    /// packs and one for the boxes), written straight into its lane (a list of boxes then
    /// a serial pass of scattered lane writes cost as much again). Then the inner lanes,
    /// which take the SAH cost on the way (a second walk over the nodes was ~2 ms of a
    /// million triangles' refit).
    pub(in crate::accel) fn refit_full(
        &mut self,
        triangles: &FrameTriangles,
        parallel: bool,
    ) -> f32 {
        let positions = &triangles.positions;
        let chunk = if parallel {
            REFIT_CHUNK_LEAVES
        } else {
            self.leaves.len().max(1)
        };
        let cuts = self.leaves.chunks(chunk).skip(1).map(|c| c[0].first);
        let runs = self.triangles.runs_mut(cuts);
        let lanes = self.wide.leaf_lanes_writer();
        let refresh = |(leaves, packs): (&[Leaf], &mut [TrianglePack])| {
            let mut packs = packs.iter_mut();
            for leaf in leaves {
                let mut aabb = Aabb::empty();
                for pack in packs
                    .by_ref()
                    .take(leaf.count.div_ceil(LANES as u32) as usize)
                {
                    pack.refresh(positions, |tri| aabb = aabb.union(&padded_box(tri)));
                }
                // SAFETY: every leaf has its own lane (`Leaf::lane` is one-to-one), and each
                // leaf is in one chunk.
                unsafe { lanes.set_leaf_box(leaf.lane, &aabb) };
            }
        };
        if parallel {
            self.leaves.par_chunks(chunk).zip(runs).for_each(refresh);
        } else {
            self.leaves.chunks(chunk).zip(runs).for_each(refresh);
        }
        let cost = self
            .wide
            .refit_inner(SAH_TRAVERSAL_COST, SAH_INTERSECTION_COST);
        cost.unwrap_or_else(|| self.one_leaf_cost())
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
