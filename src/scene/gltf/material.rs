//! Materials and base-colour textures: glTF metallic/roughness mapped to the Whitted model.
//!
//! # Metallic/roughness -> Whitted mapping
//! With metallic `m` and roughness `r` (factors, clamped to [0, 1]; their textures are
//! ignored):
//! - `reflectance = m * (1 - r)^2`: only smooth metals are mirrors; rough or dielectric
//!   surfaces reflect through the highlight alone.
//! - `specular = 0.5 * (1 - r)^2`: the Phong highlight fades as the surface roughens.
//! - `shininess = 2 / max(r^4, 1e-4) - 2`, clamped to [1, 10000]: the Blinn-Phong exponent
//!   equivalent to a GGX lobe with `alpha = r^2` (`n = 2 / alpha^2 - 2`).
//! - `transmission` = `KHR_materials_transmission` factor (its texture is ignored, with a
//!   note); `ior` = `KHR_materials_ior` (default 1.5, clamped to [1, 4]; the spec's special
//!   value 0 means an infinite IOR, so it becomes 4).
//! - `base_color` = the RGB of `baseColorFactor` (already linear); alpha is ignored.
//!
//! One [`Texture`] is built per glTF texture used as a base colour, decoded as sRGB into a
//! MIP pyramid once per image (textures sharing an image share the decode).

use std::collections::HashMap;
use std::path::Path;

use glam::{Vec2, Vec3};

use super::buffers::{Buffers, image_bytes};
use crate::scene::MaterialDesc;
use crate::texture::{
    ColorEncoding, MipFilter, MipPyramid, Sampler, Texture, WrapMode, decode_texels,
};

/// Largest index of refraction kept; also what the spec's "infinite" IOR (0) becomes.
const MAX_IOR: f32 = 4.0;

/// Loads every material and the base-colour textures they use.
pub(super) fn load_materials(
    document: &gltf::Document,
    buffers: &Buffers,
    base_dir: &Path,
    notes: &mut Vec<String>,
) -> Result<(Vec<MaterialDesc>, Vec<Texture>), String> {
    let mut textures = TextureLoader {
        buffers,
        base_dir,
        by_gltf_texture: HashMap::new(),
        by_image: HashMap::new(),
        textures: Vec::new(),
    };
    let mut ignored_maps = 0;
    let mut ignored_transmission_textures = 0;
    let mut materials = Vec::new();
    for material in document.materials() {
        let index = material.index().unwrap_or_default();
        let what = format!("material {index}");
        let pbr = material.pbr_metallic_roughness();
        let base_color_texture = match pbr.base_color_texture() {
            Some(info) => Some(
                textures
                    .index_of(&info.texture())
                    .map_err(|e| format!("{what}: {e}"))?,
            ),
            None => None,
        };
        if pbr.metallic_roughness_texture().is_some()
            || material.normal_texture().is_some()
            || material.occlusion_texture().is_some()
            || material.emissive_texture().is_some()
        {
            ignored_maps += 1;
        }
        let transmission = match material.transmission() {
            Some(t) => {
                if t.transmission_texture().is_some() {
                    ignored_transmission_textures += 1;
                }
                finite(t.transmission_factor(), &what, "transmission factor")?.clamp(0.0, 1.0)
            }
            None => 0.0,
        };
        let [r, g, b, _alpha] = pbr.base_color_factor();
        let base_color = Vec3::new(r, g, b);
        if !base_color.is_finite() {
            return Err(format!("{what} has a non-finite base colour factor"));
        }
        let metallic = finite(pbr.metallic_factor(), &what, "metallic factor")?.clamp(0.0, 1.0);
        let roughness = finite(pbr.roughness_factor(), &what, "roughness factor")?.clamp(0.0, 1.0);
        materials.push(MaterialDesc {
            name: material.name().unwrap_or_default().to_string(),
            base_color: base_color.max(Vec3::ZERO),
            base_color_texture,
            reflectance: reflectance(metallic, roughness),
            transmission,
            ior: ior(material.ior().unwrap_or(1.5), &what)?,
            shininess: shininess(roughness),
            specular: specular(roughness),
            double_sided: material.double_sided(),
            ambient: None,
            shading: crate::scene::Shading::Physical,
        });
    }
    if ignored_maps > 0 {
        notes.push(format!(
            "{ignored_maps} material(s) use metallic-roughness, normal, occlusion or emissive textures, which are ignored (factors only)"
        ));
    }
    if ignored_transmission_textures > 0 {
        notes.push(format!(
            "{ignored_transmission_textures} material(s) use a transmission texture, which is ignored (factor only)"
        ));
    }
    Ok((materials, textures.textures))
}

fn finite(value: f32, what: &str, name: &str) -> Result<f32, String> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(format!("{what} has a non-finite {name}"))
    }
}

/// Mirror reflectance: smooth metals reflect, rough ones do not.
fn reflectance(metallic: f32, roughness: f32) -> f32 {
    metallic * (1.0 - roughness).powi(2)
}

/// Phong highlight strength, fading with roughness.
fn specular(roughness: f32) -> f32 {
    0.5 * (1.0 - roughness).powi(2)
}

/// Blinn-Phong exponent equivalent to GGX with `alpha = roughness^2`.
fn shininess(roughness: f32) -> f32 {
    (2.0 / roughness.powi(4).max(1e-4) - 2.0).clamp(1.0, 10000.0)
}

/// `KHR_materials_ior` value to the renderer's range; 0 is the spec's infinite IOR.
fn ior(value: f32, what: &str) -> Result<f32, String> {
    let value = finite(value, what, "ior")?;
    Ok(if value == 0.0 {
        MAX_IOR
    } else {
        value.clamp(1.0, MAX_IOR)
    })
}

/// Which UV set a material's base-colour texture reads, and the transform applied to it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct UvSource {
    pub set: u32,
    pub transform: Option<UvTransform>,
}

/// `KHR_texture_transform`: `uv' = T * R * S * uv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct UvTransform {
    pub offset: Vec2,
    pub rotation: f32,
    pub scale: Vec2,
}

impl UvTransform {
    /// Scales, rotates, then offsets `uv`. The rotation is counter-clockwise in UV space
    /// (v down): `u' = cos*u + sin*v`, `v' = -sin*u + cos*v`. The GLSL listing in the
    /// extension's README builds the transposed matrix (GLSL is column-major); that is a
    /// known erratum (KhronosGroup/glTF issue 1563), and this direction is the one the
    /// TextureTransformTest sample model checks and that viewers implement.
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let scaled = uv * self.scale;
        let (sin, cos) = self.rotation.sin_cos();
        let rotated = Vec2::new(
            cos * scaled.x + sin * scaled.y,
            -sin * scaled.x + cos * scaled.y,
        );
        rotated + self.offset
    }
}

/// The UV set and transform of a material's base-colour texture, `None` if untextured.
pub(super) fn uv_source(material: &gltf::Material) -> Option<UvSource> {
    let info = material.pbr_metallic_roughness().base_color_texture()?;
    let transform = info.texture_transform();
    let set = transform
        .as_ref()
        .and_then(|t| t.tex_coord())
        .unwrap_or(info.tex_coord());
    let transform = transform.map(|t| UvTransform {
        offset: Vec2::from(t.offset()),
        rotation: t.rotation(),
        scale: Vec2::from(t.scale()),
    });
    Some(UvSource { set, transform })
}

/// Builds each used glTF texture once, decoding each image once.
struct TextureLoader<'b> {
    buffers: &'b Buffers,
    base_dir: &'b Path,
    /// glTF texture index -> index into `textures`.
    by_gltf_texture: HashMap<usize, usize>,
    /// glTF image index -> index into `textures` of the first texture built from it.
    by_image: HashMap<usize, usize>,
    textures: Vec<Texture>,
}

impl TextureLoader<'_> {
    /// Index into the scene's textures of glTF texture `texture`, loading it on first use.
    fn index_of(&mut self, texture: &gltf::Texture) -> Result<usize, String> {
        if let Some(&index) = self.by_gltf_texture.get(&texture.index()) {
            return Ok(index);
        }
        let image = texture.source();
        let (pyramid, name) = match self.by_image.get(&image.index()) {
            // Another texture (other sampler) shares the image: reuse its pyramid.
            Some(&shared) => (
                self.textures[shared].pyramid.clone(),
                self.textures[shared].name.clone(),
            ),
            None => self.decode_pyramid(&image)?,
        };
        let sampler = texture.sampler();
        self.textures.push(Texture {
            name,
            pyramid,
            sampler: Sampler {
                wrap_s: wrap_mode(sampler.wrap_s()),
                wrap_t: wrap_mode(sampler.wrap_t()),
                mip: mip_filter(sampler.min_filter()),
            },
        });
        let index = self.textures.len() - 1;
        self.by_gltf_texture.insert(texture.index(), index);
        self.by_image.entry(image.index()).or_insert(index);
        Ok(index)
    }

    /// Decodes an image as sRGB colour into a MIP pyramid; returns it with the image's name.
    fn decode_pyramid(&self, image: &gltf::Image) -> Result<(MipPyramid, String), String> {
        let (bytes, name) = image_bytes(image, self.buffers, self.base_dir)?;
        let what = format!("image {} ('{name}')", image.index());
        let (width, height, texels) =
            decode_texels(&bytes, ColorEncoding::Srgb).map_err(|e| format!("{what}: {e}"))?;
        let pyramid = MipPyramid::from_linear_rgba(width, height, texels)
            .map_err(|e| format!("{what}: {e}"))?;
        Ok((pyramid, name))
    }
}

fn wrap_mode(mode: gltf::texture::WrappingMode) -> WrapMode {
    match mode {
        gltf::texture::WrappingMode::ClampToEdge => WrapMode::ClampToEdge,
        gltf::texture::WrappingMode::MirroredRepeat => WrapMode::MirroredRepeat,
        gltf::texture::WrappingMode::Repeat => WrapMode::Repeat,
    }
}

/// The MIP half of a sampler's minification filter. mipray MIP-maps every texture and
/// filters within a level bilinearly, so a filter without MIP-maps (`NEAREST`, `LINEAR`)
/// and the texel half (`NEAREST_*` against `LINEAR_*`) are not read: only whether the
/// levels are blended (`*_MIPMAP_LINEAR`, and no filter given) or the nearest is read
/// alone (`*_MIPMAP_NEAREST`).
fn mip_filter(filter: Option<gltf::texture::MinFilter>) -> MipFilter {
    use gltf::texture::MinFilter;
    match filter {
        Some(MinFilter::NearestMipmapNearest | MinFilter::LinearMipmapNearest) => {
            MipFilter::Nearest
        }
        _ => MipFilter::Linear,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_mipmap_nearest_filters_read_one_level() {
        use gltf::texture::MinFilter;
        for (filter, want) in [
            (None, MipFilter::Linear),
            (Some(MinFilter::LinearMipmapLinear), MipFilter::Linear),
            (Some(MinFilter::NearestMipmapLinear), MipFilter::Linear),
            (Some(MinFilter::Linear), MipFilter::Linear),
            (Some(MinFilter::Nearest), MipFilter::Linear),
            (Some(MinFilter::LinearMipmapNearest), MipFilter::Nearest),
            (Some(MinFilter::NearestMipmapNearest), MipFilter::Nearest),
        ] {
            assert_eq!(mip_filter(filter), want, "{filter:?}");
        }
    }

    #[test]
    fn smooth_metal_is_a_mirror_and_rough_dielectric_is_matte() {
        assert_eq!(reflectance(1.0, 0.0), 1.0);
        assert_eq!(reflectance(0.0, 0.0), 0.0);
        assert_eq!(reflectance(1.0, 1.0), 0.0);
        assert_eq!(specular(1.0), 0.0);
        assert_eq!(shininess(1.0), 1.0);
        assert_eq!(shininess(0.0), 10000.0);
        // r = 0.5: alpha = 0.25, n = 2 / 0.0625 - 2 = 30.
        assert!((shininess(0.5) - 30.0).abs() < 1e-4);
    }

    #[test]
    fn ior_zero_is_infinite_and_range_is_clamped() {
        assert_eq!(ior(0.0, "m").unwrap(), MAX_IOR);
        assert_eq!(ior(1.33, "m").unwrap(), 1.33);
        assert_eq!(ior(0.5, "m").unwrap(), 1.0);
        assert_eq!(ior(9.0, "m").unwrap(), MAX_IOR);
        assert!(ior(f32::NAN, "m").is_err());
    }

    #[test]
    fn uv_transform_rotates_counter_clockwise_in_v_down_space() {
        let quarter = UvTransform {
            offset: Vec2::ZERO,
            rotation: std::f32::consts::FRAC_PI_2,
            scale: Vec2::ONE,
        };
        // u axis goes to -v (up on the image): counter-clockwise as seen with v down.
        assert!((quarter.apply(Vec2::X) - Vec2::new(0.0, -1.0)).length() < 1e-6);
        let all = UvTransform {
            offset: Vec2::new(0.5, 0.25),
            rotation: 0.0,
            scale: Vec2::new(2.0, 3.0),
        };
        assert_eq!(all.apply(Vec2::new(1.0, 1.0)), Vec2::new(2.5, 3.25));
    }
}
