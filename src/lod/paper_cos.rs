//! `paper-cos`: Park & Kim plus the incidence term of ray cones, with each primary ray's own
//! pixel instead of the centre pixel (12 bytes: the path length and the pixel's two widths).
//!
//! ```text
//! lod = log2(P_l) - log2 P_b + log2(tangential) + log2 L
//! L   = longest axis of the pixel's footprint on the surface, for a cross-section of
//!       tangential width 1 and radial width cos(theta) (`pixel.rs`);
//!       on the optical axis L = 1 / max(|n.d|, 1/16), the paper-cos of before
//! ```
//!
//! with the geometric normal `n`, the primary ray's angle `theta` to the optical axis and
//! `tangential = cos(theta)`: a pinhole pixel off the axis is `cos(theta)` times narrower
//! across the ray and `cos^2(theta)` along the radius than the centre pixel `log2 P_b`
//! was computed for. On a plane facing the camera the two corrections cancel the path's
//! `1 / cos(theta)` exactly, at any field of view; the centre pixel's spread made such a
//! plane `-2 log2 cos(theta)` levels too blurry (8 levels in the corners of a 179-degree
//! film). The clamp at 1/16 (anisotropy 16) bounds the incidence stretch for grazing rays.
//!
//! After a mirror or glass surface the ray continues with the geometric mean of its
//! pixel's widths (`pixel.rs`); `paper` itself keeps the paper's formula.

use glam::Vec3A;

use super::pixel::{PixelWidths, footprint_longest_axis};
use super::{Footprint, LodCamera, LodMethod, PathLength, RayLod, SurfaceHit, fast_log2};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathLengthCos {
    pub path: PathLength,
    pub pixel: PixelWidths,
}

impl Default for PathLengthCos {
    fn default() -> Self {
        PathLengthCos {
            path: PathLength(0.0),
            pixel: PixelWidths::CENTRE,
        }
    }
}

impl PathLengthCos {
    /// `log2` of the pixel's footprint at the hit relative to the centre pixel's
    /// cross-section at the same distance: `log2(tangential * L)`.
    #[inline]
    pub(super) fn pixel_levels(pixel: PixelWidths, hit: &SurfaceHit, camera: &LodCamera) -> f32 {
        let longest = footprint_longest_axis(pixel.ratio(), hit, camera.forward);
        fast_log2(pixel.tangential * longest)
    }
}

impl RayLod for PathLengthCos {
    const METHOD: LodMethod = LodMethod::PaperCos;
    const BYTES: usize = 12;
    type Kept = ();

    #[inline]
    fn primary(camera: &LodCamera, px: f32, py: f32) -> Self {
        PathLengthCos {
            path: PathLength(0.0),
            pixel: camera.pixel_widths(px, py),
        }
    }

    #[inline]
    fn arrive(&mut self, hit: &SurfaceHit) {
        self.path.arrive(hit);
    }

    #[inline]
    fn footprint(&self, hit: &SurfaceHit, camera: &LodCamera, _: (u32, u32)) -> Footprint {
        Footprint::Level(
            self.path.paper_level(hit.log2_pb()) + Self::pixel_levels(self.pixel, hit, camera),
        )
    }

    #[inline]
    fn reflect(&self, _: &SurfaceHit, _: Vec3A) -> Self {
        PathLengthCos {
            pixel: self.pixel.isotropic(),
            ..*self
        }
    }

    #[inline]
    fn refract(&self, _: &SurfaceHit, _: f32, _: Vec3A) -> Self {
        PathLengthCos {
            pixel: self.pixel.isotropic(),
            ..*self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{camera, facing_triangle, hit_on};
    use super::*;

    #[test]
    fn on_axis_sixty_degrees_adds_one_level_and_grazing_at_most_four() {
        let cam = camera(1.0, 100);
        let triangles = facing_triangle(-3.0, 2.5);
        let mut hit = hit_on(&triangles, 3.0, Vec3A::NEG_Z, 1.0);
        for (cos, levels) in [(1.0f32, 0.0), (0.5, 1.0), (0.01, 4.0)] {
            hit.face_normal = Vec3A::new((1.0 - cos * cos).sqrt(), 0.0, cos);
            let mut state = PathLengthCos::primary(&cam, 50.0, 50.0);
            state.arrive(&hit);
            let level = state.footprint(&hit, &cam, (1, 1)).level();
            let expected = 3f32.log2() - 2.5 + levels;
            assert!(
                (level - expected).abs() < 1e-4,
                "cos {cos}: {level} vs {expected}"
            );
        }
    }

    #[test]
    fn a_bounce_keeps_the_path_and_makes_the_pixel_round() {
        let cam = camera(2.0, 100);
        let triangles = facing_triangle(-3.0, 0.0);
        let hit = hit_on(&triangles, 3.0, Vec3A::NEG_Z, 1.0);
        let mut state = PathLengthCos::primary(&cam, 0.5, 0.5);
        assert!(state.pixel.ratio() < 0.5, "{:?}", state.pixel);
        state.arrive(&hit);
        let bounced = state.reflect(&hit, Vec3A::Z);
        assert_eq!(bounced.path, state.path);
        assert_eq!(bounced.pixel.ratio(), 1.0);
        let mean = (state.pixel.tangential * state.pixel.radial).sqrt();
        assert!((bounced.pixel.tangential - mean).abs() < 1e-7);
        assert_eq!(state.refract(&hit, 0.7, Vec3A::NEG_Z).pixel, bounced.pixel);
    }
}
