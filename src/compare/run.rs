//! Runs the comparison: every frame is prepared once, then rendered by the reference and by
//! every method, timed interleaved, and measured.
//!
//! Timing: per frame, `repeats` rounds; each round renders every method once, starting
//! from a different method each round so none always runs first (cache warm-up and
//! frequency drift fall on all alike). A method's frame time is the median of its rounds
//! plus, for methods that use `log2 P_b` (`paper`, `paper-cos`, `cones`), the frame
//! update's `log2 P_b` refresh, which only they pay. The rest of the update (animation,
//! refit) is the same for every method and reported once as `shared_update_ms`.
//! `none` is always rendered (first in the report): overheads are relative to it. A method
//! may be asked for at N samples per pixel (`none@16`, [`MethodSpec`]): its renders, and so
//! its times, use N jittered samples, placing supersampling on the same chart.
//!
//! LOD error is measured against two references computed once per frame: the probe's
//! finite-difference reference (`lod_error.rs`, in `FrameErrors`) and the independent
//! sub-pixel reference (`subpixel_reference.rs`, in [`CompareResults::subpixel`]).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use image::RgbImage;

use super::lod_error::{LodErrorStats, method_error, reference_levels};
use super::subpixel_reference::{SubpixelReference, subpixel_reference};
use super::{
    CompareReport, FrameErrors, LevelError, LightsRow, MethodSpec, MethodSummary,
    SubpixelFrameErrors, SubpixelSummary,
};
use crate::atomic_file::write_rgb8_atomically;
use crate::frame::{FrameClock, PreparedFrame, RenderSettings, Renderer};
use crate::lod::LodMethod;
use crate::metrics;
use crate::percentiles::median;
use crate::record::Phase;
use crate::render::integrator::{FrameScene, MIP_LEVELS};
use crate::render::lod_view::lod_image;
use crate::render::memory::{LINEAR_PIXEL_BYTES, SRGB8_PIXEL_BYTES, check_frame_memory};
use crate::render::{Camera, LinearImage, render_image};
use crate::scene::SceneDesc;

/// What to compare.
#[derive(Debug, Clone)]
pub struct CompareOptions {
    pub scene_name: String,
    /// Size, lights, depth, bias and animation; `lod` and `spp` are set per render.
    pub settings: RenderSettings,
    /// Iterated, never collected up front: memory grows with the frames compared.
    pub frames: std::ops::Range<u32>,
    pub clock: FrameClock,
    /// Methods and their samples per pixel (`none` at 1 is added first if absent).
    pub methods: Vec<MethodSpec>,
    /// Samples per pixel of the level-0 reference (stratified).
    pub reference_spp: u32,
    pub repeats: u32,
    /// Light counts of the Table 1 replication (empty: skip it).
    pub table1_lights: Vec<usize>,
    /// Where to write the reference's and each method's frames (`None`: not written).
    pub frames_dir: Option<PathBuf>,
    /// Where to write each method's `--view lod` images (`None`: not written).
    pub lod_view_dir: Option<PathBuf>,
}

/// The bytes per pixel a comparison holds at least while it compares a frame: every
/// method's linear image (the interleaved timing keeps them all), the reference's 8-bit
/// codes, the probe's and the two sub-pixel LOD references, and from the second frame on
/// the previous frame's codes of every method and of the reference (for flicker). A lower
/// bound: each method's 8-bit codes, made one at a time, and the `--view lod` images come
/// on top.
fn compare_pixel_bytes(methods: usize, several_frames: bool) -> u64 {
    let methods = methods as u64;
    let level = std::mem::size_of::<Option<super::lod_error::ReferenceLevel>>() as u64;
    let previous = if several_frames {
        (methods + 1) * SRGB8_PIXEL_BYTES
    } else {
        0
    };
    methods * LINEAR_PIXEL_BYTES + SRGB8_PIXEL_BYTES + 3 * level + previous
}

/// Per-method state carried over the frames.
struct MethodRun {
    method: MethodSpec,
    frames: Vec<FrameErrors>,
    subpixel: Vec<SubpixelFrameErrors>,
    histogram: [u64; MIP_LEVELS],
    previous: Option<RgbImage>,
}

/// What `run_compare` measured: the report (errors against the supersampled image and the
/// probe's finite-difference LOD reference) and, per method in the same order, the LOD
/// errors against the sub-pixel reference.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareResults {
    pub report: CompareReport,
    pub subpixel: Vec<SubpixelSummary>,
}

/// Compares the methods on `load()`'s scene; `log` receives one line per frame.
pub fn run_compare(
    load: impl Fn() -> Result<SceneDesc>,
    options: &CompareOptions,
    log: &dyn Fn(&str),
) -> Result<CompareResults> {
    let methods = with_baseline(&options.methods);
    if !options.frames.is_empty() {
        let (width, height) = (options.settings.width, options.settings.height);
        let per_pixel = compare_pixel_bytes(methods.len(), options.frames.len() > 1);
        check_frame_memory(width, height, per_pixel, || {
            format!(
                "comparing {} methods (`none` included) at this size",
                methods.len()
            )
        })?;
    }
    let mut runs: Vec<MethodRun> = methods
        .iter()
        .map(|&method| MethodRun {
            method,
            frames: Vec::new(),
            subpixel: Vec::new(),
            histogram: [0; MIP_LEVELS],
            previous: None,
        })
        .collect();
    // `paper` keeps `log2 P_b` up to date for every method that reads it.
    let settings = RenderSettings {
        lod: LodMethod::Paper,
        spp: 1,
        ..options.settings
    };
    let mut renderer = Renderer::new(load()?, settings);
    let lights = renderer.light_count();
    let mut previous_reference: Option<RgbImage> = None;
    let mut shared_update_ms = 0.0;
    for (fi, frame) in options.frames.clone().enumerate() {
        let prepared = renderer.prepare(frame, options.clock.time(frame))?;
        let u = prepared.update;
        shared_update_ms += Phase::ALL
            .into_iter()
            .filter(|p| p.is_shared())
            .map(|p| u.phase_ms(p))
            .sum::<f64>();
        let camera = prepared.camera;
        let scene_with = |lod| FrameScene {
            lod,
            ..renderer.frame_scene(&prepared)
        };
        let reference_scene = scene_with(LodMethod::None);
        let reference = srgb(&render_image(&reference_scene, &camera, options.reference_spp).0);
        let lod_reference = reference_levels(&reference_scene, &camera);
        let subpixel = subpixel_reference(&reference_scene, &camera);
        let timed = time_interleaved(&methods, options.repeats, fi, &scene_with, &camera);
        for (run, (times, image, counters)) in runs.iter_mut().zip(timed) {
            let scene = scene_with(run.method.method);
            let test = srgb(&image);
            let (m, _) = metrics::compare(&reference, &test);
            let lod = method_error(&scene, &camera, &lod_reference);
            run.subpixel
                .push(subpixel_errors(frame, &scene, &camera, &subpixel));
            let flicker = match (&run.previous, &previous_reference) {
                (Some(prev), Some(prev_ref)) => Some(metrics::temporal::flicker(
                    prev, &test, prev_ref, &reference,
                )),
                _ => None,
            };
            // The phases only methods reading `log2 P_b` pay.
            let update: f64 = Phase::ALL
                .into_iter()
                .filter(|p| !p.is_shared() && run.method.method.needs_log2_pb())
                .map(|p| u.phase_ms(p))
                .sum();
            run.frames.push(frame_errors(
                frame,
                median(times) + update,
                &m,
                metrics::ssim::ssim(&reference, &test),
                lod,
                flicker,
            ));
            for (a, b) in run.histogram.iter_mut().zip(counters.mip_histogram) {
                *a += b;
            }
            write_extras(options, run.method, frame, &test, &scene, &camera)?;
            run.previous = Some(test);
        }
        if let Some(dir) = &options.frames_dir {
            write_png(&dir.join("reference"), frame, &reference)?;
        }
        log(&frame_line(frame, &runs));
        previous_reference = Some(reference);
    }
    let frames = options.frames.len().max(1) as f64;
    let table1 = options
        .table1_lights
        .iter()
        .map(|&n| lights_row(&load, options, n, log))
        .collect::<Result<Vec<_>>>()?;
    let subpixel = runs.iter().map(summarise_subpixel).collect();
    let mut methods: Vec<MethodSummary> = runs.into_iter().map(summarise).collect();
    let baseline = methods[0].ms_per_frame;
    for m in &mut methods {
        m.overhead_pct = (m.ms_per_frame / baseline - 1.0) * 100.0;
    }
    let report = CompareReport {
        scene: options.scene_name.clone(),
        width: options.settings.width,
        height: options.settings.height,
        frames: options.frames.clone().collect(),
        reference_spp: options.reference_spp,
        repeats: options.repeats,
        lights,
        shared_update_ms: shared_update_ms / frames,
        lod_bias: options.settings.lod_bias,
        mip_filter: options.settings.mip_filter,
        methods,
        table1,
    };
    Ok(CompareResults { report, subpixel })
}

/// The error of `scene.lod` against the sub-pixel reference under both conventions.
fn subpixel_errors(
    frame: u32,
    scene: &FrameScene,
    camera: &Camera,
    reference: &SubpixelReference,
) -> SubpixelFrameErrors {
    let level_error = |e: LodErrorStats| LevelError {
        bias: e.bias,
        rms: e.rms,
        under: e.under,
    };
    let longest_axis = method_error(scene, camera, &reference.longest_axis);
    let area = method_error(scene, camera, &reference.area);
    SubpixelFrameErrors {
        frame,
        longest_axis: level_error(longest_axis),
        area: level_error(area),
        pixels: longest_axis.pixels,
        undefined_share: reference.undefined_share(),
    }
}

fn summarise_subpixel(run: &MethodRun) -> SubpixelSummary {
    let mean = |f: &dyn Fn(&SubpixelFrameErrors) -> f64| mean_finite(run.subpixel.iter().map(f));
    let mean_error = |pick: fn(&SubpixelFrameErrors) -> LevelError| LevelError {
        bias: mean(&|f| pick(f).bias),
        rms: mean(&|f| pick(f).rms),
        under: mean(&|f| pick(f).under),
    };
    SubpixelSummary {
        method: run.method.to_string(),
        longest_axis: mean_error(|f| f.longest_axis),
        area: mean_error(|f| f.area),
        undefined_share: mean(&|f| f.undefined_share),
        frames: run.subpixel.clone(),
    }
}

/// Mean of the finite values (NaN if there are none).
fn mean_finite(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values
        .filter(|v| v.is_finite())
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

/// `none` at one sample first (the baseline), then the requested methods in order,
/// without repeats.
fn with_baseline(methods: &[MethodSpec]) -> Vec<MethodSpec> {
    let mut all = vec![MethodSpec::single(LodMethod::None)];
    for &m in methods {
        if !all.contains(&m) {
            all.push(m);
        }
    }
    all
}

type Timed = (Vec<f64>, LinearImage, crate::render::TraceCounters);

/// Renders the frame `repeats` times with every method, rotating the order each round and
/// each frame (`rotation`), so that no method always goes first (with one repeat the first
/// render of a frame can pay for warm-up); returns each method's render times, its image
/// and counters (renders are deterministic, so any round's image is the image).
fn time_interleaved<'s>(
    methods: &[MethodSpec],
    repeats: u32,
    rotation: usize,
    scene_with: &dyn Fn(LodMethod) -> FrameScene<'s>,
    camera: &Camera,
) -> Vec<Timed> {
    let n = methods.len();
    let mut times = vec![Vec::with_capacity(repeats as usize); n];
    let mut outputs: Vec<Option<(LinearImage, crate::render::TraceCounters)>> = vec![None; n];
    for round in 0..repeats.max(1) as usize {
        for k in 0..n {
            let m = (k + round + rotation) % n;
            let scene = scene_with(methods[m].method);
            let start = Instant::now();
            let output = render_image(&scene, camera, methods[m].spp);
            times[m].push(start.elapsed().as_secs_f64() * 1e3);
            outputs[m].get_or_insert(output);
        }
    }
    times
        .into_iter()
        .zip(outputs)
        .map(|(t, o)| {
            let (image, counters) = o.expect("every method rendered at least once");
            (t, image, counters)
        })
        .collect()
}

fn frame_errors(
    frame: u32,
    ms: f64,
    m: &metrics::FrameMetrics,
    ssim: f64,
    lod: LodErrorStats,
    flicker: Option<f64>,
) -> FrameErrors {
    FrameErrors {
        frame,
        ms,
        psnr: m.psnr_db,
        ssim,
        flip: m.mean_flip,
        lod_bias: lod.bias,
        lod_rms: lod.rms,
        lod_under: lod.under,
        lod_pixels: lod.pixels,
        flicker,
    }
}

fn summarise(run: MethodRun) -> MethodSummary {
    let mean = |f: &dyn Fn(&FrameErrors) -> Option<f64>| {
        let values: Vec<f64> = run
            .frames
            .iter()
            .filter_map(f)
            .filter(|v| v.is_finite())
            .collect();
        if values.is_empty() {
            f64::NAN
        } else {
            values.iter().sum::<f64>() / values.len() as f64
        }
    };
    let lookups: u64 = run.histogram.iter().sum();
    MethodSummary {
        method: run.method.to_string(),
        bytes_per_ray: run.method.method.bytes_per_ray(),
        ms_per_frame: mean(&|f| Some(f.ms)),
        overhead_pct: 0.0,
        // Identical frames have an infinite PSNR; the mean is over the finite ones, and
        // infinite only if every frame is identical.
        psnr: match mean(&|f| Some(f.psnr)) {
            p if p.is_nan() && run.frames.iter().all(|f| f.psnr.is_infinite()) => f64::INFINITY,
            p => p,
        },
        ssim: mean(&|f| Some(f.ssim)),
        flip: mean(&|f| Some(f.flip)),
        lod_bias: mean(&|f| Some(f.lod_bias)),
        lod_rms: mean(&|f| Some(f.lod_rms)),
        lod_under: mean(&|f| Some(f.lod_under)),
        flicker: mean(&|f| f.flicker),
        mip_share: run
            .histogram
            .iter()
            .map(|&c| {
                if lookups == 0 {
                    0.0
                } else {
                    c as f64 / lookups as f64
                }
            })
            .collect(),
        frames: run.frames,
    }
}

/// Table 1: `none` against `paper` with `lights` lights, timed interleaved per frame.
fn lights_row(
    load: &impl Fn() -> Result<SceneDesc>,
    options: &CompareOptions,
    lights: usize,
    log: &dyn Fn(&str),
) -> Result<LightsRow> {
    let settings = RenderSettings {
        lod: LodMethod::Paper,
        spp: 1,
        lights: Some(lights),
        ..options.settings
    };
    let mut renderer = Renderer::new(load()?, settings);
    let methods = [LodMethod::None, LodMethod::Paper].map(MethodSpec::single);
    let (mut none_ms, mut paper_ms) = (0.0, 0.0);
    for (fi, frame) in options.frames.clone().enumerate() {
        let prepared: PreparedFrame = renderer.prepare(frame, options.clock.time(frame))?;
        let scene_with = |lod| FrameScene {
            lod,
            ..renderer.frame_scene(&prepared)
        };
        let timed = time_interleaved(&methods, options.repeats, fi, &scene_with, &prepared.camera);
        let mut medians = timed.into_iter().map(|(t, _, _)| median(t));
        none_ms += medians.next().unwrap_or(f64::NAN);
        paper_ms += medians.next().unwrap_or(f64::NAN) + prepared.update.lod_update_ms;
    }
    let frames = options.frames.len().max(1) as f64;
    let row = LightsRow {
        lights,
        none_ms: none_ms / frames,
        paper_ms: paper_ms / frames,
        overhead_pct: (paper_ms / none_ms - 1.0) * 100.0,
    };
    log(&format!(
        "table 1: {lights} light(s): none {:.2} ms, paper {:.2} ms, overhead {:+.2}%",
        row.none_ms, row.paper_ms, row.overhead_pct
    ));
    Ok(row)
}

fn srgb(image: &LinearImage) -> RgbImage {
    RgbImage::from_raw(image.width, image.height, image.to_srgb8()).expect("w * h * 3 bytes")
}

fn write_png(dir: &std::path::Path, frame: u32, image: &RgbImage) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let path = dir.join(format!("frame_{frame:04}.png"));
    write_rgb8_atomically(&path, image).with_context(|| format!("cannot write {}", path.display()))
}

/// The method's frame and level view, when asked for.
fn write_extras(
    options: &CompareOptions,
    method: MethodSpec,
    frame: u32,
    image: &RgbImage,
    scene: &FrameScene,
    camera: &Camera,
) -> Result<()> {
    if let Some(dir) = &options.frames_dir {
        write_png(&dir.join(method.to_string()), frame, image)?;
    }
    if let Some(dir) = &options.lod_view_dir {
        write_png(
            &dir.join(method.to_string()),
            frame,
            &lod_image(scene, camera),
        )?;
    }
    Ok(())
}

fn frame_line(frame: u32, runs: &[MethodRun]) -> String {
    let parts: Vec<String> = runs
        .iter()
        .filter_map(|r| {
            let f = r.frames.last()?;
            Some(format!(
                "{} {:.1} ms flip {:.4} lod {:+.2}",
                r.method, f.ms, f.flip, f.lod_bias
            ))
        })
        .collect();
    format!("frame {frame:04}: {}", parts.join(" | "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn baseline_comes_first_once() {
        let spec = |word: &str| word.parse::<MethodSpec>().unwrap();
        assert_eq!(
            with_baseline(&[spec("paper"), spec("none"), spec("none@4"), spec("paper")]),
            vec![spec("none"), spec("paper"), spec("none@4")]
        );
    }
}
