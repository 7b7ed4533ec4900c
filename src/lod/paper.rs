//! `paper`: Park & Kim (2010). The ray carries the path length `P_l` from the eye (4 bytes),
//! summed over every bounce; at a hit
//!
//! ```text
//! lod = log2(P_l) - log2 P_b
//! ```
//!
//! with the per-triangle constant `log2 P_b` (see `pb.rs`). Reflection and refraction leave
//! the state unchanged: the distance simply keeps adding up.

use glam::Vec3A;

use super::{Footprint, LodCamera, LodMethod, RayLod, SurfaceHit, fast_log2};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PathLength(pub f32);

impl PathLength {
    /// `log2(P_l) - log2 P_b`, finite for any path length and any finite `log2_pb` (a
    /// hit's always is: a triangle's is within `±LOG2_PB_LIMIT`, see `pb.rs`).
    /// `fast_log2` is within `[-126, 128]` for any input: a zero or non-finite path length
    /// cannot occur for a real hit, but must not produce NaN, and zero, negative, subnormal
    /// and NaN lengths give -126, its value at `f32::MIN_POSITIVE`.
    ///
    /// Not clamped to a finite range here (`finite_level`): the level is finite already,
    /// and every lookup clamps it to its pyramid's levels (`MipPyramid::clamp_level`, which
    /// also sends a NaN to 0), so a clamp to `±COARSEST_LEVEL` first changes nothing a
    /// lookup reads; it cost six instructions a textured hit.
    #[inline]
    pub fn paper_level(self, log2_pb: f32) -> f32 {
        debug_assert!(log2_pb.is_finite(), "log2 P_b {log2_pb}");
        fast_log2(self.0) - log2_pb
    }
}

impl RayLod for PathLength {
    const METHOD: LodMethod = LodMethod::Paper;
    const BYTES: usize = 4;
    type Kept = ();
    const LEVEL_AT_DISTANCE: bool = true;

    #[inline(always)]
    fn level_at_distance(&self, t: f32, log2_pb: f32) -> f32 {
        // The state `arrive` makes, and `footprint`'s level of it.
        PathLength(self.0 + t).paper_level(log2_pb)
    }

    #[inline]
    fn primary(_: &LodCamera, _: f32, _: f32) -> Self {
        PathLength(0.0)
    }

    #[inline]
    fn arrive(&mut self, hit: &SurfaceHit) {
        self.0 += hit.t;
    }

    #[inline]
    fn footprint(&self, hit: &SurfaceHit, _: &LodCamera, _: (u32, u32)) -> Footprint {
        Footprint::Level(self.paper_level(hit.log2_pb()))
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
    use crate::lod::LOG2_PB_LIMIT;

    #[test]
    fn level_is_log2_path_minus_constant() {
        assert_eq!(PathLength(8.0).paper_level(1.0), 2.0);
        assert_eq!(PathLength(0.5).paper_level(-1.0), 0.0);
    }

    /// Lengths below the smallest normal read as that length (the level of the finest
    /// footprint there is), the same bits.
    #[test]
    fn tiny_zero_negative_and_nan_lengths_read_as_the_smallest_normal() {
        let smallest = PathLength(f32::MIN_POSITIVE).paper_level(0.5);
        assert_eq!(smallest, -126.5);
        for pl in [
            0.0,
            -0.0,
            -1.0,
            1e-40,
            f32::MIN_POSITIVE.next_down(),
            f32::NAN,
        ] {
            assert_eq!(
                PathLength(pl).paper_level(0.5).to_bits(),
                smallest.to_bits()
            );
        }
    }

    /// Finite for every path length and every `log2 P_b` a triangle can have, and what a
    /// lookup reads of it is what it read of the level clamped to `±COARSEST_LEVEL` first.
    #[test]
    fn level_never_nan_or_infinite() {
        let pyramid =
            crate::texture::MipPyramid::from_linear_rgba(64, 64, vec![glam::Vec4::ONE; 64 * 64])
                .unwrap();
        for pl in [0.0, -1.0, f32::NAN, f32::INFINITY, f32::MAX, 1e-30, 1e30] {
            for pb in [LOG2_PB_LIMIT, -LOG2_PB_LIMIT, 0.0, -0.0, 7.5, -130.0, 130.0] {
                let l = PathLength(pl).paper_level(pb);
                assert!(l.is_finite(), "path {pl} log2_pb {pb} -> {l}");
                let clamped_first = pyramid.clamp_level(crate::lod::finite_level(l));
                assert_eq!(
                    pyramid.clamp_level(l).to_bits(),
                    clamped_first.to_bits(),
                    "path {pl} log2_pb {pb}"
                );
            }
        }
    }
}
