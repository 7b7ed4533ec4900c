//! Materials (`fm`, `f`) and PPM textures, deduplicated.
//!
//! Mapping (FORMAT.md 1.8, NFF/SPD Whitted convention):
//! - `base_color` = diffuse (multiplied by the texture, which modulates diffuse and ambient);
//! - `reflectance` (mirror) and `specular` (Phong highlight) = mean of the specular RGB;
//! - `shininess` = the Phong exponent as given (no x4 OpenGL scaling);
//! - `transmission` = T, `ior` = the given index, `<= 0` meaning 1.0 (straight through);
//! - `ambient` = the ambient RGB (the scene's `am` is `SceneDesc::ambient`);
//! - `double_sided` always (NFF transmitters are two-sided and mesh winding is unreliable).
//!
//! `fm` is global state (not scoped by `{}` or includes). A material is created when
//! geometry first uses a (material state, texture) pair; identical pairs share one.
//! Before any `fm`, geometry uses white diffuse and nothing else (noted).
//!
//! Textures: binary PPM (P6, `#` header comments allowed) decoded as sRGB (8-bit
//! display-referred images) to linear, wrap REPEAT on both axes, row 0 of the file at v = 0
//! (FORMAT.md 1.7). Cached by name: one [`Texture`] per distinct file name.

use std::collections::HashMap;
use std::path::PathBuf;

use glam::Vec3;

use super::includes::Files;
use crate::scene::MaterialDesc;
use crate::texture::{
    ColorEncoding, MipFilter, MipPyramid, Sampler, Texture, WrapMode, decode_texels,
};

/// An `fm` state: ambient, diffuse, specular, shine, T, ior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fm {
    pub ambient: Vec3,
    pub diffuse: Vec3,
    pub specular: Vec3,
    pub shine: f32,
    pub transmission: f32,
    pub ior: f32,
}

impl Fm {
    /// The state before any `fm`: white diffuse only.
    pub const DEFAULT: Fm = Fm {
        ambient: Vec3::ZERO,
        diffuse: Vec3::ONE,
        specular: Vec3::ZERO,
        shine: 0.0,
        transmission: 0.0,
        ior: 1.0,
    };

    fn key(&self) -> [u32; 12] {
        let v = [
            self.ambient.x,
            self.ambient.y,
            self.ambient.z,
            self.diffuse.x,
            self.diffuse.y,
            self.diffuse.z,
            self.specular.x,
            self.specular.y,
            self.specular.z,
            self.shine,
            self.transmission,
            self.ior,
        ];
        v.map(f32::to_bits)
    }

    /// The description of this state with an optional base-colour texture.
    pub fn to_desc(&self, name: String, texture: Option<usize>) -> MaterialDesc {
        let spec = (self.specular.x + self.specular.y + self.specular.z) / 3.0;
        MaterialDesc {
            name,
            base_color: self.diffuse.max(Vec3::ZERO),
            base_color_texture: texture,
            reflectance: spec.clamp(0.0, 1.0),
            transmission: self.transmission.clamp(0.0, 1.0),
            ior: if self.ior <= 0.0 { 1.0 } else { self.ior },
            shininess: self.shine.max(0.0),
            specular: spec.max(0.0),
            double_sided: true,
            ambient: Some(self.ambient.max(Vec3::ZERO)),
            shading: crate::scene::Shading::Nff,
        }
    }
}

/// Materials and textures of the scene being loaded.
#[derive(Default)]
pub struct Materials {
    pub materials: Vec<MaterialDesc>,
    pub textures: Vec<Texture>,
    by_key: HashMap<([u32; 12], Option<usize>), usize>,
    texture_by_name: HashMap<String, usize>,
    /// How many `fm`/`f` commands were read (for material names).
    pub states_read: usize,
    /// Whether geometry used [`Fm::DEFAULT`].
    pub used_default: bool,
}

impl Materials {
    /// The material index for geometry with state `fm` and `texture`.
    pub fn material(&mut self, fm: Option<&Fm>, texture: Option<usize>) -> usize {
        let state = match fm {
            Some(f) => *f,
            None => {
                self.used_default = true;
                Fm::DEFAULT
            }
        };
        let key = (state.key(), texture);
        if let Some(&i) = self.by_key.get(&key) {
            return i;
        }
        let i = self.materials.len();
        let name = match texture {
            Some(t) => format!("fm{} {}", i, self.textures[t].name),
            None => format!("fm{i}"),
        };
        self.materials.push(state.to_desc(name, texture));
        self.by_key.insert(key, i);
        i
    }

    /// The texture named `name` (a bare file name), loaded on first use from the first of
    /// `candidates` that exists.
    pub fn texture(
        &mut self,
        name: &str,
        candidates: &[PathBuf],
        files: &mut Files,
    ) -> Result<usize, String> {
        if let Some(&i) = self.texture_by_name.get(name) {
            return Ok(i);
        }
        let Some(path) = candidates.iter().find(|p| files.exists(p)) else {
            let looked: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
            return Err(format!(
                "texture '{name}' not found (looked in {})",
                looked.join(", ")
            ));
        };
        let bytes = files
            .read(path)
            .map_err(|e| format!("texture '{name}': {e}"))?;
        let (width, height, texels) = decode_texels(&bytes, ColorEncoding::Srgb)
            .map_err(|e| format!("texture '{}': {e}", path.display()))?;
        let pyramid = MipPyramid::from_linear_rgba(width, height, texels)
            .map_err(|e| format!("texture '{}': {e}", path.display()))?;
        let i = self.textures.len();
        self.textures.push(Texture {
            name: name.to_string(),
            pyramid,
            sampler: Sampler {
                wrap_s: WrapMode::Repeat,
                wrap_t: WrapMode::Repeat,
                mip: MipFilter::Linear,
            },
        });
        self.texture_by_name.insert(name.to_string(), i);
        Ok(i)
    }
}
