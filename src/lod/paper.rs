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

use super::{Footprint, LodCamera, LodMethod, RayLod, SurfaceHit, fast_log2, finite_level};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PathLength(pub f32);

impl PathLength {
    /// `log2(P_l) - log2 P_b`, finite for any input (a zero or non-finite path length
    /// cannot occur for a real hit, but must not produce NaN: `fast_log2` gives -126 for
    /// zero, negative, subnormal and NaN lengths, its value at `f32::MIN_POSITIVE`).
    #[inline]
    pub fn paper_level(self, log2_pb: f32) -> f32 {
        finite_level(fast_log2(self.0) - log2_pb)
    }
}

impl RayLod for PathLength {
    const METHOD: LodMethod = LodMethod::Paper;
    const BYTES: usize = 4;
    type Kept = ();

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

    #[test]
    fn level_never_nan_or_infinite() {
        for pl in [0.0, -1.0, f32::NAN, f32::INFINITY, 1e-30, 1e30] {
            for pb in [LOG2_PB_LIMIT, -LOG2_PB_LIMIT, 0.0, 7.5, f32::NAN] {
                let l = PathLength(pl).paper_level(pb);
                assert!(l.is_finite(), "path {pl} log2_pb {pb} -> {l}");
            }
        }
    }
}
