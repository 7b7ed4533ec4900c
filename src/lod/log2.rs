//! `log2` of positive normal `f64` values, one at a time or in batches that the compiler
//! vectorises (two lanes on the x86-64 baseline, four in the AVX2 copy, chosen at run time by
//! `simd::dispatch`; eight where that copy may call AVX-512 routines, `simd::avx512`).
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
    let bits = x.to_bits();
    let biased = (bits >> 52) & 0x7ff;
    let exponent = f64::from_bits(TWO_52_BITS | biased) - TWO_52 - 1023.0;
    let mantissa = f64::from_bits((bits & MANTISSA) | ONE_BITS);
    let high = mantissa > std::f64::consts::SQRT_2;
    let m = if high { mantissa * 0.5 } else { mantissa };
    let e = if high { exponent + 1.0 } else { exponent };
    let s = (m - 1.0) / (m + 1.0);
    let z = s * s;
    let mut series = SERIES_LAST;
    for c in SERIES_BELOW {
        series = series * z + c;
    }
    e + (2.0 * s * series) * std::f64::consts::LOG2_E
}

/// An `f64`'s mantissa bits, and the bits of 1.0 (a mantissa OR-ed into them is in [1, 2)).
const MANTISSA: u64 = 0x000f_ffff_ffff_ffff;
const ONE_BITS: u64 = 0x3ff0_0000_0000_0000;
/// 2^52 as bits and value: OR-ing an 11-bit integer into its mantissa and subtracting 2^52
/// converts it exactly (vectorisable, unlike an integer-to-float conversion of 64-bit lanes
/// without AVX-512).
const TWO_52_BITS: u64 = 0x4330_0000_0000_0000;
const TWO_52: f64 = 4_503_599_627_370_496.0;

/// The coefficients of `atanh(s) / s` in `z = s^2` (module docs), summed by Horner's rule:
/// the last one, then the others from the highest power down.
const SERIES_LAST: f64 = 1.0 / 19.0;
const SERIES_BELOW: [f64; 9] = [
    1.0 / 17.0,
    1.0 / 15.0,
    1.0 / 13.0,
    1.0 / 11.0,
    1.0 / 9.0,
    1.0 / 7.0,
    1.0 / 5.0,
    1.0 / 3.0,
    1.0,
];

/// Replaces every value of `values` with its [`log2`], the same bits as one at a time, in
/// the copy [`simd::dispatch`] chooses (four lanes per instruction in the AVX2 copy, eight
/// where it may call AVX-512 routines).
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
        #[cfg(target_arch = "x86_64")]
        if AVX2 && simd::avx512() {
            // SAFETY: `simd::avx512()` holds only where the CPU has AVX-512F.
            return unsafe { avx512::log2_in_place(self.0) };
        }
        for v in self.0 {
            *v = log2(*v);
        }
    }
}

/// [`log2`] eight values per instruction with AVX-512F, for the AVX2 copy on CPUs that have
/// it: the deforming meshes' `log2 P_b` walk takes its logarithms 64 at a time, and four
/// lanes per instruction left that arithmetic the larger part of the walk.
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use std::arch::x86_64::*;

    use super::{MANTISSA, ONE_BITS, SERIES_BELOW, SERIES_LAST, TWO_52, TWO_52_BITS};

    /// Replaces every value of `values` with its [`super::log2`]: the same IEEE operations
    /// on the same operands in the same order, eight lanes at a time (the tail of fewer
    /// than eight one at a time), so the same bits.
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn log2_in_place(values: &mut [f64]) {
        let mut chunks = values.chunks_exact_mut(8);
        for chunk in &mut chunks {
            // SAFETY: a chunk holds eight f64s; unaligned load and store.
            unsafe {
                let x = _mm512_loadu_pd(chunk.as_ptr());
                _mm512_storeu_pd(chunk.as_mut_ptr(), log2_lanes(x));
            }
        }
        for v in chunks.into_remainder() {
            *v = super::log2(*v);
        }
    }

    /// [`super::log2`] of each lane, step by step as it is written there.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn log2_lanes(x: __m512d) -> __m512d {
        let splat = _mm512_set1_pd;
        let bits = _mm512_castpd_si512(x);
        let biased = _mm512_and_si512(_mm512_srli_epi64::<52>(bits), _mm512_set1_epi64(0x7ff));
        let bits_of = |b: u64| _mm512_set1_epi64(b as i64);
        let exponent = _mm512_castsi512_pd(_mm512_or_si512(bits_of(TWO_52_BITS), biased));
        let exponent = _mm512_sub_pd(_mm512_sub_pd(exponent, splat(TWO_52)), splat(1023.0));
        let mantissa = _mm512_castsi512_pd(_mm512_or_si512(
            _mm512_and_si512(bits, bits_of(MANTISSA)),
            bits_of(ONE_BITS),
        ));
        // `mantissa > SQRT_2`: false for NaN, as the scalar comparison.
        let high = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(mantissa, splat(std::f64::consts::SQRT_2));
        let m = _mm512_mask_mul_pd(mantissa, high, mantissa, splat(0.5));
        let e = _mm512_mask_add_pd(exponent, high, exponent, splat(1.0));
        let s = _mm512_div_pd(_mm512_sub_pd(m, splat(1.0)), _mm512_add_pd(m, splat(1.0)));
        let z = _mm512_mul_pd(s, s);
        let mut series = splat(SERIES_LAST);
        for c in SERIES_BELOW {
            series = _mm512_add_pd(_mm512_mul_pd(series, z), splat(c));
        }
        let sum = _mm512_mul_pd(_mm512_mul_pd(splat(2.0), s), series);
        _mm512_add_pd(e, _mm512_mul_pd(sum, splat(std::f64::consts::LOG2_E)))
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
                check(
                    &batch,
                    start,
                    if simd::avx512() { "avx512" } else { "avx2" },
                );
            }
        }
    }

    /// The eight-lane routine gives the scalar function's bits on inputs outside its
    /// contract too (zero, subnormals, infinities, NaN, negatives: a deforming triangle's
    /// squared cross product can be any of the first three), which the `log2 P_b` walk
    /// passes through before choosing its limits; on every lane position.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn eight_lanes_equal_one_at_a_time_on_any_input() {
        if !simd::Isa::cpu_has_avx512() {
            eprintln!("skipped: this CPU has no AVX-512F");
            return;
        }
        let mut state = 0x0bad_5eed_1234_5678u64;
        let mut values = vec![
            0.0,
            -0.0,
            f64::MIN_POSITIVE / 3.0,
            5e-324,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -1.0,
            -3.5e10,
            f64::MAX,
            std::f64::consts::SQRT_2,
            std::f64::consts::SQRT_2.next_up(),
        ];
        values.extend((0..4000).map(|_| random_positive(&mut state)));
        for shift in 0..8 {
            let mut batch = values[shift..].to_vec();
            // SAFETY: the CPU has AVX-512F (checked above).
            unsafe { avx512::log2_in_place(&mut batch) };
            for (x, got) in values[shift..].iter().zip(&batch) {
                let want = log2(*x);
                assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "{x:e}: {got:e} against {want:e}"
                );
            }
        }
    }
}
