//! One frame of the frame loop: animate -> update vertices -> dirty set -> refit the BVH
//! (rebuild when its quality degrades) -> update `log2 P_b` for what changed -> render, each
//! step timed into a [`FrameRecord`].
//!
//! Invariant: a frame is a pure function of the scene, the settings and its time, so any
//! frame can be rendered alone (or on another machine) and match a sequential run byte for
//! byte. What the sequential run carries over (triangles, `log2 P_b`, the tree) is exactly
//! what a fresh frame would compute: unchanged triangles keep bit-identical values, the
//! per-triangle constant of a similarity-placed mesh is defined as object-space constant +
//! `log2 s` (so a rigid motion needs no work), and closest-hit ties are broken by triangle
//! id rather than by tree order (see `accel`).

mod clock;
mod dirty;
mod log2_pb;
mod posed;
mod prefetch;
mod scatter;
mod settings;
mod two_level;
mod update;

pub use crate::accel::{BvhLayout, BvhPolicy};
pub use clock::FrameClock;
pub use dirty::{DirtySet, Motion};
pub use settings::RenderSettings;
pub use update::UpdateParallelism;

use std::time::Instant;

use glam::{Mat4, Vec3, Vec3A};

use crate::accel::{Accel, AccelError};
use crate::anim::{NodeShape, Pose, node_shapes, primitive_deforms};
use crate::geometry::{FrameTriangles, SceneGeometry};
use crate::lod::{LodCamera, PixelFootprint};
use crate::record::{FrameRecord, UpdateStats};
use crate::render::light::ring_lights;
use crate::render::{
    Camera, FrameScene, Instanced, Light, LinearImage, SceneBvh, TraceCounters, render_image,
};
use crate::scene::SceneDesc;
use log2_pb::{DeformingTexelTerms, object_space_log2_pb};
use posed::{VertexSource, posed_bounds};
use update::UpdateScratch;

/// Errors that stop a frame.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("frame {frame} (t = {time_s} s): {source}")]
    Accel {
        frame: u32,
        time_s: f32,
        source: AccelError,
    },
}

/// One frame after its update: camera, lights and what the update cost.
pub struct PreparedFrame {
    pub camera: Camera,
    pub lights: Vec<Light>,
    pub update: UpdateStats,
}

/// Whether a frame also makes its `--view lod` false-colour level image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LevelImage {
    Skip,
    Make,
}

/// Per-instance state carried from one frame to the next.
#[derive(Debug, Clone, Copy)]
struct InstanceState {
    world_from_object: Mat4,
    /// The placement's shape (uniform scale and axis stretch), exact through the hierarchy
    /// (see `anim::node_shapes`); `None` for a shear, a stretch under a rotation, or a
    /// skinned/morphed primitive (then only its world vertices tell its shape).
    shape: Option<NodeShape>,
}

/// Renders frames of one scene; owns the frame-to-frame state and scratch buffers.
pub struct Renderer {
    scene: SceneDesc,
    geometry: SceneGeometry,
    settings: RenderSettings,
    /// Node whose camera is used (first in traversal order), if any.
    camera_node: Option<usize>,
    /// Scene bounds at t = 0: frames the scene without a camera and places added lights.
    rest_bounds: (Vec3, Vec3),
    footprint: PixelFootprint,
    /// Per source triangle: `log2 P_b` of the rest vertices in object space (NaN where the
    /// material is untextured).
    object_log2_pb: Vec<f32>,
    /// Per slot: the texel terms of the deforming instances' triangles (`lod::texel_term`).
    texel_terms: DeformingTexelTerms,
    /// The frame's triangles in BVH order, carried over between frames.
    triangles: FrameTriangles,
    /// Inverse of `triangles.source`.
    slot_of_source: Vec<u32>,
    accel: Accel,
    /// `None` before the first frame.
    instances: Option<Vec<InstanceState>>,
    /// Per instance: placed rest vertices, or skinned/morphed ones.
    deforms: Vec<VertexSource>,
    /// This frame's pose and the previous frame's (swapped each frame, reused).
    pose: Pose,
    previous_pose: Pose,
    /// Reused buffers of the update (deformed vertices, per-instance plan, per-slot marks).
    update: UpdateScratch,
    /// When the update splits its steps across rayon's threads.
    parallelism: UpdateParallelism,
    dirty: DirtySet,
    /// Scratch for the `log2 P_b` update: one value per updated slot, reused every frame.
    log2_pb_values: Vec<Option<f32>>,
    /// Scratch for the `log2 P_b` update: the dirty entries it visits one by one.
    log2_pb_entries: Vec<u32>,
    /// The shared meshes, placements and top-level tree under `--bvh two-level` (`None`
    /// for the flat tree, or before the first frame).
    two_level: Option<two_level::TwoLevel>,
    /// What this frame's placed instances changed (two-level only; counted into the record).
    placed_changes: two_level::PlacedChanges,
}

impl Renderer {
    pub fn new(scene: SceneDesc, settings: RenderSettings) -> Renderer {
        let geometry = SceneGeometry::new(&scene);
        let deforms: Vec<VertexSource> = geometry
            .instances
            .iter()
            .map(|i| {
                VertexSource::of(primitive_deforms(
                    &scene,
                    i.node as usize,
                    i.mesh as usize,
                    i.primitive as usize,
                ))
            })
            .collect();
        let mut pose = Pose::default();
        pose.evaluate(&scene, settings.animation, 0.0);
        // Finite vertices of every triangle (a unit box when there are none).
        let rest_bounds = posed_bounds(&scene, &geometry, &pose, &deforms)
            .unwrap_or((Vec3::splat(-1.0), Vec3::splat(1.0)));
        let camera_node = first_node_with(&scene, |n| n.camera.is_some());
        let yfov = match camera_node {
            Some(node) => scene.cameras[scene.nodes[node].camera.unwrap_or(0)].yfov,
            None => {
                Camera::framing(
                    rest_bounds.0,
                    rest_bounds.1,
                    settings.width,
                    settings.height,
                )
                .yfov
            }
        };
        let footprint = PixelFootprint::new(yfov, settings.height);
        let object_log2_pb = object_space_log2_pb(&scene, &geometry, footprint);
        Renderer {
            scene,
            geometry,
            settings,
            camera_node,
            rest_bounds,
            footprint,
            object_log2_pb,
            texel_terms: DeformingTexelTerms::default(),
            triangles: FrameTriangles::default(),
            slot_of_source: Vec::new(),
            accel: Accel::default(),
            instances: None,
            deforms,
            pose,
            previous_pose: Pose::default(),
            update: UpdateScratch::default(),
            parallelism: UpdateParallelism::Auto,
            dirty: DirtySet::default(),
            log2_pb_values: Vec::new(),
            log2_pb_entries: Vec::new(),
            two_level: None,
            placed_changes: Default::default(),
        }
    }

    /// Sets when the per-frame update splits across rayon's threads (default
    /// [`UpdateParallelism::Auto`]); the results do not depend on it, only the time.
    pub fn set_update_parallelism(&mut self, parallelism: UpdateParallelism) {
        self.parallelism = parallelism;
    }

    pub fn scene(&self) -> &SceneDesc {
        &self.scene
    }

    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// The frame's world-space triangles in BVH order (valid after `prepare`): every
    /// triangle under the flat BVH; under the two-level one only the world tree's (skinned,
    /// morphed and static instances: the shared meshes' instances keep theirs in object
    /// space).
    pub fn triangles(&self) -> &FrameTriangles {
        &self.triangles
    }

    /// The current BVH (valid after `prepare`).
    pub fn accel(&self) -> &Accel {
        &self.accel
    }

    /// The scene's drawn instances and source triangles.
    pub fn geometry(&self) -> &SceneGeometry {
        &self.geometry
    }

    /// Materials indexed by `FrameTriangles::material` (the scene's, plus a default last).
    pub fn materials(&self) -> &[crate::render::Material] {
        &self.geometry.materials
    }

    /// What moved in the last `prepare` (empty after the first frame's: everything was new).
    pub fn dirty(&self) -> &DirtySet {
        &self.dirty
    }

    /// Number of lights each frame is lit by.
    pub fn light_count(&self) -> usize {
        let scene_lights = self.scene_light_nodes().len();
        self.settings.lights.unwrap_or(scene_lights.max(1))
    }

    /// Renders frame `frame` at time `time_s`.
    ///
    /// # Errors
    /// Animation produced a non-finite vertex.
    pub fn render_frame(
        &mut self,
        frame: u32,
        time_s: f32,
    ) -> Result<(LinearImage, FrameRecord), FrameError> {
        let (image, record, _) = self.render_frame_with_view(frame, time_s, LevelImage::Skip)?;
        Ok((image, record))
    }

    /// [`Self::render_frame`], plus the `--view lod` false-colour level image when
    /// `level_image` asks for it (made after the timed render, so it does not count in the
    /// record).
    ///
    /// # Errors
    /// Animation produced a non-finite vertex.
    pub fn render_frame_with_view(
        &mut self,
        frame: u32,
        time_s: f32,
        level_image: LevelImage,
    ) -> Result<(LinearImage, FrameRecord, Option<image::RgbImage>), FrameError> {
        let start = Instant::now();
        let prepared = self.prepare(frame, time_s)?;
        let t = Instant::now();
        let (image, counters) = render_image(
            &self.frame_scene(&prepared),
            &prepared.camera,
            self.settings.spp.max(1),
        );
        let render_ms = ms_since(t);
        let record = self.record(
            frame,
            time_s,
            &prepared,
            counters,
            render_ms,
            ms_since(start),
        );
        let view = (level_image == LevelImage::Make).then(|| {
            crate::render::lod_view::lod_image(&self.frame_scene(&prepared), &prepared.camera)
        });
        Ok((image, record, view))
    }

    /// The per-frame update without the render: animate, mark what moved, refit or rebuild
    /// the BVH, update `log2 P_b`, place camera and lights.
    ///
    /// # Errors
    /// Animation produced a non-finite vertex.
    pub fn prepare(&mut self, frame: u32, time_s: f32) -> Result<PreparedFrame, FrameError> {
        let mut stats = UpdateStats::default();
        let pose_start = Instant::now();
        std::mem::swap(&mut self.pose, &mut self.previous_pose);
        self.pose
            .evaluate(&self.scene, self.settings.animation, time_s);
        let scales = node_shapes(&self.scene, self.settings.animation, time_s);
        let pose_ms = ms_since(pose_start);
        let accel_error = |source| FrameError::Accel {
            frame,
            time_s,
            source,
        };
        let first = self.instances.is_none();
        let updated = if first {
            self.first_frame(&scales, &mut stats)
        } else {
            self.update_moved(&scales, &mut stats);
            self.check_moved_finite()
                .and_then(|()| self.update_accel(&mut stats))
        };
        if let Err(source) = updated {
            // The carried state is half updated: the next frame starts afresh.
            self.instances = None;
            self.two_level = None;
            return Err(accel_error(source));
        }
        if !first {
            let t = Instant::now();
            if self.settings.lod.needs_log2_pb() {
                self.update_dirty_log2_pb(&mut stats);
            }
            stats.lod_update_ms = ms_since(t);
        }
        // Evaluating the animation belongs to the animate phase too.
        stats.animate_ms += pose_ms;
        stats.moved_triangles = self.dirty.len();
        stats.deformed_triangles = self.dirty.count(Motion::Deformed);
        stats.add_placed(std::mem::take(&mut self.placed_changes));
        stats.sah_ratio = self.accel.sah_ratio();
        let world = &self.pose.world_from_node;
        Ok(PreparedFrame {
            camera: self.camera(world),
            lights: self.lights(world),
            update: stats,
        })
    }

    /// What the integrator reads for a prepared frame (valid until the next `prepare`).
    pub fn frame_scene<'a>(&'a self, prepared: &'a PreparedFrame) -> FrameScene<'a> {
        let bvh = match &self.two_level {
            None => SceneBvh::Flat {
                triangles: &self.triangles,
                accel: &self.accel,
            },
            Some(two) => SceneBvh::TwoLevel(Instanced {
                world_triangles: &self.triangles,
                world: &self.accel,
                accel: &two.accel,
                instances: &two.shading,
                footprint: self.footprint,
                needs_log2_pb: self.settings.lod.needs_log2_pb(),
            }),
        };
        FrameScene {
            bvh,
            materials: &self.geometry.materials,
            textures: &self.scene.textures,
            lights: &prepared.lights,
            background: Vec3A::from(self.scene.background),
            additive_ambient: Vec3A::from(self.scene.ambient.unwrap_or(Vec3::ONE)),
            lod: self.settings.lod,
            lod_bias: self.settings.lod_bias,
            lod_camera: LodCamera::new(&prepared.camera.view_frame()),
            max_depth: self.settings.max_depth,
        }
    }

    fn record(
        &self,
        frame: u32,
        time_s: f32,
        prepared: &PreparedFrame,
        counters: TraceCounters,
        render_ms: f64,
        total_ms: f64,
    ) -> FrameRecord {
        let u = prepared.update;
        FrameRecord {
            frame,
            time_s,
            width: self.settings.width,
            height: self.settings.height,
            lod_method: self.settings.lod.to_string(),
            lod_bias: self.settings.lod_bias,
            triangles: self.geometry.triangle_count(),
            lights: prepared.lights.len(),
            spp: self.settings.spp.max(1),
            update: u,
            render_ms,
            total_ms,
            rays: counters.rays,
            mip_histogram: counters.mip_histogram.to_vec(),
            nonfinite_samples: counters.nonfinite_samples,
        }
    }

    fn camera(&self, world: &[glam::Mat4]) -> Camera {
        let (w, h) = (self.settings.width, self.settings.height);
        match self.camera_node {
            Some(node) => {
                let desc = self.scene.cameras[self.scene.nodes[node].camera.unwrap_or(0)];
                Camera::from_world(world[node], desc.yfov, w, h)
            }
            None => Camera::framing(self.rest_bounds.0, self.rest_bounds.1, w, h),
        }
    }

    fn scene_light_nodes(&self) -> Vec<usize> {
        self.scene
            .traversal_order()
            .into_iter()
            .filter(|&i| self.scene.nodes[i].light.is_some())
            .collect()
    }

    fn lights(&self, world: &[glam::Mat4]) -> Vec<Light> {
        let wanted = self.light_count();
        let mut lights: Vec<Light> = self
            .scene_light_nodes()
            .into_iter()
            .take(wanted)
            .map(|node| {
                Light::placed(
                    &self.geometry.lights[self.scene.nodes[node].light.unwrap_or(0)],
                    world[node],
                )
            })
            .collect();
        if lights.len() < wanted {
            let (min, max) = self.rest_bounds;
            lights.extend(ring_lights(min, max, wanted - lights.len(), wanted));
        }
        lights
    }
}

fn first_node_with(
    scene: &SceneDesc,
    predicate: impl Fn(&crate::scene::NodeDesc) -> bool,
) -> Option<usize> {
    scene
        .traversal_order()
        .into_iter()
        .find(|&i| predicate(&scene.nodes[i]))
}

pub(crate) fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
