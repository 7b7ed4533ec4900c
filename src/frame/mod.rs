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

mod dirty;
mod posed;
mod record;

pub use dirty::{DirtySet, Motion};
pub use record::{FrameRecord, Phase, UpdateStats};

use std::time::Instant;

use glam::{Mat4, Vec3, Vec3A};

use crate::accel::{Accel, AccelError, RefitKind};
use crate::anim::{AnimationSelection, NodeShape, Pose, node_shapes, primitive_deforms};
use crate::geometry::{FrameTriangles, Placement, SceneGeometry};
use crate::lod::{LOG2_PB_LIMIT, LodCamera, LodMethod, PixelFootprint, log2_pb};
use crate::render::light::ring_lights;
use crate::render::{Camera, FrameScene, Light, LinearImage, TraceCounters, render_image};
use crate::scene::SceneDesc;
use posed::{DeformScratch, instance_vertices, same_deformation, write_all_triangles};

/// Which time each frame number shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameClock {
    /// Frame `i` at `i / fps` seconds.
    Fps(f64),
    /// The scene's own frame times (AFF `a start end frames`).
    Scene(crate::scene::FrameTimes),
}

impl FrameClock {
    /// The clock for a scene: `--fps` when given, else the scene's own frame times, else
    /// 30 frames per second.
    pub fn for_scene(scene: &SceneDesc, fps: Option<f64>) -> FrameClock {
        match (fps, scene.frame_times) {
            (Some(fps), _) => FrameClock::Fps(fps),
            (None, Some(times)) => FrameClock::Scene(times),
            (None, None) => FrameClock::Fps(30.0),
        }
    }

    /// Time of frame `frame` in seconds.
    pub fn time(&self, frame: u32) -> f32 {
        match self {
            FrameClock::Fps(fps) => (frame as f64 / fps) as f32,
            FrameClock::Scene(times) => times.time(frame),
        }
    }

    /// The frames that cover an animation of `duration_s` once (`0..round(duration * fps)`,
    /// at least one), or all of the scene's own frames.
    pub fn default_frames(&self, duration_s: f32) -> std::ops::Range<u32> {
        match self {
            FrameClock::Fps(fps) => 0..((duration_s as f64 * fps).round().clamp(1.0, 1e6) as u32),
            FrameClock::Scene(times) => 0..times.frames.max(1),
        }
    }
}

/// How the BVH follows the animation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BvhPolicy {
    /// Refit every frame; rebuild when the SAH cost exceeds `rebuild_threshold` times its
    /// value right after the last build.
    Refit { rebuild_threshold: f32 },
    /// Rebuild every frame that anything moved (for comparison).
    Rebuild,
}

impl BvhPolicy {
    /// Default rebuild threshold: a refitted tree 50% costlier than fresh is rebuilt.
    pub const DEFAULT_REBUILD_THRESHOLD: f32 = 1.5;

    /// Whether the tree should be rebuilt given its current SAH ratio.
    pub fn wants_rebuild(self, sah_ratio: f32) -> bool {
        match self {
            BvhPolicy::Rebuild => true,
            BvhPolicy::Refit { rebuild_threshold } => !(sah_ratio <= rebuild_threshold),
        }
    }
}

/// How frames are rendered (the CLI's render options).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub lod: LodMethod,
    /// Levels added to every MIP-mapped lookup (`--lod-bias`; `none` ignores it).
    pub lod_bias: f32,
    /// Samples per pixel (stratified).
    pub spp: u32,
    /// Maximum number of reflection/refraction bounces.
    pub max_depth: u32,
    /// Number of lights: the scene's first N, plus ring lights when it has fewer.
    /// `None`: all of the scene's lights (at least one).
    pub lights: Option<usize>,
    pub bvh: BvhPolicy,
    /// Which clips play (`--animation`).
    pub animation: AnimationSelection,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 640,
            height: 360,
            lod: LodMethod::Paper,
            lod_bias: 0.0,
            spp: 1,
            max_depth: 5,
            lights: None,
            bvh: BvhPolicy::Refit {
                rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
            },
            animation: AnimationSelection::All,
        }
    }
}

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
    /// The frame's triangles in BVH order, carried over between frames.
    triangles: FrameTriangles,
    /// Inverse of `triangles.source`.
    slot_of_source: Vec<u32>,
    accel: Accel,
    /// `None` before the first frame.
    instances: Option<Vec<InstanceState>>,
    /// Per instance: its primitive is skinned or morphed.
    deforms: Vec<bool>,
    /// This frame's pose and the previous frame's (swapped each frame, reused).
    pose: Pose,
    previous_pose: Pose,
    scratch: DeformScratch,
    dirty: DirtySet,
}

impl Renderer {
    pub fn new(scene: SceneDesc, settings: RenderSettings) -> Renderer {
        let geometry = SceneGeometry::new(&scene);
        let deforms: Vec<bool> = geometry
            .instances
            .iter()
            .map(|i| {
                primitive_deforms(
                    &scene,
                    i.node as usize,
                    i.mesh as usize,
                    i.primitive as usize,
                )
            })
            .collect();
        let mut pose = Pose::default();
        pose.evaluate(&scene, settings.animation, 0.0);
        let mut scratch = DeformScratch::default();
        let mut rest = FrameTriangles::default();
        write_all_triangles(&scene, &geometry, &pose, &deforms, &mut scratch, &mut rest);
        let rest_bounds = bounds(&rest);
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
            triangles: FrameTriangles::default(),
            slot_of_source: Vec::new(),
            accel: Accel::default(),
            instances: None,
            deforms,
            pose,
            previous_pose: Pose::default(),
            scratch,
            dirty: DirtySet::default(),
        }
    }

    pub fn scene(&self) -> &SceneDesc {
        &self.scene
    }

    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// The frame's triangles in BVH order (valid after `prepare`).
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
    pub fn materials(&self) -> &[crate::scene::MaterialDesc] {
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
        let (image, record, _) = self.render_frame_with_view(frame, time_s, false)?;
        Ok((image, record))
    }

    /// [`Self::render_frame`], plus the `--view lod` false-colour level image when
    /// `lod_view` (made after the timed render, so it does not count in the record).
    ///
    /// # Errors
    /// Animation produced a non-finite vertex.
    pub fn render_frame_with_view(
        &mut self,
        frame: u32,
        time_s: f32,
        lod_view: bool,
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
        let view = lod_view.then(|| {
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
        if self.instances.is_none() {
            self.first_frame(&scales, &mut stats).map_err(accel_error)?;
        } else {
            self.update_moved(&scales, &mut stats);
            self.check_moved_finite().map_err(accel_error)?;
            self.update_accel(&mut stats).map_err(accel_error)?;
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
        stats.sah_ratio = self.accel.sah_ratio();
        let world = &self.pose.world_from_node;
        Ok(PreparedFrame {
            camera: self.camera(world),
            lights: self.lights(world),
            update: stats,
        })
    }

    /// First frame: every triangle placed, the tree built, every `log2 P_b` computed.
    fn first_frame(
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
            for slot in 0..self.triangles.len() as u32 {
                if self.set_log2_pb(slot, &states) {
                    stats.lod_recomputed += 1;
                }
            }
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
            .map(|(inst, &deforms)| InstanceState {
                world_from_object: self.pose.world_from_node[inst.node as usize],
                shape: if deforms {
                    None
                } else {
                    scales[inst.node as usize]
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
    fn update_moved(&mut self, scales: &[Option<NodeShape>], stats: &mut UpdateStats) {
        let t = Instant::now();
        self.dirty.reset(self.triangles.len());
        let previous = self.instances.take().unwrap_or_default();
        let current = self.instance_states(scales);
        let mut classify_ms = ms_since(t);
        for (i, (now, before)) in current.iter().zip(&previous).enumerate() {
            if self.deforms[i] {
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
            true,
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
    fn check_moved_finite(&self) -> Result<(), AccelError> {
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

    /// Refits the tree to the dirty triangles, or rebuilds it when the policy asks.
    fn update_accel(&mut self, stats: &mut UpdateStats) -> Result<(), AccelError> {
        if self.dirty.is_empty() {
            return Ok(());
        }
        let rebuild_every_frame = self.settings.bvh == BvhPolicy::Rebuild;
        if !rebuild_every_frame {
            let t = Instant::now();
            let kind = self.accel.refit(&self.triangles, &self.dirty.slots);
            stats.refit_ms = ms_since(t);
            debug_assert_ne!(kind, RefitKind::None);
            if !self.settings.bvh.wants_rebuild(self.accel.sah_ratio()) {
                return Ok(());
            }
        }
        let t = Instant::now();
        // A rebuild reorders the slots; carry the dirty marks over by source triangle.
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

    /// `log2 P_b` for the dirty triangles: recomputed where deformed, shifted where scaled,
    /// kept where rigid.
    fn update_dirty_log2_pb(&mut self, stats: &mut UpdateStats) {
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
    fn set_log2_pb(&mut self, slot: u32, states: &[InstanceState]) -> bool {
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

    /// What the integrator reads for a prepared frame (valid until the next `prepare`).
    pub fn frame_scene<'a>(&'a self, prepared: &'a PreparedFrame) -> FrameScene<'a> {
        FrameScene {
            triangles: &self.triangles,
            accel: &self.accel,
            materials: &self.geometry.materials,
            textures: &self.scene.textures,
            lights: &prepared.lights,
            background: Vec3A::from(self.scene.background),
            nff_ambient: Vec3A::from(self.scene.ambient.unwrap_or(Vec3::ONE)),
            lod: self.settings.lod,
            lod_bias: self.settings.lod_bias,
            lod_camera: LodCamera::new(&prepared.camera),
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
            triangles: self.triangles.len(),
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
                    &self.scene.lights[self.scene.nodes[node].light.unwrap_or(0)],
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

/// Axis-aligned bounds of the finite vertices (a unit box when there are none).
fn bounds(triangles: &FrameTriangles) -> (Vec3, Vec3) {
    let mut min = Vec3::splat(f32::INFINITY);
    let mut max = Vec3::splat(f32::NEG_INFINITY);
    for p in triangles
        .positions
        .iter()
        .flatten()
        .filter(|p| p.is_finite())
    {
        min = min.min(Vec3::from(*p));
        max = max.max(Vec3::from(*p));
    }
    if min.cmple(max).all() {
        (min, max)
    } else {
        (Vec3::splat(-1.0), Vec3::splat(1.0))
    }
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// `log2 P_b` of a similarity-placed triangle: the object-space constant plus `log2 s`
/// (world area scales by `s^2`, and `log2 P_b` holds half the log of the area).
fn shift_log2_pb(object: f32, log2_scale: f64) -> f32 {
    if object.abs() >= LOG2_PB_LIMIT {
        return object; // degenerate stand-ins stay at their limit
    }
    ((object as f64 + log2_scale) as f32).clamp(-LOG2_PB_LIMIT, LOG2_PB_LIMIT)
}

/// `log2 P_b` of every source triangle from its rest vertices in object space; NaN where the
/// material is untextured.
fn object_space_log2_pb(
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
