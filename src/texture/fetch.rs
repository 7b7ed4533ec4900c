//! The texels of a lookup, read, decoded and blended: one level (bilinear) or two
//! (trilinear).
//!
//! One formula for both copies of a `simd::Kernel`: each texel's four channels are read from
//! the decoding table one by one. An AVX2 copy that decoded two texels with one gather from
//! the table (and blended two texels per 8-lane operation) was slower on an AMD Zen 4
//! (`cargo bench --bench texture_filter`: trilinear 47-60 ns a lookup against 40-47 with
//! per-channel loads; not measured on other CPUs, but Intel's microcode mitigation of Gather
//! Data Sampling slows gathers on the CPUs it covers): a lookup's sixteen or thirty-two
//! reads of a 2 KiB table that stays in cache are cheaper as plain loads.

use glam::Vec4;

use super::taps::BilinearTaps;
use super::{MipLevel, Texels};
use crate::simd::F32x8;

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
#[inline(always)]
fn texels<const ALPHA: bool>(level: &MipLevel, taps: &BilinearTaps) -> [Vec4; 4] {
    let [i00, i10, i01, i11] = taps.texels.map(|i| i as usize);
    // The storage is matched once per lookup, not once per texel.
    match &level.texels {
        Texels::Linear(t) => [t[i00], t[i10], t[i01], t[i11]],
        Texels::Srgb8 { codes, tables } => {
            let c = codes.flat();
            [
                tables.texel_in::<ALPHA>(c[i00]),
                tables.texel_in::<ALPHA>(c[i10]),
                tables.texel_in::<ALPHA>(c[i01]),
                tables.texel_in::<ALPHA>(c[i11]),
            ]
        }
    }
}

/// Bilinear lookup in one level at `taps` (alpha as [`texels`] decodes it).
#[inline(always)]
pub(super) fn bilinear<const ALPHA: bool>(level: &MipLevel, taps: &BilinearTaps) -> Vec4 {
    bilinear_blend(texels::<ALPHA>(level, taps), taps.fx, taps.fy)
}

/// Trilinear lookup: bilinear in `levels[0]` and `levels[1]` at their taps, blended by
/// `frac` (the weight of `levels[1]`). The AVX2 copy makes both levels' bilinear blends at
/// once ([`two_bilinear_blends`]).
#[inline(always)]
pub(super) fn trilinear<const ALPHA: bool, const AVX2: bool>(
    levels: [&MipLevel; 2],
    taps: &[BilinearTaps; 2],
    frac: f32,
) -> Vec4 {
    let [lower, upper] = if AVX2 {
        two_bilinear_blends(
            [
                texels::<ALPHA>(levels[0], &taps[0]),
                texels::<ALPHA>(levels[1], &taps[1]),
            ],
            taps,
        )
    } else {
        [
            bilinear::<ALPHA>(levels[0], &taps[0]),
            bilinear::<ALPHA>(levels[1], &taps[1]),
        ]
    };
    level_blend(lower, upper, frac)
}

/// [`bilinear_blend`] of two levels' texels in the eight lanes of AVX (the first level's
/// channels in lanes 0 to 3, the second's in 4 to 7): the same operations on the same
/// operands lane by lane, so the same bits, in half the arithmetic instructions. Only
/// called from the AVX2 copy.
#[inline(always)]
fn two_bilinear_blends(texels: [[Vec4; 4]; 2], taps: &[BilinearTaps; 2]) -> [Vec4; 2] {
    let [a, b] = texels;
    let pair = |i: usize| {
        F32x8(std::array::from_fn(|l| {
            if l < 4 { a[i][l] } else { b[i][l - 4] }
        }))
    };
    let weights = |w: [f32; 2]| F32x8(std::array::from_fn(|l| w[l / 4]));
    let fx = weights([taps[0].fx, taps[1].fx]);
    let fy = weights([taps[0].fy, taps[1].fy]);
    let one = F32x8::splat(1.0);
    let (gx, gy) = (one.sub::<true>(fx), one.sub::<true>(fy));
    let row0 = pair(0).mul::<true>(gx).add::<true>(pair(1).mul::<true>(fx));
    let row1 = pair(2).mul::<true>(gx).add::<true>(pair(3).mul::<true>(fx));
    let both = row0.mul::<true>(gy).add::<true>(row1.mul::<true>(fy)).0;
    [0, 4].map(|l| Vec4::new(both[l], both[l + 1], both[l + 2], both[l + 3]))
}
