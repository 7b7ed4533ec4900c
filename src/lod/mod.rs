//! Texture level-of-detail selection.
//!
//! `none` samples level 0 bilinearly (the paper's baseline). `paper` is Park & Kim (2010):
//! a per-triangle constant `log2 P_b` precomputed from world geometry, and at a hit
//! `lod = log2(P_l) - log2 P_b` with `P_l` the path length from the eye summed over every
//! bounce. The constant is derived in `pb.rs` (and `README.md`).

mod pb;

pub use pb::{LOG2_PB_LIMIT, PixelFootprint, log2_pb};

use std::fmt;
use std::str::FromStr;

/// A LOD selection method. The CLI word, the stats field and the output folder name are
/// all `Display` of this enum.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LodMethod {
    /// Level 0, bilinear: no MIP-mapping.
    None,
    /// Park & Kim: `log2(path length) - log2 P_b`.
    Paper,
}

impl LodMethod {
    pub const ALL: [LodMethod; 2] = [LodMethod::None, LodMethod::Paper];

    pub fn as_str(self) -> &'static str {
        match self {
            LodMethod::None => "none",
            LodMethod::Paper => "paper",
        }
    }

    /// Whether the method needs the per-triangle `log2 P_b` constants.
    pub fn needs_log2_pb(self) -> bool {
        matches!(self, LodMethod::Paper)
    }

    /// The (unclamped) MIP level at a hit. `path_length` is the total distance travelled
    /// from the eye; `log2_pb` the hit triangle's constant. A zero or non-finite path
    /// length cannot occur for a real hit, but is mapped to level 0 rather than -inf/NaN.
    #[inline]
    pub fn level(self, path_length: f32, log2_pb: f32) -> f32 {
        match self {
            LodMethod::None => 0.0,
            LodMethod::Paper => path_length.max(f32::MIN_POSITIVE).log2() - log2_pb,
        }
    }
}

impl fmt::Display for LodMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for LodMethod {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        LodMethod::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = LodMethod::ALL.iter().map(|m| m.as_str()).collect();
                format!(
                    "unknown LOD method '{s}' (expected one of: {})",
                    names.join(", ")
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for m in LodMethod::ALL {
            assert_eq!(m.as_str().parse::<LodMethod>().unwrap(), m);
        }
        assert!("bogus".parse::<LodMethod>().is_err());
    }

    #[test]
    fn paper_level_never_nan() {
        for pl in [0.0, -1.0, f32::NAN, f32::INFINITY, 1e-30, 1e30] {
            for pb in [LOG2_PB_LIMIT, -LOG2_PB_LIMIT, 0.0, 7.5] {
                let l = LodMethod::Paper.level(pl, pb);
                assert!(!l.is_nan(), "path {pl} log2_pb {pb} -> NaN");
            }
        }
    }
}
