//! The frame loop under the two-level BVH (`--bvh two-level`, or `--bvh auto` when it
//! instances some mesh): every instance the layout plan (`layout.rs`) places as an instance
//! of a shared object-space mesh updates nothing but its transform. Every other instance
//! (skinned and morphed ones, static ones, and under `auto` the moving ones whose update
//! costs less than instancing them) keeps the flat path (its triangles in world space,
//! refitted or rebuilt by the policy) in one world-space tree. The top-level tree over the
//! moving instances is rebuilt when one of them moved; the one over static instances (a mesh
//! whose static copies would cost too much memory merged) is built once.
//!
//! The `log2 P_b` of a placed instance follows the flat rules (`log2_pb.rs`), evaluated at
//! the hit from the object-space constant and the instance's shape key (`PbRule`), so a
//! moving instance costs nothing per triangle. The update's counters keep their meaning:
//! `moved_triangles`, `deformed_triangles`, `lod_recomputed` and `lod_shifted` count what
//! changed exactly as under the flat tree; the timings say what was paid.

use std::collections::HashMap;

use glam::{Mat4, Vec3, Vec3A};

use super::Motion;
use super::animation::InstanceState;
use super::setup::FrameSetup;
use crate::accel::{AccelError, TlasInstance, TwoLevelAccel};
use crate::anim::{NodeShape, moving_nodes};
use crate::geometry::{FrameTriangles, Placement};
use crate::record::UpdateStats;
use crate::render::{InstanceShading, PbRule};

/// What the two-level structure keeps between frames (part of the tree state).
#[derive(Default)]
pub(super) struct TwoLevel {
    pub accel: TwoLevelAccel,
    /// Per scene instance: the shared mesh it places, `None` when its triangles are in the
    /// world tree.
    pub mesh_of: Vec<Option<u32>>,
    /// Per placed instance, in scene order (the index hits report): its scene instance.
    pub placed: Vec<u32>,
    /// Per placed instance: how its triangles are shaded this frame.
    pub shading: Vec<InstanceShading>,
    /// Per placed instance: whether its node never moves (its top-level tree is built once).
    pub fixed: Vec<bool>,
    /// Per placed instance: its base-colour texture's level-0 size ((1, 1) when none).
    pub texture_size: Vec<(u32, u32)>,
    /// Per scene instance: its textured triangles (what `lod_*` counters count).
    pub textured: Vec<usize>,
}

/// Which placed instances [`TwoLevel::place_instances`] places.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Which {
    All,
    Moving,
}

/// What a frame's placed instances changed, counted as the flat update would.
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct PlacedChanges {
    pub moved: usize,
    pub deformed: usize,
    pub lod_recomputed: usize,
    pub lod_shifted: usize,
}

impl TwoLevel {
    /// First frame: which instances place shared meshes, and the meshes' trees (the caller
    /// then writes the other instances' triangles, builds the world tree over them and
    /// places the instances). `object_log2_pb`: per source triangle, its object-space
    /// constant (NaN where untextured).
    pub fn build(setup: &FrameSetup, object_log2_pb: &[f32]) -> Result<TwoLevel, AccelError> {
        let mut two = TwoLevel::default();
        let moving = moving_nodes(&setup.scene, setup.settings.animation);
        let mut mesh_of_key: HashMap<(u32, u32), u32> = HashMap::new();
        let mut meshes = Vec::new();
        for (i, instance) in setup.geometry.instances.iter().enumerate() {
            let range = setup.geometry.instance_triangles[i].clone();
            two.textured.push(
                range
                    .clone()
                    .filter(|&s| !object_log2_pb[s as usize].is_nan())
                    .count(),
            );
            let key = (instance.mesh, instance.primitive);
            let fixed = !moving[instance.node as usize];
            if !setup.layout.instanced[i] {
                two.mesh_of.push(None);
                continue;
            }
            let mesh = match mesh_of_key.get(&key) {
                Some(&mesh) => mesh,
                None => {
                    let triangles = object_triangles(setup, object_log2_pb, i);
                    // Named by the scene's source triangle, as the flat path names it.
                    let first = setup.geometry.instance_triangles[i].start as usize;
                    for (local, tri) in triangles.positions.iter().enumerate() {
                        if let Some(v) = tri.iter().find(|v| !v.is_finite()) {
                            return Err(AccelError::NonFiniteVertex {
                                triangle: first + local,
                                vertex: v.to_array(),
                            });
                        }
                    }
                    meshes.push(triangles);
                    mesh_of_key.insert(key, meshes.len() as u32 - 1);
                    meshes.len() as u32 - 1
                }
            };
            two.mesh_of.push(Some(mesh));
            two.placed.push(i as u32);
            two.fixed.push(fixed);
            // By instance, not by its first triangle: an instance may have none.
            two.texture_size
                .push(setup.instance_texture_size(i).unwrap_or((1, 1)));
        }
        two.accel = TwoLevelAccel::new(meshes)?;
        Ok(two)
    }

    /// This frame's placements of the placed instances and the top-level tree over them:
    /// every instance on the first frame (`Which::All`), then only those of moving nodes
    /// (the others never move: their tree is built once).
    ///
    /// # Errors
    /// A placement that makes a vertex non-finite (as the flat path reports it: the first
    /// such triangle of the first such instance).
    pub fn place_instances(
        &mut self,
        setup: &FrameSetup,
        states: &[InstanceState],
        which: Which,
    ) -> Result<(), AccelError> {
        if which == Which::All {
            self.shading.clear();
            self.shading.resize(
                self.placed.len(),
                InstanceShading {
                    placement: Placement::new(Mat4::IDENTITY),
                    mesh: 0,
                    source_base: 0,
                    pb: PbRule::World,
                    texture_size: (1, 1),
                },
            );
        }
        let (mut fixed, mut moving) = (Vec::new(), Vec::new());
        for (k, &i) in self.placed.iter().enumerate() {
            let i = i as usize;
            if which == Which::Moving && self.fixed[k] {
                continue;
            }
            let state = states[i];
            let mesh = self.mesh_of[i].unwrap_or(0);
            let source_base = setup.geometry.instance_triangles[i].start;
            let placement = Placement::new(state.world_from_object);
            self.shading[k] = InstanceShading {
                placement,
                mesh,
                source_base,
                pb: pb_rule(state.shape),
                texture_size: self.texture_size[k],
            };
            let instance = TlasInstance {
                index: k as u32,
                mesh,
                world_from_object: state.world_from_object,
                source_base,
            };
            if self.fixed[k] {
                fixed.push(instance);
            } else {
                moving.push(instance);
            }
        }
        let mut placed = self.accel.set_instances(&moving);
        if which == Which::All {
            placed = self.accel.set_fixed_instances(&fixed).and(placed);
        }
        let Err(k) = placed else {
            return Ok(());
        };
        let i = self.placed[k as usize] as usize;
        let placement = Placement::new(states[i].world_from_object);
        let primitive = setup.geometry.primitive(&setup.scene, i);
        for source in setup.geometry.instance_triangles[i].clone() {
            let (p, _) = setup.geometry.world_triangle(
                &setup.scene,
                source,
                &placement,
                &primitive.positions,
                None,
            );
            if let Some(v) = p.iter().find(|v| !v.is_finite()) {
                return Err(AccelError::NonFiniteVertex {
                    triangle: source as usize,
                    vertex: v.to_array(),
                });
            }
        }
        // The box overflowed though no vertex did (its corners lie further out).
        Err(AccelError::NonFiniteVertex {
            triangle: setup.geometry.instance_triangles[i].start as usize,
            vertex: [f32::INFINITY; 3],
        })
    }

    /// The counters of the placed instances that moved between `previous` and `current`.
    pub fn placed_changes(
        &self,
        setup: &FrameSetup,
        current: &[InstanceState],
        previous: &[InstanceState],
    ) -> PlacedChanges {
        let mut changes = PlacedChanges::default();
        let lod = setup.needs_log2_pb();
        for &i in &self.placed {
            let i = i as usize;
            let (now, before) = (&current[i], &previous[i]);
            if now.world_from_object == before.world_from_object {
                continue;
            }
            let count = setup.geometry.instance_triangles[i].len();
            changes.moved += count;
            match super::update::placed_motion(now.shape, before.shape) {
                Motion::Deformed => {
                    changes.deformed += count;
                    changes.lod_recomputed += if lod { self.textured[i] } else { 0 };
                }
                Motion::Scaled => changes.lod_shifted += if lod { self.textured[i] } else { 0 },
                Motion::Rigid => {}
            }
        }
        changes
    }

    /// The first frame's `lod_recomputed` share of the placed instances (their constants
    /// come from the object-space ones computed at load).
    pub fn placed_textured(&self) -> usize {
        self.placed.iter().map(|&i| self.textured[i as usize]).sum()
    }
}

/// Instance `i`'s triangles in object space as the shared tree stores them: the mesh's
/// winding, its normals as stored (zero where it has none), the object-space `log2 P_b`
/// (NaN where untextured) and the mesh's own triangle index as `source`.
fn object_triangles(setup: &FrameSetup, object_log2_pb: &[f32], i: usize) -> FrameTriangles {
    let geometry = &setup.geometry;
    let primitive = geometry.primitive(&setup.scene, i);
    let range = geometry.instance_triangles[i].clone();
    let material = geometry.instances[i].material;
    let mut t = FrameTriangles::default();
    for (local, source) in range.enumerate() {
        let v = geometry.triangle_vertices(&setup.scene, source);
        t.positions
            .push(v.map(|k| Vec3A::from(primitive.positions[k as usize])));
        t.normals.push(v.map(|k| match &primitive.normals {
            Some(n) => n[k as usize],
            None => Vec3::ZERO,
        }));
        t.uvs.push(geometry.triangle_uvs(&setup.scene, source));
        t.material.push(material);
        t.log2_pb.push(object_log2_pb[source as usize]);
        t.source.push(local as u32);
    }
    t
}

/// The `log2 P_b` rule of a placed instance with shape key `shape` (see `log2_pb.rs`).
fn pb_rule(shape: Option<NodeShape>) -> PbRule {
    match shape {
        Some(NodeShape {
            scale,
            stretch: None,
        }) => PbRule::Shift {
            log2_scale: scale.log2(),
        },
        Some(shape) => {
            let [x, y, z] = shape.diagonal();
            PbRule::Stretched(Placement::new(Mat4::from_scale(Vec3::new(
                x as f32, y as f32, z as f32,
            ))))
        }
        None => PbRule::World,
    }
}

impl PlacedChanges {
    /// Adds these changes to the frame's counters.
    pub fn add_to(self, stats: &mut UpdateStats) {
        stats.moved_triangles += self.moved;
        stats.deformed_triangles += self.deformed;
        stats.lod_recomputed += self.lod_recomputed;
        stats.lod_shifted += self.lod_shifted;
    }
}
