//! The sRGB encoding of output pixels: linear radiance in [0, 1] to an 8-bit code value.
//!
//! One function shared by everything that turns linear values into what a person sees: the
//! film's PNG frames (`render::film`), the image metrics reading float frames
//! (`metrics::read_srgb8`) and the exported material colours (`export::obj`), so a frame
//! compared or exported is encoded exactly as it was written. (Texture decoding goes the
//! other way, sRGB to linear, in `texture::decode`.)
//!
//! Invariants: every input maps to a code value; non-finite values (NaN, ±inf) encode as 0
//! and values outside [0, 1] are clamped, so no pixel is ever lost or undefined. The code
//! is exactly what the sRGB formula gives through `powf` ([`encode_srgb8_by_formula`]) for
//! every `f32`: [`encode_srgb8`] finds it in a table of the formula's own code boundaries
//! instead of taking a power per value (a frame is three values per pixel, and the power
//! was 2% of a whole BART Kitchen frame's time). A test checks every `f32` in [0, 1].

use std::sync::LazyLock;

/// Linear [0, 1] to an 8-bit sRGB code value, through the formula (a power per value).
/// [`encode_srgb8`] gives the same code for every input and is what the product uses.
pub fn encode_srgb8_by_formula(linear: f32) -> u8 {
    let c = if linear.is_finite() {
        linear.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let encoded = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (encoded * 255.0 + 0.5) as u8
}

/// Linear [0, 1] to an 8-bit sRGB code value: [`encode_srgb8_by_formula`]'s code, found
/// in [`SrgbEncoder`]'s tables.
pub fn encode_srgb8(linear: f32) -> u8 {
    srgb8_encoder().encode(linear)
}

/// The shared encoder (its tables are built on first use, about 9,300 evaluations of the
/// formula).
pub fn srgb8_encoder() -> &'static SrgbEncoder {
    static ENCODER: LazyLock<SrgbEncoder> = LazyLock::new(SrgbEncoder::new);
    &ENCODER
}

/// Below this every value encodes as 0 (the code turns 1 at about 1.5e-4), so the buckets
/// start here.
const SMALLEST_BUCKETED: f32 = 1.0 / 8192.0;
/// A value's bucket is its sign, exponent and top 7 mantissa bits: at most two codes meet
/// in any bucket in [2^-13, 1) (no bucket spans more than 0.66 of a code: the widest,
/// [0.5, 0.5039), spans 0.65; the linear segment's, 0.05), so one comparison finishes the
/// search.
const BUCKET_SHIFT: u32 = 16;
const FIRST_BUCKET: u32 = SMALLEST_BUCKETED.to_bits() >> BUCKET_SHIFT;
const BUCKETS: usize = ((1.0f32.to_bits() >> BUCKET_SHIFT) - FIRST_BUCKET) as usize;

/// The formula's code boundaries: `lowest[k]` is the least `f32` that encodes as `k` or
/// more (`lowest[256]` is +inf, so the comparison for a value of code 255 is false), and
/// `bucket_code[b]` the code of bucket `b`'s least value.
pub struct SrgbEncoder {
    lowest: [f32; 257],
    bucket_code: [u8; BUCKETS],
}

impl SrgbEncoder {
    fn new() -> Self {
        let mut lowest = [f32::INFINITY; 257];
        lowest[0] = 0.0;
        for (code, slot) in lowest.iter_mut().enumerate().take(256).skip(1) {
            *slot = least_encoding_at_least(code as u8);
        }
        let bucket_code = std::array::from_fn(|b| {
            encode_srgb8_by_formula(f32::from_bits((FIRST_BUCKET + b as u32) << BUCKET_SHIFT))
        });
        Self {
            lowest,
            bucket_code,
        }
    }

    /// [`encode_srgb8_by_formula`]'s code of `linear`.
    #[inline]
    pub fn encode(&self, linear: f32) -> u8 {
        // Negative values, NaN and tiny values: 0 (the comparison is false for NaN).
        if !(linear >= SMALLEST_BUCKETED) {
            return 0;
        }
        if linear >= 1.0 {
            return if linear.is_finite() { 255 } else { 0 };
        }
        let bucket = ((linear.to_bits() >> BUCKET_SHIFT) - FIRST_BUCKET) as usize;
        let code = self.bucket_code[bucket];
        // At most one boundary lies in a bucket (see `BUCKET_SHIFT`; checked for every
        // bucket by a test), so one comparison, without a branch: a loop here mispredicted
        // on half the values of an image.
        code + u8::from(linear >= self.lowest[code as usize + 1])
    }
}

/// The least non-negative `f32` that the formula encodes as `code` or more (`code` >= 1),
/// by bisection over the bit patterns of [0, 1], which order as the values do.
fn least_encoding_at_least(code: u8) -> f32 {
    let (mut below, mut at_least) = (0u32, 1.0f32.to_bits());
    while at_least - below > 1 {
        let middle = below + (at_least - below) / 2;
        if encode_srgb8_by_formula(f32::from_bits(middle)) >= code {
            at_least = middle;
        } else {
            below = middle;
        }
    }
    f32::from_bits(at_least)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    #[test]
    fn srgb_encoding_endpoints_and_midpoint() {
        for encode in [encode_srgb8, encode_srgb8_by_formula] {
            assert_eq!(encode(0.0), 0);
            assert_eq!(encode(1.0), 255);
            assert_eq!(encode(0.214_041_14), 128);
            assert_eq!(encode(f32::NAN), 0);
            assert_eq!(encode(7.0), 255);
        }
    }

    #[test]
    fn the_table_gives_the_formulas_code_for_every_value_in_zero_to_one() {
        // Every f32 in [0, 1] (1.07e9 values); the table is exact only if the formula never
        // steps down, which this checks too.
        let end = 1.0f32.to_bits() + 1;
        let encoder = srgb8_encoder();
        let mismatches: Vec<(u32, u8, u8)> = (0..end)
            .into_par_iter()
            .with_min_len(1 << 20)
            .filter_map(|bits| {
                let value = f32::from_bits(bits);
                let (table, formula) = (encoder.encode(value), encode_srgb8_by_formula(value));
                (table != formula).then_some((bits, table, formula))
            })
            .take_any(8)
            .collect();
        assert!(
            mismatches.is_empty(),
            "table and formula differ (bits, table, formula): {mismatches:?}"
        );
    }

    #[test]
    fn the_table_agrees_with_the_formula_outside_zero_to_one() {
        let encoder = srgb8_encoder();
        let specials = [
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            -0.0,
            -f32::MIN_POSITIVE,
            -1e-45,
            1.000_000_1,
            2.0,
            1e30,
            -1.0,
        ];
        for value in specials {
            assert_eq!(
                encoder.encode(value),
                encode_srgb8_by_formula(value),
                "{value:e}"
            );
        }
        // A stride through all other bit patterns (above 1, negatives, NaN payloads).
        let mut bits = 1.0f32.to_bits();
        while let Some(next) = bits.checked_add(65_537) {
            let value = f32::from_bits(next);
            assert_eq!(
                encoder.encode(value),
                encode_srgb8_by_formula(value),
                "{next:#x}"
            );
            bits = next;
        }
    }

    #[test]
    fn every_code_is_reached_and_boundaries_rise() {
        let encoder = srgb8_encoder();
        for code in 1..=255usize {
            let at = encoder.lowest[code];
            assert!(at > encoder.lowest[code - 1], "code {code}");
            assert_eq!(encode_srgb8_by_formula(at) as usize, code);
            assert_eq!(
                encode_srgb8_by_formula(f32::from_bits(at.to_bits() - 1)) as usize,
                code - 1
            );
        }
        // No bucket holds more than one boundary (`encode` makes one comparison).
        for bucket in 0..BUCKETS as u32 {
            let least = f32::from_bits((FIRST_BUCKET + bucket) << BUCKET_SHIFT);
            let end = f32::from_bits((FIRST_BUCKET + bucket + 1) << BUCKET_SHIFT);
            let inside = (1..=255)
                .filter(|&code| encoder.lowest[code] > least && encoder.lowest[code] < end)
                .count();
            assert!(
                inside <= 1,
                "bucket {bucket} [{least:e}, {end:e}) holds {inside}"
            );
        }
        // Below the first bucket every value encodes as 0.
        assert_eq!(
            encode_srgb8_by_formula(f32::from_bits(SMALLEST_BUCKETED.to_bits() - 1)),
            0
        );
    }
}
