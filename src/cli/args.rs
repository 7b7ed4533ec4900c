//! Flag groups shared by several commands (each declared once and flattened where used),
//! their validation, and the limits that keep a typo from allocating the machine away.

use std::ops::Range;

use anyhow::{Context, Result};
use clap::Args;

use crate::anim::AnimationSelection;
use crate::frame::RenderSettings;
use crate::texture::MipFilter;

/// Largest image: width x height.
pub const MAX_PIXELS: u64 = 16384 * 16384;
/// Most samples per pixel.
pub const MAX_SPP: u32 = 65536;
/// Deepest reflection/refraction chain.
pub const MAX_DEPTH: u32 = 64;
/// Most lights.
pub const MAX_LIGHTS: usize = 1024;

/// The most worker threads `--threads` accepts: far above any machine's cores, and below
/// the counts that take the system minutes to start (100,000 threads never finished).
pub const MAX_THREADS: usize = 1024;

/// A flag, or an environment variable standing in for one, with a value the command cannot
/// use: a usage error. `main` gives it exit status 2, as the parser's own errors have, so a
/// script tells a mistyped command from a render that failed (status 1). Attached as an
/// error's context it keeps the cause (`--size 12xa: bad height: invalid digit ...`).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// A [`UsageError`] as an `anyhow` error, for `return Err(usage(...))`.
pub fn usage(message: String) -> anyhow::Error {
    UsageError(message).into()
}

/// Checks a `--threads` count: 1 to [`MAX_THREADS`].
pub fn check_threads(n: usize) -> Result<()> {
    if n == 0 || n > MAX_THREADS {
        return Err(usage(format!("--threads {n}: must be 1 to {MAX_THREADS}")));
    }
    Ok(())
}
/// Largest `--lod-bias` magnitude accepted: past 16 levels every texture is at one end.
pub const MAX_LOD_BIAS: f32 = 16.0;

/// Which scene, which frames, at what size, playing which clip: every command that renders
/// or exports frames.
#[derive(Args, Debug, Clone)]
pub struct SequenceArgs {
    /// A .gltf/.glb, .aff, .obj or .usda/.usdc/.usdz path, or the name of a scene in
    /// animations/ (e.g. `default`).
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
    /// Play one animation clip (its name or index) instead of all clips together.
    #[arg(long)]
    pub animation: Option<String>,
    /// Look through the camera of this node (glTF node name; USD prim name or path)
    /// instead of the first camera.
    #[arg(long)]
    pub camera: Option<String>,
}

/// How rays are traced: render, bench and compare.
#[derive(Args, Debug, Clone)]
pub struct TraceArgs {
    /// Levels added to every MIP-mapped lookup (positive: blurrier); `--lod none` ignores it.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub lod_bias: f32,
    /// How every texture's MIP levels are read: `linear` blends the two nearest
    /// (trilinear), `nearest` reads the nearest alone (one bilinear lookup, cheaper, with
    /// visible steps) [default: as each texture's sampler says: glTF `*_MIPMAP_NEAREST`
    /// is `nearest`, anything else `linear`].
    #[arg(long, value_enum)]
    pub mip_filter: Option<MipFilter>,
    /// Maximum reflection/refraction depth.
    #[arg(long, default_value_t = 5)]
    pub max_depth: u32,
}

/// How many lights: render, bench and export.
#[derive(Args, Debug, Clone, Default)]
pub struct LightArgs {
    /// Number of lights: the scene's first N, plus point lights around the scene if it has
    /// fewer [default: all of the scene's lights, at least 1].
    #[arg(long)]
    pub lights: Option<usize>,
}

/// Debug views written beside the frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum View {
    /// False-colour MIP level of each pixel's texture lookup.
    Lod,
}

/// Settings from the shared flag groups, every value checked against its limit.
pub fn render_settings(
    sequence: &SequenceArgs,
    trace: &TraceArgs,
    lights: Option<usize>,
    spp: u32,
) -> Result<RenderSettings> {
    let (width, height) = parse_size(&sequence.size)?;
    if spp == 0 || spp > MAX_SPP {
        return Err(usage(format!("--spp {spp}: must be 1 to {MAX_SPP}")));
    }
    if trace.max_depth > MAX_DEPTH {
        return Err(usage(format!(
            "--max-depth {}: at most {MAX_DEPTH}",
            trace.max_depth
        )));
    }
    if lights.is_some_and(|n| n > MAX_LIGHTS) {
        return Err(usage(format!("--lights: at most {MAX_LIGHTS}")));
    }
    if let Some(fps) = sequence.fps.filter(|f| !(f.is_finite() && *f > 0.0)) {
        return Err(usage(format!("--fps {fps}: must be a positive number")));
    }
    check_lod_bias(trace.lod_bias)?;
    Ok(RenderSettings {
        width,
        height,
        lod_bias: trace.lod_bias,
        mip_filter: trace.mip_filter,
        spp,
        max_depth: trace.max_depth,
        lights,
        animation: AnimationSelection::All,
        ..RenderSettings::default()
    })
}

fn check_lod_bias(bias: f32) -> Result<()> {
    if !(bias.is_finite() && bias.abs() <= MAX_LOD_BIAS) {
        return Err(usage(format!(
            "--lod-bias {bias}: must be a number from -{MAX_LOD_BIAS} to {MAX_LOD_BIAS}"
        )));
    }
    Ok(())
}

/// Parses `WxH`.
pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| UsageError(format!("--size {s}: expected WxH, e.g. 640x360")))?;
    let w: u32 = w
        .trim()
        .parse()
        .with_context(|| UsageError(format!("--size {s}: bad width")))?;
    let h: u32 = h
        .trim()
        .parse()
        .with_context(|| UsageError(format!("--size {s}: bad height")))?;
    if w == 0 || h == 0 || w as u64 * h as u64 > MAX_PIXELS {
        return Err(usage(format!(
            "--size {s}: width and height must be at least 1 and at most {MAX_PIXELS} pixels in all"
        )));
    }
    Ok((w, h))
}

/// Parses a half-open frame range `A..B`, or a single frame `A`. The range is only ever
/// iterated, so its length costs no memory.
pub fn parse_frames(s: &str) -> Result<Range<u32>> {
    let range = match s.split_once("..") {
        Some((a, b)) => {
            let a: u32 = a
                .trim()
                .parse()
                .with_context(|| UsageError(format!("--frames {s}: bad start")))?;
            let b: u32 = b
                .trim()
                .parse()
                .with_context(|| UsageError(format!("--frames {s}: bad end")))?;
            a..b
        }
        None => {
            let a: u32 = s
                .trim()
                .parse()
                .with_context(|| UsageError(format!("--frames {s}: expected A..B or A")))?;
            if a == u32::MAX {
                return Err(usage(format!(
                    "--frames {s}: frame numbers go up to {}",
                    u32::MAX - 1
                )));
            }
            a..a + 1
        }
    };
    if range.is_empty() {
        return Err(usage(format!(
            "--frames {s}: empty range (the end is exclusive)"
        )));
    }
    Ok(range)
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
            .with_context(|| UsageError(format!("--lights {s}: '{t}' is not a whole number")))
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
        return Err(usage(format!(
            "--lights {s}: counts must satisfy 1 <= A <= B <= {MAX_LIGHTS}"
        )));
    }
    Ok(spec)
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
        // A huge range is accepted: it is iterated, never collected.
        assert_eq!(parse_frames("0..4000000000").unwrap().len(), 4_000_000_000);
        // The last frame number a half-open range can end after, and one past it.
        assert_eq!(parse_frames("4294967294").unwrap(), 4294967294..4294967295);
        let e = parse_frames("4294967295").unwrap_err().to_string();
        assert!(e.contains("go up to 4294967294"), "{e}");
    }

    #[test]
    fn parses_light_counts_and_table_ranges() {
        assert_eq!(parse_lights("3").unwrap(), LightsSpec::Count(3));
        assert_eq!(parse_lights("1..6").unwrap(), LightsSpec::Range(1, 6));
        assert_eq!(parse_lights("1..=6").unwrap(), LightsSpec::Range(1, 6));
        assert!(parse_lights("0").is_err());
        assert!(parse_lights("4..2").is_err());
        assert!(parse_lights("1..5000").is_err());
    }
}
