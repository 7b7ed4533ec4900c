//! Lights placed in world space for one frame, and the point lights `--lights N` adds.
//!
//! Units follow KHR_lights_punctual: point and spot intensity in candela (irradiance
//! `I / d^2` at distance d), directional in lux. `range` fades the light to zero with the
//! extension's recommended window `clamp(1 - (d/range)^4, 0, 1)`. A light whose description
//! has `inverse_square: false` (AFF/NFF point lights) skips the `1 / d^2`: its irradiance is
//! `color * intensity` at any distance (range window and spot cone still apply).
//!
//! A [`LightSource`] is what a scene light emits, built once from the scene description by
//! `frame::appearance`; [`Light::placed`] puts it at its node's world transform each frame.

use glam::{Mat4, Vec3, Vec3A};

/// The shape of a light's emission.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LightKind {
    /// Radiates from its origin; intensity in candela.
    Point,
    /// Shines along its -Z; intensity in lux.
    Directional,
    /// Point light restricted to a cone along -Z (angles in radians).
    Spot { inner_cone: f32, outer_cone: f32 },
}

/// A light before placement: what it emits, in its own frame (origin, shining along -Z).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSource {
    pub kind: LightKind,
    /// Linear RGB colour times intensity (non-negative).
    pub intensity: Vec3,
    /// Distance past which the light has no effect (`None`: unlimited; always positive).
    pub range: Option<f32>,
    /// Whether irradiance falls off as `1 / d^2` (`false`: AFF/NFF point lights).
    pub inverse_square: bool,
}

/// A light placed in world space for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    pub kind: LightKind,
    pub position: Vec3A,
    /// Unit direction the light shines along (directional and spot).
    pub direction: Vec3A,
    /// Colour times intensity.
    pub intensity: Vec3A,
    pub range: Option<f32>,
    /// Whether irradiance falls off as `1 / d^2` (see [`LightSource::inverse_square`]).
    pub inverse_square: bool,
    /// A spot's `[cos(outer_cone), cos(inner_cone)]`, taken once when the light is placed
    /// rather than for every point it lights (two library calls each); unused otherwise.
    cone_cosines: [f32; 2],
}

/// `[cos(outer_cone), cos(inner_cone)]` of a spot light (zeros for other kinds).
fn cone_cosines(kind: LightKind) -> [f32; 2] {
    match kind {
        LightKind::Spot {
            inner_cone,
            outer_cone,
        } => [outer_cone.cos(), inner_cone.cos()],
        LightKind::Point | LightKind::Directional => [0.0; 2],
    }
}

/// What a light delivers to a point: unit direction towards the light, distance to it
/// (infinite for directional) and irradiance on a surface facing it.
#[derive(Debug, Clone, Copy)]
pub struct Incident {
    pub to_light: Vec3A,
    pub distance: f32,
    pub irradiance: Vec3A,
}

impl Light {
    /// Places a light source at its node's world transform.
    pub fn placed(source: &LightSource, world_from_light: Mat4) -> Light {
        let position = world_from_light.transform_point3(Vec3::ZERO).into();
        let direction = world_from_light
            .transform_vector3(Vec3::NEG_Z)
            .try_normalize()
            .unwrap_or(Vec3::NEG_Y)
            .into();
        Light {
            kind: source.kind,
            position,
            direction,
            intensity: source.intensity.into(),
            range: source.range,
            inverse_square: source.inverse_square,
            cone_cosines: cone_cosines(source.kind),
        }
    }

    /// A white point light.
    pub fn point(position: Vec3, intensity: f32) -> Light {
        Light {
            kind: LightKind::Point,
            position: position.into(),
            direction: Vec3A::NEG_Y,
            intensity: Vec3A::splat(intensity),
            range: None,
            inverse_square: true,
            cone_cosines: cone_cosines(LightKind::Point),
        }
    }

    /// Light arriving at `p`, or `None` where it delivers nothing (behind a spot, out of range).
    #[inline]
    pub fn incident(&self, p: Vec3A) -> Option<Incident> {
        if let LightKind::Directional = self.kind {
            return Some(Incident {
                to_light: -self.direction,
                distance: f32::INFINITY,
                irradiance: self.intensity,
            });
        }
        let offset = self.position - p;
        let d2 = offset.length_squared();
        if !(d2 > 0.0) || !d2.is_finite() {
            return None;
        }
        let distance = d2.sqrt();
        let to_light = offset / distance;
        let mut falloff = if self.inverse_square { 1.0 / d2 } else { 1.0 };
        if let Some(range) = self.range {
            let x = distance / range;
            falloff *= (1.0 - x * x * x * x).clamp(0.0, 1.0);
        }
        if let LightKind::Spot { .. } = self.kind {
            let cos_angle = (-to_light).dot(self.direction);
            let [cos_outer, cos_inner] = self.cone_cosines;
            let t = if cos_inner > cos_outer {
                (cos_angle - cos_outer) / (cos_inner - cos_outer)
            } else {
                1.0
            };
            let t = if cos_angle < cos_outer {
                0.0
            } else {
                t.clamp(0.0, 1.0)
            };
            falloff *= t * t;
        }
        (falloff > 0.0).then_some(Incident {
            to_light,
            distance,
            irradiance: self.intensity * falloff,
        })
    }
}

/// Point lights added when a render asks for more lights than the scene has: spread evenly
/// on a ring above the scene bounds, each delivering irradiance ~`3 / total` at the centre
/// (so the total stays roughly constant as lights are added; the paper sweeps 1 to 6).
pub fn ring_lights(min: Vec3, max: Vec3, count: usize, total: usize) -> Vec<Light> {
    let centre = (min + max) * 0.5;
    let radius = ((max - min).length() * 0.5).max(1.0);
    (0..count)
        .map(|i| {
            let angle = std::f32::consts::TAU * (i as f32 + 0.25) / count as f32;
            let position = centre
                + Vec3::new(
                    angle.cos() * radius * 1.2,
                    radius * 0.9,
                    angle.sin() * radius * 1.2,
                );
            let d2 = (position - centre).length_squared();
            Light::point(position, 3.0 * d2 / total.max(1) as f32)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_light_falls_off_with_square_distance() {
        let light = Light::point(Vec3::new(0.0, 4.0, 0.0), 32.0);
        let i = light.incident(Vec3A::ZERO).unwrap();
        assert!((i.irradiance.x - 2.0).abs() < 1e-6);
        assert!((i.to_light - Vec3A::Y).length() < 1e-6);
        assert_eq!(i.distance, 4.0);
        assert!(light.incident(Vec3A::new(0.0, 4.0, 0.0)).is_none());
    }

    #[test]
    fn spot_light_cuts_off_outside_cone() {
        let source = LightSource {
            kind: LightKind::Spot {
                inner_cone: 0.2,
                outer_cone: 0.4,
            },
            intensity: Vec3::splat(10.0),
            range: None,
            inverse_square: true,
        };
        let light = Light::placed(&source, Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0)));
        assert!(light.incident(Vec3A::ZERO).is_some());
        assert!(light.incident(Vec3A::new(10.0, 0.0, 0.0)).is_none());
    }

    #[test]
    fn light_without_inverse_square_has_no_distance_falloff() {
        let source = LightSource {
            kind: LightKind::Point,
            intensity: Vec3::new(1.0, 0.5, 2.0),
            range: None,
            inverse_square: false,
        };
        let light = Light::placed(&source, Mat4::from_translation(Vec3::new(0.0, 10.0, 0.0)));
        for y in [0.0, 5.0, 9.0, -100.0] {
            let i = light.incident(Vec3A::new(0.0, y, 0.0)).unwrap();
            assert_eq!(i.irradiance, Vec3A::new(1.0, 0.5, 2.0));
        }
    }

    #[test]
    fn ring_lights_sum_to_constant_irradiance_at_centre() {
        for n in 1..=6 {
            let lights = ring_lights(Vec3::splat(-2.0), Vec3::splat(2.0), n, n);
            let total: f32 = lights
                .iter()
                .map(|l| l.incident(Vec3A::ZERO).unwrap().irradiance.x)
                .sum();
            assert!((total - 3.0).abs() < 1e-4, "{n}: {total}");
        }
    }
}
