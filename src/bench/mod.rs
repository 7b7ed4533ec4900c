//! `mipray bench`: times LOD methods, BVH layouts and thread counts side by side in one run.
//!
//! Configurations are interleaved within each repeat (and their order rotated between
//! repeats) so that drift in machine load hits all of them alike; the report gives the median
//! over repeats and the median of the per-repeat ratios against the first method, which is
//! what `BENCHMARKS.md` records.

use std::fmt::Write;

mod rays;

pub use rays::{
    RayApi, RayFileRate, RayKind, RayKinds, RayRate, ray_file_table, ray_table, run_ray_bench,
    run_ray_file_bench,
};

use anyhow::Result;

use crate::accel::{BvhLayout, BvhPolicy};
use crate::frame::{RenderSettings, Renderer};
use crate::lod::LodMethod;
use crate::percentiles::Percentiles;
use crate::render::memory::{LINEAR_PIXEL_BYTES, check_frame_memory};
use crate::scene::SceneDesc;

/// One timed configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchConfig {
    pub lod: LodMethod,
    pub threads: usize,
    pub layout: BvhLayout,
    pub policy: BvhPolicy,
}

impl BenchConfig {
    /// The `--bvh` value this configuration stands for.
    pub fn bvh_name(&self) -> &'static str {
        match (self.layout, self.policy) {
            (BvhLayout::TwoLevel, _) => "two-level",
            (BvhLayout::Auto, _) => "auto",
            (BvhLayout::Flat, BvhPolicy::Rebuild) => "rebuild",
            (BvhLayout::Flat, _) => "flat",
        }
    }
}

/// Medians over repeats for one configuration.
#[derive(Debug, Clone)]
pub struct BenchResult {
    pub config: BenchConfig,
    /// Render time per frame (ms), over repeats.
    pub render_ms_per_frame: Percentiles,
    /// Whole-frame time (update + render) per frame (ms), over repeats.
    pub total_ms_per_frame: Percentiles,
    /// Rays per second of render time, over repeats.
    pub rays_per_second: Percentiles,
    /// Per-repeat ratio of this configuration's render time to the first configuration with
    /// the same thread count.
    pub render_ratio: Percentiles,
}

/// What a bench run measured: a result per configuration, and how much of the process's
/// memory the kernel backed with huge pages at the end, with every configuration's scene
/// still loaded (KiB, transparent and reserved: see [`crate::large_pages::huge_page_kib`];
/// `None` where the system does not say).
#[derive(Debug, Clone)]
pub struct BenchRun {
    pub results: Vec<BenchResult>,
    pub huge_page_kib: Option<(u64, u64)>,
}

/// Renders `frames` for every configuration, `repeats` times, interleaved.
pub fn run_bench(
    load: impl Fn() -> Result<SceneDesc>,
    settings: RenderSettings,
    frames: std::ops::Range<u32>,
    clock: crate::frame::FrameClock,
    configs: &[BenchConfig],
    repeats: usize,
) -> Result<BenchRun> {
    // Each render holds at least its frame's linear pixels.
    if !frames.is_empty() && repeats > 0 && !configs.is_empty() {
        check_frame_memory(settings.width, settings.height, LINEAR_PIXEL_BYTES, || {
            "rendering a frame this size".to_string()
        })?;
    }
    let pools = configs
        .iter()
        .map(|c| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(c.threads)
                .build()
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut renderers = configs
        .iter()
        .map(|c| {
            Ok(Renderer::new(
                load()?,
                RenderSettings {
                    lod: c.lod,
                    layout: c.layout,
                    bvh: c.policy,
                    ..settings
                },
            ))
        })
        .collect::<Result<Vec<_>>>()?;
    let n = configs.len();
    // samples[config][repeat] = (render ms, total ms, rays), summed over frames
    let mut samples = vec![vec![(0.0f64, 0.0f64, 0u64); repeats]; n];
    for repeat in 0..repeats {
        for k in 0..n {
            let c = (k + repeat) % n;
            for frame in frames.clone() {
                let time_s = clock.time(frame);
                let (_, record) = pools[c].install(|| renderers[c].render_frame(frame, time_s))?;
                let s = &mut samples[c][repeat];
                s.0 += record.render_ms;
                s.1 += record.total_ms;
                s.2 += record.rays;
            }
        }
    }
    let frame_count = frames.len().max(1) as f64;
    let huge_page_kib = crate::large_pages::huge_page_kib();
    let results = (0..n)
        .map(|c| {
            let baseline = (0..n)
                .find(|&b| configs[b].threads == configs[c].threads)
                .unwrap_or(c);
            BenchResult {
                config: configs[c],
                render_ms_per_frame: Percentiles::of(samples[c].iter().map(|s| s.0 / frame_count)),
                total_ms_per_frame: Percentiles::of(samples[c].iter().map(|s| s.1 / frame_count)),
                rays_per_second: Percentiles::of(
                    samples[c].iter().map(|s| s.2 as f64 / (s.0 / 1e3)),
                ),
                render_ratio: Percentiles::of(
                    (0..repeats).map(|r| samples[c][r].0 / samples[baseline][r].0),
                ),
            }
        })
        .collect();
    Ok(BenchRun {
        results,
        huge_page_kib,
    })
}

/// A Markdown table of bench results.
pub fn bench_table(results: &[BenchResult]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| lod | bvh | threads | render ms/frame (median) | min..max | frame ms (median) | Mrays/s (median) | render ratio vs first (median) |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|");
    for r in results {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2} | {:.2}..{:.2} | {:.2} | {:.3} | {:.4} |",
            r.config.lod,
            r.config.bvh_name(),
            r.config.threads,
            r.render_ms_per_frame.median,
            r.render_ms_per_frame.min,
            r.render_ms_per_frame.max,
            r.total_ms_per_frame.median,
            r.rays_per_second.median / 1e6,
            r.render_ratio.median
        );
    }
    s
}
