//! Textures: decoded images, box-filtered MIP pyramids built once at load, filtered lookup.
//!
//! The module is split by concept:
//! - [`decode`](decode_texels): encoded bytes (PNG, JPEG, PNM) -> linear RGBA texels;
//! - `pyramid`: level 0 -> the full box-filtered pyramid ([`MipPyramid::from_linear_rgba`]);
//! - `sample`: wrap modes, bilinear and trilinear lookup (the renderer's hot path);
//! - `ewa`: elliptically weighted average over the pyramid (pbrt-v4's EWA filter).
//!
//! Conventions shared by all three:
//! - texels are linear RGBA `Vec4`, numbered row-major (`y * width + x`), row 0 is the
//!   image's top row and sits at v = 0 (glTF convention: no flip anywhere); 8-bit levels
//!   store them in 4 x 4 blocks, which only the lookup's taps see ([`MipLevel`]);
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

/// How a lookup whose level lies between two MIP levels reads them (the MIP half of
/// glTF's minification filters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum MipFilter {
    /// Both levels, bilinear in each and blended by the level's fraction: trilinear (glTF
    /// `*_MIPMAP_LINEAR`, the default).
    #[default]
    Linear,
    /// The nearest level alone, ties to the finer one (OpenGL's rule for glTF
    /// `*_MIPMAP_NEAREST`): one bilinear lookup, so cheaper, with a visible step where a
    /// surface's level crosses a half.
    Nearest,
}

impl MipFilter {
    /// The name the command line, the frame records and OBJ export use.
    pub fn name(self) -> &'static str {
        match self {
            MipFilter::Linear => "linear",
            MipFilter::Nearest => "nearest",
        }
    }

    /// The filter [`Self::name`] calls `name`.
    pub fn from_name(name: &str) -> Option<MipFilter> {
        use clap::ValueEnum;
        MipFilter::value_variants()
            .iter()
            .copied()
            .find(|f| f.name() == name)
    }
}

/// Per-axis wrap modes (s = u, t = v) and how levels are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sampler {
    pub wrap_s: WrapMode,
    pub wrap_t: WrapMode,
    pub mip: MipFilter,
}

/// One level of a pyramid: linear RGBA texels, row 0 at v = 0.
///
/// Texels are named two ways: by their row-major number `y * width + x` ([`MipLevel::texel`],
/// [`MipLevel::texels`]: the public order), and by where the storage keeps them
/// (`MipLevel::row_start` + `MipLevel::column_offset`: what a lookup's taps hold).
/// The two agree for float levels; 8-bit levels keep their codes in 4 x 4 blocks.
#[derive(Debug, Clone)]
pub struct MipLevel {
    pub width: u32,
    pub height: u32,
    /// Whether `width` and `height` are both powers of two (the lookups' f32 shortcut,
    /// `taps.rs`), decided once per level instead of twice per lookup.
    sides_power_of_two: bool,
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
        codes: BlockedCodes,
        tables: decode::Srgb8Tables,
    },
}

/// Sixteen texels' codes, a 4 x 4 block (row by row), in one cache line.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(64))]
struct CodeBlock([[u8; 4]; 16]);

// SAFETY: `CodeBlock` is `repr(C)` over 64 bytes with alignment 64, so it has no padding,
// and every bit pattern is a valid array of bytes.
unsafe impl bytemuck::Zeroable for CodeBlock {}
// SAFETY: as above; it is `Copy` and `'static`.
unsafe impl bytemuck::Pod for CodeBlock {}

/// A level's 8-bit codes in 4 x 4 blocks, each block one cache line, blocks row by row
/// (the last column and row of blocks padded with zero codes that no lookup reads).
///
/// Why: a bilinear lookup reads a 2 x 2 square of texels. Row-major, its two rows are
/// always two cache lines (and often two pages, for a wide image); in blocks, the square
/// lies in one line nine times in sixteen, and neighbouring lookups (a tile's pixels,
/// which land near each other in the texture in both directions) share lines and pages.
#[derive(Debug, Clone)]
struct BlockedCodes {
    blocks: Vec<CodeBlock>,
    /// Blocks per row of blocks: `ceil(width / 4)`.
    blocks_across: usize,
}

impl BlockedCodes {
    /// The codes of a `width x height` level given row-major.
    fn from_row_major(width: u32, height: u32, codes: &[[u8; 4]]) -> BlockedCodes {
        let (w, h) = (width as usize, height as usize);
        debug_assert_eq!(codes.len(), w * h);
        let blocks_across = w.div_ceil(4);
        let mut blocked = BlockedCodes {
            blocks: vec![CodeBlock::default(); blocks_across * h.div_ceil(4)],
            blocks_across,
        };
        for y in 0..h {
            let start = blocked.row_start(y);
            let flat = blocked.flat_mut();
            for (x, &code) in codes[y * w..(y + 1) * w].iter().enumerate() {
                flat[start + Self::column_offset(x)] = code;
            }
        }
        blocked
    }

    /// Every code (padding included), indexed by `row_start(y) + column_offset(x)`.
    #[inline(always)]
    fn flat(&self) -> &[[u8; 4]] {
        bytemuck::cast_slice(&self.blocks)
    }

    fn flat_mut(&mut self) -> &mut [[u8; 4]] {
        bytemuck::cast_slice_mut(&mut self.blocks)
    }

    /// Where row `y`'s part of a texel's index starts.
    #[inline(always)]
    fn row_start(&self, y: usize) -> usize {
        (y >> 2) * self.blocks_across * 16 + (y & 3) * 4
    }

    /// Column `x`'s part of a texel's index.
    #[inline(always)]
    fn column_offset(x: usize) -> usize {
        (x >> 2) * 16 + (x & 3)
    }
}

impl MipLevel {
    /// A level of `width * height` linear texels (the caller checks the length).
    fn linear(width: u32, height: u32, texels: Vec<Vec4>) -> MipLevel {
        MipLevel {
            width,
            height,
            sides_power_of_two: width.is_power_of_two() && height.is_power_of_two(),
            texels: Texels::Linear(texels),
        }
    }

    /// Whether both sides are powers of two.
    #[inline(always)]
    pub(super) fn sides_power_of_two(&self) -> bool {
        self.sides_power_of_two
    }

    /// For a level of 8-bit codes, the storage distance from one row of 4 x 4 blocks to
    /// the next (so [`MipLevel::row_start`] of `y` is `(y >> 2) * stride + (y & 3) * 4`);
    /// `None` for float texels. At most `MAX_SIZE / 4 * 16 = 2^16`.
    #[inline(always)]
    pub(super) fn block_row_stride(&self) -> Option<u32> {
        match &self.texels {
            Texels::Srgb8 { codes, .. } => Some((codes.blocks_across * 16) as u32),
            Texels::Linear(_) => None,
        }
    }

    /// Texel number `i` (`y * width + x`) as linear RGBA, whatever the storage.
    #[inline(always)]
    pub fn texel(&self, i: usize) -> Vec4 {
        let w = self.width as usize;
        self.texel_at(i % w, i / w)
    }

    /// Texel `(x, y)` as linear RGBA, whatever the storage: the one accessor for filters
    /// that read texels one by one.
    #[inline(always)]
    pub fn texel_at(&self, x: usize, y: usize) -> Vec4 {
        match &self.texels {
            Texels::Linear(t) => t[y * self.width as usize + x],
            Texels::Srgb8 { codes, tables } => {
                let i = codes.row_start(y) + BlockedCodes::column_offset(x);
                tables.texel(codes.flat()[i])
            }
        }
    }

    /// Where row `y`'s part of a texel's storage index starts; the index of texel
    /// `(x, y)` is `row_start(y) + column_offset(x)`.
    #[inline(always)]
    pub(super) fn row_start(&self, y: usize) -> usize {
        match &self.texels {
            Texels::Linear(_) => y * self.width as usize,
            Texels::Srgb8 { codes, .. } => codes.row_start(y),
        }
    }

    /// Column `x`'s part of a texel's storage index (see [`MipLevel::row_start`]).
    #[inline(always)]
    pub(super) fn column_offset(&self, x: usize) -> usize {
        match &self.texels {
            Texels::Linear(_) => x,
            Texels::Srgb8 { .. } => BlockedCodes::column_offset(x),
        }
    }

    /// Hints the cache to load the texels at storage indices `texels` (a bilinear lookup's
    /// four, in [`taps::BilinearTaps::texels`] order). Unchecked: a prefetch never faults,
    /// so an index out of range only hints a useless line (planned taps are always in
    /// range), and the hints cost no bounds checks.
    ///
    /// Float texels (16 bytes, rows apart): all four. 8-bit codes in 4 x 4 blocks: the
    /// first and the last texel only. Their blocks are every block the 2 x 2 square touches
    /// unless it crosses both a block column and a block row (one lookup in sixteen), when
    /// the other two blocks go unhinted: half the hints for the lines of fifteen lookups
    /// in sixteen. A hint changes no result.
    #[inline(always)]
    fn prefetch_texels(&self, texels: [u32; 4]) {
        use crate::simd::prefetch_ptr;
        match &self.texels {
            Texels::Linear(t) => {
                for i in texels {
                    prefetch_ptr(t.as_ptr().wrapping_add(i as usize));
                }
            }
            Texels::Srgb8 { codes, .. } => {
                let flat = codes.flat().as_ptr();
                prefetch_ptr(flat.wrapping_add(texels[0] as usize));
                prefetch_ptr(flat.wrapping_add(texels[3] as usize));
            }
        }
    }

    /// How many texels the level's storage holds (an 8-bit level's blocks are padded):
    /// every tap's index is below it.
    #[cfg(test)]
    pub(super) fn storage_len(&self) -> usize {
        match &self.texels {
            Texels::Linear(t) => t.len(),
            Texels::Srgb8 { codes, .. } => codes.flat().len(),
        }
    }

    /// Every texel in row-major order.
    pub fn texels(&self) -> impl ExactSizeIterator<Item = Vec4> + '_ {
        (0..self.width as usize * self.height as usize).map(|i| self.texel(i))
    }

    /// Whether the level keeps 8-bit codes (see `Texels`).
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
        let codes = BlockedCodes::from_row_major(self.width, self.height, &codes);
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
        let codes: Vec<[u8; 4]> = texels.iter().map(|&t| tables.nearest_codes(t)).collect();
        let codes = BlockedCodes::from_row_major(self.width, self.height, &codes);
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
        // `f32::max` returns the non-NaN operand, so NaN becomes 0 here. The last level's
        // number through `u32` (at most 14, see `MAX_SIZE`): one conversion, where x86-64
        // converts a `usize` with a sign test and two paths.
        lod.max(0.0).min((self.levels.len() - 1) as u32 as f32)
    }

    /// The level a lookup at `lod` reads, after [`Self::clamp_level`], and the fraction
    /// towards the next one.
    #[inline(always)]
    pub fn clamp_and_split_level(&self, lod: f32) -> (usize, f32) {
        let lod = self.clamp_level(lod);
        // In `[0, last]` (finite, at most 14) truncation is the floor and needs no
        // saturation: on x86-64 one conversion instruction, not `as u32`'s conversion,
        // two comparisons and two selects.
        #[cfg(target_arch = "x86_64")]
        // SAFETY: SSE is part of x86_64; the intrinsics compute on registers only.
        let k = unsafe { std::arch::x86_64::_mm_cvttss_si32(std::arch::x86_64::_mm_set_ss(lod)) };
        #[cfg(not(target_arch = "x86_64"))]
        let k = lod as i32;
        (k as usize, lod - k as f32)
    }

    /// The level a one-level lookup ([`MipFilter::Nearest`]) at `lod` reads: the nearest to
    /// [`Self::clamp_level`]'s level, ties to the finer (OpenGL's `ceil(lod + 1/2) - 1`
    /// above level 0), from the same split as [`Self::clamp_and_split_level`].
    #[inline(always)]
    pub fn nearest_level(&self, lod: f32) -> usize {
        let (k, frac) = self.clamp_and_split_level(lod);
        // At the last level the fraction is 0 (the clamp), so this never passes it.
        let nearest = k + usize::from(frac > 0.5);
        debug_assert!(nearest < self.levels.len(), "level {nearest} of {lod}");
        nearest
    }

    /// The level a lookup at `lod` reads with `mip` (the lower of two when it blends): what
    /// its plan's [`PlannedLookup::level`] says, for lookups that are not planned.
    #[inline(always)]
    pub fn level_read(&self, lod: f32, mip: MipFilter) -> usize {
        match mip {
            MipFilter::Linear => self.clamp_and_split_level(lod).0,
            MipFilter::Nearest => self.nearest_level(lod),
        }
    }

    /// The level below `lod` (a level in `[0, last]`, as [`Self::clamp_level`] gives it)
    /// and the fraction towards the next one: the plain form of
    /// [`Self::clamp_and_split_level`], kept as the tests' reference for it.
    #[cfg(test)]
    pub fn split_level(lod: f32) -> (usize, f32) {
        // In `[0, last]` truncation is the floor. Through `u32`: x86-64 converts an `f32`
        // to a `usize` with two conversions and a select (no unsigned 64-bit conversion
        // before AVX-512), to a `u32` with one, and both saturate (NaN gives 0).
        let k = lod as u32;
        (k as usize, lod - k as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The command line's words (clap's) are the records' and OBJ export's (`name`), and
    /// `from_name` reads them back.
    #[test]
    fn mip_filter_names_agree_everywhere() {
        use clap::ValueEnum;
        for &f in MipFilter::value_variants() {
            let clap_name = f.to_possible_value().expect("a name").get_name().to_owned();
            assert_eq!(clap_name, f.name());
            assert_eq!(MipFilter::from_name(f.name()), Some(f));
        }
        assert_eq!(MipFilter::from_name("cubic"), None);
        assert_eq!(MipFilter::from_name("Linear"), None);
    }

    /// The flag the lookups' shortcut reads is the sides' own test, for every size a
    /// pyramid makes (each level of a power-of-two image, down to 1 x 1, is one too).
    #[test]
    fn a_level_knows_whether_its_sides_are_powers_of_two() {
        for (w, h) in [
            (1, 1),
            (1, 8),
            (16, 2),
            (4, 4),
            (3, 4),
            (4, 3),
            (6, 6),
            (1, 3),
        ] {
            let level = MipLevel::linear(w, h, vec![Vec4::ZERO; (w * h) as usize]);
            let want = w.is_power_of_two() && h.is_power_of_two();
            assert_eq!(level.sides_power_of_two(), want, "{w} x {h}");
        }
        let pyramid = MipPyramid::from_linear_rgba(64, 16, vec![Vec4::ONE; 64 * 16]).unwrap();
        assert!(pyramid.levels.iter().all(MipLevel::sides_power_of_two));
        let pyramid = MipPyramid::from_linear_rgba(48, 5, vec![Vec4::ONE; 48 * 5]).unwrap();
        for level in &pyramid.levels {
            let want = level.width.is_power_of_two() && level.height.is_power_of_two();
            assert_eq!(level.sides_power_of_two(), want);
        }
    }

    /// Blocked 8-bit storage: every texel of a level of any size has its own storage index
    /// inside the codes, and reads back the texel it was given, in both namings.
    #[test]
    fn blocked_codes_give_every_texel_its_own_place() {
        let tables = decode::Srgb8Tables::get();
        for (w, h) in [
            (1, 1),
            (1, 7),
            (5, 1),
            (4, 4),
            (3, 5),
            (8, 12),
            (37, 21),
            (261, 6),
        ] {
            let texels: Vec<Vec4> = (0..w * h)
                .map(|i: u32| tables.texel((i.wrapping_mul(0x9E37_79B9) ^ i).to_le_bytes()))
                .collect();
            let mut level = MipLevel::linear(w, h, texels.clone());
            assert!(level.store_8bit_if_exact());
            let Texels::Srgb8 { codes, .. } = &level.texels else {
                unreachable!()
            };
            let mut seen = vec![false; codes.flat().len()];
            for y in 0..h as usize {
                for x in 0..w as usize {
                    let at = level.row_start(y) + level.column_offset(x);
                    assert!(
                        !std::mem::replace(&mut seen[at], true),
                        "{w}x{h}: ({x}, {y}) shares {at}"
                    );
                    let want = texels[y * w as usize + x];
                    assert_eq!(level.texel_at(x, y).to_array(), want.to_array());
                    assert_eq!(level.texel(y * w as usize + x).to_array(), want.to_array());
                }
            }
            assert!(
                level.texels().eq(texels.iter().copied()),
                "{w}x{h} in row-major order"
            );
        }
    }
}
