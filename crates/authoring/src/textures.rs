//! Procedural RGBA8 textures for authored scenes: an in-memory image type and generators
//! (checkerboard, running-bond brick, square wall tiles, building facade with windows,
//! street asphalt with lane marks, marble checker, abstract paintings).
//!
//! Invariant of [`RgbaImage`]: `pixels.len() == width * height * 4`, rows top to bottom,
//! so row 0 is `v = 0` in glTF's texture space (origin at the image's top-left). Colour
//! channels are sRGB-encoded (as glTF base-colour images are), alpha is linear.

use image::ImageEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};

/// An 8-bit RGBA image in memory, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbaImage {
    /// Columns, > 0.
    pub width: u32,
    /// Rows, > 0.
    pub height: u32,
    /// `width * height * 4` bytes: sRGB-encoded red, green, blue, then linear alpha.
    pub pixels: Vec<u8>,
}

impl RgbaImage {
    /// Builds an image by calling `texel(x, y)` for every pixel, row by row.
    ///
    /// # Panics
    /// If `width` or `height` is zero.
    pub fn from_fn(width: u32, height: u32, mut texel: impl FnMut(u32, u32) -> [u8; 4]) -> Self {
        assert!(width > 0 && height > 0, "image size must be positive");
        let mut pixels = Vec::with_capacity(width as usize * height as usize * 4);
        for y in 0..height {
            for x in 0..width {
                pixels.extend_from_slice(&texel(x, y));
            }
        }
        RgbaImage {
            width,
            height,
            pixels,
        }
    }

    /// The pixel at column `x`, row `y` (row 0 at the top).
    ///
    /// # Panics
    /// If `(x, y)` is outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside the image"
        );
        let i = (y as usize * self.width as usize + x as usize) * 4;
        [
            self.pixels[i],
            self.pixels[i + 1],
            self.pixels[i + 2],
            self.pixels[i + 3],
        ]
    }

    /// Encodes the image as a PNG file's bytes; the same image always gives the same bytes.
    ///
    /// # Errors
    /// If the pixel buffer does not have `width * height * 4` bytes, or the encoder fails.
    pub fn encode_png(&self) -> Result<Vec<u8>, image::ImageError> {
        let mut bytes = Vec::new();
        PngEncoder::new_with_quality(&mut bytes, CompressionType::Best, FilterType::Adaptive)
            .write_image(
                &self.pixels,
                self.width,
                self.height,
                image::ExtendedColorType::Rgba8,
            )?;
        Ok(bytes)
    }
}

/// A square checkerboard of `size` x `size` pixels with `squares` x `squares` squares; the
/// top-left square is `light`. It tiles seamlessly when `squares` is even.
///
/// # Panics
/// If `size` or `squares` is zero, or `squares > size`.
pub fn checkerboard(size: u32, squares: u32, light: [u8; 4], dark: [u8; 4]) -> RgbaImage {
    assert!(squares > 0 && squares <= size, "need 1 <= squares <= size");
    let square_of = |p: u32| (p as u64 * squares as u64 / size as u64) as u32;
    RgbaImage::from_fn(size, size, |x, y| {
        if (square_of(x) + square_of(y)) % 2 == 0 {
            light
        } else {
            dark
        }
    })
}

/// Layout and colours of a [`brick`] texture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrickPattern {
    /// Courses (rows of bricks) over the image height.
    pub rows: u32,
    /// Bricks per course over the image width; odd courses are shifted by half a brick.
    pub bricks_per_row: u32,
    /// Mortar line width in pixels.
    pub mortar_px: u32,
    /// Base colour of a brick (sRGB RGBA).
    pub brick: [u8; 4],
    /// Colour of the joints (sRGB RGBA).
    pub mortar: [u8; 4],
    /// Largest brightness change of one brick, in 8-bit steps (each brick gets a fixed,
    /// hashed shade in `[-variation, variation]`).
    pub variation: u8,
}

impl Default for BrickPattern {
    fn default() -> Self {
        BrickPattern {
            rows: 8,
            bricks_per_row: 4,
            mortar_px: 3,
            brick: [158, 62, 40, 255],
            mortar: [214, 206, 190, 255],
            variation: 24,
        }
    }
}

/// A running-bond brick wall of `size` x `size` pixels. With `size` divisible by
/// `pattern.rows` and `2 * pattern.bricks_per_row` it tiles seamlessly.
///
/// # Panics
/// If `size`, `pattern.rows` or `pattern.bricks_per_row` is zero.
pub fn brick(size: u32, pattern: &BrickPattern) -> RgbaImage {
    assert!(
        size > 0 && pattern.rows > 0 && pattern.bricks_per_row > 0,
        "brick size, rows and bricks per row must be positive"
    );
    let course_h = size as f32 / pattern.rows as f32;
    let brick_w = size as f32 / pattern.bricks_per_row as f32;
    let mortar = pattern.mortar_px as f32;
    RgbaImage::from_fn(size, size, |x, y| {
        let row = (y as f32 / course_h) as u32;
        let shift = if row % 2 == 1 { brick_w / 2.0 } else { 0.0 };
        let bx = (x as f32 + shift) % size as f32;
        let column = (bx / brick_w) as u32 % pattern.bricks_per_row;
        let in_course = y as f32 - row as f32 * course_h;
        let in_brick = bx - (bx / brick_w).floor() * brick_w;
        if in_course < mortar || in_brick < mortar {
            return pattern.mortar;
        }
        let shade = brick_shade(row, column, pattern.variation);
        let [r, g, b, a] = pattern.brick;
        [
            shade_channel(r, shade),
            shade_channel(g, shade),
            shade_channel(b, shade),
            a,
        ]
    })
}

/// A fixed pseudo-random shade in `[-variation, variation]` for one brick.
fn brick_shade(row: u32, column: u32, variation: u8) -> i32 {
    let mut h = row.wrapping_mul(0x9E37_79B9) ^ column.wrapping_mul(0x85EB_CA6B);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2C1B_3C6D);
    h ^= h >> 13;
    let span = 2 * variation as u32 + 1;
    (h % span) as i32 - variation as i32
}

fn shade_channel(value: u8, shade: i32) -> u8 {
    (value as i32 + shade).clamp(0, 255) as u8
}

/// A fixed pseudo-random number in [0, 1) for integer coordinates and a seed.
fn hash01(x: u32, y: u32, seed: u32) -> f32 {
    let mut h =
        x.wrapping_mul(0x9E37_79B9) ^ y.wrapping_mul(0x85EB_CA6B) ^ seed.wrapping_mul(0xC2B2_AE35);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2C1B_3C6D);
    h ^= h >> 13;
    h = h.wrapping_mul(0x297A_2D39);
    h ^= h >> 16;
    (h >> 8) as f32 / (1u32 << 24) as f32
}

/// Smooth value noise in [0, 1) with lattice period `cells` over `size` pixels (tiles
/// seamlessly).
fn value_noise(x: u32, y: u32, size: u32, cells: u32, seed: u32) -> f32 {
    let fx = x as f32 * cells as f32 / size as f32;
    let fy = y as f32 * cells as f32 / size as f32;
    let (ix, iy) = (fx.floor() as u32, fy.floor() as u32);
    let (tx, ty) = (fx - ix as f32, fy - iy as f32);
    let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
    let at = |i: u32, j: u32| hash01(i % cells, j % cells, seed);
    let top = at(ix, iy) + (at(ix + 1, iy) - at(ix, iy)) * smooth(tx);
    let bottom = at(ix, iy + 1) + (at(ix + 1, iy + 1) - at(ix, iy + 1)) * smooth(tx);
    top + (bottom - top) * smooth(ty)
}

fn mix(a: [u8; 4], b: [u8; 4], t: f32) -> [u8; 4] {
    let t = t.clamp(0.0, 1.0);
    let m = |x: u8, y: u8| (x as f32 + (y as f32 - x as f32) * t).round() as u8;
    [m(a[0], b[0]), m(a[1], b[1]), m(a[2], b[2]), m(a[3], b[3])]
}

/// Square wall tiles: `tiles` x `tiles` tiles of colour `tile` (each with a small hashed
/// shade) separated by `grout_px`-wide `grout` lines; tiles seamlessly.
///
/// # Panics
/// If `size` or `tiles` is zero, or `tiles > size`.
pub fn tiles(size: u32, tiles: u32, grout_px: u32, tile: [u8; 4], grout: [u8; 4]) -> RgbaImage {
    assert!(tiles > 0 && tiles <= size, "need 1 <= tiles <= size");
    let cell = size as f32 / tiles as f32;
    RgbaImage::from_fn(size, size, |x, y| {
        let (cx, cy) = ((x as f32 / cell) as u32, (y as f32 / cell) as u32);
        let (ix, iy) = (x as f32 - cx as f32 * cell, y as f32 - cy as f32 * cell);
        if ix < grout_px as f32 || iy < grout_px as f32 {
            return grout;
        }
        let shade = ((hash01(cx, cy, 7) - 0.5) * 20.0) as i32;
        let [r, g, b, a] = tile;
        [
            shade_channel(r, shade),
            shade_channel(g, shade),
            shade_channel(b, shade),
            a,
        ]
    })
}

/// A building facade: `columns` x `floors` windows (dark glass, some lit warm) in `wall`
/// coloured stucco with a little noise; tiles seamlessly (one texture repeat = one block of
/// windows). `seed` varies which windows are lit.
///
/// # Panics
/// If `size`, `columns` or `floors` is zero.
pub fn facade(size: u32, columns: u32, floors: u32, wall: [u8; 4], seed: u32) -> RgbaImage {
    assert!(
        size > 0 && columns > 0 && floors > 0,
        "facade needs a positive size"
    );
    let cell_w = size as f32 / columns as f32;
    let cell_h = size as f32 / floors as f32;
    RgbaImage::from_fn(size, size, |x, y| {
        let (cx, cy) = ((x as f32 / cell_w) as u32, (y as f32 / cell_h) as u32);
        let (u, v) = (
            (x as f32 - cx as f32 * cell_w) / cell_w,
            (y as f32 - cy as f32 * cell_h) / cell_h,
        );
        let stucco = 0.85 + 0.3 * value_noise(x, y, size, 16, seed);
        let wall_texel = [
            (wall[0] as f32 * stucco).min(255.0) as u8,
            (wall[1] as f32 * stucco).min(255.0) as u8,
            (wall[2] as f32 * stucco).min(255.0) as u8,
            255,
        ];
        let in_window = (0.25..0.75).contains(&u) && (0.2..0.75).contains(&v);
        let in_frame = (0.21..0.79).contains(&u) && (0.16..0.79).contains(&v);
        let sill = (0.21..0.79).contains(&u) && (0.79..0.85).contains(&v);
        if in_window {
            let lit = hash01(cx, cy, seed) < 0.3;
            let mullion = (u - 0.5).abs() < 0.015 || (v - 0.47).abs() < 0.015;
            if mullion {
                [60, 60, 64, 255]
            } else if lit {
                mix([250, 214, 140, 255], [255, 240, 190, 255], v)
            } else {
                mix([70, 92, 120, 255], [30, 40, 58, 255], v)
            }
        } else if in_frame || sill {
            [225, 222, 215, 255]
        } else {
            wall_texel
        }
    })
}

/// Street asphalt: noisy dark grey with a dashed white centre line along V (at u = 0.5)
/// and solid edge lines near u = 0 and u = 1; tiles seamlessly along V.
///
/// # Panics
/// If `size` is zero.
pub fn asphalt(size: u32) -> RgbaImage {
    assert!(size > 0, "asphalt needs a positive size");
    RgbaImage::from_fn(size, size, |x, y| {
        let (u, v) = (x as f32 / size as f32, y as f32 / size as f32);
        let grain = 0.7 * hash01(x, y, 3) + 0.3 * value_noise(x, y, size, 32, 4);
        let grey = (52.0 + 40.0 * grain) as u8;
        let centre = (u - 0.5).abs() < 0.012 && v.fract() < 0.5;
        let edge = (0.03..0.05).contains(&u) || (0.95..0.97).contains(&u);
        if centre {
            [236, 206, 90, 255]
        } else if edge {
            [225, 225, 220, 255]
        } else {
            [grey, grey, (grey as f32 * 1.04) as u8, 255]
        }
    })
}

/// A polished marble checker: `squares` x `squares` squares alternating between two
/// marble colours, each veined with turbulent sine bands; tiles seamlessly for even
/// `squares`.
///
/// # Panics
/// If `size` or `squares` is zero, or `squares > size`.
pub fn marble_checker(size: u32, squares: u32, light: [u8; 4], dark: [u8; 4]) -> RgbaImage {
    assert!(squares > 0 && squares <= size, "need 1 <= squares <= size");
    let square_of = |p: u32| (p as u64 * squares as u64 / size as u64) as u32;
    RgbaImage::from_fn(size, size, |x, y| {
        let is_light = (square_of(x) + square_of(y)) % 2 == 0;
        let base = if is_light { light } else { dark };
        let turbulence =
            value_noise(x, y, size, 8, 11) * 0.6 + value_noise(x, y, size, 32, 12) * 0.25;
        let phase = (x + y) as f32 / size as f32 * std::f32::consts::TAU * 3.0 + turbulence * 9.0;
        let vein = (1.0 - phase.sin().abs()).powi(8);
        let vein_colour = if is_light {
            [120, 118, 126, 255]
        } else {
            [200, 196, 186, 255]
        };
        mix(base, vein_colour, vein * 0.8)
    })
}

/// An abstract painting of `width` x `height` pixels in a gilded frame: `style` 0 draws
/// coloured rectangles on a grid of black bars, 1 concentric rings, 2 a sunset landscape
/// with hills, others a field of dots. `seed` varies the colours and layout.
///
/// # Panics
/// If `width` or `height` is below 16.
pub fn painting(width: u32, height: u32, style: u32, seed: u32) -> RgbaImage {
    assert!(
        width >= 16 && height >= 16,
        "paintings need at least 16 x 16 pixels"
    );
    let frame = (width.min(height) / 14).max(2);
    let palette = [
        [200, 40, 36, 255],
        [28, 64, 160, 255],
        [236, 196, 40, 255],
        [240, 236, 224, 255],
        [40, 120, 70, 255],
        [230, 120, 40, 255],
    ];
    let pick = |i: u32| {
        palette[((hash01(i, seed, 21) * palette.len() as f32) as usize).min(palette.len() - 1)]
    };
    RgbaImage::from_fn(width, height, |x, y| {
        if x < frame || y < frame || x >= width - frame || y >= height - frame {
            let edge = x.min(y).min(width - 1 - x).min(height - 1 - y) as f32 / frame as f32;
            return mix(
                [120, 86, 30, 255],
                [214, 176, 90, 255],
                (edge * std::f32::consts::PI).sin(),
            );
        }
        let (u, v) = (
            (x - frame) as f32 / (width - 2 * frame) as f32,
            (y - frame) as f32 / (height - 2 * frame) as f32,
        );
        match style {
            0 => {
                let cuts_u = [0.0, 0.22 + 0.1 * hash01(1, seed, 0), 0.68, 1.0];
                let cuts_v = [0.0, 0.35, 0.55 + 0.2 * hash01(2, seed, 0), 1.0];
                let near = |c: &[f32], t: f32| c.iter().any(|k| (t - k).abs() < 0.018);
                if near(&cuts_u, u) || near(&cuts_v, v) {
                    return [20, 20, 24, 255];
                }
                let cu = cuts_u.iter().filter(|&&k| k <= u).count() as u32;
                let cv = cuts_v.iter().filter(|&&k| k <= v).count() as u32;
                if hash01(cu, cv, seed) < 0.55 {
                    [240, 236, 224, 255]
                } else {
                    pick(cu * 7 + cv)
                }
            }
            1 => {
                let r = ((u - 0.5).powi(2) + (v - 0.5).powi(2) * 1.0).sqrt();
                let ring = (r * 12.0) as u32;
                mix(pick(ring), pick(ring + 1), (r * 12.0).fract().powi(4))
            }
            2 => {
                let hill = 0.62 + 0.08 * (u * 9.0 + seed as f32).sin() + 0.05 * (u * 23.0).sin();
                let sun = ((u - 0.7).powi(2) + (v - 0.35).powi(2)).sqrt() < 0.09;
                if v > hill {
                    mix([60, 110, 50, 255], [20, 50, 24, 255], (v - hill) * 3.0)
                } else if sun {
                    [255, 230, 120, 255]
                } else {
                    mix([250, 150, 70, 255], [70, 60, 140, 255], 1.0 - v / hill)
                }
            }
            _ => {
                let (gx, gy) = ((u * 9.0) as u32, (v * 7.0) as u32);
                let (fx, fy) = ((u * 9.0).fract() - 0.5, (v * 7.0).fract() - 0.5);
                let radius = 0.2 + 0.25 * hash01(gx, gy, seed);
                if fx * fx + fy * fy < radius * radius {
                    pick(gx + 3 * gy)
                } else {
                    [232, 226, 210, 255]
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const WHITE: [u8; 4] = [255, 255, 255, 255];
    const BLACK: [u8; 4] = [0, 0, 0, 255];

    #[test]
    fn checkerboard_squares_alternate_from_a_light_top_left() {
        let img = checkerboard(512, 8, WHITE, BLACK);
        assert_eq!((img.width, img.height), (512, 512));
        assert_eq!(img.pixels.len(), 512 * 512 * 4);
        assert_eq!(img.pixel(0, 0), WHITE);
        assert_eq!(img.pixel(63, 63), WHITE);
        assert_eq!(img.pixel(64, 0), BLACK);
        assert_eq!(img.pixel(0, 64), BLACK);
        assert_eq!(img.pixel(64, 64), WHITE);
        assert_eq!(img.pixel(511, 511), WHITE);
        assert_eq!(img.pixel(511, 0), BLACK);
    }

    #[test]
    fn brick_has_mortar_lines_and_tiles_horizontally() {
        let pattern = BrickPattern::default();
        let img = brick(256, &pattern);
        // Course 0 starts with a mortar line, brick texels follow.
        assert_eq!(img.pixel(10, 0), pattern.mortar);
        assert_ne!(img.pixel(10, 10), pattern.mortar);
        // Vertical joints of course 0 every 64 px, of course 1 shifted by 32 px.
        assert_eq!(img.pixel(64, 10), pattern.mortar);
        assert_eq!(img.pixel(96, 40), pattern.mortar);
        assert_ne!(img.pixel(64, 40), pattern.mortar);
        // Wrapping around: course 0's last brick runs to the right edge, its first joint
        // sits at the left edge, so the texture repeats without a seam.
        assert_ne!(img.pixel(255, 10), pattern.mortar);
        assert_eq!(img.pixel(0, 10), pattern.mortar);
        assert_eq!(img.pixel(255, 0), pattern.mortar);
    }

    #[test]
    fn new_generators_give_their_sizes_and_tile() {
        let t = tiles(128, 8, 2, [230, 230, 225, 255], [90, 90, 90, 255]);
        assert_eq!(t.pixel(0, 5), [90, 90, 90, 255]);
        assert_ne!(t.pixel(5, 5), [90, 90, 90, 255]);
        let f = facade(64, 2, 2, [180, 150, 120, 255], 1);
        assert_eq!((f.width, f.height), (64, 64));
        let a = asphalt(64);
        assert_eq!(a.pixel(32, 0), [236, 206, 90, 255]);
        let m = marble_checker(64, 4, [230, 228, 220, 255], [40, 42, 48, 255]);
        assert!(m.pixel(2, 2)[0] > m.pixel(18, 2)[0]);
        for style in 0..4 {
            let p = painting(96, 64, style, 5);
            assert_eq!((p.width, p.height), (96, 64));
            assert_eq!(p, painting(96, 64, style, 5));
        }
    }

    #[test]
    fn png_encoding_round_trips_and_is_deterministic() {
        let img = checkerboard(16, 4, WHITE, BLACK);
        let a = img.encode_png().unwrap();
        let b = img.encode_png().unwrap();
        assert_eq!(a, b);
        let decoded = image::load_from_memory(&a).unwrap().to_rgba8();
        assert_eq!(decoded.as_raw(), &img.pixels);
    }
}
