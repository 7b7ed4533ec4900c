//! The ground floor of the kernel: one frame's world-space triangles as the flat arrays
//! the integrator and the trees read (`FrameTriangles`), the hit record shading reads
//! (`HitTriangle`), and a node's placement in world space (`Placement`).
//!
//! `FrameTriangles` is refilled each frame from the node world transforms; its arrays are
//! permuted into BVH order by `accel`, so traversal reads them directly. The load-time
//! flattening of a scene into instances and source triangles, and the renderer's
//! materials and lights, are built above, where the scene description and the renderer's
//! types are both known (`frame::SceneGeometry`, `frame::appearance`).
//!
//! Invariants: all arrays of a `FrameTriangles` have the same length, except `positions`,
//! which is either as long (before a tree is built) or empty (once a tree is built over
//! them: its packs hold the only copy, read by slot through `Accel::triangle`), and
//! `normals`, which is either as long or empty (no slot stores its normals: every
//! triangle's are read through its vertex indices, see `VertexNormals`); triangles
//! are wound
//! counter-clockwise about their geometric normal in world space (a node with a negative
//! determinant has its winding flipped, as glTF requires). This module imports nothing
//! else from the crate, so `accel` and `lod`, which stand on it, reach neither the
//! renderer nor the scene description through it (`tests/architecture.rs`).

use glam::{Mat3, Mat4, Vec2, Vec3, Vec3A};

/// One frame's world-space triangles, in BVH order once `accel` has permuted them.
#[derive(Debug, Default, Clone)]
pub struct FrameTriangles {
    /// The vertices, until a tree is built over them: `Accel::build` moves them into the
    /// tree's packs (the hit test's layout) and leaves this empty, so a frame keeps one copy
    /// of each position, not two (48 bytes a triangle).
    pub positions: Vec<[Vec3A; 3]>,
    /// World-space shading normals (unit length; the geometric normal where the mesh has
    /// none), for the slots that store them: a slot of a skinned or morphed instance does
    /// not (its entry is left as it was), and shading reads its normals through its vertex
    /// indices ([`VertexNormals`]); empty when no slot stores them.
    pub normals: Vec<[Vec3; 3]>,
    pub uvs: Vec<[Vec2; 3]>,
    pub material: Vec<u32>,
    /// Park & Kim's per-triangle constant (0 where the material is untextured).
    pub log2_pb: Vec<f32>,
    /// For each slot, the source triangle index it holds.
    pub source: Vec<u32>,
}

/// The unit normal of triangle `p` (counter-clockwise front), or zero for a triangle of no
/// area. In f32; where that leaves f32's range (edges beyond about 4e9: the squared length
/// of the cross product is their fourth power), in f64.
#[inline]
pub fn unit_normal([p0, p1, p2]: [Vec3A; 3]) -> Vec3A {
    let cross = (p1 - p0).cross(p2 - p0);
    let normal = cross.normalize_or_zero();
    if normal != Vec3A::ZERO || cross == Vec3A::ZERO {
        return normal;
    }
    unit_normal_f64([p0, p1, p2])
}

#[cold]
#[inline(never)]
fn unit_normal_f64(p: [Vec3A; 3]) -> Vec3A {
    let [p0, p1, p2] = p.map(|v| v.as_dvec3());
    (p1 - p0).cross(p2 - p0).normalize_or_zero().as_vec3a()
}

/// One triangle as shading reads it at a hit: world-space vertices and normals in the
/// winding the flat arrays use, and the per-triangle values.
#[derive(Debug, Clone, Copy)]
pub struct HitTriangle {
    pub positions: [Vec3A; 3],
    pub normals: [Vec3; 3],
    pub uvs: [Vec2; 3],
    pub material: u32,
    pub log2_pb: f32,
    pub source: u32,
}

impl HitTriangle {
    /// A triangle to be overwritten: NaN everywhere, so one read before it was written gives
    /// NaN, not plausible values. The frame's hit lists push it and then write each field
    /// in place: a triangle built on the stack and copied into the list was read back as
    /// 16-byte loads right after its 4- and 8-byte fields were stored, which the CPU cannot
    /// forward (a stall per hit: 8% of the tile loop's samples in a BART Kitchen profile).
    pub const UNSET: HitTriangle = HitTriangle {
        positions: [Vec3A::NAN; 3],
        normals: [Vec3::NAN; 3],
        uvs: [Vec2::NAN; 3],
        material: u32::MAX,
        log2_pb: f32::NAN,
        source: u32::MAX,
    };
}

/// Shading normals kept by vertex rather than by slot: a skinned or morphed mesh's normals
/// change every frame, and writing three of them into each slot (36 bytes a triangle) was
/// a third of what its update wrote. The frame keeps the posed vertices anyway; a hit reads
/// its three normals from them through the triangle's vertex indices instead.
pub trait VertexNormals: Sync {
    /// Source triangle `source`'s world-space shading normals in the winding its slot holds
    /// (`positions`: its vertices, read from the tree), the same bits its slot would have
    /// stored; `None` when its slot stores them.
    fn normals(&self, source: u32, positions: &[Vec3A; 3]) -> Option<[Vec3; 3]>;
}

/// A triangle's shading normals from its vertices' (`None`: the mesh has none), in its
/// slot's winding: a zero vertex normal, or all three where the mesh has none, become the
/// geometric normal of `p` (computed only then: a sqrt and a division).
#[inline(always)]
pub fn shading_normals(normals: Option<[Vec3; 3]>, p: &[Vec3A; 3]) -> [Vec3; 3] {
    let geometric = || Vec3::from((p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero());
    match normals {
        Some(n) if n.contains(&Vec3::ZERO) => {
            n.map(|n| if n == Vec3::ZERO { geometric() } else { n })
        }
        Some(n) => n,
        None => [geometric(); 3],
    }
}

impl FrameTriangles {
    /// Slot `slot` as shading reads it, with its vertices (`positions`, read from the tree);
    /// `by_vertex`: where the slots of deforming instances get their normals.
    #[inline]
    pub fn hit_triangle(
        &self,
        slot: usize,
        positions: [Vec3A; 3],
        by_vertex: Option<&dyn VertexNormals>,
    ) -> HitTriangle {
        let mut triangle = HitTriangle::UNSET;
        self.write_hit_triangle(
            slot,
            (positions, self.source[slot]),
            by_vertex,
            &mut triangle,
        );
        triangle
    }

    /// [`FrameTriangles::hit_triangle`] written field by field into `out` (see
    /// [`HitTriangle::UNSET`] for why), with the slot's vertices and source triangle as its
    /// tree holds them (`source` is `self.source[slot]`; a hit's walk has just read the
    /// tree's copy, where the array is one more line to wait for).
    // Always inlined: the tile kernel (`render::tile::TraceTile`) calls it, and so gets it
    // compiled into each of its SIMD copies.
    #[inline(always)]
    pub fn write_hit_triangle(
        &self,
        slot: usize,
        (positions, source): ([Vec3A; 3], u32),
        by_vertex: Option<&dyn VertexNormals>,
        out: &mut HitTriangle,
    ) {
        debug_assert_eq!(source, self.source[slot], "slot {slot}'s source");
        // The vertices are stored first and the normals read from that copy: lent to
        // `normals` from the argument, they were spilled to the stack as 16-byte stores
        // and copied into `out` as 32-byte loads, which the CPU cannot forward (a stall
        // per hit, 2-3% of a BART Kitchen frame's samples on one load).
        out.positions = positions;
        out.normals = match by_vertex.and_then(|v| v.normals(source, &out.positions)) {
            Some(normals) => normals,
            None => self.normals[slot],
        };
        out.uvs = self.uvs[slot];
        out.material = self.material[slot];
        out.log2_pb = self.log2_pb[slot];
        out.source = source;
    }

    /// How many triangles (slots) there are.
    pub fn len(&self) -> usize {
        self.source.len()
    }

    pub fn is_empty(&self) -> bool {
        self.source.is_empty()
    }

    /// Reorders every per-triangle array so slot `i` holds what slot `order[i]` held
    /// (`positions` too unless a tree already holds them).
    pub fn permute(&mut self, order: &[u32]) {
        fn apply<T: Copy>(v: &mut Vec<T>, order: &[u32]) {
            let permuted: Vec<T> = order.iter().map(|&i| v[i as usize]).collect();
            *v = permuted;
        }
        if !self.positions.is_empty() {
            apply(&mut self.positions, order);
        }
        if !self.normals.is_empty() {
            apply(&mut self.normals, order);
        }
        apply(&mut self.uvs, order);
        apply(&mut self.material, order);
        apply(&mut self.log2_pb, order);
        apply(&mut self.source, order);
    }
}

/// A node's world transform with what shading needs derived once per instance.
#[derive(Debug, Clone, Copy)]
pub struct Placement {
    pub world_from_object: Mat4,
    /// Inverse transpose of the upper 3x3 (normals transform covariantly).
    pub normal_from_object: Mat3,
    pub flips_winding: bool,
}

impl Placement {
    /// A vertex position in world space.
    #[inline]
    pub fn place_point(&self, p: Vec3) -> Vec3 {
        self.world_from_object.transform_point3(p)
    }

    /// A shading normal in world space, unit length (zero when it degenerates: the caller
    /// falls back to the geometric normal).
    #[inline]
    pub fn place_normal(&self, n: Vec3) -> Vec3 {
        (self.normal_from_object * n).normalize_or_zero()
    }

    /// An object-space triangle (vertices in the mesh's winding, normals as the mesh
    /// stores them, zero where it has none) placed in world space: the same bits as
    /// `frame::SceneGeometry::world_triangle` gives for that triangle under this placement,
    /// uvs in the same (possibly flipped) order.
    #[inline]
    pub fn place_triangle(
        &self,
        positions: [Vec3A; 3],
        normals: [Vec3; 3],
        uvs: [Vec2; 3],
    ) -> ([Vec3A; 3], [Vec3; 3], [Vec2; 3]) {
        let (mut p, mut n, mut uv) = (positions, normals, uvs);
        if self.flips_winding {
            p.swap(1, 2);
            n.swap(1, 2);
            uv.swap(1, 2);
        }
        let p = p.map(|v| Vec3A::from(self.place_point(Vec3::from(v))));
        let geometric = Vec3::from(unit_normal(p));
        let n = n.map(|n| {
            let placed = self.place_normal(n);
            if placed == Vec3::ZERO {
                geometric
            } else {
                placed
            }
        });
        (p, n, uv)
    }

    pub fn new(world_from_object: Mat4) -> Self {
        let linear = Mat3::from_mat4(world_from_object);
        let det = linear.determinant();
        let normal_from_object = if det.abs() > f32::MIN_POSITIVE && det.is_finite() {
            linear.inverse().transpose()
        } else {
            Mat3::ZERO // collapsed node: every normal falls back to the geometric one
        };
        Placement {
            world_from_object,
            normal_from_object,
            flips_winding: det < 0.0,
        }
    }
}
