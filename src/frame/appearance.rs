//! The renderer's materials and light sources, built from the scene description.
//!
//! This is the one place where load-time types (`scene::MaterialDesc`, `scene::LightDesc`)
//! become the integrator's (`render::Material`, `render::LightSource`), so `render` never
//! learns which file format a surface came from: the AFF/NFF convention becomes
//! `ShadingModel::Additive`, glTF's becomes `ShadingModel::EnergyWeighted`.
//!
//! Invariant: material index `i` of `FrameTriangles::material` is the scene's material `i`;
//! one more, the default material, follows them for primitives without one
//! ([`material_descs`] and [`Appearance::new`] agree on this order).

use crate::render::{LightKind, LightSource, Material, ShadingModel, highlight_floor};
use crate::scene::{LightDesc, MaterialDesc, SceneDesc, Shading};

/// Everything the integrator needs to know about a scene's surfaces and lights.
#[derive(Debug, Clone, Default)]
pub struct Appearance {
    /// Indexed by `FrameTriangles::material`: the scene's materials, then the default.
    pub materials: Vec<Material>,
    /// Indexed like `SceneDesc::lights`; placed per frame by their nodes.
    pub lights: Vec<LightSource>,
}

impl Appearance {
    /// Converts every material and light of `scene`.
    pub fn new(scene: &SceneDesc) -> Appearance {
        Appearance {
            materials: material_descs(scene).iter().map(material).collect(),
            lights: scene.lights.iter().map(light_source).collect(),
        }
    }
}

/// The description behind each material index of `FrameTriangles::material`: the scene's
/// materials, then the default one (for exporters, which write names and flags the
/// renderer does not read).
pub fn material_descs(scene: &SceneDesc) -> Vec<MaterialDesc> {
    let mut descs = scene.materials.clone();
    descs.push(MaterialDesc::default());
    descs
}

/// The render material of a description.
pub fn material(desc: &MaterialDesc) -> Material {
    let model = match desc.shading {
        Shading::Physical => ShadingModel::EnergyWeighted,
        // The additive convention's ambient reflectance defaults to its diffuse colour.
        Shading::Nff => ShadingModel::Additive {
            ambient: desc.ambient.unwrap_or(desc.base_color),
        },
    };
    Material {
        base_color: desc.base_color,
        base_color_texture: desc.base_color_texture,
        reflectance: desc.reflectance,
        transmission: desc.transmission,
        ior: desc.ior,
        shininess: desc.shininess,
        highlight_floor: highlight_floor(desc.shininess),
        specular: desc.specular,
        model,
    }
}

/// The light source of a description: colour times (non-negative) intensity, and a range
/// only when it is positive.
pub fn light_source(desc: &LightDesc) -> LightSource {
    let kind = match desc.kind {
        crate::scene::LightKind::Point => LightKind::Point,
        crate::scene::LightKind::Directional => LightKind::Directional,
        crate::scene::LightKind::Spot {
            inner_cone,
            outer_cone,
        } => LightKind::Spot {
            inner_cone,
            outer_cone,
        },
    };
    LightSource {
        kind,
        intensity: desc.color * desc.intensity.max(0.0),
        range: desc.range.filter(|r| *r > 0.0),
        inverse_square: desc.inverse_square,
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    #[test]
    fn default_material_follows_the_scene_materials() {
        let scene = SceneDesc {
            materials: vec![MaterialDesc {
                base_color: Vec3::X,
                ..Default::default()
            }],
            ..Default::default()
        };
        let appearance = Appearance::new(&scene);
        assert_eq!(appearance.materials.len(), 2);
        assert_eq!(appearance.materials[0].base_color, Vec3::X);
        assert_eq!(appearance.materials[1], material(&MaterialDesc::default()));
        assert_eq!(material_descs(&scene).len(), appearance.materials.len());
    }

    #[test]
    fn additive_ambient_defaults_to_the_base_colour() {
        let nff = MaterialDesc {
            base_color: Vec3::new(0.2, 0.4, 0.6),
            shading: Shading::Nff,
            ..Default::default()
        };
        let expect = |m: Material| match m.model {
            ShadingModel::Additive { ambient } => ambient,
            ShadingModel::EnergyWeighted => panic!("expected the additive model"),
        };
        assert_eq!(expect(material(&nff)), nff.base_color);
        let with_ambient = MaterialDesc {
            ambient: Some(Vec3::ONE),
            ..nff.clone()
        };
        assert_eq!(expect(material(&with_ambient)), Vec3::ONE);
        assert!(!material(&MaterialDesc::default()).is_additive());
    }

    #[test]
    fn light_source_scales_colour_and_drops_invalid_values() {
        let desc = LightDesc {
            kind: crate::scene::LightKind::Spot {
                inner_cone: 0.1,
                outer_cone: 0.3,
            },
            color: Vec3::new(0.5, 0.25, 1.0),
            intensity: 2.0,
            range: Some(0.0),
            inverse_square: false,
        };
        let source = light_source(&desc);
        assert_eq!(source.intensity, Vec3::new(1.0, 0.5, 2.0));
        assert_eq!(source.range, None);
        assert!(!source.inverse_square);
        assert_eq!(
            source.kind,
            LightKind::Spot {
                inner_cone: 0.1,
                outer_cone: 0.3
            }
        );
        let dark = light_source(&LightDesc {
            intensity: -4.0,
            range: Some(3.0),
            ..desc
        });
        assert_eq!(dark.intensity, Vec3::ZERO);
        assert_eq!(dark.range, Some(3.0));
    }
}
