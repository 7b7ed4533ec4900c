//! The results of `mipray compare`: what the runner measures and the report writes.

/// Per-frame errors of one method against the supersampled reference.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameErrors {
    pub frame: u32,
    /// Median render time of this frame over the repeats, plus this method's share of the
    /// frame update (the `log2 P_b` refresh for methods that need it), in ms.
    pub ms: f64,
    /// PSNR in dB (8-bit sRGB; `f64::INFINITY` when identical).
    pub psnr: f64,
    /// Mean SSIM (Gaussian 11x11, sigma 1.5), averaged over R, G, B.
    pub ssim: f64,
    /// Mean LDR-FLIP.
    pub flip: f64,
    /// Mean of `level(method) - level(finite-difference reference)` over measured pixels.
    pub lod_bias: f64,
    /// Root mean square of the same difference.
    pub lod_rms: f64,
    /// Share of measured pixels whose level is more than 0.5 below the reference's.
    pub lod_under: f64,
    /// Pixels that entered the LOD statistics (textured hits whose neighbouring rays
    /// followed the same chain).
    pub lod_pixels: u64,
    /// Temporal flicker against the previous frame: mean absolute difference between the
    /// method's frame-to-frame change and the reference's, in 8-bit code values. `None`
    /// for the first frame of the range.
    pub flicker: Option<f64>,
}

/// One method's results over the whole frame range.
#[derive(Debug, Clone, PartialEq)]
pub struct MethodSummary {
    /// `--lod` name.
    pub method: String,
    /// Bytes of LOD state each ray carries.
    pub bytes_per_ray: usize,
    /// Mean over frames of the per-frame time.
    pub ms_per_frame: f64,
    /// `(ms_per_frame / ms_per_frame of none - 1) * 100`, from the same run.
    pub overhead_pct: f64,
    /// Means over frames of the per-frame values (PSNR: mean of finite values).
    pub psnr: f64,
    pub ssim: f64,
    pub flip: f64,
    pub lod_bias: f64,
    pub lod_rms: f64,
    pub lod_under: f64,
    /// Mean over frames that have a flicker value (NaN if the range has one frame).
    pub flicker: f64,
    /// Share of texture lookups per integer MIP level (index = level), summing to 1 when
    /// there were lookups (all zeros otherwise).
    pub mip_share: Vec<f64>,
    pub frames: Vec<FrameErrors>,
}

/// One row of the paper's Table 1: `none` against `paper` with `lights` lights.
#[derive(Debug, Clone, PartialEq)]
pub struct LightsRow {
    pub lights: usize,
    pub none_ms: f64,
    pub paper_ms: f64,
    /// `(paper_ms / none_ms - 1) * 100`.
    pub overhead_pct: f64,
}

/// Everything `mipray compare` measured for one scene.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareReport {
    /// Scene name as given (file stem or built-in name).
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub frames: Vec<u32>,
    /// Samples per pixel of the level-0 reference.
    pub reference_spp: u32,
    /// Timed renders per method and frame (the median is kept).
    pub repeats: u32,
    pub lights: usize,
    /// Shared per-frame update (animate, refit, ...) not attributed to any method, mean ms.
    pub shared_update_ms: f64,
    pub lod_bias: f32,
    /// `--mip-filter`, when given (else each texture read as its sampler says).
    pub mip_filter: Option<crate::texture::MipFilter>,
    pub methods: Vec<MethodSummary>,
    /// Empty unless `--lights A..B` asked for the Table 1 replication.
    pub table1: Vec<LightsRow>,
}

/// A method's level error against one reference: over one frame, or the mean over frames.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LevelError {
    /// Mean of `level(method) - level(reference)` (positive: blurrier).
    pub bias: f64,
    /// Root mean square of the same difference.
    pub rms: f64,
    /// Share of measured pixels more than half a level below the reference (aliasing).
    pub under: f64,
}

/// One method's LOD error over one frame against the sub-pixel reference
/// (`compare::subpixel_reference`), under both of its conventions.
#[derive(Debug, Clone, PartialEq)]
pub struct SubpixelFrameErrors {
    pub frame: u32,
    /// Against the longest-axis (OpenGL) level of the fitted footprint.
    pub longest_axis: LevelError,
    /// Against the area-preserving level of the same fit.
    pub area: LevelError,
    /// Pixels measured (the fit was defined and the method's probe reached a texture).
    pub pixels: u64,
    /// Share of textured pixels whose fit is undefined (silhouettes, seams); the same for
    /// every method of a frame.
    pub undefined_share: f64,
}

/// One method's errors against the sub-pixel reference over the frame range (means over
/// frames of the per-frame values; NaN where no frame measured anything).
#[derive(Debug, Clone, PartialEq)]
pub struct SubpixelSummary {
    /// The method's word as in `MethodSummary::method` (`none@16` for supersampling).
    pub method: String,
    pub longest_axis: LevelError,
    pub area: LevelError,
    pub undefined_share: f64,
    pub frames: Vec<SubpixelFrameErrors>,
}
