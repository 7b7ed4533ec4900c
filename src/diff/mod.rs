//! Frame-by-frame regression: compare a rendered sequence with a stored reference sequence.
//!
//! Frames pair by number (`frame_0003.png` with `frame_0003.png`). Each pair gets PSNR, mean
//! FLIP, the maximum absolute difference and the share of differing pixels; the chosen
//! metric against a threshold decides pass or fail. The two `stats.jsonl` are compared too
//! (render time ratio, rays, `lod_recomputed`, MIP histogram shift), for information.
//! Bad input (a frame missing on either side, sizes that differ, unreadable files) is a
//! [`DiffInputError`], distinct from a regression: the CLI exits 2 for it and 1 for a
//! failing frame. `mipray diff` stops at it; `render --check`, whose frames are the
//! product, keeps rendering and records the frame as not compared
//! ([`FrameDiff::not_compared`]), shown as such in every report, and exits 2 at the end.
//! Both find a frame by number with one rule ([`frame_file`], [`list_frames`]): a PNG
//! frame pairs with an EXR frame of the same number.

mod junit;
mod stats;

pub use junit::junit_xml;
pub use stats::{StatsDelta, compare_stats};

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::csv::csv_field;
use crate::metrics::{FrameMetrics, MetricsError, compare, format_psnr, heat_map, read_srgb8};

/// Whether a checked sequence stayed within its threshold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Passed,
    Failed,
}

/// The metric that decides pass or fail.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum DiffMetric {
    /// Fails below the threshold in dB (default 40).
    #[default]
    Psnr,
    /// Fails above the threshold mean FLIP (default 0.01).
    Flip,
    /// Fails above the threshold largest channel difference, 0-255 (default 0).
    MaxAbs,
}

impl DiffMetric {
    pub fn default_threshold(self) -> f64 {
        match self {
            DiffMetric::Psnr => 40.0,
            DiffMetric::Flip => 0.01,
            DiffMetric::MaxAbs => 0.0,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            DiffMetric::Psnr => "psnr",
            DiffMetric::Flip => "flip",
            DiffMetric::MaxAbs => "max-abs",
        }
    }

    /// The metric's value for a frame.
    pub fn value(self, m: &FrameMetrics) -> f64 {
        match self {
            DiffMetric::Psnr => m.psnr_db,
            DiffMetric::Flip => m.mean_flip,
            DiffMetric::MaxAbs => m.max_abs as f64,
        }
    }

    /// Whether a frame with these metrics is within `threshold`.
    pub fn passes(self, m: &FrameMetrics, threshold: f64) -> bool {
        match self {
            DiffMetric::Psnr => m.psnr_db >= threshold,
            DiffMetric::Flip => m.mean_flip <= threshold,
            DiffMetric::MaxAbs => m.max_abs as f64 <= threshold,
        }
    }

    /// Badness for sorting: larger is worse.
    fn badness(self, m: &FrameMetrics) -> f64 {
        match self {
            DiffMetric::Psnr => -m.psnr_db,
            _ => self.value(m),
        }
    }
}

/// Bad input: not comparable, so neither pass nor fail.
#[derive(Debug, thiserror::Error)]
pub enum DiffInputError {
    #[error("frame {frame}: {path} is missing ({side} side)")]
    MissingFrame {
        frame: u32,
        side: &'static str,
        path: PathBuf,
    },
    #[error("{dir}: no frame_NNNN.png or .exr files")]
    NoFrames { dir: PathBuf },
    #[error("{dir}: {message}")]
    Folder { dir: PathBuf, message: String },
    #[error("frame {frame}: {source}")]
    Frame { frame: u32, source: MetricsError },
}

/// One compared frame.
#[derive(Debug, Clone)]
pub struct FrameDiff {
    pub frame: u32,
    pub reference: PathBuf,
    pub test: PathBuf,
    pub metrics: FrameMetrics,
    pub passed: bool,
    /// The heat map written for a failing frame.
    pub heat_map: Option<PathBuf>,
    /// Stats of the two renders for this frame, when both have a record.
    pub stats: Option<StatsDelta>,
    /// Why the frame could not be compared (bad input: no reference frame, sizes that
    /// differ, a file that cannot be read); its metrics are then NaN and 0, and it does
    /// not pass.
    pub problem: Option<String>,
}

impl FrameDiff {
    /// A frame that could not be compared, and why.
    pub fn not_compared(
        frame: u32,
        reference: &Path,
        test: &Path,
        problem: &DiffInputError,
    ) -> FrameDiff {
        FrameDiff {
            frame,
            reference: reference.to_path_buf(),
            test: test.to_path_buf(),
            metrics: FrameMetrics {
                psnr_db: f64::NAN,
                mean_flip: f64::NAN,
                max_abs: 0,
                differing_pixels: 0,
                differing_share: f64::NAN,
            },
            passed: false,
            heat_map: None,
            stats: None,
            problem: Some(problem.to_string()),
        }
    }

    /// Whether the frame was compared (else [`FrameDiff::problem`] says why not).
    pub fn compared(&self) -> bool {
        self.problem.is_none()
    }
}

/// How to judge and where to write.
#[derive(Debug, Clone)]
pub struct DiffOptions {
    pub metric: DiffMetric,
    pub threshold: f64,
    /// Folder for `diff.md`, `diff.csv` and the failing frames' images.
    pub out: PathBuf,
}

/// The file of frame `frame` in `dir`: `frame_NNNN.png`, else `frame_NNNN.exr` (the names
/// a render writes), `None` when neither is there.
pub fn frame_file(dir: &Path, frame: u32) -> Option<PathBuf> {
    FRAME_EXTENSIONS
        .iter()
        .map(|ext| dir.join(format!("frame_{frame:04}.{ext}")))
        .find(|path| path.is_file())
}

/// Frame file extensions, in the order a frame number is looked up.
const FRAME_EXTENSIONS: [&str; 2] = ["png", "exr"];

/// The frames of an output folder by number (`frame_NNNN.png` / `.exr`; where a number
/// has both, the PNG, as [`frame_file`] finds it).
pub fn list_frames(dir: &Path) -> Result<BTreeMap<u32, PathBuf>, DiffInputError> {
    let entries = std::fs::read_dir(dir).map_err(|e| DiffInputError::Folder {
        dir: dir.to_path_buf(),
        message: e.to_string(),
    })?;
    let mut frames = BTreeMap::new();
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(number) = name.strip_prefix("frame_").and_then(|rest| {
            rest.strip_suffix(".png")
                .or_else(|| rest.strip_suffix(".exr"))
        }) else {
            continue;
        };
        if let Ok(n) = number.parse::<u32>() {
            let path = entry.path();
            let is_png = path.extension().is_some_and(|e| e == FRAME_EXTENSIONS[0]);
            if is_png || !frames.contains_key(&n) {
                frames.insert(n, path);
            }
        }
    }
    Ok(frames)
}

/// Compares one frame pair; writes a heat map and copies of both frames into `options.out`
/// when it fails.
pub fn diff_frame(
    frame: u32,
    reference: &Path,
    test: &Path,
    options: &DiffOptions,
) -> Result<FrameDiff, DiffInputError> {
    for (side, path) in [("reference", reference), ("test", test)] {
        if !path.is_file() {
            return Err(DiffInputError::MissingFrame {
                frame,
                side,
                path: path.to_path_buf(),
            });
        }
    }
    let wrap = |source| DiffInputError::Frame { frame, source };
    let a = read_srgb8(reference).map_err(wrap)?;
    let b = read_srgb8(test).map_err(wrap)?;
    if a.dimensions() != b.dimensions() {
        let ((rw, rh), (tw, th)) = (a.dimensions(), b.dimensions());
        return Err(wrap(MetricsError::SizeMismatch {
            reference: reference.display().to_string(),
            test: test.display().to_string(),
            rw,
            rh,
            tw,
            th,
        }));
    }
    let (metrics, error_map) = compare(&a, &b);
    let passed = options.metric.passes(&metrics, options.threshold);
    let heat_map = if passed {
        None
    } else {
        Some(write_failure_images(
            frame,
            &a,
            &b,
            &heat_map(&error_map),
            &options.out,
        )?)
    };
    Ok(FrameDiff {
        frame,
        reference: reference.to_path_buf(),
        test: test.to_path_buf(),
        metrics,
        passed,
        heat_map,
        stats: None,
        problem: None,
    })
}

/// `frame_NNNN_ref.png`, `frame_NNNN_test.png` and `frame_NNNN_diff.png` side by side.
fn write_failure_images(
    frame: u32,
    a: &image::RgbImage,
    b: &image::RgbImage,
    heat: &image::RgbImage,
    out: &Path,
) -> Result<PathBuf, DiffInputError> {
    let folder_error = |message: String| DiffInputError::Folder {
        dir: out.to_path_buf(),
        message,
    };
    std::fs::create_dir_all(out).map_err(|e| folder_error(e.to_string()))?;
    let mut diff_path = PathBuf::new();
    for (suffix, image) in [("ref", a), ("test", b), ("diff", heat)] {
        let path = out.join(format!("frame_{frame:04}_{suffix}.png"));
        crate::atomic_file::write_rgb8_atomically(&path, image)
            .map_err(|e| folder_error(e.to_string()))?;
        diff_path = path;
    }
    Ok(diff_path)
}

/// A whole comparison.
#[derive(Debug, Clone)]
pub struct DiffReport {
    pub reference_dir: PathBuf,
    pub test_dir: PathBuf,
    pub metric: DiffMetric,
    pub threshold: f64,
    /// In frame order.
    pub frames: Vec<FrameDiff>,
    /// Why the stats were not compared, if they were not.
    pub stats_note: Option<String>,
}

/// Prepares `out` for a comparison's report before any frame is compared (else a long
/// comparison would end in an error): creates it (and its parents) and makes sure a file
/// can be written in it. Bad input, as a `--junit` path whose folder does not exist.
///
/// # Errors
/// [`DiffInputError::Folder`] naming `out`: it is a file, cannot be created, or refuses a
/// file.
pub fn prepare_report_folder(out: &Path) -> Result<(), DiffInputError> {
    let problem = if out.exists() && !out.is_dir() {
        "exists and is not a folder (the report goes into a folder)".to_string()
    } else if let Err(e) = std::fs::create_dir_all(out) {
        format!("cannot create the report folder: {e}")
    } else {
        let probe = out.join(format!(".write-check.{}.tmp", std::process::id()));
        match std::fs::File::create(&probe) {
            Ok(_) => {
                let _ = std::fs::remove_file(&probe);
                return Ok(());
            }
            Err(e) => format!("cannot write the report there: {e}"),
        }
    };
    Err(DiffInputError::Folder {
        dir: out.to_path_buf(),
        message: problem,
    })
}

/// Compares every frame of `test_dir` with `reference_dir`; both must hold the same frame
/// numbers.
/// `options.out` is prepared ([`prepare_report_folder`]) before the first frame is
/// compared.
pub fn diff_dirs(
    reference_dir: &Path,
    test_dir: &Path,
    options: &DiffOptions,
) -> Result<DiffReport, DiffInputError> {
    let reference = list_frames(reference_dir)?;
    let test = list_frames(test_dir)?;
    if reference.is_empty() {
        return Err(DiffInputError::NoFrames {
            dir: reference_dir.to_path_buf(),
        });
    }
    for (frame, path) in &reference {
        if !test.contains_key(frame) {
            let name = path
                .file_name()
                .map(|n| test_dir.join(n))
                .unwrap_or_else(|| test_dir.to_path_buf());
            return Err(DiffInputError::MissingFrame {
                frame: *frame,
                side: "test",
                path: name,
            });
        }
    }
    if let Some((frame, path)) = test.iter().find(|(f, _)| !reference.contains_key(f)) {
        let name = path
            .file_name()
            .map(|n| reference_dir.join(n))
            .unwrap_or_else(|| reference_dir.to_path_buf());
        return Err(DiffInputError::MissingFrame {
            frame: *frame,
            side: "reference",
            path: name,
        });
    }
    // Failing frames write their heat maps there, and the reports follow.
    prepare_report_folder(&options.out)?;
    let mut frames = Vec::with_capacity(reference.len());
    for (frame, path) in &reference {
        frames.push(diff_frame(*frame, path, &test[frame], options)?);
    }
    let stats_note = compare_stats(reference_dir, test_dir, &mut frames).err();
    Ok(DiffReport {
        reference_dir: reference_dir.to_path_buf(),
        test_dir: test_dir.to_path_buf(),
        metric: options.metric,
        threshold: options.threshold,
        frames,
        stats_note,
    })
}

impl DiffReport {
    /// Frames compared and outside the threshold.
    pub fn failed(&self) -> usize {
        self.frames
            .iter()
            .filter(|f| f.compared() && !f.passed)
            .count()
    }

    /// Frames that could not be compared (bad input).
    pub fn not_compared(&self) -> usize {
        self.frames.iter().filter(|f| !f.compared()).count()
    }

    /// Frames, those not compared first, then worst first by the deciding metric.
    pub fn worst_first(&self) -> Vec<&FrameDiff> {
        let mut frames: Vec<&FrameDiff> = self.frames.iter().collect();
        frames.sort_by(|a, b| {
            a.compared()
                .cmp(&b.compared())
                .then(
                    self.metric
                        .badness(&b.metrics)
                        .total_cmp(&self.metric.badness(&a.metrics)),
                )
                .then(a.frame.cmp(&b.frame))
        });
        frames
    }

    /// One line: PASS/FAIL, counts, the worst frame compared, the frames not compared.
    pub fn verdict(&self) -> String {
        let worst = self
            .worst_first()
            .into_iter()
            .find(|f| f.compared())
            .map(|f| (f.frame, self.metric.value(&f.metrics)));
        let worst = worst.map_or(String::new(), |(frame, v)| {
            format!(
                "; worst frame {frame}: {} {}",
                self.metric.name(),
                format_value(self.metric, v)
            )
        });
        let status = if self.failed() + self.not_compared() == 0 {
            "PASS"
        } else {
            "FAIL"
        };
        let not_compared = match self.not_compared() {
            0 => String::new(),
            n => format!("; {n} frame(s) not compared (bad input, see the report)"),
        };
        format!(
            "{status}: {} of {} frame(s) outside {} threshold {}{worst}{not_compared}",
            self.failed(),
            self.frames.len(),
            self.metric.name(),
            format_value(self.metric, self.threshold)
        )
    }

    /// The per-frame Markdown table, worst first.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "| frame | result | PSNR dB | mean FLIP | max abs | differing pixels | time ratio | rays delta | lod_recomputed delta | MIP shift |"
        );
        let _ = writeln!(s, "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|");
        for f in self.worst_first() {
            if let Some(problem) = &f.problem {
                let _ = writeln!(
                    s,
                    "| {} | not compared: {} | - | - | - | - | - | - | - | - |",
                    f.frame,
                    problem.replace('|', "\\|")
                );
                continue;
            }
            let m = &f.metrics;
            let st = f.stats.as_ref();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.5} | {} | {} ({:.3}%) | {} | {} | {} | {} |",
                f.frame,
                if f.passed { "pass" } else { "FAIL" },
                format_psnr(m.psnr_db),
                m.mean_flip,
                m.max_abs,
                m.differing_pixels,
                m.differing_share * 100.0,
                st.map_or("-".into(), |d| format!("{:.3}", d.time_ratio)),
                st.map_or("-".into(), |d| d.rays_delta.to_string()),
                st.map_or("-".into(), |d| d.lod_recomputed_delta.to_string()),
                st.map_or("-".into(), |d| format!("{:+.4}", d.mip_level_shift)),
            );
        }
        s
    }

    /// `diff.csv`: one row per frame, in frame order.
    pub fn csv(&self) -> String {
        let mut s = String::from(
            "frame,passed,psnr_db,mean_flip,max_abs,differing_pixels,differing_share,time_ratio,rays_delta,lod_recomputed_delta,mip_level_shift,reference,test,problem\n",
        );
        for f in &self.frames {
            if let Some(problem) = &f.problem {
                let _ = writeln!(
                    s,
                    "{},false,,,,,,,,,,{},{},{}",
                    f.frame,
                    csv_field(&f.reference.display().to_string()),
                    csv_field(&f.test.display().to_string()),
                    csv_field(problem),
                );
                continue;
            }
            let m = &f.metrics;
            let st = f.stats.as_ref();
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{},{},{},{},{},{},{},",
                f.frame,
                f.passed,
                if m.psnr_db.is_infinite() {
                    "inf".to_string()
                } else {
                    m.psnr_db.to_string()
                },
                m.mean_flip,
                m.max_abs,
                m.differing_pixels,
                m.differing_share,
                st.map_or(String::new(), |d| d.time_ratio.to_string()),
                st.map_or(String::new(), |d| d.rays_delta.to_string()),
                st.map_or(String::new(), |d| d.lod_recomputed_delta.to_string()),
                st.map_or(String::new(), |d| d.mip_level_shift.to_string()),
                csv_field(&f.reference.display().to_string()),
                csv_field(&f.test.display().to_string()),
            );
        }
        s
    }

    /// `diff.md`: verdict, the table, and the stats note.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "# mipray diff\n\nreference: `{}`\ntest: `{}`\n\n**{}**\n\n",
            self.reference_dir.display(),
            self.test_dir.display(),
            self.verdict()
        );
        s.push_str(&self.table());
        if let Some(note) = &self.stats_note {
            let _ = writeln!(s, "\nstats not compared: {note}");
        }
        for f in self.frames.iter().filter(|f| !f.passed) {
            if let Some(h) = &f.heat_map {
                let _ = writeln!(s, "\nframe {}: heat map `{}`", f.frame, h.display());
            }
        }
        s
    }

    /// Writes `diff.md` and `diff.csv` into `out`.
    pub fn write(&self, out: &Path) -> std::io::Result<()> {
        std::fs::create_dir_all(out)?;
        crate::atomic_file::write_text_atomically(&out.join("diff.md"), &self.markdown())?;
        crate::atomic_file::write_text_atomically(&out.join("diff.csv"), &self.csv())
    }
}

fn format_value(metric: DiffMetric, v: f64) -> String {
    match metric {
        DiffMetric::Psnr => format!("{} dB", format_psnr(v)),
        DiffMetric::Flip => format!("{v:.5}"),
        DiffMetric::MaxAbs => format!("{v:.0}"),
    }
}
