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
    /// Park & Kim plus the incidence term of ray cones: `- log2 max(|n.d|, 1/16)`.
    PaperCos,
}

/// Smallest `|n.d|` the incidence term uses (anisotropy 16, as the OptiX toolkit clamps),
/// so grazing rays add at most 4 levels instead of infinitely many.
pub const MIN_INCIDENCE_COS: f32 = 1.0 / 16.0;

impl LodMethod {
    pub const ALL: [LodMethod; 3] = [LodMethod::None, LodMethod::Paper, LodMethod::PaperCos];

    pub fn as_str(self) -> &'static str {
        match self {
            LodMethod::None => "none",
            LodMethod::Paper => "paper",
            LodMethod::PaperCos => "paper-cos",
        }
    }

    /// Whether the method needs the per-triangle `log2 P_b` constants.
    pub fn needs_log2_pb(self) -> bool {
        matches!(self, LodMethod::Paper | LodMethod::PaperCos)
    }

    /// The (unclamped) MIP level at a hit. `path_length` is the total distance travelled
    /// from the eye; `log2_pb` the hit triangle's constant; `cos_incidence` is `|n.d|` with
    /// the geometric normal. A zero or non-finite path length cannot occur for a real hit,
    /// but is mapped to a finite level rather than -inf/NaN; NaN incidence counts as grazing.
    #[inline]
    pub fn level(self, path_length: f32, log2_pb: f32, cos_incidence: f32) -> f32 {
        let paper = || path_length.max(f32::MIN_POSITIVE).log2() - log2_pb;
        match self {
            LodMethod::None => 0.0,
            LodMethod::Paper => paper(),
            LodMethod::PaperCos => {
                paper() - cos_incidence.abs().max(MIN_INCIDENCE_COS).min(1.0).log2()
            }
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
    fn incidence_term_adds_log2_of_one_over_cos_clamped_at_16() {
        let (pl, pb) = (8.0, 1.0);
        let paper = LodMethod::Paper.level(pl, pb, 0.5);
        let tilted = LodMethod::PaperCos.level(pl, pb, 0.5);
        assert!(
            (tilted - paper - 1.0).abs() < 1e-6,
            "60 degrees adds one level"
        );
        assert_eq!(LodMethod::PaperCos.level(pl, pb, 1.0), paper);
        assert_eq!(LodMethod::PaperCos.level(pl, pb, 0.0) - paper, 4.0);
        assert_eq!(LodMethod::PaperCos.level(pl, pb, f32::NAN) - paper, 4.0);
    }

    #[test]
    fn paper_level_never_nan() {
        for pl in [0.0, -1.0, f32::NAN, f32::INFINITY, 1e-30, 1e30] {
            for pb in [LOG2_PB_LIMIT, -LOG2_PB_LIMIT, 0.0, 7.5] {
                for cos in [0.0, 1.0, -0.5, f32::NAN, 1e-30] {
                    for m in LodMethod::ALL {
                        let l = m.level(pl, pb, cos);
                        assert!(!l.is_nan(), "{m}: path {pl} log2_pb {pb} cos {cos} -> NaN");
                    }
                }
            }
        }
    }
}
