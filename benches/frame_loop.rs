//! Frame-loop update costs on generated scenes: `cargo bench --bench frame_loop`.
//!
//! Scenes (all textured, generated in code outside the timed region; see
//! `benches/common/generated.rs`):
//! - `patches`: 100k and 1M triangles in a grid of patch instances (968 triangles each) of
//!   which 1%, 10% or 100% deform every frame (an animated non-uniform scale: the shape
//!   changes, so `log2 P_b` is recomputed, as for skinning or morphing), the rest static;
//! - `skin`: one 1M-triangle grid skinned to a chain of 8 animated joints: every vertex
//!   moves every frame;
//! - `rigid`: 200 instances of a 5,000-triangle patch, each turning and sliding (rigid
//!   motion: no `log2 P_b` recomputed after the first frame).
//!
//! Each scene runs under each BVH layout (`flat`, `two-level`: see `accel::TwoLevelAccel`;
//! `auto`, the default: per mesh, see `frame::LayoutPlan`).
//! For each the per-frame update is timed over several frames with refits only and with a
//! rebuild every frame (under `two-level` the rebuild is the world tree's, over the
//! deforming instances; the top-level tree is rebuilt whenever an instance moved, and
//! counted as refit), and three frames are rendered at 640x480 with the default policy to give
//! the render time and the preprocessing share (medians). Peak resident memory (VmHWM from
//! /proc/self/status, reset through /proc/self/clear_refs before the scene is generated)
//! is reported above the resident size at the reset, in MB per million triangles, for the
//! default-policy run (scene, renderer, tree and the rendered frames), beside the resident
//! size after those frames (VmRSS: what stays between frames). Below the table, the peak of
//! obvhs's builder alone over a million triangle boxes, and over one chunk of the flat
//! build (which hands the builder at most `BUILD_CHUNK_TRIANGLES` at once).
//!
//! Arguments (after `--`): words choosing rows: a size (`100k`, `1M`), a scene (`patches`,
//! `skin`, `rigid`) and/or a layout (`flat`, `two-level`, `auto`); none runs every row. Rayon's global pool is set to 2
//! threads (the figures in BENCHMARKS.md are for a 2-core machine); `RAYON_NUM_THREADS`
//! overrides it. Prints a Markdown table of medians (see BENCHMARKS.md and docs/benchmark-log.md).

#[path = "common/generated.rs"]
mod generated;

use std::time::Instant;

use glam::Vec3;
use mipray::frame::{BvhLayout, BvhPolicy, RenderSettings, Renderer};
use mipray::percentiles::Percentiles;
use mipray::record::{FrameRecord, UpdateStats};
use mipray::scene::*;

const PATCH_SIDE: u32 = 22; // 22 x 22 quads: 968 triangles per patch
const FRAMES: u32 = 6;

/// Frames rendered per row for the preprocessing share (the median is reported).
const RENDERED: u32 = 3;

/// `triangles` textured triangles in patches on a grid facing a camera; the first
/// `deformed_share` of the patches stretch over time.
fn patches_scene(triangles: usize, deformed_share: f64) -> SceneDesc {
    let patch = generated::patch(PATCH_SIDE, PATCH_SIDE, 1.0, 1.0);
    let per_patch = patch.triangle_count();
    let patches = triangles.div_ceil(per_patch);
    let side = (patches as f64).sqrt().ceil() as usize;
    let mut scene = generated::textured_scene();
    scene.meshes.push(MeshDesc {
        name: "patch".into(),
        primitives: vec![patch],
        ..Default::default()
    });
    let deformed = (patches as f64 * deformed_share).round() as usize;
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
        scene.roots.push(scene.nodes.len() - 1);
        if p < deformed {
            scene.animations[0].channels.push(ChannelDesc {
                node: scene.nodes.len() - 1,
                target: ChannelTarget::Scale,
                interpolation: Interpolation::Linear,
                times: vec![0.0, 1.0],
                values: vec![1.0, 1.0, 1.0, 1.5, 0.8, 1.0],
                components: 3,
            });
        }
    }
    generated::add_camera(&mut scene, Vec3::new(0.0, 0.0, side as f32 * 1.1), 1.0);
    scene
}

/// One 1M-triangle grid (1,000 x 500 quads, 10 x 5 units) skinned to 8 animated joints.
fn skin_scene() -> SceneDesc {
    let mut scene = generated::textured_scene();
    generated::add_skinned_grid(
        &mut scene,
        1000,
        500,
        (10.0, 5.0),
        8,
        Vec3::new(-5.0, 0.0, 0.0),
    );
    generated::add_camera(&mut scene, Vec3::new(0.0, 0.0, 9.0), 1.0);
    scene
}

/// 200 instances of a 50 x 50-quad (5,000-triangle) patch, each moving rigidly.
fn rigid_scene() -> SceneDesc {
    let mut scene = generated::textured_scene();
    generated::add_rigid_patches(&mut scene, 200, 50, 1.3, Vec3::ZERO);
    generated::add_camera(&mut scene, Vec3::new(0.0, 0.0, 20.0), 1.0);
    scene
}

/// Median per-frame update stats over frames 1..=FRAMES (frame 0 is the initial build):
/// the last frame's stats; medians of (animate + dirty, refit, build, LOD update,
/// preprocessing, animate, dirty) ms; the first frame's ms; the triangle count.
fn update_medians(
    scene: SceneDesc,
    bvh: BvhPolicy,
    layout: BvhLayout,
) -> (UpdateStats, [f64; 7], f64, usize) {
    let settings = RenderSettings {
        width: 640,
        height: 480,
        bvh,
        layout,
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
        median(|u| u.animate_ms),
        median(|u| u.dirty_ms),
    ];
    let triangles = renderer.geometry().triangle_count();
    (rows[rows.len() - 1], medians, first_ms, triangles)
}

/// Rendered frames 1..=RENDERED (after the initial build) at 640x480 with the default
/// policy: medians of (preprocessing share, frame ms, render ms), and the resident MB above
/// the start at its peak and after the last frame. (One frame alone made the share swing by
/// several points run to run.)
fn rendered_frame(
    make_scene: impl FnOnce() -> SceneDesc,
    layout: BvhLayout,
) -> (f64, f64, f64, Resident) {
    let start_mb = reset_peak_resident_mb();
    let settings = RenderSettings {
        width: 640,
        height: 480,
        layout,
        ..Default::default()
    };
    let mut renderer = Renderer::new(make_scene(), settings);
    renderer.prepare(0, 0.0).unwrap();
    let mut frames = Vec::new();
    for frame in 1..=RENDERED {
        let (_, r) = renderer.render_frame(frame, frame as f32 / 30.0).unwrap();
        frames.push(r);
    }
    let resident = Resident {
        peak_mb: status_mb("VmHWM:") - start_mb,
        after_mb: status_mb("VmRSS:") - start_mb,
    };
    let median = |f: &dyn Fn(&FrameRecord) -> f64| Percentiles::of(frames.iter().map(f)).median;
    (
        median(&|r| r.update.preprocessing_ms() / r.total_ms),
        median(&|r| r.total_ms),
        median(&|r| r.render_ms),
        resident,
    )
}

/// Resident memory of a run above the resident size at its start (MB).
#[derive(Clone, Copy)]
struct Resident {
    /// At its peak (VmHWM): the first frame's tree build, for the flat layouts.
    peak_mb: f64,
    /// After the last rendered frame (VmRSS): what the frame loop keeps between frames,
    /// plus whatever the allocator has not returned to the system.
    after_mb: f64,
}

/// The BVH builder's own peak over `triangles` primitives: resident MB above the start
/// while obvhs builds its binary tree over a grid of triangle boxes, with the boxes counted
/// out (mipray hands the builder its triangles without copying their boxes). A build that
/// hands it all `triangles` at once cannot peak lower than this plus what it keeps.
fn builder_peak_mb(triangles: usize) -> f64 {
    use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::builder::build_bvh2};
    let side = ((triangles as f64 / 2.0).sqrt().ceil()) as usize;
    let boxes: Vec<Aabb> = (0..2 * side * side)
        .map(|i| {
            let (x, y) = ((i / 2) % side, (i / 2) / side);
            let min = glam::Vec3A::new(x as f32, y as f32, 0.0);
            Aabb::new(min, min + glam::Vec3A::new(1.0, 1.0, 1e-3))
        })
        .collect();
    let start_mb = reset_peak_resident_mb();
    let bvh = build_bvh2(
        &boxes,
        BvhBuildParams::medium_build(),
        &mut std::time::Duration::default(),
    );
    let peak = status_mb("VmHWM:") - start_mb;
    std::hint::black_box(bvh);
    peak
}

/// Resets the process's peak resident size to its current one (Linux: `clear_refs` 5) and
/// returns that size in MB (NaN where /proc is unavailable).
fn reset_peak_resident_mb() -> f64 {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    status_mb("VmRSS:")
}

/// A `/proc/self/status` field in kB, as MB (NaN when absent).
fn status_mb(field: &str) -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix(field))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// One table row: a scene by its labels, with a generator called afresh for each run.
struct Row {
    kind: &'static str,
    size: &'static str,
    moving: String,
    make: Box<dyn Fn() -> SceneDesc>,
}

fn rows() -> Vec<Row> {
    let mut rows = Vec::new();
    for (size, triangles) in [("100k", 100_000usize), ("1M", 1_000_000)] {
        for share in [0.01, 0.10, 1.0] {
            rows.push(Row {
                kind: "patches",
                size,
                moving: format!("{:.0}% deformed", share * 100.0),
                make: Box::new(move || patches_scene(triangles, share)),
            });
        }
    }
    rows.push(Row {
        kind: "skin",
        size: "1M",
        moving: "100% skinned".into(),
        make: Box::new(skin_scene),
    });
    rows.push(Row {
        kind: "rigid",
        size: "1M",
        moving: "200 x 5k rigid".into(),
        make: Box::new(rigid_scene),
    });
    rows
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(at) = args.iter().position(|a| a == "--peak-of") {
        // Child run: one row, one layout, print its peak MB.
        let index: usize = args[at + 1].parse().expect("row index");
        let layout = args[at + 2].parse().unwrap_or(BvhLayout::Flat);
        let (_, _, _, resident) = rendered_frame(&rows()[index].make, layout);
        println!("{} {}", resident.peak_mb, resident.after_mb);
        return;
    }
    if let Some(at) = args.iter().position(|a| a == "--builder-peak-of") {
        // Child run: the builder alone over this many triangles, print its peak MB.
        let triangles: usize = args[at + 1].parse().expect("triangle count");
        println!("{}", builder_peak_mb(triangles));
        return;
    }
    // `cargo bench` passes `--bench`; row filters like `1M`, `skin` or `two-level` may follow.
    let words: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let layouts = [
        (BvhLayout::Flat, "flat"),
        (BvhLayout::TwoLevel, "two-level"),
        (BvhLayout::Auto, "auto"),
    ];
    let layout_words: Vec<&String> = words
        .iter()
        .filter(|w| layouts.iter().any(|(_, name)| name == w))
        .collect();
    let row_words: Vec<&String> = words.iter().filter(|w| !layout_words.contains(w)).collect();
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build_global()
            .unwrap();
    }
    println!(
        "| scene | triangles | moving | bvh | animate+dirty ms | refit ms | LOD update ms | update ms (refit) | rebuild ms | update ms (rebuild) | refit/rebuild | LOD recomputed | preprocessing share @640x480 | frame ms | animate ms | dirty ms | render ms | peak MB per 1M triangles | MB per 1M triangles after the frames |"
    );
    println!(
        "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for (index, row) in rows().iter().enumerate() {
        if row_words.iter().any(|w| **w != row.kind && **w != row.size) {
            continue;
        }
        for &(layout, layout_name) in &layouts {
            if !layout_words.is_empty() && !layout_words.iter().any(|w| **w == layout_name) {
                continue;
            }
            print_row(index, row, layout, layout_name);
        }
    }
    if row_words.is_empty() || row_words.iter().any(|w| *w == "1M") {
        let chunk = mipray::accel::BUILD_CHUNK_TRIANGLES;
        println!(
            "\nobvhs's build over 1M triangle boxes alone peaks at {:.0} MB (its node arrays and the binary tree; the boxes not counted); over one chunk of a flat build ({chunk} boxes), at {:.0} MB.",
            builder_peak_in_fresh_process(1_000_000),
            builder_peak_in_fresh_process(chunk),
        );
    }
}

/// [`builder_peak_mb`] measured by a fresh run of this bench; NaN when that fails.
fn builder_peak_in_fresh_process(triangles: usize) -> f64 {
    child_output(&["--builder-peak-of", &triangles.to_string()])
        .and_then(|out| out.trim().parse().ok())
        .unwrap_or(f64::NAN)
}

/// What a fresh run of this bench with `args` prints, if it succeeds.
fn child_output(args: &[&str]) -> Option<String> {
    let exe = std::env::current_exe().ok()?;
    std::process::Command::new(exe)
        .args(args)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
}

/// Resident MB of row `index` under `layout_name` (peak, after the frames), measured by a
/// fresh run of this bench (`--peak-of`); NaN when that fails.
fn resident_in_fresh_process(index: usize, layout_name: &str) -> Resident {
    let parsed = child_output(&["--peak-of", &index.to_string(), layout_name]).and_then(|out| {
        let mut words = out.split_whitespace().map(|w| w.parse::<f64>().ok());
        Some(Resident {
            peak_mb: words.next()??,
            after_mb: words.next()??,
        })
    });
    parsed.unwrap_or(Resident {
        peak_mb: f64::NAN,
        after_mb: f64::NAN,
    })
}

/// Times one scene under one layout and prints its table row.
fn print_row(index: usize, row: &Row, layout: BvhLayout, layout_name: &str) {
    {
        let refit_only = BvhPolicy::Refit {
            rebuild_threshold: f32::INFINITY,
        };
        let (last, refit, _, triangles) = update_medians((row.make)(), refit_only, layout);
        let (_, rebuild, _, _) = update_medians((row.make)(), BvhPolicy::Rebuild, layout);
        let (pre_share, frame_ms, render_ms, _) = rendered_frame(&row.make, layout);
        let resident = resident_in_fresh_process(index, layout_name);
        let per_million = |mb: f64| mb / (triangles as f64 / 1e6);
        println!(
            "| {} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {:.1}% | {:.1} | {:.3} | {:.3} | {:.1} | {:.0} | {:.0} |",
            row.kind,
            triangles,
            row.moving,
            layout_name,
            refit[0],
            refit[1],
            refit[3],
            refit[4],
            rebuild[2],
            rebuild[4],
            refit[1] / rebuild[2],
            last.lod_recomputed,
            pre_share * 100.0,
            frame_ms,
            refit[5],
            refit[6],
            render_ms,
            per_million(resident.peak_mb),
            per_million(resident.after_mb),
        );
    }
}
