//! The film's tiles, traced breadth first with packets (primary rays from the camera, shadow
//! rays toward each light), give exactly the image of tracing each sample depth first one
//! ray at a time (`FrameScene::primary_radiance`), at sample counts whose packets split
//! pixels and tiles unevenly, and trace the same number of rays.

mod common;

use std::path::Path;

use glam::{Vec3, Vec3A};
use mipray::accel::BvhLayout;
use mipray::frame::Renderer;
use mipray::lod::{LodMethod, PathLength, RayCone, RayDiffsAniso, RayLod};
use mipray::render::film::sample_offset;
use mipray::render::{TraceCounters, render_image};

/// Renders `frame` of an animation with the film and again ray by ray; every pixel must match.
/// `L` is the per-ray state type of `lod`.
fn packets_equal_single_rays<L: RayLod>(animation: &str, frame: u32, spp: u32, lod: LodMethod) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("animations/{animation}.gltf"));
    // Not a multiple of the tile.
    packets_equal_single_rays_at::<L>(&path, (83, 37), frame, spp, lod, BvhLayout::Auto);
}

/// [`packets_equal_single_rays`] for the scene at `path` rendered at `size`.
fn packets_equal_single_rays_at<L: RayLod>(
    path: &Path,
    size: (u32, u32),
    frame: u32,
    spp: u32,
    lod: LodMethod,
    layout: BvhLayout,
) {
    let animation = path.display();
    let scene = mipray::scene::load(path).unwrap();
    let mut settings = common::scenes::settings(size.0, size.1, lod);
    settings.spp = spp;
    settings.layout = layout;
    let mut renderer = Renderer::new(scene, settings);
    let prepared = renderer.prepare(frame, frame as f32 / 30.0).unwrap();
    let scene = renderer.frame_scene(&prepared);
    let camera = &prepared.camera;
    let (image, film_counters) = render_image(&scene, camera, spp);
    let mut counters = TraceCounters::default();
    let mut differing = 0;
    let mut first = None;
    for y in 0..camera.height {
        for x in 0..camera.width {
            let mut sum = Vec3A::ZERO;
            for i in 0..spp {
                let (sx, sy) = sample_offset(x, y, i, spp);
                let radiance = scene.primary_radiance::<L>(
                    camera,
                    x as f32 + sx,
                    y as f32 + sy,
                    &mut counters,
                );
                if radiance.is_finite() {
                    sum += radiance.max(Vec3A::ZERO);
                }
            }
            let alone = Vec3::from(sum / spp as f32);
            let film = image.pixels[(y * camera.width + x) as usize];
            if alone.to_array().map(f32::to_bits) != film.to_array().map(f32::to_bits) {
                differing += 1;
                first.get_or_insert((x, y, alone, film));
            }
        }
    }
    assert_eq!(
        differing, 0,
        "{animation} frame {frame} spp {spp} {lod}: {differing} pixels differ, first {first:?}"
    );
    assert_eq!(
        counters.rays, film_counters.rays,
        "the same rays were traced"
    );
}

#[test]
fn packets_equal_single_rays_on_every_animation() {
    for animation in ["default", "kitchen", "robots", "museum"] {
        packets_equal_single_rays::<PathLength>(animation, 7, 1, LodMethod::Paper);
    }
}

#[test]
fn packets_equal_single_rays_when_samples_split_packets() {
    packets_equal_single_rays::<RayCone>("default", 3, 3, LodMethod::Cones);
    packets_equal_single_rays::<RayDiffsAniso>("robots", 3, 5, LodMethod::DiffsAniso);
}

/// BART Kitchen, whose mirrors and glass send a tile's reflected rays off planes (packets
/// walked with bounds from the camera's mirror image) and whose shadow rays converge on its
/// light (bounds over their segments): at a size where a tile's rays are coherent enough
/// for both.
#[test]
fn packets_equal_single_rays_on_bart_kitchen() {
    let Some(kitchen) = common::shared_data::shared_path("bart/kitchen/aff/kitchen.aff") else {
        return;
    };
    packets_equal_single_rays_at::<PathLength>(
        &kitchen,
        (400, 300),
        400,
        1,
        LodMethod::Paper,
        BvhLayout::Flat,
    );
}

/// Under the two-level structure shadow and bounce packets walk the world tree, the
/// top-level trees and the instances together: every animation with each mesh instanced,
/// and BART Robots (whose default layout instances its larger parts) at a size where a
/// tile's shadow rays converge on a light.
#[test]
fn two_level_packets_equal_single_rays() {
    for animation in ["default", "kitchen", "robots", "museum"] {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("animations/{animation}.gltf"));
        let two_level = BvhLayout::TwoLevel;
        packets_equal_single_rays_at::<PathLength>(
            &path,
            (83, 37),
            7,
            1,
            LodMethod::Paper,
            two_level,
        );
    }
    let Some(robots) = common::shared_data::shared_path("bart/robots/aff/Robot.aff") else {
        return;
    };
    packets_equal_single_rays_at::<PathLength>(
        &robots,
        (200, 150),
        100,
        1,
        LodMethod::Paper,
        BvhLayout::Auto,
    );
}
