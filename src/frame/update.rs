//! The tree state of the frame loop and its steps: the world-space triangles in BVH slot
//! order with their tree (flat, or the world tree under the two-level structure), and the
//! steps that keep them: the first frame's build, the *dirty* step (place or deform what
//! moved, write it into its slots and mark it in the dirty set as rigid, scaled or
//! deformed) and the *refit or rebuild* step. Only what changed is touched;
//! `tests/frame_loop.rs` checks every changed-only path against a fresh build.
//!
//! The dirty step has three parts, each split across rayon's threads when its work is large
//! enough to pay ([`UpdateParallelism`]): pose the vertices of the instances that moved
//! (skinned or morphed then placed, or rest vertices placed; each instance into its own
//! world-space buffers), write their triangles into the BVH slots (recording each
//! triangle's motion), then list the marked slots in the dirty set in source-triangle
//! order. The write goes in source order, scattering into the slots (`scatter`), unless at
//! least half the slots are written (and the tree is not rebuilt every frame): then it goes
//! in slot order, the order of the tree's packs, reading each slot's vertex indices from a
//! compact copy kept in slot order (`slot_vertices`); there a pack whose slots all belong
//! to one deforming instance is written whole, its four lanes compared and stored as
//! vectors (`SlotLanes::rewrite_pack`). Every written value is a pure function of the pose
//! and its triangle, and the dirty order is fixed by source order, so the parallel update is
//! bit-identical to the sequential one, dirty order included. Timing: classifying instances
//! and listing the dirty set count as `dirty_ms`; posing and writing (including the
//! "did its vertices change" test, per triangle or per pack, fused with the write) as
//! `animate_ms`.

use std::time::Instant;

use rayon::prelude::*;

use super::Motion;
use super::animation::{AnimationState, InstanceState};
use super::dirty::{DirtySet, FrameChanges, Listed};
use super::layout::UsedLayout;
use super::ms_since;
use super::posed::{
    InstanceWriter, PosedVertices, Rewrite, TriangleWriter, VertexSource, WRITE_CHUNK,
    pose_all_triangles, same_deformation, write_slot_attributes,
};
use super::scatter::{SlotScatter, SourceMotions};
use super::setup::FrameSetup;
use super::slot_vertices::{self, SlotIndices, SlotVertices};
use super::two_level::{TwoLevel, Which};
use crate::accel::{Accel, AccelError, BvhPolicy, PACK_LANES, RunLeafBoxes, SlotLanes, TreeStep};
use crate::anim::NodeShape;
use crate::geometry::FrameTriangles;
use crate::simd;
use glam::{Vec2, Vec3, Vec3A};

/// Below this much work (triangles or vertices) an update step stays on the calling thread:
/// rayon's split and join cost more than the work (tens of ns per item).
const PARALLEL_MIN_ITEMS: usize = 8192;

/// How many triangles ahead the writes prefetch: the scattered write its slot, the write
/// in slot order its vertices.
const PREFETCH_AHEAD: usize = 16;

thread_local! {
    /// Per thread: the run of slot-order indices the write in slot order is working
    /// through (64 KB, kept between runs and frames, not allocated per task).
    static DECODED: std::cell::RefCell<Vec<SlotIndices>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// Slots per task of the write in slot order: a run of the slot-order indices.
const SLOT_RUN: usize = slot_vertices::RUN;

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
    /// Per instance: whether the placement its slots' uvs were last written under mirrored
    /// (`None`: never written). Uvs change only with that, so a write under the same winding
    /// skips them (a fifth of the bytes a moved triangle writes).
    uv_flips: Vec<Option<bool>>,
    /// Per visited instance: how many dirty entries it gave (scratch of the listing).
    listed: Vec<usize>,
}

/// The world-space triangles in BVH slot order and the trees over them, carried from one
/// frame to the next.
#[derive(Default)]
pub(super) struct TreeState {
    /// The frame's triangles in BVH order (under the two-level BVH only the world tree's).
    pub triangles: FrameTriangles,
    /// Inverse of `triangles.source` (`u32::MAX` for sources without a slot).
    slot_of_source: Vec<u32>,
    /// Per slot: its source triangle's instance and vertex indices (as the instance's index
    /// buffer lists them), so a write in slot order reads them in order. Made by the first
    /// such write after a build; empty until then (a scene that never writes most of its
    /// triangles in one frame never pays for it).
    slot_vertices: SlotVertices,
    pub accel: Accel,
    /// The shared meshes, placements and top-level tree under `--bvh two-level` (`None`
    /// for the flat tree, or before the first frame).
    pub two_level: Option<TwoLevel>,
    /// Reused buffers of the write (posed vertices, per-instance plan, per-slot marks).
    scratch: UpdateScratch,
    /// Whether the triangles and trees hold the previous frame's state: false before the
    /// first frame and after a frame that failed half way (the next one starts afresh).
    carried: bool,
}

/// What the first frame's build cost.
#[derive(Debug, Clone, Copy)]
pub(super) struct BuildTimes {
    /// Writing every triangle (counted as `animate_ms`).
    pub write_ms: f64,
    /// The trees (two-level meshes, world tree, top-level trees).
    pub build_ms: f64,
}

/// What the dirty step cost.
#[derive(Debug, Clone, Copy)]
pub(super) struct DirtyTimes {
    /// Classifying instances and listing the dirty set.
    pub dirty_ms: f64,
    /// Posing and writing the moved triangles (counted as `animate_ms`).
    pub write_ms: f64,
}

/// What the refit-or-rebuild step did.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct TreeUpdate {
    /// Refitting (and, under two-level, rebuilding the top-level tree over moved instances).
    pub refit_ms: f64,
    /// `Some(ms)` when the world tree was rebuilt: the slots are in a new order.
    pub build_ms: Option<f64>,
}

impl TreeState {
    /// Whether the triangles and trees hold the previous frame's state (else the next frame
    /// is built afresh).
    pub fn is_carried(&self) -> bool {
        self.carried
    }

    /// Every instance's posed vertices (a deforming instance's: those its slots were last
    /// written from, which shading reads its normals from).
    pub fn posed(&self) -> &PosedVertices {
        &self.scratch.posed
    }

    /// Drops the carried state (after a frame that failed half way).
    pub fn reset(&mut self) {
        self.carried = false;
        self.two_level = None;
    }

    /// First frame: every triangle placed and written, the trees built, the dirty set
    /// emptied. `object_log2_pb`: per source triangle, its object-space constant (the
    /// two-level meshes store it).
    pub fn build(
        &mut self,
        setup: &FrameSetup,
        animation: &AnimationState,
        object_log2_pb: &[f32],
        changes: &mut FrameChanges,
    ) -> Result<BuildTimes, AccelError> {
        let t = Instant::now();
        self.two_level = match setup.layout.used() {
            UsedLayout::TwoLevel => Some(TwoLevel::build(setup, object_log2_pb)?),
            UsedLayout::Flat => None,
        };
        let two_level_ms = ms_since(t);
        let t = Instant::now();
        // The previous state (a frame that failed half way) goes first, not under the build.
        (self.triangles, self.accel) = Default::default();
        // Under the two-level BVH only what is not an instance of a shared mesh. The
        // vertices alone first: the tree is built over them and packs them (their only
        // copy), and the rest of each triangle is written afterwards, straight into its slot,
        // so the build's peak never holds normals and uvs beside two copies of the positions.
        let two_level = self.two_level.as_ref();
        let parallel = setup.parallelism.splits(setup.geometry.triangle_count());
        let (positions, sources) = pose_all_triangles(
            &setup.scene,
            &setup.geometry,
            animation.pose(),
            &setup.deforms,
            &mut self.scratch.posed,
            &mut self.scratch.plan,
            parallel,
            |i| two_level.is_none_or(|two| two.mesh_of[i].is_none()),
        );
        let mut write_ms = ms_since(t);

        let t = Instant::now();
        let (accel, order) = Accel::build_from_positions(positions, &sources)?;
        self.accel = accel;
        let mut build_ms = ms_since(t);

        let t = Instant::now();
        self.triangles.source = order.iter().map(|&i| sources[i as usize]).collect();
        drop((order, sources));
        let UpdateScratch {
            posed,
            plan,
            uv_flips,
            ..
        } = &mut self.scratch;
        write_slot_attributes(
            &setup.scene,
            &setup.geometry,
            posed,
            plan,
            &setup.deforms,
            parallel,
            &mut self.triangles,
        );
        uv_flips.clear();
        uv_flips.extend(
            plan.iter()
                .enumerate()
                .map(|(i, r)| (*r != Rewrite::Keep).then(|| posed.placement(i).flips_winding)),
        );
        write_ms += ms_since(t);

        let t = Instant::now();
        self.index_slots(setup);
        self.place_instances(setup, animation.instances(), Which::All)?;
        changes.dirty.reset(self.triangles.len());
        self.carried = true;
        build_ms += ms_since(t);
        Ok(BuildTimes {
            write_ms,
            build_ms: two_level_ms + build_ms,
        })
    }

    /// Inverts `triangles.source` (sources without a slot, instances of shared meshes
    /// under the two-level BVH, map to `u32::MAX`).
    fn index_slots(&mut self, setup: &FrameSetup) {
        self.slot_vertices.clear();
        self.slot_of_source.clear();
        self.slot_of_source
            .resize(setup.geometry.triangle_count(), u32::MAX);
        for (slot, &source) in self.triangles.source.iter().enumerate() {
            self.slot_of_source[source as usize] = slot as u32;
        }
    }

    /// Places the two-level structure's instances (nothing under the flat tree).
    fn place_instances(
        &mut self,
        setup: &FrameSetup,
        states: &[InstanceState],
        which: Which,
    ) -> Result<(), AccelError> {
        match &mut self.two_level {
            Some(two) => two.place_instances(setup, states, which),
            None => Ok(()),
        }
    }

    /// The first frame's `lod_recomputed` share of the two-level structure's placed
    /// instances (0 under the flat tree).
    pub fn placed_textured(&self) -> usize {
        self.two_level.as_ref().map_or(0, TwoLevel::placed_textured)
    }

    /// The dirty step: rewrites the triangles of every instance whose placement or
    /// deformation changed since the previous frame and records them in `changes`.
    pub fn mark_moved(
        &mut self,
        setup: &FrameSetup,
        animation: &AnimationState,
        changes: &mut FrameChanges,
    ) -> DirtyTimes {
        let t = Instant::now();
        changes.dirty.reset(self.triangles.len());
        let (current, previous) = (animation.instances(), animation.previous_instances());
        changes.placed = match &self.two_level {
            Some(two) => two.placed_changes(setup, current, previous),
            None => Default::default(),
        };
        let visited = self.plan_rewrites(setup, animation);
        let mut dirty_ms = ms_since(t);

        let t = Instant::now();
        self.pose_planned(setup, animation);
        let (moved_nonfinite, bits_set) = self.write_planned(setup, visited, &mut changes.dirty);
        changes.moved_nonfinite = moved_nonfinite;
        let write_ms = ms_since(t);

        let t = Instant::now();
        self.list_dirty(setup, visited, bits_set, changes);
        dirty_ms += ms_since(t);
        DirtyTimes { dirty_ms, write_ms }
    }

    /// Decides each instance's [`Rewrite`] from its placement now and before (and records
    /// the placement of those to rewrite); returns how many triangles the write visits.
    fn plan_rewrites(&mut self, setup: &FrameSetup, animation: &AnimationState) -> usize {
        let UpdateScratch { posed, plan, .. } = &mut self.scratch;
        let (current, previous) = (animation.instances(), animation.previous_instances());
        posed.resize(current.len());
        plan.clear();
        let mut visited = 0;
        let instanced = |i: usize| {
            self.two_level
                .as_ref()
                .is_some_and(|two| two.mesh_of[i].is_some())
        };
        for (i, (now, before)) in current.iter().zip(previous).enumerate() {
            let rewrite = if setup.deforms[i] == VertexSource::Deformed {
                let same = same_deformation(
                    &setup.scene,
                    &setup.geometry,
                    i,
                    animation.pose(),
                    animation.previous_pose(),
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
                visited += setup.geometry.instance_triangles[i].len();
            }
            plan.push(rewrite);
        }
        visited
    }

    /// Writes the world-space vertices of the planned instances (skinned or morphed, then
    /// placed; or rest vertices placed), on rayon's threads when there are enough of them.
    fn pose_planned(&mut self, setup: &FrameSetup, animation: &AnimationState) {
        let UpdateScratch { posed, plan, .. } = &mut self.scratch;
        let planned = |i: usize| plan[i] != Rewrite::Keep;
        let vertices: usize = (0..plan.len())
            .filter(|&i| planned(i))
            .map(|i| setup.geometry.primitive(&setup.scene, i).positions.len())
            .sum();
        posed.pose(
            &setup.scene,
            &setup.geometry,
            animation.pose(),
            &setup.deforms,
            planned,
            setup.parallelism.splits(vertices),
        );
    }

    /// Writes the triangles of the planned instances into their slots and records each
    /// written triangle's motion in `source_motion`, in slot order when the frame rewrites
    /// at least half the slots, else in source order; then notes the winding each rewritten
    /// instance's uvs now follow. Returns whether a moved triangle got a non-finite vertex,
    /// and whether the write set the dirty bits of the slots it moved.
    fn write_planned(
        &mut self,
        setup: &FrameSetup,
        visited: usize,
        dirty: &mut DirtySet,
    ) -> (bool, bool) {
        // Under the rebuild-every-frame policy the slot-order indices would be made again
        // each frame, for one write.
        let rebuilds = setup.settings.bvh == BvhPolicy::Rebuild;
        let written = if visited * 2 >= self.triangles.len() && !rebuilds {
            self.write_in_slot_order(setup, visited, dirty)
        } else {
            (self.write_in_source_order(setup, visited), false)
        };
        let UpdateScratch {
            posed,
            plan,
            uv_flips,
            ..
        } = &mut self.scratch;
        for (i, rewrite) in plan.iter().enumerate() {
            if *rewrite != Rewrite::Keep {
                uv_flips[i] = Some(posed.placement(i).flips_winding);
            }
        }
        written
    }

    /// [`Self::write_planned`] visiting the moved triangles in source order (reads stay
    /// sequential); in parallel, instances and chunks of their triangles run as separate
    /// tasks, writing distinct slots (`scatter`). Returns whether a moved triangle got a
    /// non-finite vertex.
    fn write_in_source_order(&mut self, setup: &FrameSetup, visited: usize) -> bool {
        let UpdateScratch {
            posed,
            plan,
            source_motion,
            uv_flips,
            ..
        } = &mut self.scratch;
        let geometry = &setup.geometry;
        source_motion.resize(geometry.triangle_count(), None);
        let writer = frame_writer(setup, posed, plan, uv_flips);
        let ranges = &geometry.instance_triangles;
        let slot_of_source = &self.slot_of_source;
        if setup.parallelism.splits(visited) {
            let slots =
                SlotScatter::new(&mut self.triangles, self.accel.slot_lanes(), source_motion);
            plan.par_iter()
                .enumerate()
                .filter(|(_, r)| **r != Rewrite::Keep)
                .for_each(|(i, _)| {
                    let instance = writer.instance(i);
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
                                    instance.write(source, p, n, uv)
                                })
                            };
                        });
                });
        } else {
            let (triangles, accel) = (&mut self.triangles, &mut self.accel);
            let visited_instances = plan
                .iter()
                .enumerate()
                .filter(|(_, r)| **r != Rewrite::Keep);
            for (i, _) in visited_instances {
                let instance = writer.instance(i);
                for source in ranges[i].clone() {
                    let slot = slot_of_source[source as usize];
                    let s = slot as usize;
                    let mut position = accel.triangle(slot);
                    // None where the tree stores no normals (every instance deforms).
                    let normal = triangles.normals.get_mut(s);
                    let motion =
                        instance.write(source, &mut position, normal, &mut triangles.uvs[s]);
                    if motion.is_some() {
                        accel.set_triangle(slot, &position);
                    }
                    source_motion[source as usize] = motion;
                }
            }
        }
        writer.moved_nonfinite.into_inner()
    }

    /// [`Self::write_planned`] visiting every slot in slot order, for a frame that rewrites
    /// at least half of them: the tree's packs, the normals and the uvs are then written
    /// in the order they lie in memory, and each slot's vertex indices are read from
    /// `slot_vertices` (in slot order too) instead of the index buffers (in source order,
    /// which slot order scatters). Writes the same values and motions as the write in
    /// source order: each is a pure function of its triangle.
    ///
    /// On rayon's threads it also sets the dirty bits of the slots it moves (each task owns
    /// its run's words), so the listing need not set them one by one; returns whether the
    /// write gave a moved triangle a non-finite vertex, and whether it set the bits.
    fn write_in_slot_order(
        &mut self,
        setup: &FrameSetup,
        visited: usize,
        dirty: &mut DirtySet,
    ) -> (bool, bool) {
        let UpdateScratch {
            posed,
            plan,
            source_motion,
            uv_flips,
            ..
        } = &mut self.scratch;
        let geometry = &setup.geometry;
        source_motion.resize(geometry.triangle_count(), None);
        let writer = frame_writer(setup, posed, plan, uv_flips);
        let parallel = setup.parallelism.splits(visited);
        let triangles = &mut self.triangles;
        if self.slot_vertices.len() != triangles.len() {
            let sources = &triangles.source;
            let indices = |slot: usize| {
                let source = sources[slot];
                let instance = geometry.triangle_instance[source as usize];
                SlotIndices {
                    instance,
                    vertices: writer.instance(instance as usize).vertices(source),
                }
            };
            self.slot_vertices
                .encode(triangles.len(), indices, parallel);
        }
        let (lanes, leaf_boxes) = self.accel.slot_lanes_and_leaf_boxes(SLOT_RUN as u32);
        let motions = SourceMotions::new(source_motion);
        let (plan, slot_vertices) = (&*plan, &self.slot_vertices);
        // `normals`: the run's stored normals, empty when no slot stores them (every
        // instance deforms, so the write leaves them alone).
        let write_run = |run: usize,
                         sources: &[u32],
                         normals: &mut [[Vec3; 3]],
                         uvs: &mut [[Vec2; 3]],
                         words: Option<&mut [u64]>,
                         decoded: &mut Vec<SlotIndices>| {
            simd::dispatch(SlotRunWrite {
                writer: &writer,
                plan,
                slot_vertices,
                lanes: &lanes,
                leaf_boxes: &leaf_boxes,
                motions: &motions,
                run,
                sources,
                normals,
                uvs,
                words,
                decoded,
            })
        };
        let FrameTriangles {
            normals,
            uvs,
            source,
            ..
        } = triangles;
        // Each run's stored normals: none (empty runs) when no slot stores them.
        let runs = source.len().div_ceil(SLOT_RUN);
        let normal_runs: Vec<&mut [[Vec3; 3]]> = if normals.is_empty() {
            (0..runs).map(|_| Default::default()).collect()
        } else {
            normals.chunks_mut(SLOT_RUN).collect()
        };
        if parallel {
            source
                .par_chunks(SLOT_RUN)
                .zip(normal_runs)
                .zip(uvs.par_chunks_mut(SLOT_RUN))
                .zip(dirty.words_mut().par_chunks_mut(SLOT_RUN / 64))
                .enumerate()
                .for_each(|(run, (((sources, normals), uvs), words))| {
                    DECODED.with_borrow_mut(|decoded| {
                        write_run(run, sources, normals, uvs, Some(words), decoded)
                    })
                });
        } else {
            let runs = source
                .chunks(SLOT_RUN)
                .zip(normal_runs)
                .zip(uvs.chunks_mut(SLOT_RUN));
            DECODED.with_borrow_mut(|decoded| {
                for (run, ((sources, normals), uvs)) in runs.enumerate() {
                    write_run(run, sources, normals, uvs, None, decoded);
                }
            });
        }
        (writer.moved_nonfinite.into_inner(), parallel)
    }

    /// Lists the slots the write marked in the dirty set, in source-triangle order (the
    /// order of instances, then of their triangles), and clears the marks; notes which runs
    /// of the list the deforming instances gave.
    /// `bits_set`: the write already set the listed slots' dirty bits (in slot order).
    fn list_dirty(
        &mut self,
        setup: &FrameSetup,
        visited: usize,
        bits_set: bool,
        changes: &mut FrameChanges,
    ) {
        let UpdateScratch {
            plan,
            source_motion,
            listed,
            ..
        } = &mut self.scratch;
        let FrameChanges {
            dirty,
            deformed,
            reshaped_entries,
            ..
        } = changes;
        let ranges = &setup.geometry.instance_triangles;
        let visited_instances = || {
            plan.iter()
                .enumerate()
                .filter(|(_, r)| **r != Rewrite::Keep)
                .map(|(i, _)| i)
        };
        // The write in slot order set the bits (it does when it splits, as this does) and
        // recorded no motions for the slots of deforming instances: those stay unlisted.
        let listed_as = |i: usize| match plan[i] {
            Rewrite::Changed if bits_set => Listed::DeformedByBit,
            _ => Listed::ByMotion,
        };
        if bits_set || setup.parallelism.splits(visited) {
            dirty.assign_in_source_order(
                visited_instances().map(|i| (ranges[i].clone(), listed_as(i))),
                source_motion,
                &self.slot_of_source,
                bits_set,
                listed,
            );
        } else {
            listed.clear();
            for i in visited_instances() {
                let before = dirty.len();
                for source in ranges[i].clone() {
                    if let Some(motion) = source_motion[source as usize].take() {
                        dirty.mark(self.slot_of_source[source as usize], motion);
                    }
                }
                listed.push(dirty.len() - before);
            }
        }
        // The deforming instances' moved slots: the unlisted ones and those listed by motion.
        *deformed = dirty.unlisted();
        reshaped_entries.clear();
        let mut start = 0;
        for (i, &count) in visited_instances().zip(listed.iter()) {
            let end = start + count;
            if plan[i] == Rewrite::Changed {
                *deformed += count;
            }
            let reshaped = matches!(plan[i], Rewrite::All(Motion::Scaled | Motion::Deformed));
            if reshaped && count > 0 {
                match reshaped_entries.last_mut() {
                    Some(run) if run.end == start => run.end = end,
                    _ => reshaped_entries.push(start..end),
                }
            }
            start = end;
        }
    }

    /// A moved vertex that came out NaN or infinite stops the frame (never a NaN pixel).
    /// The error names the lowest such source triangle, so every update path (whatever
    /// its slot order, listed or not) names the same one.
    pub fn check_moved_finite(&self, changes: &FrameChanges) -> Result<(), AccelError> {
        if !changes.moved_nonfinite {
            return Ok(()); // the write saw none: skip the scan
        }
        let first = changes
            .dirty
            .slots_in_order()
            .filter_map(|slot| {
                let tri = self.accel.triangle(slot);
                let v = tri.iter().find(|v| !v.is_finite())?;
                Some((self.triangles.source[slot as usize], v.to_array()))
            })
            .min_by_key(|&(source, _)| source);
        match first {
            Some((source, vertex)) => Err(AccelError::NonFiniteVertex {
                triangle: source as usize,
                vertex,
            }),
            None => Ok(()),
        }
    }

    /// The refit-or-rebuild step: refits the tree to the dirty triangles, or rebuilds it
    /// when the policy asks (the decision is `Accel::refit_or_rebuild`'s; the rebuild is
    /// here because it reorders the triangle slots and the dirty set must follow); under
    /// two-level, rebuilds the top-level tree when a placed instance moved.
    pub fn refit_or_rebuild(
        &mut self,
        setup: &FrameSetup,
        animation: &AnimationState,
        changes: &mut FrameChanges,
    ) -> Result<TreeUpdate, AccelError> {
        let mut update = TreeUpdate::default();
        let dirty = &changes.dirty;
        let step = self.accel.refit_or_rebuild_listing(
            dirty.len(),
            || dirty.all_slots(),
            setup.settings.bvh,
        );
        match step {
            TreeStep::Unchanged => {}
            TreeStep::Refitted { refit_ms } => update.refit_ms = refit_ms,
            TreeStep::Rebuild { refit_ms } => {
                update.refit_ms = refit_ms;
                update.build_ms = Some(self.rebuild(setup, changes)?);
            }
        }
        if self.two_level.is_some() && changes.placed.moved > 0 {
            // The top-level tree over the new placements: counted as refit.
            let t = Instant::now();
            self.place_instances(setup, animation.instances(), Which::Moving)?;
            update.refit_ms += ms_since(t);
        }
        Ok(update)
    }

    /// Builds a fresh tree over the moved triangles; the dirty marks follow their triangles
    /// into the new slot order (by source triangle). Returns the milliseconds it took.
    fn rebuild(
        &mut self,
        setup: &FrameSetup,
        changes: &mut FrameChanges,
    ) -> Result<f64, AccelError> {
        let t = Instant::now();
        let dirty = &mut changes.dirty;
        // The listed entries first, in their order (the `log2 P_b` step's entry runs index
        // them), then the unlisted ones.
        let (slots, motions) = dirty.listed();
        let unlisted = dirty.unlisted_slots();
        let source = |slot: u32| self.triangles.source[slot as usize];
        let moved: Vec<(u32, Motion)> = slots
            .iter()
            .zip(motions)
            .map(|(&slot, &m)| (source(slot), m))
            .chain(
                unlisted
                    .into_iter()
                    .map(|slot| (source(slot), Motion::Deformed)),
            )
            .collect();
        // The positions come out of the old tree's packs, and the old tree goes before the
        // build: kept until the new one is built, its 110 bytes or so per triangle would sit
        // under the builder's peak.
        self.triangles.positions = self.accel.triangles_in_slot_order();
        self.accel = Accel::default();
        self.accel = Accel::build(&mut self.triangles)?;
        self.index_slots(setup);
        dirty.reset(self.triangles.len());
        for (source, motion) in moved {
            dirty.mark(self.slot_of_source[source as usize], motion);
        }
        Ok(ms_since(t))
    }
}

/// One run of [`TreeState::write_in_slot_order`]: its slots' indices decoded, then each
/// planned slot's triangle written into its pack lane (a pack of one deforming instance's
/// slots lying in the run, all four lanes at once), its motion recorded and (with `words`)
/// its dirty bit set; then the boxes of the leaves inside the run. A [`simd::Kernel`] so
/// the loop is compiled once per SIMD copy: the AVX2 copy encodes the per-slot gathers,
/// compares and lane stores with fewer instructions (the whole-pack rewrite is SSE2 in
/// both).
struct SlotRunWrite<'a, 'r> {
    writer: &'a TriangleWriter<'a>,
    plan: &'a [Rewrite],
    slot_vertices: &'a SlotVertices,
    lanes: &'a SlotLanes<'a>,
    /// Where the run sets its leaves' boxes once their slots are written.
    leaf_boxes: &'a RunLeafBoxes<'a>,
    motions: &'a SourceMotions<'a>,
    run: usize,
    /// The run's slots' source triangles.
    sources: &'r [u32],
    /// The run's stored normals (empty when no slot stores them).
    normals: &'r mut [[Vec3; 3]],
    uvs: &'r mut [[Vec2; 3]],
    /// The run's dirty words, when the write sets the bits.
    words: Option<&'r mut [u64]>,
    decoded: &'r mut Vec<SlotIndices>,
}

impl simd::Kernel for SlotRunWrite<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn run<const AVX2: bool>(self) {
        let SlotRunWrite {
            writer,
            plan,
            slot_vertices,
            lanes,
            leaf_boxes,
            motions,
            run,
            sources,
            normals,
            uvs,
            mut words,
            decoded,
        } = self;
        // An escaped slot's indices come from its instance's index buffer.
        let escaped = |slot: usize, i: u32| {
            let source = sources[slot - run * SLOT_RUN];
            writer.instance(i as usize).vertices(source)
        };
        slot_vertices.decode_run(run, escaped, decoded);
        let deformed_by_bit = words.is_some();
        // Slot `k`'s motion recorded: its dirty bit when the write sets them, and its motion
        // by source, except where a deforming instance's moved slots are listed from those
        // bits (`Listed::DeformedByBit`).
        let mut record = |k: usize, motion: Option<Motion>, deforms_by_change: bool| {
            if let Some(words) = words.as_deref_mut()
                && motion.is_some()
            {
                words[k / 64] |= 1 << (k % 64);
            }
            if !(deformed_by_bit && deforms_by_change) {
                // SAFETY: each slot is in one run only, and each source has one slot, so no
                // other task writes this source's motion (`scatter`).
                unsafe { motions.set(sources[k], motion) };
            }
        };
        let mut current: Option<(u32, InstanceWriter)> = None;
        let mut k = 0;
        while k < decoded.len() {
            let SlotIndices {
                instance: i,
                vertices,
            } = decoded[k];
            if plan[i as usize] == Rewrite::Keep {
                k += 1;
                continue;
            }
            let instance = match &current {
                Some((at, instance)) if *at == i => instance,
                _ => &current.insert((i, writer.instance(i as usize))).1,
            };
            let slot = (run * SLOT_RUN + k) as u32;
            // A whole pack of this instance's slots that write their positions alone: its
            // lanes written together (`SlotLanes::rewrite_pack`).
            if instance.writes_positions_alone()
                && let Some(live) = lanes.pack_from(slot).map(|live| live as usize)
                && decoded
                    .get(k..k + live)
                    .is_some_and(|pack| pack.iter().all(|s| s.instance == i))
            {
                let mut tri = [[Vec3A::ZERO; 3]; PACK_LANES];
                for (l, t) in tri.iter_mut().enumerate().take(live) {
                    if let Some(ahead) = decoded.get(k + l + PREFETCH_AHEAD)
                        && ahead.instance == i
                    {
                        instance.prefetch_vertices(ahead.vertices);
                    }
                    *t = instance.placed_positions(decoded[k + l].vertices);
                }
                // SAFETY: all the pack's slots lie in this run (`decoded` holds the run's
                // slots, and `get(k..k + live)` found them there), and no other task reads
                // or writes a run's slots (`scatter`).
                let (changed, nonfinite) = unsafe { lanes.rewrite_pack(slot, live as u32, &tri) };
                if nonfinite != 0 {
                    instance.note_nonfinite();
                }
                for l in 0..live {
                    let moved = changed & (1 << l) != 0;
                    record(k + l, moved.then_some(Motion::Deformed), true);
                }
                k += live;
                continue;
            }
            if let Some(ahead) = decoded.get(k + PREFETCH_AHEAD)
                && ahead.instance == i
            {
                instance.prefetch_vertices(ahead.vertices);
            }
            // SAFETY: each slot is in one run only, so no other task reads or writes its
            // lane (`scatter`).
            let motion = unsafe {
                let mut position = lanes.get(slot);
                let motion = instance.write_vertices(
                    vertices,
                    sources[k],
                    &mut position,
                    normals.get_mut(k),
                    &mut uvs[k],
                );
                if motion.is_some() {
                    lanes.set(slot, &position);
                }
                motion
            };
            record(k, motion, instance.deforms_by_change());
            k += 1;
        }
        // The boxes of the run's leaves, while its packs are in this task's cache: the
        // refit's leaf pass read every pack again from memory (a million skinned
        // triangles' refit was mostly that pass).
        let first = (run * SLOT_RUN) as u32;
        // SAFETY: the run's slots are this task's alone (as above), and so are the lanes
        // of the leaves inside them.
        unsafe { leaf_boxes.set_inside(lanes, first..first + sources.len() as u32) };
    }
}

/// What writing this frame's planned instances reads (both write orders use it).
fn frame_writer<'a>(
    setup: &'a FrameSetup,
    posed: &'a PosedVertices,
    plan: &'a [Rewrite],
    uv_flips: &'a [Option<bool>],
) -> TriangleWriter<'a> {
    let (scene, geometry) = (&setup.scene, &setup.geometry);
    TriangleWriter::new(scene, geometry, posed, plan, uv_flips, &setup.deforms)
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
