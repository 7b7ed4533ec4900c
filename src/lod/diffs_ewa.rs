//! `diffs-ewa`: the ray differentials of `diffs` (48 bytes), filtered with an elliptically
//! weighted average as pbrt-v4's `MIPMap::Filter` does (the filter is
//! `texture::MipPyramid::sample_ewa`):
//!
//! ```text
//! major, minor = the longer, shorter of duv/dx, duv/dy      (texture coordinates per pixel)
//! if 16 |minor| < |major|:  minor *= |major| / (16 |minor|)  (anisotropy clamp)
//! level = log2 |minor|, in texels of level 0
//! lookup: Gaussian over the ellipse with conjugate semi-axes major and minor, in levels
//!         floor(level) and floor(level) + 1, blended by the fraction
//! ```
//!
//! Where ours differs from pbrt-v4: the anisotropy clamp is 16 (pbrt's default is 8), the
//! bound `paper-cos`, `diffs` and `diffs-aniso` use, so `diffs-aniso` and `diffs-ewa`
//! filter the same footprints; the minor axis is measured in texels of level 0 per axis
//! (`W` across, `H` down, the `diffs` convention) where pbrt scales texture coordinates by
//! the larger side (the same for square textures); a footprint with no minor axis at all (a
//! line) gets one of `|major| / 16` across it where pbrt falls back to bilinear at level 0;
//! and `--lod-bias b` scales both axes by `2^b` (pbrt has no bias).

use glam::{Vec2, Vec3A};

use super::diffs::TexelGradients;
use super::{
    COARSEST_LEVEL, Footprint, LodCamera, LodMethod, MAX_ANISOTROPY, RayDiffs, RayLod, SurfaceHit,
    fast_log2, finite_level,
};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RayDiffsEwa(pub RayDiffs);

/// An EWA footprint: the level of its minor axis and both axes in texels of level 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EllipticalFootprint {
    pub level: f32,
    pub major: Vec2,
    pub minor: Vec2,
}

impl TexelGradients {
    /// The EWA footprint of these gradients: the longer one as the major axis, the shorter
    /// one lengthened to at least `1 / MAX_ANISOTROPY` of it, and the minor axis's level.
    pub fn elliptical(&self) -> EllipticalFootprint {
        let (major, minor) = if self.dx.length_squared() >= self.dy.length_squared() {
            (self.dx, self.dy)
        } else {
            (self.dy, self.dx)
        };
        let (long, short) = (major.length(), minor.length());
        let shortest = long / MAX_ANISOTROPY as f32;
        let minor = if short >= shortest {
            minor
        } else if short > 0.0 {
            minor * (shortest / short)
        } else {
            // A line footprint: the minor axis across it.
            major.perp() / MAX_ANISOTROPY as f32
        };
        EllipticalFootprint {
            level: finite_level(fast_log2(minor.length().max(1e-30))),
            major,
            minor,
        }
    }
}

impl RayLod for RayDiffsEwa {
    const METHOD: LodMethod = LodMethod::DiffsEwa;
    const BYTES: usize = 48;
    type Kept = crate::geometry::HitTriangle;

    #[inline]
    fn primary(camera: &LodCamera, px: f32, py: f32) -> Self {
        RayDiffsEwa(RayDiffs::primary(camera, px, py))
    }

    #[inline]
    fn arrive(&mut self, hit: &SurfaceHit) {
        self.0.arrive(hit);
    }

    fn footprint(&self, hit: &SurfaceHit, _: &LodCamera, texture_size: (u32, u32)) -> Footprint {
        let Some(g) = self.0.texel_gradients(hit, texture_size) else {
            return Footprint::Level(COARSEST_LEVEL);
        };
        let e = g.elliptical();
        let size = Vec2::new(texture_size.0 as f32, texture_size.1 as f32);
        Footprint::Elliptical {
            level: e.level,
            major: e.major / size,
            minor: e.minor / size,
        }
    }

    #[inline]
    fn reflect(&self, hit: &SurfaceHit, reflected: Vec3A) -> Self {
        RayDiffsEwa(self.0.reflect(hit, reflected))
    }

    #[inline]
    fn refract(&self, hit: &SurfaceHit, eta: f32, refracted: Vec3A) -> Self {
        RayDiffsEwa(self.0.refract(hit, eta, refracted))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_isotropic_footprint_has_the_isotropic_level() {
        let g = TexelGradients {
            dx: Vec2::new(4.0, 0.0),
            dy: Vec2::new(0.0, 4.0),
        };
        let e = g.elliptical();
        assert_eq!(e.level, 2.0);
        assert_eq!(e.level, g.isotropic_level());
        assert_eq!((e.major, e.minor), (g.dx, g.dy));
    }

    #[test]
    fn the_level_follows_the_minor_axis_up_to_anisotropy_16() {
        let g = TexelGradients {
            dx: Vec2::new(0.0, 2.0),
            dy: Vec2::new(16.0, 0.0),
        };
        let e = g.elliptical();
        assert_eq!((e.major, e.minor), (g.dy, g.dx));
        assert_eq!(e.level, 1.0);
        // Elongation 64: the minor axis is lengthened to 64 / 16 = 4 texels, same direction.
        let g = TexelGradients {
            dx: Vec2::new(64.0, 0.0),
            dy: Vec2::new(0.0, 1.0),
        };
        let e = g.elliptical();
        assert_eq!(e.minor, Vec2::new(0.0, 4.0));
        assert_eq!(e.level, 2.0);
        // A line: a minor axis across it, 1/16 of it.
        let line = TexelGradients {
            dx: Vec2::new(0.0, 0.0),
            dy: Vec2::new(0.0, 64.0),
        };
        let e = line.elliptical();
        assert!((e.minor.length() - 4.0).abs() < 1e-6 && e.minor.dot(e.major) == 0.0);
        assert_eq!(e.level, 2.0);
    }

    #[test]
    fn a_zero_footprint_is_finite() {
        let e = TexelGradients {
            dx: Vec2::ZERO,
            dy: Vec2::ZERO,
        }
        .elliptical();
        assert!(e.level.is_finite() && e.level < 0.0);
        assert!(e.major.is_finite() && e.minor.is_finite());
    }
}
