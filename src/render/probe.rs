//! The LOD probe: the level a method selects at the first textured surface a pixel's
//! centre ray reaches, directly or through mirrors and glass.
//!
//! Used by `--view lod`, `mipray compare` (its finite-difference reference follows the
//! probe's specular chain) and tests; rendering never calls it. The probe bends rays with
//! the same `surface` optics and asks the method for the same footprint as the integrator,
//! so what it reports is what the integrator's lookup used.

use glam::{Vec2, Vec3A};

use crate::accel::{Hit, TriangleRef};
use crate::geometry::HitTriangle;
use crate::lod::{RayLod, with_lod_state};
use crate::render::camera::Camera;
use crate::render::integrator::FrameScene;
use crate::render::material::Material;
use crate::render::surface::{SurfacePoint, interpolate_uv, reflect, refract};

/// Longest specular chain a probe records (mirror and glass bounces before the textured hit).
pub const MAX_CHAIN: usize = 16;

/// How a ray left one surface of a specular chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bend {
    Reflect,
    /// Refracted with relative index `eta = n_incident / n_transmitted`.
    Refract {
        eta: f32,
    },
}

/// The specular chain from the eye to a textured surface: each mirror or glass triangle
/// hit on the way and how the ray bent there, then the textured triangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chain {
    bends: [(TriangleRef, Bend); MAX_CHAIN],
    len: usize,
}

impl Chain {
    fn new() -> Chain {
        Chain {
            bends: [(TriangleRef::default(), Bend::Reflect); MAX_CHAIN],
            len: 0,
        }
    }

    /// The surfaces passed before the textured one: (triangle, bend).
    pub fn bends(&self) -> &[(TriangleRef, Bend)] {
        &self.bends[..self.len]
    }
}

/// The LOD selected at the first textured surface along a specular chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LodProbe {
    /// The textured triangle hit, and its material.
    pub triangle: TriangleRef,
    pub material: u32,
    /// Total distance from the ray's origin over every bounce.
    pub path_length: f32,
    /// The method's level including the bias, before clamping to the texture's pyramid.
    pub level: f32,
    /// The level the lookup used: clamped to `[0, last level]` (0 for `none`).
    pub clamped_level: f32,
    /// Texture coordinates at the hit.
    pub uv: Vec2,
    /// Index of the base-colour texture and its level-0 size.
    pub texture: usize,
    pub texture_size: (u32, u32),
    /// Number of MIP levels of that texture.
    pub texture_levels: usize,
    /// The mirrors and glass passed on the way.
    pub chain: Chain,
}

impl FrameScene<'_> {
    /// Follows the primary ray through film point `(px, py)` along perfect mirrors and
    /// glass (the dominant specular branch) to its first textured surface and reports the
    /// LOD method `L` selects there. For tests, `--view lod` and `mipray compare`; the
    /// integrator computes the same quantities inline.
    pub fn probe<L: RayLod>(&self, camera: &Camera, px: f32, py: f32) -> Option<LodProbe> {
        let direction = camera.primary_direction(px, py);
        self.probe_ray(camera.eye, direction, L::primary(&self.lod_camera, px, py))
    }

    /// [`Self::probe`] with the state type of `self.lod`.
    pub fn probe_method(&self, camera: &Camera, px: f32, py: f32) -> Option<LodProbe> {
        with_lod_state!(self.lod, L => self.probe::<L>(camera, px, py))
    }

    /// [`Self::probe`] for any ray and starting state.
    pub fn probe_ray<L: RayLod>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        mut lod: L,
    ) -> Option<LodProbe> {
        let (mut origin, mut direction) = (origin, direction);
        let mut path_length = 0.0f32;
        let mut chain = Chain::new();
        loop {
            let mut hit = self.bvh.closest_hit(origin, direction, f32::INFINITY)?;
            let triangle = self.hit_triangle(&mut hit, origin, direction);
            let surface = SurfacePoint::at(&triangle, &hit, origin, direction);
            let lod_hit = surface.lod_hit(&triangle, &hit, direction);
            lod.arrive(&lod_hit);
            path_length += hit.t;
            let material = &self.materials[triangle.material as usize];
            if let Some((index, texture)) = material
                .base_color_texture
                .and_then(|t| Some((t, self.textures.get(t)?)))
            {
                let footprint =
                    lod.footprint(&lod_hit, &self.lod_camera, texture.pyramid.base_size());
                let (level, clamped_level) = self.biased_level(&footprint, &texture.pyramid);
                return Some(LodProbe {
                    triangle: hit.triangle_ref(),
                    material: triangle.material,
                    path_length,
                    level,
                    clamped_level,
                    uv: interpolate_uv(triangle.uvs, hit.bary),
                    texture: index,
                    texture_size: texture.pyramid.base_size(),
                    texture_levels: texture.pyramid.level_count(),
                    chain,
                });
            }
            if chain.len == MAX_CHAIN || chain.len as u32 >= self.max_depth {
                return None;
            }
            let (next, bend) = dominant_bend(&surface, direction, material)?;
            lod = match bend {
                Bend::Reflect => lod.reflect(&lod_hit, next),
                Bend::Refract { eta } => lod.refract(&lod_hit, eta, next),
            };
            chain.bends[chain.len] = (hit.triangle_ref(), bend);
            chain.len += 1;
            let side = match bend {
                Bend::Reflect => surface.face_normal,
                Bend::Refract { .. } => -surface.face_normal,
            };
            direction = next;
            origin = surface.position + side * surface.epsilon;
        }
    }

    /// Where a ray from `origin` along `direction` lands in texture space if it follows
    /// `chain` (the probe of a nearby ray) and then meets the plane of `textured`: each
    /// surface is intersected as its triangle's plane, with barycentrics extrapolated
    /// outside the triangle, and bent the same way. The finite-difference LOD reference
    /// traces its neighbouring pixel rays with this. `None` if a plane is missed (parallel
    /// or behind) or a refraction becomes total internal reflection.
    pub fn follow_chain(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        chain: &Chain,
        textured: TriangleRef,
    ) -> Option<Vec2> {
        let (mut origin, mut direction) = (origin, direction);
        for &(at, bend) in chain.bends() {
            let surface = self.plane_point(&self.world_triangle(at), origin, direction)?;
            direction = match bend {
                Bend::Reflect => reflect(direction, surface.shading_normal, surface.face_normal),
                Bend::Refract { eta } => {
                    let n = surface.shading_normal;
                    let cos_i = (-direction.dot(n)).clamp(0.0, 1.0);
                    refract(direction, n, cos_i, eta)?.0
                }
            };
            origin = surface.position;
        }
        let textured = self.world_triangle(textured);
        let (_, bary) = plane_barycentrics(textured.positions, origin, direction)?;
        Some(interpolate_uv(textured.uvs, bary))
    }

    fn world_triangle(&self, at: TriangleRef) -> HitTriangle {
        self.bvh.triangle(at)
    }

    /// The hit of a ray with the plane of `triangle`, as a surface point.
    fn plane_point(
        &self,
        triangle: &HitTriangle,
        origin: Vec3A,
        direction: Vec3A,
    ) -> Option<SurfacePoint> {
        let (t, bary) = plane_barycentrics(triangle.positions, origin, direction)?;
        let hit = Hit {
            t,
            triangle: 0,
            instance: Hit::WORLD,
            bary,
        };
        Some(SurfacePoint::at(triangle, &hit, origin, direction))
    }
}

/// The branch a probe follows at a mirror or glass surface: refraction through mostly
/// transmissive surfaces (reflection on total internal reflection), reflection off mostly
/// reflective ones; `None` for anything else (a diffuse surface ends the chain).
fn dominant_bend(
    surface: &SurfacePoint,
    direction: Vec3A,
    material: &Material,
) -> Option<(Vec3A, Bend)> {
    let reflected = || reflect(direction, surface.shading_normal, surface.face_normal);
    if material.transmission >= 0.5 {
        let r = surface.refraction(direction, material.ior);
        Some(match r.transmitted {
            Some((refracted, _)) => (refracted, Bend::Refract { eta: r.eta }),
            None => (reflected(), Bend::Reflect),
        })
    } else if material.reflectance >= 0.5 {
        Some((reflected(), Bend::Reflect))
    } else {
        None
    }
}

/// Distance to, and barycentrics of, the point where a ray meets a triangle's plane, with
/// no bounds on the barycentrics (Moller-Trumbore without the inside test). `None` when the
/// ray is parallel to the plane, the triangle is degenerate, or the plane is behind.
fn plane_barycentrics(p: [Vec3A; 3], origin: Vec3A, direction: Vec3A) -> Option<(f32, Vec2)> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let pvec = direction.cross(e2);
    let det = e1.dot(pvec);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let tvec = origin - p[0];
    let b1 = tvec.dot(pvec) * inv;
    let qvec = tvec.cross(e1);
    let b2 = direction.dot(qvec) * inv;
    let t = e2.dot(qvec) * inv;
    (t > 0.0 && t.is_finite() && b1.is_finite() && b2.is_finite()).then_some((t, Vec2::new(b1, b2)))
}
