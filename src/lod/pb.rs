//! The per-triangle constant `log2 P_b` of Park & Kim (2010), in the corrected form derived in
//! `../shared/METHOD.md` (not the paper's eq. 7 as printed, which inverts the dependence on
//! world area and omits the field of view).
//!
//! Pinhole camera, vertical field of view `fov`, image height `H` pixels: a pixel at distance
//! `z` is `k z` wide with `k = 2 tan(fov/2) / H`. A triangle of world area `A` and UV area
//! `a` carrying a `W x Ht` texture has texels `sqrt(A / (a W Ht))` wide, so one texel covers
//! one pixel at `P_b = sqrt(A / (a W Ht)) / k`:
//!
//! ```text
//! log2 P_b = 0.5 log2(A / (a W Ht)) - log2 k
//! ```
//!
//! Both areas are true areas (half the cross product), so their factors of 1/2 cancel.
//! Computed in f64 from f32 vertices: edge differences are then exact, which keeps huge
//! world coordinates from destroying the area.
//!
//! Degenerate triangles get a finite constant, never NaN (documented in docs/src/lod-methods.md):
//! - zero world area (`A = 0`, hit only edge-on, if at all): `-LOG2_PB_LIMIT`, so the level
//!   clamps to the coarsest MIP level;
//! - zero UV area with `A > 0` (the texture is constant along the triangle or a line): the
//!   finest level is correct, so `+LOG2_PB_LIMIT`, which clamps the level to 0;
//! - non-finite inputs: `+LOG2_PB_LIMIT` (level 0).

use glam::{DVec2, DVec3, Vec2, Vec3A};

/// Magnitude of the finite stand-in for `log2 P_b = ±inf`. Larger than any `log2` of an f32
/// (at most 128 in magnitude) so the level still clamps to the right end, small enough that
/// `log2(P_l) - log2 P_b` stays finite.
pub const LOG2_PB_LIMIT: f32 = 1024.0;

/// The camera quantity `log2 P_b` depends on: the width of a pixel at unit distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelFootprint {
    /// `log2(2 tan(fov/2) / H)`.
    pub log2_k: f64,
}

impl PixelFootprint {
    /// `yfov` in radians, `image_height` in pixels (both > 0).
    pub fn new(yfov: f32, image_height: u32) -> Self {
        let k = 2.0 * (yfov as f64 / 2.0).tan() / image_height.max(1) as f64;
        PixelFootprint { log2_k: k.log2() }
    }
}

/// `log2 P_b` of one triangle: world vertices `p`, texture coordinates `uv`, level-0 texture
/// size `texture_size` (width, height), camera `footprint`.
///
/// The guards read the texel area (the uv area times the texel count): it is finite exactly
/// when the uv area is (a texture has 1..=16384² texels), and zero exactly when the uv area
/// or the texel count is.
pub fn log2_pb(
    p: [Vec3A; 3],
    uv: [Vec2; 3],
    texture_size: (u32, u32),
    footprint: PixelFootprint,
) -> f32 {
    let texel_area = texel_area(uv_area(uv), texture_size);
    let [p0, p1, p2] = p.map(|v| DVec3::new(v.x as f64, v.y as f64, v.z as f64));
    let world_area = 0.5 * (p1 - p0).cross(p2 - p0).length();
    if !(world_area.is_finite() && texel_area.is_finite()) {
        return LOG2_PB_LIMIT;
    }
    if world_area <= 0.0 {
        return -LOG2_PB_LIMIT;
    }
    if texel_area <= 0.0 {
        return LOG2_PB_LIMIT;
    }
    let value = 0.5 * (world_area / texel_area).log2() - footprint.log2_k;
    (value as f32).clamp(-LOG2_PB_LIMIT, LOG2_PB_LIMIT)
}

/// The area of a triangle in texture coordinates (in `f64`; the same for either winding,
/// bit for bit: swapping two vertices negates the cross product exactly).
#[inline]
pub fn uv_area(uv: [Vec2; 3]) -> f64 {
    let [t0, t1, t2] = uv.map(|t| DVec2::new(t.x as f64, t.y as f64));
    0.5 * (t1 - t0).perp_dot(t2 - t0).abs()
}

/// The triangle's area in level-0 texels: its [`uv_area`] times the texture's texel count
/// (the product [`log2_pb`] divides the world area by).
#[inline]
pub fn texel_area(uv_area: f64, texture_size: (u32, u32)) -> f64 {
    uv_area * (texture_size.0 as f64 * texture_size.1 as f64)
}

/// The part of `log2 P_b` a triangle's [`texel_area`] `T` contributes, `0.5 log2(T) + 0.5`
/// (the `0.5` is the halving of the world area's cross product), so that
/// `log2 P_b = 0.25 log2(|e1 x e2|^2) - texel_term - log2 k` needs neither a square root nor
/// a division per triangle (a deforming mesh keeps this term per triangle: its uvs and
/// texture never change). Zero area gives `-inf`, a non-finite area `+inf`: the guards of
/// [`log2_pb_with_texel_term`] read them.
#[inline]
pub fn texel_term(texel_area: f64) -> f64 {
    if texel_area.is_finite() {
        0.5 * texel_area.log2() + 0.5
    } else {
        f64::INFINITY
    }
}

/// `log2 P_b` from the triangle's [`texel_term`]: the value [`log2_pb`] gives or its f32
/// neighbour (the two round differently in f64; tested). The form for triangles whose term
/// is kept (a deforming mesh's, recomputed every frame): one `log2` per triangle and frame,
/// no square root, no division. A triangle gets its constant from one form or the other for
/// the whole run, so frames never mix the two roundings for it.
///
/// The guards read the squared cross product `cc` and the term: `cc` is finite exactly when
/// the world area is (edges of f32 vertices are at most ~7e38, so `cc` stays below 1e157),
/// and zero exactly when it is (the smallest nonzero product of f32 differences squared is
/// ~1e-180, far above f64's underflow); the term is `+inf` exactly when the texel area is not
/// finite and `-inf` exactly when it is zero.
#[inline]
pub fn log2_pb_with_texel_term(p: [Vec3A; 3], texel_term: f64, footprint: PixelFootprint) -> f32 {
    let cc = cross_squared(p);
    log2_pb_from_parts(cc, super::log2::log2(cc), texel_term, footprint)
}

/// `|e1 x e2|^2` of a triangle, in `f64` (edges of f32 vertices are exact there).
#[inline]
pub fn cross_squared(p: [Vec3A; 3]) -> f64 {
    let [p0, p1, p2] = p.map(|v| DVec3::new(v.x as f64, v.y as f64, v.z as f64));
    let cross = (p1 - p0).cross(p2 - p0);
    cross.dot(cross)
}

/// [`log2_pb_with_texel_term`] from its parts: `cc` ([`cross_squared`]) and its `log2`
/// (`lod::log2`, perhaps taken in a batch: the same bits), so a pass over many triangles can
/// take the logarithms together.
///
/// Degenerate inputs give a limit: a non-finite `cc` or an infinite texel term (no area in
/// uv, or none at all) `LOG2_PB_LIMIT`; a triangle of no area (`cc <= 0`) its negative. The
/// value is computed for every input and the limits chosen after it, without branches, so
/// a loop over a batch compiles to vector code. A NaN texel term (callers leave such slots
/// out) gives NaN for a triangle with area, as `f32::clamp` passes it on.
#[inline(always)]
pub fn log2_pb_from_parts(
    cc: f64,
    log2_cc: f64,
    texel_term: f64,
    footprint: PixelFootprint,
) -> f32 {
    // 0.5 log2(A / T) with A = 0.5 sqrt(cc): 0.25 log2(cc) - 0.5 - 0.5 log2(T).
    let value = (0.25 * log2_cc - texel_term - footprint.log2_k) as f32;
    // `f32::clamp`'s comparisons, as selects.
    let value = if value < -LOG2_PB_LIMIT {
        -LOG2_PB_LIMIT
    } else {
        value
    };
    let value = if value > LOG2_PB_LIMIT {
        LOG2_PB_LIMIT
    } else {
        value
    };
    // The degenerate cases, the first that holds deciding (so taken last to first).
    let value = if texel_term == f64::NEG_INFINITY {
        LOG2_PB_LIMIT
    } else {
        value
    };
    let value = if cc <= 0.0 { -LOG2_PB_LIMIT } else { value };
    if cc.is_finite() && texel_term != f64::INFINITY {
        value
    } else {
        LOG2_PB_LIMIT
    }
}

/// `log2 P_b` of a similarity-placed triangle: the object-space constant plus `log2 s`
/// (world area scales by `s^2`, and `log2 P_b` holds half the log of the area).
pub fn shift_log2_pb(object: f32, log2_scale: f64) -> f32 {
    if object.abs() >= LOG2_PB_LIMIT {
        return object; // degenerate stand-ins stay at their limit
    }
    ((object as f64 + log2_scale) as f32).clamp(-LOG2_PB_LIMIT, LOG2_PB_LIMIT)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Vec3};

    /// The first-written form of [`log2_pb_from_parts`], one early return per degenerate case.
    fn log2_pb_from_parts_by_branches(
        cc: f64,
        log2_cc: f64,
        texel_term: f64,
        footprint: PixelFootprint,
    ) -> f32 {
        if !(cc.is_finite() && texel_term != f64::INFINITY) {
            return LOG2_PB_LIMIT;
        }
        if cc <= 0.0 {
            return -LOG2_PB_LIMIT;
        }
        if texel_term == f64::NEG_INFINITY {
            return LOG2_PB_LIMIT;
        }
        let value = 0.25 * log2_cc - texel_term - footprint.log2_k;
        (value as f32).clamp(-LOG2_PB_LIMIT, LOG2_PB_LIMIT)
    }

    /// The branch-free form gives the first-written form's bits on every combination of hard
    /// parts: zero, negative, subnormal, tiny, huge, infinite and NaN squared cross products
    /// (with their true `log2` where there is one, and garbage where there is none: a
    /// degenerate case must not read it), texel terms of every such kind, and footprints
    /// that push the value past either limit.
    #[test]
    fn log2_pb_from_parts_gives_the_branching_form_s_bits() {
        let specials = [
            0.0,
            -0.0,
            -1.0,
            f64::MIN_POSITIVE / 8.0,
            f64::MIN_POSITIVE,
            1e-300,
            1e-12,
            0.25,
            1.0,
            3.5,
            1e12,
            1e300,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
        ];
        let terms = [
            0.0,
            -0.0,
            -3.0,
            7.5,
            2000.0,
            -2000.0,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let footprints = [-9.3, 0.0, 5000.0, -5000.0].map(|log2_k| PixelFootprint { log2_k });
        let mut compared = 0;
        for &cc in &specials {
            for log2_cc in [crate::lod::log2::log2(cc), f64::NAN, 1e308, -1e308] {
                for &term in &terms {
                    for footprint in footprints {
                        let want = log2_pb_from_parts_by_branches(cc, log2_cc, term, footprint);
                        let got = log2_pb_from_parts(cc, log2_cc, term, footprint);
                        assert!(
                            got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                            "cc {cc:e}, log2 {log2_cc:e}, term {term:e}, k {}: {got} against {want}",
                            footprint.log2_k
                        );
                        compared += 1;
                    }
                }
            }
        }
        assert_eq!(compared, 17 * 4 * 11 * 4);
    }

    const FOV: f32 = std::f32::consts::FRAC_PI_3;

    fn quad_triangle(size: f32, z: f32) -> [Vec3A; 3] {
        let h = size / 2.0;
        [
            Vec3A::new(-h, -h, z),
            Vec3A::new(h, -h, z),
            Vec3A::new(h, h, z),
        ]
    }
    const UV: [Vec2; 3] = [
        Vec2::new(0.0, 1.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(1.0, 0.0),
    ];

    /// The frame loop reads a deforming triangle's uv area from its source uvs while its
    /// slot may hold them in the other winding (a mirrored node): the same bits.
    #[test]
    fn uv_area_is_the_same_bits_in_either_winding() {
        let mut seed = 0x853c49e6748fea9bu64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 3.0 - 1.0
        };
        for _ in 0..10_000 {
            let uv = [0, 1, 2].map(|_| Vec2::new(next(), next() * 1e3));
            let swapped = [uv[0], uv[2], uv[1]];
            assert_eq!(uv_area(uv).to_bits(), uv_area(swapped).to_bits(), "{uv:?}");
        }
    }

    #[test]
    fn matches_closed_form_for_facing_quad() {
        // A 2 m quad with one 256^2 texture: texel = 2/256 m. At 480 px and 60 degrees,
        // k = 2 tan(30deg) / 480; P_b = (2/256) / k.
        let fp = PixelFootprint::new(FOV, 480);
        let got = log2_pb(quad_triangle(2.0, 0.0), UV, (256, 256), fp) as f64;
        let k = 2.0 * (FOV as f64 / 2.0).tan() / 480.0;
        let expected = ((2.0 / 256.0) / k).log2();
        assert!((got - expected).abs() < 1e-6, "{got} vs {expected}");
    }

    #[test]
    fn scales_as_derived() {
        let fp = PixelFootprint::new(FOV, 480);
        let base = log2_pb(quad_triangle(2.0, 0.0), UV, (256, 256), fp);
        // World area x2 -> P_b x sqrt2 -> +0.5.
        let s = 2f32.sqrt();
        let bigger = log2_pb(quad_triangle(2.0 * s, 0.0), UV, (256, 256), fp);
        assert!((bigger - base - 0.5).abs() < 1e-5);
        // Texture doubled per side -> -1.
        let denser = log2_pb(quad_triangle(2.0, 0.0), UV, (512, 512), fp);
        assert!((denser - base + 1.0).abs() < 1e-6);
        // Image height doubled -> +1.
        let taller = log2_pb(
            quad_triangle(2.0, 0.0),
            UV,
            (256, 256),
            PixelFootprint::new(FOV, 960),
        );
        assert!((taller - base - 1.0).abs() < 1e-6);
        // UV area halved -> +0.5.
        let half_uv = UV.map(|t| Vec2::new(t.x * 0.5, t.y));
        let sparser = log2_pb(quad_triangle(2.0, 0.0), half_uv, (256, 256), fp);
        assert!((sparser - base - 0.5).abs() < 1e-6);
        // tan(fov/2) halved -> +1.
        let narrow = PixelFootprint::new(2.0 * 0.5f32.atan(), 480);
        let wide = PixelFootprint::new(std::f32::consts::FRAC_PI_2, 480);
        let d = log2_pb(quad_triangle(2.0, 0.0), UV, (256, 256), narrow)
            - log2_pb(quad_triangle(2.0, 0.0), UV, (256, 256), wide);
        assert!((d - 1.0).abs() < 1e-6);
    }

    #[test]
    fn rigid_motion_leaves_it_unchanged() {
        let fp = PixelFootprint::new(FOV, 480);
        let tri = [
            Vec3A::new(0.3, -1.2, 0.5),
            Vec3A::new(2.0, 0.1, -0.7),
            Vec3A::new(-0.4, 1.5, 1.1),
        ];
        let uv = [
            Vec2::new(0.1, 0.2),
            Vec2::new(0.9, 0.35),
            Vec2::new(0.4, 0.8),
        ];
        let base = log2_pb(tri, uv, (300, 200), fp);
        let r = Mat3::from_euler(glam::EulerRot::XYZ, 0.7, -1.3, 2.1);
        let t = Vec3::new(150.0, -42.0, 7.5);
        let moved = tri.map(|p| Vec3A::from(r * Vec3::from(p) + t));
        let after = log2_pb(moved, uv, (300, 200), fp);
        assert!((after - base).abs() < 1e-6, "{base} -> {after}");
        // Winding reversed (mirror image UVs) changes nothing: areas are absolute.
        let flipped = log2_pb(
            [tri[0], tri[2], tri[1]],
            [uv[0], uv[2], uv[1]],
            (300, 200),
            fp,
        );
        assert!((flipped - base).abs() < 1e-6);
    }

    #[test]
    fn huge_coordinates_keep_precision() {
        let fp = PixelFootprint::new(FOV, 480);
        let near = log2_pb(quad_triangle(2.0, 0.0), UV, (256, 256), fp);
        let offset = Vec3A::new(1.0e6, 0.0, 0.0);
        let far = log2_pb(
            quad_triangle(2.0, 0.0).map(|p| p + offset),
            UV,
            (256, 256),
            fp,
        );
        assert!((far - near).abs() < 1e-6);
    }

    #[test]
    fn degenerate_triangles_are_finite() {
        let fp = PixelFootprint::new(FOV, 480);
        let line = [Vec3A::ZERO, Vec3A::X, Vec3A::X * 2.0];
        assert_eq!(log2_pb(line, UV, (256, 256), fp), -LOG2_PB_LIMIT);
        let flat_uv = [Vec2::ZERO, Vec2::X, Vec2::X * 2.0];
        assert_eq!(
            log2_pb(quad_triangle(1.0, 0.0), flat_uv, (256, 256), fp),
            LOG2_PB_LIMIT
        );
        assert_eq!(log2_pb(line, flat_uv, (256, 256), fp), -LOG2_PB_LIMIT);
        let nan = [Vec3A::NAN, Vec3A::X, Vec3A::Y];
        assert_eq!(log2_pb(nan, UV, (256, 256), fp), LOG2_PB_LIMIT);
        assert_eq!(
            log2_pb(quad_triangle(1.0, 0.0), UV, (0, 0), fp),
            LOG2_PB_LIMIT
        );
    }

    /// The texel-term form (no square root, no division) against the formula as derived,
    /// `0.5 log2(A / T) - log2 k` with `A` half the cross product's length (which `log2_pb`
    /// computes exactly so), on random triangles from tiny to huge and textures from 1 to
    /// 16384^2 texels: the same f32 or its neighbour (the two round differently in f64
    /// before the f32 cast), mostly the same.
    #[test]
    fn texel_term_form_matches_the_derived_formula() {
        let fp = PixelFootprint::new(FOV, 480);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut same, mut neighbour) = (0, 0);
        for _ in 0..20_000 {
            let scale = 2f64.powf(next() * 80.0 - 40.0) as f32;
            let offset = 2f64.powf(next() * 40.0) as f32 * if next() < 0.5 { -1.0 } else { 1.0 };
            let mut vertex =
                || Vec3A::new(next() as f32, next() as f32, next() as f32) * scale + offset;
            let p = [vertex(), vertex(), vertex()];
            let uv = [0, 1, 2].map(|_| Vec2::new(next() as f32, next() as f32));
            let size = (1 + (next() * 16383.0) as u32, 1 + (next() * 16383.0) as u32);
            let texels = texel_area(uv_area(uv), size);
            let [p0, p1, p2] = p.map(|v| DVec3::new(v.x as f64, v.y as f64, v.z as f64));
            let area = 0.5 * (p1 - p0).cross(p2 - p0).length();
            if area <= 0.0 || texels <= 0.0 {
                continue;
            }
            let derived = ((0.5 * (area / texels).log2() - fp.log2_k) as f32)
                .clamp(-LOG2_PB_LIMIT, LOG2_PB_LIMIT);
            assert_eq!(log2_pb(p, uv, size, fp).to_bits(), derived.to_bits());
            let ours = log2_pb_with_texel_term(p, texel_term(texels), fp);
            let ulps = (ours.to_bits() as i64 - derived.to_bits() as i64).abs();
            assert!(ulps <= 1, "{p:?} {uv:?} {size:?}: {ours} vs {derived}");
            if ulps == 0 {
                same += 1;
            } else {
                neighbour += 1;
            }
        }
        assert!(
            same > 100 * neighbour,
            "{same} equal, {neighbour} one ulp apart"
        );
    }

    /// The term's guards: a zero texel area gives the finest level, a non-finite one too;
    /// a zero world area the coarsest unless the texel area is not finite.
    #[test]
    fn texel_term_keeps_the_guards_of_the_areas() {
        let fp = PixelFootprint::new(FOV, 480);
        let quad = quad_triangle(1.0, 0.0);
        let line = [Vec3A::ZERO, Vec3A::X, Vec3A::X * 2.0];
        assert_eq!(texel_term(0.0), f64::NEG_INFINITY);
        assert_eq!(
            log2_pb_with_texel_term(quad, texel_term(0.0), fp),
            LOG2_PB_LIMIT
        );
        for bad in [f64::INFINITY, f64::NAN] {
            assert_eq!(texel_term(bad), f64::INFINITY);
            assert_eq!(
                log2_pb_with_texel_term(quad, texel_term(bad), fp),
                LOG2_PB_LIMIT
            );
            assert_eq!(
                log2_pb_with_texel_term(line, texel_term(bad), fp),
                LOG2_PB_LIMIT
            );
        }
        assert_eq!(
            log2_pb_with_texel_term(line, texel_term(1.0), fp),
            -LOG2_PB_LIMIT
        );
        assert_eq!(
            log2_pb_with_texel_term(line, texel_term(0.0), fp),
            -LOG2_PB_LIMIT
        );
        let huge = [Vec3A::ZERO, Vec3A::X * 3e38, Vec3A::Y * 3e38];
        let value = log2_pb_with_texel_term(huge, texel_term(1.0), fp);
        assert!(value.is_finite() && value > 100.0, "{value}");
    }

    #[test]
    fn uniform_scale_shifts_the_constant_by_log2_s_and_keeps_degenerate_limits() {
        assert_eq!(shift_log2_pb(3.0, 1.0), 4.0);
        assert_eq!(shift_log2_pb(-2.5, -0.5), -3.0);
        // Degenerate stand-ins (at the limit) never move, and shifts clamp at the limit.
        assert_eq!(shift_log2_pb(LOG2_PB_LIMIT, -3.0), LOG2_PB_LIMIT);
        assert_eq!(shift_log2_pb(-LOG2_PB_LIMIT, 3.0), -LOG2_PB_LIMIT);
        assert_eq!(shift_log2_pb(LOG2_PB_LIMIT - 1.0, 10.0), LOG2_PB_LIMIT);
    }
}
