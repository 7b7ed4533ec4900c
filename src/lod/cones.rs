//! `cones`: ray cones (Akenine-Moller et al., Ray Tracing Gems ch. 20, 2019; JCGT 2021;
//! refraction after Boksansky et al., RTG II ch. 10, and the OptiX toolkit). The ray carries
//! the cone's width `w` and full spread angle `gamma`, and the ratio `a` of its radial to
//! its tangential width (12 bytes).
//!
//! ```text
//! primary:     w = 0, gamma = k cos(theta), a = cos(theta),  k = 2 tan(fov/2) / H
//! arrive:      w += gamma * t
//! level:       log2(|w| L) - log2(pixel) - log2 P_b
//! reflection:  (w, gamma) *= sqrt(a), a = 1;  gamma += 2 beta
//! refraction:  (w, gamma) *= sqrt(a), a = 1;  gamma = eta (gamma + beta) - beta  (eta = n_i / n_t)
//! beta = kappa w / |n.d|                                     (surface spread, signed w)
//! ```
//!
//! `theta` is the primary ray's angle to the optical axis. A pinhole pixel off the axis is
//! an elliptical cone: `k cos(theta)` across the ray (tangential; the OptiX toolkit's
//! correction) and `k cos^2(theta)` along the radius, so `w` is the tangential width and
//! `a w` the radial one. `L` is the longest axis of that cross-section's footprint on the
//! surface per unit tangential width (`pixel.rs`): `1 / |n.d|` on the axis (RTG's
//! incidence term), exactly the tangential width on a plane facing the camera at any field
//! of view. Falcor's single angle for the whole image over-blurs the corners of such a plane
//! by `-log2 cos(theta)`, the tangential spread alone with RTG's `1 / |n.d|` by as much
//! again (4 levels, the clamp, in the corners of a 179-degree film). At the first mirror or
//! glass surface the cone becomes round, of the geometric mean of its two widths and spreads
//! (`sqrt(a)` times the tangential ones): the radial direction is the one towards the
//! optical axis, which a bent ray no longer has.
//!
//! `log2 P_b + log2(pixel)` is the texture-space triangle constant of ray cones,
//! `-(Delta + 0.5 log2(W H))` (LOD-ANCHORS.md 3.1), so cones reuse the per-triangle values
//! `paper` already keeps. `kappa` is the triangle's mean edge curvature from its vertex
//! normals (positive for convex as seen by the ray), `|n.d|` is clamped at 1/16 like
//! `paper-cos`. A converging cone may pass through a focus (negative width): the level
//! uses `|w|`, and a zero width clamps to level 0. The surface spread keeps the sign of `w`
//! (JCGT 2021's rule): past a focus the cone is inverted, so a convex mirror must push the
//! (negative) spread further negative, which `|w|` would turn into a false convergence
//! (3.7 levels too sharp on the two-mirror chain, `tests/lod_methods.rs`).

use glam::Vec3A;

use super::pixel::footprint_longest_axis;
use super::{
    Footprint, LodCamera, LodMethod, RayLod, SurfaceHit, fast_log2, finite_level,
    mean_edge_curvature,
};

/// Largest spread angle kept (radians): a cone wider than a half-space has no meaning, and
/// grazing curved mirrors could otherwise inflate it without bound.
const MAX_SPREAD: f32 = std::f32::consts::PI;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayCone {
    /// Tangential width (signed: negative past a focus).
    pub width: f32,
    /// Tangential spread angle.
    pub spread: f32,
    /// Radial over tangential width and spread, in `(0, 1]`: `cos(theta)` until the first
    /// surface, 1 (round) after it.
    pub radial_ratio: f32,
}

impl Default for RayCone {
    fn default() -> Self {
        RayCone {
            width: 0.0,
            spread: 0.0,
            radial_ratio: 1.0,
        }
    }
}

impl RayCone {
    /// The surface spread angle `beta` the hit's curvature adds over the cone's footprint,
    /// signed like the width (an inverted cone past a focus is spread the other way).
    #[inline]
    fn surface_spread(&self, hit: &SurfaceHit) -> f32 {
        let kappa = mean_edge_curvature(hit.positions(), hit.oriented_normals());
        let beta = kappa * self.width / hit.clamped_cos();
        if beta.is_finite() { beta } else { 0.0 }
    }

    #[inline]
    fn with_spread(self, spread: f32) -> Self {
        let spread = if spread.is_nan() { self.spread } else { spread };
        RayCone {
            spread: spread.clamp(-MAX_SPREAD, MAX_SPREAD),
            ..self
        }
    }

    /// The round cone of the same cross-section area: width and spread scaled to the
    /// geometric mean of their tangential and radial values.
    #[inline]
    fn round(self) -> Self {
        let mean = self.radial_ratio.sqrt();
        RayCone {
            width: self.width * mean,
            spread: self.spread * mean,
            radial_ratio: 1.0,
        }
    }
}

impl RayLod for RayCone {
    const METHOD: LodMethod = LodMethod::Cones;
    const BYTES: usize = 12;
    type Kept = crate::geometry::HitTriangle;

    #[inline]
    fn primary(camera: &LodCamera, px: f32, py: f32) -> Self {
        let pixel = camera.pixel_widths(px, py);
        RayCone {
            width: 0.0,
            spread: camera.spread * pixel.tangential,
            radial_ratio: pixel.ratio(),
        }
    }

    #[inline]
    fn arrive(&mut self, hit: &SurfaceHit) {
        let width = self.width + self.spread * hit.t;
        if width.is_finite() {
            self.width = width;
        }
    }

    #[inline]
    fn footprint(&self, hit: &SurfaceHit, camera: &LodCamera, _: (u32, u32)) -> Footprint {
        let longest = footprint_longest_axis(self.radial_ratio, hit, camera.forward);
        let level = fast_log2((self.width.abs() * longest).max(f32::MIN_POSITIVE))
            - camera.log2_pixel
            - hit.log2_pb();
        Footprint::Level(finite_level(level))
    }

    #[inline]
    fn reflect(&self, hit: &SurfaceHit, _: Vec3A) -> Self {
        let cone = self.round();
        cone.with_spread(cone.spread + 2.0 * cone.surface_spread(hit))
    }

    #[inline]
    fn refract(&self, hit: &SurfaceHit, eta: f32, _: Vec3A) -> Self {
        let cone = self.round();
        let beta = cone.surface_spread(hit);
        cone.with_spread(eta * (cone.spread + beta) - beta)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{camera, facing_triangle, hit_on, sphere_cap_triangle};
    use super::*;

    #[test]
    fn primary_cone_is_one_pixel_wide_per_metre_and_narrows_off_axis() {
        let cam = camera(1.0, 100);
        let k = 2.0 * 0.5f32.tan() / 100.0;
        let centre = RayCone::primary(&cam, 50.0, 50.0);
        assert_eq!(centre.width, 0.0);
        assert!((centre.spread - k).abs() < 1e-7 * k);
        // A corner ray is at `theta` with cos = 1 / |(sx, sy, 1)|.
        let corner = RayCone::primary(&cam, 0.0, 0.0);
        let cos = 1.0 / (1.0 + 2.0 * 0.5f32.tan().powi(2)).sqrt();
        assert!(
            (corner.spread - k * cos).abs() < 1e-6 * k,
            "{}",
            corner.spread
        );
        assert!((corner.radial_ratio - cos).abs() < 1e-6, "{corner:?}");
        assert_eq!(centre.radial_ratio, 1.0);
    }

    #[test]
    fn an_off_axis_cone_becomes_round_at_its_first_surface() {
        let cam = camera(2.0, 100);
        let triangles = facing_triangle(-3.0, 0.0);
        let hit = hit_on(&triangles, 3.0, Vec3A::NEG_Z, 1.0);
        let mut cone = RayCone::primary(&cam, 0.5, 0.5);
        cone.arrive(&hit);
        let a = cone.radial_ratio;
        assert!(a < 0.5, "{cone:?}");
        // A flat mirror adds no spread: only the rounding to the geometric mean.
        let reflected = cone.reflect(&hit, Vec3A::Z);
        assert_eq!(reflected.radial_ratio, 1.0);
        assert!((reflected.width - cone.width * a.sqrt()).abs() < 1e-7);
        assert!((reflected.spread - cone.spread * a.sqrt()).abs() < 1e-9);
        let refracted = cone.refract(&hit, 1.0, Vec3A::NEG_Z);
        assert_eq!(refracted, reflected);
    }

    #[test]
    fn facing_level_is_log2_width_minus_the_triangle_constant() {
        let cam = camera(1.0, 100);
        let triangles = facing_triangle(-3.0, 2.5);
        let hit = hit_on(&triangles, 3.0, Vec3A::NEG_Z, 1.0);
        let mut cone = RayCone::primary(&cam, 50.0, 50.0);
        cone.arrive(&hit);
        assert!((cone.width - 3.0 * cam.spread).abs() < 1e-6);
        let level = cone.footprint(&hit, &cam, (1, 1)).level();
        // w = k t and log2 k = log2_pixel: the level is log2 t - log2 P_b.
        assert!((level - (3f32.log2() - 2.5)).abs() < 1e-5, "{level}");
    }

    #[test]
    fn convex_mirror_widens_the_spread_by_twice_the_surface_spread() {
        let triangles = sphere_cap_triangle(2.0);
        let hit = hit_on(&triangles, 1.0, Vec3A::NEG_Z, 1.0);
        let cos = hit.clamped_cos();
        let cone = RayCone {
            width: 0.3,
            spread: 0.01,
            radial_ratio: 1.0,
        };
        // kappa = 1 / 2: beta = 0.15 / cos.
        let reflected = cone.reflect(&hit, Vec3A::Z);
        assert!(
            (reflected.spread - (0.01 + 0.3 / cos)).abs() < 1e-5,
            "{reflected:?}"
        );
        // Past a focus (negative width) the cone is inverted: a convex mirror makes it
        // diverge faster, i.e. the spread more negative (|w| would make it converge).
        let inverted = RayCone {
            width: -0.3,
            spread: -0.01,
            radial_ratio: 1.0,
        };
        let reflected = inverted.reflect(&hit, Vec3A::Z);
        assert!(
            (reflected.spread - (-0.01 - 0.3 / cos)).abs() < 1e-5,
            "{reflected:?}"
        );
        // Seen from inside (a concave mirror) the same patch converges the cone.
        let inside = hit_on(&triangles, 1.0, Vec3A::Z, -1.0);
        let reflected = cone.reflect(&inside, Vec3A::NEG_Z);
        assert!(
            (reflected.spread - (0.01 - 0.3 / cos)).abs() < 1e-5,
            "{reflected:?}"
        );
    }

    #[test]
    fn flat_refraction_scales_the_spread_by_eta() {
        let triangles = facing_triangle(0.0, 0.0);
        let hit = hit_on(&triangles, 1.0, Vec3A::NEG_Z, 1.0);
        let cone = RayCone {
            width: 0.3,
            spread: 0.01,
            radial_ratio: 1.0,
        };
        let refracted = cone.refract(&hit, 1.0 / 1.5, Vec3A::NEG_Z);
        assert!((refracted.spread - 0.01 / 1.5).abs() < 1e-8);
        assert_eq!(refracted.width, 0.3);
        // On a ball (kappa = 1/2) the paraxial law: eta (gamma + beta) - beta.
        let ball = sphere_cap_triangle(2.0);
        let hit = hit_on(&ball, 1.0, Vec3A::NEG_Z, 1.0);
        let beta = 0.5 * 0.3 / hit.clamped_cos();
        let refracted = cone.refract(&hit, 1.0 / 1.5, Vec3A::NEG_Z);
        assert!((refracted.spread - ((0.01 + beta) / 1.5 - beta)).abs() < 1e-6);
    }
}
