//! One frame of the frame loop: animate -> world triangles -> BVH -> `log2 P_b` -> render,
//! each step timed into a [`FrameRecord`].
//!
//! Invariant: a frame is a pure function of the scene, the settings and its time, so any
//! frame can be rendered alone (or on another machine) and match a sequential run.
//! The walking skeleton rebuilds the BVH and recomputes every `log2 P_b` each frame; the
//! dirty-set refit and selective LOD update come with the frame-loop issue.

use std::time::Instant;

use glam::{Vec3, Vec3A};
use serde::Serialize;

use crate::accel::{Accel, AccelError};
use crate::anim::node_world_transforms;
use crate::geometry::{FrameTriangles, SceneGeometry};
use crate::lod::{LodMethod, PixelFootprint, log2_pb};
use crate::render::light::ring_lights;
use crate::render::{Camera, FrameScene, Light, LinearImage, TraceCounters, render_image};
use crate::scene::SceneDesc;

/// How frames are rendered (the CLI's render options).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub lod: LodMethod,
    /// Samples per pixel (stratified).
    pub spp: u32,
    /// Maximum number of reflection/refraction bounces.
    pub max_depth: u32,
    /// Number of lights: the scene's first N, plus ring lights when it has fewer.
    /// `None`: all of the scene's lights (at least one).
    pub lights: Option<usize>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 640,
            height: 360,
            lod: LodMethod::Paper,
            spp: 1,
            max_depth: 5,
            lights: None,
        }
    }
}

/// What one frame cost and produced: one line of `stats.jsonl`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct FrameRecord {
    pub frame: u32,
    pub time_s: f32,
    pub width: u32,
    pub height: u32,
    pub lod_method: String,
    pub triangles: usize,
    pub lights: usize,
    pub spp: u32,
    /// Node transforms at the frame time and world-space triangles.
    pub animate_ms: f64,
    /// BVH build over the frame's triangles, including the reorder into BVH order.
    pub build_ms: f64,
    /// `log2 P_b` for the frame's textured triangles (0 for methods that do not use it).
    pub lod_update_ms: f64,
    /// Triangles whose `log2 P_b` was computed this frame.
    pub lod_recomputed: usize,
    pub render_ms: f64,
    /// Everything above plus camera/light placement (not the file write).
    pub total_ms: f64,
    /// All rays traced: primary, shadow, reflection, refraction.
    pub rays: u64,
    /// Texture lookups per integer level (floor of the clamped level), index 0 = level 0.
    pub mip_histogram: Vec<u64>,
    /// Samples that came out NaN/inf and were written as black (expected 0).
    pub nonfinite_samples: u64,
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

/// One frame after its update: the BVH, camera and lights, and what the update cost.
pub struct PreparedFrame {
    pub accel: Accel,
    pub camera: Camera,
    pub lights: Vec<Light>,
    pub animate_ms: f64,
    pub build_ms: f64,
    pub lod_update_ms: f64,
    pub lod_recomputed: usize,
}

/// Renders frames of one scene; owns the per-frame scratch buffers.
pub struct Renderer {
    scene: SceneDesc,
    geometry: SceneGeometry,
    settings: RenderSettings,
    /// Node whose camera is used (first in traversal order), if any.
    camera_node: Option<usize>,
    /// Scene bounds at t = 0: frames the scene without a camera and places added lights.
    rest_bounds: (Vec3, Vec3),
    footprint: PixelFootprint,
    /// Scratch for the frame's triangles, reused across frames.
    triangles: FrameTriangles,
}

impl Renderer {
    pub fn new(scene: SceneDesc, settings: RenderSettings) -> Renderer {
        let geometry = SceneGeometry::new(&scene);
        let mut triangles = FrameTriangles::default();
        geometry.world_triangles(&scene, &node_world_transforms(&scene, 0.0), &mut triangles);
        let rest_bounds = bounds(&triangles);
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
        Renderer {
            scene,
            geometry,
            settings,
            camera_node,
            rest_bounds,
            footprint,
            triangles,
        }
    }

    pub fn scene(&self) -> &SceneDesc {
        &self.scene
    }

    pub fn settings(&self) -> &RenderSettings {
        &self.settings
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
        let start = Instant::now();
        let prepared = self.prepare(frame, time_s)?;
        let t = Instant::now();
        let (image, counters) = render_image(
            &self.frame_scene(&prepared),
            &prepared.camera,
            self.settings.spp.max(1),
        );
        let render_ms = ms_since(t);
        let p = &prepared;
        let ms = [
            p.animate_ms,
            p.build_ms,
            p.lod_update_ms,
            render_ms,
            ms_since(start),
        ];
        let record = self.record(
            frame,
            time_s,
            p.lights.len(),
            counters,
            ms,
            p.lod_recomputed,
        );
        Ok((image, record))
    }

    /// The per-frame update without the render: animate, build the BVH, update `log2 P_b`,
    /// place camera and lights.
    ///
    /// # Errors
    /// Animation produced a non-finite vertex.
    pub fn prepare(&mut self, frame: u32, time_s: f32) -> Result<PreparedFrame, FrameError> {
        let start = Instant::now();
        let world = node_world_transforms(&self.scene, time_s);
        self.geometry
            .world_triangles(&self.scene, &world, &mut self.triangles);
        let animate_ms = ms_since(start);

        let t = Instant::now();
        let accel = Accel::build(&mut self.triangles).map_err(|source| FrameError::Accel {
            frame,
            time_s,
            source,
        })?;
        let build_ms = ms_since(t);

        let t = Instant::now();
        let lod_recomputed = if self.settings.lod.needs_log2_pb() {
            self.update_log2_pb()
        } else {
            0
        };
        let lod_update_ms = ms_since(t);

        Ok(PreparedFrame {
            accel,
            camera: self.camera(&world),
            lights: self.lights(&world),
            animate_ms,
            build_ms,
            lod_update_ms,
            lod_recomputed,
        })
    }

    /// What the integrator reads for a prepared frame (valid until the next `prepare`).
    pub fn frame_scene<'a>(&'a self, prepared: &'a PreparedFrame) -> FrameScene<'a> {
        FrameScene {
            triangles: &self.triangles,
            accel: &prepared.accel,
            materials: &self.geometry.materials,
            textures: &self.scene.textures,
            lights: &prepared.lights,
            background: Vec3A::from(self.scene.background),
            lod: self.settings.lod,
            max_depth: self.settings.max_depth,
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn record(
        &self,
        frame: u32,
        time_s: f32,
        lights: usize,
        counters: TraceCounters,
        ms: [f64; 5],
        lod_recomputed: usize,
    ) -> FrameRecord {
        let [animate_ms, build_ms, lod_update_ms, render_ms, total_ms] = ms;
        FrameRecord {
            frame,
            time_s,
            width: self.settings.width,
            height: self.settings.height,
            lod_method: self.settings.lod.to_string(),
            triangles: self.triangles.len(),
            lights,
            spp: self.settings.spp.max(1),
            animate_ms,
            build_ms,
            lod_update_ms,
            lod_recomputed,
            render_ms,
            total_ms,
            rays: counters.rays,
            mip_histogram: counters.mip_histogram.to_vec(),
            nonfinite_samples: counters.nonfinite_samples,
        }
    }

    /// Computes `log2 P_b` for every textured triangle; returns how many.
    fn update_log2_pb(&mut self) -> usize {
        let mut computed = 0;
        let tris = &mut self.triangles;
        for slot in 0..tris.positions.len() {
            let material = &self.geometry.materials[tris.material[slot] as usize];
            let Some(texture) = material
                .base_color_texture
                .and_then(|t| self.scene.textures.get(t))
            else {
                continue;
            };
            tris.log2_pb[slot] = log2_pb(
                tris.positions[slot],
                tris.uvs[slot],
                texture.pyramid.base_size(),
                self.footprint,
            );
            computed += 1;
        }
        computed
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
