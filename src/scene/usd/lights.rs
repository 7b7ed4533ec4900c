//! `UsdLux` lights to the renderer's lights. The renderer has point, spot and directional
//! lights with hard shadows, so area lights become points at their centre; what that
//! approximates:
//! - radiance `L = intensity * 2^exposure * color` (inputs with or without the `inputs:`
//!   prefix of older files);
//! - `SphereLight` (and `treatAsPoint`) -> a point light of intensity `L * pi r^2` (the
//!   sphere's projected area, `r` in metres; with `normalize` the area is taken as 1): soft
//!   shadows and the sphere's own size are lost;
//! - `DiskLight` (`L * pi r^2`) and `RectLight` (`L * width * height`) -> a spot light facing
//!   -Z with a 90 degree cone, whose smooth edge stands in for the emitter's cosine falloff;
//! - `CylinderLight` -> a point light of `L * 2 r length`;
//! - `ShapingAPI` `shaping:cone:angle` (< 90 degrees) -> the spot's outer cone, the inner one
//!   `angle * (1 - softness)`;
//! - `DistantLight` -> a directional light of irradiance `L` along -Z (its `angle`, the sun's
//!   size, is ignored);
//! - `DomeLight` -> the background colour `L` (it lights nothing directly; a texture on it is
//!   ignored); `GeometryLight` and `PortalLight` are ignored. Each approximation is noted.

use std::f32::consts::{FRAC_PI_2, PI};

use glam::Vec3;
use openusd::usd::Prim;

use super::Builder;
use super::values::{scalar, vec3_or_4};
use crate::scene::{LightDesc, LightKind};

pub(super) fn add(b: &mut Builder, prim: &Prim, node: usize) -> Result<(), String> {
    let path = prim.path().as_str().to_string();
    let type_name = prim
        .type_name()
        .ok()
        .flatten()
        .map(|t| t.as_str().to_string())
        .unwrap_or_default();
    let mpu = b.meters_per_unit as f32;
    let reader = &b.reader;
    let mut animated = false;
    let mut input = |name: &str| -> Result<Option<openusd::sdf::Value>, String> {
        for attr in [format!("inputs:{name}"), name.to_string()] {
            if reader.sample_count(prim, &attr)? > 1 {
                animated = true;
            }
            if let Some(v) = reader.static_value(prim, &attr)? {
                return Ok(Some(v));
            }
        }
        Ok(None)
    };
    let mut number = |name: &str, fallback: f32| -> Result<f32, String> {
        match input(name)? {
            None => Ok(fallback),
            Some(v) => match scalar(&v) {
                Some(x) if x.is_finite() => Ok(x as f32),
                _ => Err(format!("{path}: inputs:{name} must be a finite number")),
            },
        }
    };
    let intensity = number("intensity", 1.0)?;
    let exposure = number("exposure", 0.0)?;
    let normalize = number("normalize", 0.0)? != 0.0;
    let radius = number("radius", 0.5)?.abs() * mpu;
    let width = number("width", 1.0)?.abs() * mpu;
    let height = number("height", 1.0)?.abs() * mpu;
    let length = number("length", 1.0)?.abs() * mpu;
    let cone = number("shaping:cone:angle", 90.0)?;
    let softness = number("shaping:cone:softness", 0.0)?.clamp(0.0, 1.0);
    let color = match input("color")? {
        None => Vec3::ONE,
        Some(v) => vec3_or_4(&v)
            .filter(|c| c.is_finite())
            .ok_or_else(|| format!("{path}: inputs:color must be a finite colour"))?,
    };
    let radiance = intensity * exposure.exp2();
    if !(radiance.is_finite() && radiance >= 0.0) || color.min_element() < 0.0 {
        return Err(format!(
            "{path}: intensity {intensity} with exposure {exposure} and colour {color} is not a usable light"
        ));
    }
    if animated {
        b.notes.push(format!(
            "{path}: animated light inputs are not supported; their first values hold"
        ));
    }
    let area = |a: f32| if normalize { 1.0 } else { a };
    let shaped = (cone < 90.0).then(|| {
        let outer = cone.clamp(0.0, 90.0).to_radians();
        LightKind::Spot {
            inner_cone: outer * (1.0 - softness),
            outer_cone: outer,
        }
    });
    let (kind, intensity) = match type_name.as_str() {
        "SphereLight" => (
            shaped.unwrap_or(LightKind::Point),
            radiance * area(PI * radius * radius),
        ),
        "DiskLight" => (
            shaped.unwrap_or(LightKind::Spot {
                inner_cone: 0.0,
                outer_cone: FRAC_PI_2,
            }),
            radiance * area(PI * radius * radius),
        ),
        "RectLight" => (
            shaped.unwrap_or(LightKind::Spot {
                inner_cone: 0.0,
                outer_cone: FRAC_PI_2,
            }),
            radiance * area(width * height),
        ),
        "CylinderLight" => (LightKind::Point, radiance * area(2.0 * radius * length)),
        "DistantLight" => (LightKind::Directional, radiance),
        "DomeLight" | "DomeLight_1" => {
            b.background = color * radiance;
            b.notes.push(format!(
                "{path}: the DomeLight's colour becomes the background (rays that leave the scene); it does not light surfaces directly, and a texture on it is ignored"
            ));
            return Ok(());
        }
        other => {
            b.notes
                .push(format!("{path}: {other} is not supported; ignored"));
            return Ok(());
        }
    };
    if type_name != "DistantLight" {
        b.notes.push(format!(
            "{path}: {type_name} rendered as a {} light at its centre (hard shadows)",
            if matches!(kind, LightKind::Spot { .. }) {
                "spot"
            } else {
                "point"
            }
        ));
    }
    if !intensity.is_finite() {
        return Err(format!("{path}: the light's intensity overflows"));
    }
    b.lights.push(LightDesc {
        kind,
        color,
        intensity,
        range: None,
        inverse_square: true,
    });
    b.nodes[node].light = Some(b.lights.len() - 1);
    Ok(())
}
