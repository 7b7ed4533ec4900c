//! The `log2 P_b` rules of the frame loop (the constant itself is `lod::pb`): which
//! triangles get a new constant this frame and from what.
//!
//! - rigid motion (same shape key): keep the constant, no work;
//! - a new uniform scale `s`: object-space constant + `log2 s` (`lod::shift_log2_pb`);
//! - a new axis stretch: the object-space triangle under the exact diagonal;
//! - anything else (shear, skin, morph): recomputed from the world vertices.
//!
//! Each value depends only on the shape key and the vertices, never on earlier frames, so a
//! sequential run equals a frame rendered alone (`tests/frame_loop.rs`, `tests/deform.rs`
//! check it against a full recompute).

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use super::posed::VertexSource;
use super::prefetch::prefetch;
use super::{InstanceState, Motion, Renderer, UpdateStats};
use crate::anim::NodeShape;
use crate::geometry::{Placement, SceneGeometry};
use crate::lod::{PixelFootprint, log2_pb, log2_pb_with_uv_area, shift_log2_pb, uv_area};
use crate::scene::SceneDesc;

/// How many entries ahead the `log2 P_b` pass prefetches its slots.
const PREFETCH_AHEAD: usize = 16;

impl Renderer {
    /// `log2 P_b` for the dirty triangles: recomputed where deformed, shifted where scaled,
    /// kept where rigid.
    pub(super) fn update_dirty_log2_pb(&mut self, stats: &mut UpdateStats) {
        let states = self.instances.take().unwrap_or_default();
        let mut values = std::mem::take(&mut self.log2_pb_values);
        let (slots, motions) = (&self.dirty.slots, &self.dirty.motions);
        self.log2_pb_values_into(
            slots.len(),
            |k| (motions[k] != Motion::Rigid).then_some(slots[k]),
            &states,
            &mut values,
        );
        for (k, value) in values.iter().enumerate() {
            let Some(value) = *value else { continue };
            self.triangles.log2_pb[self.dirty.slots[k] as usize] = value;
            match self.dirty.motions[k] {
                Motion::Deformed => stats.lod_recomputed += 1,
                _ => stats.lod_shifted += 1,
            }
        }
        self.log2_pb_values = values;
        self.instances = Some(states);
    }

    /// `log2 P_b` of every triangle (the first frame); returns how many are textured.
    pub(super) fn recompute_all_log2_pb(&mut self, states: &[InstanceState]) -> usize {
        let mut values = std::mem::take(&mut self.log2_pb_values);
        self.log2_pb_values_into(
            self.triangles.len(),
            |k| Some(k as u32),
            states,
            &mut values,
        );
        let mut textured = 0;
        for (slot, value) in values.iter().enumerate() {
            if let Some(value) = *value {
                self.triangles.log2_pb[slot] = value;
                textured += 1;
            }
        }
        self.log2_pb_values = values;
        textured
    }

    /// Fills `values[k]` with the new `log2 P_b` of slot `slot_at(k)` for `k` in
    /// `0..count` (`None` where `slot_at` skips it or the triangle is untextured). Each
    /// value is a pure function of its own triangle, so the work splits across rayon's
    /// threads when there is enough of it, with results bit-identical to one thread's.
    fn log2_pb_values_into(
        &self,
        count: usize,
        slot_at: impl Fn(usize) -> Option<u32> + Sync,
        states: &[InstanceState],
        values: &mut Vec<Option<f32>>,
    ) {
        // Only the rule for triangles without a shape key reads the slot's vertices: other
        // passes would fetch them for nothing (a stretched 1M crowd's pass was 1.17x slower).
        let reads_vertices = states.iter().any(|state| state.shape.is_none());
        let value = |k: usize| {
            // The slots are scattered through the per-slot arrays: ask for the ones a few
            // entries ahead now (before, most of the pass's own time on a million deforming
            // triangles went to waiting for these loads).
            if let Some(ahead) = (k + PREFETCH_AHEAD < count)
                .then(|| slot_at(k + PREFETCH_AHEAD))
                .flatten()
            {
                self.prefetch_slot(ahead as usize, reads_vertices);
            }
            slot_at(k).and_then(|slot| self.log2_pb_of(slot, states))
        };
        // Below 8,192 triangles (`UpdateParallelism::Auto`) rayon's split and join cost more
        // than the work (a triangle's constant takes tens of ns).
        if self.parallelism.splits(count) {
            (0..count)
                .into_par_iter()
                .map(value)
                .collect_into_vec(values);
        } else {
            values.clear();
            values.extend((0..count).map(value));
        }
    }

    /// Hints the cache to load what [`Self::log2_pb_of`] reads of slot `s` (its vertices
    /// too when `vertices`).
    #[inline]
    fn prefetch_slot(&self, s: usize, vertices: bool) {
        let t = &self.triangles;
        prefetch(&t.source, s);
        if vertices {
            prefetch(&t.positions, s);
        }
    }

    /// One triangle's `log2 P_b` by the rule for its instance's shape; `None` when
    /// untextured. The value depends only on the shape key and the vertices, never on the
    /// frames before: this is what keeps a sequential run equal to a fresh frame.
    fn log2_pb_of(&self, slot: u32, states: &[InstanceState]) -> Option<f32> {
        let s = slot as usize;
        let source = self.triangles.source[s] as usize;
        let object = self.object_log2_pb[source];
        if object.is_nan() {
            return None;
        }
        let instance = self.geometry.triangle_instance[source] as usize;
        Some(match states[instance].shape {
            // Similarity: the object-space constant plus log2 s.
            Some(NodeShape {
                scale,
                stretch: None,
            }) => shift_log2_pb(object, scale.log2()),
            // Stretch: the object-space triangle under the exact diagonal (a canonical value,
            // whatever rotation the frame adds).
            Some(shape) => self.stretched_log2_pb(source, shape),
            // Deforming (or sheared): from its world vertices, with the uv area its slot's
            // uvs have (for a deforming instance read from the table: the source's uvs,
            // perhaps in the other winding, the same area).
            None => {
                let size = self.texture_size(source).unwrap_or((1, 1));
                let uv = self
                    .uv_areas
                    .of(&self.geometry, instance, source)
                    .unwrap_or_else(|| uv_area(self.triangles.uvs[s]));
                log2_pb_with_uv_area(self.triangles.positions[s], uv, size, self.footprint)
            }
        })
    }

    /// `log2 P_b` of a source triangle's rest vertices under `diag(shape.diagonal())`.
    fn stretched_log2_pb(&self, source: usize, shape: NodeShape) -> f32 {
        let instance = self.geometry.triangle_instance[source] as usize;
        let primitive = self.geometry.primitive(&self.scene, instance);
        let [x, y, z] = shape.diagonal();
        let stretch = Mat4::from_scale(Vec3::new(x as f32, y as f32, z as f32));
        let placement = Placement::new(stretch);
        let (p, _) =
            self.geometry
                .world_triangle(source as u32, &placement, &primitive.positions, None);
        let size = self.texture_size(source).unwrap_or((1, 1));
        log2_pb(
            p,
            self.geometry.oriented_uvs(source as u32, &placement),
            size,
            self.footprint,
        )
    }

    /// Level-0 size of the base-colour texture of source triangle `source`'s material.
    pub(super) fn texture_size(&self, source: usize) -> Option<(u32, u32)> {
        let instance = self.geometry.instances[self.geometry.triangle_instance[source] as usize];
        let material = &self.geometry.materials[instance.material as usize];
        let texture = self.scene.textures.get(material.base_color_texture?)?;
        Some(texture.pyramid.base_size())
    }
}

/// `log2 P_b` of every source triangle from its rest vertices in object space; NaN where the
/// material is untextured.
pub(super) fn object_space_log2_pb(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    footprint: PixelFootprint,
) -> Vec<f32> {
    let identity = Placement::new(Mat4::IDENTITY);
    let mut out = vec![f32::NAN; geometry.triangle_count()];
    for (i, instance) in geometry.instances.iter().enumerate() {
        let material = &geometry.materials[instance.material as usize];
        let Some(texture) = material
            .base_color_texture
            .and_then(|t| scene.textures.get(t))
        else {
            continue;
        };
        let primitive = geometry.primitive(scene, i);
        for source in geometry.instance_triangles[i].clone() {
            let (p, _) = geometry.world_triangle(source, &identity, &primitive.positions, None);
            out[source as usize] = log2_pb(
                p,
                geometry.oriented_uvs(source, &identity),
                texture.pyramid.base_size(),
                footprint,
            );
        }
    }
    out
}

/// The [`uv_area`] of every triangle of the deforming instances, made once: their uvs
/// never move while their vertices do, so the `log2 P_b` pass reads the area instead of the
/// slot's uvs each frame. Other instances have no entry (8 bytes per triangle only where
/// it is used).
#[derive(Debug, Default)]
pub(super) struct DeformingUvAreas {
    /// Per instance: where its triangles' areas start in `areas`, or `u32::MAX`.
    first: Vec<u32>,
    areas: Vec<f64>,
}

impl DeformingUvAreas {
    pub(super) fn new(geometry: &SceneGeometry, deforms: &[VertexSource]) -> Self {
        let mut table = DeformingUvAreas::default();
        for (range, &source) in geometry.instance_triangles.iter().zip(deforms) {
            if source != VertexSource::Deformed {
                table.first.push(u32::MAX);
                continue;
            }
            table.first.push(table.areas.len() as u32);
            let uvs = &geometry.triangle_uvs[range.start as usize..range.end as usize];
            table.areas.extend(uvs.iter().map(|&uv| uv_area(uv)));
        }
        table
    }

    /// Source triangle `source`'s area, if its instance `instance` deforms.
    #[inline]
    fn of(&self, geometry: &SceneGeometry, instance: usize, source: usize) -> Option<f64> {
        let first = *self.first.get(instance)?;
        if first == u32::MAX {
            return None;
        }
        let offset = source - geometry.instance_triangles[instance].start as usize;
        self.areas.get(first as usize + offset).copied()
    }
}
