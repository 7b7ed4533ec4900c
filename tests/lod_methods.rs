//! The LOD methods side by side on scenes with closed-form answers.

mod common;

use common::scenes::*;
use glam::{Quat, Vec3};
use image::RgbImage;
use mipray::frame::{RenderSettings, Renderer};
use mipray::lod::LodMethod;
use mipray::render::LodProbe;
use mipray::scene::{MeshDesc, SceneDesc, Trs};

/// What method `lod` selects through film point `(px, py)` of frame 0.
fn probe(scene: SceneDesc, size: (u32, u32), lod: LodMethod, px: f32, py: f32) -> LodProbe {
    let mut renderer = Renderer::new(scene, settings(size.0, size.1, lod));
    let prepared = renderer.prepare(0, 0.0).unwrap();
    renderer
        .frame_scene(&prepared)
        .probe_method(&prepared.camera, px, py)
        .unwrap_or_else(|| panic!("{lod}: the probe ray finds no textured surface"))
}

/// The closed form on a quad facing the camera: `log2(d) - log2 P_b`, with
/// `P_b = texel width / pixel width at unit distance`.
fn facing_closed_form(distance: f64, size: f64, texture: u32, yfov: f32, height: u32) -> f64 {
    let k = 2.0 * (yfov as f64 / 2.0).tan() / height as f64;
    distance.log2() - ((size / texture as f64) / k).log2()
}

const MIPMAPPED: [LodMethod; 6] = [
    LodMethod::Paper,
    LodMethod::PaperCos,
    LodMethod::Cones,
    LodMethod::Diffs,
    LodMethod::DiffsAniso,
    LodMethod::DiffsEwa,
];

#[test]
fn facing_quad_every_method_is_within_two_hundredths_of_the_closed_form() {
    let yfov = 60f32.to_radians();
    for (distance, size, texture) in [(4.0, 2.0, 256), (9.0, 1.0, 1024), (2.5, 3.0, 64)] {
        let expected = facing_closed_form(distance as f64, size as f64, texture, yfov, 64);
        for lod in MIPMAPPED {
            let scene = facing_quad_scene(distance, size, texture, yfov);
            let got = probe(scene, (64, 64), lod, 32.0, 32.0).level as f64;
            assert!(
                (got - expected).abs() < 0.02,
                "{lod} at d={distance}, size {size}, texture {texture}: level {got}, closed form {expected}"
            );
        }
        // `none` has no MIP-mapping: always level 0.
        let scene = facing_quad_scene(distance, size, texture, yfov);
        assert_eq!(
            probe(scene, (64, 64), LodMethod::None, 32.0, 32.0).level,
            0.0
        );
    }
}

#[test]
fn lod_bias_shifts_every_mipmapped_level() {
    let yfov = 60f32.to_radians();
    for lod in MIPMAPPED {
        let level = |bias: f32| {
            let mut renderer = Renderer::new(
                facing_quad_scene(4.0, 2.0, 256, yfov),
                RenderSettings {
                    lod_bias: bias,
                    ..settings(64, 64, lod)
                },
            );
            let prepared = renderer.prepare(0, 0.0).unwrap();
            let p = renderer
                .frame_scene(&prepared)
                .probe_method(&prepared.camera, 32.0, 32.0)
                .unwrap();
            p.level
        };
        let shift = level(1.5) - level(0.0);
        assert!(
            (shift - 1.5).abs() < 1e-5,
            "{lod}: bias 1.5 moved the level by {shift}"
        );
    }
}

fn tilted_quad(yfov: f32) -> SceneDesc {
    let mut scene = facing_quad_scene(4.0, 2.0, 256, yfov);
    scene.nodes[0].local.rotation = Quat::from_rotation_x(60f32.to_radians());
    scene
}

#[test]
fn plane_tilted_60_degrees_adds_one_level_to_cos_aware_methods() {
    let yfov = 60f32.to_radians();
    let level = |lod| probe(tilted_quad(yfov), (64, 64), lod, 32.0, 32.0);
    let paper = level(LodMethod::Paper).level;
    for lod in [LodMethod::PaperCos, LodMethod::Cones, LodMethod::Diffs] {
        let got = level(lod).level;
        assert!(
            (got - paper - 1.0).abs() < 0.02,
            "{lod}: {got}, paper {paper}: expected one level more"
        );
    }
    // Anisotropic filtering spends the elongation (1 / cos 60 = 2) on two taps instead: its
    // level stays at the footprint's short axis, which the tilt leaves unchanged.
    // EWA likewise filters at the minor axis's level and spreads along the major one.
    for lod in [LodMethod::DiffsAniso, LodMethod::DiffsEwa] {
        let got = level(lod).level;
        assert!((got - paper).abs() < 0.02, "{lod} {got}, paper {paper}");
    }
}

/// Camera at the origin looking down -Z at a mirror 3 m away; the textured quad hangs 2 m
/// behind the camera facing -Z, so the reflected path is 3 + 5 = 8 m.
fn planar_mirror_scene(yfov: f32) -> SceneDesc {
    let mut scene = facing_quad_scene(0.0, 2.0, 256, yfov);
    scene.nodes[0].local.translation = Vec3::new(0.0, 0.0, 2.0);
    scene.nodes[0].local.rotation = Quat::from_rotation_y(std::f32::consts::PI);
    scene.materials.push(mirror());
    scene.meshes.push(MeshDesc {
        name: "mirror".into(),
        primitives: vec![quad(4.0, 1.0, 1)],
        ..Default::default()
    });
    add_root(
        &mut scene,
        node("mirror", at(Vec3::new(0.0, 0.0, -3.0)), Some(1)),
    );
    scene
}

#[test]
fn planar_mirror_paper_and_cones_use_the_total_path_length() {
    let yfov = 50f32.to_radians();
    let expected = facing_closed_form(8.0, 2.0, 256, yfov, 64);
    for lod in [LodMethod::Paper, LodMethod::Cones, LodMethod::Diffs] {
        let p = probe(planar_mirror_scene(yfov), (64, 64), lod, 32.0, 32.0);
        assert_eq!(p.chain.bends().len(), 1, "{lod}: one mirror on the way");
        assert!(
            (p.path_length - 8.0).abs() < 1e-3,
            "{lod}: path {}",
            p.path_length
        );
        assert!(
            (p.level as f64 - expected).abs() < 0.02,
            "{lod}: level {} vs the virtual image at 8 m: {expected}",
            p.level
        );
    }
}

/// A smooth mirror ball between the camera and a textured backdrop behind the camera.
fn convex_mirror_scene(yfov: f32) -> SceneDesc {
    let mut scene = planar_mirror_scene(yfov);
    scene.meshes[1].primitives = vec![sphere(1, 4)];
    let ball = scene.nodes.iter().position(|n| n.name == "mirror").unwrap();
    scene.nodes[ball].local.translation = Vec3::new(0.0, 0.0, -4.0);
    scene.meshes[0].primitives = vec![quad(40.0, 20.0, 0)];
    scene
}

#[test]
fn convex_mirror_spreads_cones_and_differentials_beyond_the_path_length() {
    // A ball of radius 1 at 3 m: the reflected footprint grows much faster than the path
    // length alone says (the virtual image of the backdrop is a small, far-away one).
    let yfov = 50f32.to_radians();
    let level = |lod| probe(convex_mirror_scene(yfov), (64, 64), lod, 32.0, 32.0).level;
    let paper = level(LodMethod::Paper);
    for lod in [LodMethod::Cones, LodMethod::Diffs] {
        let got = level(lod);
        assert!(got > paper + 1.0, "{lod}: {got}, paper {paper}");
    }
    // Cones and differentials model the same physics: they agree to within a level.
    let (cones, diffs) = (level(LodMethod::Cones), level(LodMethod::Diffs));
    eprintln!("convex mirror: paper {paper}, cones {cones}, diffs {diffs}");
    assert!((cones - diffs).abs() < 1.0, "cones {cones}, diffs {diffs}");
}

/// A receding checker floor (camera 1 m above it looking at the horizon).
fn receding_floor_scene(squares: f32) -> SceneDesc {
    let mut scene = SceneDesc {
        background: Vec3::new(0.3, 0.4, 0.6),
        ..Default::default()
    };
    scene.textures.push(checker(256, 8));
    scene.materials.push(textured(0));
    scene.meshes.push(MeshDesc {
        name: "floor".into(),
        primitives: vec![quad(400.0, squares, 0)],
        ..Default::default()
    });
    add_root(
        &mut scene,
        node(
            "floor",
            Trs {
                rotation: Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
                ..Default::default()
            },
            Some(0),
        ),
    );
    let cam = camera_node(Vec3::new(0.0, 1.0, 0.0), &mut scene, 0.8);
    scene.roots.push(cam);
    scene
}

#[test]
fn no_method_gives_a_nan_or_infinite_level_on_degenerate_or_grazing_hits() {
    for lod in LodMethod::ALL {
        assert_finite_levels(grazing_scene(), lod);
    }
}

/// Camera at floor height: every floor hit is grazing. Also a mirror ball and a glass
/// ball (curvature spread, refraction of cones and differentials) on the floor.
fn grazing_scene() -> SceneDesc {
    let mut scene = receding_floor_scene(200.0);
    add_degenerate_mesh(&mut scene, 0);
    let camera = scene.nodes.iter().position(|n| n.camera.is_some()).unwrap();
    scene.nodes[camera].local.translation = Vec3::new(0.0, 1e-3, 0.0);
    scene.materials.extend([mirror(), glass()]);
    for (material, x) in [(1, -0.8f32), (2, 0.8)] {
        scene.meshes.push(MeshDesc {
            name: format!("ball{material}"),
            primitives: vec![sphere(material, 3)],
            ..Default::default()
        });
        let mesh = scene.meshes.len() - 1;
        let mut ball = node("ball", at(Vec3::new(x, 0.5, -4.0)), Some(mesh));
        ball.local.scale = Vec3::splat(0.5);
        add_root(&mut scene, ball);
    }
    scene
}

fn assert_finite_levels(scene: SceneDesc, lod: LodMethod) {
    {
        let mut renderer = Renderer::new(scene, settings(48, 32, lod));
        let (image, record) = renderer.render_frame(0, 0.0).unwrap();
        assert!(
            image.pixels.iter().all(|p| p.is_finite()),
            "{lod}: NaN pixel"
        );
        assert_eq!(record.nonfinite_samples, 0, "{lod}");
        let prepared = renderer.prepare(0, 0.0).unwrap();
        let frame_scene = renderer.frame_scene(&prepared);
        let mut probed = 0;
        for y in 0..32 {
            for x in 0..48 {
                let Some(p) =
                    frame_scene.probe_method(&prepared.camera, x as f32 + 0.5, y as f32 + 0.5)
                else {
                    continue;
                };
                probed += 1;
                assert!(
                    p.level.is_finite() && p.clamped_level.is_finite(),
                    "{lod}: level {} at pixel ({x}, {y})",
                    p.level
                );
            }
        }
        assert!(probed > 100, "{lod}: only {probed} textured pixels");
    }
}

fn srgb(image: &mipray::render::film::LinearImage) -> RgbImage {
    RgbImage::from_raw(image.width, image.height, image.to_srgb8()).unwrap()
}

#[test]
fn on_a_receding_checker_none_has_the_largest_flip_error() {
    let (w, h) = (96, 64);
    let render = |lod: LodMethod, spp: u32| {
        let mut renderer = Renderer::new(
            receding_floor_scene(400.0),
            RenderSettings {
                spp,
                ..settings(w, h, lod)
            },
        );
        srgb(&renderer.render_frame(0, 0.0).unwrap().0)
    };
    // The ground truth: level 0, 8x8 stratified samples per pixel.
    let reference = render(LodMethod::None, 64);
    let flip: Vec<(LodMethod, f64)> = LodMethod::ALL
        .iter()
        .map(|&lod| {
            let test = render(lod, 1);
            (lod, mipray::metrics::compare(&reference, &test).0.mean_flip)
        })
        .collect();
    let none = flip[0].1;
    eprintln!("receding checker FLIP: {flip:?}");
    for &(lod, error) in &flip[1..] {
        assert!(
            error < none,
            "{lod}: FLIP {error:.4} is not below none's {none:.4} (all: {flip:?})"
        );
    }
}

/// Mean LOD error of `lod` against the finite-difference reference over frame 0.
fn lod_error(scene: SceneDesc, lod: LodMethod) -> mipray::compare::lod_error::LodErrorStats {
    use mipray::compare::lod_error::{method_error, reference_levels};
    let mut renderer = Renderer::new(scene, settings(64, 64, lod));
    let prepared = renderer.prepare(0, 0.0).unwrap();
    let frame_scene = renderer.frame_scene(&prepared);
    let reference = reference_levels(&frame_scene, &prepared.camera);
    method_error(&frame_scene, &prepared.camera, &reference)
}

#[test]
fn finite_difference_reference_agrees_with_the_closed_forms() {
    let yfov = 60f32.to_radians();
    // Facing the camera every method (but none) matches the reference over the whole quad.
    for lod in MIPMAPPED {
        let e = lod_error(facing_quad_scene(4.0, 2.0, 256, yfov), lod);
        assert!(e.pixels > 100, "{lod}: {} pixels measured", e.pixels);
        assert!(
            e.bias.abs() < 0.1 && e.under == 0.0,
            "{lod} facing: bias {} under {}",
            e.bias,
            e.under
        );
    }
    // Tilted by 60 degrees the paper misses log2(1 / cos 60) = 1 level everywhere; the
    // incidence-aware methods do not.
    let paper = lod_error(tilted_quad(yfov), LodMethod::Paper);
    assert!(
        (paper.bias + 1.0).abs() < 0.15,
        "paper tilted: bias {}",
        paper.bias
    );
    assert!(
        paper.under > 0.9,
        "paper tilted: under-filtered share {}",
        paper.under
    );
    for lod in [
        LodMethod::PaperCos,
        LodMethod::Cones,
        LodMethod::Diffs,
        LodMethod::DiffsAniso,
    ] {
        let e = lod_error(tilted_quad(yfov), lod);
        assert!(e.bias.abs() < 0.15, "{lod} tilted: bias {}", e.bias);
    }
    // Behind a planar mirror the reference follows the reflected rays.
    let e = lod_error(planar_mirror_scene(50f32.to_radians()), LodMethod::Paper);
    assert!(
        e.pixels > 100 && e.bias.abs() < 0.1,
        "paper via mirror: {e:?}"
    );
}

/// The two-mirror chain, in the camera's xz plane: eye at the origin looking down
/// -Z; a concave mirror (radius 2) 3 m away at 20 degrees incidence; 2 m on, past its
/// focus, a convex mirror ball (radius 1) at 15 degrees; 5 m on, a textured wall facing the
/// ray. `TwoMirrorChain` holds the designed geometry (f64) for the exact 2-D trace.
struct TwoMirrorChain {
    concave_centre: glam::DVec3,
    ball_centre: glam::DVec3,
    wall_point: glam::DVec3,
    wall_normal: glam::DVec3,
}

const CONCAVE_RADIUS: f64 = 2.0;
const BALL_RADIUS: f64 = 1.0;

fn reflect64(d: glam::DVec3, n: glam::DVec3) -> glam::DVec3 {
    d - n * (2.0 * d.dot(n))
}

impl TwoMirrorChain {
    fn design() -> TwoMirrorChain {
        use glam::{DQuat, DVec3};
        let p1 = DVec3::new(0.0, 0.0, -3.0);
        let n1 = DQuat::from_rotation_y(20f64.to_radians()) * DVec3::Z;
        let d1 = reflect64(DVec3::NEG_Z, n1);
        let p2 = p1 + d1 * 2.0;
        let n2 = DQuat::from_rotation_y(15f64.to_radians()) * -d1;
        let d2 = reflect64(d1, n2);
        TwoMirrorChain {
            concave_centre: p1 + n1 * CONCAVE_RADIUS,
            ball_centre: p2 - n2 * BALL_RADIUS,
            wall_point: p2 + d2 * 5.0,
            wall_normal: -d2,
        }
    }

    /// Where an eye ray at `angle` (radians, about +Y) meets the wall, traced exactly
    /// through the two circles: the distance along the wall from the designed point.
    fn wall_offset(&self, angle: f64) -> f64 {
        use glam::{DQuat, DVec3};
        let sphere_hit = |o: DVec3, d: DVec3, c: DVec3, r: f64, far: bool| {
            let (b, cc) = ((o - c).dot(d), (o - c).length_squared() - r * r);
            let root = (b * b - cc).sqrt();
            o + d * if far { -b + root } else { -b - root }
        };
        let d0 = DQuat::from_rotation_y(angle) * DVec3::NEG_Z;
        let p1 = sphere_hit(DVec3::ZERO, d0, self.concave_centre, CONCAVE_RADIUS, true);
        let d1 = reflect64(d0, (self.concave_centre - p1).normalize());
        let p2 = sphere_hit(p1, d1, self.ball_centre, BALL_RADIUS, false);
        let d2 = reflect64(d1, (p2 - self.ball_centre).normalize());
        let t = (self.wall_point - p2).dot(self.wall_normal) / d2.dot(self.wall_normal);
        let along = self.wall_normal.cross(DVec3::Y);
        (p2 + d2 * t - self.wall_point).dot(along)
    }

    /// The footprint width at the wall of a beam of unit angular width from the eye (the
    /// ray-cone width in units of the pixel spread angle), by central differences.
    fn exact_width_per_spread(&self) -> f64 {
        let e = 1e-6;
        (self.wall_offset(e) - self.wall_offset(-e)).abs() / (2.0 * e)
    }

    fn scene(&self, yfov: f32) -> SceneDesc {
        let mut scene = facing_quad_scene(0.0, 2.0, 256, yfov);
        let wall_rotation = glam::DQuat::from_rotation_arc(glam::DVec3::Z, self.wall_normal);
        scene.nodes[0].local = Trs {
            translation: self.wall_point.as_vec3(),
            rotation: wall_rotation.as_quat(),
            ..Default::default()
        };
        scene.materials.push(mirror());
        // Only a cap of the concave sphere (the camera sits inside the full sphere, and
        // the last leg leaves it 34 degrees from the cap's centre).
        let towards_cap = (glam::DVec3::new(0.0, 0.0, -3.0) - self.concave_centre).normalize();
        scene.meshes.push(MeshDesc {
            name: "concave".into(),
            primitives: vec![spherical_cap(
                1,
                6,
                towards_cap.as_vec3(),
                25f32.to_radians(),
            )],
            ..Default::default()
        });
        scene.meshes.push(MeshDesc {
            name: "ball".into(),
            primitives: vec![sphere(1, 6)],
            ..Default::default()
        });
        let mut concave = node("concave", at(self.concave_centre.as_vec3()), Some(1));
        concave.local.scale = Vec3::splat(CONCAVE_RADIUS as f32);
        add_root(&mut scene, concave);
        let mut ball = node("ball", at(self.ball_centre.as_vec3()), Some(2));
        ball.local.scale = Vec3::splat(BALL_RADIUS as f32);
        add_root(&mut scene, ball);
        scene
    }
}

/// The triangles of the unit sphere whose vertices all lie within `half_angle` of `axis`.
fn spherical_cap(
    material: usize,
    subdivisions: u32,
    axis: Vec3,
    half_angle: f32,
) -> mipray::scene::PrimitiveDesc {
    let mut cap = sphere(material, subdivisions);
    let inside = |i: &u32| cap.positions[*i as usize].dot(axis) >= half_angle.cos();
    cap.indices = cap
        .indices
        .chunks_exact(3)
        .filter(|t| t.iter().all(inside))
        .flatten()
        .copied()
        .collect();
    cap
}

#[test]
fn cones_match_the_exact_trace_through_a_focus_and_a_convex_mirror() {
    let chain = TwoMirrorChain::design();
    let width = chain.exact_width_per_spread();
    // The chain's figure: 26.7 pixel spreads (the |w| rule gave 2.0, 3.7 levels too sharp).
    assert!((width - 26.7).abs() < 0.05, "exact 2-D trace width {width}");
    let yfov = 30f32.to_radians();
    // A cone of width `width * gamma` on a facing wall looks like the wall seen directly
    // from `width` metres.
    let expected = facing_closed_form(width, 2.0, 256, yfov, 64);
    let p = probe(chain.scene(yfov), (64, 64), LodMethod::Cones, 32.0, 32.0);
    assert_eq!(
        p.chain.bends().len(),
        2,
        "two mirrors on the way: {:?}",
        p.chain
    );
    // Tolerance: the tessellated mirrors (subdivision 6, faces within 0.7 degrees of the
    // sphere) move the hits and incidence cosines by well under 1%, i.e. < 0.02 levels.
    assert!(
        (p.level as f64 - expected).abs() < 0.03,
        "cones level {} vs the exact trace's {expected} (width {width} spreads)",
        p.level
    );
}

#[test]
fn a_wide_field_of_view_renders_and_selects_levels_with_the_same_value() {
    // yfov 3.12 rad: tan(yfov / 2) = 92.6. The camera used to render such a camera at
    // 0.8 rad while `log2 P_b` took 3.12 (since fixed).
    let yfov = 3.12f32;
    let (distance, size, side) = (0.02f32, 2.0f32, 64u32);
    let mut renderer = Renderer::new(
        facing_quad_scene(distance, size, 256, yfov),
        settings(side, side, LodMethod::Paper),
    );
    let prepared = renderer.prepare(0, 0.0).unwrap();
    assert_eq!(
        prepared.camera.yfov, yfov,
        "the render camera's field of view"
    );
    // The level on the optical axis is the closed form of the same field of view.
    for lod in [LodMethod::Paper, LodMethod::Cones, LodMethod::Diffs] {
        let p = probe(
            facing_quad_scene(distance, size, 256, yfov),
            (side, side),
            lod,
            32.0,
            32.0,
        );
        let expected = facing_closed_form(distance as f64, size as f64, 256, yfov, side);
        assert!(
            (p.level as f64 - expected).abs() < 0.02,
            "{lod}: level {} vs {expected}",
            p.level
        );
    }
    // And the image shows the quad at the size that field of view gives it: half-width
    // 1 m at 2 cm is tan = 50 of the film's 92.6, i.e. 34.6 of 64 pixels across.
    let (image, _) = renderer.render_frame(0, 0.0).unwrap();
    let row = side / 2;
    let background = Vec3::splat(0.1);
    let covered = (0..side)
        .filter(|&x| {
            (image.pixels[(row * side + x) as usize] - background)
                .abs()
                .max_element()
                > 1e-3
        })
        .count() as f64;
    let expected = side as f64 * (size as f64 / 2.0 / distance as f64) / (yfov as f64 / 2.0).tan();
    assert!(
        (covered - expected).abs() <= 1.0,
        "{covered} pixels of the middle row show the quad; a {yfov} rad film shows {expected:.1}"
    );
}

/// Asserts `got` is within 0.02 levels of `expected` (the tolerance for closed forms).
fn assert_level(what: &str, got: f32, expected: f64) {
    assert!(
        (got as f64 - expected).abs() < 0.02,
        "{what}: level {got}, closed form {expected:.4}"
    );
}

#[test]
fn corner_pixel_of_a_wide_image_matches_each_methods_closed_form() {
    // 128 x 64 at 90 degrees: the corner pixel's ray is 65.7 degrees off the optical axis.
    // The film projects onto a parallel plane by a uniform scale, so the exact footprint is
    // the on-axis one, `k d`; `diffs` finds it, and so do `cones` and `paper-cos`, whose
    // pixel is `k cos` wide across the ray and `k cos^2` along the radius, which the
    // incidence stretches back to `k cos`; `paper` uses the path `d / cos` (the paper's
    // formula knows only the centre pixel).
    let (yfov, (w, h), d, size, texture) = (90f32.to_radians(), (128, 64), 2.0f32, 10.0, 1024);
    let exact = facing_closed_form(d as f64, size, texture, yfov, h);
    let (px, py) = (0.5f32, 0.5f32);
    let tan_half = (yfov as f64 / 2.0).tan();
    let sx = (2.0 * px as f64 / w as f64 - 1.0) * tan_half * w as f64 / h as f64;
    let sy = (1.0 - 2.0 * py as f64 / h as f64) * tan_half;
    let off_axis = -(1.0 / (1.0 + sx * sx + sy * sy).sqrt()).log2();
    assert!(off_axis > 1.2, "corner only {off_axis} levels off axis");
    for (lod, expected) in [
        (LodMethod::Diffs, exact),
        (LodMethod::Cones, exact),
        (LodMethod::Paper, exact + off_axis),
        (LodMethod::PaperCos, exact),
    ] {
        let scene = facing_quad_scene(d, size as f32, texture, yfov);
        let p = probe(scene, (w, h), lod, px, py);
        assert_level(&format!("{lod} at the corner"), p.level, expected);
        let scene = facing_quad_scene(d, size as f32, texture, yfov);
        let centre = probe(scene, (w, h), lod, w as f32 / 2.0, h as f32 / 2.0);
        assert_level(&format!("{lod} at the centre"), centre.level, exact);
    }
}

#[test]
fn tilted_plane_levels_are_the_closed_forms() {
    let yfov = 60f32.to_radians();
    let facing = facing_closed_form(4.0, 2.0, 256, yfov, 64);
    let level = |lod| probe(tilted_quad(yfov), (64, 64), lod, 32.0, 32.0).level;
    assert_level("paper tilted", level(LodMethod::Paper), facing);
    for lod in [LodMethod::PaperCos, LodMethod::Cones, LodMethod::Diffs] {
        assert_level(&format!("{lod} tilted"), level(lod), facing + 1.0);
    }
}

#[test]
fn convex_mirror_on_axis_is_paper_plus_the_paraxial_spread() {
    // Ball radius 1 at 3 m, backdrop 5 m back: w = 3 gamma, the mirror adds 2 * 3 gamma to
    // the spread, so w = 3 + 7 * 5 = 38 gamma against a path of 8: log2(38 / 8) = 2.25.
    let yfov = 50f32.to_radians();
    let scene = || {
        let mut scene = convex_mirror_scene(yfov);
        scene.meshes[1].primitives = vec![sphere(1, 6)];
        scene
    };
    let paper = probe(scene(), (64, 64), LodMethod::Paper, 32.0, 32.0).level;
    assert_level(
        "paper",
        paper,
        facing_closed_form(8.0, 40.0, 256, yfov, 64) + 20f64.log2(),
    );
    for lod in [LodMethod::Cones, LodMethod::Diffs] {
        let got = probe(scene(), (64, 64), lod, 32.0, 32.0).level;
        let expected = paper as f64 + (38.0f64 / 8.0).log2();
        assert_level(&format!("{lod} via the ball"), got, expected);
    }
}

/// A glass slab (faces at 2 and 2.5 m) or ball (radius 1 at 3 m) in front of a textured
/// quad 9 m away, on the optical axis.
fn glass_scene(yfov: f32, ball: bool) -> SceneDesc {
    let mut scene = facing_quad_scene(9.0, 4.0, 256, yfov);
    scene.materials.push(glass());
    if ball {
        scene.meshes.push(MeshDesc {
            name: "ball".into(),
            primitives: vec![sphere(1, 6)],
            ..Default::default()
        });
        add_root(
            &mut scene,
            node("ball", at(Vec3::new(0.0, 0.0, -3.0)), Some(1)),
        );
        return scene;
    }
    scene.meshes.push(MeshDesc {
        name: "slab face".into(),
        primitives: vec![quad(3.0, 1.0, 1)],
        ..Default::default()
    });
    add_root(
        &mut scene,
        node("front", at(Vec3::new(0.0, 0.0, -2.0)), Some(1)),
    );
    let back = Trs {
        translation: Vec3::new(0.0, 0.0, -2.5),
        rotation: Quat::from_rotation_y(std::f32::consts::PI),
        ..Default::default()
    };
    add_root(&mut scene, node("back", back, Some(1)));
    scene
}

/// Paraxial trace (height `y` of a ray leaving the eye at unit angle) through the centred
/// surfaces `(position along the axis, radius or None for flat, n before, n after)` to the
/// plane at `end`: `n' u' = n u - (n' - n) y / R`. The cone's width in pixel spreads.
fn paraxial_width(surfaces: &[(f64, Option<f64>, f64, f64)], end: f64) -> f64 {
    let (mut y, mut u, mut z) = (0.0, 1.0, 0.0);
    for &(at, radius, n, n_after) in surfaces {
        y += u * (at - z);
        z = at;
        let power = radius.map_or(0.0, |r| (n_after - n) / r);
        u = (n * u - power * y) / n_after;
    }
    (y + u * (end - z)).abs()
}

#[test]
fn glass_at_normal_incidence_matches_the_paraxial_trace() {
    let yfov = 40f32.to_radians();
    // The slab: apparent depth, 2 + 0.5 / 1.5 + 6.5 m.
    let slab = paraxial_width(&[(2.0, None, 1.0, 1.5), (2.5, None, 1.5, 1.0)], 9.0);
    assert!((slab - (8.5 + 0.5 / 1.5)).abs() < 1e-12);
    // The ball: front surface at 2 m (centre behind it), back at 4 m; focus 2 m behind it.
    let ball = paraxial_width(
        &[(2.0, Some(1.0), 1.0, 1.5), (4.0, Some(-1.0), 1.5, 1.0)],
        9.0,
    );
    assert!((ball - 3.0).abs() < 1e-12);
    for (is_ball, width) in [(false, slab), (true, ball)] {
        let expected = facing_closed_form(width, 4.0, 256, yfov, 64);
        let paper = probe(
            glass_scene(yfov, is_ball),
            (64, 64),
            LodMethod::Paper,
            32.0,
            32.0,
        );
        assert_eq!(paper.chain.bends().len(), 2, "two refractions");
        assert_level(
            "paper through glass",
            paper.level,
            facing_closed_form(9.0, 4.0, 256, yfov, 64),
        );
        for lod in [LodMethod::Cones, LodMethod::Diffs] {
            let p = probe(glass_scene(yfov, is_ball), (64, 64), lod, 32.0, 32.0);
            let what = format!(
                "{lod} through the glass {}",
                if is_ball { "ball" } else { "slab" }
            );
            assert_level(&what, p.level, expected);
        }
    }
}

/// A `width` x `height` texture of alternating texels mapped once on the facing quad.
fn non_square_scene(width: u32, height: u32, yfov: f32) -> SceneDesc {
    let mut scene = facing_quad_scene(4.0, 2.0, 8, yfov);
    let texels = (0..width * height)
        .map(|i| glam::Vec4::splat(((i + i / width) % 2) as f32))
        .collect();
    scene.textures[0].pyramid =
        mipray::texture::MipPyramid::from_linear_rgba(width, height, texels).unwrap();
    scene
}

#[test]
fn non_square_texture_levels_use_width_times_height() {
    // 1024 x 64 texels on a 2 m quad at 4 m: the triangle constant uses sqrt(W H) = 256
    // texels across (a W * W mistake is 2 levels off); diffs take the longest axis, W.
    let yfov = 60f32.to_radians();
    let k = 2.0 * (yfov as f64 / 2.0).tan() / 64.0;
    let level_for = |texels_across: f64| (k * 4.0 * texels_across / 2.0).log2();
    for (lod, expected) in [
        (LodMethod::Paper, level_for(256.0)),
        (LodMethod::PaperCos, level_for(256.0)),
        (LodMethod::Cones, level_for(256.0)),
        (LodMethod::Diffs, level_for(1024.0)),
    ] {
        let p = probe(non_square_scene(1024, 64, yfov), (64, 64), lod, 32.0, 32.0);
        assert_eq!(p.texture_size, (1024, 64));
        assert_level(&format!("{lod} on 1024 x 64"), p.level, expected);
    }
}

/// A method's errors against the sub-pixel reference (longest axis, area) over frame 0,
/// and the reference's undefined share.
fn subpixel_error(
    scene: SceneDesc,
    lod: LodMethod,
) -> (
    mipray::compare::lod_error::LodErrorStats,
    mipray::compare::lod_error::LodErrorStats,
    f64,
) {
    use mipray::compare::lod_error::method_error;
    use mipray::compare::subpixel_reference::subpixel_reference;
    let mut renderer = Renderer::new(scene, settings(64, 64, lod));
    let prepared = renderer.prepare(0, 0.0).unwrap();
    let frame_scene = renderer.frame_scene(&prepared);
    let reference = subpixel_reference(&frame_scene, &prepared.camera);
    (
        method_error(&frame_scene, &prepared.camera, &reference.longest_axis),
        method_error(&frame_scene, &prepared.camera, &reference.area),
        reference.undefined_share(),
    )
}

#[test]
fn subpixel_reference_agrees_with_the_closed_forms_under_both_conventions() {
    let yfov = 60f32.to_radians();
    // Facing: both conventions give the same level. `diffs`, `cones` and `paper-cos` (each
    // ray with its own pixel) match it everywhere; `paper` pays the off-axis term
    // `-log2 cos theta` (up to 0.085 levels at the quad's corners).
    let facing = |lod| subpixel_error(facing_quad_scene(4.0, 2.0, 256, yfov), lod);
    let mut bias = std::collections::HashMap::new();
    for lod in MIPMAPPED {
        let (longest, area, _) = facing(lod);
        assert!(longest.pixels > 100, "{lod}: {} pixels", longest.pixels);
        assert!(
            (longest.bias - area.bias).abs() < 0.01,
            "{lod}: {longest:?} {area:?}"
        );
        bias.insert(lod, longest.bias);
    }
    for lod in [LodMethod::Diffs, LodMethod::Cones, LodMethod::PaperCos] {
        assert!(bias[&lod].abs() < 0.02, "{lod} facing {bias:?}");
    }
    assert!((0.01..0.085).contains(&bias[&LodMethod::Paper]), "{bias:?}");
    // Tilted 60 degrees: the footprint is 1 x 2 on the axis; longest axis charges paper a
    // full level, area half of one (and charges the cos-aware methods the other half).
    // Means over the whole quad, where perspective varies the tilt: within 0.15.
    let (longest, area, _) = subpixel_error(tilted_quad(yfov), LodMethod::Paper);
    assert!(
        (longest.bias + 1.0).abs() < 0.15,
        "paper longest {longest:?}"
    );
    assert!((area.bias + 0.5).abs() < 0.15, "paper area {area:?}");
    assert!(
        (longest.bias - area.bias + 0.5).abs() < 0.05,
        "{longest:?} {area:?}"
    );
    let (longest, area, _) = subpixel_error(tilted_quad(yfov), LodMethod::Diffs);
    assert!(longest.bias.abs() < 0.05, "diffs longest {longest:?}");
    assert!((area.bias - 0.5).abs() < 0.05, "diffs area {area:?}");
    // A second quad of the same material right of the first: the texture restarts at
    // the shared edge (u jumps from 1 to 0, 256 texels against a 9-texel footprint), so
    // the pixels straddling it have no affine fit and count as undefined.
    let seam = || {
        let mut scene = facing_quad_scene(4.0, 2.0, 256, yfov);
        add_root(
            &mut scene,
            node("right", at(Vec3::new(2.0, 0.0, -4.0)), Some(0)),
        );
        scene
    };
    let (_, _, undefined) = subpixel_error(seam(), LodMethod::Paper);
    // 28 rows of the seam against about 28 x 36 textured pixels.
    assert!(
        undefined > 0.01 && undefined < 0.06,
        "undefined share {undefined}"
    );
    // Through the convex mirror the real rays see the ball's spread: cones and diffs
    // within a quarter level, paper about 2.25 levels too sharp on axis.
    let scene = || {
        let mut scene = convex_mirror_scene(50f32.to_radians());
        scene.meshes[1].primitives = vec![sphere(1, 6)];
        scene
    };
    let (paper, _, _) = subpixel_error(scene(), LodMethod::Paper);
    let (cones, _, _) = subpixel_error(scene(), LodMethod::Cones);
    eprintln!("convex mirror vs sub-pixel reference: paper {paper:?}, cones {cones:?}");
    assert!(paper.bias < -1.5, "paper {paper:?}");
    assert!(cones.bias.abs() < 0.25, "cones {cones:?}");
}
