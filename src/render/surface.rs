//! A ray's hit as a surface point, and the optics of leaving it: mirror reflection, Snell
//! refraction and dielectric Fresnel.
//!
//! Shared by the Whitted integrator and the LOD probe, which must bend rays identically
//! (the probe reports what the integrator's lookups use). Orientation convention: every
//! normal of a [`SurfacePoint`] faces the incoming ray.

use glam::{Vec2, Vec3A};

use crate::accel::Hit;
use crate::geometry::HitTriangle;
use crate::lod::SurfaceHit;

/// Surface data at a hit, oriented towards the incoming ray.
#[derive(Clone, Copy)]
pub(super) struct SurfacePoint {
    /// World-space hit point.
    pub(super) position: Vec3A,
    /// Geometric normal on the side the ray came from.
    pub(super) face_normal: Vec3A,
    /// Interpolated normal, flipped to the same side as `face_normal`.
    pub(super) shading_normal: Vec3A,
    /// +1 or -1: what turns the mesh's vertex normals to the side of `shading_normal`.
    pub(super) normal_sign: f32,
    /// Whether the ray arrived on the front (counter-clockwise) side.
    pub(super) entering: bool,
    /// Offset that lifts spawned rays off the surface.
    pub(super) epsilon: f32,
}

/// Snell refraction at a surface: the incident cosine, the relative index, and the
/// transmitted direction with its cosine (`None` on total internal reflection).
#[derive(Clone, Copy)]
pub(super) struct Refraction {
    pub(super) cos_i: f32,
    pub(super) eta: f32,
    pub(super) transmitted: Option<(Vec3A, f32)>,
}

impl SurfacePoint {
    /// The point where `hit` (of a ray from `origin` along unit `direction`) lies on
    /// `triangle`, oriented towards the ray.
    // Always inlined: part of the tile kernel (`TraceTile`), compiled into each SIMD copy.
    #[inline(always)]
    pub(super) fn at(
        triangle: &HitTriangle,
        hit: &Hit,
        origin: Vec3A,
        direction: Vec3A,
    ) -> SurfacePoint {
        let [p0, p1, p2] = triangle.positions;
        let geometric = crate::geometry::unit_normal([p0, p1, p2]);
        let [n0, n1, n2] = triangle.normals;
        let (b1, b2) = (hit.bary.x, hit.bary.y);
        let interpolated =
            Vec3A::from(n0 * (1.0 - b1 - b2) + n1 * b1 + n2 * b2).normalize_or_zero();
        let entering = geometric.dot(direction) <= 0.0;
        let face_normal = if entering { geometric } else { -geometric };
        let (shading_normal, normal_sign) = match interpolated.dot(face_normal) {
            d if d > 0.0 => (interpolated, 1.0),
            d if d < 0.0 => (-interpolated, -1.0),
            _ => (face_normal, if entering { 1.0 } else { -1.0 }),
        };
        let position = origin + direction * hit.t;
        let magnitude = position.abs().max_element().max(origin.abs().max_element());
        SurfacePoint {
            position,
            face_normal,
            shading_normal,
            normal_sign,
            entering,
            epsilon: 1e-5 + magnitude * 2f32.powi(-17),
        }
    }

    /// Whether direction `to_light` leaves the surface on the side both its shading and
    /// geometric normals face: only then does a light there shine on it (and get a shadow
    /// ray).
    pub(super) fn faces(&self, to_light: Vec3A) -> bool {
        // Written as the negation of "either faces away" so that a NaN cosine counts as
        // facing, as the integrator always treated it.
        !(self.shading_normal.dot(to_light) <= 0.0 || self.face_normal.dot(to_light) <= 0.0)
    }

    /// The shadow ray from this point toward a light `distance` away along `to_light`:
    /// origin lifted off the surface, and the distance where the search ends (short of the
    /// light so that a light on a surface does not shadow itself). `None` when the light is
    /// closer than the lift.
    pub(super) fn shadow_ray(&self, distance: f32) -> Option<(Vec3A, f32)> {
        let origin = self.position + self.face_normal * self.epsilon;
        let t_max = if distance.is_finite() {
            distance * (1.0 - 1e-4) - self.epsilon
        } else {
            f32::INFINITY
        };
        (t_max > 0.0).then_some((origin, t_max))
    }

    /// Refraction of `direction` into (or out of) a material of index `ior`, on the side the
    /// ray arrived from.
    pub(super) fn refraction(&self, direction: Vec3A, ior: f32) -> Refraction {
        let eta = if self.entering { 1.0 / ior } else { ior };
        let n = self.shading_normal;
        let cos_i = (-direction.dot(n)).clamp(0.0, 1.0);
        Refraction {
            cos_i,
            eta,
            transmitted: refract(direction, n, cos_i, eta),
        }
    }

    /// What a LOD method reads at this hit.
    #[inline]
    pub(super) fn lod_hit<'t>(
        &self,
        triangle: &'t HitTriangle,
        hit: &Hit,
        direction: Vec3A,
    ) -> SurfaceHit<'t> {
        SurfaceHit {
            triangle,
            t: hit.t,
            direction,
            face_normal: self.face_normal,
            shading_normal: self.shading_normal,
            normal_sign: self.normal_sign,
            bary: hit.bary,
        }
    }

    /// The same point seen from the far side (where a transmitted ray leaves).
    pub(super) fn far_side(&self) -> SurfacePoint {
        SurfacePoint {
            face_normal: -self.face_normal,
            ..*self
        }
    }
}

/// Mirror direction about the shading normal; if that points into the surface (possible
/// with interpolated normals at grazing angles) the geometric normal is used instead.
#[inline]
pub(super) fn reflect(direction: Vec3A, shading_normal: Vec3A, face_normal: Vec3A) -> Vec3A {
    let r = direction - 2.0 * direction.dot(shading_normal) * shading_normal;
    if r.dot(face_normal) > 0.0 {
        r.normalize()
    } else {
        (direction - 2.0 * direction.dot(face_normal) * face_normal).normalize()
    }
}

/// Snell refraction of unit `direction` through a surface with normal `n` (facing the
/// incoming ray), relative index `eta = n_incident / n_transmitted`. `None` on total
/// internal reflection. Returns the direction and the cosine of the transmitted angle.
#[inline]
pub(super) fn refract(direction: Vec3A, n: Vec3A, cos_i: f32, eta: f32) -> Option<(Vec3A, f32)> {
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let t = eta * direction + (eta * cos_i - cos_t) * n;
    Some((t.normalize(), cos_t))
}

/// Unpolarised Fresnel reflectance of a dielectric boundary.
#[inline]
pub(super) fn dielectric_fresnel(cos_i: f32, cos_t: f32, eta: f32) -> f32 {
    // With eta = n1/n2: r_s = (n1 cos_i - n2 cos_t)/(n1 cos_i + n2 cos_t), divided by n2.
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let f = 0.5 * (rs * rs + rp * rp);
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Texture coordinates at barycentrics `(b1, b2)`.
#[inline]
pub(super) fn interpolate_uv([t0, t1, t2]: [Vec2; 3], bary: Vec2) -> Vec2 {
    t0 * (1.0 - bary.x - bary.y) + t1 * bary.x + t2 * bary.y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_at_normal_incidence_is_schlick_r0() {
        let eta = 1.0 / 1.5;
        let f = dielectric_fresnel(1.0, 1.0, eta);
        assert!((f - 0.04).abs() < 1e-6, "{f}");
        // Grazing incidence reflects everything.
        assert!(dielectric_fresnel(0.0, 0.7, eta) > 0.999);
    }

    #[test]
    fn refraction_obeys_snell_and_total_internal_reflection() {
        let n = Vec3A::Y;
        let angle = 40f32.to_radians();
        let d = Vec3A::new(angle.sin(), -angle.cos(), 0.0);
        let (t, cos_t) = refract(d, n, angle.cos(), 1.0 / 1.5).unwrap();
        let sin_t = (1.0 - cos_t * cos_t).sqrt();
        assert!((angle.sin() - 1.5 * sin_t).abs() < 1e-5);
        assert!((t.x - sin_t).abs() < 1e-5 && t.y < 0.0);
        // From glass to air past the critical angle (41.8 degrees): TIR.
        let steep = 60f32.to_radians();
        let d = Vec3A::new(steep.sin(), -steep.cos(), 0.0);
        assert!(refract(d, n, steep.cos(), 1.5).is_none());
    }

    #[test]
    fn reflection_never_enters_the_surface() {
        let face = Vec3A::Y;
        let bent = Vec3A::new(0.9, 0.1, 0.0).normalize();
        let d = Vec3A::new(1.0, -0.05, 0.0).normalize();
        let r = reflect(d, bent, face);
        assert!(r.dot(face) > 0.0);
        assert!((r.length() - 1.0).abs() < 1e-6);
    }
}

/// The shadow ray a hit sends toward `light` as the integrator traces it (origin, unit
/// direction, search distance), or `None` when the light cannot reach the hit's side. For
/// `mipray bench --rays shadow`, which times exactly the integrator's shadow rays.
pub fn shadow_ray_toward(
    scene: &crate::render::FrameScene,
    hit: Hit,
    origin: Vec3A,
    direction: Vec3A,
    light: &crate::render::Light,
) -> Option<(Vec3A, Vec3A, f32)> {
    let mut hit = hit;
    let triangle = scene.hit_triangle(&mut hit, origin, direction);
    let surface = SurfacePoint::at(&triangle, &hit, origin, direction);
    let incident = light.incident(surface.position)?;
    if !surface.faces(incident.to_light) {
        return None;
    }
    let (from, t_max) = surface.shadow_ray(incident.distance)?;
    Some((from, incident.to_light, t_max))
}
