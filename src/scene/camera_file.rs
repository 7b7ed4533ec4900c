//! `camera_NNNN.json`: one frame's camera with its exact primary-ray convention, its lights
//! and the background, as data.
//!
//! `export` writes it (from the renderer's camera and lights) and `scene::obj` reads it back
//! beside an exported frame, so the type lives here, below both: a loader may use it without
//! importing the exporter.

use serde::{Deserialize, Serialize};

use crate::scene::LightKind;

/// The primary-ray convention, in prose (also written into every camera file).
pub const RAY_CONVENTION: &str = "Pixel (x, y) has its top-left corner at (x, y) and its centre at (x + 0.5, y + 0.5); y grows downwards; W = width, H = height. Film point (px, py) maps to dir = normalize(forward + right * (2 px / W - 1) * tan(fov/2) * W/H + up * (1 - 2 py / H) * tan(fov/2)), right = forward x up (right-handed, +Y up, the camera looks down its -Z as in glTF). Bit-exact f32 evaluation, in this order: sx = ((2 * px) / W - 1) * tan_half_fov * aspect; sy = (1 - (2 * py) / H) * tan_half_fov; d = (forward + right * sx) + up * sy per component; len = sqrt((d.x * d.x + d.y * d.y) + d.z * d.z); dir = (d.x / len, d.y / len, d.z / len), with tan_half_fov and aspect taken from this file (not recomputed with another libm's tan). Rays start at eye.";

/// One frame's camera, lights and background.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraFile {
    pub frame: u32,
    pub time_s: f32,
    /// Camera position (world space).
    pub eye: [f32; 3],
    /// Unit view direction.
    pub forward: [f32; 3],
    /// Unit up direction (orthogonal to forward).
    pub up: [f32; 3],
    /// Unit right direction: `forward x up`.
    pub right: [f32; 3],
    pub yfov_degrees: f32,
    pub yfov_radians: f32,
    pub width: u32,
    pub height: u32,
    /// `tan(yfov_radians / 2)` as the renderer computed it (f32).
    pub tan_half_fov: f32,
    /// `width / height` as f32.
    pub aspect: f32,
    /// IEEE-754 bit patterns of the f32 fields above, for readers whose decimal parsing
    /// is not exact.
    pub bits: CameraBits,
    pub primary_ray: RayConvention,
    /// The lights this frame is lit by (after `--lights`), in the renderer's order.
    pub lights: Vec<LightFile>,
    /// Linear RGB radiance of rays that leave the scene.
    pub background: [f32; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraBits {
    pub eye: [u32; 3],
    pub forward: [u32; 3],
    pub up: [u32; 3],
    pub right: [u32; 3],
    pub tan_half_fov: u32,
    pub aspect: u32,
}

/// The primary-ray convention as data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RayConvention {
    /// Offset of a pixel's centre from its top-left corner: `[0.5, 0.5]`.
    pub pixel_centre: [f32; 2],
    /// Pixel rows grow downwards (row 0 at the top).
    pub y_down: bool,
    /// `"right"`: `right = forward x up`.
    pub handedness: String,
    /// The world's up axis and the camera's look axis (glTF): `"+Y"`, `"-Z"`.
    pub world_up: String,
    pub camera_looks_along: String,
    pub formula: String,
}

/// One light placed in world space for the frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LightFile {
    /// `"point"`, `"directional"` or `"spot"`.
    pub kind: String,
    pub position: [f32; 3],
    /// Unit direction the light shines along (directional and spot).
    pub direction: [f32; 3],
    /// Linear RGB: colour times intensity (candela for point/spot, lux for directional).
    pub intensity: [f32; 3],
    /// Distance past which the light has no effect; `null`: unlimited.
    pub range: Option<f32>,
    /// Spot cone angles in radians (`null` for other kinds).
    pub inner_cone: Option<f32>,
    pub outer_cone: Option<f32>,
    /// Whether irradiance falls off as `1/d^2` (false for AFF/NFF lights); absent means true.
    #[serde(default = "default_true")]
    pub inverse_square: bool,
}

fn default_true() -> bool {
    true
}

impl LightFile {
    /// The light kind, or `None` for an unknown `kind` string.
    pub fn light_kind(&self) -> Option<LightKind> {
        match self.kind.as_str() {
            "point" => Some(LightKind::Point),
            "directional" => Some(LightKind::Directional),
            "spot" => Some(LightKind::Spot {
                inner_cone: self.inner_cone.unwrap_or(0.0),
                outer_cone: self.outer_cone.unwrap_or(std::f32::consts::FRAC_PI_4),
            }),
            _ => None,
        }
    }
}

impl CameraFile {
    /// The primary ray direction through film point `(px, py)`, evaluated from this file's
    /// fields exactly as [`RAY_CONVENTION`] describes (scalar f32, no fused operations).
    pub fn primary_direction(&self, px: f32, py: f32) -> [f32; 3] {
        let f = self.bits.forward.map(f32::from_bits);
        let r = self.bits.right.map(f32::from_bits);
        let u = self.bits.up.map(f32::from_bits);
        let tan = f32::from_bits(self.bits.tan_half_fov);
        let aspect = f32::from_bits(self.bits.aspect);
        let sx = (2.0 * px / self.width as f32 - 1.0) * tan * aspect;
        let sy = (1.0 - 2.0 * py / self.height as f32) * tan;
        let d: [f32; 3] = std::array::from_fn(|i| f[i] + r[i] * sx + u[i] * sy);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|c| c / len)
    }
}
