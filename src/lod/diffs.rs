//! `diffs`: ray differentials (Igehy, SIGGRAPH 1999). The ray carries the derivatives of
//! its origin and unit direction with respect to the film's x and y: `dP/dx, dP/dy, dD/dx,
//! dD/dy` (12 floats, 48 bytes).
//!
//! ```text
//! primary:     dP = 0, dD = (D.D dD~ - (D.dD~) D~) / (D.D)^1.5          (eq. 8)
//! transfer:    dP' = dP + t dD + dt D,  dt = -(dP + t dD).N / (D.N)      (eq. 10, 12)
//! reflection:  dR = dD - 2 ((D.N) dN + d(D.N) N),  d(D.N) = dD.N + D.dN  (eq. 14, 15)
//! refraction:  dT = eta dD - (mu dN + dmu N),                            (eq. 16-19)
//!              mu = eta (D.N) - T.N,  dmu = (eta - eta^2 (D.N)/(T.N)) d(D.N)
//! at a hit:    db = (L_u . dP, L_v . dP)       barycentric differentials (RTG1)
//!              duv = db1 (uv1 - uv0) + db2 (uv2 - uv0),  in texels: duv * (W, H)
//! level:       0.5 log2 max(|duv/dx|^2, |duv/dy|^2)     (OpenGL, isotropic)
//! ```
//!
//! `dN` is the derivative of the normalised interpolated normal. Guards: `|D.N|` in the
//! transfer is clamped at 1/16 (the same anisotropy bound as `paper-cos`), and differentials
//! that overflow are dropped (set to zero, level 0) rather than turned into NaN.

use glam::{Vec2, Vec3A};

use super::{
    COARSEST_LEVEL, Footprint, LodCamera, LodMethod, MIN_INCIDENCE_COS, RayLod, SurfaceHit,
    fast_log2, finite_level,
};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RayDiffs {
    pub dp_dx: Vec3A,
    pub dp_dy: Vec3A,
    pub dd_dx: Vec3A,
    pub dd_dy: Vec3A,
}

/// Texture-space derivatives at a hit, in texels per pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TexelGradients {
    pub dx: Vec2,
    pub dy: Vec2,
}

impl TexelGradients {
    /// OpenGL's isotropic level: `log2` of the longer gradient (finite; zero gradients give
    /// a very negative level that clamps to 0).
    #[inline]
    pub fn isotropic_level(&self) -> f32 {
        let longest2 = self.dx.length_squared().max(self.dy.length_squared());
        finite_level(0.5 * fast_log2(longest2.max(1e-30)))
    }
}

impl RayDiffs {
    fn is_finite(&self) -> bool {
        self.dp_dx.is_finite()
            && self.dp_dy.is_finite()
            && self.dd_dx.is_finite()
            && self.dd_dy.is_finite()
    }

    /// Keeps a finite state: overflowing differentials are dropped (pbrt does the same).
    fn finite_or_zero(self) -> Self {
        if self.is_finite() {
            self
        } else {
            RayDiffs::default()
        }
    }

    /// The texel gradients at the hit (after `arrive`), or `None` for a triangle of zero
    /// world area (hit edge-on: the coarsest level is the only safe answer).
    pub fn texel_gradients(
        &self,
        hit: &SurfaceHit,
        texture_size: (u32, u32),
    ) -> Option<TexelGradients> {
        let (lu, lv) = barycentric_gradients(hit.positions())?;
        let [t0, t1, t2] = hit.uvs();
        let (du1, du2) = (t1 - t0, t2 - t0);
        let size = Vec2::new(texture_size.0 as f32, texture_size.1 as f32);
        let texels = |dp: Vec3A| (du1 * lu.dot(dp) + du2 * lv.dot(dp)) * size;
        let g = TexelGradients {
            dx: texels(self.dp_dx),
            dy: texels(self.dp_dy),
        };
        (g.dx.is_finite() && g.dy.is_finite()).then_some(g)
    }
}

/// Gradients `L_u`, `L_v` of the barycentrics b1, b2 in the triangle's plane (`L_u.e1 = 1`,
/// `L_u.e2 = 0`, and the reverse): `db = L . dP` for an in-plane offset `dP`. `None` for a
/// triangle of zero (or non-finite) area.
fn barycentric_gradients([p0, p1, p2]: [Vec3A; 3]) -> Option<(Vec3A, Vec3A)> {
    let (e1, e2) = (p1 - p0, p2 - p0);
    let normal = e1.cross(e2);
    let area2 = normal.length_squared();
    if !(area2 > 0.0 && area2.is_finite()) {
        return None;
    }
    Some((e2.cross(normal) / area2, normal.cross(e1) / area2))
}

/// The normalised interpolated normal's derivatives along the footprint (x, y), zero where
/// the surface is flat-shaded or the shading normal fell back to the face normal.
fn normal_differentials(hit: &SurfaceHit, dp_dx: Vec3A, dp_dy: Vec3A) -> (Vec3A, Vec3A) {
    let [n0, n1, n2] = hit.oriented_normals();
    let (b1, b2) = (hit.bary.x, hit.bary.y);
    let n = n0 * (1.0 - b1 - b2) + n1 * b1 + n2 * b2;
    let nn = n.length_squared();
    let Some((lu, lv)) = barycentric_gradients(hit.positions()) else {
        return (Vec3A::ZERO, Vec3A::ZERO);
    };
    if !(nn > 0.0) || n.dot(hit.shading_normal) <= 0.0 {
        return (Vec3A::ZERO, Vec3A::ZERO);
    }
    let unit_derivative = |dp: Vec3A| {
        let dn = (n1 - n0) * lu.dot(dp) + (n2 - n0) * lv.dot(dp);
        (dn * nn - n * n.dot(dn)) / (nn * nn.sqrt())
    };
    let (dx, dy) = (unit_derivative(dp_dx), unit_derivative(dp_dy));
    if dx.is_finite() && dy.is_finite() {
        (dx, dy)
    } else {
        (Vec3A::ZERO, Vec3A::ZERO)
    }
}

impl RayLod for RayDiffs {
    const METHOD: LodMethod = LodMethod::Diffs;
    const BYTES: usize = 48;
    type Kept = crate::geometry::HitTriangle;

    #[inline]
    fn primary(camera: &LodCamera, px: f32, py: f32) -> Self {
        let (dd_dx, dd_dy) = camera.direction_differentials(px, py);
        RayDiffs {
            dp_dx: Vec3A::ZERO,
            dp_dy: Vec3A::ZERO,
            dd_dx,
            dd_dy,
        }
    }

    #[inline]
    fn arrive(&mut self, hit: &SurfaceHit) {
        let (d, n) = (hit.direction, hit.face_normal);
        // The face normal faces the ray, so D.N <= 0; keep that sign through the clamp.
        let dn = -(d.dot(n).abs().max(MIN_INCIDENCE_COS));
        let transfer = |dp: Vec3A, dd: Vec3A| {
            let moved = dp + dd * hit.t;
            moved + d * (-moved.dot(n) / dn)
        };
        *self = RayDiffs {
            dp_dx: transfer(self.dp_dx, self.dd_dx),
            dp_dy: transfer(self.dp_dy, self.dd_dy),
            ..*self
        }
        .finite_or_zero();
    }

    #[inline]
    fn footprint(&self, hit: &SurfaceHit, _: &LodCamera, texture_size: (u32, u32)) -> Footprint {
        match self.texel_gradients(hit, texture_size) {
            Some(g) => Footprint::Level(g.isotropic_level()),
            None => Footprint::Level(COARSEST_LEVEL),
        }
    }

    fn reflect(&self, hit: &SurfaceHit, _: Vec3A) -> Self {
        let (d, n) = (hit.direction, hit.shading_normal);
        let (dn_dx, dn_dy) = normal_differentials(hit, self.dp_dx, self.dp_dy);
        let reflect = |dd: Vec3A, dn: Vec3A| {
            let d_dot = dd.dot(n) + d.dot(dn);
            dd - 2.0 * (dn * d.dot(n) + n * d_dot)
        };
        RayDiffs {
            dd_dx: reflect(self.dd_dx, dn_dx),
            dd_dy: reflect(self.dd_dy, dn_dy),
            ..*self
        }
        .finite_or_zero()
    }

    fn refract(&self, hit: &SurfaceHit, eta: f32, refracted: Vec3A) -> Self {
        let (d, n) = (hit.direction, hit.shading_normal);
        let (dn_dx, dn_dy) = normal_differentials(hit, self.dp_dx, self.dp_dy);
        let d_n = d.dot(n);
        let t_n = refracted.dot(n);
        let mu = eta * d_n - t_n;
        let dmu_factor = eta - eta * eta * d_n / t_n;
        let refract = |dd: Vec3A, dn: Vec3A| {
            let d_dot = dd.dot(n) + d.dot(dn);
            dd * eta - (dn * mu + n * (dmu_factor * d_dot))
        };
        RayDiffs {
            dd_dx: refract(self.dd_dx, dn_dx),
            dd_dy: refract(self.dd_dy, dn_dy),
            ..*self
        }
        .finite_or_zero()
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{camera, facing_triangle, hit_on, sphere_cap_triangle};
    use super::*;

    fn close(a: Vec3A, b: Vec3A) -> bool {
        (a - b).length() <= 1e-6 * b.length().max(1e-3)
    }

    #[test]
    fn primary_differentials_on_axis_are_one_pixel_along_right_and_down() {
        let cam = camera(1.0, 100);
        let k = 2.0 * 0.5f32.tan() / 100.0;
        let d = RayDiffs::primary(&cam, 50.0, 50.0);
        assert!(close(d.dd_dx, Vec3A::X * k), "{:?}", d.dd_dx);
        assert!(close(d.dd_dy, Vec3A::NEG_Y * k), "{:?}", d.dd_dy);
        assert_eq!((d.dp_dx, d.dp_dy), (Vec3A::ZERO, Vec3A::ZERO));
    }

    #[test]
    fn transfer_to_a_facing_plane_moves_by_t_times_the_direction_differential() {
        let cam = camera(1.0, 100);
        let triangles = facing_triangle(-4.0, 0.0);
        let hit = hit_on(&triangles, 4.0, Vec3A::NEG_Z, 1.0);
        let mut d = RayDiffs::primary(&cam, 50.0, 50.0);
        d.arrive(&hit);
        assert!(close(d.dp_dx, d.dd_dx * 4.0) && close(d.dp_dy, d.dd_dy * 4.0));
        // UVs equal (x, y) on this triangle: a 64 x 64 texture sees 64 k t texels.
        let g = d.texel_gradients(&hit, (64, 64)).unwrap();
        let k = 2.0 * 0.5f32.tan() / 100.0;
        assert!((g.dx.length() - 64.0 * k * 4.0).abs() < 1e-4, "{g:?}");
        assert!((g.isotropic_level() - (64.0 * k * 4.0).log2()).abs() < 1e-5);
    }

    #[test]
    fn planar_mirror_keeps_tangential_and_flips_normal_differentials() {
        let triangles = facing_triangle(0.0, 0.0);
        let hit = hit_on(&triangles, 1.0, Vec3A::NEG_Z, 1.0);
        let d = RayDiffs {
            dp_dx: Vec3A::X,
            dp_dy: Vec3A::Y,
            dd_dx: Vec3A::new(0.01, 0.0, 0.002),
            dd_dy: Vec3A::new(0.0, 0.01, 0.0),
        };
        let r = d.reflect(&hit, Vec3A::Z);
        assert!(
            close(r.dd_dx, Vec3A::new(0.01, 0.0, -0.002)),
            "{:?}",
            r.dd_dx
        );
        assert!(close(r.dd_dy, d.dd_dy));
        assert_eq!((r.dp_dx, r.dp_dy), (d.dp_dx, d.dp_dy));
    }

    #[test]
    fn curved_mirror_and_glass_follow_the_paraxial_laws_at_normal_incidence() {
        // A ball of radius 2 hit head-on: reflection adds 2 dP / R to the angle (kappa = 1/2),
        // refraction gives eta dD - (1 - eta) dP / R (n' u' = n u - (n' - n) y / R).
        let ball = sphere_cap_triangle(2.0);
        let hit = hit_on(&ball, 1.0, Vec3A::NEG_Z, 1.0);
        let d = RayDiffs {
            dp_dx: Vec3A::X * 0.1,
            dp_dy: Vec3A::Y * 0.1,
            dd_dx: Vec3A::X * 0.01,
            dd_dy: Vec3A::Y * 0.01,
        };
        let r = d.reflect(&hit, Vec3A::Z);
        // The beam keeps diverging towards +x on its way back: 0.01 + 2 * 0.1 / 2.
        assert!((r.dd_dx.x - 0.11).abs() < 2e-4, "{:?}", r.dd_dx);
        let eta = 1.0 / 1.5;
        let t = d.refract(&hit, eta, Vec3A::NEG_Z);
        let expected = eta * 0.01 - (1.0 - eta) * 0.1 / 2.0;
        assert!(
            (t.dd_dx.x - expected).abs() < 2e-4,
            "{:?} vs {expected}",
            t.dd_dx
        );
        // Flat glass: the direction differential scales by eta.
        let flat = facing_triangle(0.0, 0.0);
        let hit = hit_on(&flat, 1.0, Vec3A::NEG_Z, 1.0);
        let t = d.refract(&hit, eta, Vec3A::NEG_Z);
        assert!(close(t.dd_dx, d.dd_dx * eta), "{:?}", t.dd_dx);
    }
}
