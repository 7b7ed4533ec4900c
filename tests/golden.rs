//! Golden frames: every animation in `animations/` and the three BART scenes, rendered at
//! 96x72 with `none`, `paper` and `cones` at four times each, against reference frames in
//! `tests/golden/<scene>/<method>/frame_NNNN.png`.
//!
//! Frames render through the binary (the interface users have), so the check covers
//! loading, animation, the BVH, the LOD methods, shading and the PNG writer together.
//!
//! The comparison uses the metrics of `mipray diff` (`mipray::metrics::compare`). A frame
//! passes when both hold:
//! - **mean FLIP <= 0.002**: the perceptual error of a 96x72 frame in which at most ~14
//!   pixels changed completely (FLIP 1 each), or many changed invisibly;
//! - **at most 0.5% of the pixels (35 of 6912) differ by more than 2 codes** in a channel.
//!
//! Why not `max-abs 0`: frames are deterministic today (same bits for any thread count),
//! but speed work may legitimately reorder float operations; that moves colours by a code
//! or so, and may flip a few silhouette pixels to the neighbouring triangle (a full-size
//! difference at one pixel). Both stay inside the thresholds. A real change does not:
//! moving every level by a quarter (`--lod-bias 0.25`, checked below), one bounce fewer, a
//! different light falloff or a shifted animation moves hundreds of pixels by more than 2
//! codes. The test below that renders with a bias proves the check can fail.
//!
//! Re-bless (after a deliberate change to the images, never automatically):
//! `MIPRAY_BLESS=1 cargo test --release --test golden`; then look at the new frames
//! before committing them.

use std::path::{Path, PathBuf};

use image::RgbImage;
use mipray::metrics::{FrameMetrics, compare, heat_map, read_srgb8};

mod common;

/// One golden sequence: a scene and the frame rate that spreads four frames over it.
struct GoldenScene {
    /// Folder name under `tests/golden/`.
    name: &'static str,
    /// `mipray render` scene argument (a name in `animations/`, or a path).
    scene: PathBuf,
    /// Frame rate for `--fps`: frames 0..4 sample the animation at `i / fps` seconds.
    fps: f64,
}

const METHODS: [&str; 3] = ["none", "paper", "cones"];
const FRAMES: u32 = 4;
const SIZE: &str = "96x72";
const MAX_MEAN_FLIP: f64 = 0.002;
const CODE_TOLERANCE: u8 = 2;
const MAX_SHARE_BEYOND_TOLERANCE: f64 = 0.005;

fn crate_root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn our_animations() -> Vec<GoldenScene> {
    // Durations (mipray info): default 1.6 s, kitchen 6 s, robots 4 s, museum 6 s.
    [
        ("default", 2.5),
        ("kitchen", 0.75),
        ("robots", 1.0),
        ("museum", 0.75),
    ]
    .into_iter()
    .map(|(name, fps)| GoldenScene {
        name,
        scene: crate_root().join("animations").join(format!("{name}.gltf")),
        fps,
    })
    .collect()
}

/// The BART scenes, or `None` (after printing why, or panicking under `CI`) without them.
fn bart_scenes() -> Option<Vec<GoldenScene>> {
    let bart = common::shared_data::shared_path("bart")?;
    // Durations: kitchen 20 s, robots 50 s, museum5 5 s.
    Some(
        [
            ("bart-kitchen", "kitchen/aff/kitchen.aff", 0.2),
            ("bart-robots", "robots/aff/Robot.aff", 0.08),
            ("bart-museum5", "museum/aff/museum5.aff", 0.8),
        ]
        .into_iter()
        .map(|(name, file, fps)| GoldenScene {
            name,
            scene: bart.join(file),
            fps,
        })
        .collect(),
    )
}

/// Renders frames 0..FRAMES of `scene` with `method` (plus `extra` arguments) into `out`.
fn render(scene: &GoldenScene, method: &str, extra: &[&str], out: &Path) {
    let fps = scene.fps.to_string();
    let scene_arg = scene.scene.to_str().expect("UTF-8 path");
    let frames = format!("0..{FRAMES}");
    let mut args = vec![
        "render", scene_arg, "--frames", &frames, "--fps", &fps, "--size", SIZE, "--lod", method,
        "--out",
    ];
    let out_arg = out.to_str().expect("UTF-8 path");
    args.push(out_arg);
    args.extend_from_slice(extra);
    let output = common::mipray(&args, crate_root());
    assert!(
        output.status.success(),
        "{} {method}: render failed: {}",
        scene.name,
        String::from_utf8_lossy(&output.stderr)
    );
}

/// Whether `m` (and the share of pixels beyond the code tolerance) is within the thresholds.
fn within_thresholds(m: &FrameMetrics, share_beyond_tolerance: f64) -> bool {
    m.mean_flip <= MAX_MEAN_FLIP && share_beyond_tolerance <= MAX_SHARE_BEYOND_TOLERANCE
}

/// Share of pixels with some channel more than `CODE_TOLERANCE` codes from the reference.
fn share_beyond_tolerance(reference: &RgbImage, test: &RgbImage) -> f64 {
    let beyond = reference
        .pixels()
        .zip(test.pixels())
        .filter(|(a, b)| (0..3).any(|c| a.0[c].abs_diff(b.0[c]) > CODE_TOLERANCE))
        .count();
    beyond as f64 / (reference.width() as f64 * reference.height() as f64).max(1.0)
}

/// Where a failing frame's reference, render and FLIP heat map go.
fn failure_dir(scene: &str, method: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .expect("target dir")
        .join("test-failures/golden")
        .join(scene)
        .join(method)
}

/// Compares one rendered frame with its golden frame; `Err` describes a failure.
fn check_frame(
    scene: &str,
    method: &str,
    frame: u32,
    golden: &Path,
    test: &Path,
) -> Result<(), String> {
    let label = format!("{scene} frame {frame} --lod {method}");
    if !golden.is_file() {
        return Err(format!(
            "{label}: no golden frame {} (bless with MIPRAY_BLESS=1 cargo test --release --test golden)",
            golden.display()
        ));
    }
    let reference = read_srgb8(golden).map_err(|e| format!("{label}: {e}"))?;
    let rendered = read_srgb8(test).map_err(|e| format!("{label}: {e}"))?;
    if reference.dimensions() != rendered.dimensions() {
        return Err(format!(
            "{label}: golden is {:?}, render is {:?}",
            reference.dimensions(),
            rendered.dimensions()
        ));
    }
    let (metrics, error_map) = compare(&reference, &rendered);
    let share = share_beyond_tolerance(&reference, &rendered);
    if within_thresholds(&metrics, share) {
        return Ok(());
    }
    let dir = failure_dir(scene, method);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for (suffix, image) in [
        ("ref", &reference),
        ("test", &rendered),
        ("diff", &heat_map(&error_map)),
    ] {
        let path = dir.join(format!("frame_{frame:04}_{suffix}.png"));
        image
            .save(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
    }
    Err(format!(
        "{label}: mean FLIP {:.5} (limit {MAX_MEAN_FLIP}), {:.2}% of pixels off by more than \
         {CODE_TOLERANCE} codes (limit {:.1}%), max abs {}, PSNR {} dB; images in {}",
        metrics.mean_flip,
        100.0 * share,
        100.0 * MAX_SHARE_BEYOND_TOLERANCE,
        metrics.max_abs,
        mipray::metrics::format_psnr(metrics.psnr_db),
        dir.display()
    ))
}

fn blessing() -> bool {
    std::env::var_os("MIPRAY_BLESS").is_some_and(|v| v == "1")
}

/// Renders every scene and method; blesses or checks every frame; panics listing failures.
fn check_scenes(scenes: &[GoldenScene]) {
    let scratch = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    let mut checked = 0;
    for scene in scenes {
        for method in METHODS {
            let out = scratch.path().join(scene.name).join(method);
            render(scene, method, &[], &out);
            let golden_dir = crate_root()
                .join("tests/golden")
                .join(scene.name)
                .join(method);
            for frame in 0..FRAMES {
                let name = format!("frame_{frame:04}.png");
                let (golden, test) = (golden_dir.join(&name), out.join(&name));
                if blessing() {
                    std::fs::create_dir_all(&golden_dir).unwrap();
                    std::fs::copy(&test, &golden).unwrap();
                    println!("blessed {}", golden.display());
                    continue;
                }
                checked += 1;
                if let Err(failure) = check_frame(scene.name, method, frame, &golden, &test) {
                    failures.push(failure);
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {checked} golden frames failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn animations_match_their_golden_frames() {
    check_scenes(&our_animations());
}

#[test]
fn bart_scenes_match_their_golden_frames() {
    if let Some(scenes) = bart_scenes() {
        check_scenes(&scenes);
    }
}

/// The thresholds are not so loose that a real change passes: a quarter-level LOD bias on
/// the default animation must fail for `paper` and `cones`.
#[test]
fn a_quarter_level_lod_bias_fails_the_golden_check() {
    if blessing() {
        return;
    }
    let scene = &our_animations()[0];
    let scratch = tempfile::tempdir().unwrap();
    for method in ["paper", "cones"] {
        let out = scratch.path().join(method);
        render(scene, method, &["--lod-bias", "0.25"], &out);
        let golden_dir = crate_root()
            .join("tests/golden")
            .join(scene.name)
            .join(method);
        let failing = (0..FRAMES)
            .filter(|frame| {
                let name = format!("frame_{frame:04}.png");
                check_frame(
                    "default-biased",
                    method,
                    *frame,
                    &golden_dir.join(&name),
                    &out.join(&name),
                )
                .is_err()
            })
            .count();
        assert_eq!(
            failing, FRAMES as usize,
            "{method}: a +0.25 level bias passed the golden check"
        );
    }
}
