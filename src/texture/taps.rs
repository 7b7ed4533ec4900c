//! Where a bilinear lookup reads in a level: four texel indices and two weights.
//!
//! Along each axis the answer is `sample::axis_in`'s, bit for bit: the texel coordinate
//! `x = t * n - 0.5` in f64 (see `sample.rs` for why), its floor and fraction, wrapped.
//! [`axis_taps_in`] reaches it in f32 when the side `n` is a power of two, the coordinate is
//! moderate and no wrap mode but Repeat has to act (the common case: tiled or not, the
//! lookup lands in the image or repeats it):
//! - `p = t * n` is exact in f32 (a power of two only moves the exponent) when
//!   `0.5 <= |p| < 2^23`, which also rules out overflow and underflow;
//! - `p`'s ulp is then at least `2^-24`, so with `r = p - floor(p)` in `[0, 1)` (exact: both
//!   are multiples of that ulp), `floor(x)` is `floor(p)` when `r >= 0.5` and
//!   `floor(p) - 1` otherwise, and the fraction of `x` is `r - 0.5` or `r + 0.5`, a multiple
//!   of `2^-24` below 1: exact in f32;
//! - in f64, `x = p - 0.5` is exact too (at most 48 significant bits), so `x - floor(x)` is
//!   the same real number, and its conversion to f32 rounds nothing.
//!
//! A level whose sides are not both powers of two takes the f64 formula itself, on both
//! axes at once in SSE2's two f64 lanes ([`two_axes`]). Everything else (on a power-of-two
//! side `|p| < 0.5`; huge or non-finite coordinates; Clamp and Mirror outside the image)
//! goes to `sample::axis_in`, one axis at a time. The AVX2 copy takes a trilinear lookup's
//! two levels' four axes in AVX's four f64 lanes ([`four_axes_f64`]) where the f32 shortcut
//! does not take them all. The tests check each against it on edge and random coordinates
//! (`shortcut_is_exactly_the_f64_axis`, `two_axes_are_exactly_the_f64_axis`,
//! `a_pair_of_levels_has_each_levels_own_taps`).

use glam::Vec2;

#[cfg(test)]
use super::sample::axis;
use super::sample::axis_in;
use super::{MipLevel, Sampler, WrapMode};

/// What a bilinear lookup reads in one level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct BilinearTaps {
    /// Storage indices (`MipLevel::row_start(y) + MipLevel::column_offset(x)`) of the
    /// texels `(x0, y0)`, `(x1, y0)`, `(x0, y1)`, `(x1, y1)`, already wrapped into the
    /// level. `u32`: a level stores at most `MAX_SIZE^2 = 2^28` texels (`MAX_SIZE` is a
    /// multiple of the 8-bit blocks' side, so padding adds none at the limit), and a
    /// planned lookup keeps two sets of taps until it is filtered, so they are kept small.
    pub texels: [u32; 4],
    /// Weight of the `x1` column (`x0` has `1 - fx`).
    pub fx: f32,
    /// Weight of the `y1` row (`y0` has `1 - fy`).
    pub fy: f32,
}

/// One axis of a lookup: the two texel indices along it and the weight of the second.
type AxisTaps = (usize, usize, f32);

impl BilinearTaps {
    /// [`BilinearTaps::new_in`] as the baseline copy computes it.
    #[cfg(test)]
    pub fn new(level: &MipLevel, uv: Vec2, sampler: Sampler) -> BilinearTaps {
        Self::new_in::<false>(level, uv, sampler)
    }

    /// The taps at any `uv` with any wrap modes, as the kernels' copies compute them (the
    /// same bits in each, see [`axis_taps_in`]).
    #[inline(always)]
    pub fn new_in<const AVX2: bool>(level: &MipLevel, uv: Vec2, sampler: Sampler) -> BilinearTaps {
        if !level.sides_power_of_two() {
            let repeat = [sampler.wrap_s, sampler.wrap_t].map(|m| m == WrapMode::Repeat);
            if let Some([x, y]) = two_axes([uv.x, uv.y], [level.width, level.height], repeat) {
                return Self::of_axes(level, x, y);
            }
        }
        Self::of_axes(
            level,
            axis_taps_in::<AVX2>(uv.x, level.width, sampler.wrap_s),
            axis_taps_in::<AVX2>(uv.y, level.height, sampler.wrap_t),
        )
    }

    /// The taps of `level` from its two axes' texel indices and weights.
    #[inline(always)]
    fn of_axes(level: &MipLevel, (x0, x1, fx): AxisTaps, (y0, y1, fy): AxisTaps) -> BilinearTaps {
        let (row0, row1) = (level.row_start(y0), level.row_start(y1));
        let (col0, col1) = (level.column_offset(x0), level.column_offset(x1));
        BilinearTaps {
            texels: [row0 + col0, row0 + col1, row1 + col0, row1 + col1].map(|i| i as u32),
            fx,
            fy,
        }
    }

    /// [`BilinearTaps::new_in`] in two levels at once (a trilinear lookup's), the same bits
    /// as one level at a time: where the shortcut applies to all four axes (both levels'
    /// sides powers of two, see the module note), their floors, fractions and wraps are
    /// computed four lanes at a time ([`four_axes`]); otherwise, in the AVX2 copy, the f64
    /// formula on the four axes at once ([`four_axes_f64`]); otherwise each level alone.
    /// From either four-lane form, two levels of 8-bit codes get their storage indices in
    /// lanes too ([`blocked_pair_texels`]).
    ///
    /// Why: the second level of a trilinear lookup made it cost nearly two bilinear ones;
    /// on x86-64 the four axes take about the instructions of two.
    #[inline(always)]
    pub fn pair_in<const AVX2: bool>(
        levels: [&MipLevel; 2],
        uv: Vec2,
        sampler: Sampler,
    ) -> [BilinearTaps; 2] {
        let [a, b] = levels;
        let sides = [a.width, a.height, b.width, b.height];
        let repeat = [sampler.wrap_s, sampler.wrap_t].map(|m| m == WrapMode::Repeat);
        let axes = if a.sides_power_of_two() && b.sides_power_of_two() {
            four_axes(uv, sides, repeat)
        } else {
            None
        };
        #[cfg(target_arch = "x86_64")]
        let axes = match axes {
            // SAFETY: `AVX2` is true only in the copy `simd::dispatch` runs where the CPU
            // has AVX2 (and in tests that check the CPU first).
            None if AVX2 => unsafe { four_axes_f64([uv.x, uv.y], sides, repeat) },
            axes => axes,
        };
        if let Some((i0, i1, frac)) = axes {
            let taps = |texels, lane: usize| BilinearTaps {
                texels,
                fx: frac[lane],
                fy: frac[lane + 1],
            };
            if let (Some(sa), Some(sb)) = (a.block_row_stride(), b.block_row_stride()) {
                let [ta, tb] = blocked_pair_texels(i0, i1, [sa, sb]);
                return [taps(ta, 0), taps(tb, 2)];
            }
            // Lane `lane`'s axis; every index is in `0..n` (wrapped, or inside).
            let axis = |lane: usize| (i0[lane] as usize, i1[lane] as usize, frac[lane]);
            return [
                Self::of_axes(a, axis(0), axis(1)),
                Self::of_axes(b, axis(2), axis(3)),
            ];
        }
        // Written out, not `levels.map`: a closure the compiler leaves out of line loses
        // the AVX2 copy's rounding instructions (its floors became library calls).
        [
            Self::new_in::<AVX2>(a, uv, sampler),
            Self::new_in::<AVX2>(b, uv, sampler),
        ]
    }
}

/// [`axis_taps_in`]'s shortcut on two levels' four axes at once (`sides`: the two levels'
/// widths and heights, each a power of two; `repeat`: whether the s and t axes repeat):
/// for `p = t * n` on each axis, the two texel indices and the weight of the second, the
/// same bits as the shortcut gives each; `None` when the shortcut does not apply to every
/// axis (a `|p|` outside `[0.5, 2^23)` or NaN, or a lookup that leaves the image under a
/// mode other than Repeat).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn four_axes(uv: Vec2, sides: [u32; 4], repeat: [bool; 2]) -> Option<FourAxes> {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64, and these intrinsics only compute on registers and
    // store local arrays of four lanes.
    unsafe {
        // The sides in integer lanes (at most `MAX_SIZE`, so exact as i32 and as f32):
        // `t * n` is the product each axis computes alone, and the masks below are `n - 1`,
        // made in the lanes rather than lane by lane and loaded.
        let n = _mm_setr_epi32(
            sides[0] as i32,
            sides[1] as i32,
            sides[2] as i32,
            sides[3] as i32,
        );
        let p = _mm_mul_ps(_mm_setr_ps(uv.x, uv.y, uv.x, uv.y), _mm_cvtepi32_ps(n));
        let magnitude = _mm_and_ps(p, _mm_castsi128_ps(_mm_set1_epi32(i32::MAX)));
        let fits = _mm_and_ps(
            _mm_cmpge_ps(magnitude, _mm_set1_ps(0.5)),
            _mm_cmplt_ps(magnitude, _mm_set1_ps(F32_EXACT_BELOW)),
        );
        if _mm_movemask_ps(fits) != 0b1111 {
            return None;
        }
        // `floor_and_fraction_of_p_minus_half` lane by lane: the floor by truncation, one
        // less where that rounded up (exact for |p| < 2^23, as the rounding instruction).
        let truncated = _mm_cvttps_epi32(p);
        let rounded_up = _mm_castps_si128(_mm_cmpgt_ps(_mm_cvtepi32_ps(truncated), p));
        let floor = _mm_add_epi32(truncated, rounded_up);
        let r = _mm_sub_ps(p, _mm_cvtepi32_ps(floor));
        let h = _mm_cvttps_epi32(_mm_mul_ps(r, _mm_set1_ps(2.0)));
        let x0 = _mm_sub_epi32(_mm_add_epi32(floor, h), _mm_set1_epi32(1));
        let frac = _mm_add_ps(_mm_sub_ps(r, _mm_cvtepi32_ps(h)), _mm_set1_ps(0.5));
        // Repeat wraps with the side's mask (two's complement: the Euclidean remainder for
        // negative `x0` too); other modes need both texels inside, `0 <= x0 < last`.
        let last = _mm_sub_epi32(n, _mm_set1_epi32(1));
        let (repeat_s, repeat_t) = (-i32::from(repeat[0]), -i32::from(repeat[1]));
        let repeat = _mm_setr_epi32(repeat_s, repeat_t, repeat_s, repeat_t);
        let inside = _mm_andnot_si128(
            _mm_cmplt_epi32(x0, _mm_setzero_si128()),
            _mm_cmplt_epi32(x0, last),
        );
        if _mm_movemask_ps(_mm_castsi128_ps(_mm_or_si128(repeat, inside))) != 0b1111 {
            return None;
        }
        let one = _mm_set1_epi32(1);
        let select = |wrapped: __m128i, plain: __m128i| {
            _mm_or_si128(
                _mm_and_si128(repeat, wrapped),
                _mm_andnot_si128(repeat, plain),
            )
        };
        let i0 = select(_mm_and_si128(x0, last), x0);
        let i1 = select(
            _mm_and_si128(_mm_add_epi32(i0, one), last),
            _mm_add_epi32(x0, one),
        );
        let (mut first, mut second, mut weight) = ([0i32; 4], [0i32; 4], [0.0f32; 4]);
        _mm_storeu_si128(first.as_mut_ptr().cast(), i0);
        _mm_storeu_si128(second.as_mut_ptr().cast(), i1);
        _mm_storeu_ps(weight.as_mut_ptr(), frac);
        Some((first, second, weight))
    }
}

/// `sample::axis_in` on a level's two axes at once (`t` the coordinates, `sides` the
/// level's width and height), in f64 as that computes them, for sides of any size: the
/// same indices and the same weight bits; `None` when a lane is not a moderate finite
/// coordinate (`|t * n - 0.5| >= 2^30`), or leaves the image under a mode other than
/// Repeat (`repeat[i]` false), for `axis_in` to take.
///
/// Why: the f32 shortcut holds only for sides that are powers of two, and images of other
/// sizes are common (BART Kitchen's floor is 1044 texels square, tiled), so their lookups
/// went through `axis_in` one axis at a time, with a 64-bit division for every tiled one.
/// Here SSE2's two f64 lanes do both axes, and the Repeat remainder is
/// `x0 - n * floor(x0 / n)`, exact: for `|x0| <= 2^30` and `n <= 2^14` the quotient
/// `x0 / n` is at least `1 / n` from any integer it does not equal, far more than its
/// rounding error, so its floor is the integer quotient; the product and the difference
/// are integers below 2^31, exact in f64.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn two_axes(t: [f32; 2], sides: [u32; 2], repeat: [bool; 2]) -> Option<[AxisTaps; 2]> {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64, and these intrinsics only compute on registers and
    // store local arrays of two or four lanes.
    unsafe {
        let n = _mm_setr_pd(f64::from(sides[0]), f64::from(sides[1]));
        let t = _mm_setr_pd(f64::from(t[0]), f64::from(t[1]));
        // `axis_in`'s `t * n - 0.5`, the same two operations (the product is exact: 24 by
        // 15 bits).
        let x = _mm_sub_pd(_mm_mul_pd(t, n), _mm_set1_pd(0.5));
        // Moderate and finite (NaN fails the comparison), so the conversions to i32 below
        // are exact.
        let magnitude = _mm_andnot_pd(_mm_set1_pd(-0.0), x);
        if _mm_movemask_pd(_mm_cmplt_pd(magnitude, _mm_set1_pd(TWO_AXES_BELOW))) != 0b11 {
            return None;
        }
        let x0 = floor_moderate(x);
        let frac = _mm_cvtpd_ps(_mm_sub_pd(x, x0));
        let one = _mm_set1_pd(1.0);
        let next = _mm_add_pd(x0, one);
        // Both texels inside: `0 <= x0` and `x0 + 1 < n`.
        let inside = _mm_and_pd(_mm_cmpge_pd(x0, _mm_setzero_pd()), _mm_cmplt_pd(next, n));
        let repeat = _mm_castsi128_pd(_mm_setr_epi32(
            -i32::from(repeat[0]),
            -i32::from(repeat[0]),
            -i32::from(repeat[1]),
            -i32::from(repeat[1]),
        ));
        if _mm_movemask_pd(_mm_or_pd(repeat, inside)) != 0b11 {
            return None;
        }
        // Repeat: the Euclidean remainder of `x0` and of `x0 + 1` (the second is 0 at
        // `n - 1`); inside the image they are `x0` and `x0 + 1` themselves.
        let wrapped = _mm_sub_pd(x0, _mm_mul_pd(floor_moderate(_mm_div_pd(x0, n)), n));
        let wrapped_next = _mm_add_pd(wrapped, one);
        let wrapped_next = _mm_andnot_pd(_mm_cmpeq_pd(wrapped_next, n), wrapped_next);
        let select = |wrapped: __m128d, plain: __m128d| {
            _mm_or_pd(_mm_and_pd(repeat, wrapped), _mm_andnot_pd(repeat, plain))
        };
        let (mut first, mut second, mut weight) = ([0i32; 4], [0i32; 4], [0.0f32; 4]);
        _mm_storeu_si128(
            first.as_mut_ptr().cast(),
            _mm_cvttpd_epi32(select(wrapped, x0)),
        );
        _mm_storeu_si128(
            second.as_mut_ptr().cast(),
            _mm_cvttpd_epi32(select(wrapped_next, next)),
        );
        _mm_storeu_ps(weight.as_mut_ptr(), frac);
        let axis = |i: usize| (first[i] as usize, second[i] as usize, weight[i]);
        Some([axis(0), axis(1)])
    }
}

/// [`two_axes`] on both levels of a pair at once, in AVX's four f64 lanes (`sides` the
/// levels' widths and heights, `t` the coordinates, `repeat` per axis as there): the same
/// operations lane by lane, so the same indices and weight bits (in [`four_axes`]'s lanes:
/// the first level's x and y, then the second's), or `None` where `two_axes` gives `None`
/// for either level. The floors are the rounding instruction's (exact, as
/// [`floor_moderate`] is, and no lane is `-0.0`, see there).
///
/// Why: a trilinear lookup in an image whose sides are not powers of two (BART Kitchen's
/// floor) computed the two levels' axes one level at a time.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx")]
unsafe fn four_axes_f64(t: [f32; 2], sides: [u32; 4], repeat: [bool; 2]) -> Option<FourAxes> {
    use std::arch::x86_64::*;
    let n = _mm256_setr_pd(
        f64::from(sides[0]),
        f64::from(sides[1]),
        f64::from(sides[2]),
        f64::from(sides[3]),
    );
    let [u, v] = t.map(f64::from);
    let x = _mm256_sub_pd(
        _mm256_mul_pd(_mm256_setr_pd(u, v, u, v), n),
        _mm256_set1_pd(0.5),
    );
    let magnitude = _mm256_andnot_pd(_mm256_set1_pd(-0.0), x);
    let moderate = _mm256_cmp_pd::<_CMP_LT_OQ>(magnitude, _mm256_set1_pd(TWO_AXES_BELOW));
    if _mm256_movemask_pd(moderate) != 0b1111 {
        return None;
    }
    let x0 = _mm256_floor_pd(x);
    let frac = _mm256_cvtpd_ps(_mm256_sub_pd(x, x0));
    let one = _mm256_set1_pd(1.0);
    let next = _mm256_add_pd(x0, one);
    let inside = _mm256_and_pd(
        _mm256_cmp_pd::<_CMP_GE_OQ>(x0, _mm256_setzero_pd()),
        _mm256_cmp_pd::<_CMP_LT_OQ>(next, n),
    );
    let [s, t] = repeat.map(|r| -i64::from(r));
    let repeat = _mm256_castsi256_pd(_mm256_setr_epi64x(s, t, s, t));
    if _mm256_movemask_pd(_mm256_or_pd(repeat, inside)) != 0b1111 {
        return None;
    }
    let wrapped = _mm256_sub_pd(x0, _mm256_mul_pd(_mm256_floor_pd(_mm256_div_pd(x0, n)), n));
    let wrapped_next = _mm256_add_pd(wrapped, one);
    let wrapped_next = _mm256_andnot_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(wrapped_next, n), wrapped_next);
    let (mut first, mut second, mut weight) = ([0i32; 4], [0i32; 4], [0.0f32; 4]);
    // SAFETY: unaligned stores of four lanes into local arrays of four.
    unsafe {
        _mm_storeu_si128(
            first.as_mut_ptr().cast(),
            _mm256_cvttpd_epi32(_mm256_blendv_pd(x0, wrapped, repeat)),
        );
        _mm_storeu_si128(
            second.as_mut_ptr().cast(),
            _mm256_cvttpd_epi32(_mm256_blendv_pd(next, wrapped_next, repeat)),
        );
        _mm_storeu_ps(weight.as_mut_ptr(), frac);
    }
    Some((first, second, weight))
}

/// Largest `|t * n - 0.5|` [`two_axes`] takes: its floors convert through `i32`.
const TWO_AXES_BELOW: f64 = 1_073_741_824.0; // 2^30

/// `floor(x)` lane by lane for `|x| < 2^31`, in SSE2 (the rounding instruction is SSE4.1):
/// the truncation, one less where it rounded up. Exact; `x` is never `-0.0` here (see
/// [`two_axes`]: `t * n - 0.5` and `x0 / n` with `x0` an integer of either sign), so the
/// sign of a zero floor does not matter.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn floor_moderate(x: std::arch::x86_64::__m128d) -> std::arch::x86_64::__m128d {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64; the intrinsics compute on registers only.
    unsafe {
        let truncated = _mm_cvtepi32_pd(_mm_cvttpd_epi32(x));
        let rounded_up = _mm_cmpgt_pd(truncated, x);
        _mm_sub_pd(truncated, _mm_and_pd(rounded_up, _mm_set1_pd(1.0)))
    }
}

/// [`two_axes`] where there is no SSE2: `None` (each axis alone).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn two_axes(_: [f32; 2], _: [u32; 2], _: [bool; 2]) -> Option<[AxisTaps; 2]> {
    None
}

/// The storage indices of two levels of 8-bit codes (block row strides `strides`) at the
/// texel indices [`four_axes`] or [`four_axes_f64`] gives (`i0`, `i1`: lanes x and y of the
/// first level, then of the second, each in `0..n`): what [`BilinearTaps::of_axes`]
/// computes for each level, `row_start(y) + column_offset(x)` with
/// `row_start(y) = (y >> 2) * stride + (y & 3) * 4` and
/// `column_offset(x) = (x >> 2) * 16 + (x & 3)`, in integer lanes. Every index is
/// below 2^29 (`MAX_SIZE` texels a side), so the 32-bit lanes hold it exactly.
///
/// Why: one by one, the two levels' row starts and column offsets (each matching the
/// storage) took about 50 instructions of a trilinear lookup's plan.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn blocked_pair_texels(i0: [i32; 4], i1: [i32; 4], strides: [u32; 2]) -> [[u32; 4]; 2] {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64, and these intrinsics only compute on registers and
    // load and store local arrays of four lanes.
    unsafe {
        let (i0, i1) = (
            _mm_loadu_si128(i0.as_ptr().cast()),
            _mm_loadu_si128(i1.as_ptr().cast()),
        );
        let three = _mm_set1_epi32(3);
        // Every lane's column offset; the x lanes (0 and 2) are the ones used.
        let column = |x: __m128i| {
            _mm_add_epi32(
                _mm_slli_epi32::<4>(_mm_srli_epi32::<2>(x)),
                _mm_and_si128(x, three),
            )
        };
        // The y lanes (1 and 3) moved to lanes 0 and 2, where SSE2 multiplies 32-bit lanes
        // (into 64 bits: the products are below 2^28, so their low halves are exact).
        let stride = _mm_setr_epi32(strides[0] as i32, 0, strides[1] as i32, 0);
        let row = |y: __m128i| {
            let y = _mm_srli_epi64::<32>(y);
            _mm_add_epi32(
                _mm_mul_epu32(_mm_srli_epi32::<2>(y), stride),
                _mm_slli_epi32::<2>(_mm_and_si128(y, three)),
            )
        };
        let (r0, r1, c0, c1) = (row(i0), row(i1), column(i0), column(i1));
        // Each level's rows `[r0, r0, r1, r1]` plus columns `[c0, c1, c0, c1]`: the taps'
        // order (x0 y0, x1 y0, x0 y1, x1 y1); the first level from lane 0, the second
        // from lane 2.
        let rows_first = _mm_shuffle_epi32::<0b10_10_00_00>(_mm_unpacklo_epi64(r0, r1));
        let columns_first = _mm_shuffle_epi32::<0b01_00_01_00>(_mm_unpacklo_epi32(c0, c1));
        let rows_second = _mm_shuffle_epi32::<0b10_10_00_00>(_mm_unpackhi_epi64(r0, r1));
        let columns_second = _mm_shuffle_epi32::<0b01_00_01_00>(_mm_unpackhi_epi32(c0, c1));
        let mut texels = [[0u32; 4]; 2];
        _mm_storeu_si128(
            texels[0].as_mut_ptr().cast(),
            _mm_add_epi32(rows_first, columns_first),
        );
        _mm_storeu_si128(
            texels[1].as_mut_ptr().cast(),
            _mm_add_epi32(rows_second, columns_second),
        );
        texels
    }
}

/// [`blocked_pair_texels`] where there is no SSE2 (never reached: [`four_axes`] gives
/// nothing there).
#[cfg(not(target_arch = "x86_64"))]
fn blocked_pair_texels(i0: [i32; 4], i1: [i32; 4], strides: [u32; 2]) -> [[u32; 4]; 2] {
    let row = |y: i32, stride: u32| (y as u32 >> 2) * stride + (y as u32 & 3) * 4;
    let column = |x: i32| (x as u32 >> 2) * 16 + (x as u32 & 3);
    [0, 1].map(|level| {
        let (x, y, stride) = (2 * level, 2 * level + 1, strides[level]);
        let (r0, r1) = (row(i0[y], stride), row(i1[y], stride));
        let (c0, c1) = (column(i0[x]), column(i1[x]));
        [r0 + c0, r0 + c1, r1 + c0, r1 + c1]
    })
}

/// [`four_axes`] where there is no SSE2: no shortcut (each level alone).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn four_axes(_: Vec2, _: [u32; 4], _: [bool; 2]) -> Option<FourAxes> {
    None
}

/// Two levels' four axes in lanes (the first level's x and y, then the second's): each
/// lane's two texel indices, in `0..n`, and the weight of the second.
type FourAxes = ([i32; 4], [i32; 4], [f32; 4]);

/// Largest `|t * n|` the f32 shortcut takes (see the module note).
const F32_EXACT_BELOW: f32 = 8_388_608.0; // 2^23

/// [`axis_taps_in`] as the baseline copy computes it.
#[cfg(test)]
pub(super) fn axis_taps(t: f32, n: u32, mode: WrapMode) -> AxisTaps {
    axis_taps_in::<false>(t, n, mode)
}

/// `sample::axis_in(t, n, mode)`, through the f32 shortcut where it is exact, as the
/// kernels' copies compute it: the AVX2 copy (which has SSE4.1's rounding instructions)
/// takes floors in one instruction; the floors are exact either way, so every copy gives
/// the same bits.
#[inline(always)]
pub(super) fn axis_taps_in<const AVX2: bool>(t: f32, n: u32, mode: WrapMode) -> AxisTaps {
    if n.is_power_of_two() {
        let p = t * n as f32;
        if p.abs() >= 0.5 && p.abs() < F32_EXACT_BELOW {
            let (x0, frac) = floor_and_fraction_of_p_minus_half::<AVX2>(p);
            let last = n as i32 - 1;
            if mode == WrapMode::Repeat {
                // Two's complement: the mask is the Euclidean remainder for negative x0 too.
                let i0 = x0 & last;
                return (i0 as usize, ((i0 + 1) & last) as usize, frac);
            }
            if x0 >= 0 && x0 < last {
                return (x0 as usize, x0 as usize + 1, frac);
            }
        }
    }
    axis_in::<AVX2>(t, n, mode)
}

/// `floor(p - 0.5)` and `p - 0.5 - floor(p - 0.5)`, exactly, for `0.5 <= |p| < 2^23`.
///
/// Without branches or selects: which half of a texel `p` falls in is as good as random
/// from one lookup to the next, and a mispredicted branch costs more than the arithmetic
/// (the AVX2 copy compiled a select of `±0.5` into one). With `r = p - floor(p)`, the half
/// is `h = trunc(2 r)`; `floor(x) = floor(p) + h - 1` and the fraction is `(r - h) + 0.5`,
/// where `r - h` lies in `[-0.5, 0.5)` on `r`'s grid of `2^-24`, so both steps are exact.
/// `floor(p)` itself comes from a rounding instruction in the AVX2 copy, and from a
/// truncation corrected by one where it overshot in the baseline copy (which has no such
/// instruction: `f32::floor` would be a library call there).
#[inline(always)]
fn floor_and_fraction_of_p_minus_half<const AVX2: bool>(p: f32) -> (i32, f32) {
    let (floor, r) = if AVX2 {
        let floor = p.floor();
        // SAFETY: |p| < 2^23, so its floor fits an i32.
        (unsafe { floor.to_int_unchecked::<i32>() }, p - floor)
    } else {
        // SAFETY: |p| < 2^23, so the truncation fits an i32.
        let truncated = unsafe { p.to_int_unchecked::<i32>() };
        let floor = truncated - i32::from(truncated as f32 > p);
        (floor, p - floor as f32)
    };
    // SAFETY: 0 <= 2 r < 2.
    let h = unsafe { (r * 2.0).to_int_unchecked::<i32>() };
    (floor + h - 1, (r - h as f32) + 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::WrapMode;
    use glam::Vec4;

    /// Every wrap mode.
    const MODES: [WrapMode; 3] = [
        WrapMode::Repeat,
        WrapMode::ClampToEdge,
        WrapMode::MirroredRepeat,
    ];

    fn level(w: u32, h: u32) -> MipLevel {
        MipLevel::linear(w, h, vec![Vec4::ZERO; (w * h) as usize])
    }

    /// Coordinates at the image's edges and the shortcut's limits, with every fraction bit
    /// used.
    fn hard_coordinates(n: u32, seed: &mut u64) -> Vec<f32> {
        let n_f = n as f32;
        let mut out = Vec::new();
        for edge in [0.5, 1.0, 1.5, n_f - 1.5, n_f - 0.5, n_f - 1.0, n_f * 0.5] {
            let t = edge / n_f;
            out.extend([t, t.next_down(), t.next_up()]);
        }
        out.extend([0.0, -0.0, 1.0, -1e-30, 1e-30, 1e-8, 0.999_999_94, 1.0e-3]);
        // Tiled, far, at the shortcut's limits and past them, non-finite.
        let limit = F32_EXACT_BELOW / n_f;
        out.extend([3.3, -7.9, 1e4, -1e4, 1e6, limit, -limit, limit.next_down()]);
        out.extend([
            0.5 / n_f,
            -0.5 / n_f,
            (0.5 / n_f).next_down(),
            -(0.5 / n_f).next_up(),
        ]);
        out.extend([f32::NAN, f32::INFINITY, f32::MIN, f32::MAX]);
        // p just below a power of two, negative: p - 0.5 would need a 25th bit in f32.
        for k in 0..23 {
            let p = -(2.0f32.powi(k)).next_down();
            out.extend([p / n_f, (p - 0.5) / n_f]);
        }
        for _ in 0..2000 {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            // Uniform in [-0.25, 1.25), sometimes tiled further, then the lowest mantissa
            // bits set at random.
            let t = (*seed >> 40) as f32 / (1u64 << 24) as f32 * 1.5 - 0.25;
            let t = t * [1.0, 1.0, 16.0, 300.0][(*seed >> 20) as usize % 4];
            out.push(f32::from_bits(t.to_bits() ^ (*seed as u32 & 0x7f)));
        }
        out
    }

    #[test]
    fn shortcut_is_exactly_the_f64_axis() {
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut shortcut = 0;
        for n in [1u32, 2, 8, 512, 1024, 16384, 1044, 3, 1000] {
            for t in hard_coordinates(n, &mut seed) {
                for mode in MODES {
                    let want = axis(t, n, mode);
                    // Both copies' formulas (the floors by truncation and by rounding),
                    // bit for bit, the weight included.
                    for got in [axis_taps(t, n, mode), axis_taps_in::<true>(t, n, mode)] {
                        assert_eq!(
                            (got.0, got.1, got.2.to_bits()),
                            (want.0, want.1, want.2.to_bits()),
                            "t {t:e}, n {n}, {mode:?}"
                        );
                    }
                    let other = axis_in::<true>(t, n, mode);
                    assert_eq!(
                        (other.0, other.1, other.2.to_bits()),
                        (want.0, want.1, want.2.to_bits()),
                        "t {t:e}, n {n}, {mode:?}"
                    );
                    let p = t * n as f32;
                    shortcut += usize::from(
                        n.is_power_of_two() && p.abs() >= 0.5 && p.abs() < F32_EXACT_BELOW,
                    );
                }
            }
        }
        // The comparison covered the shortcut, not only the fallback.
        assert!(shortcut > 30_000, "{shortcut}");
    }

    /// Both axes of a level in f64 lanes: `axis`'s indices and weight bits on every lane
    /// they take, at the edge and random coordinates above, on sides of every kind (not
    /// powers of two, 1, the largest), under every pair of wrap modes; and they do take
    /// many.
    #[test]
    fn two_axes_are_exactly_the_f64_axis() {
        let mut seed = 0x5851_f42d_4c95_7f2d_u64;
        let (mut compared, mut taken) = (0, 0);
        for sides in [
            [1044, 1044],
            [522, 3],
            [1, 7],
            [1000, 16384],
            [12, 20],
            [1024, 333],
        ] {
            let mut us = hard_coordinates(sides[0], &mut seed);
            let vs = hard_coordinates(sides[1], &mut seed);
            // Around the lanes' limit `|t * n - 0.5| < 2^30`, on both sides of zero.
            for p in [
                TWO_AXES_BELOW - 4096.0,
                TWO_AXES_BELOW,
                TWO_AXES_BELOW + 4096.0,
            ] {
                let t = (p / f64::from(sides[0])) as f32;
                us.extend([
                    t,
                    t.next_down(),
                    t.next_up(),
                    -t,
                    -t.next_down(),
                    -t.next_up(),
                ]);
            }
            for (i, &u) in us.iter().enumerate() {
                let t = [u, vs[(i * 13) % vs.len()]];
                for wrap_s in MODES {
                    for wrap_t in MODES {
                        let mode = [wrap_s, wrap_t];
                        let repeat = mode.map(|m| m == WrapMode::Repeat);
                        compared += 1;
                        let Some(got) = two_axes(t, sides, repeat) else {
                            continue;
                        };
                        taken += 1;
                        for k in 0..2 {
                            let want = axis(t[k], sides[k], mode[k]);
                            assert_eq!(
                                (got[k].0, got[k].1, got[k].2.to_bits()),
                                (want.0, want.1, want.2.to_bits()),
                                "t {:e}, n {}, {:?}",
                                t[k],
                                sides[k],
                                mode[k]
                            );
                        }
                    }
                }
            }
        }
        // (Most pairs leave the image under Clamp or Mirror on an axis: those are `axis_in`'s.)
        #[cfg(target_arch = "x86_64")]
        assert!(taken > 20_000, "{taken} of {compared}");
        assert!(compared > 50_000, "{compared}");
    }

    #[test]
    fn taps_read_the_four_texels_around_the_point() {
        let level = level(8, 4);
        let sampler = Sampler::default();
        // Between texels (2, 1) and (3, 2), a quarter of the way in x, half in y.
        let taps = BilinearTaps::new(&level, Vec2::new(2.75 / 8.0, 2.0 / 4.0), sampler);
        assert_eq!(taps.texels, [8 + 2, 8 + 3, 16 + 2, 16 + 3]);
        assert_eq!((taps.fx, taps.fy), (0.25, 0.5));
        // Across the Repeat seam at u = 0: texels 7 and 0.
        let taps = BilinearTaps::new(&level, Vec2::new(0.0, 2.0 / 4.0), sampler);
        assert_eq!(taps.texels, [8 + 7, 8, 16 + 7, 16]);
        assert_eq!(taps.fx, 0.5);
    }

    /// The taps of a pair of levels, four axes at a time where they can be (f32 lanes, or in
    /// the AVX2 copy f64 lanes), are each level's own taps bit for bit, with both copies'
    /// formulas: on pairs of float levels of any sizes
    /// (powers of two or not, sides of 1), on consecutive 8-bit levels (blocked storage),
    /// at the edge and random coordinates above, under every pair of wrap modes.
    #[test]
    fn a_pair_of_levels_has_each_levels_own_taps() {
        let tables = crate::texture::decode::Srgb8Tables::get();
        let codes = |w: u32, h: u32| {
            let texels = (0..u64::from(w * h))
                .map(|i| {
                    let z = (i + 7).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                    tables.texel((z >> 32).to_le_bytes()[..4].try_into().unwrap())
                })
                .collect();
            crate::texture::MipPyramid::from_linear_rgba(w, h, texels).unwrap()
        };
        let eight_bit = [codes(64, 16), codes(8, 1024), codes(12, 20)];
        let mut pairs: Vec<[MipLevel; 2]> = eight_bit
            .iter()
            .flat_map(|p| p.levels.windows(2).map(|w| [w[0].clone(), w[1].clone()]))
            .collect();
        assert!(pairs.iter().all(|[a, b]| a.is_8bit() && b.is_8bit()));
        for ((w, h), (w2, h2)) in [
            ((1024, 512), (512, 256)),
            ((16, 16), (8, 8)),
            ((2, 1), (1, 1)),
            ((1, 1), (1, 1)),
            ((1044, 512), (522, 256)),
            ((16, 16), (3, 5)),
        ] {
            pairs.push([level(w, h), level(w2, h2)]);
        }
        let mut seed = 0x9d2c_5680_1b87_3a4f_u64;
        let avx2 = crate::simd::Isa::cpu_has_avx2();
        let (mut compared, mut four_at_once) = (0, 0);
        #[cfg_attr(not(target_arch = "x86_64"), allow(unused_mut))]
        let mut f64_at_once = 0;
        for [a, b] in &pairs {
            let us = hard_coordinates(a.width, &mut seed);
            let vs = hard_coordinates(a.height, &mut seed);
            for (i, &u) in us.iter().enumerate() {
                let uv = Vec2::new(u, vs[(i * 7) % vs.len()]);
                for wrap_s in MODES {
                    for wrap_t in MODES {
                        let sampler = Sampler {
                            wrap_s,
                            wrap_t,
                            ..Sampler::default()
                        };
                        // Each level alone, one axis at a time in f64.
                        let reference = |l: &MipLevel| {
                            BilinearTaps::of_axes(
                                l,
                                axis(uv.x, l.width, wrap_s),
                                axis(uv.y, l.height, wrap_t),
                            )
                        };
                        let alone = [reference(a), reference(b)];
                        // In range of the level's storage, which the renderer's filter
                        // relies on to read the texels without bounds checks.
                        for (l, t) in [a, b].into_iter().zip(alone) {
                            let len = l.storage_len();
                            assert!(t.texels.iter().all(|&i| (i as usize) < len), "{uv}");
                        }
                        let bits = |t: [BilinearTaps; 2]| {
                            t.map(|t| (t.texels, t.fx.to_bits(), t.fy.to_bits()))
                        };
                        for copy in [
                            [a, b].map(|l| BilinearTaps::new_in::<false>(l, uv, sampler)),
                            [a, b].map(|l| BilinearTaps::new_in::<true>(l, uv, sampler)),
                        ] {
                            assert_eq!(bits(copy), bits(alone), "{uv} {sampler:?}");
                        }
                        let pair = BilinearTaps::pair_in::<false>([a, b], uv, sampler);
                        assert_eq!(bits(pair), bits(alone), "{uv} {sampler:?}");
                        // The AVX2 copy's formula (it takes AVX) where the CPU has it.
                        if avx2 {
                            let pair = BilinearTaps::pair_in::<true>([a, b], uv, sampler);
                            assert_eq!(bits(pair), bits(alone), "{uv} {sampler:?}");
                        }
                        compared += 1;
                        let sides = [a.width, a.height, b.width, b.height];
                        let two_levels = [wrap_s, wrap_t].map(|m| m == WrapMode::Repeat);
                        let f32_lanes = sides.iter().all(|n| n.is_power_of_two())
                            && four_axes(uv, sides, two_levels).is_some();
                        four_at_once += usize::from(f32_lanes);
                        #[cfg(target_arch = "x86_64")]
                        if avx2 && !f32_lanes {
                            // SAFETY: the CPU has AVX2 (checked above).
                            let f64_lanes =
                                unsafe { four_axes_f64([uv.x, uv.y], sides, two_levels) };
                            f64_at_once += usize::from(f64_lanes.is_some());
                        }
                    }
                }
            }
        }
        // Both ways were compared: four axes at once (where x86-64 has them) and each level
        // alone.
        #[cfg(target_arch = "x86_64")]
        assert!(four_at_once > 20_000, "{four_at_once} of {compared}");
        assert!(
            compared - four_at_once > 20_000,
            "{four_at_once} of {compared}"
        );
        // And the AVX2 copy's f64 lanes for both levels, where the f32 ones do not apply.
        if avx2 {
            assert!(f64_at_once > 10_000, "{f64_at_once} of {compared}");
        } else {
            println!("no AVX2 on this CPU: the AVX2 copy's pair taps were not compared");
        }
    }

    #[test]
    fn f32_would_round_a_side_that_is_not_a_power_of_two() {
        // Why the shortcut keeps to powers of two: 0.3 * 1044 - 0.5 in f32 is not the exact
        // value f64 computes.
        let (t, n) = (0.3f32, 1044u32);
        let exact = f64::from(t) * f64::from(n) - 0.5;
        assert_ne!(f64::from(t * n as f32 - 0.5), exact);
        assert_eq!(
            axis_taps(t, n, WrapMode::Repeat).2,
            (exact - exact.floor()) as f32
        );
    }
}
