//! Textures: decoded images, box-filtered MIP pyramids built once at load, filtered lookup.
//!
//! The module is split by concept:
//! - [`decode`](decode_texels): encoded bytes (PNG, JPEG, PNM) -> linear RGBA texels;
//! - `pyramid`: level 0 -> the full box-filtered pyramid ([`MipPyramid::from_linear_rgba`]);
//! - `sample`: wrap modes, bilinear and trilinear lookup (the renderer's hot path);
//! - `ewa`: elliptically weighted average over the pyramid (pbrt-v4's EWA filter).
//!
//! Conventions shared by all three:
//! - texels are linear RGBA `Vec4`, row-major, row 0 is the image's top row and sits at
//!   v = 0 (glTF convention: no flip anywhere);
//! - texel `(i, j)` of a `w x h` level has its centre at `((i + 0.5) / w, (j + 0.5) / h)`;
//! - a pyramid always has at least one level, and every level's `texels.len()` is
//!   `width * height` (guaranteed by [`MipPyramid::from_linear_rgba`], relied on by lookup);
//! - sizes are 1..=[`MAX_SIZE`] per side.

mod decode;
mod ewa;
mod pyramid;
mod sample;

mod fetch;
mod taps;

pub use decode::{ColorEncoding, decode_texels, srgb_to_linear};
pub use sample::PlannedLookup;

use glam::Vec4;

/// Largest accepted texture side, in texels. Anything larger is treated as corrupt or
/// hostile input rather than allocated (16384² RGBA f32 is already 4 GiB).
pub const MAX_SIZE: u32 = 16384;

/// How texture coordinates outside [0, 1] are mapped back (glTF sampler wrap modes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WrapMode {
    /// Tile: texel index taken modulo the size (glTF `REPEAT`, the default).
    #[default]
    Repeat,
    /// Indices outside the image use the nearest edge texel (glTF `CLAMP_TO_EDGE`).
    ClampToEdge,
    /// Tile with every other copy mirrored, period two sizes (glTF `MIRRORED_REPEAT`).
    MirroredRepeat,
}

/// Per-axis wrap modes (s = u, t = v).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sampler {
    pub wrap_s: WrapMode,
    pub wrap_t: WrapMode,
}

/// One level of a pyramid: linear RGBA texels, row-major, row 0 at v = 0.
#[derive(Debug, Clone)]
pub struct MipLevel {
    pub width: u32,
    pub height: u32,
    /// `width * height` texels; texel `(x, y)` is at `y * width + x`.
    texels: Texels,
}

/// How a level keeps its texels. Every level of an 8-bit image keeps 8-bit codes (4 bytes
/// per texel instead of 16) and decodes them through the tables its loader used: texture
/// lookups of whole frames wait on texel loads, and a quarter of the bytes keeps more of a
/// texture in cache. Level 0 holds the image's own codes, so every lookup there returns the
/// same `Vec4` bit for bit as the decoded image; a reduced level holds, per channel, the
/// code whose value is nearest the box-filtered value (computed from the unrounded levels
/// above it), as a GPU's sRGB MIP chain stores it. 16-bit and float images keep linear
/// `f32` at every level.
#[derive(Debug, Clone)]
enum Texels {
    Linear(Vec<Vec4>),
    /// sRGB-encoded colour codes and linear alpha codes, with the decoding tables (held
    /// here so a lookup does not go through the tables' lazy initialisation).
    Srgb8 {
        codes: Vec<[u8; 4]>,
        tables: decode::Srgb8Tables,
    },
}

impl MipLevel {
    /// A level of `width * height` linear texels (the caller checks the length).
    fn linear(width: u32, height: u32, texels: Vec<Vec4>) -> MipLevel {
        MipLevel {
            width,
            height,
            texels: Texels::Linear(texels),
        }
    }

    /// Texel `i` (`y * width + x`) as linear RGBA, whatever the storage: the one accessor
    /// for filters that read texels one by one.
    #[inline(always)]
    pub fn texel(&self, i: usize) -> Vec4 {
        match &self.texels {
            Texels::Linear(t) => t[i],
            Texels::Srgb8 { codes, tables } => tables.texel(codes[i]),
        }
    }

    /// Hints the cache to load texel `i` (`y * width + x`; nothing when out of range).
    #[inline(always)]
    fn prefetch(&self, i: usize) {
        match &self.texels {
            Texels::Linear(t) => crate::simd::prefetch(t, i),
            Texels::Srgb8 { codes, .. } => crate::simd::prefetch(codes, i),
        }
    }

    /// Every texel in order.
    pub fn texels(&self) -> impl ExactSizeIterator<Item = Vec4> + '_ {
        (0..self.width as usize * self.height as usize).map(|i| self.texel(i))
    }

    /// Whether the level keeps 8-bit codes (see [`Texels`]).
    pub fn is_8bit(&self) -> bool {
        matches!(self.texels, Texels::Srgb8 { .. })
    }

    /// Keeps the texels as 8-bit codes when every one of them is exactly what the 8-bit
    /// sRGB decoding produces for some code; otherwise leaves the level as it is. Returns
    /// whether the level keeps codes.
    fn store_8bit_if_exact(&mut self) -> bool {
        let Texels::Linear(texels) = &self.texels else {
            return true;
        };
        let tables = decode::Srgb8Tables::get();
        let codes: Option<Vec<[u8; 4]>> = texels.iter().map(|&t| tables.codes(t)).collect();
        let Some(codes) = codes else {
            return false;
        };
        self.texels = Texels::Srgb8 { codes, tables };
        true
    }

    /// Keeps, per channel, the 8-bit code whose decoded value is nearest the texel's (for
    /// the reduced levels of an 8-bit image).
    fn store_nearest_8bit(&mut self) {
        let Texels::Linear(texels) = &self.texels else {
            return;
        };
        let tables = decode::Srgb8Tables::get();
        let codes = texels.iter().map(|&t| tables.nearest_codes(t)).collect();
        self.texels = Texels::Srgb8 { codes, tables };
    }
}

/// A MIP pyramid: level 0 is the source image; each next level halves each side (floor,
/// at least 1) until 1x1.
#[derive(Debug, Clone)]
pub struct MipPyramid {
    /// Never empty; `levels[k + 1]` is the box-filtered reduction of `levels[k]`.
    pub levels: Vec<MipLevel>,
}

/// A texture as the renderer samples it.
#[derive(Debug, Clone)]
pub struct Texture {
    /// File name or glTF image name, for messages and `info`.
    pub name: String,
    pub pyramid: MipPyramid,
    pub sampler: Sampler,
}

/// Why an image could not become a texture.
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    #[error("image has zero size ({width}x{height})")]
    Empty { width: u32, height: u32 },
    #[error("image is {width}x{height}, larger than the {max}x{max} limit")]
    TooLarge { width: u32, height: u32, max: u32 },
    #[error("texel data has {got} texels, expected {expected}")]
    WrongLength { got: usize, expected: usize },
    #[error("cannot decode image: {0}")]
    Decode(String),
}

/// Checks a texture size against the accepted range (1..=[`MAX_SIZE`] per side).
pub fn check_size(width: u32, height: u32) -> Result<(), TextureError> {
    if width == 0 || height == 0 {
        return Err(TextureError::Empty { width, height });
    }
    if width > MAX_SIZE || height > MAX_SIZE {
        return Err(TextureError::TooLarge {
            width,
            height,
            max: MAX_SIZE,
        });
    }
    Ok(())
}

impl MipPyramid {
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Level-0 size in texels.
    pub fn base_size(&self) -> (u32, u32) {
        (self.levels[0].width, self.levels[0].height)
    }

    /// Maps any level to [0, last]: NaN -> 0, +inf -> last, negative -> 0.
    pub fn clamp_level(&self, lod: f32) -> f32 {
        // `f32::max` returns the non-NaN operand, so NaN becomes 0 here.
        lod.max(0.0).min((self.levels.len() - 1) as f32)
    }
}
