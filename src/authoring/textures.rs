//! Procedural RGBA8 textures for authored scenes: an in-memory image type and generators
//! (checkerboard, running-bond brick).
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
    fn png_encoding_round_trips_and_is_deterministic() {
        let img = checkerboard(16, 4, WHITE, BLACK);
        let a = img.encode_png().unwrap();
        let b = img.encode_png().unwrap();
        assert_eq!(a, b);
        let decoded = image::load_from_memory(&a).unwrap().to_rgba8();
        assert_eq!(decoded.as_raw(), &img.pixels);
    }
}
