//! `UsdGeomCamera` to a perspective camera: vertical field of view
//! `2 atan(verticalAperture / (2 focalLength))` (the image's `--size` sets the aspect: the
//! vertical aperture spans the image height, as USD's "fit" conform policy does for an image
//! wider than the aperture), near plane from `clippingRange`. The camera looks down its -Z
//! with +Y up, as in glTF, so its node's transform places it unchanged.

use openusd::usd::Prim;

use super::Builder;
use super::values::{scalar, token, vec2};
use crate::scene::CameraDesc;

/// USD's fallbacks (tenths of a scene unit; only their ratio matters here).
const FOCAL_LENGTH: f64 = 50.0;
const HORIZONTAL_APERTURE: f64 = 20.955;
const VERTICAL_APERTURE: f64 = 15.2908;
const NEAR: f32 = 1.0;

pub(super) fn add(b: &mut Builder, prim: &Prim, node: usize) -> Result<(), String> {
    let path = prim.path().as_str().to_string();
    let reader = &b.reader;
    let projection = reader
        .default_value(prim, "projection")?
        .as_ref()
        .and_then(token);
    if projection.as_deref() == Some("orthographic") {
        b.notes.push(format!(
            "{path}: orthographic cameras are not supported; skipped"
        ));
        return Ok(());
    }
    let mut number = |name: &str, fallback: f64| -> Result<f64, String> {
        if reader.sample_count(prim, name)? > 1 {
            b.notes.push(format!(
                "{path}.{name} is animated, which cameras do not support here: its first sample holds"
            ));
        }
        match reader.static_value(prim, name)? {
            None => Ok(fallback),
            Some(v) => match scalar(&v) {
                Some(x) if x.is_finite() && x > 0.0 => Ok(x),
                _ => Err(format!("{path}.{name} must be a positive number")),
            },
        }
    };
    let focal = number("focalLength", FOCAL_LENGTH)?;
    let vertical = number("verticalAperture", VERTICAL_APERTURE)?;
    let horizontal = number("horizontalAperture", HORIZONTAL_APERTURE)?;
    let yfov = (2.0 * (vertical / (2.0 * focal)).atan()) as f32;
    if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
        return Err(format!(
            "{path}: focalLength {focal} and verticalAperture {vertical} give no usable field of view"
        ));
    }
    let znear = match reader
        .static_value(prim, "clippingRange")?
        .as_ref()
        .and_then(vec2)
    {
        Some(range) if range.x.is_finite() && range.x > 0.0 => range.x,
        Some(_) => {
            return Err(format!(
                "{path}.clippingRange must start at a positive distance"
            ));
        }
        None => NEAR,
    };
    b.cameras.push(CameraDesc { yfov, znear });
    b.nodes[node].camera = Some(b.cameras.len() - 1);
    for offset in ["horizontalApertureOffset", "verticalApertureOffset"] {
        if reader
            .static_value(prim, offset)?
            .as_ref()
            .and_then(scalar)
            .is_some_and(|x| x != 0.0)
        {
            b.notes.push(format!(
                "{path}.{offset} is ignored: the camera looks through the centre of its aperture"
            ));
        }
    }
    let aspect = horizontal / vertical;
    if (aspect - 16.0 / 9.0).abs() > 0.01 {
        b.notes.push(format!(
            "{path}: aperture aspect {aspect:.3} (horizontal/vertical); the vertical field of view {:.2} deg is kept and --size sets the image aspect",
            yfov.to_degrees()
        ));
    }
    Ok(())
}
