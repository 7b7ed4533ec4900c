//! What rays are traced against: the flat tree over world-space triangles, or the two-level
//! structure (shared object-space meshes placed by instances, plus a world-space tree for
//! what deforms or stands still). The integrator asks for hits and for the hit triangle in world space and
//! never sees which one it has.
//!
//! A hit on an instance is turned into world space at the hit, with the same arithmetic the
//! flat path uses to write its triangles (`Placement::place_triangle`), and the distance and
//! barycentrics are taken again from the world-space triangle with the same watertight test:
//! where both structures find the same triangle, shading sees the same bits. Only which
//! triangle is found can differ: on an edge, or between coincident surfaces of an instance
//! and another tree (its object-space `t` may round a few ulps away from the world-space
//! one, so the tie rule by source triangle no longer decides between them).

use glam::{Vec2, Vec3A};

use crate::accel::{Accel, Hit, TriangleRef, TwoLevelAccel, intersect};
use crate::geometry::{FrameTriangles, HitTriangle, Placement, VertexNormals};
use crate::lod::{PixelFootprint, log2_pb, shift_log2_pb};

/// The acceleration structure of a frame, with the triangles its hits refer to.
#[derive(Clone, Copy)]
pub enum SceneBvh<'a> {
    Flat {
        triangles: &'a FrameTriangles,
        accel: &'a Accel,
        /// Where the slots of deforming instances get their normals (`None`: every slot
        /// stores its own).
        by_vertex: Option<&'a dyn VertexNormals>,
    },
    TwoLevel(Instanced<'a>),
}

/// The two-level structure of a frame.
#[derive(Clone, Copy)]
pub struct Instanced<'a> {
    /// The world tree's triangles, in world space: skinned and morphed instances, and static
    /// ones merged into it (see `frame/two_level.rs`).
    pub world_triangles: &'a FrameTriangles,
    pub world: &'a Accel,
    /// Where the world tree's slots of deforming instances get their normals.
    pub by_vertex: Option<&'a dyn VertexNormals>,
    pub accel: &'a TwoLevelAccel,
    /// Per instance of `accel` (the index a hit reports): how its triangles are shaded.
    pub instances: &'a [InstanceShading],
    /// For the `log2 P_b` of triangles whose instance is not a similarity.
    pub footprint: PixelFootprint,
    /// Whether the LOD method reads `log2 P_b` (otherwise it is left 0).
    pub needs_log2_pb: bool,
}

/// How the triangles of one instance of a shared mesh are shaded this frame.
#[derive(Debug, Clone, Copy)]
pub struct InstanceShading {
    /// Object to world.
    pub placement: Placement,
    /// Which mesh of the two-level structure it places.
    pub mesh: u32,
    /// Its first source triangle: the mesh's triangle `i` is source `source_base + i`.
    pub source_base: u32,
    pub pb: PbRule,
    /// Level-0 size of its base-colour texture ((1, 1) when untextured), for `PbRule`s
    /// that compute the constant.
    pub texture_size: (u32, u32),
}

/// Where a placed instance's `log2 P_b` comes from (the rules of `frame/log2_pb.rs`, here
/// evaluated at the hit instead of written per triangle).
#[derive(Debug, Clone, Copy)]
pub enum PbRule {
    /// A similarity: the object-space constant plus `log2 s`.
    Shift { log2_scale: f64 },
    /// An axis stretch: the constant of the object-space triangle under this placement (the
    /// exact diagonal, whatever rotation the frame adds).
    Stretched(Placement),
    /// Anything else (a shear): the constant of the world-space triangle.
    World,
}

impl Instanced<'_> {
    /// The material and source triangle of a hit's `slot` in `instance` ([`Hit::WORLD`]:
    /// the world tree).
    #[inline(always)]
    fn material_and_source(&self, instance: u32, slot: u32) -> (u32, u32) {
        let s = slot as usize;
        if instance == Hit::WORLD {
            let w = self.world_triangles;
            return (w.material[s], w.source[s]);
        }
        let shading = &self.instances[instance as usize];
        let mesh = self.accel.mesh_triangles(shading.mesh);
        (mesh.material[s], shading.source_base + mesh.source[s])
    }
}

impl SceneBvh<'_> {
    /// The closest hit with `t` in `[0, t_max)` (ties to the lowest source triangle).
    #[inline]
    pub fn closest_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        match self {
            SceneBvh::Flat { accel, .. } => accel.closest_hit(origin, direction, t_max),
            SceneBvh::TwoLevel(i) => i.accel.closest_hit(i.world, origin, direction, t_max),
        }
    }

    /// [`SceneBvh::closest_hit`] for a packet of coherent rays.
    pub fn closest_hits(&self, rays: &[(Vec3A, Vec3A)], t_max: f32, hits: &mut [Option<Hit>]) {
        match self {
            SceneBvh::Flat { accel, .. } => accel.closest_hits(rays, t_max, hits),
            SceneBvh::TwoLevel(i) => i.accel.closest_hits(i.world, rays, t_max, hits),
        }
    }

    /// [`SceneBvh::closest_hit`] for a packet of rays from any origins (a bounce's reflected
    /// and refracted rays), walked together through every tree (masked, or with bounds from
    /// an apex behind them); each ray finds what it finds alone.
    pub fn closest_hits_scattered(
        &self,
        rays: &[(Vec3A, Vec3A)],
        t_max: f32,
        hits: &mut [Option<Hit>],
    ) {
        match self {
            SceneBvh::Flat { accel, .. } => accel.closest_hits_masked(rays, t_max, hits),
            SceneBvh::TwoLevel(i) => i.accel.closest_hits_scattered(i.world, rays, t_max, hits),
        }
    }

    /// Visits every hit with `t` in `[0, t_max)` as `visit(t, material, source)`, in an
    /// order that depends on the tree, until `visit` returns false; returns false when it
    /// was stopped early.
    #[inline]
    pub fn visit_hits(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        mut visit: impl FnMut(f32, u32, u32) -> bool,
    ) -> bool {
        match self {
            SceneBvh::Flat {
                triangles, accel, ..
            } => accel.visit_hits(origin, direction, t_max, |slot, t| {
                let s = slot as usize;
                visit(t, triangles.material[s], triangles.source[s])
            }),
            SceneBvh::TwoLevel(i) => {
                i.accel
                    .visit_hits(i.world, origin, direction, t_max, |instance, slot, t| {
                        let (material, source) = i.material_and_source(instance, slot);
                        visit(t, material, source)
                    })
            }
        }
    }

    /// [`SceneBvh::visit_hits`] for a packet of rays `(origin, direction)`, ray `r`
    /// searched up to `t_max[r]`: visits ray `r`'s hits as `visit(r, t, material, source)`
    /// until `visit` returns false for it; returns the mask of rays stopped early. The rays
    /// walk each tree together (the world tree, then the top-level trees, then each instance
    /// that enough of them enter); each meets the triangles it meets alone.
    pub fn visit_hits_packet(
        &self,
        rays: &[(Vec3A, Vec3A)],
        t_max: &[f32],
        mut visit: impl FnMut(usize, f32, u32, u32) -> bool,
    ) -> u64 {
        match self {
            SceneBvh::Flat {
                triangles, accel, ..
            } => accel.visit_hits_packet(rays, t_max, |r, slot, t| {
                let s = slot as usize;
                visit(r, t, triangles.material[s], triangles.source[s])
            }),
            SceneBvh::TwoLevel(i) => {
                i.accel
                    .visit_hits_packet(i.world, rays, t_max, |r, instance, slot, t| {
                        let (material, source) = i.material_and_source(instance, slot);
                        visit(r, t, material, source)
                    })
            }
        }
    }

    /// The hit triangle in world space. For a hit on an instance the hit's distance and
    /// barycentrics are replaced by the world-space triangle's own (see the module note).
    #[inline]
    pub fn hit_triangle(&self, hit: &mut Hit, origin: Vec3A, direction: Vec3A) -> HitTriangle {
        let mut triangle = HitTriangle::UNSET;
        self.write_hit_triangle(hit, origin, direction, &mut triangle);
        triangle
    }

    /// [`SceneBvh::hit_triangle`] written field by field into `out` (see
    /// [`HitTriangle::UNSET`] for why).
    // Always inlined: the tile kernel (`render::tile::TraceTile`) calls it, and so gets it
    // compiled into each of its SIMD copies.
    #[inline(always)]
    pub fn write_hit_triangle(
        &self,
        hit: &mut Hit,
        origin: Vec3A,
        direction: Vec3A,
        out: &mut HitTriangle,
    ) {
        self.write_triangle(hit.triangle_ref(), out);
        if let SceneBvh::TwoLevel(i) = self
            && hit.instance != Hit::WORLD
        {
            match intersect(&out.positions, origin, direction) {
                Some((t, bary)) => (hit.t, hit.bary) = (t, bary),
                // Missed by rounding on an edge: keep the object-space answer, its
                // barycentrics in the world winding.
                None if i.instances[hit.instance as usize].placement.flips_winding => {
                    hit.bary = Vec2::new(hit.bary.y, hit.bary.x)
                }
                None => {}
            }
        }
    }

    /// Triangle `at` in world space.
    #[inline]
    pub fn triangle(&self, at: TriangleRef) -> HitTriangle {
        let mut triangle = HitTriangle::UNSET;
        self.write_triangle(at, &mut triangle);
        triangle
    }

    /// [`SceneBvh::triangle`] written field by field into `out`.
    #[inline(always)]
    fn write_triangle(&self, at: TriangleRef, out: &mut HitTriangle) {
        let slot = at.slot as usize;
        let i = match self {
            SceneBvh::Flat {
                triangles,
                accel,
                by_vertex,
            } => {
                return triangles.write_hit_triangle(
                    slot,
                    accel.triangle_and_source(at.slot),
                    *by_vertex,
                    out,
                );
            }
            SceneBvh::TwoLevel(i) if at.instance == Hit::WORLD => {
                return i.world_triangles.write_hit_triangle(
                    slot,
                    i.world.triangle_and_source(at.slot),
                    i.by_vertex,
                    out,
                );
            }
            SceneBvh::TwoLevel(i) => i,
        };
        let shading = &i.instances[at.instance as usize];
        let mesh = i.accel.mesh_triangles(shading.mesh);
        let object = (
            i.accel.mesh_triangle(shading.mesh, at.slot),
            mesh.normals[slot],
            mesh.uvs[slot],
        );
        let (positions, normals, uvs) = shading
            .placement
            .place_triangle(object.0, object.1, object.2);
        let object_log2_pb = mesh.log2_pb[slot];
        out.log2_pb = if !i.needs_log2_pb || object_log2_pb.is_nan() {
            0.0 // untextured, as the flat arrays hold it
        } else {
            match shading.pb {
                PbRule::Shift { log2_scale } => shift_log2_pb(object_log2_pb, log2_scale),
                PbRule::Stretched(under) => {
                    let (p, _, uv) = under.place_triangle(object.0, object.1, object.2);
                    log2_pb(p, uv, shading.texture_size, i.footprint)
                }
                PbRule::World => log2_pb(positions, uvs, shading.texture_size, i.footprint),
            }
        };
        out.positions = positions;
        out.normals = normals;
        out.uvs = uvs;
        out.material = mesh.material[slot];
        out.source = shading.source_base + mesh.source[slot];
    }
}
