//! A surface's appearance in the integrator's own terms: the Whitted parameters and the
//! shading model that combines them.
//!
//! The renderer does not know which file format a material came from: `frame::appearance`
//! builds these from the scene description, and the integrator reads only this type. Two
//! models exist because the two conventions the loaders meet weigh the same parameters
//! differently; each is named for what it computes.

use glam::Vec3;

/// One material, indexed by `FrameTriangles::material`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Linear RGB base colour factor (multiplies the texture).
    pub base_color: Vec3,
    /// Index into the frame's textures; `None` (or out of range) is untextured.
    pub base_color_texture: Option<usize>,
    /// Mirror reflectance in [0, 1].
    pub reflectance: f32,
    /// Specular transmission in [0, 1].
    pub transmission: f32,
    /// Index of refraction.
    pub ior: f32,
    /// Phong exponent of the highlight of direct light.
    pub shininess: f32,
    /// Phong highlight strength.
    pub specular: f32,
    /// How the parameters combine.
    pub model: ShadingModel,
}

/// How a material's parameters combine into reflected radiance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ShadingModel {
    /// Lobes weighted so the diffuse, mirror and transmitted parts share one unit of
    /// energy (glTF-style): diffuse `(1 - transmission)(1 - reflectance)`, mirror reflection
    /// tinted by the base colour (metal), transmission tinted by it and split by Fresnel;
    /// the renderer's fixed ambient light.
    EnergyWeighted,
    /// Every term added at its own weight (the NFF/Whitted convention of AFF files,
    /// FORMAT.md 1.8): `scene ambient * ambient * tex + sum_lights(diffuse * tex * N.L +
    /// highlight) + reflectance * L_reflect + transmission * L_refract`, reflection and
    /// refraction untinted, no Fresnel.
    Additive {
        /// Ambient reflectance (linear RGB), multiplied by the scene's ambient light.
        ambient: Vec3,
    },
}

impl Material {
    /// Whether parameters add up term by term (see [`ShadingModel::Additive`]).
    #[inline]
    pub fn is_additive(&self) -> bool {
        matches!(self.model, ShadingModel::Additive { .. })
    }
}
