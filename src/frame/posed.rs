//! Where an instance's vertices come from this frame: its mesh's rest vertices placed by its
//! node, or (for skinned and morphed primitives) the vertices `anim::deform_primitive`
//! writes, in object or world space; and the writer that turns them into a slot's
//! world-space triangle.
//!
//! Every triangle written is a pure function of the pose and its own source triangle, and
//! each instance deforms into its own buffers, so the write can run over slots on rayon's
//! threads in any split with results bit-identical to one thread's (`tests/frame_loop.rs`).

use std::sync::atomic::{AtomicBool, Ordering};

use glam::{Mat4, Vec2, Vec3, Vec3A};
use rayon::prelude::*;

use super::Motion;
use super::scene_geometry::SceneGeometry;
use crate::anim::{Pose, VertexSpace, deform_primitive};
use crate::geometry::{FrameTriangles, Placement};
use crate::scene::SceneDesc;
use crate::simd::prefetch;

/// Where an instance's vertices come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VertexSource {
    /// The mesh's rest vertices placed by the node.
    Placed,
    /// Vertices skinned and/or morphed this frame.
    Deformed,
}

impl VertexSource {
    /// `Deformed` for a skinned or morphed primitive.
    pub fn of(deforms: bool) -> VertexSource {
        if deforms {
            VertexSource::Deformed
        } else {
            VertexSource::Placed
        }
    }
}

/// One instance's vertices this frame in world space (buffers reused from frame to frame).
#[derive(Debug, Default)]
struct WorldVertices {
    /// Placed by [`Placement::place_point`].
    positions: Vec<Vec3>,
    /// Placed by [`Placement::place_normal`]; empty when the primitive has no normals.
    normals: Vec<Vec3>,
}

/// Every instance's world-space vertices and placement for one pose: rest vertices placed
/// by the node, or vertices skinned or morphed, then placed. Each instance has its own
/// buffers, so instances can be posed and written concurrently, and each shared vertex is
/// transformed once (not once per triangle that uses it).
///
/// Invariant: `placements[i]` and `vertices[i]` are this frame's for every instance the
/// frame rewrites; the others hold an earlier frame's values.
#[derive(Debug, Default)]
pub struct PosedVertices {
    /// Per instance.
    vertices: Vec<WorldVertices>,
    /// Per instance: object (or, for skinned vertices, world) to world.
    placements: Vec<Placement>,
}

/// Below this many vertices an instance is placed on the calling thread.
const PARALLEL_MIN_VERTICES: usize = 8192;

/// Vertices per parallel placement task.
const PLACE_CHUNK: usize = 4096;

impl PosedVertices {
    /// Sizes the per-instance arrays for `instances` instances (keeps allocations).
    pub fn resize(&mut self, instances: usize) {
        self.vertices.resize_with(instances, Default::default);
        self.placements
            .resize(instances, Placement::new(Mat4::IDENTITY));
    }

    /// Records placed instance `i`'s placement for this frame (before [`Self::pose`]).
    pub fn place(&mut self, i: usize, world_from_object: Mat4) {
        self.placements[i] = Placement::new(world_from_object);
    }

    /// Writes the world-space vertices of every instance `i` with `needed(i)`: a deforming
    /// instance is skinned or morphed for `pose` (which sets its placement), a placed one
    /// placed by the placement [`Self::place`] recorded. Across instances (and within large
    /// ones) on rayon's threads when `parallel`: each vertex is a pure function of its
    /// inputs, so the result does not depend on it.
    #[allow(clippy::too_many_arguments)]
    pub fn pose(
        &mut self,
        scene: &SceneDesc,
        geometry: &SceneGeometry,
        pose: &Pose,
        deforms: &[VertexSource],
        needed: impl Fn(usize) -> bool + Sync,
        parallel: bool,
    ) {
        let pose_one = |(i, (out, placement)): (usize, (&mut WorldVertices, &mut Placement))| {
            if needed(i) {
                pose_instance(scene, geometry, pose, deforms, i, out, placement, parallel);
            }
        };
        if parallel {
            (self.vertices.par_iter_mut(), self.placements.par_iter_mut())
                .into_par_iter()
                .enumerate()
                .for_each(pose_one);
        } else {
            self.vertices
                .iter_mut()
                .zip(self.placements.iter_mut())
                .enumerate()
                .for_each(pose_one);
        }
    }

    /// Instance `i`'s placement (valid for the instances this frame rewrites).
    pub fn placement(&self, i: usize) -> &Placement {
        &self.placements[i]
    }

    /// Source triangle `source`'s shading normals when its instance deforms (`None`
    /// otherwise: its slot stores them), in the winding of its slot, whose vertices are
    /// `positions`: the same bits the write would have stored (`geometry::VertexNormals`).
    /// Valid for every instance with slots: a deforming instance's vertices here are the
    /// ones its slots were last written from (every frame that poses it writes it).
    #[inline]
    pub fn deformed_normals(
        &self,
        scene: &SceneDesc,
        geometry: &SceneGeometry,
        deforms: &[VertexSource],
        source: u32,
        positions: &[Vec3A; 3],
    ) -> Option<[Vec3; 3]> {
        let i = geometry.triangle_instance[source as usize] as usize;
        if deforms[i] != VertexSource::Deformed {
            return None;
        }
        Some(geometry.placed_normals(
            geometry.triangle_vertices(scene, source),
            self.placements[i].flips_winding,
            positions,
            self.world_arrays(i).1,
        ))
    }

    /// Instance `i`'s world-space positions and normals (valid for the instances this frame
    /// rewrites).
    #[inline]
    pub fn world_arrays(&self, i: usize) -> (&[Vec3], Option<&[Vec3]>) {
        let v = &self.vertices[i];
        (
            &v.positions,
            (!v.normals.is_empty()).then_some(v.normals.as_slice()),
        )
    }
}

/// Writes instance `i`'s world-space vertices into `out`: skinned or morphed for `pose`
/// (which sets `placement`), or its rest vertices placed by `placement`.
#[allow(clippy::too_many_arguments)]
fn pose_instance(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    pose: &Pose,
    deforms: &[VertexSource],
    i: usize,
    out: &mut WorldVertices,
    placement: &mut Placement,
    parallel: bool,
) {
    if deforms[i] == VertexSource::Deformed {
        let (deformed_placement, space) = deform_instance(scene, geometry, pose, i, out);
        *placement = deformed_placement;
        // Skinned vertices come out in world space with unit (or zero) normals: the identity
        // placement would only copy them (a pass over a million vertices for nothing).
        if space == VertexSpace::Object {
            place_in_place(placement, out, parallel);
        }
    } else {
        let primitive = geometry.primitive(scene, i);
        place_rest(
            placement,
            &primitive.positions,
            primitive.normals.as_deref(),
            out,
            parallel,
        );
    }
}

/// Writes deforming instance `i`'s vertices into `out`; returns the placement that takes
/// them to world space (its node's for object-space vertices, the identity for skinned)
/// and the space they are in.
fn deform_instance(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    pose: &Pose,
    i: usize,
    out: &mut WorldVertices,
) -> (Placement, VertexSpace) {
    let instance = geometry.instances[i];
    let space = deform_primitive(
        scene,
        pose,
        instance.node as usize,
        instance.mesh as usize,
        instance.primitive as usize,
        &mut out.positions,
        &mut out.normals,
    );
    let placement = Placement::new(match space {
        VertexSpace::Object => pose.world_from_node[instance.node as usize],
        VertexSpace::World => Mat4::IDENTITY,
    });
    (placement, space)
}

/// Places `out`'s (deformed) vertices in place.
fn place_in_place(placement: &Placement, out: &mut WorldVertices, parallel: bool) {
    let split = parallel && out.positions.len() >= PARALLEL_MIN_VERTICES;
    let point = |p: &mut Vec3| *p = placement.place_point(*p);
    let normal = |n: &mut Vec3| *n = placement.place_normal(*n);
    if split {
        out.positions
            .par_iter_mut()
            .with_min_len(PLACE_CHUNK)
            .for_each(point);
        out.normals
            .par_iter_mut()
            .with_min_len(PLACE_CHUNK)
            .for_each(normal);
    } else {
        out.positions.iter_mut().for_each(point);
        out.normals.iter_mut().for_each(normal);
    }
}

/// Writes rest vertices placed by `placement` into `out`.
fn place_rest(
    placement: &Placement,
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    out: &mut WorldVertices,
    parallel: bool,
) {
    let normals = normals.unwrap_or_default();
    out.positions.resize(positions.len(), Vec3::ZERO);
    out.normals.resize(normals.len(), Vec3::ZERO);
    let point = |(p, &rest): (&mut Vec3, &Vec3)| *p = placement.place_point(rest);
    let normal = |(n, &rest): (&mut Vec3, &Vec3)| *n = placement.place_normal(rest);
    if parallel && positions.len() >= PARALLEL_MIN_VERTICES {
        out.positions
            .par_iter_mut()
            .zip(positions)
            .with_min_len(PLACE_CHUNK)
            .for_each(point);
        out.normals
            .par_iter_mut()
            .zip(normals)
            .with_min_len(PLACE_CHUNK)
            .for_each(normal);
    } else {
        out.positions.iter_mut().zip(positions).for_each(point);
        out.normals.iter_mut().zip(normals).for_each(normal);
    }
}

/// What the frame does to one instance's triangles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rewrite {
    /// Unchanged: not visited.
    Keep,
    /// Every triangle rewritten and marked with this motion.
    All(Motion),
    /// A deforming instance whose inputs changed: positions and uvs rewritten only where a
    /// vertex changed, those marked deformed (its normals are not stored by slot: they are
    /// read from the posed vertices, see [`PosedVertices::deformed_normals`]).
    Changed,
}

/// What writing one triangle reads: shared, read-only, so slots can be written from any
/// thread in any order with the same result.
pub struct TriangleWriter<'a> {
    pub scene: &'a SceneDesc,
    pub geometry: &'a SceneGeometry,
    pub posed: &'a PosedVertices,
    /// Per instance.
    pub plan: &'a [Rewrite],
    /// Per instance: whether the placement its slots' uvs were last written under mirrored
    /// (`None`: never written; empty: none were). Uvs depend only on that, so a write under
    /// the same winding leaves them alone.
    pub uv_flips: &'a [Option<bool>],
    /// Per instance: where its vertices come from (a deforming instance's slots do not
    /// store normals).
    pub deforms: &'a [VertexSource],
    /// Set when a triangle written with new vertices has a non-finite one (so the ordered
    /// search for the first such triangle runs only then).
    pub moved_nonfinite: AtomicBool,
    /// Per instance: its first source triangle and its primitive's index buffer (looked up
    /// once a frame, not once a triangle).
    indices: Vec<(u32, &'a [u32])>,
}

impl<'a> TriangleWriter<'a> {
    pub fn new(
        scene: &'a SceneDesc,
        geometry: &'a SceneGeometry,
        posed: &'a PosedVertices,
        plan: &'a [Rewrite],
        uv_flips: &'a [Option<bool>],
        deforms: &'a [VertexSource],
    ) -> Self {
        let indices = (0..geometry.instances.len())
            .map(|i| {
                let first = geometry.instance_triangles[i].start;
                (first, &geometry.primitive(scene, i).indices[..])
            })
            .collect();
        TriangleWriter {
            scene,
            geometry,
            posed,
            plan,
            uv_flips,
            deforms,
            moved_nonfinite: AtomicBool::new(false),
            indices,
        }
    }

    /// Source triangle `source`'s world-space vertices under its instance's pose (the
    /// bits [`TriangleWriter::write`] writes).
    #[inline]
    pub fn position(&self, source: u32) -> [Vec3A; 3] {
        let i = self.geometry.triangle_instance[source as usize] as usize;
        let instance = self.instance(i);
        instance.placed_positions(instance.vertices(source))
    }

    /// What writing instance `i`'s triangles reads, looked up once: the update writes an
    /// instance's triangles together, and these lookups per triangle were a fifth of the
    /// write's time on a million skinned triangles.
    #[inline]
    pub fn instance(&self, i: usize) -> InstanceWriter<'_> {
        let placement = self.posed.placement(i);
        let (positions, normals) = self.posed.world_arrays(i);
        let (first, indices) = self.indices[i];
        InstanceWriter {
            writer: self,
            rewrite: self.plan[i],
            positions,
            normals,
            first,
            indices,
            rewrites_uvs: self.uv_flips.get(i) != Some(&Some(placement.flips_winding)),
            stores_normals: self.deforms[i] != VertexSource::Deformed,
            placement,
        }
    }

    /// Writes source triangle `source` into its slot's `position`, `normal` and `uv` as its
    /// instance's [`Rewrite`] says; returns the slot's motion (`None`: unmoved).
    /// ([`InstanceWriter::write`] with the instance looked up.)
    #[inline]
    pub fn write(
        &self,
        source: u32,
        position: &mut [Vec3A; 3],
        normal: Option<&mut [Vec3; 3]>,
        uv: &mut [Vec2; 3],
    ) -> Option<Motion> {
        let i = self.geometry.triangle_instance[source as usize] as usize;
        self.instance(i).write(source, position, normal, uv)
    }
}

/// [`TriangleWriter`] for the triangles of one instance.
pub struct InstanceWriter<'a> {
    writer: &'a TriangleWriter<'a>,
    rewrite: Rewrite,
    /// The instance's world-space vertices and normals this frame.
    positions: &'a [Vec3],
    normals: Option<&'a [Vec3]>,
    /// Its first source triangle and its primitive's index buffer.
    first: u32,
    indices: &'a [u32],
    /// Whether its slots' uvs were last written under another winding (or never).
    rewrites_uvs: bool,
    /// Whether its slots store their normals (all but deforming instances').
    stores_normals: bool,
    /// Its placement (its winding decides the vertex order).
    placement: &'a Placement,
}

impl InstanceWriter<'_> {
    /// Whether the instance is a deforming one whose changed triangles the write marks
    /// ([`Rewrite::Changed`]): every slot it moves moves as [`Motion::Deformed`].
    #[inline]
    pub fn deforms_by_change(&self) -> bool {
        self.rewrite == Rewrite::Changed
    }

    /// Whether writing a slot of this instance writes its positions alone and marks it
    /// deformed where they changed: a deforming instance whose inputs changed, whose slots
    /// store no normals and keep their uvs (then the write in slot order can write a pack's
    /// lanes together, [`crate::accel::SlotLanes::rewrite_pack`]).
    #[inline]
    pub fn writes_positions_alone(&self) -> bool {
        self.rewrite == Rewrite::Changed && !self.stores_normals && !self.rewrites_uvs
    }

    /// Marks that a triangle written with new vertices has a non-finite one.
    #[inline]
    pub fn note_nonfinite(&self) {
        self.writer.moved_nonfinite.store(true, Ordering::Relaxed);
    }

    /// Source triangle `source`'s vertex indices in its primitive (as the index buffer
    /// lists them).
    #[inline]
    pub fn vertices(&self, source: u32) -> [u32; 3] {
        let at = (source - self.first) as usize * 3;
        [self.indices[at], self.indices[at + 1], self.indices[at + 2]]
    }

    /// Hints the cache to load the world-space positions and normals of primitive vertices
    /// `vertices` (the write in slot order gathers them from wherever the tree's order
    /// leads: most of its time was the wait for these loads).
    #[inline]
    pub fn prefetch_vertices(&self, vertices: [u32; 3]) {
        for v in vertices {
            prefetch(self.positions, v as usize);
            if let Some(normals) = self.normals.filter(|_| self.stores_normals) {
                prefetch(normals, v as usize);
            }
        }
    }

    /// The vertices alone of the triangle of primitive vertices `vertices` placed (what
    /// [`Self::write_vertices`] writes when [`Self::writes_positions_alone`]).
    #[inline(always)]
    pub fn placed_positions(&self, vertices: [u32; 3]) -> [Vec3A; 3] {
        self.writer.geometry.placed_positions(
            vertices,
            self.placement.flips_winding,
            self.positions,
        )
    }

    /// The triangle of primitive vertices `vertices` placed.
    #[inline]
    fn placed_vertices(&self, vertices: [u32; 3]) -> ([Vec3A; 3], [Vec3; 3]) {
        self.writer.geometry.placed_triangle(
            vertices,
            self.placement.flips_winding,
            self.positions,
            self.normals,
        )
    }

    /// Writes source triangle `source` (of this instance) into its slot's `position`,
    /// `normal` and `uv` as the instance's [`Rewrite`] says; returns the slot's motion
    /// (`None`: unmoved). `normal` is the slot's stored normals: `None` where the tree
    /// stores none, which only a tree of deforming instances does, whose writes never
    /// store them.
    #[inline]
    pub fn write(
        &self,
        source: u32,
        position: &mut [Vec3A; 3],
        normal: Option<&mut [Vec3; 3]>,
        uv: &mut [Vec2; 3],
    ) -> Option<Motion> {
        if self.rewrite == Rewrite::Keep {
            return None;
        }
        self.write_vertices(self.vertices(source), source, position, normal, uv)
    }

    /// [`Self::write`] with the triangle's vertex indices already at hand (`vertices`, as
    /// [`Self::vertices`] gives them): the write in slot order reads them from a copy in
    /// slot order instead of the index buffer.
    #[inline(always)]
    pub fn write_vertices(
        &self,
        vertices: [u32; 3],
        source: u32,
        position: &mut [Vec3A; 3],
        normal: Option<&mut [Vec3; 3]>,
        uv: &mut [Vec2; 3],
    ) -> Option<Motion> {
        let all = match self.rewrite {
            Rewrite::Keep => return None,
            Rewrite::All(motion) => Some(motion),
            Rewrite::Changed => None,
        };
        let p = if self.stores_normals {
            let (p, n) = self.placed_vertices(vertices);
            debug_assert!(normal.is_some(), "a slot that stores normals has an entry");
            if let Some(normal) = normal {
                *normal = n;
            }
            p
        } else {
            self.placed_positions(vertices)
        };
        let motion = all.or_else(|| (!same_bits(&p, position)).then_some(Motion::Deformed))?;
        if !p.iter().all(|v| v.is_finite()) {
            self.writer.moved_nonfinite.store(true, Ordering::Relaxed);
        }
        *position = p;
        if self.rewrites_uvs {
            *uv = self
                .writer
                .geometry
                .oriented_uvs(self.writer.scene, source, self.placement);
        }
        Some(motion)
    }
}

/// Axis-aligned bounds of the finite vertices of every triangle posed by `pose` (`None`
/// when there are none): the bounds of what [`write_all_triangles`] writes, without
/// writing the triangles (only each instance's vertices, one instance at a time).
pub fn posed_bounds(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    pose: &Pose,
    deforms: &[VertexSource],
) -> Option<(Vec3, Vec3)> {
    let mut vertices = WorldVertices::default();
    let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for (i, instance) in geometry.instances.iter().enumerate() {
        let mut placement = Placement::new(pose.world_from_node[instance.node as usize]);
        pose_instance(
            scene,
            geometry,
            pose,
            deforms,
            i,
            &mut vertices,
            &mut placement,
            false,
        );
        // Every vertex the instance's triangles use: its primitive's index buffer.
        for &v in geometry
            .primitive(scene, i)
            .indices
            .chunks_exact(3)
            .flatten()
        {
            let p = vertices.positions[v as usize];
            if p.is_finite() {
                (min, max) = (min.min(p), max.max(p));
            }
        }
    }
    min.cmple(max).all().then_some((min, max))
}

/// Whether two triangles have bit-identical vertices (so -0 and 0 differ, and a NaN
/// equals itself: "did it move" is about the stored bits).
#[inline]
fn same_bits(a: &[Vec3A; 3], b: &[Vec3A; 3]) -> bool {
    a.iter().zip(b).all(|(a, b)| {
        let (a, b) = (a.to_array(), b.to_array());
        (0..3).all(|k| a[k].to_bits() == b[k].to_bits())
    })
}

/// Poses every instance `include` accepts by `pose` (its vertices into `posed`, its plan a
/// full write) and returns their triangles' vertices and source triangles, in source
/// order: what the first frame builds its tree over. [`write_slot_attributes`] then writes
/// the rest of each triangle, once the tree has given the slots their order. On rayon's
/// threads when `parallel`.
#[allow(clippy::too_many_arguments)]
pub fn pose_all_triangles(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    pose: &Pose,
    deforms: &[VertexSource],
    posed: &mut PosedVertices,
    plan: &mut Vec<Rewrite>,
    parallel: bool,
    include: impl Fn(usize) -> bool + Sync,
) -> (Vec<[Vec3A; 3]>, Vec<u32>) {
    posed.resize(geometry.instances.len());
    plan.clear();
    plan.extend((0..geometry.instances.len()).map(|i| {
        if include(i) {
            Rewrite::All(Motion::Deformed)
        } else {
            Rewrite::Keep
        }
    }));
    for (i, instance) in geometry.instances.iter().enumerate() {
        posed.place(i, pose.world_from_node[instance.node as usize]);
    }
    posed.pose(scene, geometry, pose, deforms, &include, parallel);
    let mut sources = Vec::new();
    for (i, range) in geometry.instance_triangles.iter().enumerate() {
        if include(i) {
            sources.extend(range.clone());
        }
    }
    let writer = TriangleWriter::new(scene, geometry, posed, plan, &[], deforms);
    let position = |&source: &u32| writer.position(source);
    let positions = if parallel {
        sources
            .par_iter()
            .with_min_len(WRITE_CHUNK)
            .map(position)
            .collect()
    } else {
        sources.iter().map(position).collect()
    };
    (positions, sources)
}

/// Fills `out`'s normals, uvs, materials and (zeroed) `log2 P_b` for the slots its `source`
/// lists (tree order), from the pose [`pose_all_triangles`] left in `posed` and `plan`: the
/// same values a write in source order gives, written in slot order, on rayon's threads
/// when `parallel`. The positions are the tree's (built from the same pose).
#[allow(clippy::too_many_arguments)]
pub fn write_slot_attributes(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    posed: &PosedVertices,
    plan: &[Rewrite],
    deforms: &[VertexSource],
    parallel: bool,
    out: &mut FrameTriangles,
) {
    let n = out.source.len();
    // Only the slots of instances that do not deform store normals; with none, the
    // array stays empty (a skinned character's frame keeps no 36 bytes a triangle for it).
    let stores_normals = |&s: &u32| {
        deforms[geometry.triangle_instance[s as usize] as usize] != VertexSource::Deformed
    };
    out.normals.clear();
    if out.source.iter().any(stores_normals) {
        out.normals.resize(n, [Vec3::ZERO; 3]);
    }
    out.uvs.clear();
    out.uvs.resize(n, [Vec2::ZERO; 3]);
    out.log2_pb.clear();
    out.log2_pb.resize(n, 0.0);
    out.material.clear();
    out.material.extend(
        out.source
            .iter()
            .map(|&s| geometry.instances[geometry.triangle_instance[s as usize] as usize].material),
    );
    let writer = TriangleWriter::new(scene, geometry, posed, plan, &[], deforms);
    let write = |normal, uv, source| {
        writer.write(source, &mut [Vec3A::ZERO; 3], normal, uv);
    };
    let write_without = |(uv, &source): (_, &u32)| write(None, uv, source);
    let write_with = |(normal, (uv, &source)): (_, (_, &u32))| write(Some(normal), uv, source);
    let FrameTriangles {
        normals,
        uvs,
        source,
        ..
    } = out;
    match (parallel, normals.is_empty()) {
        (true, false) => normals
            .par_iter_mut()
            .zip(uvs.par_iter_mut().zip(source.par_iter()))
            .with_min_len(WRITE_CHUNK)
            .for_each(write_with),
        (true, true) => uvs
            .par_iter_mut()
            .zip(source.par_iter())
            .with_min_len(WRITE_CHUNK)
            .for_each(write_without),
        (false, false) => normals
            .iter_mut()
            .zip(uvs.iter_mut().zip(source.iter()))
            .for_each(write_with),
        (false, true) => uvs.iter_mut().zip(source.iter()).for_each(write_without),
    }
}

/// Triangles per parallel write task (a triangle takes tens of ns).
pub const WRITE_CHUNK: usize = 1024;

/// Whether instance `i`'s deformation inputs are the same in both poses (node transform,
/// morph weights, and its skin's joint matrices), so its vertices cannot have changed.
pub fn same_deformation(
    scene: &SceneDesc,
    geometry: &SceneGeometry,
    i: usize,
    now: &Pose,
    before: &Pose,
) -> bool {
    let node = geometry.instances[i].node as usize;
    let skin_same = match scene.nodes[node].skin {
        Some(skin) => now.joint_matrices.get(skin) == before.joint_matrices.get(skin),
        None => true,
    };
    skin_same
        && now.world_from_node[node] == before.world_from_node[node]
        && now.morph_weights[node] == before.morph_weights[node]
}
