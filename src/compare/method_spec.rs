//! What `mipray compare` renders per column: a LOD method at a number of samples per pixel.
//!
//! The alternative to a LOD method is more samples, so the speed-error chart places each
//! method against brute-force supersampling: `--methods none@4,none@16,paper,cones` renders
//! `none` at 4 and 16 jittered stratified samples per pixel (`render::film::sample_offset`)
//! next to the one-sample LOD methods. The word is the method's name, with `@N` when
//! `N != 1`; the report's method column and the output folder use the same string.

use std::fmt;
use std::str::FromStr;

use crate::lod::LodMethod;

/// Most samples per pixel a compared variant may use (a 64 x 64 grid).
pub const MAX_VARIANT_SPP: u32 = 4096;

/// A LOD method rendered at `spp` samples per pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MethodSpec {
    pub method: LodMethod,
    /// Samples per pixel, `1..=MAX_VARIANT_SPP`.
    pub spp: u32,
}

impl MethodSpec {
    /// The method at one sample per pixel (the LOD methods' own setting).
    pub fn single(method: LodMethod) -> MethodSpec {
        MethodSpec { method, spp: 1 }
    }
}

impl From<LodMethod> for MethodSpec {
    fn from(method: LodMethod) -> Self {
        MethodSpec::single(method)
    }
}

impl fmt::Display for MethodSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.spp == 1 {
            write!(f, "{}", self.method)
        } else {
            write!(f, "{}@{}", self.method, self.spp)
        }
    }
}

impl FromStr for MethodSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (name, spp) = match s.split_once('@') {
            None => (s, 1),
            Some((name, count)) => {
                let spp = count
                    .parse::<u32>()
                    .ok()
                    .filter(|n| (1..=MAX_VARIANT_SPP).contains(n))
                    .ok_or_else(|| {
                        format!(
                            "'{s}': samples per pixel after '@' must be 1 to {MAX_VARIANT_SPP}, \
                             got '{count}'"
                        )
                    })?;
                (name, spp)
            }
        };
        Ok(MethodSpec {
            method: name.parse()?,
            spp,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_round_trip_and_bad_counts_are_refused() {
        for word in ["none", "paper", "none@4", "diffs-aniso@16"] {
            assert_eq!(word.parse::<MethodSpec>().unwrap().to_string(), word);
        }
        assert_eq!(
            "none@16".parse::<MethodSpec>().unwrap(),
            MethodSpec {
                method: LodMethod::None,
                spp: 16
            }
        );
        // `@1` is the plain method.
        assert_eq!(
            "cones@1".parse::<MethodSpec>().unwrap().to_string(),
            "cones"
        );
        for bad in ["none@0", "none@", "none@x", "none@5000", "bogus@4", "@4"] {
            assert!(bad.parse::<MethodSpec>().is_err(), "{bad}");
        }
    }
}
