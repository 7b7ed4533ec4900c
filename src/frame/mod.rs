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

mod animation;
pub mod appearance;
mod clock;
mod dirty;
mod layout;
mod log2_pb;
mod posed;
mod scatter;
mod scene_geometry;
mod settings;
mod setup;
mod slot_vertices;
mod two_level;
mod update;

pub use crate::accel::{BvhLayout, BvhPolicy};
pub use clock::FrameClock;
pub use dirty::{DirtySet, Motion};
pub use layout::{
    BYTES_PER_TRIANGLE, Choice, CopyMotion, CopyUse, ENTRY_NS_PER_RAY, LayoutPlan,
    MERGE_BUDGET_TRIANGLES, MeshChoice, MeshPlan, MeshUse, PLACE_NS_PER_INSTANCE,
    REFIT_NS_PER_TRIANGLE, Reason, TOP_LEVEL_NS_PER_RAY, UsedLayout, decide_auto,
    decide_auto_scene, decide_two_level,
};
pub use scene_geometry::{Instance, SceneGeometry};
pub use settings::RenderSettings;
pub use update::UpdateParallelism;

use std::time::Instant;

use glam::{Vec3, Vec3A};

use crate::accel::{Accel, AccelError};
use crate::geometry::{FrameTriangles, VertexNormals};
use crate::lod::LodCamera;
use crate::record::{FrameRecord, UpdateStats};
use crate::render::{
    Camera, FrameScene, Instanced, Light, LinearImage, SceneBvh, TraceCounters, render_image,
};
use crate::scene::SceneDesc;
use animation::AnimationState;
use dirty::FrameChanges;
use log2_pb::Log2PbState;
use posed::VertexSource;
use setup::FrameSetup;
use update::TreeState;

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

/// Renders frames of one scene. Its state is split by the step of the frame loop that
/// owns it: each step is one method that borrows the fixed setup and the parts it reads,
/// and writes only its own part.
///
/// | step | method | reads | writes |
/// |---|---|---|---|
/// | animate | `AnimationState::advance` | setup, time | animation |
/// | dirty set | `TreeState::mark_moved` | setup, animation | tree (triangles), changes |
/// | refit or rebuild | `TreeState::refit_or_rebuild` | setup, animation | tree, changes (slot order) |
/// | `log2 P_b` | `Log2PbState::update` | setup, animation, changes | `log2 P_b` state, tree's constants |
/// | render | `render_image` over [`Renderer::frame_scene`] | all of it | the image |
///
/// (The first frame builds the tree instead: `TreeState::build`, then
/// `Log2PbState::recompute_all`.)
pub struct Renderer {
    /// What never changes between frames: scene, geometry, settings, view constants.
    setup: FrameSetup,
    /// This frame's pose, shapes and instance placements, and the previous frame's.
    animation: AnimationState,
    /// The triangles in slot order and their trees.
    tree: TreeState,
    /// What moved this frame.
    changes: FrameChanges,
    /// The constants `log2 P_b` is kept from, and the per-slot texel terms.
    log2_pb: Log2PbState,
}

/// The normals of the slots of deforming instances, read from the posed vertices their
/// slots were written from.
impl VertexNormals for Renderer {
    #[inline]
    fn normals(&self, source: u32, positions: &[Vec3A; 3]) -> Option<[Vec3; 3]> {
        let setup = &self.setup;
        self.tree.posed().deformed_normals(
            &setup.scene,
            &setup.geometry,
            &setup.deforms,
            source,
            positions,
        )
    }
}

impl Renderer {
    pub fn new(scene: SceneDesc, settings: RenderSettings) -> Renderer {
        let (setup, rest_pose) = FrameSetup::new(scene, settings);
        let log2_pb = Log2PbState::new(&setup);
        Renderer {
            setup,
            animation: AnimationState::new(rest_pose),
            tree: TreeState::default(),
            changes: FrameChanges::default(),
            log2_pb,
        }
    }

    /// Sets when the per-frame update splits across rayon's threads (default
    /// [`UpdateParallelism::Auto`]); the results do not depend on it, only the time.
    pub fn set_update_parallelism(&mut self, parallelism: UpdateParallelism) {
        self.setup.parallelism = parallelism;
    }

    pub fn scene(&self) -> &SceneDesc {
        &self.setup.scene
    }

    pub fn settings(&self) -> &RenderSettings {
        &self.setup.settings
    }

    /// The frame's world-space triangles in BVH order (valid after `prepare`): every
    /// triangle under the flat BVH; under the two-level one only the world tree's (skinned,
    /// morphed and static instances: the shared meshes' instances keep theirs in object
    /// space). Their vertices are in the tree: [`Renderer::accel`]`.triangle(slot)`, or all
    /// of them copied by [`Renderer::world_positions`].
    pub fn triangles(&self) -> &FrameTriangles {
        &self.tree.triangles
    }

    /// Slot `slot`'s world-space shading normals (valid after `prepare`): stored in
    /// [`Renderer::triangles`] for most instances, read through the vertex indices from the
    /// posed vertices for skinned and morphed ones (`geometry::VertexNormals`).
    pub fn slot_normals(&self, slot: usize) -> [Vec3; 3] {
        let positions = self.tree.accel.triangle(slot as u32);
        self.tree
            .triangles
            .hit_triangle(slot, positions, Some(self))
            .normals
    }

    /// The vertices of [`Renderer::triangles`], slot by slot (a copy, read from the tree).
    pub fn world_positions(&self) -> Vec<[Vec3A; 3]> {
        self.tree.accel.triangles_in_slot_order()
    }

    /// Which meshes are placed as instances and which merged into the world tree, and why
    /// (decided when the renderer was made).
    pub fn layout(&self) -> &LayoutPlan {
        &self.setup.layout
    }

    /// The current BVH (valid after `prepare`).
    pub fn accel(&self) -> &Accel {
        &self.tree.accel
    }

    /// The scene's drawn instances and source triangles.
    pub fn geometry(&self) -> &SceneGeometry {
        &self.setup.geometry
    }

    /// Materials indexed by `FrameTriangles::material` (the scene's, plus a default last).
    pub fn materials(&self) -> &[crate::render::Material] {
        &self.setup.geometry.materials
    }

    /// What moved in the last `prepare` (empty after the first frame's: everything was new).
    pub fn dirty(&self) -> &DirtySet {
        &self.changes.dirty
    }

    /// Number of lights each frame is lit by.
    pub fn light_count(&self) -> usize {
        self.setup.light_count()
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
            self.setup.settings.spp.max(1),
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
        self.animation.advance(&self.setup, time_s);
        let pose_ms = ms_since(pose_start);
        let updated = if self.tree.is_carried() {
            self.update(&mut stats)
        } else {
            self.first_frame(&mut stats)
        };
        if let Err(source) = updated {
            // The carried state is half updated: the next frame starts afresh.
            self.tree.reset();
            return Err(FrameError::Accel {
                frame,
                time_s,
                source,
            });
        }
        // Evaluating the animation belongs to the animate phase too.
        stats.animate_ms += pose_ms;
        stats.moved_triangles = self.changes.dirty.len();
        stats.deformed_triangles = self.changes.dirty.count(Motion::Deformed);
        std::mem::take(&mut self.changes.placed).add_to(&mut stats);
        stats.sah_ratio = self.tree.accel.sah_ratio();
        let world = &self.animation.pose().world_from_node;
        Ok(PreparedFrame {
            camera: self.setup.camera(world),
            lights: self.setup.lights(world),
            update: stats,
        })
    }

    /// First frame: every triangle placed, the tree built, every `log2 P_b` computed.
    fn first_frame(&mut self, stats: &mut UpdateStats) -> Result<(), AccelError> {
        let (setup, tree) = (&self.setup, &mut self.tree);
        let built = tree.build(
            setup,
            &self.animation,
            &self.log2_pb.object,
            &mut self.changes,
        )?;
        stats.animate_ms = built.write_ms;
        stats.build_ms = built.build_ms + self.index_slots();
        stats.rebuild = true;
        let t = Instant::now();
        if self.setup.needs_log2_pb() {
            let states = self.animation.instances();
            let tree = &mut self.tree;
            let computed =
                self.log2_pb
                    .recompute_all(&self.setup, states, &mut tree.triangles, &tree.accel);
            stats.lod_recomputed = computed + tree.placed_textured();
        }
        stats.lod_update_ms = ms_since(t);
        Ok(())
    }

    /// A frame after the first: the dirty set, the tree's refit or rebuild, the dirty
    /// triangles' `log2 P_b`.
    fn update(&mut self, stats: &mut UpdateStats) -> Result<(), AccelError> {
        let (setup, animation) = (&self.setup, &self.animation);
        let marked = self.tree.mark_moved(setup, animation, &mut self.changes);
        stats.dirty_ms = marked.dirty_ms;
        stats.animate_ms = marked.write_ms;
        self.tree.check_moved_finite(&self.changes)?;
        let tree = self
            .tree
            .refit_or_rebuild(setup, animation, &mut self.changes)?;
        stats.refit_ms = tree.refit_ms;
        if let Some(build_ms) = tree.build_ms {
            stats.build_ms = build_ms + self.index_slots();
            stats.rebuild = true;
        }
        let t = Instant::now();
        if self.setup.needs_log2_pb() {
            let counts = self.log2_pb.update(
                &self.setup,
                self.animation.instances(),
                &self.changes,
                &mut self.tree.triangles,
                &self.tree.accel,
            );
            stats.lod_recomputed += counts.recomputed;
            stats.lod_shifted += counts.shifted;
        }
        stats.lod_update_ms = ms_since(t);
        Ok(())
    }

    /// After a build of the tree (new slot order): the per-slot texel terms again; returns
    /// the milliseconds it took (counted as building).
    fn index_slots(&mut self) -> f64 {
        let t = Instant::now();
        self.log2_pb.index_slots(&self.setup, &self.tree.triangles);
        ms_since(t)
    }

    /// What the integrator reads for a prepared frame (valid until the next `prepare`).
    pub fn frame_scene<'a>(&'a self, prepared: &'a PreparedFrame) -> FrameScene<'a> {
        let (setup, tree) = (&self.setup, &self.tree);
        // Only a scene with deforming instances has slots without stored normals.
        let by_vertex = setup
            .deforms
            .contains(&VertexSource::Deformed)
            .then_some(self as &dyn VertexNormals);
        let bvh = match &tree.two_level {
            None => SceneBvh::Flat {
                triangles: &tree.triangles,
                accel: &tree.accel,
                by_vertex,
            },
            Some(two) => SceneBvh::TwoLevel(Instanced {
                world_triangles: &tree.triangles,
                world: &tree.accel,
                by_vertex,
                accel: &two.accel,
                instances: &two.shading,
                footprint: setup.footprint,
                needs_log2_pb: setup.needs_log2_pb(),
            }),
        };
        let (scene, settings) = (&setup.scene, &setup.settings);
        FrameScene {
            bvh,
            materials: &setup.geometry.materials,
            textures: &scene.textures,
            lights: &prepared.lights,
            background: Vec3A::from(scene.background),
            additive_ambient: Vec3A::from(scene.ambient.unwrap_or(Vec3::ONE)),
            lod: settings.lod,
            lod_bias: settings.lod_bias,
            mip_filter: settings.mip_filter,
            lod_camera: LodCamera::new(&prepared.camera.view_frame()),
            max_depth: settings.max_depth,
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
        let settings = &self.setup.settings;
        FrameRecord {
            frame,
            time_s,
            width: settings.width,
            height: settings.height,
            lod_method: settings.lod.to_string(),
            lod_bias: settings.lod_bias,
            triangles: self.setup.geometry.triangle_count(),
            lights: prepared.lights.len(),
            spp: settings.spp.max(1),
            bvh_layout: self.setup.layout.used().to_string(),
            instanced_meshes: self.setup.layout.instanced_meshes(),
            update: prepared.update,
            render_ms,
            total_ms,
            rays: counters.rays,
            mip_histogram: counters.mip_histogram.to_vec(),
            nonfinite_samples: counters.nonfinite_samples,
            // The run's identity is the run layer's to stamp (`run::SequenceOutput`).
            scene: String::new(),
            scene_files: String::new(),
            settings: Default::default(),
        }
    }
}

pub(crate) fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
