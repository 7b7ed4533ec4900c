//! Materials of authored scenes: glTF metallic-roughness with an optional base-colour
//! texture, plus `KHR_materials_transmission` and `KHR_materials_ior`.
//!
//! Invariants checked by the builder: factors lie in [0, 1], `ior >= 1`.

use glam::{Vec3, Vec4};

use super::handles::ImageId;

/// How texture coordinates outside [0, 1] map back into the image (glTF sampler wrap).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum WrapMode {
    /// Tile the image (glTF `REPEAT`, the default).
    #[default]
    Repeat,
    /// Use the edge texel (glTF `CLAMP_TO_EDGE`).
    ClampToEdge,
    /// Tile, flipping every other copy (glTF `MIRRORED_REPEAT`).
    MirroredRepeat,
}

/// A material's use of an image: which image, and how it wraps along U (s) and V (t).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TextureBinding {
    /// The image sampled.
    pub image: ImageId,
    /// Wrap along U.
    pub wrap_s: WrapMode,
    /// Wrap along V.
    pub wrap_t: WrapMode,
}

impl TextureBinding {
    /// `image` with the same wrap mode on both axes.
    pub fn new(image: ImageId, wrap: WrapMode) -> Self {
        TextureBinding {
            image,
            wrap_s: wrap,
            wrap_t: wrap,
        }
    }
}

/// A metallic-roughness material, with optional specular transmission.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Shown by viewers; need not be unique.
    pub name: String,
    /// Linear RGBA base colour factor (multiplies the texture).
    pub base_color: Vec4,
    /// sRGB base-colour image, read with the primitive's `TEXCOORD_0`.
    pub base_color_texture: Option<TextureBinding>,
    /// In [0, 1].
    pub metallic: f32,
    /// In [0, 1].
    pub roughness: f32,
    /// `KHR_materials_transmission` factor in [0, 1]; `None` leaves the extension out.
    pub transmission: Option<f32>,
    /// `KHR_materials_ior` index of refraction (>= 1); `None` leaves the extension out.
    pub ior: Option<f32>,
    /// Whether back faces are shaded too (glTF `doubleSided`).
    pub double_sided: bool,
}

impl Material {
    /// A dielectric diffuse-looking surface: `color`, metallic 0, roughness 1.
    pub fn matte(name: &str, color: Vec3) -> Self {
        Material {
            name: name.into(),
            base_color: color.extend(1.0),
            base_color_texture: None,
            metallic: 0.0,
            roughness: 1.0,
            transmission: None,
            ior: None,
            double_sided: false,
        }
    }

    /// A matte surface whose base colour is `texture` (white factor).
    pub fn textured(name: &str, texture: TextureBinding) -> Self {
        Material {
            base_color_texture: Some(texture),
            ..Material::matte(name, Vec3::ONE)
        }
    }

    /// A perfect mirror: metallic 1, roughness 0, tinted by `color`.
    pub fn mirror(name: &str, color: Vec3) -> Self {
        Material {
            metallic: 1.0,
            roughness: 0.0,
            ..Material::matte(name, color)
        }
    }

    /// Clear glass: white, metallic 0, roughness 0, transmission 1, the given `ior`.
    pub fn glass(name: &str, ior: f32) -> Self {
        Material {
            roughness: 0.0,
            transmission: Some(1.0),
            ior: Some(ior),
            ..Material::matte(name, Vec3::ONE)
        }
    }
}
