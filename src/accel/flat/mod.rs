//! The flat tree: one 8-wide tree over the frame's world-space triangles ([`Accel`]).
//!
//! Built without spatial splits so it can be refitted later, by obvhs's PLOC builder (in
//! chunks past 131,072 triangles, which bounds the builder's memory: [`binary`]). After a build the triangle
//! arrays are permuted into BVH order (`FrameTriangles::permute`), so a leaf's primitive
//! range indexes the triangle arrays directly: no indirection on the hot path. The hit test
//! reads the triangles from their own copy laid out four to a pack in slot order
//! (`accel::triangles`, watertight), refreshed with the boxes ([`refit`]).
//! Leaf boxes are padded (see [`padded_box`]) because a flat triangle's box has zero
//! thickness and an axis-aligned ray can slip through it by rounding.

use glam::Vec3A;
use obvhs::aabb::Aabb;

use super::triangles::{PackedTriangles, SlotLanes};
use super::wide::WideBvh;
use crate::geometry::FrameTriangles;

/// Past this many triangles the edge and leaf-box refresh of a full refit runs on rayon's
/// threads (below it the fork costs more than the work).
pub(in crate::accel) const PARALLEL_REFIT_MIN: usize = 16_384;

/// A BVH over one frame's triangles.
#[derive(Default)]
pub struct Accel {
    /// The tree rays walk and refits update.
    pub(in crate::accel) wide: WideBvh,
    /// The triangles as the hit test reads them.
    pub(in crate::accel) triangles: PackedTriangles,
    /// Per leaf, in slot order: its first slot, triangle count and lane in the wide tree.
    /// Refits walk leaves (and packs) in this order, so they stream through the triangles.
    pub(in crate::accel) leaves: Vec<Leaf>,
    /// Per slot, its leaf's index in `leaves`.
    pub(in crate::accel) leaf_of_slot: Vec<u32>,
    /// SAH cost right after the last build (see [`Accel::sah_cost`]).
    pub(in crate::accel) build_cost: f32,
    /// `sah_cost()` of the tree as it is, kept from the last build or refit: the cost is a
    /// walk over every node, which a frame that moved nothing (a static scene) must not pay,
    /// and which the refit's time should include.
    pub(in crate::accel) cost: f32,
    /// The cut of the tree the parallel full refit works in, made by the first such refit.
    pub(in crate::accel) refit_split: std::sync::OnceLock<Option<refit::RefitSplit>>,
    /// `Some(run)`: the packs were last written through [`Accel::slot_lanes_and_leaf_boxes`],
    /// whose writer set the box of every leaf that lies inside one run of `run` slots
    /// (`k * run..(k + 1) * run`) after writing its slots, so the next full refit sets only
    /// the leaves that straddle two runs. Any other access that writes the packs clears it,
    /// and the next refit (or the decision not to refit) takes it.
    pub(in crate::accel) leaf_boxes_written: Option<u32>,
}

/// A leaf of the tree: its triangle slots and where the wide tree keeps its box.
#[derive(Clone, Copy)]
pub(in crate::accel) struct Leaf {
    pub(in crate::accel) first: u32,
    pub(in crate::accel) count: u32,
    pub(in crate::accel) lane: u32,
}

/// Relative costs of the surface-area heuristic: one node visit vs one triangle test.
pub(in crate::accel) const SAH_TRAVERSAL_COST: f32 = 1.0;

pub(in crate::accel) const SAH_INTERSECTION_COST: f32 = 1.0;

/// Errors that stop a BVH build.
#[derive(Debug, thiserror::Error)]
pub enum AccelError {
    #[error("triangle {triangle} has a non-finite vertex ({vertex:?})")]
    NonFiniteVertex { triangle: usize, vertex: [f32; 3] },
}

impl Accel {
    /// Builds a BVH over `triangles` (in any order) and permutes them into BVH order. The
    /// positions move into the tree's packs ([`Accel::triangle`] reads them back), leaving
    /// `triangles.positions` empty.
    ///
    /// # Errors
    /// A non-finite vertex (obvhs would panic on it); `triangles` is then left as it was.
    pub fn build(triangles: &mut FrameTriangles) -> Result<Accel, AccelError> {
        Accel::build_in_chunks(triangles, binary::CHUNK_TRIANGLES)
    }

    /// [`Accel::build`] with obvhs's builder taking at most `chunk` triangles at once.
    pub(in crate::accel) fn build_in_chunks(
        triangles: &mut FrameTriangles,
        chunk: usize,
    ) -> Result<Accel, AccelError> {
        check_finite(&triangles.positions, &triangles.source)?;
        let positions = std::mem::take(&mut triangles.positions);
        let (accel, order) = Accel::build_ordered(positions, &triangles.source, chunk);
        triangles.permute(&order);
        Ok(accel)
    }

    /// Builds a BVH over `positions` (triangle `i` named `source[i]` in hits); returns it
    /// with the slot order (slot `s` holds input triangle `order[s]`), which the caller
    /// applies to its own per-triangle arrays. The positions are freed once packed: a caller
    /// that writes its other per-slot arrays only afterwards never holds them beside the
    /// packs (the first frame's build does, see `frame/update.rs`).
    ///
    /// # Errors
    /// A non-finite vertex.
    pub fn build_from_positions(
        positions: Vec<[Vec3A; 3]>,
        source: &[u32],
    ) -> Result<(Accel, Vec<u32>), AccelError> {
        check_finite(&positions, source)?;
        Ok(Accel::build_ordered(
            positions,
            source,
            binary::CHUNK_TRIANGLES,
        ))
    }

    /// The build of checked positions.
    fn build_ordered(
        positions: Vec<[Vec3A; 3]>,
        source: &[u32],
        chunk: usize,
    ) -> (Accel, Vec<u32>) {
        if positions.is_empty() {
            return (Accel::default(), Vec::new());
        }
        // The builder reads each primitive's box once: computed on the fly from the
        // positions, not held in a second array (32 bytes per triangle at the build's peak).
        let mut bvh = binary::binary_tree(&positions, chunk);
        let order = std::mem::take(&mut bvh.primitive_indices);
        let mut leaves = Vec::new();
        let mut wide = WideBvh::collapse(&bvh, |first, count| {
            leaves.push(Leaf {
                first,
                count,
                lane: 0,
            });
            first
        });
        for (leaf, &lane) in leaves.iter_mut().zip(wide.leaf_lanes()) {
            leaf.lane = lane;
        }
        // The binary tree is not needed past here: freed before the packs are allocated
        // (48 bytes per node would otherwise sit under them at the build's peak).
        drop(bvh);
        // Packs and leaves in slot order; each leaf then refers to its first pack.
        leaves.sort_unstable_by_key(|l| l.first);
        leaves.shrink_to_fit();
        let mut packed =
            PackedTriangles::with_pack_capacity(leaves.iter().map(|l| l.count), positions.len());
        let mut leaf_of_slot = vec![0; positions.len()];
        for (i, leaf) in leaves.iter().enumerate() {
            let (first, count) = (leaf.first as usize, leaf.count as usize);
            leaf_of_slot[first..first + count].fill(i as u32);
            let first_pack = packed.push_leaf(
                |slot| {
                    let input = order[slot as usize] as usize;
                    (positions[input], source[input])
                },
                leaf.first,
                leaf.count,
            );
            wide.set_leaf_ref(leaf.lane, first_pack);
        }
        drop(positions);
        let mut accel = Accel {
            wide,
            triangles: packed,
            leaves,
            leaf_of_slot,
            build_cost: 0.0,
            cost: 0.0,
            refit_split: Default::default(),
            leaf_boxes_written: None,
        };
        accel.build_cost = accel.sah_cost();
        accel.cost = accel.build_cost;
        (accel, order)
    }

    /// The triangle in slot `slot` (world space for the frame's tree, object space for a
    /// shared mesh's): the bits last built or written.
    #[inline]
    pub fn triangle(&self, slot: u32) -> [Vec3A; 3] {
        self.triangles.triangle(slot)
    }

    /// [`Accel::triangle`] and the source triangle the tree was built with for slot `slot`
    /// (read from the hit-test pack, whose lines a hit's walk has just read).
    #[inline]
    pub fn triangle_and_source(&self, slot: u32) -> ([Vec3A; 3], u32) {
        self.triangles.triangle_and_source(slot)
    }

    /// `lod::cross_squared` of the triangles of slot `slot`'s hit-test pack, four lanes at
    /// once, with the slots its live lanes hold (lane `i` holds slot `slots.start + i`; the
    /// lanes past them are padding).
    #[inline(always)]
    pub fn pack_cross_squared(&self, slot: u32) -> (std::ops::Range<u32>, [f64; 4]) {
        self.triangles.pack_cross_squared(slot)
    }

    /// Every slot's triangle, in slot order (a copy: for exports, rebuilds and tests).
    pub fn triangles_in_slot_order(&self) -> Vec<[Vec3A; 3]> {
        self.triangles.triangles_in_slot_order()
    }

    /// Writes a moved triangle into slot `slot`; [`Accel::refit`] then takes the boxes.
    pub fn set_triangle(&mut self, slot: u32, tri: &[Vec3A; 3]) {
        self.leaf_boxes_written = None;
        self.triangles.set_triangle(slot, tri);
    }

    /// Slot access for concurrent writers of moved triangles ([`SlotLanes`]).
    pub fn slot_lanes(&mut self) -> SlotLanes<'_> {
        self.leaf_boxes_written = None;
        self.triangles.slot_lanes()
    }

    /// [`Accel::slot_lanes`] for a writer that goes through the slots in runs of `run`
    /// slots (`k * run..(k + 1) * run`, one task per run) and, after writing a run, sets
    /// the boxes of the leaves inside it ([`RunLeafBoxes::set_inside`]) while its packs are
    /// in cache: the next full refit then reads the packs only of the leaves that straddle
    /// two runs, instead of all of them again.
    ///
    /// The caller must call [`RunLeafBoxes::set_inside`] for every run it writes, and the
    /// packs of runs it does not write must not have changed since the last refit; the
    /// tree's inner boxes stay stale until the next refit, as after any write.
    pub fn slot_lanes_and_leaf_boxes(&mut self, run: u32) -> (SlotLanes<'_>, RunLeafBoxes<'_>) {
        assert!(run > 0, "runs of no slots");
        self.leaf_boxes_written = Some(run);
        let boxes = RunLeafBoxes {
            leaves: &self.leaves,
            leaf_of_slot: &self.leaf_of_slot,
            lanes: self.wide.leaf_lanes_writer(),
        };
        (self.triangles.slot_lanes(), boxes)
    }

    /// Hints the cache to load slot `slot`'s triangle (no effect when out of range).
    #[inline]
    pub fn prefetch_slot(&self, slot: u32) {
        self.triangles.prefetch_slot(slot);
    }

    /// How many triangle slots the tree holds.
    pub fn slots(&self) -> usize {
        self.triangles.slots()
    }

    /// Surface-area-heuristic cost of the tree, relative to its root box: the expected cost
    /// of a ray through the root. Compared with its value right after the build to decide
    /// when refitting has degraded the tree enough to rebuild it.
    pub fn sah_cost(&self) -> f32 {
        self.wide
            .sah_cost(SAH_TRAVERSAL_COST, SAH_INTERSECTION_COST)
            .unwrap_or_else(|| self.one_leaf_cost())
    }

    /// The SAH cost of a tree of one leaf (or nothing): every ray tests every triangle.
    pub(in crate::accel) fn one_leaf_cost(&self) -> f32 {
        self.leaves
            .first()
            .map_or(0.0, |l| l.count as f32 * SAH_INTERSECTION_COST)
    }

    /// The box of every triangle in the tree (`None` when empty).
    pub fn bounds(&self) -> Option<Aabb> {
        if self.leaves.is_empty() {
            return None;
        }
        Some(self.wide.root_box().unwrap_or_else(|| {
            self.leaves
                .iter()
                .fold(Aabb::empty(), |a, l| a.union(&self.leaf_box(l)))
        }))
    }

    /// The union of the padded boxes of a leaf's triangles, read from its packs.
    pub(in crate::accel) fn leaf_box(&self, leaf: &Leaf) -> Aabb {
        self.triangles.leaf_box(leaf.first, leaf.count)
    }

    /// `sah_cost() / cost right after the last build` (1 for an empty tree), as of the last
    /// build or refit.
    pub fn sah_ratio(&self) -> f32 {
        if self.build_cost > 0.0 {
            self.cost / self.build_cost
        } else {
            1.0
        }
    }
}

/// The first non-finite vertex of `positions`, as an error naming its source triangle.
pub(in crate::accel) fn check_finite(
    positions: &[[Vec3A; 3]],
    source: &[u32],
) -> Result<(), AccelError> {
    for (i, tri) in positions.iter().enumerate() {
        if let Some(v) = tri.iter().find(|v| !v.is_finite()) {
            return Err(AccelError::NonFiniteVertex {
                triangle: source[i] as usize,
                vertex: v.to_array(),
            });
        }
    }
    Ok(())
}

/// A triangle's box grown by a few ulps of its own magnitude on every axis, so that a flat
/// box still has volume and slab tests cannot miss it by rounding.
///
/// `TrianglePack::live_box` computes the same boxes four triangles at once: a change here
/// is a change there (a test holds the two to the same bits).
pub fn padded_box(tri: &[Vec3A; 3]) -> Aabb {
    let min = tri[0].min(tri[1]).min(tri[2]);
    let max = tri[0].max(tri[1]).max(tri[2]);
    let magnitude = min.abs().max(max.abs()).max_element();
    let pad = Vec3A::splat(magnitude * 2f32.powi(-20) + f32::MIN_POSITIVE * 8.0);
    Aabb::new(min - pad, max + pad)
}

/// A triangle as the BVH builder's primitive: its box is [`padded_box`].
#[repr(transparent)]
struct PaddedTriangle([Vec3A; 3]);

// SAFETY: `PaddedTriangle` is `repr(transparent)` over `[Vec3A; 3]`, its only field, so a
// slice of one is a slice of the other (what `TransparentWrapper` requires).
unsafe impl bytemuck::TransparentWrapper<[Vec3A; 3]> for PaddedTriangle {}

impl obvhs::Boundable for PaddedTriangle {
    #[inline]
    fn aabb(&self) -> Aabb {
        padded_box(&self.0)
    }
}

mod binary;
mod hits;
mod refit;
#[cfg(test)]
pub(crate) mod tests;

pub use binary::CHUNK_TRIANGLES as BUILD_CHUNK_TRIANGLES;
pub use refit::{RefitKind, RunLeafBoxes};
