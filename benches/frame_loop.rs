//! Frame-loop update costs on generated scenes: `cargo bench --bench frame_loop`.
//!
//! Scenes of 100k and 1M textured triangles (a grid of patch instances, 1,000 triangles per
//! patch) where 1%, 10% or 100% of the patches deform every frame (an animated non-uniform
//! scale: shape changes, so `log2 P_b` must be recomputed, as for skinning or morphing), the
//! rest static. For each scene the per-frame update is timed over several frames with the
//! default refit policy and with a rebuild every frame, and one frame is rendered at 640x480
//! to give the preprocessing share. Scene generation happens outside the timed region.
//! Prints a Markdown table of medians (see BENCHMARKS.md).

use std::time::Instant;

use glam::{Vec2, Vec3, Vec4};
use mipray::frame::{BvhPolicy, RenderSettings, Renderer, UpdateStats};
use mipray::report::Percentiles;
use mipray::scene::*;
use mipray::texture::{MipPyramid, Sampler, Texture};

const PATCH_SIDE: u32 = 22; // 22 x 22 quads: 968 triangles per patch
const FRAMES: u32 = 6;

/// A flat patch of `n x n` quads (2 n^2 triangles) in the XY plane, unit size.
fn patch(n: u32) -> PrimitiveDesc {
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    for y in 0..=n {
        for x in 0..=n {
            let (u, v) = (x as f32 / n as f32, y as f32 / n as f32);
            positions.push(Vec3::new(u - 0.5, v - 0.5, 0.0));
            uvs.push(Vec2::new(u * 4.0, v * 4.0));
        }
    }
    let mut indices = Vec::new();
    for y in 0..n {
        for x in 0..n {
            let i = y * (n + 1) + x;
            indices.extend([i, i + 1, i + n + 2, i, i + n + 2, i + n + 1]);
        }
    }
    PrimitiveDesc {
        normals: Some(vec![Vec3::Z; positions.len()]),
        positions,
        uvs: Some(uvs),
        indices,
        material: Some(0),
        ..Default::default()
    }
}

/// `triangles` textured triangles in patches on a grid facing a camera; the first
/// `deformed_share` of the patches stretch over time.
fn scene(triangles: usize, deformed_share: f64) -> SceneDesc {
    let patch = patch(PATCH_SIDE);
    let per_patch = patch.triangle_count();
    let patches = triangles.div_ceil(per_patch);
    let side = (patches as f64).sqrt().ceil() as usize;
    let texels = (0..64 * 64)
        .map(|i| {
            if (i % 64 / 8 + i / 64 / 8) % 2 == 0 {
                Vec4::ONE
            } else {
                Vec4::new(0.1, 0.2, 0.6, 1.0)
            }
        })
        .collect();
    let mut scene = SceneDesc {
        textures: vec![Texture {
            name: "checker".into(),
            pyramid: MipPyramid::from_linear_rgba(64, 64, texels).unwrap(),
            sampler: Sampler::default(),
        }],
        materials: vec![MaterialDesc {
            base_color: Vec3::ONE,
            base_color_texture: Some(0),
            ..Default::default()
        }],
        meshes: vec![MeshDesc {
            name: "patch".into(),
            primitives: vec![patch],
            ..Default::default()
        }],
        background: Vec3::splat(0.2),
        ..Default::default()
    };
    let deformed = (patches as f64 * deformed_share).round() as usize;
    let mut channels = Vec::new();
    for p in 0..patches {
        let (x, y) = ((p % side) as f32, (p / side) as f32);
        let translation = Vec3::new(
            x * 1.1 - side as f32 * 0.55,
            y * 1.1 - side as f32 * 0.55,
            0.0,
        );
        scene.nodes.push(NodeDesc {
            local: Trs {
                translation,
                ..Default::default()
            },
            mesh: Some(0),
            ..Default::default()
        });
        scene.roots.push(p);
        if p < deformed {
            channels.push(ChannelDesc {
                node: p,
                target: ChannelTarget::Scale,
                interpolation: Interpolation::Linear,
                times: vec![0.0, 1.0],
                values: vec![1.0, 1.0, 1.0, 1.5, 0.8, 1.0],
                components: 3,
            });
        }
    }
    scene.animations.push(AnimationDesc {
        name: "stretch".into(),
        channels,
    });
    let distance = side as f32 * 1.1;
    scene.cameras.push(CameraDesc {
        yfov: 1.0,
        znear: 0.1,
    });
    scene.nodes.push(NodeDesc {
        local: Trs {
            translation: Vec3::new(0.0, 0.0, distance),
            ..Default::default()
        },
        camera: Some(0),
        ..Default::default()
    });
    scene.roots.push(scene.nodes.len() - 1);
    scene
}

/// Median per-frame update stats over frames 1..=FRAMES (frame 0 is the initial build).
fn update_medians(scene: SceneDesc, bvh: BvhPolicy) -> (UpdateStats, [f64; 5], f64) {
    let settings = RenderSettings {
        width: 640,
        height: 480,
        bvh,
        ..Default::default()
    };
    let mut renderer = Renderer::new(scene, settings);
    let t = Instant::now();
    renderer.prepare(0, 0.0).unwrap();
    let first_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut rows = Vec::new();
    for frame in 1..=FRAMES {
        rows.push(renderer.prepare(frame, frame as f32 / 30.0).unwrap().update);
    }
    let median = |f: fn(&UpdateStats) -> f64| Percentiles::of(rows.iter().map(f)).median;
    let medians = [
        median(|u| u.animate_ms + u.dirty_ms),
        median(|u| u.refit_ms),
        median(|u| u.build_ms),
        median(|u| u.lod_update_ms),
        median(UpdateStats::preprocessing_ms),
    ];
    (rows[rows.len() - 1], medians, first_ms)
}

/// Preprocessing share of one rendered frame (frame 1, after the initial build) at 640x480.
fn preprocessing_share(scene: SceneDesc) -> (f64, f64) {
    let settings = RenderSettings {
        width: 640,
        height: 480,
        ..Default::default()
    };
    let mut renderer = Renderer::new(scene, settings);
    renderer.prepare(0, 0.0).unwrap();
    let (_, r) = renderer.render_frame(1, 1.0 / 30.0).unwrap();
    let u = r.update;
    (u.preprocessing_ms() / r.total_ms, r.total_ms)
}

fn main() {
    // `cargo bench` passes `--bench`; an optional size filter like `100k` or `1M` may follow.
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with("--"));
    println!(
        "| triangles | deformed | animate+dirty ms | refit ms | LOD update ms | update ms (refit) | rebuild ms | update ms (rebuild) | refit/rebuild | LOD recomputed | preprocessing share @640x480 | frame ms |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (label, triangles) in [("100k", 100_000usize), ("1M", 1_000_000)] {
        if filter.as_deref().is_some_and(|f| f != label) {
            continue;
        }
        for share in [0.01, 0.10, 1.0] {
            let (last, refit, _) = update_medians(
                scene(triangles, share),
                BvhPolicy::Refit {
                    rebuild_threshold: f32::INFINITY,
                },
            );
            let (_, rebuild, _) = update_medians(scene(triangles, share), BvhPolicy::Rebuild);
            let (pre_share, frame_ms) = preprocessing_share(scene(triangles, share));
            println!(
                "| {} | {:.0}% | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {:.1}% | {:.1} |",
                triangles,
                share * 100.0,
                refit[0],
                refit[1],
                refit[3],
                refit[4],
                rebuild[2],
                rebuild[4],
                refit[1] / rebuild[2],
                last.lod_recomputed,
                pre_share * 100.0,
                frame_ms
            );
        }
    }
}
