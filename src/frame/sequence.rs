//! The sequence loop: what happens to each frame of a render, in order.
//!
//! For each frame of the range (this shard's block of it, minus frames already complete on
//! disk when resuming): update and render it (`Renderer::render_frame_with_view`), write the
//! frame (temporary file, then rename), its `--view lod` level image, and one stats record;
//! judge it against a reference when checking. At the end, the summary. The range is only
//! iterated, so its length costs no memory: memory grows with the frames actually rendered
//! (one record each).

use std::collections::BTreeSet;
use std::io::IsTerminal;
use std::ops::Range;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

use super::{FrameClock, LevelImage, Renderer};
use crate::diff::{DiffOptions, DiffReport, FrameDiff, Verdict, compare_stats, diff_frame};
use crate::output::{FrameFormat, OutputDir, Shard};
use crate::record::FrameRecord;

/// Where and how a sequence is written.
#[derive(Debug, Clone)]
pub struct SequenceOutput {
    pub dir: PathBuf,
    pub format: FrameFormat,
    pub shard: Option<Shard>,
    /// Skip frames already complete on disk (frame file and stats record).
    pub resume: Resume,
    /// Whether each frame also writes `lod_NNNN.png` (`--view lod`).
    pub level_image: LevelImage,
}

/// Whether a sequence continues an interrupted run in its folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Resume {
    /// Render every frame of the range (earlier records of the folder are replaced).
    Restart,
    /// Skip frames whose file exists and whose record was written after it.
    SkipComplete,
}

/// `render --check`: judge each frame against a reference as soon as it is written.
#[derive(Debug, Clone)]
pub struct Check {
    pub reference: PathBuf,
    pub options: DiffOptions,
    pub fail_fast: bool,
    pub junit: Option<PathBuf>,
}

/// How a sequence ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SequenceOutcome {
    /// Rendered, no check asked for.
    Rendered,
    /// Rendered and checked against the reference.
    Checked(Verdict),
}

/// Renders `frames` (this shard's part of them) into the output folder, one record per
/// frame, then the summary.
///
/// # Errors
/// A frame fails to update (non-finite vertices), a file cannot be written, or a checked
/// frame cannot be compared (missing reference frame, different sizes).
pub fn render_sequence(
    renderer: &mut Renderer,
    frames: Range<u32>,
    clock: FrameClock,
    out: &SequenceOutput,
    check: Option<&Check>,
) -> Result<SequenceOutcome> {
    let frames = match out.shard {
        Some(shard) => shard.frames(frames),
        None => frames,
    };
    let resume = out.resume == Resume::SkipComplete;
    let (mut output, previous) = OutputDir::open(&out.dir, out.format, out.shard, resume)?;
    // A frame is complete when its file exists and its record was written after it.
    let mut records: Vec<FrameRecord> = previous
        .into_iter()
        .filter(|r| frames.contains(&r.frame) && output.frame_path(r.frame).is_file())
        .collect();
    let done: BTreeSet<u32> = records.iter().map(|r| r.frame).collect();
    if !done.is_empty() {
        println!(
            "resuming: {} of {} frame(s) already complete",
            done.len(),
            frames.len()
        );
    }
    let mut checked: Vec<FrameDiff> = Vec::new();
    let progress = progress_bar(frames.len() as u64 - done.len() as u64);
    let start = Instant::now();
    for frame in frames.clone().filter(|f| !done.contains(f)) {
        let time_s = clock.time(frame);
        let (image, record, view) =
            renderer.render_frame_with_view(frame, time_s, out.level_image)?;
        let path = output.write_frame(frame, &image)?;
        if let Some(view) = view {
            let view_path = output.path().join(format!("lod_{frame:04}.png"));
            crate::atomic_file::write_rgb8_atomically(&view_path, &view)
                .with_context(|| format!("cannot write {}", view_path.display()))?;
        }
        output.append_record(&record)?;
        let line = frame_line(frame, time_s, &record, &path);
        progress.suspend(|| println!("{line}"));
        progress.inc(1);
        records.push(record);
        if let Some(check) = check {
            let (judged, verdict_line) = check_frame(frame, &path, out.format, check)?;
            progress.suspend(|| println!("{verdict_line}"));
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
    let page = crate::pages::write_render_page(std::slice::from_ref(&out.dir), &out.dir, None)?;
    println!("page: {}", page.display());
    match check {
        None => Ok(SequenceOutcome::Rendered),
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
            let verdict =
                crate::diff::finish_report(&report, &check.options.out, check.junit.as_deref())?;
            Ok(SequenceOutcome::Checked(verdict))
        }
    }
}

/// The line printed for each rendered frame.
fn frame_line(frame: u32, time_s: f32, record: &FrameRecord, path: &std::path::Path) -> String {
    format!(
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
    )
}

/// Compares a written frame with the reference's frame of the same number; the judgement
/// and its printed line.
fn check_frame(
    frame: u32,
    path: &std::path::Path,
    format: FrameFormat,
    check: &Check,
) -> Result<(FrameDiff, String)> {
    let name = crate::output::frame_file_name(frame, format);
    let judged = diff_frame(frame, &check.reference.join(&name), path, &check.options)?;
    let line = format!(
        "check frame {frame:04}: {}  psnr {} dB  flip {:.5}  max abs {}",
        if judged.passed { "pass" } else { "FAIL" },
        crate::metrics::format_psnr(judged.metrics.psnr_db),
        judged.metrics.mean_flip,
        judged.metrics.max_abs
    );
    Ok((judged, line))
}

/// A progress bar on stderr over `len` frames, hidden when stderr is not a terminal.
pub fn progress_bar(len: u64) -> ProgressBar {
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
