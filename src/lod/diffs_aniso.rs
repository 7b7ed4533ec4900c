//! `diffs-aniso`: the ray differentials of `diffs` (48 bytes), filtered anisotropically as
//! OpenGL's EXT_texture_filter_anisotropic suggests:
//!
//! ```text
//! P_max, P_min = longer, shorter of |duv/dx|, |duv/dy|   (texels)
//! N     = min(ceil(P_max / P_min - 0.001), 16)            taps
//! level = log2(P_max / N)
//! ```
//!
//! and `N` trilinear taps at that level, spaced evenly along the major axis across the
//! footprint, averaged. An isotropic footprint (`N = 1`) is exactly `diffs`.

use glam::{Vec2, Vec3A};

use super::diffs::TexelGradients;
use super::{
    COARSEST_LEVEL, Footprint, LodCamera, LodMethod, MAX_ANISOTROPY, RayDiffs, RayLod, SurfaceHit,
    fast_log2, finite_level,
};

/// Elongation below which a footprint counts as an exact integer ratio.
const RATIO_TOLERANCE: f32 = 1e-3;

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RayDiffsAniso(pub RayDiffs);

impl TexelGradients {
    /// The anisotropic lookup: `(level, taps, major axis in texels)`.
    pub fn anisotropic(&self) -> (f32, u32, Vec2) {
        let (lx, ly) = (self.dx.length(), self.dy.length());
        let (major, p_max, p_min) = if lx >= ly {
            (self.dx, lx, ly)
        } else {
            (self.dy, ly, lx)
        };
        // A ratio a rounding error above an integer (exactly 2 at 60 degrees) must not buy
        // a tap, and a finer level with it.
        let ratio = p_max / p_min;
        let taps = if ratio.is_finite() {
            ((ratio - RATIO_TOLERANCE).ceil() as u32).clamp(1, MAX_ANISOTROPY)
        } else {
            MAX_ANISOTROPY
        };
        let level = finite_level(fast_log2((p_max / taps as f32).max(1e-30)));
        (level, taps, major)
    }
}

impl RayLod for RayDiffsAniso {
    const METHOD: LodMethod = LodMethod::DiffsAniso;
    const BYTES: usize = 48;
    type Kept = crate::geometry::HitTriangle;

    #[inline]
    fn primary(camera: &LodCamera, px: f32, py: f32) -> Self {
        RayDiffsAniso(RayDiffs::primary(camera, px, py))
    }

    #[inline]
    fn arrive(&mut self, hit: &SurfaceHit) {
        self.0.arrive(hit);
    }

    fn footprint(&self, hit: &SurfaceHit, _: &LodCamera, texture_size: (u32, u32)) -> Footprint {
        let Some(g) = self.0.texel_gradients(hit, texture_size) else {
            return Footprint::Level(COARSEST_LEVEL);
        };
        let (level, taps, major) = g.anisotropic();
        if taps <= 1 {
            return Footprint::Level(level);
        }
        let size = Vec2::new(texture_size.0 as f32, texture_size.1 as f32);
        Footprint::Anisotropic {
            level,
            axis: major / size,
            taps,
        }
    }

    #[inline]
    fn reflect(&self, hit: &SurfaceHit, reflected: Vec3A) -> Self {
        RayDiffsAniso(self.0.reflect(hit, reflected))
    }

    #[inline]
    fn refract(&self, hit: &SurfaceHit, eta: f32, refracted: Vec3A) -> Self {
        RayDiffsAniso(self.0.refract(hit, eta, refracted))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isotropic_footprint_takes_one_tap_at_the_isotropic_level() {
        let g = TexelGradients {
            dx: Vec2::new(4.0, 0.0),
            dy: Vec2::new(0.0, 4.0),
        };
        let (level, taps, _) = g.anisotropic();
        assert_eq!(taps, 1);
        assert_eq!(level, g.isotropic_level());
        assert_eq!(level, 2.0);
    }

    #[test]
    fn elongated_footprint_takes_more_taps_at_a_finer_level() {
        let g = TexelGradients {
            dx: Vec2::new(16.0, 0.0),
            dy: Vec2::new(0.0, 2.0),
        };
        let (level, taps, major) = g.anisotropic();
        assert_eq!(taps, 8);
        assert_eq!(level, 1.0);
        assert_eq!(major, Vec2::new(16.0, 0.0));
        // A line footprint (zero minor axis) is capped at 16 taps.
        let line = TexelGradients {
            dx: Vec2::new(0.0, 0.0),
            dy: Vec2::new(0.0, 64.0),
        };
        assert_eq!(line.anisotropic(), (2.0, 16, Vec2::new(0.0, 64.0)));
    }

    #[test]
    fn zero_footprint_is_finite() {
        let g = TexelGradients {
            dx: Vec2::ZERO,
            dy: Vec2::ZERO,
        };
        let (level, taps, _) = g.anisotropic();
        assert!(level.is_finite() && level < 0.0);
        assert_eq!(taps, MAX_ANISOTROPY);
    }
}
