//! Writing `camera_NNNN.json` (the type is `scene::camera_file::CameraFile`): the frame's
//! camera with its exact primary-ray convention, its lights and the background, so another
//! program can generate the same primary rays bit for bit and a re-load (`scene::obj`) can
//! reproduce the frame.

use glam::{Vec3, Vec3A};

use crate::render::{Camera, Light, LightKind};
use crate::scene::camera_file::{CameraBits, CameraFile, LightFile, RAY_CONVENTION, RayConvention};

fn arr(v: Vec3A) -> [f32; 3] {
    v.to_array()
}

fn bits3(v: Vec3A) -> [u32; 3] {
    v.to_array().map(f32::to_bits)
}

impl LightFile {
    /// The record of a light placed for the frame.
    pub fn of(light: &Light) -> LightFile {
        let (kind, inner_cone, outer_cone) = match light.kind {
            LightKind::Point => ("point", None, None),
            LightKind::Directional => ("directional", None, None),
            LightKind::Spot {
                inner_cone,
                outer_cone,
            } => ("spot", Some(inner_cone), Some(outer_cone)),
        };
        LightFile {
            kind: kind.into(),
            position: arr(light.position),
            direction: arr(light.direction),
            intensity: arr(light.intensity),
            range: light.range,
            inner_cone,
            outer_cone,
            inverse_square: light.inverse_square,
        }
    }
}

impl CameraFile {
    /// The record of one frame: `camera`, the `lights` it is lit by and the background.
    pub fn new(
        frame: u32,
        time_s: f32,
        camera: &Camera,
        lights: &[Light],
        background: Vec3,
    ) -> CameraFile {
        // The same expressions `Camera::look` evaluates (same binary, same libm).
        let tan_half_fov = (camera.yfov / 2.0).tan();
        let aspect = camera.width as f32 / camera.height.max(1) as f32;
        CameraFile {
            frame,
            time_s,
            eye: arr(camera.eye),
            forward: arr(camera.forward),
            up: arr(camera.up),
            right: arr(camera.right),
            yfov_degrees: camera.yfov.to_degrees(),
            yfov_radians: camera.yfov,
            width: camera.width,
            height: camera.height,
            tan_half_fov,
            aspect,
            bits: CameraBits {
                eye: bits3(camera.eye),
                forward: bits3(camera.forward),
                up: bits3(camera.up),
                right: bits3(camera.right),
                tan_half_fov: tan_half_fov.to_bits(),
                aspect: aspect.to_bits(),
            },
            primary_ray: RayConvention {
                pixel_centre: [0.5, 0.5],
                y_down: true,
                handedness: "right".into(),
                world_up: "+Y".into(),
                camera_looks_along: "-Z".into(),
                formula: RAY_CONVENTION.into(),
            },
            lights: lights.iter().map(LightFile::of).collect(),
            background: background.to_array(),
        }
    }
}
