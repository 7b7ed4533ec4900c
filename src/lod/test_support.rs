//! One-triangle hits for the methods' unit tests: a `HitTriangle` and a `SurfaceHit` on it, so each formula can be checked without a scene.

use glam::{Vec2, Vec3, Vec3A};

use super::{LodCamera, SurfaceHit, ViewFrame};
use crate::geometry::HitTriangle;

/// A single triangle with the given vertex normals, UVs and `log2 P_b`.
pub fn one_triangle(
    positions: [Vec3A; 3],
    normals: [Vec3; 3],
    uvs: [Vec2; 3],
    log2_pb: f32,
) -> HitTriangle {
    HitTriangle {
        positions,
        normals,
        uvs,
        material: 0,
        log2_pb,
        source: 0,
    }
}

/// A flat triangle in the plane `z = z`, facing +Z, UVs = (x, y) of the vertices.
pub fn facing_triangle(z: f32, log2_pb: f32) -> HitTriangle {
    let p = [
        Vec3A::new(-1.0, -1.0, z),
        Vec3A::new(1.0, -1.0, z),
        Vec3A::new(0.0, 1.0, z),
    ];
    let uvs = p.map(|v| Vec2::new(v.x, v.y));
    one_triangle(p, [Vec3::Z; 3], uvs, log2_pb)
}

/// A small triangle on the sphere of `radius` about the origin around +Z, with the
/// sphere's outward normals (curvature `1 / radius` seen from outside).
pub fn sphere_cap_triangle(radius: f32) -> HitTriangle {
    let n = [
        Vec3::new(-0.02, -0.02, 1.0),
        Vec3::new(0.02, -0.02, 1.0),
        Vec3::new(0.0, 0.02, 1.0),
    ]
    .map(|v| v.normalize());
    let p = n.map(|v| Vec3A::from(v * radius));
    one_triangle(p, n, [Vec2::ZERO; 3], 0.0)
}

/// The hit of a ray along `direction` at distance `t` in the middle of `triangle`, seen from
/// the side `normal_sign` turns the vertex normals to (+1 for the +Z side).
pub fn hit_on(
    triangle: &HitTriangle,
    t: f32,
    direction: Vec3A,
    normal_sign: f32,
) -> SurfaceHit<'_> {
    let [p0, p1, p2] = triangle.positions;
    let face = (p1 - p0).cross(p2 - p0).normalize() * normal_sign;
    SurfaceHit {
        triangle,
        t,
        direction,
        face_normal: face,
        shading_normal: face,
        normal_sign,
        bary: Vec2::splat(1.0 / 3.0),
    }
}

/// A square camera looking down -Z with vertical field of view `yfov` and `height` pixels.
pub fn camera(yfov: f32, height: u32) -> LodCamera {
    LodCamera::new(&ViewFrame {
        forward: Vec3A::NEG_Z,
        right: Vec3A::X,
        up: Vec3A::Y,
        yfov,
        width: height,
        height,
    })
}
