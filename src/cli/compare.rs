//! `mipray compare`: every LOD method on the same frames, time against error from a
//! supersampled reference (see `crate::compare`).

// The options' doc comments are the command's `--help` text, where `<scene>` is a
// placeholder the user reads, not an HTML tag.
#![allow(rustdoc::invalid_html_tags)]

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use super::args::{
    LightsSpec, MAX_SPP, SequenceArgs, TraceArgs, View, parse_lights, render_settings, usage,
};
use super::bench::MAX_REPEATS;
use super::progress::progress_bar;
use super::scene::{load_scene, open_scene};
use crate::compare::{CompareOptions, MethodSpec, report, run_compare, subpixel_table};

#[derive(Args, Debug, Clone)]
pub struct CompareArgs {
    /// The scene, frames (default: the animation's length) and size.
    #[command(flatten)]
    pub sequence: SequenceArgs,
    #[command(flatten)]
    pub trace: TraceArgs,
    /// LOD methods, comma separated (`none` is always included: overheads are against it);
    /// `METHOD@N` renders the method with N samples per pixel (`none@4,none@16`), so
    /// supersampling sits on the same time-error chart as the LOD methods.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "none,paper,paper-cos,cones,diffs,diffs-aniso,diffs-ewa"
    )]
    pub methods: Vec<MethodSpec>,
    /// `N` lights for every render, or a range `A..B` (inclusive: `1..6` is 1 to 6 lights)
    /// for the paper's Table 1, none vs paper per light count; the method comparison then
    /// uses the scene's own lights [default: the scene's lights].
    #[arg(long)]
    pub lights: Option<String>,
    /// Output folder for compare.csv, compare.md and the plots [default: out/<scene>/compare/].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Samples per pixel of the level-0 reference (a square number: 64 = 8x8 stratified).
    #[arg(long, default_value_t = 64)]
    pub reference_spp: u32,
    /// Timed renders per method and frame (the median counts).
    #[arg(long, default_value_t = 3)]
    pub repeats: u32,
    /// Also write the reference's and every method's frames (OUT/frames/<method>/).
    #[arg(long)]
    pub save_frames: bool,
    /// `lod`: also write every method's false-colour level images (OUT/lod/<method>/).
    #[arg(long, value_enum)]
    pub view: Option<View>,
}

/// Creates `out` (and its parents), or says why it cannot be the output folder.
fn prepare_out_folder(out: &std::path::Path) -> Result<()> {
    if out.exists() && !out.is_dir() {
        anyhow::bail!(
            "{}: exists and is not a folder (the output must be a folder)",
            out.display()
        );
    }
    std::fs::create_dir_all(out).map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))
}

/// `mipray compare`.
pub fn compare(args: &CompareArgs) -> Result<()> {
    let lights = args.lights.as_deref().map(parse_lights).transpose()?;
    let light_count = match lights {
        Some(LightsSpec::Count(n)) => Some(n),
        _ => None,
    };
    let mut settings = render_settings(&args.sequence, &args.trace, light_count, 1)?;
    if args.reference_spp == 0 || args.reference_spp > MAX_SPP {
        return Err(usage(format!(
            "--reference-spp {}: must be 1 to {MAX_SPP}",
            args.reference_spp
        )));
    }
    if args.repeats == 0 || args.repeats as usize > MAX_REPEATS {
        return Err(usage(format!(
            "--repeats {}: must be 1 to {MAX_REPEATS}",
            args.repeats
        )));
    }
    let scene = open_scene(&args.sequence)?;
    settings.animation = scene.animation;
    let (path, frames) = (scene.path, scene.frames);
    drop(scene.desc); // every method loads its own copy
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&scene.name).join("compare"));
    // The folder is made before the renders, which take minutes: a path that cannot be a
    // folder fails now, not after them.
    prepare_out_folder(&out)?;
    let options = CompareOptions {
        scene_name: scene.name,
        settings,
        frames: frames.clone(),
        clock: scene.clock,
        methods: args.methods.clone(),
        reference_spp: args.reference_spp,
        repeats: args.repeats,
        table1_lights: match lights {
            Some(LightsSpec::Range(a, b)) => (a..=b).collect(),
            _ => Vec::new(),
        },
        frames_dir: args.save_frames.then(|| out.join("frames")),
        lod_view_dir: (args.view == Some(View::Lod)).then(|| out.join("lod")),
    };
    eprintln!(
        "compare: {} frames {}..{} at {}x{}, reference {} spp, {} repeat(s), methods {}",
        path.display(),
        frames.start,
        frames.end,
        settings.width,
        settings.height,
        args.reference_spp,
        args.repeats,
        args.methods
            .iter()
            .map(|m| m.to_string())
            .collect::<Vec<_>>()
            .join(",")
    );
    let progress = progress_bar(frames.len() as u64);
    let log = |line: &str| {
        progress.suspend(|| eprintln!("{line}"));
        if line.starts_with("frame") {
            progress.inc(1);
        }
    };
    let results = run_compare(|| load_scene(&path), &options, &log)?;
    progress.finish_and_clear();
    let report = &results.report;
    // compare.md carries both references: the probe's table, then the sub-pixel one.
    let subpixel = subpixel_table::markdown(&results.subpixel);
    let mut written = report::write_all(report, &subpixel, &out)?;
    written.push(subpixel_table::write_csv(&results.subpixel, &out)?);
    written.push(crate::pages::write_compare_page(&out)?);
    print!("{}", report::markdown_with(report, &subpixel));
    println!();
    for path in written {
        println!("wrote {}", path.display());
    }
    Ok(())
}
