//! The command line: argument structs (shared flag groups in `args`, flattened once where
//! used), one file per command, and the dispatch. No arguments = render the default
//! animation. The frame loop itself is in `crate::frame`, a whole sequence in `crate::run`;
//! this module turns arguments into settings, calls them, and prints what they report (the
//! only module that prints, with `main.rs`).

mod args;
mod bench;
mod compare;
mod diff;
mod examples;
mod export;
mod info;
mod progress;
mod render;
mod scene;
mod shell;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

pub use args::{
    LightArgs, LightsSpec, SequenceArgs, TraceArgs, UsageError, View, parse_frames, parse_lights,
    parse_size,
};
pub use bench::BenchArgs;
pub use compare::CompareArgs;
pub use diff::{CheckArgs, DiffArgs};
pub use export::ExportArgs;
pub use info::{InfoArgs, TriangleMotion, describe};
pub use render::{BvhMode, RenderArgs, resolve_shard};
pub use scene::{OpenedScene, load_scene, open_scene, resolve_scene};
pub use shell::{CompletionsArgs, ManArgs, man_page};

#[derive(Parser, Debug)]
#[command(
    name = "mipray",
    version,
    about = "Ray-traced animations with ray-length MIP-map level selection",
    after_help = examples::MIPRAY
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render an animation to an image sequence with per-frame stats.
    #[command(after_help = examples::RENDER)]
    Render(RenderArgs),
    /// Time LOD methods and thread counts side by side (interleaved, repeated, median).
    #[command(after_help = examples::BENCH)]
    Bench(BenchArgs),
    /// Per-phase statistics and an SVG plot of rendered sequences (shards merged).
    #[command(after_help = examples::REPORT)]
    Report(ReportArgs),
    /// Compare a rendered sequence with a reference sequence, frame by frame.
    #[command(after_help = examples::DIFF)]
    Diff(DiffArgs),
    /// Every LOD method on the same frames: time (interleaved) against error from a
    /// supersampled level-0 reference; optionally the paper's Table 1 (`--lights 1..6`).
    #[command(after_help = examples::COMPARE)]
    Compare(CompareArgs),
    /// Write each frame's world-space triangles (OBJ or PLY), camera and lights.
    #[command(after_help = examples::EXPORT)]
    Export(ExportArgs),
    /// Print what a scene contains.
    #[command(after_help = examples::INFO)]
    Info(InfoArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell) to stdout.
    #[command(after_help = examples::COMPLETIONS)]
    Completions(shell::CompletionsArgs),
    /// Print the man page (roff) of mipray or of one of its commands to stdout.
    #[command(after_help = examples::MAN)]
    Man(shell::ManArgs),
}

#[derive(clap::Args, Debug, Clone)]
pub struct ReportArgs {
    /// Output folders (or stats files) of one sequence.
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Where to write the plot [default: report.svg in the first folder].
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// The frames the sequence must have (`A..B`, as `render --frames`): after the report,
    /// fail, naming them, when one has no record or no frame file, or a damaged one, or
    /// when the records came from different renders (a farm's merge step).
    #[arg(long, value_name = "A..B")]
    pub expect_frames: Option<String>,
}

/// `RAYON_NUM_THREADS` sizes the worker pool where `--threads` is not given (rayon reads it);
/// a count the system would take minutes to start is refused as `--threads` is.
fn check_rayon_threads() -> Result<()> {
    let Ok(value) = std::env::var("RAYON_NUM_THREADS") else {
        return Ok(());
    };
    match value.trim().parse::<usize>() {
        Ok(n) if n > args::MAX_THREADS => Err(args::usage(format!(
            "RAYON_NUM_THREADS={value}: at most {} worker threads",
            args::MAX_THREADS
        ))),
        _ => Ok(()),
    }
}

/// `MIPRAY_SIMD` chooses the copy of the hot loops; a value it does not know is refused
/// rather than silently running the default copy.
fn check_simd_override() -> Result<()> {
    crate::simd::simd_override().map(|_| ()).map_err(|value| {
        args::usage(format!(
            "MIPRAY_SIMD={value}: expected auto, baseline or avx2"
        ))
    })
}

/// Runs the parsed command line. `Ok(FAILURE)` means a regression check found frames outside
/// the threshold; errors are bad input (see `main.rs` for the exit codes).
pub fn run(cli: Cli) -> Result<ExitCode> {
    check_rayon_threads()?;
    check_simd_override()?;
    let ok = |()| ExitCode::SUCCESS;
    match cli.command {
        None => render::render(&RenderArgs::default()),
        Some(Command::Render(args)) => render::render(&args),
        Some(Command::Bench(args)) => bench::bench(&args).map(ok),
        Some(Command::Diff(args)) => diff::diff(&args),
        Some(Command::Compare(args)) => compare::compare(&args).map(ok),
        Some(Command::Export(args)) => export::export(&args).map(ok),
        Some(Command::Report(args)) => report(&args).map(ok),
        Some(Command::Info(args)) => info::info(&args).map(ok),
        Some(Command::Completions(args)) => shell::completions(&args).map(ok),
        Some(Command::Man(args)) => shell::man(&args).map(ok),
    }
}

/// `mipray report`: merges the records of the folders, prints the table, writes the plot;
/// then, with `--expect-frames`, fails when a frame of that range is missing.
fn report(args: &ReportArgs) -> Result<()> {
    let expected = args
        .expect_frames
        .as_deref()
        .map(parse_frames)
        .transpose()
        .context(args::UsageError("--expect-frames".into()))?;
    let svg = args.svg.clone().unwrap_or_else(|| {
        let first = &args.dirs[0];
        let folder = if first.is_dir() {
            first.clone()
        } else {
            first.parent().map(Path::to_path_buf).unwrap_or_default()
        };
        folder.join("report.svg")
    });
    // The temporaries an interrupted `mipray report` left for the files it writes here.
    let page_dir = svg.parent().unwrap_or(Path::new("."));
    let svg_name = svg.file_name().map(|n| n.to_string_lossy().into_owned());
    crate::atomic_file::remove_stale_temporaries(
        if page_dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            page_dir
        },
        Some(crate::atomic_file::REPORT_OWNER),
        |target| Some(target) == svg_name.as_deref() || target == crate::pages::PAGE_NAME,
    );
    let summary = crate::report::report(&args.dirs, &svg)?;
    print!("{summary}");
    if let Some(mixed) = &summary.mixed_runs {
        // Without --expect-frames the statistics are still worth a look; a completeness
        // claim fails on it below.
        eprintln!("warning: {mixed}");
    }
    let page = crate::pages::write_render_page(
        &args.dirs,
        page_dir,
        Some(&svg),
        Some(crate::atomic_file::REPORT_OWNER),
    )?;
    println!("page: {}", page.display());
    if let Some(expected) = expected {
        let sequence = crate::record::load_sequence(&args.dirs)?;
        let folders = crate::report::frame_folders(&args.dirs);
        crate::report::require_frames(&sequence, &folders, expected.clone())?;
        println!(
            "complete: every frame of {}..{} has its record and frame file",
            expected.start, expected.end
        );
    }
    Ok(())
}
