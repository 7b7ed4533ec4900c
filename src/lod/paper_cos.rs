//! `paper-cos`: Park & Kim plus the incidence term of ray cones (same 4-byte state):
//!
//! ```text
//! lod = log2(P_l) - log2 P_b - log2 max(|n.d|, 1/16)
//! ```
//!
//! with the geometric normal `n`. The clamp at 1/16 (anisotropy 16) bounds the term at
//! 4 levels for grazing rays, where `1/|n.d|` would grow without limit.

use glam::Vec3A;

use super::{Footprint, LodCamera, LodMethod, PathLength, RayLod, SurfaceHit, fast_log2};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PathLengthCos(pub PathLength);

/// The incidence term `-log2 |n.d|` for a cosine already clamped to `[1/16, 1]`.
#[inline]
pub fn incidence_levels(clamped_cos: f32) -> f32 {
    -fast_log2(clamped_cos)
}

impl RayLod for PathLengthCos {
    const METHOD: LodMethod = LodMethod::PaperCos;
    const BYTES: usize = 4;

    #[inline]
    fn primary(_: &LodCamera, _: f32, _: f32) -> Self {
        PathLengthCos(PathLength(0.0))
    }

    #[inline]
    fn arrive(&mut self, hit: &SurfaceHit) {
        self.0.arrive(hit);
    }

    #[inline]
    fn footprint(&self, hit: &SurfaceHit, _: &LodCamera, _: (u32, u32)) -> Footprint {
        Footprint::Level(self.0.paper_level(hit.log2_pb()) + incidence_levels(hit.clamped_cos()))
    }

    #[inline]
    fn reflect(&self, _: &SurfaceHit, _: Vec3A) -> Self {
        *self
    }

    #[inline]
    fn refract(&self, _: &SurfaceHit, _: f32, _: Vec3A) -> Self {
        *self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixty_degrees_adds_one_level_and_grazing_at_most_four() {
        assert!((incidence_levels(0.5) - 1.0).abs() < 1e-6);
        assert_eq!(incidence_levels(1.0), 0.0);
        assert_eq!(incidence_levels(crate::lod::MIN_INCIDENCE_COS), 4.0);
    }
}
