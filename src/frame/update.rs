//! The per-frame update of the scene's triangles and tree: place or deform what moved,
//! mark it in the dirty set as rigid, scaled or deformed, and refit or rebuild the BVH.
//! Only what changed is touched; `tests/frame_loop.rs` checks every changed-only path
//! against a fresh build.

use std::time::Instant;

use glam::Mat4;

use super::posed::{VertexSource, instance_vertices, same_deformation, write_all_triangles};
use super::{InstanceState, Motion, Renderer, UpdateStats, ms_since};
use crate::accel::{Accel, AccelError, TreeStep};
use crate::anim::NodeShape;
use crate::geometry::Placement;

impl Renderer {
    /// First frame: every triangle placed, the tree built, every `log2 P_b` computed.
    pub(super) fn first_frame(
        &mut self,
        scales: &[Option<NodeShape>],
        stats: &mut UpdateStats,
    ) -> Result<(), AccelError> {
        let t = Instant::now();
        write_all_triangles(
            &self.scene,
            &self.geometry,
            &self.pose,
            &self.deforms,
            &mut self.scratch,
            &mut self.triangles,
        );
        let states = self.instance_states(scales);
        stats.animate_ms = ms_since(t);

        let t = Instant::now();
        self.accel = Accel::build(&mut self.triangles)?;
        self.index_slots();
        stats.build_ms = ms_since(t);
        stats.rebuild = true;

        let t = Instant::now();
        self.dirty.reset(self.triangles.len());
        if self.settings.lod.needs_log2_pb() {
            stats.lod_recomputed = self.recompute_all_log2_pb(&states);
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

    fn index_slots(&mut self) {
        self.slot_of_source.resize(self.triangles.len(), 0);
        for (slot, &source) in self.triangles.source.iter().enumerate() {
            self.slot_of_source[source as usize] = slot as u32;
        }
    }

    /// Rewrites the triangles of every instance whose placement changed and records them in
    /// the dirty set.
    pub(super) fn update_moved(&mut self, scales: &[Option<NodeShape>], stats: &mut UpdateStats) {
        let t = Instant::now();
        self.dirty.reset(self.triangles.len());
        let previous = self.instances.take().unwrap_or_default();
        let current = self.instance_states(scales);
        let mut classify_ms = ms_since(t);
        for (i, (now, before)) in current.iter().zip(&previous).enumerate() {
            if self.deforms[i] == VertexSource::Deformed {
                if !same_deformation(
                    &self.scene,
                    &self.geometry,
                    i,
                    &self.pose,
                    &self.previous_pose,
                ) {
                    classify_ms += self.deform_instance(i);
                }
                continue;
            }
            if now.world_from_object == before.world_from_object {
                continue; // static: untouched
            }
            let c = Instant::now();
            // Same shape key: the triangles only turned and moved. Otherwise a new uniform
            // scale shifts `log2 P_b`; anything else changed the shape.
            let motion = match (now.shape, before.shape) {
                (Some(s), Some(p)) if s == p => Motion::Rigid,
                (Some(NodeShape { stretch: None, .. }), _) => Motion::Scaled,
                _ => Motion::Deformed,
            };
            classify_ms += ms_since(c);
            self.place_instance(i, now.world_from_object, motion);
        }
        self.instances = Some(current);
        stats.dirty_ms = classify_ms;
        stats.animate_ms = ms_since(t) - classify_ms;
    }

    /// Rewrites a skinned or morphed instance's triangles from its deformed vertices; marks
    /// exactly those whose vertices changed as deformed. Returns the milliseconds spent
    /// comparing (the classification share of the work).
    fn deform_instance(&mut self, i: usize) -> f64 {
        let mut compare_ms = 0.0;
        let (placement, positions, normals) = instance_vertices(
            &self.scene,
            &self.geometry,
            &self.pose,
            i,
            VertexSource::Deformed,
            &mut self.scratch,
        );
        for source in self.geometry.instance_triangles[i].clone() {
            let slot = self.slot_of_source[source as usize];
            let s = slot as usize;
            let (p, n) = self
                .geometry
                .world_triangle(source, &placement, positions, normals);
            let c = Instant::now();
            let moved = p.map(|v| v.to_array().map(f32::to_bits))
                != self.triangles.positions[s].map(|v| v.to_array().map(f32::to_bits));
            compare_ms += ms_since(c);
            if moved {
                self.triangles.positions[s] = p;
                self.triangles.uvs[s] = self.geometry.oriented_uvs(source, &placement);
                self.dirty.mark(slot, Motion::Deformed);
            }
            // Normals can turn without the triangle moving (a neighbour's vertex moved).
            self.triangles.normals[s] = n;
        }
        compare_ms
    }

    /// A moved vertex that came out NaN or infinite stops the frame (never a NaN pixel).
    pub(super) fn check_moved_finite(&self) -> Result<(), AccelError> {
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

    /// Writes instance `i`'s triangles for a new placement and marks them.
    fn place_instance(&mut self, i: usize, world_from_object: Mat4, motion: Motion) {
        let placement = Placement::new(world_from_object);
        let primitive = self.geometry.primitive(&self.scene, i);
        for source in self.geometry.instance_triangles[i].clone() {
            let slot = self.slot_of_source[source as usize];
            let (p, n) = self.geometry.world_triangle(
                source,
                &placement,
                &primitive.positions,
                primitive.normals.as_deref(),
            );
            let s = slot as usize;
            self.triangles.positions[s] = p;
            self.triangles.normals[s] = n;
            self.triangles.uvs[s] = self.geometry.oriented_uvs(source, &placement);
            self.dirty.mark(slot, motion);
        }
    }

    /// Refits the tree to the dirty triangles, or rebuilds it when the policy asks (the
    /// decision is `Accel::refit_or_rebuild`'s; the rebuild is here because it reorders the
    /// triangle slots and the dirty set must follow).
    pub(super) fn update_accel(&mut self, stats: &mut UpdateStats) -> Result<(), AccelError> {
        let step =
            self.accel
                .refit_or_rebuild(&self.triangles, &self.dirty.slots, self.settings.bvh);
        match step {
            TreeStep::Unchanged => Ok(()),
            TreeStep::Refitted { refit_ms } => {
                stats.refit_ms = refit_ms;
                Ok(())
            }
            TreeStep::Rebuild { refit_ms } => {
                stats.refit_ms = refit_ms;
                self.rebuild_accel(stats)
            }
        }
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
