//! Textures: decoded images, box-filtered MIP pyramids built once at load, filtered lookup.
//! (API stub: the implementation lands with the texture module.)

use glam::{Vec2, Vec4};

/// How texture coordinates outside [0, 1] are mapped back (glTF sampler wrap modes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WrapMode {
    #[default]
    Repeat,
    ClampToEdge,
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
    pub texels: Vec<Vec4>,
}

/// A MIP pyramid: level 0 is the source image; each next level halves each side (floor,
/// at least 1) until 1x1.
#[derive(Debug, Clone)]
pub struct MipPyramid {
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

impl MipPyramid {
    /// Builds the pyramid from linear RGBA level-0 texels.
    pub fn from_linear_rgba(width: u32, height: u32, texels: Vec<Vec4>) -> Result<Self, TextureError> {
        let _ = (width, height, texels);
        todo!("texture module")
    }

    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Level-0 size in texels.
    pub fn base_size(&self) -> (u32, u32) {
        (self.levels[0].width, self.levels[0].height)
    }

    /// Maps any level to [0, last]: NaN -> 0, +inf -> last, negative -> 0.
    pub fn clamp_level(&self, lod: f32) -> f32 {
        lod.max(0.0).min((self.levels.len() - 1) as f32)
    }

    /// Bilinear lookup in one level.
    pub fn sample_bilinear(&self, level: usize, uv: Vec2, sampler: Sampler) -> Vec4 {
        let _ = (level, uv, sampler);
        todo!("texture module")
    }

    /// Trilinear lookup at a fractional level (clamped with [`Self::clamp_level`]).
    pub fn sample_trilinear(&self, uv: Vec2, lod: f32, sampler: Sampler) -> Vec4 {
        let _ = (uv, lod, sampler);
        todo!("texture module")
    }
}

/// Decodes an encoded image (PNG, JPEG, PPM, ...) into linear RGBA texels.
/// `srgb`: colour channels are sRGB-encoded (base colour) and are decoded to linear;
/// alpha is always linear.
pub fn decode_image(bytes: &[u8], srgb: bool) -> Result<(u32, u32, Vec<Vec4>), TextureError> {
    let _ = (bytes, srgb);
    todo!("texture module")
}
