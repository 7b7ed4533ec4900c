//! Image decoding: encoded bytes (PNG, JPEG, PPM/PNM; format guessed from the content) ->
//! linear RGBA `Vec4` texels.
//!
//! Invariant: the output is `width * height` texels, row-major, row 0 = the image's top
//! row = v = 0 (glTF convention, no flip), with `width` and `height` in 1..=`MAX_SIZE`.
//! Gray is replicated to RGB; a missing alpha is 1. With `srgb`, the colour channels go
//! through the exact sRGB EOTF (IEC 61966-2-1) and alpha stays linear; without it every
//! channel is just normalised to [0, 1] (integer formats) or passed through (float).

use std::io::Cursor;
use std::sync::LazyLock;

use glam::Vec4;
use image::{DynamicImage, ImageReader, Limits};

use super::{MAX_SIZE, TextureError, check_size};

/// Upper bound on what the decoder may allocate for one image. Guards against files whose
/// header claims a huge size; a real 16384² RGBA8 texture still fits.
const MAX_DECODE_ALLOC: u64 = 1 << 30;

/// The exact sRGB EOTF (encoded value in [0, 1] -> linear), evaluated in f64.
fn srgb_eotf(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Converts one sRGB-encoded channel value in [0, 1] to linear (exact EOTF). Values below
/// 0 use the linear segment; values above 1 continue the power curve.
pub fn srgb_to_linear(c: f32) -> f32 {
    srgb_eotf(f64::from(c)) as f32
}

/// 8-bit sRGB -> linear, built once: 256 entries cover every input exactly.
static SRGB8_LUT: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| srgb_eotf(i as f64 / 255.0) as f32));

/// 8-bit alpha -> [0, 1], as `expand_u8` computes it, built once.
static ALPHA8_LUT: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| unorm8(i as u8)));

fn unorm8(v: u8) -> f32 {
    f32::from(v) / 255.0
}

/// Where each value of a strictly increasing table of non-negative floats sits, by the top
/// 16 bits of the value: `start[b]..start[b + 1]` are the codes whose bits start with `b`
/// (at most a few), so finding a value's code is a lookup, not a search.
struct CodeIndex {
    table: &'static [f32; 256],
    start: Vec<u16>,
}

impl CodeIndex {
    fn new(table: &'static [f32; 256]) -> CodeIndex {
        let mut start = vec![0u16; (1 << 16) + 1];
        for &value in table {
            start[(value.to_bits() >> 16) as usize + 1] += 1;
        }
        for b in 1..start.len() {
            start[b] += start[b - 1];
        }
        CodeIndex { table, start }
    }

    /// The first code whose table value is not below `value` (256 when every value is
    /// below it; 0 for NaN): the table's `partition_point(|&t| t < value)`. Non-negative
    /// floats order as their bits do, so every code of a lower bucket is below `value` and
    /// every code of a higher one above it: only `value`'s own bucket is searched.
    #[inline]
    fn first_not_below(&self, value: f32) -> usize {
        // -0, negatives and NaN: no table value is below them (the table starts at 0).
        if value.is_nan() || value <= 0.0 {
            return 0;
        }
        let bucket = (value.to_bits() >> 16) as usize;
        let (first, end) = (self.start[bucket] as usize, self.start[bucket + 1] as usize);
        first
            + self.table[first..end]
                .iter()
                .take_while(|&&t| t < value)
                .count()
    }

    /// The code whose table value is exactly `value` (bit for bit), if any.
    #[inline]
    fn code(&self, value: f32) -> Option<u8> {
        let bucket = (value.to_bits() >> 16) as usize;
        (self.start[bucket]..self.start[bucket + 1])
            .find(|&code| self.table[code as usize].to_bits() == value.to_bits())
            .map(|code| code as u8)
    }
}

static SRGB8_INDEX: LazyLock<CodeIndex> = LazyLock::new(|| CodeIndex::new(&SRGB8_LUT));
static ALPHA8_INDEX: LazyLock<CodeIndex> = LazyLock::new(|| CodeIndex::new(&ALPHA8_LUT));

/// [`SRGB8_LUT`] then [`ALPHA8_LUT`] in one array, so that a texel's four channels are read
/// from one table (`code` for red, green and blue, `ALPHA_OFFSET + code` for alpha), whose
/// 2 KiB stay in the first-level cache.
static DECODE8: LazyLock<[f32; 2 * 256]> =
    LazyLock::new(|| std::array::from_fn(|i| [&*SRGB8_LUT, &*ALPHA8_LUT][i / 256][i % 256]));

/// Where the alpha table starts in `DECODE8`.
pub(super) const ALPHA_OFFSET: usize = 256;

/// The two tables that decode an 8-bit sRGB image's pixels, as `expand_u8` decodes them.
#[derive(Debug, Clone, Copy)]
pub(super) struct Srgb8Tables {
    /// Colour codes at `0..256`, alpha codes at `ALPHA_OFFSET..ALPHA_OFFSET + 256`.
    decode: &'static [f32; 2 * 256],
}

impl Srgb8Tables {
    pub(super) fn get() -> Srgb8Tables {
        Srgb8Tables { decode: &DECODE8 }
    }

    /// The texel of pixel `codes` (red, green, blue, alpha).
    #[inline(always)]
    pub(super) fn texel(&self, codes: [u8; 4]) -> Vec4 {
        self.texel_in::<true>(codes)
    }

    /// [`Srgb8Tables::texel`], with alpha decoded only when `ALPHA` (else 0): a lookup whose
    /// caller keeps the colour alone saves one table read a texel.
    #[inline(always)]
    pub(super) fn texel_in<const ALPHA: bool>(&self, codes: [u8; 4]) -> Vec4 {
        let t = self.decode;
        Vec4::new(
            t[codes[0] as usize],
            t[codes[1] as usize],
            t[codes[2] as usize],
            if ALPHA {
                t[ALPHA_OFFSET + codes[3] as usize]
            } else {
                0.0
            },
        )
    }

    /// The codes [`Srgb8Tables::texel`] turns into exactly `texel`, if there are any.
    pub(super) fn codes(&self, texel: Vec4) -> Option<[u8; 4]> {
        let (colour, alpha) = (&*SRGB8_INDEX, &*ALPHA8_INDEX);
        Some([
            colour.code(texel.x)?,
            colour.code(texel.y)?,
            colour.code(texel.z)?,
            alpha.code(texel.w)?,
        ])
    }

    /// The codes whose decoded values are nearest `texel`'s channels (see [`nearest_code`]):
    /// what a reduced MIP level of an 8-bit image keeps.
    pub(super) fn nearest_codes(&self, texel: Vec4) -> [u8; 4] {
        [
            nearest_code(&SRGB8_INDEX, texel.x),
            nearest_code(&SRGB8_INDEX, texel.y),
            nearest_code(&SRGB8_INDEX, texel.z),
            nearest_code(&ALPHA8_INDEX, texel.w),
        ]
    }
}

/// The code of a strictly increasing table (`index`'s) whose value is nearest `value` (ties
/// to the lower code); values below the first entry or above the last take the end codes,
/// and NaN takes code 0. The two distances are compared in f64, where the difference of two
/// `f32` values loses nothing unless their exponents are 29 or more apart (a value that
/// close to zero is nearer code 0 by far). The neighbours come from the index, not a binary
/// search: reducing the MIP levels of 8-bit images called this for every channel of every
/// reduced texel, a fifth of loading BART Kitchen.
fn nearest_code(index: &CodeIndex, value: f32) -> u8 {
    let table = index.table;
    let above = index.first_not_below(value);
    if above == 0 {
        return 0;
    }
    if above == table.len() {
        return 255;
    }
    let (below, above_value) = (f64::from(table[above - 1]), f64::from(table[above]));
    let value = f64::from(value);
    if above_value - value < value - below {
        above as u8
    } else {
        (above - 1) as u8
    }
}

/// Expands interleaved 1..=4-channel pixels to RGBA with separate colour and alpha maps.
fn expand<T: Copy>(
    raw: &[T],
    channels: usize,
    colour: impl Fn(T) -> f32,
    alpha: impl Fn(T) -> f32,
) -> Vec<Vec4> {
    raw.chunks_exact(channels)
        .map(|p| match channels {
            1 => Vec4::new(colour(p[0]), colour(p[0]), colour(p[0]), 1.0),
            2 => {
                let g = colour(p[0]);
                Vec4::new(g, g, g, alpha(p[1]))
            }
            3 => Vec4::new(colour(p[0]), colour(p[1]), colour(p[2]), 1.0),
            _ => Vec4::new(colour(p[0]), colour(p[1]), colour(p[2]), alpha(p[3])),
        })
        .collect()
}

fn expand_u8(raw: &[u8], channels: usize, srgb: bool) -> Vec<Vec4> {
    let unorm = unorm8;
    if srgb {
        let lut = &*SRGB8_LUT;
        expand(raw, channels, |v| lut[v as usize], unorm)
    } else {
        expand(raw, channels, unorm, unorm)
    }
}

fn expand_u16(raw: &[u16], channels: usize, srgb: bool) -> Vec<Vec4> {
    let unorm = |v: u16| f32::from(v) / 65535.0;
    if srgb {
        // Exact formula: a 65536-entry table would cost more than it saves here.
        expand(
            raw,
            channels,
            |v| srgb_eotf(f64::from(v) / 65535.0) as f32,
            unorm,
        )
    } else {
        expand(raw, channels, unorm, unorm)
    }
}

fn expand_f32(raw: &[f32], channels: usize, srgb: bool) -> Vec<Vec4> {
    let same = |v: f32| v;
    if srgb {
        expand(raw, channels, srgb_to_linear, same)
    } else {
        expand(raw, channels, same, same)
    }
}

/// Pixels a compressed image (PNG, JPEG, ...) may declare per byte of file: deflate's
/// largest expansion is 1032:1, times 8 pixels per byte at 1 bit per pixel. JPEG's is
/// lower (at best ~2 bits per 8x8 block per component).
const MAX_PIXELS_PER_COMPRESSED_BYTE: u64 = 8 * 1032;

/// The header of a binary or ASCII PNM file (P1-P6): its sample layout.
struct PnmHeader {
    /// `P1`..`P6` as 1..6.
    kind: u8,
    /// The largest sample value (1 for bitmaps).
    max_value: u32,
    /// Byte offset of the first sample.
    data_offset: usize,
}

/// Parses the header of a PNM file; `None` when `bytes` is not one (or is malformed: the
/// decoder then reports it).
fn pnm_header(bytes: &[u8]) -> Option<PnmHeader> {
    let kind = match bytes {
        [b'P', k @ b'1'..=b'6', ..] => k - b'0',
        _ => return None,
    };
    let fields = if matches!(kind, 1 | 4) { 2 } else { 3 };
    let mut values = Vec::with_capacity(3);
    let mut i = 2;
    while values.len() < fields {
        match bytes.get(i)? {
            b'#' => {
                while *bytes.get(i)? != b'\n' {
                    i += 1;
                }
            }
            c if c.is_ascii_whitespace() => i += 1,
            c if c.is_ascii_digit() => {
                let start = i;
                while bytes.get(i).is_some_and(u8::is_ascii_digit) {
                    i += 1;
                }
                values.push(
                    std::str::from_utf8(&bytes[start..i])
                        .ok()?
                        .parse::<u32>()
                        .ok()?,
                );
            }
            _ => return None,
        }
    }
    Some(PnmHeader {
        kind,
        max_value: if fields == 3 { values[2] } else { 1 },
        // One whitespace byte ends the header.
        data_offset: i + 1,
    })
}

/// Checks that `width x height` pixels can be backed by `bytes`, before anything is
/// allocated for them: exactly for binary PNM (P4-P6: packed samples), at least one digit
/// and a separator per sample for ASCII PNM (P1-P3), and at most
/// [`MAX_PIXELS_PER_COMPRESSED_BYTE`] pixels per byte for compressed formats.
fn check_size_backed_by_bytes(bytes: &[u8], width: u32, height: u32) -> Result<(), TextureError> {
    let pixels = width as u64 * height as u64;
    let len = bytes.len() as u64;
    let short = |needed: u64, what: &str| {
        TextureError::Decode(format!(
            "the header declares {width}x{height} pixels, which need {needed} bytes of {what}, \
             but the file has {len} bytes"
        ))
    };
    let Some(header) = pnm_header(bytes) else {
        let needed = pixels.div_ceil(MAX_PIXELS_PER_COMPRESSED_BYTE);
        return if len < needed {
            Err(short(needed, "compressed data at the least"))
        } else {
            Ok(())
        };
    };
    let channels: u64 = if matches!(header.kind, 3 | 6) { 3 } else { 1 };
    let samples = pixels * channels;
    let data = len.saturating_sub(header.data_offset as u64);
    let needed = match header.kind {
        4 => (width as u64).div_ceil(8) * height as u64,
        5 | 6 => samples * if header.max_value > 255 { 2 } else { 1 },
        // ASCII: a digit per sample and separators between them (P1 may omit those).
        1 => samples,
        _ => 2 * samples - 1,
    };
    if data < needed {
        return Err(short(needed, "pixel data"));
    }
    Ok(())
}

fn decode_error(e: impl std::fmt::Display) -> TextureError {
    TextureError::Decode(e.to_string())
}

/// How an image's colour channels are encoded (alpha is always linear).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColorEncoding {
    /// sRGB-encoded colour (base colour textures): decoded to linear.
    Srgb,
    /// Already linear data (normal maps, roughness): taken as is.
    Linear,
}

/// Decodes an encoded image (PNG, JPEG, PPM, ...) into linear RGBA texels; colour channels
/// in `encoding` ([`ColorEncoding::Srgb`] ones are converted to linear), alpha linear.
///
/// Returns `(width, height, texels)` with row 0 = top row = v = 0. Any decoder failure
/// (unknown format, truncated or corrupt data) is [`TextureError::Decode`] with the
/// decoder's message; a zero or over-[`MAX_SIZE`] side, or a size the file's bytes cannot
/// hold (see `check_size_backed_by_bytes`), is rejected from the header, before the pixel
/// buffer is allocated.
pub fn decode_texels(
    bytes: &[u8],
    encoding: ColorEncoding,
) -> Result<(u32, u32, Vec<Vec4>), TextureError> {
    let srgb = encoding == ColorEncoding::Srgb;
    let mut limits = Limits::default();
    limits.max_alloc = Some(MAX_DECODE_ALLOC);
    let reader = |limits: Limits| {
        let mut r = ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(decode_error)?;
        r.limits(limits);
        Ok::<_, TextureError>(r)
    };
    // Header first, so an absurd size gets its own error and nothing is allocated for it.
    // (Without side limits here: the decoder would reject it with a less precise message.)
    let (width, height) = reader(limits.clone())?
        .into_dimensions()
        .map_err(decode_error)?;
    check_size(width, height)?;
    check_size_backed_by_bytes(bytes, width, height)?;

    // The side limits again inside the decoder, for formats whose header could disagree
    // with what they then decode.
    limits.max_image_width = Some(MAX_SIZE);
    limits.max_image_height = Some(MAX_SIZE);
    let img = reader(limits)?.decode().map_err(decode_error)?;
    let (width, height) = (img.width(), img.height());
    check_size(width, height)?;
    let texels = match img {
        DynamicImage::ImageLuma8(b) => expand_u8(b.as_raw(), 1, srgb),
        DynamicImage::ImageLumaA8(b) => expand_u8(b.as_raw(), 2, srgb),
        DynamicImage::ImageRgb8(b) => expand_u8(b.as_raw(), 3, srgb),
        DynamicImage::ImageRgba8(b) => expand_u8(b.as_raw(), 4, srgb),
        DynamicImage::ImageLuma16(b) => expand_u16(b.as_raw(), 1, srgb),
        DynamicImage::ImageLumaA16(b) => expand_u16(b.as_raw(), 2, srgb),
        DynamicImage::ImageRgb16(b) => expand_u16(b.as_raw(), 3, srgb),
        DynamicImage::ImageRgba16(b) => expand_u16(b.as_raw(), 4, srgb),
        DynamicImage::ImageRgb32F(b) => expand_f32(b.as_raw(), 3, srgb),
        DynamicImage::ImageRgba32F(b) => expand_f32(b.as_raw(), 4, srgb),
        // `DynamicImage` is non-exhaustive: anything newer goes through image's own
        // conversion to f32 RGBA.
        other => expand_f32(other.to_rgba32f().as_raw(), 4, srgb),
    };
    let expected = width as usize * height as usize;
    if texels.len() != expected {
        return Err(TextureError::WrongLength {
            got: texels.len(),
            expected,
        });
    }
    Ok((width, height, texels))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{ImageBuffer, ImageFormat, Luma, LumaA, Rgb, Rgba};

    fn encode<P, C>(buf: &ImageBuffer<P, C>, format: ImageFormat) -> Vec<u8>
    where
        P: image::Pixel + image::PixelWithColorType,
        [P::Subpixel]: image::EncodableLayout,
        C: std::ops::Deref<Target = [P::Subpixel]>,
    {
        let mut out = Cursor::new(Vec::new());
        buf.write_to(&mut out, format).unwrap();
        out.into_inner()
    }

    fn close(a: Vec4, b: Vec4, tol: f32) -> bool {
        (a - b).abs().max_element() <= tol
    }

    /// The index's search gives the binary search's answer for floats of every kind: a
    /// stride through all 2^32 bit patterns (both signs, subnormals, infinities, NaNs), and
    /// every table value and its two float neighbours.
    #[test]
    fn the_indexed_search_is_the_binary_search() {
        for index in [&*SRGB8_INDEX, &*ALPHA8_INDEX] {
            let check = |value: f32| {
                assert_eq!(
                    index.first_not_below(value),
                    index.table.partition_point(|&t| t < value),
                    "{value:e} ({:#x})",
                    value.to_bits()
                );
            };
            for bits in (0..=u32::MAX).step_by(4099) {
                check(f32::from_bits(bits));
            }
            for &t in index.table {
                for bits in [t.to_bits().wrapping_sub(1), t.to_bits(), t.to_bits() + 1] {
                    check(f32::from_bits(bits));
                }
            }
            for value in [
                0.0,
                -0.0,
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::NAN,
                1.0,
                0.5,
            ] {
                check(value);
            }
        }
    }

    #[test]
    fn srgb_eotf_reference_values() {
        let lut = &*SRGB8_LUT;
        assert!((lut[128] - 0.2158605).abs() < 1e-6, "{}", lut[128]);
        assert_eq!(lut[255], 1.0);
        // Every table value finds its own code, and values between codes find none.
        let tables = Srgb8Tables::get();
        for code in 0..=255u8 {
            let texel = tables.texel([code, 255 - code, code / 2, code]);
            assert_eq!(
                tables.codes(texel),
                Some([code, 255 - code, code / 2, code])
            );
            let between = Vec4::new(
                f32::from_bits(texel.x.to_bits() + 1),
                texel.y,
                texel.z,
                texel.w,
            );
            assert_eq!(tables.codes(between), None, "{code}");
        }
        assert_eq!(tables.codes(Vec4::new(-0.0, 0.0, 0.0, 1.0)), None);
        assert_eq!(tables.codes(Vec4::new(f32::NAN, 0.0, 0.0, 1.0)), None);
        assert_eq!(lut[0], 0.0);
        // Linear segment: 10/255 = 0.0392 <= 0.04045.
        assert!((lut[10] - 10.0 / 255.0 / 12.92).abs() < 1e-9);
        assert!(
            lut.windows(2).all(|w| w[0] < w[1]),
            "LUT must be increasing"
        );
        assert!((srgb_to_linear(0.5) - 0.21404114).abs() < 1e-6);
        assert_eq!(srgb_to_linear(1.0), 1.0);
    }

    #[test]
    fn png_rgba8_orientation_values_and_srgb() {
        // 3x2: row 0 = red, green, blue; row 1 = (128,128,128,64), black, white half alpha.
        let px: [[u8; 4]; 6] = [
            [255, 0, 0, 255],
            [0, 255, 0, 255],
            [0, 0, 255, 255],
            [128, 128, 128, 64],
            [0, 0, 0, 0],
            [255, 255, 255, 128],
        ];
        let buf = ImageBuffer::from_fn(3, 2, |x, y| Rgba(px[(y * 3 + x) as usize]));
        let png = encode(&buf, ImageFormat::Png);

        let (w, h, t) = decode_texels(&png, ColorEncoding::Srgb).unwrap();
        assert_eq!((w, h, t.len()), (3, 2, 6));
        assert_eq!(t[0], Vec4::new(1.0, 0.0, 0.0, 1.0));
        assert_eq!(t[1], Vec4::new(0.0, 1.0, 0.0, 1.0));
        assert_eq!(t[2], Vec4::new(0.0, 0.0, 1.0, 1.0));
        let g = 0.2158605;
        assert!(
            close(t[3], Vec4::new(g, g, g, 64.0 / 255.0), 1e-6),
            "{}",
            t[3]
        );
        assert_eq!(t[4], Vec4::ZERO);
        // Alpha stays linear even with srgb.
        assert!(close(t[5], Vec4::new(1.0, 1.0, 1.0, 128.0 / 255.0), 1e-7));

        let (_, _, lin) = decode_texels(&png, ColorEncoding::Linear).unwrap();
        let half = 128.0 / 255.0;
        assert!(close(
            lin[3],
            Vec4::new(half, half, half, 64.0 / 255.0),
            1e-7
        ));
        assert_eq!(lin[0], t[0]);
    }

    #[test]
    fn png_gray_and_gray_alpha() {
        let buf = ImageBuffer::from_fn(2, 2, |x, y| Luma([(x * 255 + y * 10) as u8]));
        let (w, h, t) =
            decode_texels(&encode(&buf, ImageFormat::Png), ColorEncoding::Srgb).unwrap();
        assert_eq!((w, h), (2, 2));
        assert_eq!(t[0], Vec4::new(0.0, 0.0, 0.0, 1.0));
        assert_eq!(t[1], Vec4::ONE);
        let g = SRGB8_LUT[10];
        assert_eq!(t[2], Vec4::new(g, g, g, 1.0));

        let buf = ImageBuffer::from_fn(2, 1, |x, _| LumaA([128u8, 51 * x as u8]));
        let (_, _, t) =
            decode_texels(&encode(&buf, ImageFormat::Png), ColorEncoding::Srgb).unwrap();
        assert!(close(
            t[1],
            Vec4::new(0.2158605, 0.2158605, 0.2158605, 0.2),
            1e-6
        ));
        assert_eq!(t[0].w, 0.0);
    }

    #[test]
    fn png_16bit_rgb_and_rgba() {
        // 1x2 RGB16: row 0 = (65535, 0, 32768), row 1 = (1000, 2000, 3000).
        let rows = [[65535u16, 0, 32768], [1000, 2000, 3000]];
        let buf = ImageBuffer::from_fn(1, 2, |_, y| Rgb(rows[y as usize]));
        let png = encode(&buf, ImageFormat::Png);
        let (w, h, t) = decode_texels(&png, ColorEncoding::Linear).unwrap();
        assert_eq!((w, h), (1, 2));
        assert!(close(
            t[0],
            Vec4::new(1.0, 0.0, 32768.0 / 65535.0, 1.0),
            1e-7
        ));
        assert!(close(
            t[1],
            Vec4::new(1000.0, 2000.0, 3000.0, 65535.0) / 65535.0,
            1e-7
        ));
        let (_, _, s) = decode_texels(&png, ColorEncoding::Srgb).unwrap();
        let exact = |v: u16| srgb_eotf(f64::from(v) / 65535.0) as f32;
        assert_eq!(s[0], Vec4::new(1.0, 0.0, exact(32768), 1.0));
        // 32768/65535 is just above 0.5: its linear value is just above 0.2140411.
        assert!((s[0].z - 0.2140411).abs() < 1e-5);
        assert_eq!(s[1], Vec4::new(exact(1000), exact(2000), exact(3000), 1.0));

        let buf = ImageBuffer::from_fn(1, 1, |_, _| Rgba([65535u16, 65535, 65535, 13107]));
        let (_, _, t) =
            decode_texels(&encode(&buf, ImageFormat::Png), ColorEncoding::Srgb).unwrap();
        assert!(close(t[0], Vec4::new(1.0, 1.0, 1.0, 0.2), 1e-7), "{}", t[0]);
    }

    #[test]
    fn ppm_and_pgm_decode() {
        // Binary PPM, 2x1: (255, 0, 128), (0, 64, 255).
        let mut ppm = b"P6\n2 1\n255\n".to_vec();
        ppm.extend_from_slice(&[255, 0, 128, 0, 64, 255]);
        let (w, h, t) = decode_texels(&ppm, ColorEncoding::Linear).unwrap();
        assert_eq!((w, h), (2, 1));
        assert!(close(t[0], Vec4::new(1.0, 0.0, 128.0 / 255.0, 1.0), 1e-7));
        assert!(close(t[1], Vec4::new(0.0, 64.0 / 255.0, 1.0, 1.0), 1e-7));
        // ASCII PGM, 1x2, gray rows 0 then 255: row order is top first.
        let (w, h, t) = decode_texels(b"P2\n1 2\n255\n0\n255\n", ColorEncoding::Srgb).unwrap();
        assert_eq!((w, h), (1, 2));
        assert_eq!(t, [Vec4::new(0.0, 0.0, 0.0, 1.0), Vec4::ONE]);
    }

    #[test]
    fn jpeg_decodes_roughly() {
        let buf = ImageBuffer::from_fn(8, 8, |_, _| Rgb([200u8, 100, 50]));
        let jpg = encode(&buf, ImageFormat::Jpeg);
        let (w, h, t) = decode_texels(&jpg, ColorEncoding::Linear).unwrap();
        assert_eq!((w, h, t.len()), (8, 8, 64));
        let want = Vec4::new(200.0, 100.0, 50.0, 255.0) / 255.0;
        assert!(t.iter().all(|&p| close(p, want, 0.03)), "{}", t[0]);
    }

    #[test]
    fn truncated_png_is_decode_error() {
        let buf = ImageBuffer::from_fn(16, 16, |x, y| Rgba([x as u8 * 16, y as u8 * 16, 7, 255]));
        let png = encode(&buf, ImageFormat::Png);
        for cut in [png.len() / 2, png.len() - 20, 40, 8] {
            match decode_texels(&png[..cut], ColorEncoding::Linear) {
                Err(TextureError::Decode(msg)) => assert!(!msg.is_empty()),
                other => panic!("cut at {cut}: expected Decode error, got {other:?}"),
            }
        }
        assert!(matches!(
            decode_texels(b"not an image at all", ColorEncoding::Linear),
            Err(TextureError::Decode(_))
        ));
        assert!(matches!(
            decode_texels(&[], ColorEncoding::Linear),
            Err(TextureError::Decode(_))
        ));
    }

    #[test]
    fn zero_and_absurd_sizes_are_rejected() {
        // PNM headers allow any size; none of these may panic or allocate.
        for header in [&b"P6\n0 0\n255\n"[..], b"P6\n0 5\n255\n", b"P5\n4 0\n255\n"] {
            assert!(decode_texels(header, ColorEncoding::Linear).is_err());
        }
        let huge = b"P6\n100000 100000\n255\n";
        assert!(matches!(
            decode_texels(huge, ColorEncoding::Linear),
            Err(TextureError::TooLarge {
                width: 100000,
                height: 100000,
                max: MAX_SIZE
            })
        ));
        let wide = b"P5\n20000 1\n255\n";
        assert!(matches!(
            decode_texels(wide, ColorEncoding::Linear),
            Err(TextureError::TooLarge {
                width: 20000,
                height: 1,
                ..
            })
        ));
    }

    #[test]
    fn pnm_sizes_the_bytes_cannot_hold_are_refused_before_decoding() {
        for file in [
            &b"P6\n16000 16000\n255\n\x00\x01"[..],
            b"P5 # comment\n4 4\n65535\n0123456789abcdef",
            b"P3\n100 100\n255\n1 2 3",
            b"P4\n64 64\n\xff",
        ] {
            let e = decode_texels(file, ColorEncoding::Srgb)
                .unwrap_err()
                .to_string();
            assert!(e.contains("declares") && e.contains("bytes"), "{e}");
        }
    }

    #[test]
    fn pnm_sizes_backed_by_their_bytes_decode() {
        let ok = decode_texels(
            b"P6\n2 1\n255\n\x00\x01\x02\x03\x04\x05",
            ColorEncoding::Srgb,
        )
        .unwrap();
        assert_eq!((ok.0, ok.1), (2, 1));
        let ascii = decode_texels(b"P3 1 1 255 0 0 255\n", ColorEncoding::Linear).unwrap();
        assert_eq!(ascii.2[0], Vec4::new(0.0, 0.0, 1.0, 1.0));
    }

    #[test]
    fn compressed_images_may_not_claim_more_pixels_than_deflate_can_expand_to() {
        // A valid 16x16 PNG with IHDR patched to 16384x16384 (and its CRC fixed): a few
        // hundred bytes cannot inflate to 268M pixels.
        let mut png = encode(&ImageBuffer::<Luma<u8>, _>::new(16, 16), ImageFormat::Png);
        png[16..20].copy_from_slice(&16384u32.to_be_bytes());
        png[20..24].copy_from_slice(&16384u32.to_be_bytes());
        let crc = crc32(&png[12..29]);
        png[29..33].copy_from_slice(&crc.to_be_bytes());
        let e = decode_texels(&png, ColorEncoding::Srgb)
            .unwrap_err()
            .to_string();
        assert!(e.contains("declares 16384x16384"), "{e}");
    }

    /// CRC-32 (ISO-HDLC), as PNG chunks use.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }
}
