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
    /// [`highlight_floor`] of `shininess`: below it the highlight is exactly zero.
    pub highlight_floor: f32,
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

/// The cosine below which the highlight `cos^shininess` is exactly zero in f32: `powf`
/// returns +0 there, so shading can leave the call out and add nothing (0 where no cosine
/// in `[0, 1]` qualifies: a zero, negative or NaN exponent, or one so small that the floor
/// itself is below f32's range).
///
/// Why: `powf` was 2.4% of a BART Robots frame, much of it on results that underflow
/// (glossy materials lit at wide angles: Robots' exponents reach 255), where libm takes its
/// slowest path. `floor^shininess = 2^-152`, an eighth of f32's smallest subnormal
/// (2^-149): libm's `powf` (glibc's and musl's) computes the power in f64 and rounds it to
/// f32 once, so a cosine below the floor, whose true power is below 2^-152, gives +0; the
/// floor's own rounding to f32 moves that power by a factor of at most
/// `(1 + 2^-24)^shininess`, nowhere near the factor of 4 to the rounding point for any
/// exponent a material has (the loaders cap it at 10,000). The test below checks this
/// libm on cosines up to the floor.
pub fn highlight_floor(shininess: f32) -> f32 {
    if shininess > 0.0 {
        (-152.0 / f64::from(shininess)).exp2() as f32
    } else {
        0.0
    }
}

impl Material {
    /// Whether parameters add up term by term (see [`ShadingModel::Additive`]).
    #[inline]
    pub fn is_additive(&self) -> bool {
        matches!(self.model, ShadingModel::Additive { .. })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Below the floor `powf` gives exactly +0, for exponents across the loaders' range and
    /// beyond; at 1 the power is 1 (never floored), and no exponent floors a cosine of 1.
    #[test]
    fn below_the_highlight_floor_the_power_is_exactly_zero() {
        for shininess in [
            1e-3, 0.5, 1.0, 2.0, 7.5, 20.0, 32.0, 100.0, 128.0, 1000.0, 4096.0, 10_000.0, 1e6,
        ] {
            let floor = highlight_floor(shininess);
            assert!((0.0..1.0).contains(&floor), "{shininess}: {floor}");
            // Only an exponent up to about 1 has a floor below f32's range (and floors nothing).
            assert_eq!(floor > 0.0, shininess > 1.5, "{shininess}: {floor}");
            let mut below = vec![floor.next_down(), f32::MIN_POSITIVE, 1e-30, 0.0];
            // A spread of cosines below the floor, down to a thousandth of it.
            below.extend(
                (1..=1000)
                    .map(|i| floor * (i as f32 / 1000.0))
                    .filter(|&x| x < floor),
            );
            for x in below.into_iter().filter(|_| floor > 0.0) {
                let power = x.powf(shininess);
                assert_eq!(power.to_bits(), 0, "{x}^{shininess} = {power:e}");
            }
            assert_eq!(1f32.powf(shininess), 1.0);
        }
        for shininess in [0.0, -0.0, -3.0, f32::NAN] {
            assert_eq!(highlight_floor(shininess), 0.0, "{shininess}");
        }
        assert_eq!(highlight_floor(f32::INFINITY), 1.0);
    }
}
