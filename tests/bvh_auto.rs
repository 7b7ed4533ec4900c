//! `--bvh auto` (the default) against `--bvh flat`: where it instances nothing the frames
//! are the flat ones byte for byte; where it instances some meshes and merges the rest
//! (moving, skinned and static) into the world tree, within the two-level tolerance, with
//! the same update counters; a frame alone equals the same frame of a sequence; the record
//! says which layout each frame used.

mod common;
#[path = "../benches/common/generated.rs"]
mod generated;

use common::scenes::*;
use glam::Vec3;
use mipray::frame::{BvhLayout, BvhPolicy, RenderSettings, Renderer, UsedLayout};
use mipray::lod::LodMethod;
use mipray::record::UpdateStats;
use mipray::render::LinearImage;
use mipray::scene::SceneDesc;

const FPS: f32 = 30.0;

/// As `tests/two_level.rs`: where both layouts find the same triangle shading is
/// bit-identical; only a ray on an edge may find its neighbour (an instance's transform
/// rounds its vertices differently).
const MAX_DIFFERING_SHARE: f64 = 0.005;
const MAX_MEAN_ABS: f64 = 1e-3;

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

/// Spinning, growing and stretched small cards over a mirror, glass and a textured floor,
/// and a textured skinned strip: nothing large enough or repeated enough to instance.
fn small_parts_scene() -> SceneDesc {
    let (mut scene, _) = dynamic_scene();
    merge_textured(
        &mut scene,
        common::deform_scenes::skinned_strip_scene(1.3),
        0,
        Vec3::new(-1.0, 1.5, -3.0),
    );
    scene
}

/// The small-parts scene with a crowd of 20 turning and sliding 7,200-triangle patches
/// behind it: merged, the crowd would store 136,800 extra triangles, so it is instanced
/// while the cards, the strip and the static objects stay in the world tree.
fn mixed_scene() -> SceneDesc {
    let mut scene = small_parts_scene();
    let crowd = {
        let mut crowd = generated::textured_scene();
        generated::add_rigid_patches(&mut crowd, 20, 60, 1.3, Vec3::ZERO);
        crowd
    };
    merge_textured(&mut scene, crowd, 0, Vec3::new(0.0, 1.0, -9.0));
    scene
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

#[test]
fn auto_is_the_default_layout() {
    assert_eq!(RenderSettings::default().layout, BvhLayout::Auto);
}

#[test]
fn where_auto_instances_nothing_frames_are_flat_byte_for_byte() {
    for lod in LodMethod::ALL {
        let mut flat = Renderer::new(small_parts_scene(), settings(lod, BvhLayout::Flat));
        let mut auto = Renderer::new(small_parts_scene(), settings(lod, BvhLayout::Auto));
        assert_eq!(
            auto.layout().used(),
            UsedLayout::Flat,
            "{}",
            auto.layout().describe(99)
        );
        for frame in 0..20 {
            let time = frame as f32 / FPS;
            let (a, ra) = flat.render_frame(frame, time).unwrap();
            let (b, rb) = auto.render_frame(frame, time).unwrap();
            assert!(
                a.pixels == b.pixels,
                "{lod} frame {frame}: {:?}",
                difference(&a, &b)
            );
            assert_eq!(counters(&ra.update), counters(&rb.update), "{lod} {frame}");
            assert_eq!((rb.bvh_layout.as_str(), rb.instanced_meshes), ("flat", 0));
        }
    }
}

#[test]
fn a_mixed_layout_matches_flat_within_the_tolerance_with_the_same_counters() {
    let plan = Renderer::new(mixed_scene(), settings(LodMethod::Paper, BvhLayout::Auto))
        .layout()
        .clone();
    assert_eq!(plan.used(), UsedLayout::TwoLevel, "{}", plan.describe(99));
    // Only the crowd's patch is instanced: the cards and the strip move in the world tree.
    assert_eq!(plan.instanced_meshes(), 1, "{}", plan.describe(99));
    let instanced = plan.instanced.iter().filter(|&&i| i).count();
    assert_eq!(instanced, 20, "{}", plan.describe(99));
    let mut compared = 0;
    for lod in LodMethod::ALL {
        let mut flat = Renderer::new(mixed_scene(), settings(lod, BvhLayout::Flat));
        let mut auto = Renderer::new(mixed_scene(), settings(lod, BvhLayout::Auto));
        let mut merged_moved = 0;
        for frame in 0..12 {
            let time = frame as f32 / FPS;
            let (a, ra) = flat.render_frame(frame, time).unwrap();
            let (b, rb) = auto.render_frame(frame, time).unwrap();
            let (share, mean, largest) = difference(&a, &b);
            assert!(
                share <= MAX_DIFFERING_SHARE && mean <= MAX_MEAN_ABS,
                "{lod} frame {frame}: {:.3}% of pixels differ (mean {mean:.2e}, largest {largest})",
                share * 100.0
            );
            assert_eq!(
                counters(&ra.update),
                counters(&rb.update),
                "{lod} frame {frame}: [moved, deformed, lod_recomputed, lod_shifted]"
            );
            assert_eq!(
                (rb.bvh_layout.as_str(), rb.instanced_meshes),
                ("two-level", 1)
            );
            assert_eq!(ra.bvh_layout, "flat");
            if frame > 0 {
                merged_moved += auto.dirty().len();
            }
            compared += a.pixels.len();
        }
        assert!(merged_moved > 0, "{lod}: merged parts were meant to move");
    }
    assert!(compared > 0);
}

#[test]
fn an_auto_frame_alone_equals_the_same_frame_of_a_sequence() {
    let mut sequence = Renderer::new(mixed_scene(), settings(LodMethod::Cones, BvhLayout::Auto));
    for frame in 0..14 {
        let time = frame as f32 / FPS;
        let (a, ra) = sequence.render_frame(frame, time).unwrap();
        if frame % 6 == 5 {
            let mut alone =
                Renderer::new(mixed_scene(), settings(LodMethod::Cones, BvhLayout::Auto));
            let (b, rb) = alone.render_frame(frame, time).unwrap();
            assert!(
                a.pixels == b.pixels,
                "frame {frame} alone: {:?}",
                difference(&a, &b)
            );
            assert_eq!(ra.bvh_layout, rb.bvh_layout);
        }
    }
}

#[test]
fn the_plan_does_not_depend_on_the_frame_rendered_first() {
    let mut late = Renderer::new(mixed_scene(), settings(LodMethod::Paper, BvhLayout::Auto));
    let early = Renderer::new(mixed_scene(), settings(LodMethod::Paper, BvhLayout::Auto));
    late.prepare(9, 9.0 / FPS).unwrap();
    assert_eq!(late.layout(), early.layout());
}

#[test]
fn info_prints_the_layout_decision() {
    let run = common::mipray(
        &["info", "default"],
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")),
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let out = String::from_utf8_lossy(&run.stdout);
    assert!(out.contains("bvh auto: "), "{out}");
    assert!(out.contains("merged") || out.contains("instanced"), "{out}");
}

#[test]
fn the_record_names_the_layout_of_each_explicit_choice() {
    for (layout, name) in [
        (BvhLayout::Flat, "flat"),
        (BvhLayout::TwoLevel, "two-level"),
    ] {
        let mut r = Renderer::new(mixed_scene(), settings(LodMethod::Paper, layout));
        let (_, record) = r.render_frame(0, 0.0).unwrap();
        assert_eq!(record.bvh_layout, name);
        assert_eq!(record.instanced_meshes > 0, layout == BvhLayout::TwoLevel);
    }
}
