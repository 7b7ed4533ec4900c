//! The command line: `mipray render`, `mipray info`, and no arguments = render the default
//! animation. Parses options into `RenderSettings`, then runs the frame loop.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use std::process::ExitCode;

use crate::anim::{AnimationSelection, select_animation};
use crate::diff::{
    DiffMetric, DiffOptions, DiffReport, compare_stats, diff_dirs, diff_frame, junit_xml,
};
use crate::frame::{BvhPolicy, FrameClock, FrameRecord, RenderSettings, Renderer};
use crate::lod::LodMethod;
use crate::output::{FrameFormat, OutputDir, Shard};
use crate::scene::SceneDesc;

#[derive(Parser, Debug)]
#[command(
    name = "mipray",
    version,
    about = "Ray-traced animations with ray-length MIP-map level selection"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render an animation to an image sequence with per-frame stats.
    Render(RenderArgs),
    /// Time LOD methods and thread counts side by side (interleaved, repeated, median).
    Bench(BenchArgs),
    /// Per-phase statistics and an SVG plot of rendered sequences (shards merged).
    Report {
        /// Output folders (or stats files) of one sequence.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Where to write the plot [default: report.svg in the first folder].
        #[arg(long)]
        svg: Option<PathBuf>,
    },
    /// Compare a rendered sequence with a reference sequence, frame by frame.
    Diff(DiffArgs),
    /// Every LOD method on the same frames: time (interleaved) against error from a
    /// supersampled level-0 reference; optionally the paper's Table 1 (`--lights 1..6`).
    Compare(CompareArgs),
    /// Write each frame's world-space triangles (OBJ or PLY), camera and lights.
    Export(ExportArgs),
    /// Print what a scene contains.
    Info {
        /// A .gltf/.glb path, or the name of a scene in animations/ (e.g. `default`).
        scene: String,
    },
}

/// Which scene, which frames, at what size: shared by render, bench and export.
#[derive(Args, Debug, Clone)]
pub struct SequenceArgs {
    /// A .gltf/.glb, .aff or .obj path, or the name of a scene in animations/ (e.g. `default`).
    #[arg(default_value = "default")]
    pub scene: String,
    /// Half-open frame range `A..B` (or a single frame `A`) [default: the animation's length].
    #[arg(long)]
    pub frames: Option<String>,
    /// Frames per second: frame i is at time i / fps [default: 30, or the scene's own frame
    /// times when it has them (AFF `a`)].
    #[arg(long)]
    pub fps: Option<f64>,
    /// Image size `WxH` (also sets the camera's aspect and the LOD footprint).
    #[arg(long, default_value = "640x360")]
    pub size: String,
}

#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    #[command(flatten)]
    pub sequence: SequenceArgs,
    /// Output folder [default: out/<scene>/<lod>/].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Texture LOD selection method.
    #[arg(long, default_value = "paper")]
    pub lod: LodMethod,
    /// Levels added to every MIP-mapped lookup (positive: blurrier); `none` ignores it.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub lod_bias: f32,
    /// Number of lights: the scene's first N, plus point lights around the scene if it has fewer
    /// [default: all of the scene's lights, at least 1].
    #[arg(long)]
    pub lights: Option<usize>,
    /// Samples per pixel (stratified; a square number fills the strata grid exactly).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Maximum reflection/refraction depth.
    #[arg(long, default_value_t = 5)]
    pub max_depth: u32,
    /// Worker threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Frame file format.
    #[arg(long, value_enum, default_value_t = FrameFormat::Png)]
    pub format: FrameFormat,
    /// BVH update: `refit` every frame (rebuild past --rebuild-threshold) or `rebuild`
    /// every frame (for comparison).
    #[arg(long, value_enum, default_value_t = BvhMode::Refit)]
    pub bvh: BvhMode,
    /// Rebuild when the refitted tree's SAH cost exceeds this multiple of its cost right
    /// after the last build.
    #[arg(long, default_value_t = BvhPolicy::DEFAULT_REBUILD_THRESHOLD)]
    pub rebuild_threshold: f32,
    /// Render only shard I of N (a contiguous block of the frames); default: from Slurm or
    /// Kubernetes Indexed Job variables when set (see README).
    #[arg(long)]
    pub shard: Option<String>,
    /// Skip frames already complete in the output folder.
    #[arg(long)]
    pub resume: bool,
    /// Play one animation clip (its name or index) instead of all clips together.
    #[arg(long)]
    pub animation: Option<String>,
    /// Compare each frame as it finishes with the same frame in this reference folder
    /// (results in OUT/check/).
    #[arg(long)]
    pub check: Option<PathBuf>,
    /// With --check: stop at the first frame outside the threshold.
    #[arg(long, requires = "check")]
    pub fail_fast: bool,
    /// `lod`: also write a false-colour image of each pixel's MIP level beside each frame
    /// (`lod_NNNN.png`; colours in README).
    #[arg(long, value_enum)]
    pub view: Option<View>,
    #[command(flatten)]
    pub check_args: CheckArgs,
}

/// `mipray export` options (render's defaults: 640x360, 30 fps).
#[derive(Args, Debug, Clone)]
pub struct ExportArgs {
    #[command(flatten)]
    pub sequence: SequenceArgs,
    /// Mesh file format.
    #[arg(long, value_enum, default_value_t = crate::export::ExportFormat::Obj)]
    pub format: crate::export::ExportFormat,
    /// Output folder [default: out/<scene>/export/].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Play one animation clip (its name or index) instead of all clips together.
    #[arg(long)]
    pub animation: Option<String>,
    /// Number of lights, as for render.
    #[arg(long)]
    pub lights: Option<usize>,
}

/// How frames are judged against a reference (shared by `diff` and `render --check`).
#[derive(Args, Debug, Clone)]
pub struct CheckArgs {
    /// Metric that decides pass or fail.
    #[arg(long, value_enum, default_value_t = DiffMetric::Psnr)]
    pub metric: DiffMetric,
    /// Threshold for the metric [default: psnr 40 dB, flip 0.01, max-abs 0].
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Also write a JUnit XML report (one test case per frame).
    #[arg(long)]
    pub junit: Option<PathBuf>,
}

#[derive(Args, Debug, Clone)]
pub struct DiffArgs {
    /// The reference sequence's folder.
    pub reference: PathBuf,
    /// The sequence to check.
    pub test: PathBuf,
    #[command(flatten)]
    pub check: CheckArgs,
    /// Where diff.md, diff.csv and the failing frames' images go [default: TEST/diff].
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug, Clone)]
pub struct CompareArgs {
    /// The scene, frames (default: the animation's length) and size.
    #[command(flatten)]
    pub sequence: SequenceArgs,
    /// LOD methods, comma separated (`none` is always included: overheads are against it).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "none,paper,paper-cos,cones,diffs,diffs-aniso"
    )]
    pub methods: Vec<LodMethod>,
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
    /// Levels added to every method's MIP level.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub lod_bias: f32,
    #[arg(long, default_value_t = 5)]
    pub max_depth: u32,
    /// Play one animation clip (its name or index) instead of all clips together.
    #[arg(long)]
    pub animation: Option<String>,
    /// Also write the reference's and every method's frames (OUT/frames/<method>/).
    #[arg(long)]
    pub save_frames: bool,
    /// `lod`: also write every method's false-colour level images (OUT/lod/<method>/).
    #[arg(long, value_enum)]
    pub view: Option<View>,
}

/// Debug views written beside the frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum View {
    /// False-colour MIP level of each pixel's texture lookup.
    Lod,
}

/// `--lights` of compare: one count, or an inclusive range for Table 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LightsSpec {
    Count(usize),
    Range(usize, usize),
}

/// Parses `N`, `A..B` or `A..=B` (both inclusive) with 1 <= A <= B <= the light limit.
pub fn parse_lights(s: &str) -> Result<LightsSpec> {
    let number = |t: &str| -> Result<usize> {
        t.trim()
            .parse::<usize>()
            .with_context(|| format!("--lights {s}: '{t}' is not a whole number"))
    };
    let spec = match s.split_once("..") {
        None => LightsSpec::Count(number(s)?),
        Some((a, b)) => LightsSpec::Range(number(a)?, number(b.trim_start_matches('='))?),
    };
    let (lo, hi) = match spec {
        LightsSpec::Count(n) => (n, n),
        LightsSpec::Range(a, b) => (a, b),
    };
    if lo == 0 || lo > hi || hi > MAX_LIGHTS {
        bail!("--lights {s}: counts must satisfy 1 <= A <= B <= {MAX_LIGHTS}");
    }
    Ok(spec)
}

/// `--bvh` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BvhMode {
    Refit,
    Rebuild,
}

#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// The scene and frames rendered per repeat.
    #[command(flatten)]
    pub sequence: SequenceArgs,
    /// LOD methods, comma separated; ratios are against the first.
    #[arg(long, value_delimiter = ',', default_value = "none,paper")]
    pub methods: Vec<LodMethod>,
    /// Thread counts, comma separated [default: 1 and all cores].
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    #[arg(long)]
    pub lights: Option<usize>,
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    #[arg(long, default_value_t = 5)]
    pub max_depth: u32,
    /// How many times every configuration renders the frames.
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Levels added to every MIP-mapped lookup. `-16` pins every level to 0, so `paper`
    /// then costs its LOD selection without the second trilinear lookup.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub lod_bias: f32,
}

impl Default for RenderArgs {
    fn default() -> Self {
        match Cli::parse_from(["mipray", "render"]).command {
            Some(Command::Render(args)) => args,
            _ => unreachable!("`mipray render` parses to the render command"),
        }
    }
}

/// Upper bounds that keep a typo from allocating the machine away.
const MAX_PIXELS: u64 = 16384 * 16384;
const MAX_SPP: u32 = 65536;
const MAX_DEPTH: u32 = 64;
const MAX_LIGHTS: usize = 1024;

/// Runs the parsed command line.
/// Runs the parsed command line. `Ok(FAILURE)` means a regression check found frames outside
/// the threshold; errors are bad input (see `main.rs` for the exit codes).
pub fn run(cli: Cli) -> Result<ExitCode> {
    let ok = |()| ExitCode::SUCCESS;
    match cli.command {
        None => render(&RenderArgs::default()),
        Some(Command::Render(args)) => render(&args),
        Some(Command::Bench(args)) => bench(&args).map(ok),
        Some(Command::Diff(args)) => diff(&args),
        Some(Command::Compare(args)) => compare(&args).map(ok),
        Some(Command::Export(args)) => export(&args).map(ok),
        Some(Command::Report { dirs, svg }) => {
            let svg = svg.unwrap_or_else(|| {
                let first = &dirs[0];
                let folder = if first.is_dir() {
                    first.clone()
                } else {
                    first.parent().map(Path::to_path_buf).unwrap_or_default()
                };
                folder.join("report.svg")
            });
            let summary = crate::report::report(&dirs, &svg)?;
            print!("{summary}");
            println!(
                "page: {}",
                crate::pages::write_render_page(
                    &dirs,
                    svg.parent().unwrap_or(Path::new(".")),
                    Some(&svg)
                )?
                .display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Some(Command::Info { scene }) => {
            let path = resolve_scene(&scene)?;
            let desc = load_scene(&path)?;
            print!("{}", describe(&desc));
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// Finds a scene: an existing file path, or `NAME` in `animations/` (as `.gltf` or `.glb`),
/// looked up in the current folder and then in the crate's own `animations/`.
pub fn resolve_scene(scene: &str) -> Result<PathBuf> {
    let direct = PathBuf::from(scene);
    if direct.is_file() {
        return Ok(direct);
    }
    let folders = [
        PathBuf::from("animations"),
        Path::new(env!("CARGO_MANIFEST_DIR")).join("animations"),
    ];
    for folder in &folders {
        for ext in ["gltf", "glb"] {
            let candidate = folder.join(format!("{scene}.{ext}"));
            if candidate.is_file() {
                return Ok(candidate);
            }
        }
    }
    bail!(
        "{scene}: no such file, and no scene of that name in animations/ (looked in {})",
        folders
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )
}

/// Loads a scene file by its extension.
pub fn load_scene(path: &Path) -> Result<SceneDesc> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("gltf") | Some("glb") => Ok(crate::scene::gltf::load(path)?),
        Some("aff") => Ok(crate::scene::aff::load(path)?),
        Some("obj") => Ok(crate::scene::obj::load(path)?),
        _ => bail!(
            "{}: unsupported scene format (expected .gltf, .glb, .aff or .obj)",
            path.display()
        ),
    }
}

/// Parses `WxH`.
pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("--size {s}: expected WxH, e.g. 640x360"))?;
    let w: u32 = w
        .trim()
        .parse()
        .with_context(|| format!("--size {s}: bad width"))?;
    let h: u32 = h
        .trim()
        .parse()
        .with_context(|| format!("--size {s}: bad height"))?;
    if w == 0 || h == 0 || w as u64 * h as u64 > MAX_PIXELS {
        bail!(
            "--size {s}: width and height must be at least 1 and at most {MAX_PIXELS} pixels in all"
        );
    }
    Ok((w, h))
}

/// Parses a half-open frame range `A..B`, or a single frame `A`.
pub fn parse_frames(s: &str) -> Result<std::ops::Range<u32>> {
    let range = match s.split_once("..") {
        Some((a, b)) => {
            let a: u32 = a
                .trim()
                .parse()
                .with_context(|| format!("--frames {s}: bad start"))?;
            let b: u32 = b
                .trim()
                .parse()
                .with_context(|| format!("--frames {s}: bad end"))?;
            a..b
        }
        None => {
            let a: u32 = s
                .trim()
                .parse()
                .with_context(|| format!("--frames {s}: expected A..B or A"))?;
            a..a.saturating_add(1)
        }
    };
    if range.is_empty() {
        bail!("--frames {s}: empty range (the end is exclusive)");
    }
    Ok(range)
}

fn scene_name(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into())
}

fn validated_settings(args: &RenderArgs) -> Result<RenderSettings> {
    let (width, height) = parse_size(&args.sequence.size)?;
    if args.spp == 0 || args.spp > MAX_SPP {
        bail!("--spp {}: must be 1 to {MAX_SPP}", args.spp);
    }
    if args.max_depth > MAX_DEPTH {
        bail!("--max-depth {}: at most {MAX_DEPTH}", args.max_depth);
    }
    if args.lights.is_some_and(|n| n > MAX_LIGHTS) {
        bail!("--lights: at most {MAX_LIGHTS}");
    }
    if !(args.rebuild_threshold.is_finite() && args.rebuild_threshold >= 1.0) {
        bail!(
            "--rebuild-threshold {}: must be a number >= 1",
            args.rebuild_threshold
        );
    }
    if let Some(fps) = args.sequence.fps.filter(|f| !(f.is_finite() && *f > 0.0)) {
        bail!("--fps {fps}: must be a positive number");
    }
    check_lod_bias(args.lod_bias)?;
    Ok(RenderSettings {
        width,
        height,
        lod: args.lod,
        lod_bias: args.lod_bias,
        spp: args.spp,
        max_depth: args.max_depth,
        lights: args.lights,
        bvh: match args.bvh {
            BvhMode::Refit => BvhPolicy::Refit {
                rebuild_threshold: args.rebuild_threshold,
            },
            BvhMode::Rebuild => BvhPolicy::Rebuild,
        },
        animation: AnimationSelection::All,
    })
}

/// Largest `--lod-bias` magnitude accepted: past 16 levels every texture is at one end.
const MAX_LOD_BIAS: f32 = 16.0;

fn check_lod_bias(bias: f32) -> Result<()> {
    if !(bias.is_finite() && bias.abs() <= MAX_LOD_BIAS) {
        bail!("--lod-bias {bias}: must be a number from -{MAX_LOD_BIAS} to {MAX_LOD_BIAS}");
    }
    Ok(())
}

/// `mipray diff`.
pub fn diff(args: &DiffArgs) -> Result<ExitCode> {
    let options = DiffOptions {
        metric: args.check.metric,
        threshold: args
            .check
            .threshold
            .unwrap_or(args.check.metric.default_threshold()),
        out: args.out.clone().unwrap_or_else(|| args.test.join("diff")),
    };
    let report = diff_dirs(&args.reference, &args.test, &options)?;
    print!("{}", report.table());
    if let Some(note) = &report.stats_note {
        println!("stats not compared: {note}");
    }
    finish_report(&report, &options.out, args.check.junit.as_deref())
}

/// Writes diff.md / diff.csv (and JUnit), prints the verdict, and gives the exit code.
fn finish_report(report: &DiffReport, out: &Path, junit: Option<&Path>) -> Result<ExitCode> {
    report
        .write(out)
        .with_context(|| format!("{}: cannot write the diff report", out.display()))?;
    if let Some(path) = junit {
        crate::output::write_text_atomically(path, &junit_xml(report))
            .with_context(|| format!("{}: cannot write JUnit XML", path.display()))?;
    }
    println!("{}", report.verdict());
    println!("report: {}", out.join("diff.md").display());
    println!(
        "page: {}",
        crate::pages::write_diff_page(
            out,
            report.metric.name(),
            report.threshold,
            &report.verdict()
        )?
        .display()
    );
    Ok(if report.failed() == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// `mipray render`.
pub fn render(args: &RenderArgs) -> Result<ExitCode> {
    let settings = validated_settings(args)?;
    let path = resolve_scene(&args.sequence.scene)?;
    let scene = load_scene(&path)?;
    for note in &scene.notes {
        eprintln!("note: {}: {note}", path.display());
    }
    let mut settings = settings;
    if let Some(spec) = &args.animation {
        settings.animation = select_animation(&scene, spec)
            .map_err(|e| anyhow::anyhow!("{}: --animation {spec}: {e}", path.display()))?;
    }
    let clock = FrameClock::for_scene(&scene, args.sequence.fps);
    let frames = match &args.sequence.frames {
        Some(f) => parse_frames(f)?,
        None => clock.default_frames(settings.animation.duration(&scene)),
    };
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("out")
            .join(scene_name(&path))
            .join(args.lod.to_string())
    });
    let mut threads = rayon::ThreadPoolBuilder::new();
    if let Some(n) = args.threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        threads = threads.num_threads(n);
    }
    let pool = threads.build().context("cannot start worker threads")?;
    let output = SequenceOutput {
        dir: out,
        format: args.format,
        shard: resolve_shard(args.shard.as_deref(), |name| std::env::var(name).ok())?,
        resume: args.resume,
        lod_view: args.view == Some(View::Lod),
    };
    let check = args.check.as_ref().map(|reference| Check {
        reference: reference.clone(),
        options: DiffOptions {
            metric: args.check_args.metric,
            threshold: args
                .check_args
                .threshold
                .unwrap_or(args.check_args.metric.default_threshold()),
            out: output.dir.join("check"),
        },
        fail_fast: args.fail_fast,
        junit: args.check_args.junit.clone(),
    });
    let mut renderer = Renderer::new(scene, settings);
    pool.install(|| render_sequence(&mut renderer, frames, clock, &output, check.as_ref()))
}

/// `mipray export`: prepares each frame with render's settings and writes its triangles,
/// camera and lights (see `export`).
pub fn export(args: &ExportArgs) -> Result<()> {
    let render_args = RenderArgs {
        sequence: args.sequence.clone(),
        lights: args.lights,
        ..RenderArgs::default()
    };
    let mut settings = validated_settings(&render_args)?;
    let path = resolve_scene(&args.sequence.scene)?;
    let scene = load_scene(&path)?;
    if let Some(spec) = &args.animation {
        settings.animation = select_animation(&scene, spec)
            .map_err(|e| anyhow::anyhow!("{}: --animation {spec}: {e}", path.display()))?;
    }
    let clock = FrameClock::for_scene(&scene, args.sequence.fps);
    let frames = match &args.sequence.frames {
        Some(f) => parse_frames(f)?,
        None => clock.default_frames(settings.animation.duration(&scene)),
    };
    let options = crate::export::ExportOptions {
        format: args.format,
        dir: args
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from("out").join(scene_name(&path)).join("export")),
        frames,
        clock,
    };
    let mut renderer = Renderer::new(scene, settings);
    let done = crate::export::export_frames(&mut renderer, &options, |f| {
        println!(
            "frame {:04}  t={:.3}s  {} triangles  {} deformed  -> {}",
            f.frame,
            f.time_s,
            f.triangles,
            f.deformed,
            f.mesh.display()
        );
    })?;
    println!(
        "exported {} frame(s) into {}",
        done.len(),
        options.dir.display()
    );
    Ok(())
}

/// `render --check`: judge each frame against a reference as soon as it is written.
#[derive(Debug, Clone)]
pub struct Check {
    pub reference: PathBuf,
    pub options: DiffOptions,
    pub fail_fast: bool,
    pub junit: Option<PathBuf>,
}

/// `mipray bench`.
pub fn bench(args: &BenchArgs) -> Result<()> {
    let render_args = RenderArgs {
        sequence: args.sequence.clone(),
        lights: args.lights,
        spp: args.spp,
        max_depth: args.max_depth,
        lod_bias: args.lod_bias,
        ..RenderArgs::default()
    };
    let settings = validated_settings(&render_args)?;
    if args.repeats == 0 || args.methods.is_empty() {
        bail!("bench needs at least one repeat and one method");
    }
    let path = resolve_scene(&args.sequence.scene)?;
    let scene = load_scene(&path)?;
    let clock = FrameClock::for_scene(&scene, args.sequence.fps);
    let frames = match &args.sequence.frames {
        Some(f) => parse_frames(f)?,
        None => clock.default_frames(scene.duration()),
    };
    drop(scene);
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
    let configs: Vec<crate::bench::BenchConfig> = threads
        .iter()
        .flat_map(|&t| {
            args.methods
                .iter()
                .map(move |&lod| crate::bench::BenchConfig { lod, threads: t })
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
    let results = crate::bench::run_bench(
        || load_scene(&path),
        settings,
        frames,
        clock,
        &configs,
        args.repeats,
    )?;
    print!("{}", crate::bench::bench_table(&results));
    Ok(())
}

/// `mipray compare`.
pub fn compare(args: &CompareArgs) -> Result<()> {
    let lights = args.lights.as_deref().map(parse_lights).transpose()?;
    let render_args = RenderArgs {
        sequence: args.sequence.clone(),
        lights: match lights {
            Some(LightsSpec::Count(n)) => Some(n),
            _ => None,
        },
        max_depth: args.max_depth,
        lod_bias: args.lod_bias,
        ..RenderArgs::default()
    };
    let mut settings = validated_settings(&render_args)?;
    if args.reference_spp == 0 || args.reference_spp > MAX_SPP {
        bail!(
            "--reference-spp {}: must be 1 to {MAX_SPP}",
            args.reference_spp
        );
    }
    if args.repeats == 0 || args.repeats > 1000 {
        bail!("--repeats {}: must be 1 to 1000", args.repeats);
    }
    let path = resolve_scene(&args.sequence.scene)?;
    let scene = load_scene(&path)?;
    for note in &scene.notes {
        eprintln!("note: {}: {note}", path.display());
    }
    if let Some(spec) = &args.animation {
        settings.animation = select_animation(&scene, spec)
            .map_err(|e| anyhow::anyhow!("{}: --animation {spec}: {e}", path.display()))?;
    }
    let clock = FrameClock::for_scene(&scene, args.sequence.fps);
    let frames = match &args.sequence.frames {
        Some(f) => parse_frames(f)?,
        None => clock.default_frames(settings.animation.duration(&scene)),
    };
    drop(scene);
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(scene_name(&path)).join("compare"));
    let options = crate::compare::CompareOptions {
        scene_name: scene_name(&path),
        settings,
        frames: frames.clone().collect(),
        clock,
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
            .map(|m| m.as_str())
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
    let report = crate::compare::run_compare(|| load_scene(&path), &options, &log)?;
    progress.finish_and_clear();
    let mut written = crate::compare::report::write_all(&report, &out)?;
    written.push(crate::pages::write_compare_page(&out)?);
    print!("{}", crate::compare::report::markdown(&report));
    println!();
    for path in written {
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// Where and how a sequence is written.
#[derive(Debug, Clone)]
pub struct SequenceOutput {
    pub dir: PathBuf,
    pub format: FrameFormat,
    pub shard: Option<Shard>,
    /// Skip frames already complete on disk (frame file and stats record).
    pub resume: bool,
    /// Write `lod_NNNN.png` level images beside the frames (`--view lod`).
    pub lod_view: bool,
}

/// Renders `frames` (this shard's part of them) into the output folder, one record per
/// frame, then the summary.
pub fn render_sequence(
    renderer: &mut Renderer,
    frames: std::ops::Range<u32>,
    clock: FrameClock,
    out: &SequenceOutput,
    check: Option<&Check>,
) -> Result<ExitCode> {
    let frames = match out.shard {
        Some(shard) => shard.frames(frames),
        None => frames,
    };
    let (mut output, previous) = OutputDir::open(&out.dir, out.format, out.shard, out.resume)?;
    // A frame is complete when its file exists and its record was written after it.
    let mut records: Vec<FrameRecord> = previous
        .into_iter()
        .filter(|r| frames.contains(&r.frame) && output.frame_path(r.frame).is_file())
        .collect();
    let done: std::collections::BTreeSet<u32> = records.iter().map(|r| r.frame).collect();
    if !done.is_empty() {
        println!(
            "resuming: {} of {} frame(s) already complete",
            done.len(),
            frames.len()
        );
    }
    let todo: Vec<u32> = frames.clone().filter(|f| !done.contains(f)).collect();
    let mut checked: Vec<crate::diff::FrameDiff> = Vec::new();
    let progress = progress_bar(todo.len() as u64);
    let start = Instant::now();
    for frame in todo {
        let time_s = clock.time(frame);
        let (image, record, view) = renderer.render_frame_with_view(frame, time_s, out.lod_view)?;
        let path = output.write_frame(frame, &image)?;
        if let Some(view) = view {
            let view_path = output.path().join(format!("lod_{frame:04}.png"));
            crate::output::write_rgb8_atomically(&view_path, &view)
                .with_context(|| format!("cannot write {}", view_path.display()))?;
        }
        output.append_record(&record)?;
        let line = format!(
            "frame {frame:04}  t={time_s:.3}s  {:>8.1} ms  {:>6.2} Mrays  moved {:>7}  lod_recomputed {:>7}{}  -> {}",
            record.total_ms,
            record.rays as f64 / 1e6,
            record.update.moved_triangles,
            record.update.lod_recomputed,
            if record.update.rebuild {
                "  rebuild"
            } else {
                ""
            },
            path.display()
        );
        progress.suspend(|| println!("{line}"));
        progress.inc(1);
        records.push(record);
        if let Some(check) = check {
            let name = crate::output::frame_file_name(frame, out.format);
            let judged = diff_frame(frame, &check.reference.join(&name), &path, &check.options)?;
            let verdict = format!(
                "check frame {frame:04}: {}  psnr {} dB  flip {:.5}  max abs {}",
                if judged.passed { "pass" } else { "FAIL" },
                crate::metrics::format_psnr(judged.metrics.psnr_db),
                judged.metrics.mean_flip,
                judged.metrics.max_abs
            );
            progress.suspend(|| println!("{verdict}"));
            let stop = !judged.passed && check.fail_fast;
            checked.push(judged);
            if stop {
                progress.suspend(|| println!("--fail-fast: stopping at frame {frame}"));
                break;
            }
        }
    }
    progress.finish_and_clear();
    records.sort_by_key(|r| r.frame);
    let summary = output.write_summary(&records)?;
    println!(
        "rendered {} frame(s) {}..{} in {:.1} s into {} ({})",
        records.len(),
        frames.start,
        frames.end,
        start.elapsed().as_secs_f64(),
        output.path().display(),
        summary
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    println!(
        "page: {}",
        crate::pages::write_render_page(std::slice::from_ref(&out.dir), &out.dir, None)?.display()
    );
    match check {
        None => Ok(ExitCode::SUCCESS),
        Some(check) => {
            let mut report = DiffReport {
                reference_dir: check.reference.clone(),
                test_dir: out.dir.clone(),
                metric: check.options.metric,
                threshold: check.options.threshold,
                frames: checked,
                stats_note: None,
            };
            report.stats_note = compare_stats(&check.reference, &out.dir, &mut report.frames).err();
            finish_report(&report, &check.options.out, check.junit.as_deref())
        }
    }
}

/// The shard to render: `--shard I/N`, else a Slurm job array (`SLURM_ARRAY_TASK_ID`,
/// minus `SLURM_ARRAY_TASK_MIN` when set, of `SLURM_ARRAY_TASK_COUNT`), else a Kubernetes
/// Indexed Job (`JOB_COMPLETION_INDEX` of `MIPRAY_SHARD_COUNT`, which the Job sets to its
/// `completions`), else none.
pub fn resolve_shard(
    arg: Option<&str>,
    env: impl Fn(&str) -> Option<String>,
) -> Result<Option<Shard>> {
    let parse = |name: &str, v: &str| -> Result<u32> {
        v.trim()
            .parse()
            .with_context(|| format!("{name}={v}: not a whole number"))
    };
    let (index, count) = if let Some(spec) = arg {
        let (i, n) = spec
            .split_once('/')
            .with_context(|| format!("--shard {spec}: expected I/N, e.g. 0/4"))?;
        (parse("--shard index", i)?, parse("--shard count", n)?)
    } else if let (Some(id), Some(count)) =
        (env("SLURM_ARRAY_TASK_ID"), env("SLURM_ARRAY_TASK_COUNT"))
    {
        let min = match env("SLURM_ARRAY_TASK_MIN") {
            Some(m) => parse("SLURM_ARRAY_TASK_MIN", &m)?,
            None => 0,
        };
        let id = parse("SLURM_ARRAY_TASK_ID", &id)?;
        (
            id.checked_sub(min)
                .context("SLURM_ARRAY_TASK_ID is below SLURM_ARRAY_TASK_MIN")?,
            parse("SLURM_ARRAY_TASK_COUNT", &count)?,
        )
    } else if let Some(index) = env("JOB_COMPLETION_INDEX") {
        let count = env("MIPRAY_SHARD_COUNT").context(
            "JOB_COMPLETION_INDEX is set but MIPRAY_SHARD_COUNT (the Job's completions) is not",
        )?;
        (
            parse("JOB_COMPLETION_INDEX", &index)?,
            parse("MIPRAY_SHARD_COUNT", &count)?,
        )
    } else {
        return Ok(None);
    };
    if count == 0 || index >= count {
        bail!("shard {index} of {count}: the index must be below the count");
    }
    Ok(Some(Shard { index, count }))
}

fn progress_bar(len: u64) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} {pos}/{len} frames  elapsed {elapsed}  eta {eta}")
    {
        bar.set_style(style);
    }
    bar
}

/// Drawn triangles by how they move (all clips playing).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct TriangleMotion {
    /// Under no animated node and not deforming.
    pub fixed: usize,
    /// Placed by a node that is animated or has an animated ancestor (rigid or scaled).
    pub animated: usize,
    /// Skinned or with morph targets.
    pub deforming: usize,
    /// Nodes targeted by a translation/rotation/scale channel.
    pub animated_nodes: usize,
}

impl TriangleMotion {
    pub fn of(scene: &SceneDesc) -> TriangleMotion {
        use crate::scene::ChannelTarget;
        let mut targeted = vec![false; scene.nodes.len()];
        for c in scene.animations.iter().flat_map(|a| &a.channels) {
            if c.target != ChannelTarget::Weights && c.node < targeted.len() {
                targeted[c.node] = true;
            }
        }
        let mut out = TriangleMotion {
            animated_nodes: targeted.iter().filter(|&&t| t).count(),
            ..Default::default()
        };
        let mut stack: Vec<(usize, bool)> = scene.roots.iter().map(|&r| (r, false)).collect();
        while let Some((i, parent_animated)) = stack.pop() {
            let node = &scene.nodes[i];
            let animated = parent_animated || targeted[i];
            if let Some(mesh) = node.mesh {
                for (p, primitive) in scene.meshes[mesh].primitives.iter().enumerate() {
                    let n = primitive.triangle_count();
                    if crate::anim::primitive_deforms(scene, i, mesh, p) {
                        out.deforming += n;
                    } else if animated {
                        out.animated += n;
                    } else {
                        out.fixed += n;
                    }
                }
            }
            stack.extend(node.children.iter().map(|&c| (c, animated)));
        }
        out
    }
}

/// The text `mipray info` prints.
pub fn describe(scene: &SceneDesc) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let primitives: usize = scene.meshes.iter().map(|m| m.primitives.len()).sum();
    let _ = writeln!(s, "scene: {}", scene.source.display());
    let motion = TriangleMotion::of(scene);
    let _ = writeln!(
        s,
        "triangles: {} ({} static, {} moved by animated nodes, {} skinned or morphing)",
        scene.instanced_triangle_count(),
        motion.fixed,
        motion.animated,
        motion.deforming
    );
    let _ = writeln!(
        s,
        "meshes: {} ({primitives} primitives)",
        scene.meshes.len()
    );
    let tracks: usize = scene.animations.iter().map(|a| a.channels.len()).sum();
    let _ = writeln!(
        s,
        "nodes: {} ({} animated, {tracks} key tracks)",
        scene.nodes.len(),
        motion.animated_nodes
    );
    let _ = writeln!(s, "materials: {}", scene.materials.len());
    let _ = writeln!(s, "textures: {}", scene.textures.len());
    for t in &scene.textures {
        let (w, h) = t.pyramid.base_size();
        let _ = writeln!(
            s,
            "  {}: {w}x{h}, {} MIP levels, wrap {:?}/{:?}",
            t.name,
            t.pyramid.level_count(),
            t.sampler.wrap_s,
            t.sampler.wrap_t
        );
    }
    let clock = FrameClock::for_scene(scene, None);
    let frames = clock.default_frames(scene.duration());
    let (first, last) = (
        clock.time(frames.start),
        clock.time(frames.end.saturating_sub(1)),
    );
    let source = if scene.frame_times.is_some() {
        "the file's frame times"
    } else {
        "30 fps"
    };
    let _ = writeln!(
        s,
        "frames: {}..{} ({} frames, t = {first:.3} to {last:.3} s, {source})",
        frames.start,
        frames.end,
        frames.len()
    );
    let _ = writeln!(s, "animations: {}", scene.animations.len());
    for (i, a) in scene.animations.iter().enumerate() {
        let name = if a.name.is_empty() {
            format!("#{i}")
        } else {
            a.name.clone()
        };
        let _ = writeln!(
            s,
            "  {name}: {:.3} s, {} channels",
            a.duration(),
            a.channels.len()
        );
    }
    let _ = writeln!(s, "cameras: {}", scene.cameras.len());
    for c in &scene.cameras {
        let _ = writeln!(s, "  perspective, yfov {:.2} deg", c.yfov.to_degrees());
    }
    let _ = writeln!(s, "lights: {}", scene.lights.len());
    for l in &scene.lights {
        let _ = writeln!(
            s,
            "  {:?}, intensity {}, colour {:?}",
            l.kind,
            l.intensity,
            l.color.to_array()
        );
    }
    for note in &scene.notes {
        let _ = writeln!(s, "note: {note}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_sizes_and_ranges() {
        assert_eq!(parse_size("640x360").unwrap(), (640, 360));
        assert!(parse_size("0x10").is_err());
        assert!(parse_size("100000x100000").is_err());
        assert!(parse_size("abc").is_err());
        assert_eq!(parse_frames("3..7").unwrap(), 3..7);
        assert_eq!(parse_frames("5").unwrap(), 5..6);
        assert!(parse_frames("7..3").is_err());
        assert!(parse_frames("x..3").is_err());
    }

    #[test]
    fn shards_come_from_flag_slurm_or_kubernetes() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                vars.iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| v.to_string())
            }
        };
        assert_eq!(
            resolve_shard(Some("1/4"), env(&[])).unwrap(),
            Some(Shard { index: 1, count: 4 })
        );
        assert_eq!(resolve_shard(None, env(&[])).unwrap(), None);
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_MIN", "5"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ]);
        assert_eq!(
            resolve_shard(None, slurm).unwrap(),
            Some(Shard { index: 2, count: 3 })
        );
        let k8s = env(&[("JOB_COMPLETION_INDEX", "0"), ("MIPRAY_SHARD_COUNT", "2")]);
        assert_eq!(
            resolve_shard(None, k8s).unwrap(),
            Some(Shard { index: 0, count: 2 })
        );
        assert!(resolve_shard(None, env(&[("JOB_COMPLETION_INDEX", "0")])).is_err());
        assert!(resolve_shard(Some("4/4"), env(&[])).is_err());
        assert!(resolve_shard(Some("x"), env(&[])).is_err());
        // The flag wins over the environment.
        assert_eq!(
            resolve_shard(Some("0/1"), env(&[("JOB_COMPLETION_INDEX", "3")])).unwrap(),
            Some(Shard { index: 0, count: 1 })
        );
    }

    #[test]
    fn shard_blocks_cover_the_frames_once() {
        for count in 1..7u32 {
            let mut covered = Vec::new();
            for index in 0..count {
                covered.extend(Shard { index, count }.frames(3..50));
            }
            assert_eq!(covered, (3..50).collect::<Vec<_>>(), "{count} shards");
        }
    }

    #[test]
    fn default_frames_cover_the_animation_once() {
        assert_eq!(FrameClock::Fps(30.0).default_frames(1.6), 0..48);
        assert_eq!(FrameClock::Fps(30.0).default_frames(0.0), 0..1);
        let aff = FrameClock::Scene(crate::scene::FrameTimes {
            start: 0.0,
            end: 20.0,
            frames: 800,
        });
        assert_eq!(aff.default_frames(123.0), 0..800);
        assert_eq!(aff.time(799), 20.0);
        assert_eq!(aff.time(0), 0.0);
    }
}
