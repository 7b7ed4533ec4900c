//! Filtered lookup: wrap modes, bilinear within a level, trilinear across levels.
//!
//! Invariant: a lookup never allocates, never panics on a pyramid built by
//! [`MipPyramid::from_linear_rgba`], and never returns NaN for finite texels, whatever the
//! inputs: non-finite u or v is replaced by 0, a level past the last is clamped to the last,
//! and the LOD goes through [`MipPyramid::clamp_level`].
//!
//! Texel centres sit at `(i + 0.5) / w`. The continuous texel coordinate `u * w - 0.5` and
//! its floor are computed in f64: f32 has only 24 mantissa bits, so for `|u|` around 1e5 on
//! a 1024-wide level the product would lose the texel index and all of the fraction. Wrap
//! modes act on integer texel indices, per axis, after an exact f64 reduction to one period
//! so even huge coordinates never overflow the integer conversion. Lookups inside a level
//! (no wrap) take a shortcut that gives the same indices and weights bit for bit, in f32
//! where that is exact (`taps.rs`).
//!
//! Each public lookup is one `simd::Kernel`: the coordinates, the texel reads and the blends
//! are compiled into a baseline and an AVX2 copy of the same arithmetic (`fetch.rs`,
//! `taps.rs`; the AVX2 copy does some of it in wider lanes), so the two compute the same
//! bits.
//!
//! A bilinear or trilinear lookup can also be made in two steps: planned (its levels and
//! taps computed, and the cache asked for its texels) and, later, filtered
//! ([`MipPyramid::sample_planned`]). The renderer plans a hit's lookup when it makes the hit
//! and filters it after the hit's shadow rays are traced, so the texels' cache misses
//! overlap that work; the two steps compute exactly what the one-step lookup computes (it
//! is written as them).

use glam::{Vec2, Vec3A, Vec4};

use super::taps::BilinearTaps;
use super::{MipFilter, MipLevel, MipPyramid, Sampler, WrapMode, fetch};
use crate::simd::{Kernel, dispatch};

/// Largest `|texel index|` the integer Repeat path takes (exact in f64 and far from i64
/// overflow); beyond it the exact f64 reduction below is used.
const REPEAT_FAST_LIMIT: f64 = 1e15;

/// [`axis_in`] as the baseline copy computes it.
#[cfg(test)]
pub(super) fn axis(t: f32, n: u32, mode: WrapMode) -> (usize, usize, f32) {
    axis_in::<false>(t, n, mode)
}

/// The two texel indices (already wrapped into `0..n`) and the weight of the second one,
/// for a lookup at texture coordinate `t` along an axis of `n` texels, as the kernels'
/// copies compute them: the AVX2 copy (which has SSE4.1's rounding instructions) takes the
/// floor in one instruction instead of [`floor`]'s conversions. The floor is exact either
/// way, so both copies give the same bits.
#[inline(always)]
pub(super) fn axis_in<const AVX2: bool>(t: f32, n: u32, mode: WrapMode) -> (usize, usize, f32) {
    // Non-finite coordinates would poison the weights; 0 is an arbitrary but valid point.
    let t = if t.is_finite() { f64::from(t) } else { 0.0 };
    let n_f = f64::from(n);
    let x = t * n_f - 0.5;
    let x0 = if AVX2 { x.floor() } else { floor(x) };
    let frac = (x - x0) as f32;
    // Fast path: both texels inside the level (the common case, since UVs are rebased per
    // triangle near [0, 1]): no wrapping needed, and the result equals the wrapped one.
    if x0 >= 0.0 && x0 + 1.0 < n_f {
        let i0 = x0 as usize;
        return (i0, i0 + 1, frac);
    }
    // Repeat with a moderate coordinate (tiled floors reach u = 100 and more): one integer
    // remainder, a mask for power-of-two sizes, instead of an f64 `fmod` and two more.
    if mode == WrapMode::Repeat && x0.abs() < REPEAT_FAST_LIMIT {
        let (i, n) = (x0 as i64, i64::from(n));
        let i0 = if n & (n - 1) == 0 {
            // Two's complement: the mask is the Euclidean remainder for negative i too.
            i & (n - 1)
        } else {
            i.rem_euclid(n)
        };
        let i1 = if i0 + 1 == n { 0 } else { i0 + 1 };
        return (i0 as usize, i1 as usize, frac);
    }
    axis_reduced(x0, n, mode, frac)
}

/// `axis` for a huge coordinate, or one outside the image under Clamp or Mirror.
#[cold]
#[inline(never)]
fn axis_reduced(x0: f64, n: u32, mode: WrapMode, frac: f32) -> (usize, usize, f32) {
    let n_f = f64::from(n);
    // Reduce x0 to a small range with the same wrapped result before converting to an
    // integer: `rem_euclid` on f64 is exact, and the bounds keep `i0 + 1` in range too.
    let i0 = match mode {
        WrapMode::Repeat => x0.rem_euclid(n_f),
        WrapMode::MirroredRepeat => x0.rem_euclid(2.0 * n_f),
        WrapMode::ClampToEdge => x0.clamp(-1.0, n_f),
    } as i64;
    let n = i64::from(n);
    (wrap(i0, n, mode), wrap(i0 + 1, n, mode), frac)
}

/// `x.floor()` for a finite `x`, without the libm call the baseline x86-64 target makes for
/// it (no SSE4.1 `roundsd`): two per bilinear lookup showed as a call in every texture
/// sample. Below 2^52 the conversion through `i64` truncates exactly (the sign copied back
/// keeps -0.0 and the negative fractions' -0.0 as `floor` has them); from 2^52 on every
/// `f64` is an integer already.
#[inline(always)]
fn floor(x: f64) -> f64 {
    const INTEGERS_FROM: f64 = 4_503_599_627_370_496.0; // 2^52
    if x.abs() >= INTEGERS_FROM {
        return x;
    }
    let truncated = (x as i64 as f64).copysign(x);
    if truncated > x {
        truncated - 1.0
    } else {
        truncated
    }
}

/// Maps an integer texel index to `0..n` (glTF / OpenGL wrap semantics).
#[inline]
pub(super) fn wrap(i: i64, n: i64, mode: WrapMode) -> usize {
    (match mode {
        WrapMode::Repeat => i.rem_euclid(n),
        WrapMode::ClampToEdge => i.clamp(0, n - 1),
        WrapMode::MirroredRepeat => {
            // Period 2n: 0..n forwards, then n..2n backwards (texel n-1 repeated at the seam).
            let m = i.rem_euclid(2 * n);
            if m < n { m } else { 2 * n - 1 - m }
        }
    }) as usize
}

/// Trilinear lookup at `lod` (see [`MipPyramid::sample_trilinear`]).
#[inline(always)]
fn trilinear<const AVX2: bool>(pyramid: &MipPyramid, uv: Vec2, lod: f32, sampler: Sampler) -> Vec4 {
    let plan = plan_trilinear::<AVX2, false>(pyramid, uv, lod, sampler);
    // SAFETY: planned on `pyramid` just above.
    unsafe { filter_planned::<true, AVX2, false>(pyramid, &plan) }
}

/// Where a bilinear or trilinear lookup reads: its level (or two levels, blended by
/// `frac`) and the taps in each, computed by [`MipPyramid::plan_bilinear`] or
/// [`MipPyramid::plan_trilinear`] and filtered by [`MipPyramid::sample_planned`] with the
/// pyramid it was planned on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedLookup {
    /// The (lower) level.
    level: u32,
    /// Whether the next level is blended in (by `frac`).
    blend: bool,
    frac: f32,
    taps: [BilinearTaps; 2],
}

impl PlannedLookup {
    /// The level the lookup reads (the lower of two when it blends).
    #[inline(always)]
    pub fn level(&self) -> usize {
        self.level as usize
    }
}

/// The plan of a bilinear lookup in level `k` (in range), its texels hinted to the cache
/// when `PREFETCH` (see [`MipLevel::prefetch_texels`]).
#[inline(always)]
fn plan_bilinear<const AVX2: bool, const PREFETCH: bool>(
    pyramid: &MipPyramid,
    k: usize,
    uv: Vec2,
    sampler: Sampler,
) -> PlannedLookup {
    let level = &pyramid.levels[k];
    let taps = BilinearTaps::new_in::<AVX2>(level, uv, sampler);
    if PREFETCH {
        level.prefetch_texels(taps.texels);
    }
    PlannedLookup {
        level: k as u32,
        blend: false,
        frac: 0.0,
        taps: [taps; 2],
    }
}

/// The plan of a trilinear lookup at `lod`, its texels hinted to the cache when `PREFETCH`
/// (in the levels at hand, not looked up again).
#[inline(always)]
fn plan_trilinear<const AVX2: bool, const PREFETCH: bool>(
    pyramid: &MipPyramid,
    uv: Vec2,
    lod: f32,
    sampler: Sampler,
) -> PlannedLookup {
    if sampler.mip == MipFilter::Nearest {
        return plan_bilinear::<AVX2, PREFETCH>(pyramid, pyramid.nearest_level(lod), uv, sampler);
    }
    let (k, frac) = pyramid.clamp_and_split_level(lod);
    let levels = &pyramid.levels;
    if frac == 0.0 || k + 1 >= levels.len() {
        // Integer level (including 0, magnification, and the last level): no blend, so
        // integer LODs agree exactly with `sample_bilinear`.
        return plan_bilinear::<AVX2, PREFETCH>(pyramid, k, uv, sampler);
    }
    let (lower, upper) = (&levels[k], &levels[k + 1]);
    let taps = BilinearTaps::pair_in::<AVX2>([lower, upper], uv, sampler);
    if PREFETCH {
        lower.prefetch_texels(taps[0].texels);
        upper.prefetch_texels(taps[1].texels);
    }
    PlannedLookup {
        level: k as u32,
        blend: true,
        frac,
        taps,
    }
}

/// The lookup `plan` describes (an 8-bit level's alpha decoded only when `ALPHA`), its
/// level and texels read with bounds checks when `CHECKED` (see `fetch::texels`).
///
/// # Safety
/// Without `CHECKED`, `plan` must have been planned on `pyramid` (or on a pyramid of the
/// same level sizes and storage): then its levels exist and its taps are in range.
#[inline(always)]
unsafe fn filter_planned<const ALPHA: bool, const AVX2: bool, const CHECKED: bool>(
    pyramid: &MipPyramid,
    plan: &PlannedLookup,
) -> Vec4 {
    let k = plan.level as usize;
    let level = |i: usize| {
        if CHECKED {
            &pyramid.levels[i]
        } else {
            debug_assert!(i < pyramid.levels.len(), "level {i}");
            // SAFETY: the plan was made on this pyramid (the caller's promise), whose
            // level `k` it read (and `k + 1` when it blends).
            unsafe { pyramid.levels.get_unchecked(i) }
        }
    };
    // SAFETY (both): the taps were computed for these levels (the caller's promise), or
    // `CHECKED` reads them with checks.
    if !plan.blend {
        return unsafe { fetch::bilinear::<ALPHA, CHECKED>(level(k), &plan.taps[0]) };
    }
    unsafe {
        fetch::trilinear::<ALPHA, AVX2, CHECKED>([level(k), level(k + 1)], &plan.taps, plan.frac)
    }
}

/// [`MipPyramid::sample_bilinear`] as a kernel.
struct Bilinear<'a> {
    level: &'a MipLevel,
    uv: Vec2,
    sampler: Sampler,
}

impl Kernel for Bilinear<'_> {
    type Output = Vec4;
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> Vec4 {
        let taps = BilinearTaps::new_in::<AVX2>(self.level, self.uv, self.sampler);
        // SAFETY: the taps were computed for this level just above.
        unsafe { fetch::bilinear::<true, false>(self.level, &taps) }
    }
}

/// [`MipPyramid::plan_bilinear`] as a kernel (the level in range).
struct PlanBilinear<'a> {
    pyramid: &'a MipPyramid,
    level: usize,
    uv: Vec2,
    sampler: Sampler,
}

impl Kernel for PlanBilinear<'_> {
    type Output = PlannedLookup;
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> PlannedLookup {
        plan_bilinear::<AVX2, true>(self.pyramid, self.level, self.uv, self.sampler)
    }
}

/// [`MipPyramid::plan_trilinear`] as a kernel.
struct PlanTrilinear<'a> {
    pyramid: &'a MipPyramid,
    uv: Vec2,
    lod: f32,
    sampler: Sampler,
}

impl Kernel for PlanTrilinear<'_> {
    type Output = PlannedLookup;
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> PlannedLookup {
        plan_trilinear::<AVX2, true>(self.pyramid, self.uv, self.lod, self.sampler)
    }
}

/// [`MipPyramid::sample_planned`] as a kernel, or [`MipPyramid::sample_planned_colour`]
/// without `ALPHA` (its alpha lane then meaningless).
struct Planned<'a, const ALPHA: bool> {
    pyramid: &'a MipPyramid,
    plan: &'a PlannedLookup,
}

impl<const ALPHA: bool> Kernel for Planned<'_, ALPHA> {
    type Output = Vec4;
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> Vec4 {
        // SAFETY: `CHECKED` (the plan comes from the caller, made on any pyramid).
        unsafe { filter_planned::<ALPHA, AVX2, true>(self.pyramid, self.plan) }
    }
}

/// [`MipPyramid::sample_trilinear`] as a kernel.
struct Trilinear<'a> {
    pyramid: &'a MipPyramid,
    uv: Vec2,
    lod: f32,
    sampler: Sampler,
}

impl Kernel for Trilinear<'_> {
    type Output = Vec4;
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> Vec4 {
        trilinear::<AVX2>(self.pyramid, self.uv, self.lod, self.sampler)
    }
}

/// [`MipPyramid::sample_anisotropic`] with more than one tap, as a kernel: `taps`
/// trilinear lookups at `first + step * i`, averaged.
struct Anisotropic<'a> {
    pyramid: &'a MipPyramid,
    first: Vec2,
    step: Vec2,
    taps: u32,
    lod: f32,
    sampler: Sampler,
}

impl Kernel for Anisotropic<'_> {
    type Output = Vec4;
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> Vec4 {
        let sum = (0..self.taps).fold(Vec4::ZERO, |sum, i| {
            let uv = self.first + self.step * i as f32;
            sum + trilinear::<AVX2>(self.pyramid, uv, self.lod, self.sampler)
        });
        sum / self.taps as f32
    }
}

impl MipPyramid {
    /// Bilinear lookup in one level; `level` past the last is clamped to the last.
    ///
    /// Wrap modes apply per axis to integer texel indices. Non-finite u or v reads as 0.
    pub fn sample_bilinear(&self, level: usize, uv: Vec2, sampler: Sampler) -> Vec4 {
        let level = &self.levels[level.min(self.levels.len() - 1)];
        dispatch(Bilinear { level, uv, sampler })
    }

    /// Trilinear lookup at a fractional level (clamped with [`Self::clamp_level`]).
    ///
    /// Level 0 or below is magnification: plain bilinear at level 0. Otherwise the bilinear
    /// results of `floor(lod)` and `floor(lod) + 1` are blended by the fraction; at the last
    /// level it is bilinear there. With [`MipFilter::Nearest`] it is bilinear in the level
    /// [`Self::nearest_level`] gives.
    pub fn sample_trilinear(&self, uv: Vec2, lod: f32, sampler: Sampler) -> Vec4 {
        dispatch(Trilinear {
            pyramid: self,
            uv,
            lod,
            sampler,
        })
    }

    /// Where [`Self::sample_bilinear`] with the same arguments reads, planned now and
    /// filtered later by [`Self::sample_planned`] (the same bits), with a hint to the cache
    /// to start loading those texels.
    ///
    /// Why: a renderer that knows a lookup long before it needs the result (a hit's texture,
    /// needed only once the hit's shadow rays are traced) plans it first, so the texels'
    /// cache misses overlap the work in between instead of stalling the lookup, and the
    /// coordinates are computed once.
    ///
    /// Planned in the kernels' SIMD copy: a plan is mostly floors and conversions, which the
    /// AVX2 copy's rounding instructions shorten (the same bits in every copy).
    pub fn plan_bilinear(&self, level: usize, uv: Vec2, sampler: Sampler) -> PlannedLookup {
        dispatch(self.plan_bilinear_kernel(level, uv, sampler))
    }

    /// [`Self::plan_bilinear`] in the SIMD copy `AVX2` names, for a kernel that runs in that
    /// copy already (`AVX2` true only there, as in [`Kernel::run`]).
    ///
    /// Why: the tile kernel (`render::tile::TraceTile`) plans a lookup per textured hit;
    /// through [`dispatch`] each plan was a call out of the tile's copy, its arguments and
    /// result passed through memory and the caller's registers saved around it.
    #[inline(always)]
    pub(crate) fn plan_bilinear_in<const AVX2: bool>(
        &self,
        level: usize,
        uv: Vec2,
        sampler: Sampler,
    ) -> PlannedLookup {
        self.plan_bilinear_kernel(level, uv, sampler).run::<AVX2>()
    }

    #[inline(always)]
    fn plan_bilinear_kernel(&self, level: usize, uv: Vec2, sampler: Sampler) -> PlanBilinear<'_> {
        PlanBilinear {
            pyramid: self,
            level: level.min(self.levels.len() - 1),
            uv,
            sampler,
        }
    }

    /// [`Self::plan_bilinear`] for [`Self::sample_trilinear`] (one level or two, chosen as
    /// the lookup chooses them).
    pub fn plan_trilinear(&self, uv: Vec2, lod: f32, sampler: Sampler) -> PlannedLookup {
        dispatch(self.plan_trilinear_kernel(uv, lod, sampler))
    }

    /// [`Self::plan_trilinear`] in the SIMD copy `AVX2` names (as
    /// [`Self::plan_bilinear_in`]).
    #[inline(always)]
    pub(crate) fn plan_trilinear_in<const AVX2: bool>(
        &self,
        uv: Vec2,
        lod: f32,
        sampler: Sampler,
    ) -> PlannedLookup {
        self.plan_trilinear_kernel(uv, lod, sampler).run::<AVX2>()
    }

    #[inline(always)]
    fn plan_trilinear_kernel(&self, uv: Vec2, lod: f32, sampler: Sampler) -> PlanTrilinear<'_> {
        PlanTrilinear {
            pyramid: self,
            uv,
            lod,
            sampler,
        }
    }

    /// The lookup `plan` describes (planned on this pyramid): bit for bit what the
    /// `sample_*` call it was planned for returns.
    ///
    /// # Panics
    /// If `plan` names a level this pyramid does not have (planned on another pyramid).
    pub fn sample_planned(&self, plan: &PlannedLookup) -> Vec4 {
        dispatch(Planned::<true> {
            pyramid: self,
            plan,
        })
    }

    /// The colour of [`Self::sample_planned`] (its first three channels, the same bits),
    /// for a caller that has no use for alpha: an 8-bit image's alpha codes are not
    /// decoded, one table read fewer a texel.
    ///
    /// # Panics
    /// As [`Self::sample_planned`].
    pub fn sample_planned_colour(&self, plan: &PlannedLookup) -> Vec3A {
        Vec3A::from_vec4(dispatch(Planned::<false> {
            pyramid: self,
            plan,
        }))
    }

    /// [`Self::sample_planned_colour`] in the SIMD copy `AVX2` names (as
    /// [`Self::plan_bilinear_in`]), its texels read without bounds checks: the renderer's
    /// form, which plans and filters every lookup on the same pyramid (the checks could only
    /// pass, and cost eight instructions a level).
    ///
    /// # Safety
    /// `plan` must have been planned on this pyramid.
    #[inline(always)]
    pub(crate) unsafe fn sample_planned_colour_in<const AVX2: bool>(
        &self,
        plan: &PlannedLookup,
    ) -> Vec3A {
        // SAFETY: the caller's promise.
        Vec3A::from_vec4(unsafe { filter_planned::<false, AVX2, false>(self, plan) })
    }

    /// Anisotropic lookup: the mean of `taps` trilinear lookups at `lod`, placed at the
    /// centres of `taps` equal segments of `axis` (a texture-coordinate offset spanning the
    /// footprint's major axis, centred on `uv`). One tap is plain trilinear.
    pub fn sample_anisotropic(
        &self,
        uv: Vec2,
        lod: f32,
        axis: Vec2,
        taps: u32,
        sampler: Sampler,
    ) -> Vec4 {
        let taps = taps.max(1);
        if taps == 1 || !axis.is_finite() {
            return self.sample_trilinear(uv, lod, sampler);
        }
        let step = axis / taps as f32;
        dispatch(Anisotropic {
            pyramid: self,
            first: uv - axis * 0.5 + step * 0.5,
            step,
            taps,
            lod,
            sampler,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CLAMP: WrapMode = WrapMode::ClampToEdge;
    const REPEAT: WrapMode = WrapMode::Repeat;
    const MIRROR: WrapMode = WrapMode::MirroredRepeat;

    fn sampler(s: WrapMode, t: WrapMode) -> Sampler {
        Sampler {
            wrap_s: s,
            wrap_t: t,
            ..Sampler::default()
        }
    }

    /// A w x h pyramid whose level-0 texel (x, y) is distinct: (x, y, x + 100 y, 1).
    fn grid(w: u32, h: u32) -> MipPyramid {
        let texels = (0..h)
            .flat_map(|y| {
                (0..w).map(move |x| Vec4::new(x as f32, y as f32, (x + 100 * y) as f32, 1.0))
            })
            .collect();
        MipPyramid::from_linear_rgba(w, h, texels).unwrap()
    }

    fn texel(p: &MipPyramid, level: usize, x: u32, y: u32) -> Vec4 {
        let l = &p.levels[level];
        l.texel((y * l.width + x) as usize)
    }

    fn centre(p: &MipPyramid, level: usize, x: u32, y: u32) -> Vec2 {
        let l = &p.levels[level];
        Vec2::new(
            (x as f32 + 0.5) / l.width as f32,
            (y as f32 + 0.5) / l.height as f32,
        )
    }

    fn close(a: Vec4, b: Vec4, tol: f32) -> bool {
        (a - b).abs().max_element() <= tol
    }

    #[test]
    fn bilinear_at_texel_centre_is_exact() {
        // Power-of-two sides: every centre (i + 0.5) / w is an exact f32, so the weights are
        // exactly 1 and 0 and the texel comes back bit-for-bit.
        let p = grid(8, 4);
        for level in 0..p.level_count() {
            let l = &p.levels[level];
            for y in 0..l.height {
                for x in 0..l.width {
                    for s in [REPEAT, CLAMP, MIRROR] {
                        let got = p.sample_bilinear(level, centre(&p, level, x, y), sampler(s, s));
                        assert_eq!(got, texel(&p, level, x, y), "level {level} ({x}, {y})");
                    }
                }
            }
        }
        // Other sides: the centre itself is rounded to f32 (0.5 / 5 is not exact), so the
        // result is the texel up to that rounding.
        let p = grid(5, 3);
        for y in 0..3 {
            for x in 0..5 {
                let got = p.sample_bilinear(0, centre(&p, 0, x, y), Sampler::default());
                let want = texel(&p, 0, x, y);
                assert!(close(got, want, 1e-4), "({x}, {y}): {got} vs {want}");
            }
        }
    }

    #[test]
    fn bilinear_halfway_is_average() {
        let p = grid(4, 4);
        let s = Sampler::default();
        // Between texels (1, 2) and (2, 2) horizontally.
        let got = p.sample_bilinear(0, Vec2::new(2.0 / 4.0, 2.5 / 4.0), s);
        let want = (texel(&p, 0, 1, 2) + texel(&p, 0, 2, 2)) * 0.5;
        assert!(close(got, want, 1e-6), "{got} vs {want}");
        // Between (3, 1) and (3, 2) vertically.
        let got = p.sample_bilinear(0, Vec2::new(3.5 / 4.0, 2.0 / 4.0), s);
        let want = (texel(&p, 0, 3, 1) + texel(&p, 0, 3, 2)) * 0.5;
        assert!(close(got, want, 1e-6), "{got} vs {want}");
        // Centre of four texels.
        let got = p.sample_bilinear(0, Vec2::new(1.0 / 4.0, 1.0 / 4.0), s);
        let want =
            (texel(&p, 0, 0, 0) + texel(&p, 0, 1, 0) + texel(&p, 0, 0, 1) + texel(&p, 0, 1, 1))
                * 0.25;
        assert!(close(got, want, 1e-6), "{got} vs {want}");
        // Repeat across the seam: u = 0 lies halfway between the last and first texel.
        let got = p.sample_bilinear(0, Vec2::new(0.0, 0.5 / 4.0), s);
        let want = (texel(&p, 0, 3, 0) + texel(&p, 0, 0, 0)) * 0.5;
        assert!(close(got, want, 1e-6), "{got} vs {want}");
    }

    #[test]
    fn wrap_repeat() {
        let p = grid(8, 8);
        let s = sampler(REPEAT, REPEAT);
        for v in [0.1, 0.3, 0.77] {
            let base = p.sample_bilinear(0, Vec2::new(0.25, v), s);
            assert_eq!(p.sample_bilinear(0, Vec2::new(1.25, v), s), base);
            assert_eq!(p.sample_bilinear(0, Vec2::new(-0.75, v), s), base);
            assert_eq!(p.sample_bilinear(0, Vec2::new(3.25, v), s), base);
        }
    }

    #[test]
    fn wrap_mirrored_repeat() {
        let p = grid(8, 8);
        let s = sampler(MIRROR, MIRROR);
        let v = 0.3;
        let at = |u: f32| p.sample_bilinear(0, Vec2::new(u, v), s);
        assert_eq!(at(1.25), at(0.75));
        assert_eq!(at(-0.25), at(0.25));
        assert_eq!(at(2.25), at(0.25));
        assert_eq!(at(-1.25), at(0.75));
        // At the seam u = 1 the last texel is mirrored onto itself.
        let edge = p.sample_bilinear(0, Vec2::new(1.0, 0.5 / 8.0), s);
        assert_eq!(edge, texel(&p, 0, 7, 0));
        // Mirroring differs from repeating.
        assert_ne!(at(1.25), at(0.25));
    }

    #[test]
    fn wrap_clamp_to_edge() {
        let p = grid(8, 4);
        let s = sampler(CLAMP, CLAMP);
        let row = 1;
        let v = (row as f32 + 0.5) / 4.0;
        assert_eq!(
            p.sample_bilinear(0, Vec2::new(5.0, v), s),
            texel(&p, 0, 7, row)
        );
        assert_eq!(
            p.sample_bilinear(0, Vec2::new(-3.0, v), s),
            texel(&p, 0, 0, row)
        );
        // Within half a texel of the edge there is nothing to blend with.
        assert_eq!(
            p.sample_bilinear(0, Vec2::new(1.0, v), s),
            texel(&p, 0, 7, row)
        );
        assert_eq!(
            p.sample_bilinear(0, Vec2::new(0.0, v), s),
            texel(&p, 0, 0, row)
        );
        assert_eq!(
            p.sample_bilinear(0, Vec2::new(-1e30, 1e30), s),
            texel(&p, 0, 0, 3)
        );
    }

    #[test]
    fn wrap_modes_are_per_axis() {
        let p = grid(8, 4);
        // s repeats, t clamps.
        let s = sampler(REPEAT, CLAMP);
        let got = p.sample_bilinear(0, Vec2::new(1.25, 5.0), s);
        let want = p.sample_bilinear(0, Vec2::new(0.25, 3.5 / 4.0), s);
        assert_eq!(got, want);
        assert_ne!(got, p.sample_bilinear(0, Vec2::new(0.25, 0.25), s));
        // s clamps, t mirrors.
        let s = sampler(CLAMP, MIRROR);
        let got = p.sample_bilinear(0, Vec2::new(-3.0, 1.25), s);
        let want = p.sample_bilinear(0, Vec2::new(0.5 / 8.0, 0.75), s);
        assert_eq!(got, want);
        // s mirrors, t repeats.
        let s = sampler(MIRROR, REPEAT);
        let got = p.sample_bilinear(0, Vec2::new(-0.25, 1.3125), s);
        let want = p.sample_bilinear(0, Vec2::new(0.25, 0.3125), s);
        assert_eq!(got, want);
    }

    #[test]
    fn level_past_last_is_clamped() {
        let p = grid(8, 8);
        let last = p.level_count() - 1;
        let uv = Vec2::new(0.3, 0.6);
        let s = Sampler::default();
        assert_eq!(p.sample_bilinear(99, uv, s), p.sample_bilinear(last, uv, s));
        assert_eq!(p.sample_bilinear(usize::MAX, uv, s), texel(&p, last, 0, 0));
    }

    #[test]
    fn non_finite_uv_reads_as_zero() {
        let p = grid(8, 8);
        for mode in [REPEAT, CLAMP, MIRROR] {
            let s = sampler(mode, mode);
            let zero = p.sample_bilinear(0, Vec2::ZERO, s);
            for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
                let got = p.sample_bilinear(0, Vec2::new(bad, bad), s);
                assert!(!got.is_nan());
                assert_eq!(got, zero);
                let got = p.sample_trilinear(Vec2::new(0.0, bad), 1.5, s);
                assert!(!got.is_nan());
            }
            // Huge but finite coordinates stay finite too.
            for big in [f32::MAX, f32::MIN, 1e20, -1e20] {
                let got = p.sample_bilinear(0, Vec2::new(big, -big), s);
                assert!(got.is_finite(), "{mode:?} {big}: {got}");
            }
        }
    }

    #[test]
    fn large_u_keeps_precision() {
        // 1024 x 2 with distinct texels along u; Repeat.
        let w = 1024;
        let texels = (0..2 * w)
            .map(|i| Vec4::new((i % w) as f32, (i / w) as f32, 0.0, 1.0))
            .collect();
        let p = MipPyramid::from_linear_rgba(w, 2, texels).unwrap();
        let s = Sampler::default();
        // 100000.37 is not an f32: the nearest is 100000.3671875, whose fractional part
        // 0.3671875 is exact. In f32, u * 1024 - 0.5 would round to an integer and read a
        // single texel; in f64 it is 375.5, halfway between texels 375 and 376.
        let big: f32 = 100000.37;
        let frac = (f64::from(big) - 100000.0) as f32;
        assert_eq!(frac, 0.3671875);
        let v = 0.25;
        let far = p.sample_bilinear(0, Vec2::new(big, v), s);
        let near = p.sample_bilinear(0, Vec2::new(frac, v), s);
        assert!(close(far, near, 1e-4), "{far} vs {near}");
        assert!((far.x - 375.5).abs() < 1e-4, "{far}");
        // Negative side: -100000 + 0.3671875 (exact in f32) is the same point mod 1.
        let far = p.sample_bilinear(0, Vec2::new(-100_000.0 + 0.367_187_5, v), s);
        assert!(close(far, near, 1e-4), "{far} vs {near}");
        // A fraction that is not one half: 1000.3 is 1000 + 4915/16384 in f32, so
        // u * 1024 - 0.5 = 306.6875 (weights 0.3125 / 0.6875).
        let big: f32 = 1000.3;
        let frac = (f64::from(big) - 1000.0) as f32;
        let far = p.sample_bilinear(0, Vec2::new(big, v), s);
        let near = p.sample_bilinear(0, Vec2::new(frac, v), s);
        assert!(close(far, near, 1e-4), "{far} vs {near}");
        assert!((far.x - 306.6875).abs() < 1e-4, "{far}");
    }

    #[test]
    fn trilinear_integer_levels_match_bilinear() {
        let p = grid(16, 12);
        let s = sampler(REPEAT, MIRROR);
        for uv in [
            Vec2::new(0.3, 0.7),
            Vec2::new(-1.2, 2.45),
            Vec2::new(0.01, 0.99),
        ] {
            for k in 0..p.level_count() {
                assert_eq!(
                    p.sample_trilinear(uv, k as f32, s),
                    p.sample_bilinear(k, uv, s),
                    "level {k}"
                );
            }
        }
    }

    #[test]
    fn trilinear_lod_clamping() {
        let p = grid(16, 12);
        let s = Sampler::default();
        let uv = Vec2::new(0.37, 0.61);
        let last = p.level_count() - 1;
        let level0 = p.sample_bilinear(0, uv, s);
        assert_eq!(p.sample_trilinear(uv, f32::NAN, s), level0);
        assert_eq!(p.sample_trilinear(uv, -5.0, s), level0);
        assert_eq!(p.sample_trilinear(uv, f32::NEG_INFINITY, s), level0);
        assert_eq!(p.sample_trilinear(uv, 0.0, s), level0);
        let top = p.sample_bilinear(last, uv, s);
        assert_eq!(p.sample_trilinear(uv, f32::INFINITY, s), top);
        assert_eq!(p.sample_trilinear(uv, 1e9, s), top);
        assert_eq!(p.sample_trilinear(uv, last as f32 + 0.5, s), top);
        assert_eq!(p.clamp_level(f32::NAN), 0.0);
        assert_eq!(p.clamp_level(f32::INFINITY), last as f32);
        assert_eq!(p.clamp_level(-3.0), 0.0);
        assert_eq!(p.clamp_level(1.25), 1.25);
        // Clamped and split in one step (the plans' way, one conversion without
        // saturation): the split of the clamped level, bit for bit, everywhere.
        let lasts = [
            last as f32,
            (last as f32).next_down(),
            (last as f32).next_up(),
        ];
        for lod in [
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            0.0,
        ]
        .into_iter()
        .chain([
            f32::MIN_POSITIVE,
            1e-30,
            0.5,
            1.0,
            1.0f32.next_down(),
            2.75,
            1e9,
            -1e9,
        ])
        .chain(lasts)
        {
            let (k, frac) = p.clamp_and_split_level(lod);
            let (want_k, want_frac) = MipPyramid::split_level(p.clamp_level(lod));
            assert_eq!((k, frac.to_bits()), (want_k, want_frac.to_bits()), "{lod}");
            assert!(k <= last && (0.0..1.0).contains(&frac), "{lod}");
        }
    }

    #[test]
    fn trilinear_blends_adjacent_levels() {
        let p = grid(16, 12);
        let s = Sampler::default();
        let uv = Vec2::new(0.37, 0.61);
        let l1 = p.sample_bilinear(1, uv, s);
        let l2 = p.sample_bilinear(2, uv, s);
        assert_ne!(l1, l2);
        let got = p.sample_trilinear(uv, 1.5, s);
        assert!(close(got, (l1 + l2) * 0.5, 1e-5), "{got}");
        let got = p.sample_trilinear(uv, 1.25, s);
        assert!(close(got, l1 * 0.75 + l2 * 0.25, 1e-5), "{got}");
        // Between level 0 and 1 it blends too (only lod <= 0 is pure magnification).
        let l0 = p.sample_bilinear(0, uv, s);
        let got = p.sample_trilinear(uv, 0.5, s);
        assert!(close(got, (l0 + l1) * 0.5, 1e-5), "{got}");
    }

    /// `MipFilter::Nearest` reads one level, the nearest (ties to the finer, OpenGL's
    /// rule), as `sample_bilinear` there; the planned form too, and every level a lookup
    /// can ask for (magnified, NaN, past the last) stays in the pyramid.
    #[test]
    fn nearest_mip_filter_reads_the_nearest_level_alone() {
        let p = grid(16, 12);
        let last = p.level_count() - 1;
        let s = Sampler {
            mip: MipFilter::Nearest,
            ..sampler(REPEAT, MIRROR)
        };
        let uv = Vec2::new(0.37, 0.61);
        let cases = [
            (f32::NAN, 0),
            (f32::NEG_INFINITY, 0),
            (-3.0, 0),
            (0.0, 0),
            (0.5, 0),
            (0.5f32.next_up(), 1),
            (1.0, 1),
            (1.25, 1),
            (1.5, 1),
            (1.75, 2),
            (last as f32 - 0.25, last),
            (last as f32 + 0.75, last),
            (f32::INFINITY, last),
        ];
        for (lod, level) in cases {
            assert_eq!(p.nearest_level(lod), level, "{lod}");
            let want = p.sample_bilinear(level, uv, s);
            assert!(same_bits(p.sample_trilinear(uv, lod, s), want), "{lod}");
            let plan = p.plan_trilinear(uv, lod, s);
            assert_eq!(plan.level(), level, "{lod}");
            assert_eq!(p.level_read(lod, MipFilter::Nearest), level, "{lod}");
            let linear = Sampler {
                mip: MipFilter::Linear,
                ..s
            };
            let blended_plan = p.plan_trilinear(uv, lod, linear);
            assert_eq!(
                p.level_read(lod, MipFilter::Linear),
                blended_plan.level(),
                "{lod}"
            );
            assert!(same_bits(p.sample_planned(&plan), want), "{lod}");
        }
        // The default is trilinear: between two levels the two filters differ.
        let linear = Sampler {
            mip: MipFilter::Linear,
            ..s
        };
        assert_ne!(
            p.sample_trilinear(uv, 1.25, linear),
            p.sample_trilinear(uv, 1.25, s)
        );
        assert_eq!(Sampler::default().mip, MipFilter::Linear);
    }

    #[test]
    fn anisotropic_averages_taps_along_the_axis() {
        let p = grid(16, 16);
        let s = Sampler::default();
        let uv = Vec2::new(0.5, 0.5);
        // Level 0 holds x in the red channel: taps across 8 texels along u average to the
        // centre's x, while the spread along v leaves red unchanged.
        let axis = Vec2::new(8.0 / 16.0, 0.0);
        let one = p.sample_trilinear(uv, 0.0, s);
        let four = p.sample_anisotropic(uv, 0.0, axis, 4, s);
        assert!(close(four, one, 1e-5), "{four} vs {one}");
        let taps: Vec<Vec4> = [-3.0f32, -1.0, 1.0, 3.0]
            .iter()
            .map(|o| p.sample_trilinear(uv + Vec2::new(o / 16.0, 0.0), 0.0, s))
            .collect();
        let mean = taps.iter().fold(Vec4::ZERO, |a, &b| a + b) / 4.0;
        assert!(close(four, mean, 1e-5));
        // One tap, or a non-finite axis, is plain trilinear.
        assert_eq!(
            p.sample_anisotropic(uv, 1.5, axis, 1, s),
            p.sample_trilinear(uv, 1.5, s)
        );
        let nan = Vec2::new(f32::NAN, 0.0);
        assert_eq!(
            p.sample_anisotropic(uv, 1.5, nan, 8, s),
            p.sample_trilinear(uv, 1.5, s)
        );
    }

    #[test]
    fn floor_matches_the_library_floor() {
        let mut x: u64 = 0x2545_f491_4f6c_dd1d;
        let mut values = vec![
            0.0,
            -0.0,
            -0.25,
            0.5,
            -0.5,
            1.0,
            -1.0,
            -1e-300,
            1e-300,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            4_503_599_627_370_496.0,
            -4_503_599_627_370_497.0,
            1e20,
            -1e20,
            f64::MAX,
            f64::MIN,
        ];
        for _ in 0..10_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            // Random bit patterns cover every exponent; keep the finite ones.
            let v = f64::from_bits(x);
            if v.is_finite() {
                values.push(v);
                values.push(v.fract() * 1e3);
            }
        }
        for v in values {
            assert_eq!(floor(v).to_bits(), v.floor().to_bits(), "{v:e}");
        }
    }

    /// `axis` against the library's `floor` and `wrap`, for every side from 1 to 70 and a
    /// few large ones (powers of two and not), coordinates around the image and its texel
    /// edges, every wrap mode: most of them inside the level (the fast path).
    #[test]
    fn axis_matches_the_library_floor_and_wrap() {
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut shortcut = 0;
        let sides: Vec<u32> = (1..=70)
            .chain([261, 522, 1024, 1044, 16383, 16384])
            .collect();
        for n in sides {
            let mut ts: Vec<f32> = Vec::new();
            for i in 0..=2 * n + 2 {
                // Texel edges and centres, and their neighbouring floats.
                let t = (i as f32 * 0.5 - 0.5) / n as f32;
                ts.extend([t, t.next_up(), t.next_down()]);
            }
            for _ in 0..200 {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                ts.push((x >> 40) as f32 / (1u64 << 24) as f32 * 1.4 - 0.2);
            }
            for t in ts {
                for mode in [REPEAT, WrapMode::ClampToEdge, WrapMode::MirroredRepeat] {
                    let exact = f64::from(t) * f64::from(n) - 0.5;
                    let x0 = exact.floor();
                    let i0 = x0 as i64;
                    let expected = (
                        wrap(i0, i64::from(n), mode),
                        wrap(i0 + 1, i64::from(n), mode),
                        (exact - x0) as f32,
                    );
                    let got = axis(t, n, mode);
                    assert_eq!(
                        (got.0, got.1, got.2.to_bits()),
                        (expected.0, expected.1, expected.2.to_bits()),
                        "t {t:e}, n {n}, {mode:?}"
                    );
                    shortcut += usize::from(exact >= 0.0 && exact < f64::from(n) - 1.0);
                }
            }
        }
        assert!(shortcut > 50_000, "{shortcut}");
    }

    #[test]
    fn repeat_fast_path_matches_the_exact_reduction() {
        for n in [1u32, 2, 3, 7, 8, 1000, 1024] {
            for t in [
                -100_000.37f32,
                -3.2,
                -0.001,
                0.0,
                0.999,
                1.5,
                123.456,
                99_999.9,
                3.0e6,
            ] {
                let x = f64::from(t) * f64::from(n) - 0.5;
                let x0 = x.floor();
                let i0 = x0.rem_euclid(f64::from(n)) as usize;
                let expected = (i0, (i0 + 1) % n as usize, (x - x0) as f32);
                assert_eq!(axis(t, n, REPEAT), expected, "t {t}, n {n}");
            }
        }
    }

    /// The lookup as a plain scalar formula, independent of `taps.rs` and `fetch.rs`: the
    /// texel coordinate in f64 (`axis`), texels through `MipLevel::texel`.
    fn reference_bilinear(level: &MipLevel, uv: Vec2, sampler: Sampler) -> Vec4 {
        let (x0, x1, fx) = axis(uv.x, level.width, sampler.wrap_s);
        let (y0, y1, fy) = axis(uv.y, level.height, sampler.wrap_t);
        let t = |x: usize, y: usize| level.texel(y * level.width as usize + x);
        let row0 = t(x0, y0) * (1.0 - fx) + t(x1, y0) * fx;
        let row1 = t(x0, y1) * (1.0 - fx) + t(x1, y1) * fx;
        row0 * (1.0 - fy) + row1 * fy
    }

    fn reference_trilinear(p: &MipPyramid, uv: Vec2, lod: f32, sampler: Sampler) -> Vec4 {
        let lod = p.clamp_level(lod);
        let lower = lod.floor();
        let (k, frac) = (lower as usize, lod - lower);
        let a = reference_bilinear(&p.levels[k], uv, sampler);
        if frac == 0.0 || k + 1 >= p.levels.len() {
            return a;
        }
        let b = reference_bilinear(&p.levels[k + 1], uv, sampler);
        a * (1.0 - frac) + b * frac
    }

    /// A pyramid of an 8-bit sRGB image with varied codes in every channel.
    fn codes_pyramid(w: u32, h: u32, seed: u64) -> MipPyramid {
        let tables = super::super::decode::Srgb8Tables::get();
        let texels = (0..u64::from(w * h))
            .map(|i| {
                let z = (i + seed).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                tables.texel((z >> 32).to_le_bytes()[..4].try_into().unwrap())
            })
            .collect();
        let p = MipPyramid::from_linear_rgba(w, h, texels).unwrap();
        assert!(p.levels.iter().all(MipLevel::is_8bit));
        p
    }

    /// Lookup points: inside, near the edges, tiled, far, non-finite.
    fn lookup_points(seed: &mut u64, count: usize) -> Vec<Vec2> {
        let mut next = move || {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            (*seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut points: Vec<Vec2> = (0..count)
            .map(|i| match i % 4 {
                0 | 1 => Vec2::new(next(), next()),
                2 => Vec2::new(next() * 6.0 - 3.0, next() * 6.0 - 3.0),
                _ => Vec2::new((next() - 0.5) * 2e5, next() * 1e-3),
            })
            .collect();
        points.extend([
            Vec2::ZERO,
            Vec2::ONE,
            Vec2::new(f32::NAN, 0.5),
            Vec2::new(0.5, f32::INFINITY),
            Vec2::new(f32::MAX, f32::MIN),
            Vec2::new(-1e-30, 1e-30),
        ]);
        points
    }

    fn same_bits(a: Vec4, b: Vec4) -> bool {
        a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)
    }

    #[test]
    fn both_simd_copies_compute_the_scalar_reference_bit_for_bit() {
        use crate::simd::{run_avx2_if_available, run_baseline};
        let pyramids = [
            codes_pyramid(64, 32, 1),
            codes_pyramid(37, 21, 2),
            codes_pyramid(261, 6, 3),
            codes_pyramid(1, 1, 4),
            grid(16, 12),
            grid(8, 8),
        ];
        let samplers = [
            Sampler::default(),
            sampler(CLAMP, MIRROR),
            sampler(MIRROR, CLAMP),
        ];
        let mut seed = 0x9E37_79B9_7F4A_7C15;
        let mut compared = 0;
        for p in &pyramids {
            let last = p.level_count() as f32 - 1.0;
            for (i, uv) in lookup_points(&mut seed, 3000).into_iter().enumerate() {
                let s = samplers[i % samplers.len()];
                // Every level and the fractions between them, past the ends, and NaN.
                let lod = match i % 7 {
                    0 => f32::NAN,
                    1 => last + 2.0,
                    2 => (i % 5) as f32 - 1.0,
                    _ => (i as f32 * 0.618_034).fract() * (last + 0.5),
                };
                let level = i % (p.level_count() + 1);
                let axis_uv = Vec2::new(0.01 * (i % 9) as f32, -0.003);
                let taps = 1 + (i % 5) as u32;
                let want = reference_trilinear(p, uv, lod, s);
                let want_bilinear =
                    reference_bilinear(&p.levels[level.min(p.level_count() - 1)], uv, s);
                let step = axis_uv / taps as f32;
                let first = uv - axis_uv * 0.5 + step * 0.5;
                let want_aniso = (0..taps).fold(Vec4::ZERO, |sum, t| {
                    sum + reference_trilinear(p, first + step * t as f32, lod, s)
                }) / taps as f32;
                let clamped = level.min(p.level_count() - 1);
                // Planned and filtered later: the public plans (which also prefetch, in
                // the AVX2 copy where the CPU has it) are the baseline copy's plans, and
                // so is the other copy's, run here outside its kernel (where the CPU has
                // AVX2: a pair of levels whose sides are not powers of two takes AVX).
                let plans = (p.plan_trilinear(uv, lod, s), p.plan_bilinear(level, uv, s));
                assert_eq!(plans.0, plan_trilinear::<false, false>(p, uv, lod, s));
                assert_eq!(plans.1, plan_bilinear::<false, false>(p, clamped, uv, s));
                if crate::simd::Isa::cpu_has_avx2() {
                    assert_eq!(plans.0, plan_trilinear::<true, false>(p, uv, lod, s));
                }
                assert_eq!(plans.1, plan_bilinear::<true, false>(p, clamped, uv, s));
                // The level a plan reports (the renderer's histogram reads it).
                let lower = MipPyramid::split_level(p.clamp_level(lod)).0;
                assert_eq!((plans.0.level(), plans.1.level()), (lower, clamped));
                let planned = || {
                    (
                        Planned::<true> {
                            pyramid: p,
                            plan: &plans.0,
                        },
                        Planned::<true> {
                            pyramid: p,
                            plan: &plans.1,
                        },
                    )
                };
                // The colour alone: the same bits in its three channels, in both copies.
                for (plan, want) in [(&plans.0, want), (&plans.1, want_bilinear)] {
                    let colour = || Planned::<false> { pyramid: p, plan };
                    let got = [
                        Some(run_baseline(colour())),
                        run_avx2_if_available(colour()),
                    ];
                    for got in got.into_iter().flatten() {
                        let got = Vec4::from((Vec3A::from_vec4(got), want.w));
                        assert!(same_bits(got, want), "colour at {uv} lod {lod} {s:?}");
                    }
                    let got = Vec4::from((p.sample_planned_colour(plan), want.w));
                    assert!(
                        same_bits(got, want),
                        "public colour at {uv} lod {lod} {s:?}"
                    );
                }
                let (pt, pb) = planned();
                let planned_baseline = (run_baseline(pt), run_baseline(pb));
                let (pt, pb) = planned();
                let planned_avx2 = [run_avx2_if_available(pt), run_avx2_if_available(pb)];
                let kernels = || {
                    (
                        Trilinear {
                            pyramid: p,
                            uv,
                            lod,
                            sampler: s,
                        },
                        Bilinear {
                            level: &p.levels[level.min(p.level_count() - 1)],
                            uv,
                            sampler: s,
                        },
                        Anisotropic {
                            pyramid: p,
                            first,
                            step,
                            taps,
                            lod,
                            sampler: s,
                        },
                    )
                };
                let (t, b, a) = kernels();
                let baseline = (run_baseline(t), run_baseline(b), run_baseline(a));
                let (t, b, a) = kernels();
                let avx2 = [
                    run_avx2_if_available(t),
                    run_avx2_if_available(b),
                    run_avx2_if_available(a),
                ];
                for (got, want, what) in [
                    (Some(baseline.0), want, "trilinear"),
                    (Some(baseline.1), want_bilinear, "bilinear"),
                    (Some(baseline.2), want_aniso, "anisotropic"),
                    (avx2[0], want, "trilinear (AVX2)"),
                    (avx2[1], want_bilinear, "bilinear (AVX2)"),
                    (avx2[2], want_aniso, "anisotropic (AVX2)"),
                    (Some(planned_baseline.0), want, "planned trilinear"),
                    (Some(planned_baseline.1), want_bilinear, "planned bilinear"),
                    (planned_avx2[0], want, "planned trilinear (AVX2)"),
                    (planned_avx2[1], want_bilinear, "planned bilinear (AVX2)"),
                ] {
                    let Some(got) = got else { continue };
                    assert!(
                        same_bits(got, want),
                        "{what} at {uv} lod {lod} {s:?}: {got} vs {want}"
                    );
                    assert!(got.is_finite(), "{what} at {uv}: {got}");
                    compared += 1;
                }
            }
        }
        assert!(compared >= 6 * 3006 * 5, "{compared}");
        // The public lookups run one of the two copies.
        let p = &pyramids[0];
        let uv = Vec2::new(0.3, 0.7);
        assert!(same_bits(
            p.sample_trilinear(uv, 1.25, Sampler::default()),
            reference_trilinear(p, uv, 1.25, Sampler::default())
        ));
        let plan = p.plan_trilinear(uv, 1.25, Sampler::default());
        assert!(same_bits(
            p.sample_planned(&plan),
            reference_trilinear(p, uv, 1.25, Sampler::default())
        ));
    }
}
