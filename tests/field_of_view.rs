//! Texture LOD at any field of view: on a plane facing a pinhole camera every pixel covers
//! the same `k z` square (`k = 2 tan(fov/2) / H`, depth `z`), so the exact level is the same
//! on every pixel, however far off the axis. A pixel `theta` off the axis is only
//! `cos(theta)` as wide across its ray and `cos^2(theta)` along the radius as the centre
//! pixel, while its ray is `1 / cos(theta)` longer and meets the plane at `|n.d| =
//! cos(theta)`; methods that spread every ray by the centre pixel's angle are blurrier
//! there by `-log2 cos(theta)` per missing factor.

mod common;

use common::scenes::*;
use mipray::frame::Renderer;
use mipray::lod::LodMethod;
use mipray::scene::SceneDesc;

/// Film size of the closed-form checks (square, as in the survey).
const FILM: u32 = 256;
/// Texture side, mapped once on the quad.
const TEXTURE: u32 = 256;

/// A quad at depth 1 facing a camera of vertical field of view `fov_deg` whose `width` x
/// `height` film it covers to the corners, and the exact level everywhere on it.
fn covering_quad(fov_deg: f64, width: u32, height: u32) -> (SceneDesc, f64) {
    let tan_half = (fov_deg.to_radians() / 2.0).tan();
    let aspect = width as f64 / height as f64;
    let corner_reach = tan_half * (1.0 + aspect * aspect).sqrt();
    let size = 2.5 * corner_reach;
    let k = 2.0 * tan_half / height as f64;
    let exact = (k * TEXTURE as f64 / size).log2();
    let scene = facing_quad_scene(1.0, size as f32, TEXTURE, (fov_deg as f32).to_radians());
    (scene, exact)
}

/// The level each pixel centre of a `width` x `height` film selects with `lod` (before
/// clamping), row-major; `None` where the probe finds no texture.
fn levels(scene: SceneDesc, width: u32, height: u32, lod: LodMethod) -> Vec<Option<f64>> {
    let mut renderer = Renderer::new(scene, settings(width, height, lod));
    let prepared = renderer.prepare(0, 0.0).unwrap();
    let frame = renderer.frame_scene(&prepared);
    (0..width * height)
        .map(|i| {
            let (x, y) = ((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
            frame
                .probe_method(&prepared.camera, x, y)
                .map(|p| p.level as f64)
        })
        .collect()
}

/// The level `lod` selects through film point `(px, py)` of a `FILM` x `FILM` film.
fn level_at(scene: SceneDesc, lod: LodMethod, px: f32, py: f32) -> f64 {
    let mut renderer = Renderer::new(scene, settings(FILM, FILM, lod));
    let prepared = renderer.prepare(0, 0.0).unwrap();
    renderer
        .frame_scene(&prepared)
        .probe_method(&prepared.camera, px, py)
        .unwrap_or_else(|| panic!("{lod}: no textured surface at ({px}, {py})"))
        .level as f64
}

/// `cos(theta)` of the ray through film point `(px, py)` of a `FILM` x `FILM` film.
fn off_axis_cos(fov_deg: f64, px: f64, py: f64) -> f64 {
    let tan_half = (fov_deg.to_radians() / 2.0).tan();
    let sx = (2.0 * px / FILM as f64 - 1.0) * tan_half;
    let sy = (1.0 - 2.0 * py / FILM as f64) * tan_half;
    1.0 / (1.0 + sx * sx + sy * sy).sqrt()
}

/// Film points of the closed-form checks: the centre, a point 45% of the way to the top
/// right corner, and the top left corner pixel.
const ON_AND_OFF_AXIS: [(&str, f32, f32); 3] = [
    ("on axis", 128.0, 128.0),
    ("off axis", 185.5, 70.5),
    ("corner", 0.5, 0.5),
];

#[test]
fn facing_quad_at_60_120_and_179_degrees_is_exact_on_and_off_axis() {
    // Every miss is listed, not only the first.
    let mut misses = Vec::new();
    let mut check = |lod: LodMethod, fov: f64, what: &str, px: f32, py: f32| {
        let (scene, exact) = covering_quad(fov, FILM, FILM);
        let cos = off_axis_cos(fov, px as f64, py as f64);
        let got = level_at(scene, lod, px, py);
        if (got - exact).abs() >= 0.05 {
            misses.push(format!(
                "{lod} at {fov} degrees, {what} (cos {cos:.4}): level {got:.4}, exact {exact:.4}"
            ));
        }
    };
    for fov in [60.0, 120.0, 179.0] {
        for (what, px, py) in ON_AND_OFF_AXIS {
            for lod in [LodMethod::PaperCos, LodMethod::Cones] {
                check(lod, fov, what, px, py);
            }
            // `diffs` transfers its differentials with `|n.d|` clamped at 1/16: exact where
            // the ray meets the plane at least that steeply (all of a 60 or 120 degree film),
            // not in the far corners of a 179 degree one (see the last test).
            if off_axis_cos(fov, px as f64, py as f64) >= 1.0 / 16.0 {
                check(LodMethod::Diffs, fov, what, px, py);
            }
        }
    }
    // At 179 degrees diffs is checked 85.6 degrees off the axis, inside its clamp.
    let (px, py) = (140.5, 120.5);
    let cos = off_axis_cos(179.0, px as f64, py as f64);
    assert!(cos > 1.0 / 16.0 && cos < 0.08, "cos {cos}");
    check(LodMethod::Diffs, 179.0, "85.6 degrees off axis", px, py);
    assert!(
        misses.is_empty(),
        "{} misses:\n{}",
        misses.len(),
        misses.join("\n")
    );
}

#[test]
fn facing_plane_every_pixel_within_a_tenth_of_a_level_at_any_field_of_view() {
    let (width, height) = (48, 32);
    for fov in [
        0.5, 10.0, 45.0, 90.0, 135.0, 160.0, 170.0, 175.0, 179.0, 179.9,
    ] {
        // `diffs` only up to where its transfer guard starts to bite at the corners.
        let methods: &[LodMethod] = if fov <= 160.0 {
            &[LodMethod::PaperCos, LodMethod::Cones, LodMethod::Diffs]
        } else {
            &[LodMethod::PaperCos, LodMethod::Cones]
        };
        for &lod in methods {
            let (scene, exact) = covering_quad(fov, width, height);
            let levels = levels(scene, width, height, lod);
            assert!(
                levels.iter().all(Option::is_some),
                "{lod} at {fov}: a pixel missed"
            );
            let worst = levels
                .iter()
                .flatten()
                .map(|l| l - exact)
                .fold(0.0f64, |w, e| if e.abs() > w.abs() { e } else { w });
            assert!(
                worst.abs() < 0.1,
                "{lod} at {fov} degrees: worst pixel {worst:+.4} levels from exact {exact:.4}"
            );
        }
    }
}

#[test]
fn paper_keeps_the_papers_formula_and_its_off_axis_blur() {
    // `paper` is Park & Kim's `log2(P_l) - log2 P_b`: the path to an off-axis pixel of a
    // facing plane is `z / cos(theta)`, so it is `-log2 cos(theta)` levels blurrier there.
    for fov in [60.0, 120.0, 179.0] {
        let (_, exact) = covering_quad(fov, FILM, FILM);
        for (what, px, py) in ON_AND_OFF_AXIS {
            let cos = off_axis_cos(fov, px as f64, py as f64);
            let got = level_at(covering_quad(fov, FILM, FILM).0, LodMethod::Paper, px, py);
            let paper = exact - cos.log2();
            assert!(
                (got - paper).abs() < 0.05,
                "paper at {fov} degrees, {what}: level {got:.4}, paper's formula {paper:.4}"
            );
        }
    }
}

#[test]
fn diffs_transfer_guard_sharpens_the_far_corners_of_a_179_degree_film() {
    // Where a primary ray meets the facing plane at `|n.d| < 1/16`, `diffs` moves its
    // differentials onto the plane with `|n.d|` clamped at 1/16 (its guard against grazing
    // hits): the correction along the ray is too short and the footprint on the plane
    // shrinks, up to half a level in the corners of a 179-degree film. This pins that
    // known limit of the method's own guard (frames of `diffs` are kept as they are); a
    // change to the guard must update it deliberately.
    let (scene, exact) = covering_quad(179.0, FILM, FILM);
    let got = level_at(scene, LodMethod::Diffs, 0.5, 0.5);
    let error = got - exact;
    assert!(
        (-0.55..-0.3).contains(&error),
        "diffs at the corner of a 179-degree film: {error:+.4} levels"
    );
}
