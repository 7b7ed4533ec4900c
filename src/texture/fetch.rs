//! The texels of a lookup, read, decoded and blended: one level (bilinear) or two
//! (trilinear).
//!
//! The same arithmetic in both copies of a `simd::Kernel`: each texel's four channels are read
//! from the decoding table one by one, and a trilinear lookup's two bilinear blends are the
//! same operations lane by lane, four lanes at a time in the baseline copy and both levels in
//! AVX's eight lanes in the AVX2 copy. An AVX2 copy that decoded two texels with one gather from
//! the table (and blended two texels per 8-lane operation) was slower on an AMD Zen 4
//! (`cargo bench --bench texture_filter`: trilinear 47-60 ns a lookup against 40-47 with
//! per-channel loads), and a microbenchmark of the decode alone was twice as slow with
//! gathers on an AMD Zen 5 (13.4 against 6.1-6.4 ns for eight texels' RGB); Intel's
//! microcode mitigation of Gather Data Sampling slows gathers on the CPUs it covers too: a
//! lookup's sixteen or thirty-two reads of a 2 KiB table that stays in cache are cheaper as
//! plain loads.

use glam::Vec4;

use super::taps::BilinearTaps;
use super::{MipLevel, Texels};

/// The bilinear blend of one level's four texels (in [`BilinearTaps::texels`] order): the
/// formula of every lookup.
#[inline(always)]
pub(super) fn bilinear_blend([t00, t10, t01, t11]: [Vec4; 4], fx: f32, fy: f32) -> Vec4 {
    // Weighted form (not a + (b - a) f) so a zero weight returns the texel bit-exactly.
    let row0 = t00 * (1.0 - fx) + t10 * fx;
    let row1 = t01 * (1.0 - fx) + t11 * fx;
    row0 * (1.0 - fy) + row1 * fy
}

/// The blend of two levels' bilinear results by the fraction of the LOD.
#[inline(always)]
pub(super) fn level_blend(lower: Vec4, upper: Vec4, frac: f32) -> Vec4 {
    lower * (1.0 - frac) + upper * frac
}

/// The four texels of `taps`, decoded (an 8-bit level's alpha only when `ALPHA`; the
/// blends work lane by lane, so the colour channels are the same bits either way).
///
/// Read without bounds checks unless `CHECKED`: a lookup's taps are wrapped into the level
/// they were computed for (`BilinearTaps`), so where the caller reads the level the taps
/// were made for, every index is in range and the four checks (eight instructions a level,
/// sixteen a trilinear lookup) can only pass. `CHECKED` keeps them for a plan the caller
/// hands in from outside, which may have been made on another pyramid.
///
/// # Safety
/// Without `CHECKED`, every index in `taps.texels` must be below the level's texel count:
/// true of taps computed for `level` (or for a level of the same size and storage).
#[inline(always)]
unsafe fn texels<const ALPHA: bool, const CHECKED: bool>(
    level: &MipLevel,
    taps: &BilinearTaps,
) -> [Vec4; 4] {
    #[inline(always)]
    fn read<T: Copy, const CHECKED: bool>(slice: &[T], i: u32) -> T {
        if CHECKED {
            slice[i as usize]
        } else {
            debug_assert!((i as usize) < slice.len(), "tap {i} of {}", slice.len());
            // SAFETY: the caller of `texels` guarantees the index is in range (see there).
            unsafe { *slice.get_unchecked(i as usize) }
        }
    }
    let [i00, i10, i01, i11] = taps.texels;
    // The storage is matched once per lookup, not once per texel.
    match &level.texels {
        Texels::Linear(t) => [
            read::<_, CHECKED>(t, i00),
            read::<_, CHECKED>(t, i10),
            read::<_, CHECKED>(t, i01),
            read::<_, CHECKED>(t, i11),
        ],
        Texels::Srgb8 { codes, tables } => {
            let c = codes.flat();
            [
                tables.texel_in::<ALPHA>(read::<_, CHECKED>(c, i00)),
                tables.texel_in::<ALPHA>(read::<_, CHECKED>(c, i10)),
                tables.texel_in::<ALPHA>(read::<_, CHECKED>(c, i01)),
                tables.texel_in::<ALPHA>(read::<_, CHECKED>(c, i11)),
            ]
        }
    }
}

/// Bilinear lookup in one level at `taps` (alpha as [`texels`] decodes it).
///
/// # Safety
/// As [`texels`] (nothing without `CHECKED`).
#[inline(always)]
pub(super) unsafe fn bilinear<const ALPHA: bool, const CHECKED: bool>(
    level: &MipLevel,
    taps: &BilinearTaps,
) -> Vec4 {
    // SAFETY: passed on to the caller.
    let texels = unsafe { texels::<ALPHA, CHECKED>(level, taps) };
    bilinear_blend(texels, taps.fx, taps.fy)
}

/// Trilinear lookup: bilinear in `levels[0]` and `levels[1]` at their taps, blended by
/// `frac` (the weight of `levels[1]`). The AVX2 copy makes both levels' bilinear blends at
/// once ([`two_bilinear_blends`]).
///
/// # Safety
/// As [`texels`], for each level and its taps (nothing without `CHECKED`).
#[inline(always)]
pub(super) unsafe fn trilinear<const ALPHA: bool, const AVX2: bool, const CHECKED: bool>(
    levels: [&MipLevel; 2],
    taps: &[BilinearTaps; 2],
    frac: f32,
) -> Vec4 {
    // SAFETY (all three blocks): passed on to the caller.
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        let texels = unsafe {
            [
                texels::<ALPHA, CHECKED>(levels[0], &taps[0]),
                texels::<ALPHA, CHECKED>(levels[1], &taps[1]),
            ]
        };
        // SAFETY: `AVX2` is true only in the copy `simd::dispatch` runs where the CPU has
        // AVX2 (and in tests that check the CPU first).
        let [lower, upper] = unsafe { two_bilinear_blends(texels, taps) };
        return level_blend(lower, upper, frac);
    }
    let lower = unsafe { bilinear::<ALPHA, CHECKED>(levels[0], &taps[0]) };
    let upper = unsafe { bilinear::<ALPHA, CHECKED>(levels[1], &taps[1]) };
    level_blend(lower, upper, frac)
}

/// [`bilinear_blend`] of two levels' texels in the eight lanes of AVX (the first level's
/// channels in lanes 0 to 3, the second's in 4 to 7): the same operations on the same
/// operands lane by lane, so the same bits, in half the arithmetic instructions.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx")]
unsafe fn two_bilinear_blends(texels: [[Vec4; 4]; 2], taps: &[BilinearTaps; 2]) -> [Vec4; 2] {
    use std::arch::x86_64::*;
    let [a, b] = texels;
    let t00 = _mm256_set_m128(b[0].into(), a[0].into());
    let t10 = _mm256_set_m128(b[1].into(), a[1].into());
    let t01 = _mm256_set_m128(b[2].into(), a[2].into());
    let t11 = _mm256_set_m128(b[3].into(), a[3].into());
    let fx = _mm256_set_m128(_mm_set1_ps(taps[1].fx), _mm_set1_ps(taps[0].fx));
    let fy = _mm256_set_m128(_mm_set1_ps(taps[1].fy), _mm_set1_ps(taps[0].fy));
    let one = _mm256_set1_ps(1.0);
    let (gx, gy) = (_mm256_sub_ps(one, fx), _mm256_sub_ps(one, fy));
    let row0 = _mm256_add_ps(_mm256_mul_ps(t00, gx), _mm256_mul_ps(t10, fx));
    let row1 = _mm256_add_ps(_mm256_mul_ps(t01, gx), _mm256_mul_ps(t11, fx));
    let both = _mm256_add_ps(_mm256_mul_ps(row0, gy), _mm256_mul_ps(row1, fy));
    [
        _mm256_castps256_ps128(both).into(),
        _mm256_extractf128_ps::<1>(both).into(),
    ]
}
