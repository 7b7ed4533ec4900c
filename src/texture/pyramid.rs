//! Pyramid construction: level 0 -> all MIP levels, built once at load in linear space.
//!
//! Size convention (OpenGL): each level halves each side with floor, never below 1,
//! `n -> max(1, n / 2)`, until 1x1. A `w x h` image therefore has
//! `1 + floor(log2(max(w, h)))` levels (211 -> 105 -> 52 -> 26 -> 13 -> 6 -> 3 -> 1;
//! 5x3 -> 2x1 -> 1x1).
//!
//! Filter: an exact-area box filter, separable (x pass, then y pass). Along an axis reduced
//! from `sw` to `dw` texels, destination texel `j` covers the source interval
//! `[j * sw / dw, (j + 1) * sw / dw)`; each source texel contributes in proportion to the
//! length of its overlap with that interval (fractional coverage for odd sizes). Overlaps
//! are computed in integers scaled by `dw`, weights accumulated in f64.
//!
//! Invariant: every source texel's weights over all destination texels sum to `dw / sw`,
//! so each level's mean equals the previous level's mean (and hence level 0's), up to the
//! f32 rounding of the stored texels.
//!
//! Storage: every level is first computed in f32 from the unrounded level above it. When
//! level 0 is an 8-bit image (every texel exactly an 8-bit sRGB decoding), every level then
//! keeps 8-bit codes: level 0 its own, each reduced level per channel the code nearest its
//! computed value, so it decodes to that value within half a step between adjacent codes
//! (and its mean to within that of level 0's).

use glam::{DVec4, Vec4};

use super::{MipLevel, MipPyramid, TextureError, check_size};

/// One source texel's share of one destination texel.
#[derive(Debug, Clone, Copy)]
struct Tap {
    src: usize,
    weight: f64,
}

/// Box-filter taps for reducing one axis from `sw` to `dw` texels.
///
/// Returns the taps of every destination texel, flattened, and per destination texel `j`
/// the range `starts[j]..starts[j + 1]` of its taps. Each destination's weights sum to 1.
fn axis_taps(sw: u32, dw: u32) -> (Vec<Tap>, Vec<usize>) {
    let (sw, dw) = (u64::from(sw), u64::from(dw));
    let mut taps = Vec::new();
    let mut starts = Vec::with_capacity(dw as usize + 1);
    for j in 0..dw {
        starts.push(taps.len());
        // In units of 1/dw source texels: destination j spans [j*sw, (j+1)*sw), source
        // texel x spans [x*dw, (x+1)*dw). Integers keep the overlaps exact.
        let (lo, hi) = (j * sw, (j + 1) * sw);
        for x in lo / dw..hi.div_ceil(dw) {
            let overlap = hi.min((x + 1) * dw) - lo.max(x * dw);
            if overlap > 0 {
                taps.push(Tap {
                    src: x as usize,
                    weight: overlap as f64 / sw as f64,
                });
            }
        }
    }
    starts.push(taps.len());
    (taps, starts)
}

/// The next level's size: floor halving, at least 1 (OpenGL convention).
pub(super) fn next_size(n: u32) -> u32 {
    (n / 2).max(1)
}

/// Box-filters `level` down to the next level size.
fn reduce(level: &MipLevel) -> MipLevel {
    let sh = level.height as usize;
    let (dw, dh) = (next_size(level.width), next_size(level.height));
    let (xtaps, xstarts) = axis_taps(level.width, dw);
    let (ytaps, ystarts) = axis_taps(level.height, dh);
    let (dw, dh) = (dw as usize, dh as usize);

    // x pass: sh rows of dw texels, kept in f64 so the y pass adds no extra rounding.
    let mut rows = vec![DVec4::ZERO; dw * sh];
    for y in 0..sh {
        for j in 0..dw {
            rows[y * dw + j] = xtaps[xstarts[j]..xstarts[j + 1]]
                .iter()
                .map(|t| level.texel_at(t.src, y).as_dvec4() * t.weight)
                .sum();
        }
    }

    // y pass: combine whole rows.
    let mut texels = Vec::with_capacity(dw * dh);
    for i in 0..dh {
        let taps = &ytaps[ystarts[i]..ystarts[i + 1]];
        for j in 0..dw {
            let acc: DVec4 = taps.iter().map(|t| rows[t.src * dw + j] * t.weight).sum();
            texels.push(acc.as_vec4());
        }
    }
    MipLevel::linear(dw as u32, dh as u32, texels)
}

impl MipPyramid {
    /// Builds the pyramid from linear RGBA level-0 texels (row-major, row 0 at v = 0).
    ///
    /// Errors (never panics): a zero side ([`TextureError::Empty`]), a side above
    /// [`super::MAX_SIZE`] ([`TextureError::TooLarge`]), or `texels.len() != width * height`
    /// ([`TextureError::WrongLength`]).
    pub fn from_linear_rgba(
        width: u32,
        height: u32,
        texels: Vec<Vec4>,
    ) -> Result<Self, TextureError> {
        check_size(width, height)?;
        // Both sides are <= MAX_SIZE, so the product fits in usize on 64-bit and 32-bit.
        let expected = width as usize * height as usize;
        if texels.len() != expected {
            return Err(TextureError::WrongLength {
                got: texels.len(),
                expected,
            });
        }
        let mut levels = unrounded_levels(MipLevel::linear(width, height, texels));
        // After the reduction, which reads every level unrounded: an 8-bit image keeps
        // its own codes at level 0 and the nearest codes at the reduced levels.
        if levels[0].store_8bit_if_exact() {
            for level in &mut levels[1..] {
                level.store_nearest_8bit();
            }
        }
        Ok(Self { levels })
    }
}

/// `level0` and its reductions down to 1x1, every level in f32.
fn unrounded_levels(level0: MipLevel) -> Vec<MipLevel> {
    let count = 1 + level0.width.max(level0.height).ilog2() as usize;
    let mut levels = Vec::with_capacity(count);
    levels.push(level0);
    while let Some(last) = levels.last().filter(|l| l.width > 1 || l.height > 1) {
        let next = reduce(last);
        levels.push(next);
    }
    debug_assert_eq!(levels.len(), count);
    levels
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::MAX_SIZE;

    /// Deterministic pseudo-random value in [0, 1) from an index (splitmix-style hash).
    fn hash01(i: u64) -> f32 {
        let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }

    fn noise(w: u32, h: u32) -> Vec<Vec4> {
        (0..u64::from(w) * u64::from(h))
            .map(|i| {
                Vec4::new(
                    hash01(4 * i),
                    hash01(4 * i + 1),
                    hash01(4 * i + 2),
                    hash01(4 * i + 3),
                )
            })
            .collect()
    }

    fn sizes(w: u32, h: u32) -> Vec<(u32, u32)> {
        let p = MipPyramid::from_linear_rgba(w, h, noise(w, h)).unwrap();
        for l in &p.levels {
            assert_eq!(l.texels().len(), (l.width * l.height) as usize);
        }
        p.levels.iter().map(|l| (l.width, l.height)).collect()
    }

    fn same(a: Vec4, b: Vec4) -> bool {
        a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)
    }

    fn mean(level: &MipLevel) -> [f64; 4] {
        let mut acc = [0.0f64; 4];
        for t in level.texels() {
            for c in 0..4 {
                acc[c] += f64::from(t[c]);
            }
        }
        acc.map(|a| a / level.texels().len() as f64)
    }

    #[test]
    fn npot_level_sizes_halve_with_floor() {
        let sides: Vec<u32> = sizes(211, 211).iter().map(|s| s.0).collect();
        assert_eq!(sides, [211, 105, 52, 26, 13, 6, 3, 1]);
        assert!(sizes(211, 211).iter().all(|s| s.0 == s.1));
        assert_eq!(sizes(5, 3), [(5, 3), (2, 1), (1, 1)]);
        assert_eq!(sizes(1, 7), [(1, 7), (1, 3), (1, 1)]);
        assert_eq!(sizes(1, 1), [(1, 1)]);
        assert_eq!(sizes(8, 2), [(8, 2), (4, 1), (2, 1), (1, 1)]);
    }

    #[test]
    fn level_count_is_one_plus_floor_log2_of_max_side() {
        for (w, h) in [
            (1, 1),
            (2, 1),
            (3, 3),
            (4, 4),
            (5, 3),
            (1, 7),
            (7, 9),
            (16, 15),
        ] {
            let p = MipPyramid::from_linear_rgba(w, h, noise(w, h)).unwrap();
            let expected = 1 + (f64::from(w.max(h))).log2().floor() as usize;
            assert_eq!(p.level_count(), expected, "{w}x{h}");
            assert_eq!(p.base_size(), (w, h));
            let top = p.levels.last().unwrap();
            assert_eq!((top.width, top.height), (1, 1));
        }
    }

    #[test]
    fn mean_preserved_at_every_level() {
        for (w, h) in [
            (16, 16),
            (64, 8),
            (211, 211),
            (5, 3),
            (1, 7),
            (13, 6),
            (37, 100),
        ] {
            let p = MipPyramid::from_linear_rgba(w, h, noise(w, h)).unwrap();
            let m0 = mean(&p.levels[0]);
            for (k, level) in p.levels.iter().enumerate() {
                let m = mean(level);
                for c in 0..4 {
                    let rel = (m[c] - m0[c]).abs() / m0[c].abs();
                    assert!(
                        rel < 1e-5,
                        "{w}x{h} level {k} channel {c}: {} vs {}",
                        m[c],
                        m0[c]
                    );
                }
            }
        }
    }

    #[test]
    fn odd_axis_uses_fractional_coverage() {
        // 3 -> 1: all three texels fully covered, weight 1/3 each.
        let p = MipPyramid::from_linear_rgba(
            3,
            1,
            vec![Vec4::splat(0.0), Vec4::splat(3.0), Vec4::splat(6.0)],
        )
        .unwrap();
        assert!((p.levels[1].texel(0).x - 3.0).abs() < 1e-6);
        // 5 -> 2: destination 0 covers [0, 2.5): texels 0, 1 fully and half of texel 2.
        let src: Vec<Vec4> = [1.0, 2.0, 4.0, 8.0, 16.0].map(Vec4::splat).to_vec();
        let p = MipPyramid::from_linear_rgba(5, 1, src).unwrap();
        let l1: Vec<Vec4> = p.levels[1].texels().collect();
        assert!((l1[0].x - (1.0 + 2.0 + 0.5 * 4.0) / 2.5).abs() < 1e-6);
        assert!((l1[1].x - (0.5 * 4.0 + 8.0 + 16.0) / 2.5).abs() < 1e-6);
    }

    #[test]
    fn level_zero_of_an_8bit_image_keeps_its_codes_and_samples_bit_for_bit() {
        use crate::texture::{ColorEncoding, Sampler, decode_texels};
        use glam::Vec2;
        // A 64 x 48 RGBA PNG of varied codes (every value 0..=255 on some channel).
        let image = image::RgbaImage::from_fn(64, 48, |x, y| {
            image::Rgba([
                (x * 4 + y) as u8,
                (y * 5) as u8,
                (x * y % 256) as u8,
                (255 - x) as u8,
            ])
        });
        let mut png = Vec::new();
        image
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let (w, h, texels) = decode_texels(&png, ColorEncoding::Srgb).unwrap();
        let compact = MipPyramid::from_linear_rgba(w, h, texels.clone()).unwrap();
        assert!(compact.levels.iter().all(MipLevel::is_8bit));
        // Every texel reads back as decoded.
        assert!(
            compact.levels[0]
                .texels()
                .zip(&texels)
                .all(|(a, b)| same(a, *b))
        );
        // One texel nudged by an ulp is no code's value: every level stays f32.
        let mut nudged = texels.clone();
        nudged[5].x = f32::from_bits(nudged[5].x.to_bits() + 1);
        let linear = MipPyramid::from_linear_rgba(w, h, nudged).unwrap();
        assert!(linear.levels.iter().all(|l| !l.is_8bit()));
        // Lookups equal those of the same pyramid with level 0 kept in f32.
        let mut reference = compact.clone();
        reference.levels[0] = MipLevel::linear(w, h, texels.clone());
        let mut seed = 1u64;
        for _ in 0..2000 {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let uv = Vec2::new(
                (seed >> 40) as f32 / 16777216.0 * 3.0 - 1.0,
                (seed >> 16 & 0xffffff) as f32 / 16777216.0,
            );
            let lod = (seed >> 60) as f32 * 0.4;
            let sampler = Sampler::default();
            assert!(same(
                compact.sample_trilinear(uv, lod, sampler),
                reference.sample_trilinear(uv, lod, sampler)
            ));
            assert!(same(
                compact.sample_bilinear(0, uv, sampler),
                reference.sample_bilinear(0, uv, sampler)
            ));
        }
    }

    /// The decoded values of the codes just below and above `code` (itself at the ends).
    fn neighbours(table: impl Fn(u8) -> f32, code: u8) -> (f32, f32) {
        (table(code.saturating_sub(1)), table(code.saturating_add(1)))
    }

    #[test]
    fn reduced_levels_of_an_8bit_image_keep_the_nearest_codes() {
        use crate::texture::Texels;
        use crate::texture::decode::Srgb8Tables;
        let tables = Srgb8Tables::get();
        let colour = |c: u8| tables.texel([c, 0, 0, 0]).x;
        let alpha = |c: u8| tables.texel([0, 0, 0, c]).w;
        for (w, h, seed) in [(64, 48, 1u64), (37, 100, 2), (211, 5, 3), (1, 9, 4)] {
            // Codes in runs, so that reduced levels hold every kind of mix.
            let texels: Vec<Vec4> = (0..u64::from(w * h))
                .map(|i| {
                    let z = (i / 3 + seed).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32;
                    tables.texel((z as u32).to_le_bytes())
                })
                .collect();
            let pyramid = MipPyramid::from_linear_rgba(w, h, texels.clone()).unwrap();
            let unrounded = unrounded_levels(MipLevel::linear(w, h, texels));
            assert_eq!(pyramid.level_count(), unrounded.len());
            for (k, (stored, exact)) in pyramid.levels.iter().zip(&unrounded).enumerate() {
                assert!(stored.is_8bit(), "{w}x{h} level {k}");
                let Texels::Srgb8 { codes, .. } = &stored.texels else {
                    unreachable!()
                };
                let w = stored.width as usize;
                for (i, value) in exact.texels().enumerate() {
                    let at = stored.row_start(i / w) + stored.column_offset(i % w);
                    let codes = codes.flat()[at];
                    let decoded = stored.texel(i);
                    if k == 0 {
                        assert!(same(decoded, value), "level 0 texel {i}");
                    }
                    for c in 0..4 {
                        let table = |code| if c < 3 { colour(code) } else { alpha(code) };
                        let (below, above) = neighbours(table, codes[c]);
                        let (got, want) = (decoded[c], value[c]);
                        // Within one code of the unrounded value...
                        assert!(
                            below <= want && want <= above,
                            "{w}x{h} level {k} texel {i} channel {c}: {got} for {want}"
                        );
                        // ...and no other code is nearer.
                        let error = (got - want).abs();
                        assert!(
                            error <= (below - want).abs() && error <= (above - want).abs(),
                            "{w}x{h} level {k} texel {i} channel {c}: {got} for {want}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn images_that_are_not_8bit_keep_f32_levels() {
        use crate::texture::{ColorEncoding, decode_texels};
        // A 16-bit PNG: its decoded values are no 8-bit code's.
        let image = image::ImageBuffer::from_fn(16, 8, |x, y| {
            image::Rgba([x as u16 * 4000 + 1, y as u16 * 7000 + 3, 12345, 65535])
        });
        let mut png = Vec::new();
        image
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let (w, h, texels) = decode_texels(&png, ColorEncoding::Srgb).unwrap();
        let p = MipPyramid::from_linear_rgba(w, h, texels.clone()).unwrap();
        assert!(p.levels.iter().all(|l| !l.is_8bit()));
        // Its levels are the unrounded reductions.
        let unrounded = unrounded_levels(MipLevel::linear(w, h, texels));
        for (a, b) in p.levels.iter().zip(&unrounded) {
            assert!(a.texels().zip(b.texels()).all(|(x, y)| same(x, y)));
        }
    }

    #[test]
    fn constant_image_stays_constant() {
        let c = Vec4::new(0.25, 0.5, 0.75, 1.0);
        let p = MipPyramid::from_linear_rgba(7, 5, vec![c; 35]).unwrap();
        for level in &p.levels {
            for t in level.texels() {
                assert!((t - c).abs().max_element() < 1e-6);
            }
        }
    }

    #[test]
    fn rejects_bad_sizes_without_panicking() {
        assert!(matches!(
            MipPyramid::from_linear_rgba(0, 4, vec![]),
            Err(TextureError::Empty {
                width: 0,
                height: 4
            })
        ));
        assert!(matches!(
            MipPyramid::from_linear_rgba(3, 0, vec![]),
            Err(TextureError::Empty { .. })
        ));
        assert!(matches!(
            MipPyramid::from_linear_rgba(MAX_SIZE + 1, 1, vec![]),
            Err(TextureError::TooLarge { max: MAX_SIZE, .. })
        ));
        assert!(matches!(
            MipPyramid::from_linear_rgba(u32::MAX, u32::MAX, vec![]),
            Err(TextureError::TooLarge { .. })
        ));
        assert!(matches!(
            MipPyramid::from_linear_rgba(2, 2, vec![Vec4::ONE; 3]),
            Err(TextureError::WrongLength {
                got: 3,
                expected: 4
            })
        ));
    }
}
