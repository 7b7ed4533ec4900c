//! The texels of a lookup, read, decoded and blended: one level (bilinear) or two at once
//! (trilinear), in the baseline copy or the AVX2 copy of a `simd::Kernel`.
//!
//! Both copies compute the same bits (the tests compare them with the scalar formulas
//! below on every CPU): the AVX2 copy decodes two texels' codes with one gather from the
//! decoding table and blends the texels of two levels (or the two rows of one) in one
//! 8-lane operation, but each lane is the same IEEE single-precision product or sum as the
//! baseline's, in the same order, with no fused multiply-add.

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

/// The four texels of `taps`, decoded.
#[inline(always)]
fn texels(level: &MipLevel, taps: &BilinearTaps) -> [Vec4; 4] {
    let [i00, i10, i01, i11] = taps.texels.map(|i| i as usize);
    // The storage is matched once per lookup, not once per texel.
    match &level.texels {
        Texels::Linear(t) => [t[i00], t[i10], t[i01], t[i11]],
        Texels::Srgb8 { codes, tables } => {
            let c = codes.flat();
            [
                tables.texel(c[i00]),
                tables.texel(c[i10]),
                tables.texel(c[i01]),
                tables.texel(c[i11]),
            ]
        }
    }
}

/// The four 8-bit texels of `taps`, as codes.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn codes(codes: &[[u8; 4]], taps: &BilinearTaps) -> [[u8; 4]; 4] {
    let [i00, i10, i01, i11] = taps.texels.map(|i| i as usize);
    [codes[i00], codes[i10], codes[i01], codes[i11]]
}

/// Bilinear lookup in one level at `taps`.
#[inline(always)]
pub(super) fn bilinear<const AVX2: bool>(level: &MipLevel, taps: &BilinearTaps) -> Vec4 {
    #[cfg(target_arch = "x86_64")]
    if AVX2 && let Texels::Srgb8 { codes: c, tables } = &level.texels {
        // SAFETY: `AVX2` is true only in the copy `simd::dispatch` runs where the CPU has
        // AVX2.
        return unsafe { avx2::bilinear(tables.decode_table(), codes(c.flat(), taps), taps) };
    }
    bilinear_blend(texels(level, taps), taps.fx, taps.fy)
}

/// Trilinear lookup: bilinear in `levels[0]` and `levels[1]` at their taps, blended by
/// `frac` (the weight of `levels[1]`).
#[inline(always)]
pub(super) fn trilinear<const AVX2: bool>(
    levels: [&MipLevel; 2],
    taps: &[BilinearTaps; 2],
    frac: f32,
) -> Vec4 {
    #[cfg(target_arch = "x86_64")]
    if AVX2
        && let (
            Texels::Srgb8 {
                codes: lower,
                tables,
            },
            Texels::Srgb8 {
                codes: upper,
                tables: t,
            },
        ) = (&levels[0].texels, &levels[1].texels)
        && std::ptr::eq(tables.decode_table(), t.decode_table())
    {
        let codes = [codes(lower.flat(), &taps[0]), codes(upper.flat(), &taps[1])];
        // SAFETY: as in `bilinear`.
        return unsafe { avx2::trilinear(tables.decode_table(), codes, taps, frac) };
    }
    let lower = bilinear_blend(texels(levels[0], &taps[0]), taps[0].fx, taps[0].fy);
    let upper = bilinear_blend(texels(levels[1], &taps[1]), taps[1].fx, taps[1].fy);
    level_blend(lower, upper, frac)
}

/// The AVX2 copy's 8-bit lookups: a gather decodes two texels, the lanes then hold two
/// texels side by side (`[first | second]`, four channels each) through the blend.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use glam::Vec4;

    use super::super::decode::ALPHA_OFFSET;
    use super::BilinearTaps;

    /// `[first | second]`: the two texels of 8-bit codes, decoded by `table` (colour codes
    /// at their value, alpha codes at `ALPHA_OFFSET` past it).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn decode_two(table: &[f32; 2 * 256], first: [u8; 4], second: [u8; 4]) -> __m256 {
        let bytes =
            u64::from(u32::from_le_bytes(first)) | u64::from(u32::from_le_bytes(second)) << 32;
        // One lane per byte: r g b a of `first`, then of `second`.
        let codes = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(bytes as i64));
        let a = ALPHA_OFFSET as i32;
        let index = _mm256_add_epi32(codes, _mm256_setr_epi32(0, 0, 0, a, 0, 0, 0, a));
        // SAFETY: every index is a byte, plus ALPHA_OFFSET on alpha lanes: below 512, the
        // table's length.
        unsafe { _mm256_i32gather_ps::<4>(table.as_ptr(), index) }
    }

    /// `first * (1 - weight_first) + second * weight` per half, with the weights of each
    /// half broadcast from `[lower, upper]`.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn lerp_halves(first: __m256, second: __m256, weight: [f32; 2]) -> __m256 {
        let w = _mm256_setr_m128(_mm_set1_ps(weight[0]), _mm_set1_ps(weight[1]));
        let rest = _mm256_setr_m128(_mm_set1_ps(1.0 - weight[0]), _mm_set1_ps(1.0 - weight[1]));
        _mm256_add_ps(_mm256_mul_ps(first, rest), _mm256_mul_ps(second, w))
    }

    /// `lower * (1 - weight) + upper * weight` for the two halves of `halves`.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn lerp_between_halves(halves: __m256, weight: f32) -> Vec4 {
        let lower = _mm256_castps256_ps128(halves);
        let upper = _mm256_extractf128_ps::<1>(halves);
        let blended = _mm_add_ps(
            _mm_mul_ps(lower, _mm_set1_ps(1.0 - weight)),
            _mm_mul_ps(upper, _mm_set1_ps(weight)),
        );
        Vec4::from(blended)
    }

    /// `fetch::bilinear` for 8-bit codes `[c00, c10, c01, c11]` (`BilinearTaps` order).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn bilinear(
        table: &[f32; 2 * 256],
        [c00, c10, c01, c11]: [[u8; 4]; 4],
        taps: &BilinearTaps,
    ) -> Vec4 {
        // [row0 | row1] = [t00 | t01] * (1 - fx) + [t10 | t11] * fx.
        let x0 = decode_two(table, c00, c01);
        let x1 = decode_two(table, c10, c11);
        let rows = lerp_halves(x0, x1, [taps.fx; 2]);
        lerp_between_halves(rows, taps.fy)
    }

    /// `fetch::trilinear` for 8-bit codes of both levels.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn trilinear(
        table: &[f32; 2 * 256],
        [lower, upper]: [[[u8; 4]; 4]; 2],
        taps: &[BilinearTaps; 2],
        frac: f32,
    ) -> Vec4 {
        // Texel j of both levels side by side: [lower_j | upper_j].
        let t00 = decode_two(table, lower[0], upper[0]);
        let t10 = decode_two(table, lower[1], upper[1]);
        let t01 = decode_two(table, lower[2], upper[2]);
        let t11 = decode_two(table, lower[3], upper[3]);
        let fx = [taps[0].fx, taps[1].fx];
        let fy = [taps[0].fy, taps[1].fy];
        let row0 = lerp_halves(t00, t10, fx);
        let row1 = lerp_halves(t01, t11, fx);
        let levels = lerp_halves(row0, row1, fy);
        lerp_between_halves(levels, frac)
    }
}
