//! `mipray bench`: LOD methods and thread counts timed side by side (see `crate::bench`).

use anyhow::Result;
use clap::Args;

use super::args::{LightArgs, SequenceArgs, TraceArgs, check_threads, render_settings, usage};
use super::render::{BvhMode, apply_bvh};
use super::scene::{load_scene, open_scene};
use crate::accel::BvhPolicy;
use crate::bench::{
    BenchConfig, RayApi, RayKinds, bench_table, ray_file_table, ray_table, run_bench,
    run_ray_bench, run_ray_file_bench,
};
use crate::frame::Renderer;
use crate::lod::LodMethod;

/// Most repeats of a bench or compare (each repeat renders every frame of every method).
pub const MAX_REPEATS: usize = 1000;

#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// The scene and frames rendered per repeat.
    #[command(flatten)]
    pub sequence: SequenceArgs,
    #[command(flatten)]
    pub trace: TraceArgs,
    #[command(flatten)]
    pub lights: LightArgs,
    /// LOD methods, comma separated; ratios are against the first.
    #[arg(long, value_delimiter = ',', default_value = "none,paper")]
    pub methods: Vec<LodMethod>,
    /// Thread counts, comma separated, each 1 to 1024 [default: 1 and all cores].
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// How many times every configuration renders the frames.
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Time tracing alone instead of whole frames: `primary` (closest-hit rays through pixel
    /// centres), `shadow` (occlusion rays from their hits to every light) or `all` (both),
    /// no shading; or a ray file written by `export --rays` (path), whose rays are traced
    /// class by class on the first frame of `--frames` and checked against the file's
    /// answers.
    #[arg(long, value_parser = parse_rays_arg)]
    pub rays: Option<RaysArg>,
    /// With `--rays`: time mipray's packets (as the film traces each class), single rays
    /// (one at a time), or both. One alone suits a profiler or an instruction count,
    /// which see the whole process.
    #[arg(long, value_enum, default_value = "both", requires = "rays")]
    pub api: RayApi,
    /// With `--rays`: the least time one timed sample takes, in milliseconds. A class of
    /// rays traced faster is traced again, back to back, until that much time has gone by,
    /// and the sample is the time of one pass (a small class is so timed warm, as a
    /// profiler or Embree's repeated calls see it). 0: one pass a sample, for an
    /// instruction count that must grow by exactly one pass with each repeat.
    #[arg(long, default_value_t = 20.0, requires = "rays")]
    pub min_sample_ms: f64,
    /// BVH layouts and policies, comma separated, as `render --bvh` (whole frames: each is a
    /// configuration; `--rays primary|shadow|all`: the first; a ray file is always traced on
    /// the flat tree, whose slots are the faces its answers name).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "auto")]
    pub bvh: Vec<BvhMode>,
}

/// What `--rays` times: generated rays of some kinds, or the rays of a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RaysArg {
    Kinds(RayKinds),
    File(std::path::PathBuf),
}

fn parse_rays_arg(s: &str) -> Result<RaysArg, String> {
    use clap::ValueEnum;
    match RayKinds::from_str(s, false) {
        Ok(kinds) => Ok(RaysArg::Kinds(kinds)),
        Err(_) if s.is_empty() => Err("expected primary, shadow, all or a ray file".into()),
        Err(_) => Ok(RaysArg::File(s.into())),
    }
}

/// `mipray bench`.
pub fn bench(args: &BenchArgs) -> Result<()> {
    let mut settings = render_settings(&args.sequence, &args.trace, args.lights.lights, args.spp)?;
    if args.repeats == 0 || args.repeats > MAX_REPEATS || args.methods.is_empty() {
        return Err(usage(format!(
            "bench needs 1 to {MAX_REPEATS} repeats and at least one method"
        )));
    }
    if !(args.min_sample_ms.is_finite() && (0.0..=60_000.0).contains(&args.min_sample_ms)) {
        return Err(usage(format!(
            "--min-sample-ms {}: give 0 to 60000 milliseconds",
            args.min_sample_ms
        )));
    }
    let min_sample = std::time::Duration::from_secs_f64(args.min_sample_ms / 1e3);
    let Some(&first_bvh) = args.bvh.first() else {
        return Err(usage(
            "--bvh: give at least one of auto, flat, two-level, rebuild".into(),
        ));
    };
    apply_bvh(
        &mut settings,
        first_bvh,
        BvhPolicy::DEFAULT_REBUILD_THRESHOLD,
    )?;
    let scene = open_scene(&args.sequence)?;
    settings.animation = scene.animation;
    let (path, frames, clock) = (scene.path, scene.frames, scene.clock);
    drop(scene.desc); // every configuration loads its own copy
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut threads = if args.threads.is_empty() {
        vec![1, cores]
    } else {
        args.threads.clone()
    };
    threads.dedup();
    for &n in &threads {
        check_threads(n)?;
    }
    if let Some(RaysArg::File(file)) = &args.rays {
        eprintln!(
            "bench --rays {}: {} frame {} at {}x{} (flat tree), threads {:?} x {} repeats",
            file.display(),
            path.display(),
            frames.start,
            settings.width,
            settings.height,
            threads,
            args.repeats
        );
        settings.lod = args.methods[0];
        settings.layout = crate::accel::BvhLayout::Flat;
        let mut renderer = Renderer::new(load_scene(&path)?, settings);
        let rates = run_ray_file_bench(
            &mut renderer,
            frames.start,
            clock,
            file,
            args.api,
            &threads,
            args.repeats,
            min_sample,
        )?;
        print!("{}", ray_file_table(&rates));
        return Ok(());
    }
    if let Some(RaysArg::Kinds(kinds)) = args.rays {
        eprintln!(
            "bench --rays: {} frames {}..{} at {}x{}, {}, threads {:?} x {} repeats",
            path.display(),
            frames.start,
            frames.end,
            settings.width,
            settings.height,
            args.lights
                .lights
                .map_or("the scene's lights".to_string(), |n| format!(
                    "{n} light(s)"
                )),
            threads,
            args.repeats
        );
        settings.lod = args.methods[0];
        let mut renderer = Renderer::new(load_scene(&path)?, settings);
        let rates = run_ray_bench(
            &mut renderer,
            frames,
            clock,
            kinds,
            args.api,
            &threads,
            args.repeats,
            min_sample,
        )?;
        print!("{}", ray_table(&rates));
        return Ok(());
    }
    let mut configs = Vec::new();
    for &t in &threads {
        for &mode in &args.bvh {
            let mut s = settings;
            apply_bvh(&mut s, mode, BvhPolicy::DEFAULT_REBUILD_THRESHOLD)?;
            for &lod in &args.methods {
                configs.push(BenchConfig {
                    lod,
                    threads: t,
                    layout: s.layout,
                    policy: s.bvh,
                });
            }
        }
    }
    eprintln!(
        "bench: {} frames {}..{} at {}x{}, {} configurations x {} repeats",
        path.display(),
        frames.start,
        frames.end,
        settings.width,
        settings.height,
        configs.len(),
        args.repeats
    );
    let run = run_bench(
        || load_scene(&path),
        settings,
        frames,
        clock,
        &configs,
        args.repeats,
    )?;
    print!("{}", bench_table(&run.results));
    eprintln!("{}", memory_pages_note(run.huge_page_kib));
    Ok(())
}

/// How the run's memory was paged, for the record of a benchmark (times depend on it:
/// `crate::large_pages`).
fn memory_pages_note(huge_page_kib: Option<(u64, u64)>) -> String {
    let allocator = if crate::large_pages::is_in_use() {
        "large buffers in 2 MiB-aligned mappings of their own"
    } else {
        "large buffers from the system allocator"
    };
    match huge_page_kib {
        Some((transparent, reserved)) => format!(
            "memory: {allocator}; at the end {} MiB in transparent huge pages, {} MiB in \
             reserved huge pages",
            transparent / 1024,
            reserved / 1024
        ),
        None => format!("memory: {allocator}; huge pages not reported by this system"),
    }
}
