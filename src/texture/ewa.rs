//! Elliptically weighted average (EWA) filtering over a MIP pyramid, the way pbrt-v4's
//! `MIPMap::Filter` does it (Greene & Heckbert 1986; Heckbert 1989; PBRT 4th ed. 10.4.4):
//!
//! - the footprint is the ellipse whose conjugate semi-axes are the texture-space
//!   derivatives along the film's x and y (`major`, `minor`: the longer and the shorter,
//!   the caller clamps their ratio);
//! - it is filtered in the level where the minor axis is about one texel
//!   (`floor(lod)`) and in the next one, blended by `lod`'s fraction like trilinear;
//! - within a level, every texel whose centre falls inside the ellipse is weighted by a
//!   Gaussian of its squared radius `r^2` in the ellipse's own metric,
//!   `exp(-2 r^2) - exp(-2)` (zero on the boundary), read from a 128-entry table as pbrt
//!   reads it; the ellipse is first widened by one texel each way (`A + 1`, `C + 1`), a
//!   reconstruction filter that keeps at least the nearest texels inside it however thin the
//!   footprint.
//!
//! Texels are read through one accessor, [`MipLevel::texel_at`], which returns a texel of a
//! level as linear RGBA floats whatever the level's storage.
//!
//! Invariants (as for the other lookups): never allocates, never panics on a pyramid built
//! by [`MipPyramid::from_linear_rgba`], never returns NaN for finite texels. Non-finite
//! axes fall back to trilinear filtering; a footprint whose bounding box would exceed
//! [`MAX_BOX_SIDE`] texels a side in its level (impossible when `lod` is the minor axis's
//! level, as the methods give it; a guard against hand-made footprints) does too.

use std::sync::LazyLock;

use glam::{DVec2, Vec2, Vec4};

use super::sample::wrap;
use super::{MipFilter, MipLevel, MipPyramid, Sampler, WrapMode};

/// Entries of the Gaussian weight table over `r^2` in `[0, 1)`.
const WEIGHT_TABLE_SIZE: usize = 128;

/// The Gaussian's falloff: `exp(-ALPHA r^2)`, pbrt's value.
const ALPHA: f32 = 2.0;

/// Largest bounding box side (texels) one level's loop visits. With the minor axis at
/// 1-2 texels of its level and anisotropy at most 16 the side stays below about 70.
pub const MAX_BOX_SIDE: usize = 256;

/// `exp(-ALPHA r^2) - exp(-ALPHA)` at `r^2 = i / (SIZE - 1)`.
static WEIGHTS: LazyLock<[f32; WEIGHT_TABLE_SIZE]> = LazyLock::new(|| {
    std::array::from_fn(|i| {
        let r2 = i as f32 / (WEIGHT_TABLE_SIZE - 1) as f32;
        (-ALPHA * r2).exp() - (-ALPHA).exp()
    })
});

impl MipPyramid {
    /// EWA lookup at `uv` over the ellipse with conjugate semi-axes `major` and `minor`
    /// (texture-coordinate offsets per pixel, scaled by `scale`: `2^bias` for a LOD bias),
    /// filtered at level `lod` (clamped with [`Self::clamp_level`]; the caller's level of
    /// the scaled minor axis) and the next (only the nearest level with
    /// [`MipFilter::Nearest`]). At the last level (1x1) the lookup is its texel.
    pub fn sample_ewa(
        &self,
        uv: Vec2,
        lod: f32,
        (major, minor): (Vec2, Vec2),
        scale: f32,
        sampler: Sampler,
    ) -> Vec4 {
        let (major, minor) = (major * scale, minor * scale);
        if !(major.is_finite() && minor.is_finite()) {
            return self.sample_trilinear(uv, lod, sampler);
        }
        let ewa = |k: usize| {
            ewa_in_level(&self.levels[k], uv, major, minor, sampler)
                .unwrap_or_else(|| self.sample_bilinear(k, uv, sampler))
        };
        if sampler.mip == MipFilter::Nearest {
            return ewa(self.nearest_level(lod));
        }
        let (k, frac) = self.clamp_and_split_level(lod);
        if frac == 0.0 || k + 1 >= self.levels.len() {
            return ewa(k);
        }
        ewa(k) * (1.0 - frac) + ewa(k + 1) * frac
    }
}

/// The EWA sum over one level, or `None` when the ellipse's bounding box is too large
/// (see [`MAX_BOX_SIDE`]) or holds no weight.
fn ewa_in_level(
    level: &MipLevel,
    uv: Vec2,
    major: Vec2,
    minor: Vec2,
    sampler: Sampler,
) -> Option<Vec4> {
    if level.width == 1 && level.height == 1 {
        // Every index wraps to the one texel: the weighted mean is that texel.
        return Some(level.texel_at(0, 0));
    }
    let size = Vec2::new(level.width as f32, level.height as f32);
    let (a0, a1) = (major * size, minor * size);
    let ellipse = Ellipse::through(a0, a1)?;
    // The centre in texel space (texel centres at integers), in f64 as in `sample.rs`:
    // far from the origin f32 would lose the fraction.
    let centre = DVec2::new(
        f64::from(uv.x) * f64::from(level.width) - 0.5,
        f64::from(uv.y) * f64::from(level.height) - 0.5,
    );
    let centre = if centre.is_finite() {
        centre
    } else {
        DVec2::splat(-0.5)
    };
    let (half_s, half_t) = ellipse.half_extent();
    let columns = Span::around(centre.x, half_s, level.width, sampler.wrap_s)?;
    let rows = Span::around(centre.y, half_t, level.height, sampler.wrap_t)?;
    let weights = &*WEIGHTS;
    let mut sum = Vec4::ZERO;
    let mut total = 0.0f32;
    // Wrapped once per column, not once per texel (`wrap` divides for Repeat).
    let mut wrapped_columns = [0u32; MAX_BOX_SIDE];
    for (i, slot) in wrapped_columns[..columns.len].iter_mut().enumerate() {
        *slot = columns.wrapped(i) as u32;
    }
    for j in 0..rows.len {
        let tt = rows.offset(j);
        let y = rows.wrapped(j);
        for (i, &x) in wrapped_columns[..columns.len].iter().enumerate() {
            let r2 = ellipse.radius2(columns.offset(i), tt);
            if r2 < 1.0 {
                let index = ((r2 * WEIGHT_TABLE_SIZE as f32) as usize).min(WEIGHT_TABLE_SIZE - 1);
                let weight = weights[index];
                sum += level.texel_at(x as usize, y) * weight;
                total += weight;
            }
        }
    }
    (total > 0.0).then(|| sum / total)
}

/// The implicit ellipse `A s^2 + B s t + C t^2 < 1` in a level's texel offsets `(s, t)`
/// from the lookup point.
#[derive(Debug, Clone, Copy)]
struct Ellipse {
    a: f32,
    b: f32,
    c: f32,
}

impl Ellipse {
    /// The ellipse with conjugate semi-axes `a0` and `a1` (texels), widened by one texel
    /// each way; `None` if that is not a finite ellipse.
    fn through(a0: Vec2, a1: Vec2) -> Option<Ellipse> {
        // For conjugate semi-axes the quadratic form is `(a0.y^2 + a1.y^2) s^2 - 2 (a0.x
        // a0.y + a1.x a1.y) s t + (a0.x^2 + a1.x^2) t^2 = F` with `F = (a0 x a1)^2`; the +1
        // on A and C adds a one-texel disc, and dividing by the widened form's own F puts
        // the boundary at 1.
        let a = a0.y * a0.y + a1.y * a1.y + 1.0;
        let b = -2.0 * (a0.x * a0.y + a1.x * a1.y);
        let c = a0.x * a0.x + a1.x * a1.x + 1.0;
        let f = a * c - 0.25 * b * b;
        let ellipse = Ellipse {
            a: a / f,
            b: b / f,
            c: c / f,
        };
        (f > 0.0 && ellipse.a.is_finite() && ellipse.b.is_finite() && ellipse.c.is_finite())
            .then_some(ellipse)
    }

    /// Half the bounding box's width and height (texels).
    fn half_extent(&self) -> (f64, f64) {
        let det = 4.0 * f64::from(self.a) * f64::from(self.c) - f64::from(self.b).powi(2);
        (
            2.0 * (f64::from(self.c) / det).sqrt(),
            2.0 * (f64::from(self.a) / det).sqrt(),
        )
    }

    #[inline(always)]
    fn radius2(&self, s: f32, t: f32) -> f32 {
        self.a * s * s + self.b * s * t + self.c * t * t
    }
}

/// The texels one axis of the bounding box covers: integer texel positions `first ..
/// first + len` around a centre, with their offsets from it and their wrapped indices.
#[derive(Debug, Clone, Copy)]
struct Span {
    /// Offset of the first texel from the centre (texels).
    first_offset: f32,
    /// The first texel's index, reduced to a small range with the same wrapped results.
    first: i64,
    len: usize,
    n: i64,
    mode: WrapMode,
}

impl Span {
    /// The texels within `half` of `centre` on an axis of `n` texels; `None` if the span
    /// is empty, not finite or longer than [`MAX_BOX_SIDE`].
    fn around(centre: f64, half: f64, n: u32, mode: WrapMode) -> Option<Span> {
        if !(half.is_finite() && half >= 0.0 && half < MAX_BOX_SIDE as f64 / 2.0 - 1.0) {
            return None;
        }
        let first = (centre - half).ceil();
        let last = (centre + half).floor();
        if !(last >= first) {
            return None;
        }
        let len = (last - first) as usize + 1;
        let n_f = f64::from(n);
        // Reduce the first index exactly (f64 `rem_euclid` of an integer) so that it
        // converts to i64 and `first + len` stays in range, with the same wrapped texels.
        let reduced = match mode {
            WrapMode::Repeat => first.rem_euclid(n_f),
            WrapMode::MirroredRepeat => first.rem_euclid(2.0 * n_f),
            WrapMode::ClampToEdge => first.clamp(-(MAX_BOX_SIDE as f64), n_f),
        };
        Some(Span {
            first_offset: (first - centre) as f32,
            first: reduced as i64,
            len,
            n: i64::from(n),
            mode,
        })
    }

    /// Offset from the centre of the `i`-th texel of the span.
    #[inline(always)]
    fn offset(&self, i: usize) -> f32 {
        self.first_offset + i as f32
    }

    /// Wrapped index of the `i`-th texel of the span.
    #[inline(always)]
    fn wrapped(&self, i: usize) -> usize {
        wrap(self.first + i as i64, self.n, self.mode)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pyramid(w: u32, h: u32, texel: impl Fn(u32, u32) -> Vec4) -> MipPyramid {
        let texels = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| texel(x, y));
        MipPyramid::from_linear_rgba(w, h, texels.collect()).unwrap()
    }

    fn close(a: Vec4, b: Vec4, tol: f32) -> bool {
        (a - b).abs().max_element() <= tol
    }

    #[test]
    fn weight_table_is_the_gaussian_minus_its_edge_value() {
        let w = &*WEIGHTS;
        assert!((w[0] - (1.0 - (-2.0f32).exp())).abs() < 1e-6);
        assert!(w[WEIGHT_TABLE_SIZE - 1].abs() < 1e-6);
        assert!(w.windows(2).all(|p| p[0] > p[1]));
        // pbrt's table: 0.864664733 first, 0.0021481365 next to last.
        assert!((w[0] - 0.864_664_7).abs() < 1e-6);
        assert!((w[WEIGHT_TABLE_SIZE - 2] - 0.002_148_136_5).abs() < 1e-5);
    }

    #[test]
    fn a_constant_texture_comes_back_unchanged() {
        let p = pyramid(64, 32, |_, _| Vec4::new(0.25, 0.5, 0.75, 1.0));
        for (uv, major, minor) in [
            (
                Vec2::new(0.3, 0.6),
                Vec2::new(0.2, 0.05),
                Vec2::new(-0.003, 0.012),
            ),
            (
                Vec2::new(-7.3, 12.6),
                Vec2::new(0.0, 0.001),
                Vec2::new(0.001, 0.0),
            ),
            (
                Vec2::new(0.5, 0.5),
                Vec2::new(1.0, 1.0),
                Vec2::new(-1.0, 1.0),
            ),
        ] {
            for lod in [0.0, 0.4, 2.0, 3.7, 5.0, 99.0] {
                let got = p.sample_ewa(uv, lod, (major, minor), 1.0, Sampler::default());
                assert!(close(got, Vec4::new(0.25, 0.5, 0.75, 1.0), 1e-5), "{got}");
            }
        }
    }

    /// With `MipFilter::Nearest` the ellipse is summed in the nearest level alone: what
    /// the blending filter gives at that whole level.
    #[test]
    fn nearest_mip_filter_sums_the_nearest_level_alone() {
        let p = pyramid(64, 64, |x, y| {
            Vec4::new(x as f32 / 64.0, (y * y) as f32 / 4096.0, 0.5, 1.0)
        });
        let nearest = Sampler {
            mip: MipFilter::Nearest,
            ..Sampler::default()
        };
        let axes = (Vec2::new(0.05, 0.01), Vec2::new(-0.004, 0.02));
        let uv = Vec2::new(0.31, 0.58);
        for (lod, level) in [
            (0.3, 0.0),
            (1.25, 1.0),
            (1.5, 1.0),
            (1.75, 2.0),
            (99.0, 6.0),
        ] {
            let one = p.sample_ewa(uv, level, axes, 1.0, Sampler::default());
            let got = p.sample_ewa(uv, lod, axes, 1.0, nearest);
            assert_eq!(got, one, "{lod}");
        }
        let blended = p.sample_ewa(uv, 1.5, axes, 1.0, Sampler::default());
        assert_ne!(blended, p.sample_ewa(uv, 1.5, axes, 1.0, nearest));
    }

    #[test]
    fn a_linear_ramp_is_averaged_to_its_centre_value() {
        // Red = texel x: a symmetric filter around the lookup point returns the point's x,
        // whatever the ellipse, away from the wrap seam.
        let p = pyramid(256, 256, |x, _| Vec4::new(x as f32, 0.0, 0.0, 1.0));
        let s = Sampler {
            wrap_s: WrapMode::ClampToEdge,
            wrap_t: WrapMode::ClampToEdge,
            ..Sampler::default()
        };
        let uv = Vec2::new(100.5 / 256.0, 0.5);
        for (major, minor) in [
            (Vec2::new(8.0, 0.0), Vec2::new(0.0, 1.0)),
            (Vec2::new(6.0, 6.0), Vec2::new(-0.5, 0.5)),
            (Vec2::new(0.0, 3.0), Vec2::new(0.4, 0.0)),
        ] {
            let axes = (major / 256.0, minor / 256.0);
            let got = p.sample_ewa(uv, 0.0, axes, 1.0, s);
            assert!((got.x - 100.0).abs() < 1e-3, "{major} {minor}: {got}");
        }
    }

    #[test]
    fn the_filter_spreads_along_the_major_axis_only() {
        // A single bright texel: an ellipse along u reaches it from 5 texels away in u, not
        // in v.
        let p = pyramid(64, 64, |x, y| {
            if (x, y) == (32, 32) {
                Vec4::ONE
            } else {
                Vec4::ZERO
            }
        });
        let s = Sampler::default();
        let axes = (Vec2::new(8.0 / 64.0, 0.0), Vec2::new(0.0, 1.0 / 64.0));
        let at = |dx: f32, dy: f32| {
            let uv = Vec2::new((32.5 + dx) / 64.0, (32.5 + dy) / 64.0);
            p.sample_ewa(uv, 0.0, axes, 1.0, s).x
        };
        assert!(at(5.0, 0.0) > 0.0);
        assert_eq!(at(0.0, 5.0), 0.0);
        assert!(at(0.0, 0.0) > at(5.0, 0.0));
        // The weights sum to one: a ring of lookups around it adds up to about 1 per
        // texel of area (the filter preserves the mean).
        let total: f32 = (-12..=12)
            .flat_map(|i| (-3..=3).map(move |j| (i, j)))
            .map(|(i, j)| at(i as f32, j as f32))
            .sum();
        assert!((total - 1.0).abs() < 1e-3, "{total}");
    }

    #[test]
    fn levels_are_blended_like_trilinear() {
        let p = pyramid(32, 32, |x, y| {
            Vec4::new(((x * 7 + y * 3) % 5) as f32, 0.0, 0.0, 1.0)
        });
        let s = Sampler::default();
        let uv = Vec2::new(0.37, 0.61);
        let axes = (Vec2::new(0.2, 0.1), Vec2::new(-0.02, 0.04));
        let at = |lod| p.sample_ewa(uv, lod, axes, 1.0, s);
        let got = at(1.25);
        let expected = at(1.0) * 0.75 + at(2.0) * 0.25;
        assert!(close(got, expected, 1e-5), "{got} vs {expected}");
        // Past the last level: the 1x1 texel, the texture's mean.
        let last = p.level_count() - 1;
        assert_eq!(at(99.0), p.sample_bilinear(last, uv, s));
    }

    #[test]
    fn scale_grows_the_footprint() {
        let p = pyramid(64, 64, |x, y| {
            Vec4::new(((x ^ y) & 1) as f32, 0.0, 0.0, 1.0)
        });
        let s = Sampler::default();
        let uv = Vec2::new(32.5 / 64.0, 32.5 / 64.0);
        let axes = (Vec2::new(1.0 / 64.0, 0.0), Vec2::new(0.0, 1.0 / 64.0));
        // A checker of single texels seen from a texel centre: the bigger the footprint,
        // the closer to the mean 0.5.
        let small = (p.sample_ewa(uv, 0.0, axes, 1.0, s).x - 0.5).abs();
        let big = (p.sample_ewa(uv, 0.0, axes, 4.0, s).x - 0.5).abs();
        assert!(big < small, "{big} vs {small}");
    }

    #[test]
    fn hostile_inputs_stay_finite_and_bounded() {
        let p = pyramid(16, 8, |x, y| Vec4::new(x as f32, y as f32, 1.0, 1.0));
        for mode in [
            WrapMode::Repeat,
            WrapMode::ClampToEdge,
            WrapMode::MirroredRepeat,
        ] {
            let s = Sampler {
                wrap_s: mode,
                wrap_t: mode,
                ..Sampler::default()
            };
            for uv in [
                Vec2::new(f32::NAN, 0.3),
                Vec2::new(1e30, -1e30),
                Vec2::new(100_000.37, -3.2),
            ] {
                for (major, minor) in [
                    (Vec2::new(f32::INFINITY, 0.0), Vec2::ZERO),
                    (Vec2::ZERO, Vec2::ZERO),
                    (Vec2::new(1e20, 0.0), Vec2::new(0.0, 1e20)),
                    // A line: no minor axis at all.
                    (Vec2::new(0.5, 0.0), Vec2::ZERO),
                    (Vec2::new(0.01, 0.02), Vec2::new(-0.02, 0.01)),
                ] {
                    for lod in [f32::NAN, -3.0, 0.0, 1.5, 3.0, f32::INFINITY] {
                        let got = p.sample_ewa(uv, lod, (major, minor), 1.0, s);
                        assert!(
                            got.is_finite(),
                            "{mode:?} {uv} {major} {minor} {lod}: {got}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn far_coordinates_keep_the_fraction() {
        // As bilinear does: u = 100000.37 is the same point as 0.3671875 with Repeat.
        let w = 1024;
        let p = pyramid(w, 2, |x, _| Vec4::new(x as f32, 0.0, 0.0, 1.0));
        let s = Sampler::default();
        let axes = (Vec2::new(3.0 / 1024.0, 0.0), Vec2::new(0.0, 1.0 / 1024.0));
        let big: f32 = 100000.37;
        let frac = (f64::from(big) - 100000.0) as f32;
        let far = p.sample_ewa(Vec2::new(big, 0.25), 0.0, axes, 1.0, s);
        let near = p.sample_ewa(Vec2::new(frac, 0.25), 0.0, axes, 1.0, s);
        assert!(close(far, near, 1e-3), "{far} vs {near}");
    }
}
