//! Pinhole camera and the primary-ray convention.
//!
//! Pixel `(x, y)` has its top-left corner at `(x, y)` and its centre at `(x + 0.5, y + 0.5)`;
//! `y` grows downwards. A film point `(px, py)` maps to the direction
//! `normalize(forward + right * (2 px / W - 1) * tan(fov/2) * W/H + up * (1 - 2 py / H) * tan(fov/2))`,
//! with `right = forward x up` (right-handed, glTF: the camera looks down its -Z, +Y up).
//! The output size sets the aspect ratio; a glTF camera's `aspectRatio` is not used.

use glam::{Mat4, Vec3, Vec3A};

use crate::lod::ViewFrame;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub eye: Vec3A,
    pub forward: Vec3A,
    pub right: Vec3A,
    pub up: Vec3A,
    /// Vertical field of view in radians.
    pub yfov: f32,
    pub width: u32,
    pub height: u32,
    tan_half_fov: f32,
    aspect: f32,
}

impl Camera {
    /// A camera at the origin of `world_from_camera` looking down its -Z.
    pub fn from_world(world_from_camera: Mat4, yfov: f32, width: u32, height: u32) -> Camera {
        let eye = world_from_camera.transform_point3(Vec3::ZERO);
        let forward = world_from_camera.transform_vector3(Vec3::NEG_Z);
        let up = world_from_camera.transform_vector3(Vec3::Y);
        Camera::look(eye, forward, up, yfov, width, height)
    }

    /// A camera at `eye` looking along `forward` with `up` as the approximate up direction.
    /// Degenerate directions fall back to looking down -Z with +Y up.
    ///
    /// `yfov` is used as given in `(0, pi)`, the range every loader accepts (and refuses
    /// outside with an error naming the file and camera); every such f32 has a finite,
    /// positive `tan(yfov / 2)`. Outside it (hand-built scenes only) the camera uses 0.8.
    pub fn look(eye: Vec3, forward: Vec3, up: Vec3, yfov: f32, width: u32, height: u32) -> Camera {
        let forward = forward.try_normalize().unwrap_or(Vec3::NEG_Z);
        let right = forward
            .cross(up)
            .try_normalize()
            .or_else(|| forward.cross(Vec3::Y).try_normalize())
            .unwrap_or(Vec3::X);
        let up = right.cross(forward);
        // The raw field of view over the whole range the loaders accept: `log2 P_b` was
        // computed with the scene's value (`frame::Renderer::new`), so a camera that
        // rendered with another would select levels for a different film (the
        // old clamp to (1e-4, 3.1) cost 7.8 levels at yfov 3.12). Values no loader lets
        // through (NaN, <= 0, >= pi: only a hand-built scene) get 0.8 rad rather than NaN
        // pixels.
        let yfov = if yfov > 0.0 && yfov < std::f32::consts::PI {
            yfov
        } else {
            0.8
        };
        let eye = if eye.is_finite() { eye } else { Vec3::ZERO };
        Camera {
            eye: eye.into(),
            forward: forward.into(),
            right: right.into(),
            up: up.into(),
            yfov,
            width,
            height,
            tan_half_fov: (yfov / 2.0).tan(),
            aspect: width as f32 / height.max(1) as f32,
        }
    }

    /// Frames an axis-aligned box: looks at its centre from above and in front, far enough
    /// that its bounding sphere fits the vertical field of view.
    pub fn framing(min: Vec3, max: Vec3, width: u32, height: u32) -> Camera {
        let yfov = 45f32.to_radians();
        let (min, max) = if min.is_finite() && max.is_finite() && min.cmple(max).all() {
            (min, max)
        } else {
            (Vec3::splat(-1.0), Vec3::splat(1.0))
        };
        let centre = (min + max) * 0.5;
        let radius = ((max - min).length() * 0.5).max(1e-3);
        let aspect = (width as f32 / height.max(1) as f32).min(1.0);
        let distance = radius / ((yfov / 2.0).tan() * aspect).atan().sin() * 1.05;
        let direction = Vec3::new(0.35, 0.45, 1.0).normalize();
        Camera::look(
            centre + direction * distance,
            -direction,
            Vec3::Y,
            yfov,
            width,
            height,
        )
    }

    /// What LOD selection needs of this camera (`lod::LodCamera` is built from it).
    pub fn view_frame(&self) -> ViewFrame {
        ViewFrame {
            forward: self.forward,
            right: self.right,
            up: self.up,
            yfov: self.yfov,
            width: self.width,
            height: self.height,
        }
    }

    /// Unit direction through film point `(px, py)` in pixels (see the module doc).
    #[inline]
    pub fn primary_direction(&self, px: f32, py: f32) -> Vec3A {
        let sx = (2.0 * px / self.width as f32 - 1.0) * self.tan_half_fov * self.aspect;
        let sy = (1.0 - 2.0 * py / self.height as f32) * self.tan_half_fov;
        (self.forward + self.right * sx + self.up * sy).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_forward_and_corners_span_fov() {
        let cam = Camera::look(
            Vec3::ZERO,
            Vec3::NEG_Z,
            Vec3::Y,
            90f32.to_radians(),
            200,
            100,
        );
        let c = cam.primary_direction(100.0, 50.0);
        assert!((c - Vec3A::NEG_Z).length() < 1e-6);
        // Top edge at 45 degrees up, right edge at atan(2) (aspect 2).
        let top = cam.primary_direction(100.0, 0.0);
        assert!((top.y.atan2(-top.z) - std::f32::consts::FRAC_PI_4).abs() < 1e-6);
        let right = cam.primary_direction(200.0, 50.0);
        assert!((right.x / -right.z - 2.0).abs() < 1e-5);
    }

    #[test]
    fn from_world_follows_node_rotation() {
        let m = Mat4::from_rotation_translation(
            glam::Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            Vec3::new(1.0, 2.0, 3.0),
        );
        let cam = Camera::from_world(m, 1.0, 64, 64);
        assert!((Vec3::from(cam.eye) - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-6);
        assert!((cam.forward - Vec3A::NEG_X).length() < 1e-6);
    }

    #[test]
    fn degenerate_inputs_fall_back() {
        let cam = Camera::look(Vec3::NAN, Vec3::ZERO, Vec3::ZERO, f32::NAN, 10, 10);
        assert!(cam.primary_direction(3.0, 7.0).is_finite());
        let framed = Camera::framing(Vec3::splat(f32::INFINITY), Vec3::ZERO, 10, 10);
        assert!(framed.primary_direction(0.0, 0.0).is_finite());
    }

    #[test]
    fn lod_direction_differentials_match_finite_differences_of_primary_directions() {
        let camera = Camera::look(Vec3::ZERO, Vec3::new(0.2, -0.1, -1.0), Vec3::Y, 1.0, 64, 48);
        let lod = crate::lod::LodCamera::new(&camera.view_frame());
        let (px, py) = (10.3, 40.7);
        let (dx, dy) = lod.direction_differentials(px, py);
        let h = 1e-2;
        let fd_x = (camera.primary_direction(px + h, py) - camera.primary_direction(px - h, py))
            / (2.0 * h);
        let fd_y = (camera.primary_direction(px, py + h) - camera.primary_direction(px, py - h))
            / (2.0 * h);
        // f32 central differences carry ~3e-6 of rounding at this step.
        assert!((dx - fd_x).length() < 1e-3 * dx.length(), "{dx} vs {fd_x}");
        assert!((dy - fd_y).length() < 1e-3 * dy.length(), "{dy} vs {fd_y}");
    }

    #[test]
    fn lod_pixel_widths_are_the_singular_values_of_the_pixel_in_directions() {
        // The pixel square maps to a small patch of directions with Jacobian
        // [dD/dx, dD/dy]; its singular values are the patch's tangential and radial widths,
        // `k cos(theta)` and `k cos^2(theta)`.
        for (yfov, (px, py)) in [
            (1.0f32, (10.3f32, 40.7f32)),
            (2.0, (0.5, 0.5)),
            (3.0, (60.0, 5.5)),
            (3.0, (32.0, 24.0)),
        ] {
            let camera = Camera::look(
                Vec3::ZERO,
                Vec3::new(0.2, -0.1, -1.0),
                Vec3::Y,
                yfov,
                64,
                48,
            );
            let lod = crate::lod::LodCamera::new(&camera.view_frame());
            let h = 1e-2;
            let dx = (camera.primary_direction(px + h, py) - camera.primary_direction(px - h, py))
                / (2.0 * h);
            let dy = (camera.primary_direction(px, py + h) - camera.primary_direction(px, py - h))
                / (2.0 * h);
            let (a, b, c) = (dx.dot(dx), dx.dot(dy), dy.dot(dy));
            let root = (0.25 * (a - c) * (a - c) + b * b).sqrt();
            let (larger, smaller) = (
                (0.5 * (a + c) + root).sqrt(),
                (0.5 * (a + c) - root).max(0.0).sqrt(),
            );
            let widths = lod.pixel_widths(px, py);
            let k = lod.spread;
            let what =
                format!("yfov {yfov} at ({px}, {py}): {larger}, {smaller} vs {widths:?} k {k}");
            assert!(
                (larger - k * widths.tangential).abs() < 2e-3 * larger,
                "{what}"
            );
            assert!(
                (smaller - k * widths.radial).abs() < 2e-3 * larger,
                "{what}"
            );
        }
    }
}
