//! Analytic AFF shapes turned into triangles: polygons (`p`, `pp`), open cones and
//! cylinders (`c`), spheres (`s`).
//!
//! Tessellation (documented choice): a cone/cylinder is [`CONE_SEGMENTS`] = 32 quads (64
//! triangles) around its axis with smooth per-vertex normals of the exact slanted surface
//! and no end caps (AFF cones are open); negative radii (inside visible) are made positive,
//! since every AFF material is double-sided. A sphere is a UV sphere of
//! [`SPHERE_SEGMENTS`] x [`SPHERE_RINGS`] with unit normals.

use glam::Vec3;

use super::builder::Geometry;

pub const CONE_SEGMENTS: u32 = 32;
pub const SPHERE_SEGMENTS: u32 = 32;
pub const SPHERE_RINGS: u32 = 16;

/// Two unit vectors perpendicular to unit `w` and to each other, with `u x v = w`.
fn basis(w: Vec3) -> (Vec3, Vec3) {
    let helper = if w.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let u = helper.cross(w).normalize();
    (u, w.cross(u))
}

/// Fan triangulation (0, k, k+1) of a convex polygon; `None` below 3 vertices.
pub fn polygon(positions: Vec<Vec3>, normals: Option<Vec<Vec3>>) -> Geometry {
    let n = positions.len() as u32;
    let indices = (1..n.saturating_sub(1))
        .flat_map(|k| [0, k, k + 1])
        .collect();
    Geometry {
        positions,
        normals,
        uvs: None,
        indices,
    }
}

/// An open cone from `base` (radius `r0`) to `apex` (radius `r1`); empty when the axis has
/// no length or both radii are zero.
pub fn cone(base: Vec3, r0: f32, apex: Vec3, r1: f32) -> Geometry {
    let (r0, r1) = (r0.abs(), r1.abs());
    let axis = apex - base;
    let length = axis.length();
    let Some(w) = axis.try_normalize() else {
        return Geometry::default();
    };
    if r0 == 0.0 && r1 == 0.0 {
        return Geometry::default();
    }
    let (u, v) = basis(w);
    let mut g = Geometry::default();
    let mut normals = Vec::with_capacity(2 * CONE_SEGMENTS as usize);
    for i in 0..CONE_SEGMENTS {
        let angle = std::f32::consts::TAU * i as f32 / CONE_SEGMENTS as f32;
        let radial = u * angle.cos() + v * angle.sin();
        // Surface normal of the slanted side: radial tilted by the radius change.
        let normal = (radial * length + w * (r0 - r1)).normalize();
        g.positions.push(base + radial * r0);
        g.positions.push(apex + radial * r1);
        normals.push(normal);
        normals.push(normal);
    }
    for i in 0..CONE_SEGMENTS {
        let j = (i + 1) % CONE_SEGMENTS;
        let (b0, a0, b1, a1) = (2 * i, 2 * i + 1, 2 * j, 2 * j + 1);
        // Counter-clockwise seen from outside (normal = radial).
        g.indices.extend([b0, b1, a1, b0, a1, a0]);
    }
    g.normals = Some(normals);
    g
}

/// A UV sphere; empty for a zero radius.
pub fn sphere(centre: Vec3, radius: f32) -> Geometry {
    let radius = radius.abs();
    if radius == 0.0 {
        return Geometry::default();
    }
    let mut g = Geometry::default();
    let mut normals = Vec::new();
    for ring in 0..=SPHERE_RINGS {
        let theta = std::f32::consts::PI * ring as f32 / SPHERE_RINGS as f32;
        for seg in 0..=SPHERE_SEGMENTS {
            let phi = std::f32::consts::TAU * seg as f32 / SPHERE_SEGMENTS as f32;
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            g.positions.push(centre + n * radius);
            normals.push(n);
        }
    }
    let row = SPHERE_SEGMENTS + 1;
    for ring in 0..SPHERE_RINGS {
        for seg in 0..SPHERE_SEGMENTS {
            let a = ring * row + seg;
            let b = a + row;
            if ring != 0 {
                g.indices.extend([a, a + 1, b]);
            }
            if ring != SPHERE_RINGS - 1 {
                g.indices.extend([a + 1, b + 1, b]);
            }
        }
    }
    g.normals = Some(normals);
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cone_normals_point_outward_and_winding_agrees() {
        let g = cone(Vec3::ZERO, 1.0, Vec3::new(0.0, 2.0, 0.0), 0.5);
        assert_eq!(g.indices.len() as u32, 6 * CONE_SEGMENTS);
        let normals = g.normals.as_ref().unwrap();
        for tri in g.indices.chunks(3) {
            let [a, b, c] = [0, 1, 2].map(|k| g.positions[tri[k] as usize]);
            let face = (b - a).cross(c - a);
            let centroid = (a + b + c) / 3.0;
            let outward = Vec3::new(centroid.x, 0.0, centroid.z);
            assert!(face.dot(outward) > 0.0);
            assert!(normals[tri[0] as usize].dot(outward) > 0.0);
        }
        // r0 > r1: normals tilt up towards the apex.
        assert!(normals[0].y > 0.0);
    }
}
