//! `mipray bench`: LOD methods and thread counts timed side by side (see `crate::bench`).

use anyhow::{Result, bail};
use clap::Args;

use super::args::{LightArgs, SequenceArgs, TraceArgs, render_settings};
use super::scene::{load_scene, open_scene};
use crate::bench::{BenchConfig, bench_table, run_bench};
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
    /// Thread counts, comma separated [default: 1 and all cores].
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// How many times every configuration renders the frames.
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
}

/// `mipray bench`.
pub fn bench(args: &BenchArgs) -> Result<()> {
    let mut settings = render_settings(&args.sequence, &args.trace, args.lights.lights, args.spp)?;
    if args.repeats == 0 || args.repeats > MAX_REPEATS || args.methods.is_empty() {
        bail!("bench needs 1 to {MAX_REPEATS} repeats and at least one method");
    }
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
    if threads.contains(&0) {
        bail!("--threads: counts must be at least 1");
    }
    let configs: Vec<BenchConfig> = threads
        .iter()
        .flat_map(|&t| {
            args.methods
                .iter()
                .map(move |&lod| BenchConfig { lod, threads: t })
        })
        .collect();
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
    let results = run_bench(
        || load_scene(&path),
        settings,
        frames,
        clock,
        &configs,
        args.repeats,
    )?;
    print!("{}", bench_table(&results));
    Ok(())
}
