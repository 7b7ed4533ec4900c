//! What a renderer knows before its first frame and never changes: the scene, its drawn
//! instances and where each gets its vertices, the settings, and the view constants (which
//! node's camera is used, the rest bounds that frame a scene without a camera and place
//! added lights, the pixel footprint `log2 P_b` is measured with). Every step of the frame
//! loop borrows it; none writes it.

use glam::{Mat4, Vec3};

use super::layout::{LayoutPlan, RestView, VIEW_SAMPLES, ViewSample};
use super::posed::{VertexSource, posed_bounds};
use super::scene_geometry::SceneGeometry;
use super::settings::RenderSettings;
use super::update::UpdateParallelism;
use crate::anim::{Pose, primitive_deforms};
use crate::lod::PixelFootprint;
use crate::render::Camera;
use crate::render::Light;
use crate::render::light::ring_lights;
use crate::scene::SceneDesc;

/// The fixed inputs of every frame.
pub(super) struct FrameSetup {
    pub scene: SceneDesc,
    pub geometry: SceneGeometry,
    pub settings: RenderSettings,
    /// Per instance: placed rest vertices, or skinned/morphed ones.
    pub deforms: Vec<VertexSource>,
    /// When the update splits its steps across rayon's threads.
    pub parallelism: UpdateParallelism,
    /// Node whose camera is used (first in traversal order), if any.
    camera_node: Option<usize>,
    /// The nodes with a light, in traversal order.
    light_nodes: Vec<usize>,
    /// Scene bounds at t = 0: frames the scene without a camera and places added lights.
    rest_bounds: (Vec3, Vec3),
    /// The pixel footprint every `log2 P_b` is measured with.
    pub footprint: PixelFootprint,
    /// Which instances are placed as instances of shared meshes (decided once, at t = 0).
    pub layout: LayoutPlan,
}

impl FrameSetup {
    /// The setup of `scene` under `settings`, and the scene posed at t = 0 (what the rest
    /// bounds were measured on; the animation state reuses its buffers).
    pub fn new(scene: SceneDesc, settings: RenderSettings) -> (FrameSetup, Pose) {
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
        let in_order = |has: fn(&crate::scene::NodeDesc) -> bool| {
            scene
                .traversal_order()
                .into_iter()
                .filter(|&i| has(&scene.nodes[i]))
                .collect::<Vec<usize>>()
        };
        let camera_node = in_order(|n| n.camera.is_some()).first().copied();
        let light_nodes = in_order(|n| n.light.is_some());
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
        let lights = settings.lights.unwrap_or(light_nodes.len().max(1));
        let samples = view_samples(&scene, &settings, &pose, camera_node, yfov, rest_bounds);
        let layout = LayoutPlan::new(
            &scene,
            &geometry,
            &deforms,
            settings.animation,
            &pose,
            &samples,
            settings.layout,
            rays_per_frame(&settings, lights),
        );
        let setup = FrameSetup {
            scene,
            geometry,
            settings,
            deforms,
            parallelism: UpdateParallelism::Auto,
            camera_node,
            light_nodes,
            rest_bounds,
            footprint,
            layout,
        };
        (setup, pose)
    }

    /// Whether the LOD method reads `log2 P_b` (else no step keeps it up to date).
    pub fn needs_log2_pb(&self) -> bool {
        self.settings.lod.needs_log2_pb()
    }

    /// Number of lights each frame is lit by.
    pub fn light_count(&self) -> usize {
        self.settings
            .lights
            .unwrap_or(self.light_nodes.len().max(1))
    }

    /// The camera for the node transforms `world`.
    pub fn camera(&self, world: &[Mat4]) -> Camera {
        let (w, h) = (self.settings.width, self.settings.height);
        match self.camera_node {
            Some(node) => {
                let desc = self.scene.cameras[self.scene.nodes[node].camera.unwrap_or(0)];
                Camera::from_world(world[node], desc.yfov, w, h)
            }
            None => Camera::framing(self.rest_bounds.0, self.rest_bounds.1, w, h),
        }
    }

    /// The scene's first [`Self::light_count`] lights placed by `world`, plus ring lights
    /// around the rest bounds when the scene has fewer.
    pub fn lights(&self, world: &[Mat4]) -> Vec<Light> {
        let wanted = self.light_count();
        let mut lights: Vec<Light> = self
            .light_nodes
            .iter()
            .take(wanted)
            .map(|&node| {
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

    /// Level-0 size of the base-colour texture of source triangle `source`'s material.
    pub fn texture_size(&self, source: usize) -> Option<(u32, u32)> {
        self.instance_texture_size(self.geometry.triangle_instance[source] as usize)
    }

    /// Level-0 size of the base-colour texture of instance `instance`'s material.
    pub fn instance_texture_size(&self, instance: usize) -> Option<(u32, u32)> {
        let instance = self.geometry.instances[instance];
        let material = &self.geometry.materials[instance.material as usize];
        let texture = self.scene.textures.get(material.base_color_texture?)?;
        Some(texture.pyramid.base_size())
    }
}

/// Rays a frame traces, as the layout's cost model estimates them: per sample a primary
/// ray and a shadow ray per light (bounces and misses left out).
fn rays_per_frame(settings: &RenderSettings, lights: usize) -> f64 {
    let samples = settings.width as f64 * settings.height as f64 * settings.spp.max(1) as f64;
    samples * (1 + lights) as f64
}

/// The scene and its camera at [`VIEW_SAMPLES`] times spread evenly over the selected
/// animation (only t = 0, `rest`, when nothing plays), for the layout's cost model.
fn view_samples(
    scene: &SceneDesc,
    settings: &RenderSettings,
    rest: &Pose,
    camera_node: Option<usize>,
    yfov: f32,
    rest_bounds: (Vec3, Vec3),
) -> Vec<ViewSample> {
    let duration = settings.animation.duration(scene);
    let times = if duration > 0.0 && duration.is_finite() {
        VIEW_SAMPLES
    } else {
        1
    };
    let (w, h) = (settings.width, settings.height);
    let mut pose = Pose::default();
    (0..times)
        .map(|k| {
            let posed = if k == 0 {
                rest
            } else {
                let t = duration * k as f32 / (times - 1) as f32;
                pose.evaluate(scene, settings.animation, t);
                &pose
            };
            let camera = match camera_node {
                Some(node) => Camera::from_world(posed.world_from_node[node], yfov, w, h),
                None => Camera::framing(rest_bounds.0, rest_bounds.1, w, h),
            };
            ViewSample {
                world_from_node: posed.world_from_node.clone(),
                view: RestView::of(&camera),
            }
        })
        .collect()
}
