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

use super::{InstanceState, Motion, Renderer, UpdateStats};
use crate::anim::NodeShape;
use crate::geometry::{Placement, SceneGeometry};
use crate::lod::{PixelFootprint, log2_pb, shift_log2_pb};
use crate::scene::SceneDesc;

impl Renderer {
    /// `log2 P_b` for the dirty triangles: recomputed where deformed, shifted where scaled,
    /// kept where rigid.
    pub(super) fn update_dirty_log2_pb(&mut self, stats: &mut UpdateStats) {
        let states = self.instances.take().unwrap_or_default();
        for k in 0..self.dirty.len() {
            let (slot, motion) = (self.dirty.slots[k], self.dirty.motions[k]);
            if motion == Motion::Rigid {
                continue;
            }
            if self.set_log2_pb(slot, &states) {
                match motion {
                    Motion::Deformed => stats.lod_recomputed += 1,
                    _ => stats.lod_shifted += 1,
                }
            }
        }
        self.instances = Some(states);
    }

    /// Sets one triangle's `log2 P_b` by the rule for its instance's shape; false when
    /// untextured. The value depends only on the shape key and the vertices, never on the
    /// frames before: this is what keeps a sequential run equal to a fresh frame.
    pub(super) fn set_log2_pb(&mut self, slot: u32, states: &[InstanceState]) -> bool {
        let s = slot as usize;
        let source = self.triangles.source[s] as usize;
        let object = self.object_log2_pb[source];
        if object.is_nan() {
            return false;
        }
        let instance = self.geometry.triangle_instance[source] as usize;
        self.triangles.log2_pb[s] = match states[instance].shape {
            // Similarity: the object-space constant plus log2 s.
            Some(NodeShape {
                scale,
                stretch: None,
            }) => shift_log2_pb(object, scale.log2()),
            // Stretch: the object-space triangle under the exact diagonal (a canonical value,
            // whatever rotation the frame adds).
            Some(shape) => self.stretched_log2_pb(source, shape),
            None => {
                let size = self.texture_size(source).unwrap_or((1, 1));
                log2_pb(
                    self.triangles.positions[s],
                    self.triangles.uvs[s],
                    size,
                    self.footprint,
                )
            }
        };
        true
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

    fn texture_size(&self, source: usize) -> Option<(u32, u32)> {
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
