//! The load-time flattening of a scene's drawn triangles (`SceneGeometry`), built once per
//! scene by the frame setup: every (node, mesh primitive) pair becomes an instance and
//! every triangle a source record (its instance and vertex indices; its texture
//! coordinates are rebased from the primitive's when asked, [`SceneGeometry::triangle_uvs`]); the
//! renderer's materials and lights are converted alongside (`appearance`).
//!
//! It lives in the frame loop, above both the scene description and the renderer, because
//! it reads the one and holds the other's types; what the hot loop reads of it each frame
//! (`geometry::FrameTriangles`, `geometry::Placement`) is in the leaf below.
//!
//! Invariants: an instance's source triangles are consecutive; the vertex order and
//! placement arithmetic of [`SceneGeometry::world_triangle`],
//! [`SceneGeometry::placed_triangle`] and `Placement::place_triangle` (the two-level path)
//! are the same, so every path gives a triangle the same bits.

use glam::{Vec2, Vec3, Vec3A};

use super::appearance::Appearance;
use crate::geometry::{Placement, shading_normals};
use crate::render::{LightSource, Material};
use crate::scene::{PrimitiveDesc, SceneDesc};
use crate::texture::WrapMode;

/// One drawn primitive: a mesh primitive placed by a node.
#[derive(Debug, Clone, Copy)]
pub struct Instance {
    pub node: u32,
    pub mesh: u32,
    pub primitive: u32,
    /// Index into `SceneGeometry::materials`.
    pub material: u32,
    /// Wrap modes (s, t) of its material's base-colour texture, which rebase its uvs.
    pub wrap: [WrapMode; 2],
}

/// Load-time flattening of the scene's drawn triangles.
#[derive(Debug, Default)]
pub struct SceneGeometry {
    pub instances: Vec<Instance>,
    /// Per source triangle: its instance.
    pub triangle_instance: Vec<u32>,
    /// Per instance: its source triangles (consecutive).
    pub instance_triangles: Vec<std::ops::Range<u32>>,
    /// The scene's materials plus a default one at the end (for primitives without one),
    /// in the renderer's terms.
    pub materials: Vec<Material>,
    /// The scene's lights (indexed like `SceneDesc::lights`), before placement.
    pub lights: Vec<LightSource>,
}

impl SceneGeometry {
    /// Flattens the scene's node hierarchy into instances and source triangles.
    pub fn new(scene: &SceneDesc) -> Self {
        let Appearance { materials, lights } = Appearance::new(scene);
        let mut geometry = SceneGeometry {
            materials,
            lights,
            ..Default::default()
        };
        // The default material is the last one (see `appearance`).
        let default_material = geometry.materials.len() as u32 - 1;
        for node in scene.traversal_order() {
            let Some(mesh) = scene.nodes[node].mesh else {
                continue;
            };
            for (p, primitive) in scene.meshes[mesh].primitives.iter().enumerate() {
                let material = primitive.material.map_or(default_material, |m| m as u32);
                let instance = geometry.instances.len() as u32;
                geometry.instances.push(Instance {
                    node: node as u32,
                    mesh: mesh as u32,
                    primitive: p as u32,
                    material,
                    wrap: wrap_modes(scene, &geometry.materials[material as usize]),
                });
                let first = geometry.triangle_instance.len() as u32;
                let triangles = primitive.indices.len() / 3;
                geometry
                    .triangle_instance
                    .extend(std::iter::repeat_n(instance, triangles));
                let end = geometry.triangle_instance.len() as u32;
                geometry.instance_triangles.push(first..end);
            }
        }
        geometry
    }

    pub fn triangle_count(&self) -> usize {
        self.triangle_instance.len()
    }

    /// Source triangle `source`'s vertex indices into its instance's primitive: read from
    /// the primitive's index buffer (a copy per drawn triangle was 12 bytes a triangle, and
    /// one per copy of a mesh drawn many times).
    #[inline]
    pub fn triangle_vertices(&self, scene: &SceneDesc, source: u32) -> [u32; 3] {
        let i = self.triangle_instance[source as usize] as usize;
        let first = (source - self.instance_triangles[i].start) as usize * 3;
        let v = &self.primitive(scene, i).indices[first..first + 3];
        [v[0], v[1], v[2]]
    }

    /// The mesh primitive instance `i` draws.
    pub fn primitive<'s>(&self, scene: &'s SceneDesc, i: usize) -> &'s PrimitiveDesc {
        let instance = self.instances[i];
        &scene.meshes[instance.mesh as usize].primitives[instance.primitive as usize]
    }

    /// World-space vertices and shading normals of source triangle `source`, read from
    /// `positions`/`normals` (the primitive's vertex arrays: rest or deformed) and placed by
    /// `placement`. Winding is flipped when the placement mirrors.
    #[inline]
    pub fn world_triangle(
        &self,
        scene: &SceneDesc,
        source: u32,
        placement: &Placement,
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
    ) -> ([Vec3A; 3], [Vec3; 3]) {
        self.assemble_triangle(
            self.triangle_vertices(scene, source),
            placement.flips_winding,
            |i| placement.place_point(positions[i as usize]),
            normals.map(|n| move |i: u32| placement.place_normal(n[i as usize])),
        )
    }

    /// The vertices [`Self::world_triangle`] returns, without its normals (bit for bit the
    /// same: the same vertex order and placement).
    #[inline]
    pub fn world_positions(
        &self,
        scene: &SceneDesc,
        source: u32,
        placement: &Placement,
        positions: &[Vec3],
    ) -> [Vec3A; 3] {
        oriented(
            self.triangle_vertices(scene, source),
            placement.flips_winding,
        )
        .map(|i| Vec3A::from(placement.place_point(positions[i as usize])))
    }

    /// [`Self::world_triangle`] of the triangle of `vertices` (its
    /// [`Self::triangle_vertices`]) from vertices already placed one by one (`positions` by
    /// [`Placement::place_point`], `normals` by [`Placement::place_normal`]): the same bits,
    /// with each shared vertex transformed once instead of once per triangle.
    ///
    /// Always inlined: left out of line (as it was in the write in slot order), the call
    /// returned the triangle through memory, and reading it back stalled on store
    /// forwarding (two fifths of that write's samples).
    #[inline(always)]
    pub fn placed_triangle(
        &self,
        vertices: [u32; 3],
        flips_winding: bool,
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
    ) -> ([Vec3A; 3], [Vec3; 3]) {
        self.assemble_triangle(
            vertices,
            flips_winding,
            |i| positions[i as usize],
            normals.map(|n| move |i: u32| n[i as usize]),
        )
    }

    /// The vertices of [`Self::placed_triangle`] alone: the write of a deforming instance,
    /// whose slots do not store normals (`geometry::VertexNormals`).
    #[inline(always)]
    pub fn placed_positions(
        &self,
        vertices: [u32; 3],
        flips_winding: bool,
        positions: &[Vec3],
    ) -> [Vec3A; 3] {
        let v = oriented(vertices, flips_winding);
        [
            Vec3A::from(positions[v[0] as usize]),
            Vec3A::from(positions[v[1] as usize]),
            Vec3A::from(positions[v[2] as usize]),
        ]
    }

    /// The shading normals [`Self::placed_triangle`] gives a triangle of primitive vertices
    /// `vertices` whose placed vertices are `p` (read back from its slot): what shading
    /// reads for the triangles of a deforming instance.
    #[inline]
    pub fn placed_normals(
        &self,
        vertices: [u32; 3],
        flips_winding: bool,
        p: &[Vec3A; 3],
        normals: Option<&[Vec3]>,
    ) -> [Vec3; 3] {
        let v = oriented(vertices, flips_winding);
        let n = normals.map(|n| [n[v[0] as usize], n[v[1] as usize], n[v[2] as usize]]);
        shading_normals(n, p)
    }

    /// A triangle from its placed vertices and normals (a zero normal: the geometric one).
    #[inline(always)]
    fn assemble_triangle(
        &self,
        vertices: [u32; 3],
        flips_winding: bool,
        position: impl Fn(u32) -> Vec3,
        normal: Option<impl Fn(u32) -> Vec3>,
    ) -> ([Vec3A; 3], [Vec3; 3]) {
        let v = oriented(vertices, flips_winding);
        // Written out, not `v.map(..)`: the array map's closure was left out of line, a
        // call and a spill per vertex in the update's hottest loop.
        let p = [
            Vec3A::from(position(v[0])),
            Vec3A::from(position(v[1])),
            Vec3A::from(position(v[2])),
        ];
        let normals = normal.map(|normal| [normal(v[0]), normal(v[1]), normal(v[2])]);
        // The geometric normal is computed only where a vertex needs it: a sqrt and a
        // division, most of the cost of writing a deformed triangle that has its own normals.
        let normals = shading_normals(normals, &p);
        (p, normals)
    }

    /// Source triangle `source`'s texture coordinates, rebased by whole periods of its
    /// texture's wrap modes so they stay near [0, 1] (f32 precision of `u * width` for large
    /// u); zero where its primitive has none. Taken from the primitive's vertex uvs when
    /// asked (a write under a new winding, a `log2 P_b` under a stretch, a build), not kept
    /// per triangle: that array was 24 bytes a triangle for a few reads a frame.
    pub fn triangle_uvs(&self, scene: &SceneDesc, source: u32) -> [Vec2; 3] {
        let i = self.triangle_instance[source as usize] as usize;
        match &self.primitive(scene, i).uvs {
            Some(uv) => rebase_uvs(
                self.triangle_vertices(scene, source)
                    .map(|v| uv[v as usize]),
                self.instances[i].wrap,
            ),
            None => [Vec2::ZERO; 3],
        }
    }

    /// Source triangle UVs ([`Self::triangle_uvs`]) in the vertex order
    /// [`Self::world_triangle`] uses.
    #[inline]
    pub fn oriented_uvs(&self, scene: &SceneDesc, source: u32, placement: &Placement) -> [Vec2; 3] {
        let mut uv = self.triangle_uvs(scene, source);
        if placement.flips_winding {
            uv.swap(1, 2);
        }
        uv
    }
}

/// A triangle's vertex indices in the order the flat arrays use (the last two swapped
/// under a mirroring placement, so the winding stays front-facing).
#[inline]
fn oriented(mut vertices: [u32; 3], flips_winding: bool) -> [u32; 3] {
    if flips_winding {
        vertices.swap(1, 2);
    }
    vertices
}

fn wrap_modes(scene: &SceneDesc, material: &Material) -> [WrapMode; 2] {
    match material
        .base_color_texture
        .and_then(|t| scene.textures.get(t))
    {
        Some(texture) => [texture.sampler.wrap_s, texture.sampler.wrap_t],
        None => [WrapMode::ClampToEdge; 2],
    }
}

/// Shifts a triangle's UVs by whole wrap periods (1 for repeat, 2 for mirrored repeat) so
/// the smallest coordinate lies in [0, period): the texture lookup is unchanged but large
/// coordinates no longer eat f32 precision. Clamped axes are left as they are.
fn rebase_uvs(uv: [Vec2; 3], wrap: [WrapMode; 2]) -> [Vec2; 3] {
    let mut out = uv;
    for axis in 0..2 {
        let period = match wrap[axis] {
            WrapMode::Repeat => 1.0,
            WrapMode::MirroredRepeat => 2.0,
            WrapMode::ClampToEdge => continue,
        };
        let min = uv
            .iter()
            .map(|t| t[axis] as f64)
            .fold(f64::INFINITY, f64::min);
        if !min.is_finite() {
            continue;
        }
        let shift = (min / period).floor() * period;
        for (o, t) in out.iter_mut().zip(uv) {
            o[axis] = (t[axis] as f64 - shift) as f32;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use glam::Mat4;

    use super::*;
    use crate::scene::{MeshDesc, NodeDesc, PrimitiveDesc};

    /// A scene of one root node drawing one mesh of `primitives`.
    fn one_node_scene(primitives: Vec<PrimitiveDesc>) -> SceneDesc {
        SceneDesc {
            meshes: vec![MeshDesc {
                primitives,
                ..Default::default()
            }],
            nodes: vec![NodeDesc {
                mesh: Some(0),
                ..Default::default()
            }],
            roots: vec![0],
            ..Default::default()
        }
    }

    /// Placing vertices once and assembling triangles from them gives the bits of placing
    /// each triangle's vertices itself (mirrored placement and a zero normal included).
    #[test]
    fn placed_triangle_equals_world_triangle_bit_for_bit() {
        let positions = [
            Vec3::new(0.1, -0.3, 0.7),
            Vec3::new(1.3, 0.2, -0.1),
            Vec3::new(-0.4, 1.1, 0.25),
            Vec3::new(0.9, 0.8, -1.7),
        ];
        let scene = one_node_scene(vec![PrimitiveDesc {
            positions: positions.to_vec(),
            indices: vec![0, 1, 2, 2, 1, 3],
            ..Default::default()
        }]);
        let geometry = SceneGeometry::new(&scene);
        assert_eq!(geometry.triangle_vertices(&scene, 1), [2, 1, 3]);
        let normals = [Vec3::Z, Vec3::ZERO, Vec3::new(0.3, 0.4, 0.5), Vec3::X];
        let mirrored = Mat4::from_scale_rotation_translation(
            Vec3::new(-1.5, 0.5, 2.0),
            glam::Quat::from_rotation_y(0.4),
            Vec3::new(3.0, -2.0, 1.0),
        );
        for world_from_object in [mirrored, Mat4::IDENTITY] {
            let placement = Placement::new(world_from_object);
            let placed: Vec<Vec3> = positions
                .iter()
                .map(|&p| placement.place_point(p))
                .collect();
            let placed_normals: Vec<Vec3> =
                normals.iter().map(|&n| placement.place_normal(n)).collect();
            for source in 0..2 {
                for with_normals in [false, true] {
                    let (n, pn) = (
                        with_normals.then_some(&normals[..]),
                        with_normals.then_some(&placed_normals[..]),
                    );
                    let direct = geometry.world_triangle(&scene, source, &placement, &positions, n);
                    let once = geometry.placed_triangle(
                        geometry.triangle_vertices(&scene, source),
                        placement.flips_winding,
                        &placed,
                        pn,
                    );
                    let bits = |(p, n): ([Vec3A; 3], [Vec3; 3])| {
                        (
                            p.map(|v| v.to_array().map(f32::to_bits)),
                            n.map(|v| v.to_array().map(f32::to_bits)),
                        )
                    };
                    assert_eq!(
                        bits(direct),
                        bits(once),
                        "triangle {source}, normals {with_normals}"
                    );
                    // The vertices alone (the stretch rule of the `log2 P_b` update).
                    let alone = geometry.world_positions(&scene, source, &placement, &positions);
                    assert_eq!(
                        bits((alone, [Vec3::ZERO; 3])).0,
                        bits(direct).0,
                        "triangle {source}: world_positions"
                    );
                    // The two-level path: the object-space triangle placed at a hit.
                    let v = geometry.triangle_vertices(&scene, source);
                    let object_normals = v.map(|i| match n {
                        Some(n) => n[i as usize],
                        None => Vec3::ZERO,
                    });
                    let (p, n, _) = placement.place_triangle(
                        v.map(|i| Vec3A::from(positions[i as usize])),
                        object_normals,
                        [Vec2::ZERO; 3],
                    );
                    assert_eq!(bits(direct), bits((p, n)), "placed at a hit: {source}");
                    // A deforming instance's path: the vertices written alone, the normals
                    // read back at a hit from the placed vertices and the slot's vertices.
                    let v = geometry.triangle_vertices(&scene, source);
                    let flips = placement.flips_winding;
                    let p = geometry.placed_positions(v, flips, &placed);
                    let n = geometry.placed_normals(v, flips, &p, pn);
                    assert_eq!(bits(once), bits((p, n)), "by vertex: {source}");
                }
            }
        }
    }

    /// A source triangle's uvs, asked for, are its primitive's vertex uvs through its
    /// indices (rebased by its instance's wrap modes: clamped here, so as they are), zero
    /// for a primitive without uvs, and swapped into the mirrored winding on request.
    #[test]
    fn triangle_uvs_come_from_the_primitive_through_the_indices() {
        let uvs = vec![
            Vec2::new(0.25, 0.5),
            Vec2::new(1e5, -3.0),
            Vec2::new(-0.5, 7.25),
            Vec2::new(2.0, 2.5),
        ];
        let primitive = |uvs: Option<Vec<Vec2>>| PrimitiveDesc {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE],
            uvs,
            indices: vec![0, 1, 2, 3, 2, 1],
            ..Default::default()
        };
        let scene = one_node_scene(vec![primitive(Some(uvs.clone())), primitive(None)]);
        let geometry = SceneGeometry::new(&scene);
        assert_eq!(geometry.triangle_count(), 4);
        assert_eq!(geometry.triangle_uvs(&scene, 0), [uvs[0], uvs[1], uvs[2]]);
        assert_eq!(geometry.triangle_uvs(&scene, 1), [uvs[3], uvs[2], uvs[1]]);
        assert_eq!(geometry.triangle_uvs(&scene, 3), [Vec2::ZERO; 3]);
        let mirrored = Placement::new(Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0)));
        assert_eq!(
            geometry.oriented_uvs(&scene, 1, &mirrored),
            [uvs[3], uvs[1], uvs[2]]
        );
    }

    #[test]
    fn rebasing_keeps_differences_and_period() {
        let uv = [
            Vec2::new(1000.25, -7.5),
            Vec2::new(1001.0, -7.0),
            Vec2::new(1000.5, -6.25),
        ];
        let r = rebase_uvs(uv, [WrapMode::Repeat, WrapMode::MirroredRepeat]);
        assert_eq!(r[0], Vec2::new(0.25, 0.5));
        assert_eq!(r[1], Vec2::new(1.0, 1.0));
        assert_eq!(r[2], Vec2::new(0.5, 1.75));
        let c = rebase_uvs(uv, [WrapMode::ClampToEdge; 2]);
        assert_eq!(c, uv);
    }
}
