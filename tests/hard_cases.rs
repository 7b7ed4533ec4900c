//! Numerically hard scenes, each rendered with every LOD method at 24x16 through the
//! frame loop: no panic, every pixel finite, no sample written black for being non-finite
//! (`nonfinite_samples == 0`), and a frame for every requested time. The documented
//! behaviour of each case is in its comment (and in CONTRIBUTING.md's testing section).

use glam::{Quat, Vec2, Vec3, Vec4};
use mipray::frame::{BvhLayout, RenderSettings, Renderer};
use mipray::lod::LodMethod;
use mipray::scene::{
    AnimationDesc, ChannelDesc, ChannelTarget, Interpolation, MeshDesc, SceneDesc, Trs,
};
use mipray::texture::{MipPyramid, Sampler, Texture, WrapMode};

mod common;

use common::scenes::{
    add_root, at, camera_node, checker, facing_quad_scene, node, quad, settings, sphere, textured,
};

/// Renders the scene `make_scene` builds at `times` with every method under both BVH
/// layouts, sequentially (so refit and the LOD update paths run), and checks every frame.
fn render_all_methods(name: &str, make_scene: impl Fn() -> SceneDesc, times: &[f32]) {
    for (method, layout) in LodMethod::ALL
        .into_iter()
        .flat_map(|m| [BvhLayout::Flat, BvhLayout::TwoLevel].map(|l| (m, l)))
    {
        let settings = RenderSettings {
            layout,
            ..settings(24, 16, method)
        };
        let mut renderer = Renderer::new(make_scene(), settings);
        for (frame, &t) in times.iter().enumerate() {
            let what = format!("{name} --lod {method} ({layout:?}) frame {frame} (t = {t})");
            let (image, record) = renderer
                .render_frame(frame as u32, t)
                .unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(image.pixels.len(), 24 * 16, "{what}");
            assert!(
                image.pixels.iter().all(|p| p.is_finite()),
                "{what}: non-finite pixel"
            );
            assert_eq!(record.nonfinite_samples, 0, "{what}: non-finite samples");
        }
    }
}

/// A `width x height` texture of distinct colours (a gradient).
fn gradient(width: u32, height: u32) -> Texture {
    let texels = (0..width * height)
        .map(|i| {
            let (x, y) = (i % width, i / width);
            Vec4::new(x as f32 / width as f32, y as f32 / height as f32, 0.5, 1.0)
        })
        .collect();
    Texture {
        name: format!("gradient{width}x{height}"),
        pyramid: MipPyramid::from_linear_rgba(width, height, texels).unwrap(),
        sampler: Sampler {
            wrap_s: WrapMode::Repeat,
            wrap_t: WrapMode::MirroredRepeat,
            ..Sampler::default()
        },
    }
}

/// Sub-micron geometry: a 1e-7 quad 2e-7 in front of the camera (inside the 0.01 near
/// distance: the near plane is ignored by the tracer, so it is seen; `log2 P_b` is ~-23).
#[test]
fn sub_micron_geometry() {
    render_all_methods(
        "sub-micron",
        || facing_quad_scene(2e-7, 1e-7, 64, 0.8),
        &[0.0],
    );
}

/// Huge coordinates: a 1e6 quad 1e6 away, and the whole scene moved 1e6 along x (f64
/// `log2 P_b` keeps the area exact; hits jitter by f32 spacing, ~0.06 at 1e6).
#[test]
fn huge_coordinates() {
    render_all_methods("huge", || facing_quad_scene(1e6, 1e6, 64, 0.8), &[0.0]);
    let moved = || {
        let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
        for n in &mut scene.nodes {
            n.local.translation += Vec3::new(1e6, 0.0, 0.0);
        }
        scene
    };
    render_all_methods("moved by 1e6", moved, &[0.0]);
}

/// Coordinates up to f32's range: the facing quad's scene scaled by 1e12, 1e20 and 1e30 (a
/// quad of 2e30 at 3e30) renders as at unit scale. Where the triangle test's edge functions
/// or distance, or the length of a triangle's normal, leave f32's range, they are decided in
/// f64, so such a quad neither vanishes nor turns black. Lit at 1e12; at 1e20 and 1e30 by
/// the ambient term alone, as a light's squared distance leaves f32's range there (the
/// light then delivers nothing, documented in the guide).
#[test]
fn a_scene_scaled_to_f32_range_renders_as_at_unit_scale() {
    for method in [LodMethod::None, LodMethod::Paper] {
        for layout in [BvhLayout::Flat, BvhLayout::TwoLevel] {
            let render = |scale: f32, lights: Option<usize>| {
                let settings = RenderSettings {
                    layout,
                    lights,
                    ..settings(24, 16, method)
                };
                let scene = facing_quad_scene(3.0 * scale, 2.0 * scale, 64, 0.8);
                let mut renderer = Renderer::new(scene, settings);
                let (image, record) = renderer.render_frame(0, 0.0).unwrap();
                assert_eq!(record.nonfinite_samples, 0, "scale {scale}");
                image.pixels
            };
            for (scale, lights) in [(1e12, None), (1e20, Some(0)), (1e30, Some(0))] {
                let (unit, scaled) = (render(1.0, lights), render(scale, lights));
                let worst = unit
                    .iter()
                    .zip(&scaled)
                    .map(|(a, b)| (*a - *b).abs().max_element())
                    .fold(0.0f32, f32::max);
                assert!(
                    worst < 0.02,
                    "--lod {method} ({layout:?}) at scale {scale}: differs by {worst}"
                );
                // The quad is seen: the picture is not the background alone.
                assert!(
                    scaled.iter().any(|p| (p.x - 0.1).abs() > 0.05),
                    "scale {scale}"
                );
            }
        }
    }
}

/// UVs near 1e5: the quad maps the texture 1e5 times (the level clamps at the coarsest),
/// and a quad whose UVs are offset by 1e5 (rebased per triangle at load time by the
/// loaders; here, built in code, sampled at 1e5 directly).
#[test]
fn uvs_near_1e5() {
    let repeated = || {
        let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
        scene.meshes[0].primitives[0] = quad(2.0, 1e5, 0);
        scene
    };
    render_all_methods("uv repeat 1e5", repeated, &[0.0]);
    let offset = || {
        let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
        for uv in scene.meshes[0].primitives[0].uvs.iter_mut().flatten() {
            *uv += Vec2::splat(1e5 + 0.3);
        }
        scene
    };
    render_all_methods("uv offset 1e5", offset, &[0.0]);
}

/// 1xN, Nx1, 1x1 and non-power-of-two textures.
#[test]
fn thin_and_non_power_of_two_textures() {
    for (w, h) in [(1, 37), (37, 1), (1, 1), (3, 5), (100, 7)] {
        let scene = || {
            let mut scene = facing_quad_scene(3.0, 2.0, 4, 0.8);
            scene.textures[0] = gradient(w, h);
            scene
        };
        render_all_methods(&format!("{w}x{h} texture"), scene, &[0.0]);
    }
}

/// Camera inside a closed textured sphere (every primary ray hits its back faces).
#[test]
fn camera_inside_geometry() {
    render_all_methods("inside a sphere", sphere_around_camera, &[0.0]);
}

fn sphere_around_camera() -> SceneDesc {
    let mut scene = SceneDesc::default();
    scene.textures.push(checker(32, 4));
    scene.materials.push(textured(0));
    let mut ball = sphere(0, 3);
    ball.uvs = Some(ball.positions.iter().map(|p| Vec2::new(p.x, p.y)).collect());
    scene.meshes.push(MeshDesc {
        name: "ball".into(),
        primitives: vec![ball],
        ..Default::default()
    });
    add_root(&mut scene, node("ball", Trs::default(), Some(0)));
    let cam = camera_node(Vec3::new(0.1, 0.0, 0.2), &mut scene, 1.2);
    scene.roots.push(cam);
    scene
}

/// Coincident triangles: the same quad twice (ties go to the lower triangle id).
#[test]
fn coincident_triangles() {
    let scene = || {
        let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
        scene.meshes[0].primitives.push(quad(2.0, 1.0, 0));
        scene
    };
    render_all_methods("coincident", scene, &[0.0]);
}

/// A node scaled to 0 and back (keys 1, 0, 1): at t = 1 its triangles have zero area
/// (`log2 P_b = -1024`, the coarsest level; they are invisible), and the frames after it
/// are finite again.
#[test]
fn zero_scale_animation_keys() {
    render_all_methods(
        "zero scale",
        || collapsing_quad([0.0; 3], Quat::IDENTITY),
        &[0.0, 0.5, 1.0, 1.5, 2.0],
    );
    // Turned, and flattened on one axis only (a stretch to 0).
    render_all_methods(
        "zero y scale",
        || collapsing_quad([1.0, 0.0, 1.0], Quat::from_rotation_y(0.5)),
        &[0.0, 1.0, 2.0],
    );
}

/// The facing quad, turned by `rotation`, with scale keys 1, `middle`, 1 at t = 0, 1, 2.
fn collapsing_quad(middle: [f32; 3], rotation: Quat) -> SceneDesc {
    let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
    let quad_node = scene.roots[0];
    scene.nodes[quad_node].local.rotation = rotation;
    let mut values = vec![1.0; 3];
    values.extend(middle);
    values.extend([1.0; 3]);
    scene.animations.push(AnimationDesc {
        name: "collapse".into(),
        channels: vec![ChannelDesc {
            node: quad_node,
            target: ChannelTarget::Scale,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0, 2.0],
            values,
            components: 3,
        }],
    });
    scene
}

/// An empty scene: no meshes, only a camera (background everywhere); and nothing at all.
#[test]
fn empty_scene() {
    let camera_only = || {
        let mut scene = SceneDesc::default();
        let cam = camera_node(Vec3::ZERO, &mut scene, 0.8);
        scene.roots.push(cam);
        scene
    };
    render_all_methods("empty", camera_only, &[0.0]);
    render_all_methods("nothing at all", SceneDesc::default, &[0.0]);
}

/// No lights in the scene: the renderer adds one (see `--lights`).
#[test]
fn no_lights() {
    let scene = || facing_quad_scene(3.0, 2.0, 64, 0.8);
    assert!(scene().lights.is_empty());
    render_all_methods("no lights", scene, &[0.0]);
}

/// No camera: the default camera frames the scene bounds. And a camera inside the quad's
/// own plane (every primary ray grazes it).
#[test]
fn no_camera_and_a_camera_in_a_surface_plane() {
    let no_camera = || {
        let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
        scene.cameras.clear();
        for n in &mut scene.nodes {
            n.camera = None;
        }
        scene
    };
    render_all_methods("no camera", no_camera, &[0.0]);
    let edge_on = || {
        let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
        let cam = scene.roots[1];
        scene.nodes[cam].local = at(Vec3::new(0.0, 0.0, -3.0));
        scene
    };
    render_all_methods("camera in the quad's plane", edge_on, &[0.0]);
}
