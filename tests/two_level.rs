//! The two-level BVH against the flat one: same images (within the stated tolerance) for
//! every LOD method on a scene with rigid, scaled, stretched, mirrored and skinned instances
//! of shared meshes, mirrors and glass; the same update counters; rigid motion that writes
//! no triangle; a frame alone equal to the same frame of a sequence.

mod common;
#[path = "../benches/common/generated.rs"]
mod generated;

use common::scenes::*;
use glam::{Quat, Vec3};
use mipray::frame::{BvhLayout, BvhPolicy, RenderSettings, Renderer};
use mipray::lod::LodMethod;
use mipray::record::UpdateStats;
use mipray::render::LinearImage;
use mipray::scene::{AnimationDesc, ChannelTarget, SceneDesc, Trs};

const FPS: f32 = 30.0;

/// Largest share of pixels allowed to differ between the layouts, and the largest mean
/// absolute difference per channel: where both find the same triangle shading is
/// bit-identical (`render::scene_bvh`); only a ray on an edge may find its neighbour (or,
/// not in this scene, one of two coincident surfaces of an instance and another tree).
const MAX_DIFFERING_SHARE: f64 = 0.005;
const MAX_MEAN_ABS: f64 = 1e-3;

/// The dynamic scene (spinning, growing and stretched instances of one card mesh over the
/// showcase's mirror, glass and textured floor), a textured skinned strip, a mirrored card
/// instance that turns, and a card sheared by turning under a stretched parent.
fn scene() -> SceneDesc {
    let (mut scene, _) = dynamic_scene();
    merge_textured(
        &mut scene,
        common::deform_scenes::skinned_strip_scene(1.3),
        0,
        Vec3::new(-1.0, 1.5, -3.0),
    );
    let card = scene
        .meshes
        .iter()
        .position(|m| m.name == "card")
        .expect("card mesh");
    let mirrored = add_root(
        &mut scene,
        node(
            "mirrored",
            Trs {
                translation: Vec3::new(2.2, 1.6, -5.0),
                scale: Vec3::new(-0.8, 0.8, 0.8),
                ..Default::default()
            },
            Some(card),
        ),
    );
    // A card turning about z under a parent stretched along x: a shear, whose `log2 P_b`
    // comes from the world-space triangle.
    scene
        .nodes
        .push(node("sheared", Trs::default(), Some(card)));
    let sheared = scene.nodes.len() - 1;
    let mut parent = node(
        "stretching parent",
        Trs {
            translation: Vec3::new(-2.4, 2.0, -5.5),
            scale: Vec3::new(1.8, 0.9, 1.0),
            ..Default::default()
        },
        None,
    );
    parent.children.push(sheared);
    add_root(&mut scene, parent);
    let turn = |axis: Vec3, a: f32| Quat::from_axis_angle(axis, a).to_array();
    scene.animations.push(AnimationDesc {
        name: "mirrored and sheared".into(),
        channels: vec![
            channel(
                mirrored,
                ChannelTarget::Rotation,
                &[0.0, 1.0],
                &[turn(Vec3::Y, 0.0), turn(Vec3::Y, 1.2)].concat(),
            ),
            channel(
                sheared,
                ChannelTarget::Rotation,
                &[0.0, 1.0],
                &[turn(Vec3::Z, 0.3), turn(Vec3::Z, 1.1)].concat(),
            ),
        ],
    });
    scene
}

fn settings(lod: LodMethod, layout: BvhLayout) -> RenderSettings {
    RenderSettings {
        width: 80,
        height: 60,
        lod,
        layout,
        bvh: BvhPolicy::Refit {
            rebuild_threshold: BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
        },
        ..Default::default()
    }
}

/// (share of differing pixels, mean absolute difference per channel, largest difference).
fn difference(a: &LinearImage, b: &LinearImage) -> (f64, f64, f32) {
    assert_eq!((a.width, a.height), (b.width, b.height));
    let (mut differing, mut sum, mut largest) = (0usize, 0f64, 0f32);
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        let d = (*p - *q).abs();
        if d != Vec3::ZERO {
            differing += 1;
        }
        sum += (d.x + d.y + d.z) as f64;
        largest = largest.max(d.max_element());
    }
    let n = a.pixels.len() as f64;
    (differing as f64 / n, sum / (3.0 * n), largest)
}

/// Fails, naming `what`, unless `b` is within the layouts' tolerance of `a`.
fn assert_close(a: &LinearImage, b: &LinearImage, what: &str) {
    let (share, mean, largest) = difference(a, b);
    assert!(
        share <= MAX_DIFFERING_SHARE && mean <= MAX_MEAN_ABS,
        "{what}: {:.3}% of pixels differ (mean {mean:.2e}, largest {largest})",
        share * 100.0
    );
}

/// Fails, naming `what` and how far off, unless the images are equal bit for bit.
fn assert_same(a: &LinearImage, b: &LinearImage, what: &str) {
    assert!(
        a.pixels == b.pixels,
        "{what}: differs {:?}",
        difference(a, b)
    );
}

/// The counters that say what changed (not what it cost).
fn counters(u: &UpdateStats) -> [usize; 4] {
    [
        u.moved_triangles,
        u.deformed_triangles,
        u.lod_recomputed,
        u.lod_shifted,
    ]
}

#[test]
fn two_level_frames_match_flat_for_every_lod_method() {
    let mut compared_pixels = 0;
    for lod in LodMethod::ALL {
        let mut flat = Renderer::new(scene(), settings(lod, BvhLayout::Flat));
        let mut two = Renderer::new(scene(), settings(lod, BvhLayout::TwoLevel));
        for frame in 0..30 {
            let time = frame as f32 / FPS;
            let (a, ra) = flat.render_frame(frame, time).unwrap();
            let (b, rb) = two.render_frame(frame, time).unwrap();
            assert_close(&a, &b, &format!("{lod} frame {frame}"));
            assert_eq!(
                counters(&ra.update),
                counters(&rb.update),
                "{lod} frame {frame}: [moved, deformed, lod_recomputed, lod_shifted]"
            );
            assert_eq!(ra.triangles, rb.triangles);
            compared_pixels += a.pixels.len();
        }
    }
    assert!(compared_pixels > 0);
}

#[test]
fn rigid_motion_under_two_level_writes_no_triangle() {
    let mut flat = Renderer::new(
        dynamic_scene().0,
        settings(LodMethod::Paper, BvhLayout::Flat),
    );
    let mut two = Renderer::new(
        dynamic_scene().0,
        settings(LodMethod::Paper, BvhLayout::TwoLevel),
    );
    let mut moved = 0;
    let mut world_at_start = None;
    for frame in 0..10 {
        let time = frame as f32 / FPS;
        let f = flat.prepare(frame, time).unwrap().update;
        let t = two.prepare(frame, time).unwrap().update;
        assert_eq!(counters(&f), counters(&t), "frame {frame}");
        // Nothing here deforms: the world tree holds the static objects drawn once (floor,
        // mirror, glass ball), the moving cards are instances of one shared mesh.
        let world = two.triangles();
        assert!(world.len() < flat.triangles().len(), "frame {frame}");
        let positions = two.world_positions();
        let start = world_at_start.get_or_insert_with(|| positions.clone());
        if frame > 0 {
            moved += t.moved_triangles;
            assert!(
                two.dirty().is_empty(),
                "frame {frame}: a triangle was marked"
            );
            assert!(
                *start == positions,
                "frame {frame}: a world triangle was rewritten"
            );
            assert!(!t.rebuild, "frame {frame}: nothing in the world tree moved");
        }
    }
    assert!(moved > 0, "the scene's instances were meant to move");
}

/// The frame-loop bench's rigid crowd, small: instances of one patch turning and sliding.
/// Under two-level nothing has world-space triangles, and after the first frame no
/// `log2 P_b` is recomputed or shifted.
#[test]
fn a_rigid_crowd_recomputes_nothing_after_the_first_frame() {
    let crowd = || {
        let mut scene = generated::textured_scene();
        generated::add_rigid_patches(&mut scene, 20, 10, 1.3, Vec3::ZERO);
        generated::add_camera(&mut scene, Vec3::new(0.0, 0.0, 9.0), 1.0);
        scene
    };
    let mut two = Renderer::new(crowd(), settings(LodMethod::Paper, BvhLayout::TwoLevel));
    let mut flat = Renderer::new(crowd(), settings(LodMethod::Paper, BvhLayout::Flat));
    for frame in 0..8 {
        let time = frame as f32 / FPS;
        let t = two.prepare(frame, time).unwrap().update;
        let f = flat.prepare(frame, time).unwrap().update;
        assert_eq!(counters(&f), counters(&t), "frame {frame}");
        assert_eq!(two.triangles().len(), 0, "frame {frame}: only instances");
        if frame > 0 {
            assert_eq!(
                t.moved_triangles,
                20 * 200,
                "frame {frame}: every patch moves"
            );
            assert_eq!((t.lod_recomputed, t.lod_shifted), (0, 0), "frame {frame}");
        }
    }
}

/// A textured quad whose scale animates to 0 along its own normal (z) while turned: under
/// two-level its transform has no inverse, yet it is still a visible quad, as under flat.
#[test]
fn a_quad_flattened_along_its_normal_stays_visible() {
    let scene = || {
        let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
        let quad_node = scene.roots[0];
        scene.nodes[quad_node].local.rotation = Quat::from_rotation_y(0.5);
        scene.animations.push(AnimationDesc {
            name: "flatten".into(),
            channels: vec![channel(
                quad_node,
                ChannelTarget::Scale,
                &[0.0, 1.0],
                &[1.0, 1.0, 1.0, 1.0, 1.0, 0.0],
            )],
        });
        scene
    };
    for lod in LodMethod::ALL {
        let mut flat = Renderer::new(scene(), settings(lod, BvhLayout::Flat));
        let mut two = Renderer::new(scene(), settings(lod, BvhLayout::TwoLevel));
        for (frame, time) in [(0, 0.0), (1, 0.5), (2, 1.0)] {
            let (a, _) = flat.render_frame(frame, time).unwrap();
            let (b, _) = two.render_frame(frame, time).unwrap();
            let background = Vec3::splat(0.1);
            let covered = b.pixels.iter().filter(|p| **p != background).count();
            assert!(
                covered > b.pixels.len() / 10,
                "{lod} t = {time}: the quad vanished"
            );
            assert_close(&a, &b, &format!("{lod} t = {time}"));
        }
    }
}

/// A frame whose update fails (an instance placed at infinity) leaves no stale state: the
/// next frame, back in range, equals that frame rendered by a fresh renderer.
#[test]
fn a_failed_frame_leaves_no_stale_placements() {
    let scene = || {
        let mut scene = facing_quad_scene(3.0, 2.0, 64, 0.8);
        let quad_node = scene.roots[0];
        let z = -3.0;
        scene.animations.push(AnimationDesc {
            name: "away and back".into(),
            channels: vec![mipray::scene::ChannelDesc {
                node: quad_node,
                target: ChannelTarget::Translation,
                interpolation: mipray::scene::Interpolation::Step,
                times: vec![0.0, 1.0, 2.0, 3.0],
                values: vec![
                    0.0,
                    0.0,
                    z,
                    f32::INFINITY,
                    0.0,
                    z,
                    f32::INFINITY,
                    0.0,
                    z,
                    0.3,
                    0.0,
                    z,
                ],
                components: 3,
            }],
        });
        scene
    };
    for layout in [BvhLayout::Flat, BvhLayout::TwoLevel] {
        let mut r = Renderer::new(scene(), settings(LodMethod::Paper, layout));
        r.render_frame(0, 0.0).unwrap();
        assert!(
            r.render_frame(1, 1.0).is_err(),
            "{layout:?}: the overflow is an error"
        );
        assert!(
            r.render_frame(2, 2.0).is_err(),
            "{layout:?}: still an error at frame 2"
        );
        let (after, _) = r.render_frame(3, 3.0).unwrap();
        let (fresh, _) = Renderer::new(scene(), settings(LodMethod::Paper, layout))
            .render_frame(3, 3.0)
            .unwrap();
        assert_same(
            &after,
            &fresh,
            &format!("{layout:?}: frame 3 after the failed frames, against a fresh one"),
        );
    }
}

/// A static forest: 80 copies of a 2,048-triangle patch that never move (too many to merge
/// into the world tree, so they stay instances under their own top-level tree, built once)
/// and one moving copy. Same images and counters as flat, and nothing world-space.
#[test]
fn static_copies_stay_instances_beside_moving_ones() {
    let forest = || {
        let mut scene = generated::textured_scene();
        scene.meshes.push(mipray::scene::MeshDesc {
            name: "patch".into(),
            primitives: vec![generated::patch(32, 32, 1.0, 1.0)],
            ..Default::default()
        });
        let mesh = scene.meshes.len() - 1;
        for k in 0..80 {
            let at = Vec3::new(
                (k % 10) as f32 * 1.1 - 5.0,
                (k / 10) as f32 * 1.1 - 4.0,
                -1.0,
            );
            add_root(
                &mut scene,
                node(
                    "tree",
                    Trs {
                        translation: at,
                        ..Default::default()
                    },
                    Some(mesh),
                ),
            );
        }
        generated::add_rigid_patches(&mut scene, 1, 8, 1.0, Vec3::new(0.0, 0.0, 0.5));
        generated::add_camera(&mut scene, Vec3::new(0.0, 0.0, 9.0), 1.0);
        scene
    };
    let mut flat = Renderer::new(forest(), settings(LodMethod::Paper, BvhLayout::Flat));
    let mut two = Renderer::new(forest(), settings(LodMethod::Paper, BvhLayout::TwoLevel));
    for frame in 0..6 {
        let time = frame as f32 / FPS;
        let (a, ra) = flat.render_frame(frame, time).unwrap();
        let (b, rb) = two.render_frame(frame, time).unwrap();
        assert_close(&a, &b, &format!("frame {frame}"));
        assert_eq!(counters(&ra.update), counters(&rb.update), "frame {frame}");
        assert_eq!(
            two.triangles().len(),
            0,
            "frame {frame}: every copy is an instance"
        );
        if frame > 0 {
            assert_eq!(
                rb.update.moved_triangles, 128,
                "frame {frame}: only the small patch moves"
            );
        }
    }
}

#[test]
fn a_two_level_frame_alone_equals_the_same_frame_of_a_sequence() {
    let mut sequence = Renderer::new(scene(), settings(LodMethod::Cones, BvhLayout::TwoLevel));
    for frame in 0..20 {
        let time = frame as f32 / FPS;
        let (a, _) = sequence.render_frame(frame, time).unwrap();
        if frame % 6 == 5 {
            let mut alone = Renderer::new(scene(), settings(LodMethod::Cones, BvhLayout::TwoLevel));
            let (b, _) = alone.render_frame(frame, time).unwrap();
            assert_same(
                &a,
                &b,
                &format!("frame {frame} alone, against the sequence"),
            );
        }
    }
}

#[test]
fn bvh_two_level_renders_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("two");
    let run = common::mipray(
        &[
            "render",
            "default",
            "--frames",
            "0..3",
            "--size",
            "48x27",
            "--bvh",
            "two-level",
            "--out",
            out.to_str().unwrap(),
        ],
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")),
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for frame in 0..3 {
        assert!(
            out.join(format!("frame_{frame:04}.png")).is_file(),
            "frame {frame}"
        );
    }
}
