//! `mipray render` (and no arguments at all): an animation to an image sequence.

// The options' doc comments are the command's `--help` text, where `<scene>` is a
// placeholder the user reads, not an HTML tag.
#![allow(rustdoc::invalid_html_tags)]

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Args;

use super::args::{
    LightArgs, SequenceArgs, TraceArgs, UsageError, View, check_threads, render_settings, usage,
};
use super::diff::CheckArgs;
use super::progress::{SequenceLines, print_sequence_end};
use super::scene::{OpenedScene, naming_the_scene, open_scene};
use crate::accel::{BvhLayout, BvhPolicy};
use crate::anim::AnimationSelection;
use crate::diff::{DiffOptions, Verdict};
use crate::frame::{FrameClock, LevelImage, RenderSettings, Renderer};
use crate::lod::LodMethod;
use crate::record::{RunIdentity, scene_files_identity, scene_identity};
use crate::run::{Check, FrameFormat, Resume, SequenceOutput, Shard, render_sequence};
use crate::texture::MipFilter;

#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    #[command(flatten)]
    pub sequence: SequenceArgs,
    #[command(flatten)]
    pub trace: TraceArgs,
    #[command(flatten)]
    pub lights: LightArgs,
    /// Output folder [default: out/<scene>/<lod>/].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Texture LOD selection method.
    #[arg(long, default_value = "paper")]
    pub lod: LodMethod,
    /// Samples per pixel (stratified; a square number fills the strata grid exactly).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Worker threads, 1 to 1024 [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Frame file format.
    #[arg(long, value_enum, default_value_t = FrameFormat::Png)]
    pub format: FrameFormat,
    /// BVH: `auto`: per mesh, instanced where a measured cost model says it pays, merged
    /// into the world-space tree elsewhere (`mipray info` prints the decision);
    /// `flat` (alias `refit`): one world-space tree refitted every frame, rebuilt past
    /// --rebuild-threshold; `two-level`: shared object-space meshes under a top-level tree
    /// over their instances (rigid motion moves transforms, not triangles; what deforms
    /// stays in a refitted world-space tree); `rebuild`: flat, rebuilt every frame (for
    /// comparison).
    #[arg(long, value_enum, default_value_t = BvhMode::Auto)]
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

/// `--bvh` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BvhMode {
    Auto,
    #[value(alias = "refit")]
    Flat,
    TwoLevel,
    Rebuild,
}

impl Default for RenderArgs {
    fn default() -> Self {
        use clap::Parser;
        match super::Cli::parse_from(["mipray", "render"]).command {
            Some(super::Command::Render(args)) => args,
            _ => unreachable!("`mipray render` parses to the render command"),
        }
    }
}

/// `mipray render`. `Ok(FAILURE)` when a `--check` found frames outside the threshold;
/// exit status 2 when it could not compare some frame (bad input), after every frame was
/// rendered (or `--fail-fast` stopped there) and the reports were written.
pub fn render(args: &RenderArgs) -> Result<ExitCode> {
    let mut settings = render_settings(&args.sequence, &args.trace, args.lights.lights, args.spp)?;
    settings.lod = args.lod;
    apply_bvh(&mut settings, args.bvh, args.rebuild_threshold)?;
    // Argument errors (shard spec, thread count) before a possibly long scene load.
    let shard = resolve_shard(args.shard.as_deref(), |name| std::env::var(name).ok())?;
    let pool = thread_pool(args.threads)?;
    let scene = open_scene(&args.sequence)?;
    settings.animation = scene.animation;
    let identity = run_identity(&scene, &settings, args.format)?;
    let output = SequenceOutput {
        dir: args.out.clone().unwrap_or_else(|| {
            PathBuf::from("out")
                .join(&scene.name)
                .join(args.lod.to_string())
        }),
        format: args.format,
        shard,
        resume: if args.resume {
            Resume::SkipComplete
        } else {
            Resume::Restart
        },
        level_image: match args.view {
            Some(View::Lod) => LevelImage::Make,
            None => LevelImage::Skip,
        },
        identity,
    };
    let check = args.check.as_ref().map(|reference| Check {
        reference: reference.clone(),
        options: DiffOptions {
            metric: args.check_args.metric,
            threshold: args.check_args.threshold(),
            out: output.dir.join("check"),
        },
        fail_fast: args.fail_fast,
        junit: args.check_args.junit.clone(),
    });
    let (frames, clock, scene_path) = (scene.frames.clone(), scene.clock, scene.path);
    let mut renderer = Renderer::new(scene.desc, settings);
    let mut lines = SequenceLines::default();
    let report = pool
        .install(|| {
            render_sequence(
                &mut renderer,
                frames,
                clock,
                &output,
                check.as_ref(),
                &mut lines,
            )
        })
        .map_err(|e| naming_the_scene(e, &scene_path))?;
    print_sequence_end(&report);
    Ok(match report.check {
        Some(check) if check.not_compared > 0 => {
            eprintln!(
                "error: --check: {} frame(s) could not be compared with the reference (bad \
                 input: see {})",
                check.not_compared,
                check.report.display()
            );
            ExitCode::from(2)
        }
        Some(check) if check.verdict == Verdict::Failed => ExitCode::FAILURE,
        _ => ExitCode::SUCCESS,
    })
}

/// What identifies this render's frames (see `crate::record::RunIdentity`): the scene's
/// file name and digest, a digest of the other files its load read, and by flag name every setting that changes the pixels, each as
/// resolved (the clip and camera chosen, not how they were named). Threads and `--bvh`
/// change no pixel and are left out; so is anything that differs between machines.
fn run_identity(
    scene: &OpenedScene,
    settings: &RenderSettings,
    format: FrameFormat,
) -> Result<RunIdentity> {
    let file_name = scene
        .path
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    // The load hashed every file as it read it; the scene file is read again only when the
    // load did not note it.
    let top = std::fs::canonicalize(&scene.path).unwrap_or_else(|_| scene.path.clone());
    let scene_id = match scene.sources.iter().find(|f| f.path == top) {
        Some(file) => format!("{file_name}#{:016x}", file.digest),
        None => {
            let file = std::fs::File::open(&scene.path)
                .with_context(|| format!("{}: cannot read the scene", scene.path.display()))?;
            scene_identity(&file_name, std::io::BufReader::new(file))
                .with_context(|| format!("{}: cannot read the scene", scene.path.display()))?
        }
    };
    let others: Vec<u64> = scene
        .sources
        .iter()
        .filter(|f| f.path != top)
        .map(|f| f.digest)
        .collect();
    let entries = [
        ("size", format!("{}x{}", settings.width, settings.height)),
        ("camera", camera_in_use(&scene.desc)),
        (
            "animation",
            match settings.animation {
                AnimationSelection::All => "all clips".to_string(),
                AnimationSelection::One(i) => format!("clip {i}"),
            },
        ),
        (
            "fps",
            match scene.clock {
                FrameClock::Fps(fps) => fps.to_string(),
                FrameClock::Scene(_) => "the scene's frame times".to_string(),
            },
        ),
        ("lod", settings.lod.to_string()),
        ("lod-bias", settings.lod_bias.to_string()),
        (
            "mip-filter",
            settings
                .mip_filter
                .map_or("each texture's own", MipFilter::name)
                .to_string(),
        ),
        ("max-depth", settings.max_depth.to_string()),
        (
            "lights",
            settings.lights.map_or("all".to_string(), |n| n.to_string()),
        ),
        ("spp", settings.spp.to_string()),
        ("format", format.extension().to_string()),
    ];
    Ok(RunIdentity {
        scene: scene_id,
        scene_files: scene_files_identity(&others),
        settings: entries
            .into_iter()
            .map(|(name, value)| (name.to_string(), value))
            .collect(),
    })
}

/// The camera the frame loop looks through: the first camera node in traversal order, by
/// name (or number when unnamed), else the default view of a scene without cameras.
fn camera_in_use(desc: &crate::scene::SceneDesc) -> String {
    desc.traversal_order()
        .into_iter()
        .find(|&i| desc.nodes[i].camera.is_some())
        .map_or("none (default view)".to_string(), |i| {
            match desc.nodes[i].name.as_str() {
                "" => format!("node {i}"),
                name => name.to_string(),
            }
        })
}

/// Sets the BVH policy and layout of `--bvh MODE` and `--rebuild-threshold`.
pub fn apply_bvh(
    settings: &mut crate::frame::RenderSettings,
    mode: BvhMode,
    rebuild_threshold: f32,
) -> Result<()> {
    if !(rebuild_threshold.is_finite() && rebuild_threshold >= 1.0) {
        return Err(usage(format!(
            "--rebuild-threshold {rebuild_threshold}: must be a number >= 1"
        )));
    }
    settings.bvh = match mode {
        BvhMode::Auto | BvhMode::Flat | BvhMode::TwoLevel => BvhPolicy::Refit { rebuild_threshold },
        BvhMode::Rebuild => BvhPolicy::Rebuild,
    };
    settings.layout = match mode {
        BvhMode::Auto => BvhLayout::Auto,
        BvhMode::TwoLevel => BvhLayout::TwoLevel,
        BvhMode::Flat | BvhMode::Rebuild => BvhLayout::Flat,
    };
    Ok(())
}

fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        check_threads(n)?;
        builder = builder.num_threads(n);
    }
    builder.build().context("cannot start worker threads")
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
            .with_context(|| UsageError(format!("{name}={v}: not a whole number")))
    };
    let (index, count) = if let Some(spec) = arg {
        let (i, n) = spec
            .split_once('/')
            .with_context(|| UsageError(format!("--shard {spec}: expected I/N, e.g. 0/4")))?;
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
            id.checked_sub(min).with_context(|| {
                UsageError("SLURM_ARRAY_TASK_ID is below SLURM_ARRAY_TASK_MIN".into())
            })?,
            parse("SLURM_ARRAY_TASK_COUNT", &count)?,
        )
    } else if let Some(index) = env("JOB_COMPLETION_INDEX") {
        let count = env("MIPRAY_SHARD_COUNT").with_context(|| {
            UsageError(
                "JOB_COMPLETION_INDEX is set but MIPRAY_SHARD_COUNT (the Job's completions) is not"
                    .into(),
            )
        })?;
        (
            parse("JOB_COMPLETION_INDEX", &index)?,
            parse("MIPRAY_SHARD_COUNT", &count)?,
        )
    } else {
        return Ok(None);
    };
    if count == 0 || index >= count {
        return Err(usage(format!(
            "shard {index} of {count}: the index must be below the count"
        )));
    }
    Ok(Some(Shard { index, count }))
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
