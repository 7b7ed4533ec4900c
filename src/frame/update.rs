//! The per-frame update of the scene's triangles and tree: place or deform what moved,
//! mark it in the dirty set as rigid, scaled or deformed, and refit or rebuild the BVH.
//! Only what changed is touched; `tests/frame_loop.rs` checks every changed-only path
//! against a fresh build.
//!
//! Three steps, each split across rayon's threads when its work is large enough to pay
//! ([`UpdateParallelism`]): pose the vertices of the instances that moved (skinned or morphed
//! then placed, or rest vertices placed; each instance into its own world-space buffers),
//! write their triangles into the BVH slots in source order (`scatter`; recording each
//! triangle's motion), then list the marked slots in the dirty set in source-triangle order. Every written value is a
//! pure function of the pose and its triangle, and the dirty order is fixed by source order,
//! so the parallel update is bit-identical to the sequential one, dirty order included.
//! Timing: classifying instances and listing the dirty set count as `dirty_ms`; posing and
//! writing (including the per-triangle "did its vertices change" test, fused with the write)
//! as `animate_ms`.

use std::ops::Range;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use rayon::prelude::*;

use super::posed::{
    PosedVertices, Rewrite, TriangleWriter, VertexSource, WRITE_CHUNK, same_deformation,
    write_all_triangles,
};
use super::scatter::SlotScatter;
use super::two_level::Which;
use super::{InstanceState, Motion, Renderer, ms_since};
use crate::accel::{Accel, AccelError, BvhLayout, TreeStep};
use crate::anim::NodeShape;
use crate::record::UpdateStats;

/// Below this much work (triangles or vertices) an update step stays on the calling thread:
/// rayon's split and join cost more than the work (tens of ns per item).
const PARALLEL_MIN_ITEMS: usize = 8192;

/// How many source triangles ahead the scattered write prefetches its slot.
const PREFETCH_AHEAD: usize = 16;

/// Whether the frame update splits its steps across rayon's threads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpdateParallelism {
    /// Each step splits past 8,192 items of work (the default).
    #[default]
    Auto,
    /// Every step on the calling thread: the reference the parallel update is tested against.
    Sequential,
    /// Every step split however small its work: drives the parallel path on small scenes.
    Parallel,
}

impl UpdateParallelism {
    /// Whether a step with `items` of work splits.
    pub(super) fn splits(self, items: usize) -> bool {
        match self {
            UpdateParallelism::Auto => items >= PARALLEL_MIN_ITEMS,
            UpdateParallelism::Sequential => false,
            UpdateParallelism::Parallel => true,
        }
    }
}

/// The update's reused per-frame buffers.
#[derive(Debug, Default)]
pub struct UpdateScratch {
    /// Every instance's vertices and placement this frame.
    pub posed: PosedVertices,
    /// Per instance: what this frame does to its triangles.
    pub plan: Vec<Rewrite>,
    /// Per source triangle: the motion the write gave it. All `None` between frames (the
    /// dirty listing takes them).
    source_motion: Vec<Option<Motion>>,
    /// Whether this frame's write gave a moved triangle a non-finite vertex.
    moved_nonfinite: bool,
    /// Per instance: whether the placement its slots' uvs were last written under mirrored
    /// (`None`: never written). Uvs change only with that, so a write under the same winding
    /// skips them (a fifth of the bytes a moved triangle writes).
    uv_flips: Vec<Option<bool>>,
    /// Per visited instance: how many dirty entries it gave (scratch of the listing).
    listed: Vec<usize>,
    /// The runs of the dirty list (entry indices, increasing) whose slots belong to deforming
    /// instances: the `log2 P_b` update walks those slots in slot order instead.
    pub(super) deformed_entries: Vec<Range<usize>>,
    /// The runs of placed instances that scaled or changed shape: the entries the `log2
    /// P_b` update visits one by one (rigid runs keep their constants and are skipped whole).
    pub(super) reshaped_entries: Vec<Range<usize>>,
}

impl Renderer {
    /// First frame: every triangle placed, the tree built, every `log2 P_b` computed.
    pub(super) fn first_frame(
        &mut self,
        scales: &[Option<NodeShape>],
        stats: &mut UpdateStats,
    ) -> Result<(), AccelError> {
        let t = Instant::now();
        if self.settings.layout == BvhLayout::TwoLevel {
            self.build_two_level()?;
        }
        let build_ms = ms_since(t);
        let t = Instant::now();
        // Under the two-level BVH only what is not an instance of a shared mesh.
        let two_level = self.two_level.as_ref();
        write_all_triangles(
            &self.scene,
            &self.geometry,
            &self.pose,
            &self.deforms,
            &mut self.update.posed,
            &mut self.update.plan,
            self.parallelism.splits(self.geometry.triangle_count()),
            |i| two_level.is_none_or(|two| two.mesh_of[i].is_none()),
            &mut self.triangles,
        );
        let UpdateScratch {
            posed,
            plan,
            uv_flips,
            ..
        } = &mut self.update;
        uv_flips.clear();
        uv_flips.extend(
            plan.iter()
                .enumerate()
                .map(|(i, r)| (*r != Rewrite::Keep).then(|| posed.placement(i).flips_winding)),
        );
        let states = self.instance_states(scales);
        stats.animate_ms = ms_since(t);

        let t = Instant::now();
        self.accel = Accel::build(&mut self.triangles)?;
        self.index_slots();
        self.place_instances(&states, Which::All)?;
        stats.build_ms = build_ms + ms_since(t);
        stats.rebuild = true;

        let t = Instant::now();
        self.dirty.reset(self.triangles.len());
        if self.settings.lod.needs_log2_pb() {
            stats.lod_recomputed = self.recompute_all_log2_pb(&states) + self.placed_textured();
        }
        stats.lod_update_ms = ms_since(t);
        self.instances = Some(states);
        Ok(())
    }

    /// Each instance's placement now; a deforming instance has no shape key (its `log2 P_b`
    /// always comes from its world vertices).
    fn instance_states(&self, scales: &[Option<NodeShape>]) -> Vec<InstanceState> {
        self.geometry
            .instances
            .iter()
            .zip(&self.deforms)
            .map(|(inst, &source)| InstanceState {
                world_from_object: self.pose.world_from_node[inst.node as usize],
                shape: match source {
                    VertexSource::Deformed => None,
                    VertexSource::Placed => scales[inst.node as usize],
                },
            })
            .collect()
    }

    /// Inverts `triangles.source` (sources without a slot, instances of shared meshes
    /// under the two-level BVH, map to `u32::MAX`) and remakes the per-slot texel areas.
    fn index_slots(&mut self) {
        self.slot_of_source.clear();
        self.slot_of_source
            .resize(self.geometry.triangle_count(), u32::MAX);
        for (slot, &source) in self.triangles.source.iter().enumerate() {
            self.slot_of_source[source as usize] = slot as u32;
        }
        self.index_texel_terms();
    }

    /// Rewrites the triangles of every instance whose placement or deformation changed and
    /// records them in the dirty set.
    pub(super) fn update_moved(&mut self, scales: &[Option<NodeShape>], stats: &mut UpdateStats) {
        let t = Instant::now();
        self.dirty.reset(self.triangles.len());
        let previous = self.instances.take().unwrap_or_default();
        let current = self.instance_states(scales);
        self.placed_changes = self.placed_changes(&current, &previous);
        let visited = self.plan_rewrites(&current, &previous);
        self.instances = Some(current);
        stats.dirty_ms = ms_since(t);

        let t = Instant::now();
        self.pose_planned();
        self.write_planned(visited);
        stats.animate_ms = ms_since(t);

        let t = Instant::now();
        self.list_dirty(visited);
        stats.dirty_ms += ms_since(t);
    }

    /// Decides each instance's [`Rewrite`] from its placement now and before (and records
    /// the placement of those to rewrite); returns how many triangles the write visits.
    fn plan_rewrites(&mut self, current: &[InstanceState], previous: &[InstanceState]) -> usize {
        let UpdateScratch { posed, plan, .. } = &mut self.update;
        posed.resize(current.len());
        plan.clear();
        let mut visited = 0;
        let instanced = |i: usize| {
            self.two_level
                .as_ref()
                .is_some_and(|two| two.mesh_of[i].is_some())
        };
        for (i, (now, before)) in current.iter().zip(previous).enumerate() {
            let rewrite = if self.deforms[i] == VertexSource::Deformed {
                let same = same_deformation(
                    &self.scene,
                    &self.geometry,
                    i,
                    &self.pose,
                    &self.previous_pose,
                );
                if same {
                    Rewrite::Keep
                } else {
                    Rewrite::Changed
                }
            } else if instanced(i) || now.world_from_object == before.world_from_object {
                // Static, or an instance of a shared mesh under the two-level BVH: only its
                // transform changes (`place_instances`).
                Rewrite::Keep
            } else {
                posed.place(i, now.world_from_object);
                Rewrite::All(placed_motion(now.shape, before.shape))
            };
            if rewrite != Rewrite::Keep {
                visited += self.geometry.instance_triangles[i].len();
            }
            plan.push(rewrite);
        }
        visited
    }

    /// Writes the world-space vertices of the planned instances (skinned or morphed, then
    /// placed; or rest vertices placed), on rayon's threads when there are enough of them.
    fn pose_planned(&mut self) {
        let UpdateScratch { posed, plan, .. } = &mut self.update;
        let planned = |i: usize| plan[i] != Rewrite::Keep;
        let vertices: usize = (0..plan.len())
            .filter(|&i| planned(i))
            .map(|i| self.geometry.primitive(&self.scene, i).positions.len())
            .sum();
        posed.pose(
            &self.scene,
            &self.geometry,
            &self.pose,
            &self.deforms,
            planned,
            self.parallelism.splits(vertices),
        );
    }

    /// Writes the triangles of the planned instances into their slots and records each
    /// written triangle's motion in `source_motion`. Triangles are visited in source order (reads
    /// stay sequential); in parallel, instances and chunks of their triangles run as
    /// separate tasks, writing distinct slots (`scatter`).
    fn write_planned(&mut self, visited: usize) {
        let UpdateScratch {
            posed,
            plan,
            source_motion,
            moved_nonfinite,
            uv_flips,
            ..
        } = &mut self.update;
        source_motion.resize(self.geometry.triangle_count(), None);
        let writer = TriangleWriter {
            geometry: &self.geometry,
            posed,
            plan,
            uv_flips,
            moved_nonfinite: AtomicBool::new(false),
        };
        let ranges = &self.geometry.instance_triangles;
        let slot_of_source = &self.slot_of_source;
        if self.parallelism.splits(visited) {
            let slots = SlotScatter::new(&mut self.triangles, source_motion);
            plan.par_iter()
                .enumerate()
                .filter(|(_, r)| **r != Rewrite::Keep)
                .for_each(|(i, _)| {
                    ranges[i]
                        .clone()
                        .into_par_iter()
                        .with_min_len(WRITE_CHUNK)
                        .for_each(|source| {
                            if let Some(&ahead) =
                                slot_of_source.get(source as usize + PREFETCH_AHEAD)
                            {
                                slots.prefetch(ahead);
                            }
                            let slot = slot_of_source[source as usize];
                            // SAFETY: each source triangle is visited once and
                            // `slot_of_source` is one-to-one on the written sources (see
                            // `scatter`): one task per slot.
                            unsafe {
                                slots.with_slot(slot, source, |p, n, uv| {
                                    writer.write(source, p, n, uv)
                                })
                            };
                        });
                });
        } else {
            let triangles = &mut self.triangles;
            let visited_instances = plan
                .iter()
                .enumerate()
                .filter(|(_, r)| **r != Rewrite::Keep);
            for (i, _) in visited_instances {
                for source in ranges[i].clone() {
                    let s = slot_of_source[source as usize] as usize;
                    source_motion[source as usize] = writer.write(
                        source,
                        &mut triangles.positions[s],
                        &mut triangles.normals[s],
                        &mut triangles.uvs[s],
                    );
                }
            }
        }
        *moved_nonfinite = writer.moved_nonfinite.into_inner();
        for (i, rewrite) in plan.iter().enumerate() {
            if *rewrite != Rewrite::Keep {
                uv_flips[i] = Some(posed.placement(i).flips_winding);
            }
        }
    }

    /// Lists the slots the write marked in the dirty set, in source-triangle order (the
    /// order of instances, then of their triangles), and clears the marks; notes which runs
    /// of the list the deforming instances gave.
    fn list_dirty(&mut self, visited: usize) {
        let UpdateScratch {
            plan,
            source_motion,
            listed,
            deformed_entries,
            reshaped_entries,
            ..
        } = &mut self.update;
        let ranges = &self.geometry.instance_triangles;
        let visited_instances = || {
            plan.iter()
                .enumerate()
                .filter(|(_, r)| **r != Rewrite::Keep)
                .map(|(i, _)| i)
        };
        if self.parallelism.splits(visited) {
            self.dirty.assign_in_source_order(
                visited_instances().map(|i| ranges[i].clone()),
                source_motion,
                &self.slot_of_source,
                listed,
            );
        } else {
            listed.clear();
            for i in visited_instances() {
                let before = self.dirty.len();
                for source in ranges[i].clone() {
                    if let Some(motion) = source_motion[source as usize].take() {
                        self.dirty
                            .mark(self.slot_of_source[source as usize], motion);
                    }
                }
                listed.push(self.dirty.len() - before);
            }
        }
        deformed_entries.clear();
        reshaped_entries.clear();
        let mut start = 0;
        for (i, &count) in visited_instances().zip(listed.iter()) {
            let end = start + count;
            let runs = match plan[i] {
                Rewrite::Changed => Some(&mut *deformed_entries),
                Rewrite::All(Motion::Rigid) | Rewrite::Keep => None,
                Rewrite::All(_) => Some(&mut *reshaped_entries),
            };
            if let Some(runs) = runs.filter(|_| count > 0) {
                match runs.last_mut() {
                    Some(run) if run.end == start => run.end = end,
                    _ => runs.push(start..end),
                }
            }
            start = end;
        }
    }

    /// A moved vertex that came out NaN or infinite stops the frame (never a NaN pixel).
    pub(super) fn check_moved_finite(&self) -> Result<(), AccelError> {
        if !self.update.moved_nonfinite {
            return Ok(()); // the write saw none: skip the scan
        }
        for &slot in &self.dirty.slots {
            let tri = self.triangles.positions[slot as usize];
            if let Some(v) = tri.iter().find(|v| !v.is_finite()) {
                return Err(AccelError::NonFiniteVertex {
                    triangle: self.triangles.source[slot as usize] as usize,
                    vertex: v.to_array(),
                });
            }
        }
        Ok(())
    }

    /// Refits the tree to the dirty triangles, or rebuilds it when the policy asks (the
    /// decision is `Accel::refit_or_rebuild`'s; the rebuild is here because it reorders the
    /// triangle slots and the dirty set must follow).
    pub(super) fn update_accel(&mut self, stats: &mut UpdateStats) -> Result<(), AccelError> {
        let step =
            self.accel
                .refit_or_rebuild(&self.triangles, &self.dirty.slots, self.settings.bvh);
        match step {
            TreeStep::Unchanged => {}
            TreeStep::Refitted { refit_ms } => stats.refit_ms = refit_ms,
            TreeStep::Rebuild { refit_ms } => {
                stats.refit_ms = refit_ms;
                self.rebuild_accel(stats)?;
            }
        }
        if self.two_level.is_some() && self.placed_changes.moved > 0 {
            // The top-level tree over the new placements: counted as refit.
            let t = Instant::now();
            let states = self.instances.take().unwrap_or_default();
            let placed = self.place_instances(&states, Which::Moving);
            self.instances = Some(states);
            placed?;
            stats.refit_ms += ms_since(t);
        }
        Ok(())
    }

    /// Builds a fresh tree over the moved triangles; the dirty marks follow their triangles
    /// into the new slot order (by source triangle).
    fn rebuild_accel(&mut self, stats: &mut UpdateStats) -> Result<(), AccelError> {
        let t = Instant::now();
        let moved: Vec<(u32, Motion)> = self
            .dirty
            .slots
            .iter()
            .zip(&self.dirty.motions)
            .map(|(&slot, &m)| (self.triangles.source[slot as usize], m))
            .collect();
        self.accel = Accel::build(&mut self.triangles)?;
        self.index_slots();
        self.dirty.reset(self.triangles.len());
        for (source, motion) in moved {
            self.dirty
                .mark(self.slot_of_source[source as usize], motion);
        }
        stats.build_ms = ms_since(t);
        stats.rebuild = true;
        Ok(())
    }
}

/// How a placed instance's triangles moved between two placements: the same shape key
/// means they only turned and moved; a new uniform scale shifts `log2 P_b`; anything else
/// changed their shape.
pub(super) fn placed_motion(now: Option<NodeShape>, before: Option<NodeShape>) -> Motion {
    match (now, before) {
        (Some(s), Some(p)) if s == p => Motion::Rigid,
        (Some(NodeShape { stretch: None, .. }), _) => Motion::Scaled,
        _ => Motion::Deformed,
    }
}
