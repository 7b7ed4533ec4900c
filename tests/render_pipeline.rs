//! End-to-end checks of the frame loop on scenes built in code.

mod common;

use common::scenes::*;
use glam::{Vec3, Vec3A};
use mipray::frame::Renderer;
use mipray::lod::LodMethod;
use mipray::scene::{MeshDesc, SceneDesc};

/// Level the renderer selects at the image centre of frame 0.
fn centre_level(scene: SceneDesc, height: u32) -> f32 {
    centre_level_with(scene, height, LodMethod::Paper)
}

fn centre_level_with(scene: SceneDesc, height: u32, method: LodMethod) -> f32 {
    let mut renderer = Renderer::new(scene, settings(height, height, method));
    let prepared = renderer.prepare(0, 0.0).unwrap();
    let camera = prepared.camera;
    renderer
        .frame_scene(&prepared)
        .probe_method(&camera, height as f32 / 2.0, height as f32 / 2.0)
        .expect("centre ray hits the quad")
        .level
}

#[test]
fn facing_quad_level_matches_closed_form() {
    let yfov = 60f32.to_radians();
    let (height, size, tex) = (64u32, 2.0f32, 256u32);
    let level = centre_level(facing_quad_scene(4.0, size, tex, yfov), height);
    // P_b = texel width / pixel width at unit distance.
    let k = 2.0 * (yfov as f64 / 2.0).tan() / height as f64;
    let p_b = (size as f64 / tex as f64) / k;
    let expected = (4.0f64).log2() - p_b.log2();
    assert!(
        (level as f64 - expected).abs() < 1e-4,
        "level {level}, closed form {expected}"
    );

    let doubled_distance = centre_level(facing_quad_scene(8.0, size, tex, yfov), height);
    assert!(
        (doubled_distance - level - 1.0).abs() < 1e-4,
        "doubling d: {level} -> {doubled_distance}"
    );
    let doubled_texture = centre_level(facing_quad_scene(4.0, size, 2 * tex, yfov), height);
    assert!(
        (doubled_texture - level - 1.0).abs() < 1e-4,
        "doubling texture: {level} -> {doubled_texture}"
    );
}

#[test]
fn mirror_uses_total_path_length() {
    // Camera at the origin looks down -Z at a mirror 3 m away; the textured quad hangs 2 m
    // behind the camera facing -Z, so the reflected path is 3 + 5 = 8 m.
    let yfov = 50f32.to_radians();
    let mut scene = facing_quad_scene(0.0, 2.0, 256, yfov);
    scene.nodes[0].local.translation = Vec3::new(0.0, 0.0, 2.0);
    scene.nodes[0].local.rotation = glam::Quat::from_rotation_y(std::f32::consts::PI);
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
    let mut renderer = Renderer::new(scene, settings(64, 64, LodMethod::Paper));
    let prepared = renderer.prepare(0, 0.0).unwrap();
    let probe = renderer
        .frame_scene(&prepared)
        .probe_method(&prepared.camera, 32.0, 32.0)
        .unwrap();
    assert!(
        (probe.path_length - 8.0).abs() < 1e-3,
        "path length {}",
        probe.path_length
    );
    let k = 2.0 * (yfov as f64 / 2.0).tan() / 64.0;
    let expected = 8f64.log2() - ((2.0 / 256.0) / k).log2();
    assert!(
        (probe.level as f64 - expected).abs() < 1e-3,
        "level {} vs {expected}",
        probe.level
    );
}

fn render_bytes(scene: SceneDesc, threads: usize, lod: LodMethod) -> Vec<u8> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut s = settings(72, 40, lod);
    s.spp = 4;
    let mut renderer = Renderer::new(scene, s);
    pool.install(|| renderer.render_frame(0, 0.25).unwrap().0.to_srgb8())
}

#[test]
fn image_is_identical_whatever_the_thread_count() {
    for lod in [LodMethod::None, LodMethod::Paper] {
        let one = render_bytes(showcase_scene(), 1, lod);
        let two = render_bytes(showcase_scene(), 2, lod);
        assert_eq!(one.len(), 72 * 40 * 3);
        assert!(one == two, "{lod}: 1-thread and 2-thread renders differ");
        // The scene is not blank: the floor's checker shows both colours.
        let distinct: std::collections::BTreeSet<&[u8]> = one.chunks(3).collect();
        assert!(
            distinct.len() > 20,
            "only {} distinct colours",
            distinct.len()
        );
    }
}

#[test]
fn frame_alone_equals_frame_in_sequence() {
    let mut sequential = Renderer::new(showcase_scene(), settings(48, 32, LodMethod::Paper));
    let mut in_sequence = Vec::new();
    for frame in 0..4 {
        in_sequence.push(
            sequential
                .render_frame(frame, frame as f32 / 4.0)
                .unwrap()
                .0,
        );
    }
    let mut alone = Renderer::new(showcase_scene(), settings(48, 32, LodMethod::Paper));
    let (image, record) = alone.render_frame(2, 0.5).unwrap();
    assert_eq!(image, in_sequence[2]);
    assert_ne!(
        in_sequence[0], in_sequence[3],
        "the animation moves something"
    );
    assert_eq!(record.frame, 2);
}

#[test]
fn degenerate_and_grazing_geometry_give_finite_pixels() {
    let mut scene = showcase_scene();
    add_degenerate_mesh(&mut scene, 0);
    let mut renderer = Renderer::new(scene, settings(64, 40, LodMethod::Paper));
    let (image, record) = renderer.render_frame(0, 0.0).unwrap();
    assert!(image.pixels.iter().all(|p| p.is_finite()));
    assert_eq!(record.nonfinite_samples, 0);
    // The receding floor reaches coarse levels near the horizon.
    let coarse: u64 = record.mip_histogram[3..].iter().sum();
    assert!(coarse > 0, "histogram {:?}", record.mip_histogram);
    // The grazing primary rays (camera at floor height) never produce NaN either.
    let prepared = renderer.prepare(0, 0.0).unwrap();
    let frame_scene = renderer.frame_scene(&prepared);
    let grazing = frame_scene.probe_ray(
        Vec3A::new(0.0, 1e-4, 0.0),
        Vec3A::new(0.0, -1e-6, -1.0).normalize(),
        mipray::lod::PathLength(0.0),
    );
    if let Some(probe) = grazing {
        assert!(!probe.level.is_nan());
    }
}

/// An NFF material (AFF convention) as clear glass: no diffuse, no ambient, T = 1, ior 1.
fn nff_clear_glass() -> mipray::scene::MaterialDesc {
    mipray::scene::MaterialDesc {
        name: "nff glass".into(),
        base_color: Vec3::ZERO,
        transmission: 1.0,
        ior: 1.0,
        specular: 0.0,
        ambient: Some(Vec3::ZERO),
        shading: mipray::scene::Shading::Nff,
        ..Default::default()
    }
}

#[test]
fn nff_glass_passes_light_untinted_where_physical_glass_would_tint_it() {
    // A textured quad 4 m away, lit by the ring light; the pane hangs 1 m from the camera
    // (no mirror or glass behind it, so the extra bounce never meets the depth limit).
    let base = || {
        let mut scene = facing_quad_scene(4.0, 2.0, 64, 0.9);
        // Its own light: added ring lights would follow the bounds, which the pane changes.
        scene.lights.push(mipray::scene::LightDesc {
            kind: mipray::scene::LightKind::Point,
            color: Vec3::ONE,
            intensity: 20.0,
            range: None,
            inverse_square: true,
        });
        add_root(
            &mut scene,
            mipray::scene::NodeDesc {
                light: Some(0),
                local: at(Vec3::new(0.5, 0.5, 0.5)),
                ..Default::default()
            },
        );
        scene
    };
    let plain = render_bytes(base(), 2, LodMethod::Paper);
    let with_pane = |material: mipray::scene::MaterialDesc| {
        let mut scene = base();
        scene.materials.push(material);
        let m = scene.materials.len() - 1;
        scene.meshes.push(MeshDesc {
            name: "pane".into(),
            primitives: vec![quad(8.0, 1.0, m)],
            ..Default::default()
        });
        let n = scene.meshes.len() - 1;
        add_root(
            &mut scene,
            node("pane", at(Vec3::new(0.0, 0.0, -1.0)), Some(n)),
        );
        render_bytes(scene, 2, LodMethod::Paper)
    };
    let nff = with_pane(nff_clear_glass());
    let max_diff = plain
        .iter()
        .zip(&nff)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(
        max_diff <= 1,
        "NFF clear glass changed the image by up to {max_diff}"
    );
    // The same parameters under the physical convention tint by the (black) base colour.
    let physical = with_pane(mipray::scene::MaterialDesc {
        shading: mipray::scene::Shading::Physical,
        ..nff_clear_glass()
    });
    let dark = physical.iter().map(|&c| c as u64).sum::<u64>() * 2
        < plain.iter().map(|&c| c as u64).sum::<u64>();
    assert!(
        dark,
        "physical glass with a black base colour should darken the view"
    );
}

#[test]
fn paper_cos_adds_one_level_on_a_plane_tilted_60_degrees() {
    let yfov = 60f32.to_radians();
    let tilted = || {
        let mut scene = facing_quad_scene(4.0, 2.0, 256, yfov);
        scene.nodes[0].local.rotation = glam::Quat::from_rotation_x(60f32.to_radians());
        scene
    };
    let paper = centre_level_with(tilted(), 64, LodMethod::Paper);
    let paper_cos = centre_level_with(tilted(), 64, LodMethod::PaperCos);
    assert!(
        (paper_cos - paper - 1.0).abs() < 0.1,
        "paper {paper}, paper-cos {paper_cos}"
    );
    // Facing the camera, the two agree.
    let facing = facing_quad_scene(4.0, 2.0, 256, yfov);
    let a = centre_level_with(facing, 64, LodMethod::PaperCos);
    let b = centre_level(facing_quad_scene(4.0, 2.0, 256, yfov), 64);
    assert!((a - b).abs() < 1e-4, "{a} vs {b}");
}
