//! Texture level-of-detail selection: one file per method, all behind [`RayLod`].
//!
//! Every ray carries the state its method needs (its "LOD payload"): nothing for `none`, the
//! path length for `paper` (and its pixel's two widths for `paper-cos`), a cone (width,
//! spread angle, radial ratio) for `cones`, four differential vectors for `diffs`,
//! `diffs-aniso` and `diffs-ewa`. The integrator is generic over the
//! state, so each method pays only for its own payload and arithmetic (the dispatch on
//! [`LodMethod`] happens once per primary ray).
//!
//! The state is created for a primary ray ([`RayLod::primary`]), carried to each hit
//! ([`RayLod::arrive`]), turned into a texture lookup there ([`RayLod::footprint`]), and
//! bent by mirrors and glass ([`RayLod::reflect`], [`RayLod::refract`]). Formulas per
//! method are in the method's file and in docs/src/lod-methods.md.
//!
//! Convention: levels are OpenGL's `log2` of the footprint's longest axis in texels (the
//! ray-cone width, full angle); `--lod-bias` is added to every level afterwards.

mod cones;
mod diffs;
mod diffs_aniso;
mod diffs_ewa;
pub mod log2;
mod none;
mod paper;
mod paper_cos;
mod pb;
mod pixel;
#[cfg(test)]
mod test_support;

pub use cones::RayCone;
pub use diffs::{RayDiffs, TexelGradients};
pub use diffs_aniso::RayDiffsAniso;
pub use diffs_ewa::{EllipticalFootprint, RayDiffsEwa};
pub use none::NoLod;
pub use paper::PathLength;
pub use paper_cos::PathLengthCos;
pub use pb::{
    LOG2_PB_LIMIT, PixelFootprint, cross_squared, log2_pb, log2_pb_from_parts,
    log2_pb_with_texel_term, shift_log2_pb, texel_area, texel_term, uv_area,
};
pub use pixel::{PixelWidths, footprint_longest_axis};

use std::fmt;
use std::str::FromStr;

use glam::{Vec2, Vec3, Vec3A};

use crate::geometry::HitTriangle;

/// A LOD selection method. The CLI word, the stats field and the output folder name are
/// all `Display` of this enum.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LodMethod {
    /// Level 0, bilinear: no MIP-mapping.
    None,
    /// Park & Kim: `log2(path length) - log2 P_b`.
    Paper,
    /// Park & Kim plus the incidence term of ray cones (`- log2 max(|n.d|, 1/16)` on the
    /// axis), with each primary ray's own pixel: exact on a facing plane at any field of view.
    PaperCos,
    /// Ray cones (Akenine-Moller et al. 2019/2021): width and spread angle of each primary
    /// ray's own pixel, curvature spread at mirrors, refraction of the spread.
    Cones,
    /// Igehy's ray differentials; isotropic level, OpenGL convention.
    Diffs,
    /// Ray differentials with anisotropic filtering: up to 16 trilinear taps along the
    /// footprint's major axis.
    DiffsAniso,
    /// Ray differentials with EWA filtering (pbrt-v4's): a Gaussian over the footprint's
    /// ellipse in the level of its minor axis, anisotropy up to 16.
    DiffsEwa,
}

/// Smallest `|n.d|` the incidence term uses (anisotropy 16, as the OptiX toolkit clamps),
/// so grazing rays add at most 4 levels instead of infinitely many.
pub const MIN_INCIDENCE_COS: f32 = 1.0 / 16.0;

/// Most taps an anisotropic lookup takes (and the largest footprint elongation honoured).
pub const MAX_ANISOTROPY: u32 = 16;

/// Stand-in level for "coarsest" (zero-area triangles hit edge-on): finite, and past the
/// last level of any pyramid, so clamping maps it to the last level.
pub const COARSEST_LEVEL: f32 = 1024.0;

impl LodMethod {
    pub const ALL: [LodMethod; 7] = [
        LodMethod::None,
        LodMethod::Paper,
        LodMethod::PaperCos,
        LodMethod::Cones,
        LodMethod::Diffs,
        LodMethod::DiffsAniso,
        LodMethod::DiffsEwa,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            LodMethod::None => "none",
            LodMethod::Paper => "paper",
            LodMethod::PaperCos => "paper-cos",
            LodMethod::Cones => "cones",
            LodMethod::Diffs => "diffs",
            LodMethod::DiffsAniso => "diffs-aniso",
            LodMethod::DiffsEwa => "diffs-ewa",
        }
    }

    /// Whether the method needs the per-triangle `log2 P_b` constants (cones reuse them as
    /// their texture-space triangle constant).
    pub fn needs_log2_pb(self) -> bool {
        matches!(
            self,
            LodMethod::Paper | LodMethod::PaperCos | LodMethod::Cones
        )
    }

    /// Bytes of LOD state a ray carries (f32 components; in memory `Vec3A` pads to 16).
    pub fn bytes_per_ray(self) -> usize {
        with_lod_state!(self, L => L::BYTES)
    }
}

impl fmt::Display for LodMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for LodMethod {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        LodMethod::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = LodMethod::ALL.iter().map(|m| m.as_str()).collect();
                format!(
                    "unknown LOD method '{s}' (expected one of: {})",
                    names.join(", ")
                )
            })
    }
}

/// Evaluates `$body` with the type alias `$L` bound to the per-ray state of `$method`: one
/// match arm per method, so the code inside is monomorphised per method and the dispatch
/// happens once, outside the per-ray code.
macro_rules! with_lod_state {
    ($method:expr, $L:ident => $body:expr) => {
        match $method {
            $crate::lod::LodMethod::None => {
                type $L = $crate::lod::NoLod;
                $body
            }
            $crate::lod::LodMethod::Paper => {
                type $L = $crate::lod::PathLength;
                $body
            }
            $crate::lod::LodMethod::PaperCos => {
                type $L = $crate::lod::PathLengthCos;
                $body
            }
            $crate::lod::LodMethod::Cones => {
                type $L = $crate::lod::RayCone;
                $body
            }
            $crate::lod::LodMethod::Diffs => {
                type $L = $crate::lod::RayDiffs;
                $body
            }
            $crate::lod::LodMethod::DiffsAniso => {
                type $L = $crate::lod::RayDiffsAniso;
                $body
            }
            $crate::lod::LodMethod::DiffsEwa => {
                type $L = $crate::lod::RayDiffsEwa;
                $body
            }
        }
    };
}
pub(crate) use with_lod_state;

/// What LOD needs to know of the view: the camera's orthonormal basis, vertical field of
/// view and film size. The renderer's camera provides it (`render::Camera::view_frame`);
/// `lod` owns the type so it depends on no camera model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewFrame {
    /// Unit view direction.
    pub forward: Vec3A,
    /// Unit right direction, `forward x up`.
    pub right: Vec3A,
    /// Unit up direction, orthogonal to `forward`.
    pub up: Vec3A,
    /// Vertical field of view in radians.
    pub yfov: f32,
    /// Film size in pixels.
    pub width: u32,
    pub height: u32,
}

/// The camera quantities primary rays' LOD state starts from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LodCamera {
    /// `log2` of a pixel's width at unit distance, `log2(2 tan(fov/2) / H)`: the same
    /// constant `log2 P_b` was computed with.
    pub log2_pixel: f32,
    /// Full cone angle of a pixel on the optical axis in the cone's linear model, `k = 2
    /// tan(fov/2) / H`: the width per metre of the pixel's footprint on a facing plane, so
    /// `w = gamma t` is exact there at any field of view. (RTG's `atan(k)` is the same to
    /// `k^2 / 3` relative, but 1.2 levels too sharp for a 3.12 rad film of 64 pixels.)
    pub spread: f32,
    /// Unnormalised primary direction `forward + right * sx + up * sy` and its derivatives
    /// per film pixel in x and y.
    forward: Vec3A,
    right_per_pixel: Vec3A,
    up_per_pixel: Vec3A,
    right_origin: Vec3A,
    up_origin: Vec3A,
}

impl LodCamera {
    /// The constants of a film seen through `camera`. Primary directions follow
    /// `render::camera`'s convention (pixel centres at `+0.5`, `y` down).
    pub fn new(camera: &ViewFrame) -> LodCamera {
        let tan_half = (camera.yfov / 2.0).tan();
        let (w, h) = (camera.width.max(1) as f32, camera.height.max(1) as f32);
        let pixel = PixelFootprint::new(camera.yfov, camera.height);
        let aspect = w / h;
        LodCamera {
            log2_pixel: pixel.log2_k as f32,
            spread: 2.0 * tan_half / h,
            forward: camera.forward,
            right_per_pixel: camera.right * (2.0 * tan_half * aspect / w),
            up_per_pixel: camera.up * (-2.0 * tan_half / h),
            right_origin: camera.right * (-tan_half * aspect),
            up_origin: camera.up * tan_half,
        }
    }

    /// Unnormalised primary direction through film point `(px, py)`: `forward` plus offsets
    /// in the film plane at unit distance.
    #[inline]
    fn film_direction(&self, px: f32, py: f32) -> Vec3A {
        self.forward
            + self.right_origin
            + self.up_origin
            + self.right_per_pixel * px
            + self.up_per_pixel * py
    }

    /// `cos theta` of the primary ray through `(px, py)` with the optical axis: a pixel off
    /// the axis subtends `k cos theta` across the ray (and `k cos^2 theta` along the
    /// radius), not `k`.
    #[inline]
    pub fn off_axis_cos(&self, px: f32, py: f32) -> f32 {
        // `forward` is unit and the film offsets are perpendicular to it: cos = 1 / |D|.
        let cos = self.film_direction(px, py).length_recip();
        if cos.is_finite() { cos.min(1.0) } else { 1.0 }
    }

    /// Derivatives of the unit primary direction through film point `(px, py)` with respect
    /// to the film's x and y (Igehy eq. 8: `d(D/|D|) = (D.D dD - (D.dD) D) / (D.D)^1.5`).
    pub fn direction_differentials(&self, px: f32, py: f32) -> (Vec3A, Vec3A) {
        let d = self.forward
            + self.right_origin
            + self.up_origin
            + self.right_per_pixel * px
            + self.up_per_pixel * py;
        let dd = d.dot(d);
        let scale = 1.0 / (dd * dd.sqrt());
        let unit_derivative = |dd_dp: Vec3A| (dd_dp * dd - d * d.dot(dd_dp)) * scale;
        (
            unit_derivative(self.right_per_pixel),
            unit_derivative(self.up_per_pixel),
        )
    }
}

/// What a LOD method may read at a hit. Oriented towards the incoming ray: `face_normal`
/// and `shading_normal` both face it, and `normal_sign` is the sign that turns the mesh's
/// vertex normals to the same side.
#[derive(Clone, Copy)]
pub struct SurfaceHit<'a> {
    /// The hit triangle in world space.
    pub triangle: &'a HitTriangle,
    /// Distance along the ray.
    pub t: f32,
    /// Unit direction of the incoming ray.
    pub direction: Vec3A,
    pub face_normal: Vec3A,
    pub shading_normal: Vec3A,
    pub normal_sign: f32,
    /// Barycentric weights of vertices 1 and 2.
    pub bary: Vec2,
}

impl SurfaceHit<'_> {
    /// `|n.d|` with the geometric normal, clamped to `[1/16, 1]` (NaN counts as grazing).
    #[inline]
    pub fn clamped_cos(&self) -> f32 {
        self.face_normal
            .dot(self.direction)
            .abs()
            .max(MIN_INCIDENCE_COS)
            .min(1.0)
    }

    #[inline]
    pub fn log2_pb(&self) -> f32 {
        self.triangle.log2_pb
    }

    #[inline]
    pub fn positions(&self) -> [Vec3A; 3] {
        self.triangle.positions
    }

    /// Vertex normals turned to the side the ray came from.
    #[inline]
    pub fn oriented_normals(&self) -> [Vec3A; 3] {
        self.triangle
            .normals
            .map(|n: Vec3| Vec3A::from(n) * self.normal_sign)
    }

    #[inline]
    pub fn uvs(&self) -> [Vec2; 3] {
        self.triangle.uvs
    }
}

/// The texture lookup a method asks for at a hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Footprint {
    /// No MIP-mapping: bilinear at level 0 (`none`; the bias does not apply).
    Base,
    /// Trilinear at this level (before bias and clamping).
    Level(f32),
    /// `taps` trilinear lookups at `level`, spread evenly over `axis` (a texture-coordinate
    /// offset spanning the footprint's major axis, centred on the hit), averaged.
    Anisotropic { level: f32, axis: Vec2, taps: u32 },
    /// EWA over the ellipse with conjugate semi-axes `major` and `minor` (texture-coordinate
    /// offsets per pixel), in the levels around `level`, the minor axis's level.
    Elliptical {
        level: f32,
        major: Vec2,
        minor: Vec2,
    },
}

impl Footprint {
    /// The level the lookup uses, before bias (0 for `Base`).
    pub fn level(&self) -> f32 {
        match *self {
            Footprint::Base => 0.0,
            Footprint::Level(level)
            | Footprint::Anisotropic { level, .. }
            | Footprint::Elliptical { level, .. } => level,
        }
    }
}

/// What a hit waiting for its shadow rays keeps of its triangle for [`RayLod::reflect`] and
/// [`RayLod::refract`]: the whole triangle for a method that reads it there, nothing for one
/// that does not (a renderer keeps a tile's waiting hits, and the triangle was 128 of a
/// waiting hit's 336 bytes, copied for every hit).
pub trait KeptTriangle: Copy + Send + Sync {
    /// What to keep of `triangle`.
    fn keep(triangle: &HitTriangle) -> Self;
    /// The kept triangle: for `()`, a triangle of NaNs, which a method whose `reflect` and
    /// `refract` ignore the hit's triangle never reads (`lod::tests` checks, for every
    /// method that keeps `()`, that both give the same state with it as with the real one).
    fn triangle(&self) -> &HitTriangle;
}

impl KeptTriangle for HitTriangle {
    #[inline(always)]
    fn keep(triangle: &HitTriangle) -> Self {
        *triangle
    }

    #[inline(always)]
    fn triangle(&self) -> &HitTriangle {
        self
    }
}

/// The triangle a method that keeps none sees at a bounce: NaN everywhere, so a method that
/// read it by mistake would give NaN levels, not plausible ones.
static NOT_KEPT: HitTriangle = HitTriangle::UNSET;

impl KeptTriangle for () {
    #[inline(always)]
    fn keep(_: &HitTriangle) -> Self {}

    #[inline(always)]
    fn triangle(&self) -> &HitTriangle {
        &NOT_KEPT
    }
}

/// The per-ray state of one LOD method (see the module doc for the life cycle).
pub trait RayLod: Copy + Send + Sync {
    const METHOD: LodMethod;
    /// Bytes of payload a ray carries (the method's honest cost, not `size_of`, which
    /// includes SIMD padding).
    const BYTES: usize;
    /// What [`Self::reflect`] and [`Self::refract`] read of the hit's triangle:
    /// [`HitTriangle`] when they read it, `()` when they read none of it.
    type Kept: KeptTriangle;

    /// State of the primary ray through film point `(px, py)` (pixels).
    fn primary(camera: &LodCamera, px: f32, py: f32) -> Self;

    /// Carries the state along the ray to the hit at `hit.t`.
    fn arrive(&mut self, hit: &SurfaceHit);

    /// Whether the method's level at a hit depends only on the arriving ray's state, the
    /// hit's distance and the triangle's `log2 P_b` (`paper`): then
    /// [`Self::level_at_distance`] gives it, and the renderer computes each hit's level as
    /// soon as the walk returns the hit, bit for bit the level [`Self::footprint`] gives
    /// after [`Self::arrive`] (see `render::tile`).
    const LEVEL_AT_DISTANCE: bool = false;

    /// With [`Self::LEVEL_AT_DISTANCE`], the level [`Self::footprint`] gives at a hit at
    /// distance `t` on a triangle of `log2_pb`, from the state before [`Self::arrive`].
    /// Not called otherwise.
    #[inline(always)]
    fn level_at_distance(&self, t: f32, log2_pb: f32) -> f32 {
        let _ = (t, log2_pb);
        unreachable!("{:?} has no level at a distance", Self::METHOD)
    }

    /// The lookup at the hit (called after `arrive`) in a texture of `texture_size`
    /// texels at level 0. Must be finite for any hit, degenerate or grazing.
    fn footprint(
        &self,
        hit: &SurfaceHit,
        camera: &LodCamera,
        texture_size: (u32, u32),
    ) -> Footprint;

    /// State of the ray reflected at the hit into `reflected` (unit).
    fn reflect(&self, hit: &SurfaceHit, reflected: Vec3A) -> Self;

    /// State of the ray refracted at the hit into `refracted` (unit); `eta` is
    /// `n_incident / n_transmitted`.
    fn refract(&self, hit: &SurfaceHit, eta: f32, refracted: Vec3A) -> Self;
}

/// `log2 x` for LOD selection, within 1e-6 of the exact value (relative, for results above
/// 1 in magnitude, where f32 rounding of the sum dominates) for positive normal `x`,
/// and several times cheaper than the library call (which alone cost `paper` about 3% of
/// a frame). The exponent comes from the bits; the mantissa, reduced to `[sqrt(1/2),
/// sqrt(2))`, goes through the atanh series `log2 m = 2/ln 2 (s + s^3/3 + s^5/5 + s^7/7)`,
/// `s = (m - 1)/(m + 1)`, `|s| < 0.172`, so the first dropped term is below 1e-7.
/// Non-positive and NaN inputs give -126 (the finest level after clamping), +inf gives 128.
#[inline]
pub fn fast_log2(x: f32) -> f32 {
    // Zero, subnormals, negative values and NaN read as `MIN_POSITIVE` (one `maxss`: the
    // constant is never NaN, so `f32::max` needs no NaN fix-up), whose bits below give
    // exactly -126; +inf stays, and its bits below give exactly 128 (exponent field 255,
    // mantissa 0). Every other input is positive normal finite and passes unchanged.
    let x = x.max(f32::MIN_POSITIVE);
    // x = 2^e m with m in [1, 2); where m > sqrt(2) (in f32) it reads as 2^(e + 1) (m / 2).
    // Both in the bits, without a branch (which half a hit's length falls in is as good as
    // random): subtracting the bits of `sqrt(2)`'s successor, less one exponent, borrows
    // from the exponent exactly when m <= sqrt(2), so the exponent field of `shifted` is
    // e + 1 or e and its low bits are m's mantissa moved by that offset; adding the offset
    // back gives m / 2 or m.
    const OFFSET: u32 = std::f32::consts::SQRT_2.to_bits() + 1 - (1 << 23);
    let shifted = x.to_bits().wrapping_sub(OFFSET) as i32;
    let exponent = (shifted >> 23) as f32;
    let m = f32::from_bits((shifted as u32 & 0x007f_ffff) + OFFSET);
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    exponent + s * (2.885_39 + s2 * (0.961_796_7 + s2 * (0.577_078 + s2 * 0.412_198_6)))
}

/// Replaces a non-finite level by a finite one: NaN by 0 (finest), +inf by the coarsest.
#[inline]
pub fn finite_level(level: f32) -> f32 {
    if level.is_nan() {
        0.0
    } else {
        level.clamp(-COARSEST_LEVEL, COARSEST_LEVEL)
    }
}

/// Mean edge curvature of a triangle from its (oriented) vertex normals (JCGT 2021,
/// "TriangleCurvature_Average"): `k_ij = (n_j - n_i).(p_j - p_i) / |p_j - p_i|^2`.
/// Positive where the surface bulges towards the normals (convex), 0 for flat shading.
pub fn mean_edge_curvature(p: [Vec3A; 3], n: [Vec3A; 3]) -> f32 {
    let mut sum = 0.0;
    let mut edges = 0;
    for (i, j) in [(0, 1), (1, 2), (2, 0)] {
        let dp = p[j] - p[i];
        let len2 = dp.length_squared();
        if len2 > 0.0 && len2.is_finite() {
            let k = (n[j] - n[i]).dot(dp) / len2;
            if k.is_finite() {
                sum += k;
                edges += 1;
            }
        }
    }
    if edges == 0 { 0.0 } else { sum / edges as f32 }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `reflect` and `refract` of the hit, once with its triangle and once with the NaN
    /// triangle a method that keeps none sees at a bounce ([`KeptTriangle`]): whether the
    /// states come out the same (compared as printed, bit patterns of NaN included).
    fn bounce_ignores_the_triangle<L: RayLod + fmt::Debug>() -> bool {
        let camera = test_support::camera(0.9, 480);
        let mut state = L::primary(&camera, 131.0, 207.5);
        let triangle = test_support::sphere_cap_triangle(2.5);
        let direction = Vec3A::new(0.1, -0.2, -1.0).normalize();
        let hit = test_support::hit_on(&triangle, 3.0, direction, 1.0);
        state.arrive(&hit);
        let blind = SurfaceHit {
            triangle: ().triangle(),
            ..hit
        };
        let reflected = Vec3A::new(0.1, -0.2, 1.0).normalize();
        let refracted = Vec3A::new(0.05, -0.1, -1.0).normalize();
        let same = |a: L, b: L| format!("{a:?}") == format!("{b:?}");
        same(
            state.reflect(&hit, reflected),
            state.reflect(&blind, reflected),
        ) && same(
            state.refract(&hit, 0.67, refracted),
            state.refract(&blind, 0.67, refracted),
        )
    }

    /// The methods that keep no triangle for a bounce (`type Kept = ()`) must not read it
    /// there; the check tells the others apart (they read it, and keep it).
    #[test]
    fn methods_that_keep_no_triangle_do_not_read_it_at_a_bounce() {
        assert!(bounce_ignores_the_triangle::<NoLod>());
        assert!(bounce_ignores_the_triangle::<PathLength>());
        assert!(bounce_ignores_the_triangle::<PathLengthCos>());
        assert!(!bounce_ignores_the_triangle::<RayCone>());
        assert!(!bounce_ignores_the_triangle::<RayDiffs>());
        assert!(!bounce_ignores_the_triangle::<RayDiffsAniso>());
        assert!(!bounce_ignores_the_triangle::<RayDiffsEwa>());
        // Which kind each method is, as the renderer keeps it.
        let keeps = |size: usize| size == std::mem::size_of::<HitTriangle>();
        assert!(!keeps(std::mem::size_of::<<PathLength as RayLod>::Kept>()));
        assert!(!keeps(std::mem::size_of::<<NoLod as RayLod>::Kept>()));
        assert!(!keeps(
            std::mem::size_of::<<PathLengthCos as RayLod>::Kept>()
        ));
        assert!(keeps(std::mem::size_of::<<RayCone as RayLod>::Kept>()));
        assert!(keeps(std::mem::size_of::<<RayDiffs as RayLod>::Kept>()));
    }

    #[test]
    fn names_round_trip() {
        for m in LodMethod::ALL {
            assert_eq!(m.as_str().parse::<LodMethod>().unwrap(), m);
        }
        assert!("bogus".parse::<LodMethod>().is_err());
    }

    #[test]
    fn payload_sizes_are_as_documented() {
        assert_eq!(LodMethod::None.bytes_per_ray(), 0);
        assert_eq!(LodMethod::Paper.bytes_per_ray(), 4);
        assert_eq!(LodMethod::PaperCos.bytes_per_ray(), 12);
        assert_eq!(LodMethod::Cones.bytes_per_ray(), 12);
        assert_eq!(LodMethod::Diffs.bytes_per_ray(), 48);
        assert_eq!(LodMethod::DiffsEwa.bytes_per_ray(), 48);
    }

    /// `fast_log2`'s mantissa reduction as a branch, as it was first written: the bit form
    /// gives the same exponent and mantissa, so the same bits, for every positive normal
    /// float (all 2^31 - 2^24 of them are too many for a test; every mantissa near the
    /// `sqrt(2)` threshold and at the ends, under every exponent, and a stride of the rest).
    #[test]
    fn fast_log2_reduces_the_mantissa_as_the_branch_did() {
        let branch = |x: f32| {
            if !(x >= f32::MIN_POSITIVE) {
                return -126.0;
            }
            if x > f32::MAX {
                return 128.0;
            }
            let bits = x.to_bits();
            let mut exponent = ((bits >> 23) as i32 - 127) as f32;
            let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
            if m > std::f32::consts::SQRT_2 {
                m *= 0.5;
                exponent += 1.0;
            }
            let s = (m - 1.0) / (m + 1.0);
            let s2 = s * s;
            exponent + s * (2.885_39 + s2 * (0.961_796_7 + s2 * (0.577_078 + s2 * 0.412_198_6)))
        };
        let threshold = std::f32::consts::SQRT_2.to_bits() & 0x007f_ffff;
        let mut compared = 0u64;
        for field in 1u32..255 {
            let near = (threshold - 300..threshold + 300)
                .chain(0..300)
                .chain(0x7f_fed4..0x80_0000);
            for mantissa in near.chain((0..0x80_0000).step_by(997)) {
                let x = f32::from_bits((field << 23) | mantissa);
                assert_eq!(fast_log2(x).to_bits(), branch(x).to_bits(), "{x:e}");
                compared += 1;
            }
        }
        for x in [
            0.0,
            -0.0,
            -1.0,
            1e-40,
            f32::NAN,
            f32::INFINITY,
            f32::MIN_POSITIVE,
        ] {
            assert_eq!(fast_log2(x).to_bits(), branch(x).to_bits(), "{x:e}");
        }
        // And a stride through every bit pattern: both signs, zeros, subnormals, NaNs of
        // any payload, the infinities.
        for bits in (0..=u32::MAX)
            .step_by(65_521)
            .chain([0x7fff_ffff, 0xffff_ffff])
        {
            let x = f32::from_bits(bits);
            assert_eq!(fast_log2(x).to_bits(), branch(x).to_bits(), "{bits:#x}");
        }
        assert!(compared > 2_000_000, "{compared}");
    }

    #[test]
    fn fast_log2_matches_f64_log2_to_a_millionth() {
        let mut worst = 0.0f64;
        let mut x = 1e-30f32;
        while x < 1e30 {
            let exact = (x as f64).log2();
            // Relative to the magnitude: the final f32 sum rounds like any f32 result.
            worst = worst.max((fast_log2(x) as f64 - exact).abs() / exact.abs().max(1.0));
            x *= 1.000_37;
        }
        assert!(worst < 1e-6, "worst error {worst}");
        for p in -126..128 {
            assert_eq!(fast_log2(2f32.powi(p)), p as f32, "2^{p}");
        }
        assert_eq!(fast_log2(0.0), -126.0);
        assert_eq!(fast_log2(-3.0), -126.0);
        assert_eq!(fast_log2(f32::NAN), -126.0);
        assert_eq!(fast_log2(f32::INFINITY), 128.0);
        // The ends of the range that passes the guard unchanged, and just outside it.
        assert_eq!(fast_log2(f32::MIN_POSITIVE), -126.0);
        assert!((fast_log2(f32::MAX) - 128.0).abs() < 1e-5);
        for outside in [
            f32::MIN_POSITIVE.next_down(),
            f32::from_bits(1),
            -0.0,
            -f32::MIN_POSITIVE,
            f32::MIN,
            f32::NEG_INFINITY,
            -f32::NAN,
        ] {
            assert_eq!(fast_log2(outside), -126.0, "{outside:e}");
        }
    }

    #[test]
    fn finite_level_maps_nan_and_infinities() {
        assert_eq!(finite_level(f32::NAN), 0.0);
        assert_eq!(finite_level(f32::INFINITY), COARSEST_LEVEL);
        assert_eq!(finite_level(f32::NEG_INFINITY), -COARSEST_LEVEL);
        assert_eq!(finite_level(2.5), 2.5);
    }

    #[test]
    fn sphere_curvature_is_one_over_radius() {
        // Three points on a sphere of radius 2 with outward normals.
        let n = [
            Vec3A::new(1.0, 0.0, 0.0),
            Vec3A::new(0.0, 1.0, 0.0),
            Vec3A::new(0.0, 0.0, 1.0),
        ];
        let p = n.map(|v| v * 2.0);
        assert!((mean_edge_curvature(p, n) - 0.5).abs() < 1e-6);
        assert!((mean_edge_curvature(p, n.map(|v| -v)) + 0.5).abs() < 1e-6);
        // Flat shading and a degenerate triangle: zero.
        assert_eq!(mean_edge_curvature(p, [Vec3A::Z; 3]), 0.0);
        assert_eq!(mean_edge_curvature([Vec3A::ONE; 3], n), 0.0);
    }
}
