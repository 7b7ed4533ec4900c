//! The spread of a pinhole pixel and its footprint on a surface, for the isotropic methods
//! that carry a spread instead of differentials (`paper-cos`, `cones`).
//!
//! A pinhole pixel `k = 2 tan(fov/2) / H` wide on the film at unit distance is not `k`
//! radians wide unless it sits on the optical axis. At angle `theta` off the axis it
//! subtends
//!
//! ```text
//! tangential:  k cos(theta)      (the film point is 1 / cos(theta) away)
//! radial:      k cos^2(theta)    (the film is also tilted by theta against the ray)
//! ```
//!
//! so its cross-section is an ellipse. On a surface the cross-section stretches by
//! `1 / |n.d|` along the direction the surface tilts away from the ray (the projection of
//! `n` across the ray). The footprint's longest axis is the larger singular value of that
//! map: with the tangential width 1, the radial width `a`, the stretch `s = 1 / |n.d|`
//! along a direction at angle `phi` from the radial one (`g = s^2 - 1`, `x = cos^2 phi`),
//!
//! ```text
//! M^T M = | a^2 (1 + g x)            a g sqrt(x (1 - x)) |
//!         | a g sqrt(x (1 - x))      1 + g (1 - x)       |
//! longest axis = sqrt(largest eigenvalue)
//! ```
//!
//! On a plane facing the camera the tilt is radial (`x = 1`) and `|n.d| = cos(theta)`, so
//! the radial width `k cos^2(theta) t` stretches back to `k cos(theta) t`, the tangential
//! width: the footprint is `k z` square at depth `z` on every pixel, as it must be. On the
//! axis (`a = 1`) the longest axis is `1 / |n.d|`, the ray cones' incidence term.
//!
//! Only the primary ray knows its pixel's orientation (the radial direction is the one
//! towards the optical axis). After a mirror or glass surface the methods forget it and
//! continue with the geometric mean of the two widths, `k cos^1.5(theta)` (the width of a
//! circle of the same solid angle), for which the orientation no longer matters.

use glam::Vec3A;

use super::{LodCamera, SurfaceHit};

/// The widths of a ray's pixel relative to the centre pixel's `k`: `tangential` across the
/// plane through the ray and the optical axis, `radial` within it. Both in `(0, 1]`, and
/// `radial <= tangential`; equal once the ray has left its first surface (isotropic).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelWidths {
    pub tangential: f32,
    pub radial: f32,
}

impl PixelWidths {
    /// The on-axis pixel (and what a ray that forgot its pixel's shape would use at 0
    /// degrees): one `k` each way.
    pub const CENTRE: PixelWidths = PixelWidths {
        tangential: 1.0,
        radial: 1.0,
    };

    /// The widths of a pixel `theta` off the axis, given `cos(theta)` in `(0, 1]`.
    #[inline]
    pub fn off_axis(cos: f32) -> PixelWidths {
        PixelWidths {
            tangential: cos,
            radial: cos * cos,
        }
    }

    /// The circle of the same solid angle: both widths become their geometric mean.
    #[inline]
    pub fn isotropic(self) -> PixelWidths {
        let mean = (self.tangential * self.radial).sqrt();
        PixelWidths {
            tangential: mean,
            radial: mean,
        }
    }

    /// `radial / tangential`, in `(0, 1]` (1 for an isotropic or degenerate pixel).
    #[inline]
    pub fn ratio(self) -> f32 {
        let ratio = self.radial / self.tangential;
        if ratio > 0.0 && ratio <= 1.0 {
            ratio
        } else {
            1.0
        }
    }
}

impl LodCamera {
    /// The widths of the pixel whose primary ray passes through film point `(px, py)`.
    #[inline]
    pub fn pixel_widths(&self, px: f32, py: f32) -> PixelWidths {
        PixelWidths::off_axis(self.off_axis_cos(px, py))
    }
}

/// The longest axis of the footprint at `hit` of a cross-section whose tangential width
/// is 1 and radial width `ratio` (in `(0, 1]`), with the radial direction taken towards
/// `axis` (the camera's unit forward). `|n.d|` is clamped at
/// [`MIN_INCIDENCE_COS`](super::MIN_INCIDENCE_COS) as in the methods' incidence term. In
/// `[1, 1 / MIN_INCIDENCE_COS]`, finite for any hit.
///
/// With `ratio = 1` the result is `1 / clamped |n.d|` (up to rounding) whatever `axis` is.
#[inline]
pub fn footprint_longest_axis(ratio: f32, hit: &SurfaceHit, axis: Vec3A) -> f32 {
    let cos = hit.clamped_cos();
    let g = 1.0 / (cos * cos) - 1.0;
    let x = radial_share_of_tilt(hit, axis);
    let a2 = ratio * ratio;
    // The symmetric 2x2 `[[p, r], [r, q]]` above; its larger eigenvalue in the form
    // without cancellation.
    let p = a2 * (1.0 + g * x);
    let q = 1.0 + g * (1.0 - x);
    let r2 = a2 * g * g * x * (1.0 - x);
    let half_difference = 0.5 * (p - q);
    let largest = 0.5 * (p + q) + (half_difference * half_difference + r2).sqrt();
    let axis = largest.sqrt();
    if axis.is_finite() { axis } else { 1.0 }
}

/// `cos^2 phi`: how much of the surface's tilt (the normal's part across the ray) lies
/// along the radial direction (from the ray towards `axis`, across the ray). 0 where either
/// is undefined: a ray on the axis, or a surface met head-on, where it does not matter.
#[inline]
fn radial_share_of_tilt(hit: &SurfaceHit, axis: Vec3A) -> f32 {
    let (n, d) = (hit.face_normal, hit.direction);
    let n_d = n.dot(d);
    let f_d = axis.dot(d);
    // (n - (n.d) d) . (f - (f.d) d) = n.f - (n.d)(f.d), over the product of the lengths.
    let along = n.dot(axis) - n_d * f_d;
    let lengths2 = (1.0 - n_d * n_d) * (1.0 - f_d * f_d);
    let share = along * along / lengths2;
    if share.is_finite() && lengths2 > 1e-12 {
        share.min(1.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::super::MIN_INCIDENCE_COS;
    use super::super::test_support::{facing_triangle, hit_on};
    use super::*;

    /// The hit of a ray along `direction` on a plane with unit `normal` (facing the ray).
    fn longest(ratio: f32, direction: Vec3A, normal: Vec3A, axis: Vec3A) -> f32 {
        let triangle = facing_triangle(0.0, 0.0);
        let mut hit = hit_on(&triangle, 1.0, direction.normalize(), 1.0);
        hit.face_normal = normal.normalize();
        footprint_longest_axis(ratio, &hit, axis)
    }

    #[test]
    fn facing_plane_footprint_is_the_tangential_width_at_any_angle() {
        // Camera looks down -Z at the plane z = -1 (normal +Z); a ray theta off the axis has
        // radial width cos^2 and meets the plane at |n.d| = cos theta.
        for theta in [0.0f32, 0.3, 1.0, 1.4, 1.55] {
            let d = Vec3A::new(theta.sin(), 0.0, -theta.cos());
            let widths = PixelWidths::off_axis(theta.cos());
            let got = longest(widths.ratio(), d, Vec3A::Z, Vec3A::NEG_Z);
            // Past |n.d| = 1/16 the stretch is clamped, and the tangential width (1) is
            // already the longer axis.
            assert!((got - 1.0).abs() < 1e-4, "theta {theta}: {got}");
        }
    }

    #[test]
    fn on_axis_it_is_the_incidence_term() {
        for cos in [1.0f32, 0.8, 0.5, 0.2, 0.01] {
            let n = Vec3A::new((1.0 - cos * cos).sqrt(), 0.0, cos);
            let got = longest(1.0, Vec3A::NEG_Z, n, Vec3A::NEG_Z);
            let expected = 1.0 / cos.max(MIN_INCIDENCE_COS);
            assert!((got - expected).abs() < 1e-4 * expected, "cos {cos}: {got}");
            // An isotropic cross-section ignores the axis.
            let other = longest(1.0, Vec3A::NEG_Z, n, Vec3A::X);
            assert!((other - expected).abs() < 1e-4 * expected, "{other}");
        }
    }

    #[test]
    fn a_tilt_across_the_radius_stretches_the_tangential_width() {
        // Ray 60 degrees off axis in the xz plane (radial direction in xz); the surface is
        // tilted by 60 degrees about the radial direction, i.e. along the tangential (y)
        // direction: the tangential width 1 stretches to 2, the radial 1/2 stays.
        let theta = 60f32.to_radians();
        let d = Vec3A::new(theta.sin(), 0.0, -theta.cos());
        let n = (-d * 0.5 + Vec3A::Y * (0.75f32).sqrt()).normalize();
        let got = longest(theta.cos(), d, n, Vec3A::NEG_Z);
        assert!((got - 2.0).abs() < 1e-4, "{got}");
        // The same tilt along the radius: the radial 1/2 stretches to 1, as long as the
        // tangential width.
        let radial = Vec3A::new(theta.cos(), 0.0, theta.sin());
        let n = (-d * 0.5 + radial * (0.75f32).sqrt()).normalize();
        let got = longest(theta.cos(), d, n, Vec3A::NEG_Z);
        assert!((got - 1.0).abs() < 1e-4, "{got}");
    }

    #[test]
    fn matches_the_singular_value_of_the_projection_for_any_tilt() {
        // Brute force: the ellipse's boundary points (cos u, a sin u) in the (radial,
        // tangential) frame, projected onto the plane along the ray; the longest distance.
        let theta = 0.9f32;
        let d = Vec3A::new(theta.sin(), 0.0, -theta.cos());
        let e_radial = Vec3A::new(theta.cos(), 0.0, theta.sin());
        let e_tangential = Vec3A::Y;
        let a = theta.cos();
        for (tilt, turn) in [(0.3f32, 0.0f32), (0.8, 0.7), (1.2, 2.0), (1.45, 4.0)] {
            let across = e_radial * turn.cos() + e_tangential * turn.sin();
            let n = (-d * tilt.cos() + across * tilt.sin()).normalize();
            let mut brute = 0.0f32;
            for i in 0..3600 {
                let u = i as f32 * std::f32::consts::TAU / 3600.0;
                let v = e_radial * (a * u.cos()) + e_tangential * u.sin();
                // Slide along the ray onto the plane through the origin.
                let on_plane = v - d * (v.dot(n) / d.dot(n));
                brute = brute.max(on_plane.length());
            }
            let got = longest(a, d, n, Vec3A::NEG_Z);
            assert!(
                (got - brute).abs() < 2e-3 * brute,
                "tilt {tilt}, turn {turn}: {got} vs {brute}"
            );
        }
    }

    #[test]
    fn degenerate_hits_give_finite_axes() {
        for (d, n) in [
            (Vec3A::NEG_Z, Vec3A::ZERO),
            (Vec3A::NEG_Z, Vec3A::X),
            (Vec3A::NAN, Vec3A::Z),
            (Vec3A::NEG_Z, Vec3A::NAN),
        ] {
            let triangle = facing_triangle(0.0, 0.0);
            let mut hit = hit_on(&triangle, 1.0, d, 1.0);
            hit.face_normal = n;
            for ratio in [1.0, 0.5, 1e-6] {
                let got = footprint_longest_axis(ratio, &hit, Vec3A::NEG_Z);
                assert!(got.is_finite() && got > 0.0, "{d} {n} {ratio}: {got}");
                assert!((1.0..=16.0 + 1e-3).contains(&got), "{got}");
            }
        }
    }

    #[test]
    fn widths_and_their_mean() {
        let w = PixelWidths::off_axis(0.5);
        assert_eq!((w.tangential, w.radial), (0.5, 0.25));
        assert_eq!(w.ratio(), 0.5);
        let mean = w.isotropic();
        assert!((mean.tangential - 0.125f32.sqrt()).abs() < 1e-7);
        assert_eq!(mean.ratio(), 1.0);
        assert_eq!(PixelWidths::CENTRE.ratio(), 1.0);
    }
}
