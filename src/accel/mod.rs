//! Acceleration structure: an obvhs `Bvh2` over the frame's triangles, closest-hit and
//! shadow traversal.
//!
//! Built without spatial splits so it can be refitted later. After a build the triangle
//! arrays are permuted into BVH order (`FrameTriangles::permute`), so a leaf's primitive
//! range indexes the triangle arrays directly: no indirection on the hot path.
//! Leaf boxes are padded (see [`padded_box`]) because a flat triangle's box has zero
//! thickness and an axis-aligned ray can slip through it by rounding.

use std::time::Duration;

use glam::{Vec2, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    bvh2::{Bvh2, builder::build_bvh2},
    fast_stack,
    ray::{Ray, RayHit},
};

use crate::geometry::FrameTriangles;

/// The closest intersection along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Triangle slot (BVH order).
    pub triangle: u32,
    pub t: f32,
    /// Barycentric weights of vertices 1 and 2.
    pub bary: Vec2,
}

/// A BVH over one frame's triangles.
#[derive(Default)]
pub struct Accel {
    bvh: Bvh2,
}

/// Errors that stop a BVH build.
#[derive(Debug, thiserror::Error)]
pub enum AccelError {
    #[error("triangle {triangle} has a non-finite vertex ({vertex:?})")]
    NonFiniteVertex { triangle: usize, vertex: [f32; 3] },
}

impl Accel {
    /// Builds a BVH over `triangles` (in any order) and permutes them into BVH order.
    ///
    /// # Errors
    /// A non-finite vertex (obvhs would panic on it).
    pub fn build(triangles: &mut FrameTriangles) -> Result<Accel, AccelError> {
        check_finite(triangles)?;
        if triangles.is_empty() {
            return Ok(Accel::default());
        }
        let boxes: Vec<Aabb> = triangles.positions.iter().map(padded_box).collect();
        let bvh = build_bvh2(
            &boxes,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        triangles.permute(&bvh.primitive_indices);
        Ok(Accel { bvh })
    }

    /// The closest hit with `t` in `[0, t_max)`.
    #[inline]
    pub fn closest_hit(
        &self,
        triangles: &FrameTriangles,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> Option<Hit> {
        let ray = Ray::new(origin, direction, 0.0, t_max);
        let mut hit = RayHit::none();
        let mut bary = Vec2::ZERO;
        let found = self.bvh.ray_traverse(ray, &mut hit, |ray, slot| {
            match intersect(&triangles.positions[slot], ray.origin, ray.direction) {
                Some((t, b)) if t >= ray.tmin && t < ray.tmax => {
                    bary = b;
                    t
                }
                _ => f32::INFINITY,
            }
        });
        found.then_some(Hit {
            triangle: hit.primitive_id,
            t: hit.t,
            bary,
        })
    }

    /// Visits every triangle hit with `t` in `[0, t_max)` in no particular order until
    /// `visit(slot)` returns false. Returns false when it was stopped early.
    #[inline]
    pub fn visit_hits(
        &self,
        triangles: &FrameTriangles,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        mut visit: impl FnMut(u32) -> bool,
    ) -> bool {
        let ray = Ray::new(origin, direction, 0.0, t_max);
        let mut completed = true;
        let mut test_leaf = |node: &obvhs::bvh2::node::Bvh2Node, ray: &mut Ray, _: &mut RayHit| {
            for slot in node.first_index..node.first_index + node.prim_count {
                let inside = matches!(
                    intersect(&triangles.positions[slot as usize], ray.origin, ray.direction),
                    Some((t, _)) if t >= ray.tmin && t < ray.tmax
                );
                if inside && !visit(slot) {
                    completed = false;
                    return false;
                }
            }
            true
        };
        fast_stack!(u32, (96, 192), self.bvh.max_depth, stack, {
            self.bvh
                .ray_traverse_dynamic(&mut stack, ray, &mut RayHit::none(), &mut test_leaf)
        });
        completed
    }
}

fn check_finite(triangles: &FrameTriangles) -> Result<(), AccelError> {
    for (i, tri) in triangles.positions.iter().enumerate() {
        if let Some(v) = tri.iter().find(|v| !v.is_finite()) {
            return Err(AccelError::NonFiniteVertex {
                triangle: triangles.source[i] as usize,
                vertex: v.to_array(),
            });
        }
    }
    Ok(())
}

/// A triangle's box grown by a few ulps of its own magnitude on every axis, so that a flat
/// box still has volume and slab tests cannot miss it by rounding.
pub fn padded_box(tri: &[Vec3A; 3]) -> Aabb {
    let min = tri[0].min(tri[1]).min(tri[2]);
    let max = tri[0].max(tri[1]).max(tri[2]);
    let magnitude = min.abs().max(max.abs()).max_element();
    let pad = Vec3A::splat(magnitude * 2f32.powi(-20) + f32::MIN_POSITIVE * 8.0);
    Aabb::new(min - pad, max + pad)
}

/// Möller-Trumbore ray/triangle intersection, both faces. Returns `t` and the barycentric
/// weights of vertices 1 and 2.
#[inline(always)]
pub fn intersect(tri: &[Vec3A; 3], origin: Vec3A, direction: Vec3A) -> Option<(f32, Vec2)> {
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let pvec = direction.cross(e2);
    let det = e1.dot(pvec);
    if det.abs() < f32::MIN_POSITIVE || !det.is_finite() {
        return None;
    }
    let inv_det = 1.0 / det;
    let tvec = origin - tri[0];
    let u = tvec.dot(pvec) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qvec = tvec.cross(e1);
    let v = direction.dot(qvec) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(qvec) * inv_det;
    t.is_finite().then_some((t, Vec2::new(u, v)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn soup(tris: &[[Vec3A; 3]]) -> FrameTriangles {
        FrameTriangles {
            positions: tris.to_vec(),
            normals: vec![[Vec3::Z; 3]; tris.len()],
            uvs: vec![[Vec2::ZERO; 3]; tris.len()],
            material: vec![0; tris.len()],
            log2_pb: vec![0.0; tris.len()],
            source: (0..tris.len() as u32).collect(),
        }
    }

    #[test]
    fn finds_closest_of_stacked_triangles() {
        let tri = |z: f32| {
            [
                Vec3A::new(-1.0, -1.0, z),
                Vec3A::new(1.0, -1.0, z),
                Vec3A::new(0.0, 1.0, z),
            ]
        };
        let mut tris = soup(&[tri(-5.0), tri(-2.0), tri(-9.0)]);
        let accel = Accel::build(&mut tris).unwrap();
        let hit = accel
            .closest_hit(&tris, Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY)
            .unwrap();
        assert!((hit.t - 2.0).abs() < 1e-6);
        assert_eq!(tris.source[hit.triangle as usize], 1);
        let mut count = 0;
        accel.visit_hits(&tris, Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY, |_| {
            count += 1;
            true
        });
        assert_eq!(count, 3);
        assert!(
            accel
                .closest_hit(
                    &tris,
                    Vec3A::new(5.0, 0.0, 0.0),
                    Vec3A::NEG_Z,
                    f32::INFINITY
                )
                .is_none()
        );
    }

    #[test]
    fn axis_aligned_ray_hits_axis_aligned_flat_triangle() {
        // Floor at y = 0 seen straight down, and a wall at x = 3 hit along +x.
        let floor = [
            Vec3A::new(-1.0, 0.0, -1.0),
            Vec3A::new(1.0, 0.0, -1.0),
            Vec3A::new(0.0, 0.0, 1.0),
        ];
        let wall = [
            Vec3A::new(3.0, -1.0, -1.0),
            Vec3A::new(3.0, 1.0, -1.0),
            Vec3A::new(3.0, 0.0, 1.0),
        ];
        let mut tris = soup(&[floor, wall]);
        let accel = Accel::build(&mut tris).unwrap();
        let down = accel.closest_hit(
            &tris,
            Vec3A::new(0.0, 5.0, 0.0),
            Vec3A::NEG_Y,
            f32::INFINITY,
        );
        assert!((down.unwrap().t - 5.0).abs() < 1e-6);
        let side = accel.closest_hit(&tris, Vec3A::new(-2.0, 0.0, 0.0), Vec3A::X, f32::INFINITY);
        assert!((side.unwrap().t - 5.0).abs() < 1e-6);
    }

    #[test]
    fn rejects_non_finite_vertices() {
        let mut tris = soup(&[[Vec3A::ZERO, Vec3A::X, Vec3A::new(f32::NAN, 0.0, 0.0)]]);
        assert!(matches!(
            Accel::build(&mut tris),
            Err(AccelError::NonFiniteVertex { triangle: 0, .. })
        ));
    }

    #[test]
    fn empty_scene_misses() {
        let mut tris = soup(&[]);
        let accel = Accel::build(&mut tris).unwrap();
        assert!(
            accel
                .closest_hit(&tris, Vec3A::ZERO, Vec3A::X, f32::INFINITY)
                .is_none()
        );
    }
}
