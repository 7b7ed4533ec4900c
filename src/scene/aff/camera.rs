//! The `v` view and the camera node.
//!
//! The camera is a root node with a [`CameraDesc`] (vertical FOV from `v angle`, degrees to
//! radians; `znear` from `hither`, set to 1 when below 1e-4 as the reference does). The
//! renderer looks down the node's -Z with +Y up, which is BART's camera convention
//! (FORMAT.md 1.5: view direction = -R·z, up = R·y), so a `k camera` block drives the
//! node directly: `transl` -> translation, `rot` -> rotation. Without a track the node
//! stays at `v from`, looking at `at` with `up`.

use glam::{Mat3, Quat, Vec3};

/// The `v` command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    pub from: Vec3,
    pub at: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub angle: f32,
    pub hither: f32,
    pub resolution: (u32, u32),
}

impl Default for View {
    fn default() -> Self {
        View {
            from: Vec3::ZERO,
            at: Vec3::NEG_Z,
            up: Vec3::Y,
            angle: 45.0,
            hither: 1.0,
            resolution: (800, 600),
        }
    }
}

/// The rotation taking -Z to the direction from `from` to `at` and +Y towards `up`
/// (identity when degenerate; another up is used when `up` is parallel to the direction).
pub fn look_at_rotation(from: Vec3, at: Vec3, up: Vec3) -> Quat {
    let Some(forward) = (at - from).try_normalize() else {
        return Quat::IDENTITY;
    };
    let back = -forward;
    let right = up
        .cross(back)
        .try_normalize()
        .or_else(|| Vec3::Y.cross(back).try_normalize())
        .or_else(|| Vec3::X.cross(back).try_normalize())
        .unwrap_or(Vec3::X);
    let true_up = back.cross(right);
    Quat::from_mat3(&Mat3::from_cols(right, true_up, back)).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_points_minus_z_at_target() {
        let q = look_at_rotation(Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::Y);
        assert!((q * Vec3::NEG_Z - Vec3::X).length() < 1e-6);
        assert!((q * Vec3::Y - Vec3::Y).length() < 1e-6);
    }
}
