//! `log2` of positive normal `f64` values, one at a time or in batches that the compiler
//! vectorises (two lanes on the x86-64 baseline, four in the AVX2 copy, chosen at run time by
//! `simd::dispatch`).
//!
//! The deforming meshes' `log2 P_b` pass takes one `log2` per triangle and frame, and libm's
//! is a call the loop cannot vectorise: about 3 of a million triangles' ~4.4 ms
//! (docs/benchmark-log.md). This one is branch-free arithmetic, so a batch compiles to vector code,
//! and every path (one value, a baseline batch, an AVX2 batch) performs the same IEEE
//! operations in the same order (no fused multiply-add is formed), so all give the same
//! bits. Within a few ulps of the exact `log2` (tested against libm); inputs that are not
//! positive normal numbers give unspecified finite or non-finite values, and callers guard
//! them (see `pb.rs`).
//!
//! Method: `x = 2^e m` with `m` in `[sqrt(1/2), sqrt(2))`; `ln m = 2 atanh(s)` with
//! `s = (m - 1) / (m + 1)`, `|s| <= 0.1716`, summed as `2 s (1 + s^2/3 + ... + s^18/19)`
//! (the next term is below `2.5e-17` of the sum).

use crate::simd;

/// `log2 x` for a positive normal `x` (module docs).
#[inline(always)]
pub fn log2(x: f64) -> f64 {
    const MANTISSA: u64 = 0x000f_ffff_ffff_ffff;
    const ONE_BITS: u64 = 0x3ff0_0000_0000_0000;
    // 2^52 as bits and value: OR-ing an 11-bit integer into its mantissa and subtracting
    // 2^52 converts it exactly (vectorisable, unlike an integer-to-float conversion of
    // 64-bit lanes without AVX-512).
    const TWO_52_BITS: u64 = 0x4330_0000_0000_0000;
    const TWO_52: f64 = 4_503_599_627_370_496.0;
    let bits = x.to_bits();
    let biased = (bits >> 52) & 0x7ff;
    let exponent = f64::from_bits(TWO_52_BITS | biased) - TWO_52 - 1023.0;
    let mantissa = f64::from_bits((bits & MANTISSA) | ONE_BITS);
    let high = mantissa > std::f64::consts::SQRT_2;
    let m = if high { mantissa * 0.5 } else { mantissa };
    let e = if high { exponent + 1.0 } else { exponent };
    let s = (m - 1.0) / (m + 1.0);
    let z = s * s;
    let mut series = 1.0 / 19.0;
    for c in [
        1.0 / 17.0,
        1.0 / 15.0,
        1.0 / 13.0,
        1.0 / 11.0,
        1.0 / 9.0,
        1.0 / 7.0,
        1.0 / 5.0,
        1.0 / 3.0,
        1.0,
    ] {
        series = series * z + c;
    }
    e + (2.0 * s * series) * std::f64::consts::LOG2_E
}

/// Replaces every value of `values` with its [`log2`], the same bits as one at a time, in
/// the copy [`simd::dispatch`] chooses (four lanes per instruction in the AVX2 copy).
pub fn log2_in_place(values: &mut [f64]) {
    simd::dispatch(Log2InPlace(values))
}

/// [`log2_in_place`] in the SIMD copy `AVX2` of a caller that is one already (a
/// [`simd::Kernel`]'s `run`): inlined there, without dispatching again.
#[inline(always)]
pub fn log2_in_place_in<const AVX2: bool>(values: &mut [f64]) {
    simd::Kernel::run::<AVX2>(Log2InPlace(values))
}

/// [`log2_in_place`] as a [`simd::Kernel`]: the loop compiles to vector code in each copy,
/// with the same operations.
struct Log2InPlace<'a>(&'a mut [f64]);

impl simd::Kernel for Log2InPlace<'_> {
    type Output = ();

    #[inline(always)]
    fn run<const AVX2: bool>(self) {
        for v in self.0 {
            *v = log2(*v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_positive(state: &mut u64) -> f64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        // Any positive normal: a random exponent and mantissa.
        let exponent = 1 + (*state >> 11) % 2046;
        f64::from_bits((exponent << 52) | (*state & 0x000f_ffff_ffff_ffff))
    }

    /// Within 4 ulps of libm's `log2` (below 0.5 in magnitude, where ulps shrink towards
    /// 0, within 4 ulps of 1 absolute), over 200,000 random positive normals and the edges
    /// of the range reduction.
    #[test]
    fn log2_is_within_a_few_ulps_of_libm() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut values: Vec<f64> = (0..200_000).map(|_| random_positive(&mut state)).collect();
        // And 50,000 between 0.5 and 2, where the range reduction switches and results are
        // small.
        values.extend((0..50_000).map(|k| {
            let x = random_positive(&mut state).to_bits() & 0x000f_ffff_ffff_ffff;
            f64::from_bits(x | ((1022 + k % 2) << 52))
        }));
        values.extend([
            1.0,
            2.0,
            0.5,
            std::f64::consts::SQRT_2,
            std::f64::consts::SQRT_2.next_up(),
            std::f64::consts::SQRT_2.next_down(),
            f64::MIN_POSITIVE,
            f64::MAX,
            1.0f64.next_up(),
            1.0f64.next_down(),
            3.0,
            1e-180,
            1e157,
        ]);
        let mut worst = 0i64;
        for &x in &values {
            let (ours, exact) = (log2(x), x.log2());
            assert!(ours.is_finite(), "{x}");
            if exact.abs() < 0.5 {
                assert!((ours - exact).abs() <= 4.5e-16, "{x}: {ours} vs {exact}");
            } else {
                let ulps = (ours.to_bits() as i64 - exact.to_bits() as i64).abs();
                worst = worst.max(ulps);
                assert!(ulps <= 4, "{x}: {ours} vs {exact} ({ulps} ulps)");
            }
        }
        assert_eq!(log2(1.0), 0.0);
        assert_eq!(log2(2.0), 1.0);
        assert_eq!(log2(0.25), -2.0);
        eprintln!("worst: {worst} ulps");
    }

    /// A batch gives the same bits as one value at a time, whatever the batch length and
    /// alignment, in the copy the process runs, in the baseline copy, and in the AVX2 copy
    /// where the CPU has AVX2.
    #[test]
    fn batches_equal_one_at_a_time() {
        let mut state = 0x1234_5678_9abc_def1u64;
        let values: Vec<f64> = (0..10_007).map(|_| random_positive(&mut state)).collect();
        let check = |batch: &[f64], start: usize, copy: &str| {
            for (x, got) in values[start..].iter().zip(batch) {
                assert_eq!(got.to_bits(), log2(*x).to_bits(), "{x} ({copy})");
            }
        };
        for start in 0..3 {
            let mut batch = values[start..].to_vec();
            log2_in_place(&mut batch);
            check(&batch, start, "dispatched");
            let mut batch = values[start..].to_vec();
            simd::run_baseline(Log2InPlace(&mut batch));
            check(&batch, start, "baseline");
            let mut batch = values[start..].to_vec();
            if simd::run_avx2_if_available(Log2InPlace(&mut batch)).is_some() {
                check(&batch, start, "avx2");
            }
        }
    }
}
