//! The sequence loop: what happens to each frame of a render, in order.
//!
//! For each frame of the range (this shard's block of it, minus frames already complete on
//! disk when resuming): update and render it (`Renderer::render_frame_with_view`), write the
//! frame (temporary file, then rename), its `--view lod` level image, and one stats record;
//! judge it against a reference when checking. At the end, the summary, the render page and
//! (when checking) the check's report. The range is only iterated, so its length costs no
//! memory: memory grows with the frames actually rendered (one record each).
//!
//! Nothing here prints: each step is told to a [`SequenceProgress`] as it happens, and what
//! the sequence wrote comes back as a [`SequenceReport`] (the CLI turns both into lines).

use std::collections::BTreeSet;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use super::check::{CheckFinished, finish_check};
use super::output::{FrameFormat, OutputDir, Shard, frame_file_name};
use crate::atomic_file::write_image_atomically_as;
use crate::diff::{
    DiffInputError, DiffOptions, DiffReport, FrameDiff, compare_stats, diff_frame, frame_file,
};
use crate::frame::{FrameClock, LevelImage, Renderer};
use crate::record::{FrameRecord, RunIdentity};
use crate::render::memory::{LINEAR_PIXEL_BYTES, SRGB8_PIXEL_BYTES, check_frame_memory};
use crate::report::frame_file_problem;
use image::ImageFormat;
use rayon::prelude::*;

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
    /// The scene and settings stamped on every record: a resume, or a shard beside others
    /// in the folder, is refused when the records there came from another run.
    pub identity: RunIdentity,
}

/// Whether a sequence continues an interrupted run in its folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Resume {
    /// Render every frame of the range (earlier records of the folder are replaced).
    Restart,
    /// Skip frames whose file decodes at its record's size and whose record was written
    /// after it (damaged frame files are rendered again).
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

/// One frame just rendered and written.
#[derive(Debug, Clone, Copy)]
pub struct WrittenFrame<'a> {
    pub frame: u32,
    pub time_s: f32,
    pub record: &'a FrameRecord,
    /// The frame file.
    pub path: &'a Path,
}

/// What a sequence tells as it goes, in this order: `frame_damaged` for each kept frame
/// whose file does not decode, `resumed` (when frames were already complete), `started`, then per frame `frame_written` (and `frame_checked`, and
/// `stopping` when `--fail-fast` ends the run there), then `finished` once no more frames
/// will be rendered, before the summary and the page are written. Every method does
/// nothing by default.
pub trait SequenceProgress {
    /// `complete` of the range's `of` frames are already on disk and will not be rendered.
    fn resumed(&mut self, complete: usize, of: usize) {
        let _ = (complete, of);
    }
    /// A resume found frame `frame`'s file at `path` damaged (`problem`): it is rendered
    /// again. Told before `resumed`.
    fn frame_damaged(&mut self, frame: u32, path: &Path, problem: &str) {
        let _ = (frame, path, problem);
    }
    /// `frames` frames are about to be rendered.
    fn started(&mut self, frames: u64) {
        let _ = frames;
    }
    fn frame_written(&mut self, frame: &WrittenFrame) {
        let _ = frame;
    }
    /// The frame just written, judged against the reference's frame of the same number.
    fn frame_checked(&mut self, judged: &FrameDiff) {
        let _ = judged;
    }
    /// `--fail-fast`: frame `frame` failed its check and is the last one rendered.
    fn stopping(&mut self, frame: u32) {
        let _ = frame;
    }
    fn finished(&mut self) {}
}

/// A sequence run with nobody watching.
impl SequenceProgress for () {}

/// What a sequence wrote.
#[derive(Debug, Clone)]
pub struct SequenceReport {
    /// The frames of this run: the range, or this shard's block of it.
    pub frames: Range<u32>,
    /// Frames of `frames` with a record in the folder: rendered now or, when resuming,
    /// complete before.
    pub records: usize,
    /// From the first frame rendered to the summary (the page not included).
    pub elapsed: Duration,
    pub dir: PathBuf,
    /// `summary.json` (or the shard's summary file).
    pub summary: PathBuf,
    /// The render page.
    pub page: PathBuf,
    /// The check's report and verdict (`render --check`).
    pub check: Option<CheckFinished>,
}

/// Renders `frames` (this shard's part of them) into the output folder, one record per
/// frame, then the summary, the page and, when checking, the check's report; tells
/// `progress` each step.
///
/// # Errors
/// A frame fails to update (non-finite vertices), a file cannot be written, the folder
/// holds records of another run (see [`OutputDir::open`]). A checked frame that cannot be
/// compared (missing reference frame, different sizes) is no error: the check reports it
/// ([`CheckFinished::not_compared`]) and the sequence goes on, or stops there with
/// `--fail-fast`.
pub fn render_sequence(
    renderer: &mut Renderer,
    frames: Range<u32>,
    clock: FrameClock,
    out: &SequenceOutput,
    check: Option<&Check>,
    progress: &mut dyn SequenceProgress,
) -> Result<SequenceReport> {
    let frames = match out.shard {
        Some(shard) => shard.frames(frames),
        None => frames,
    };
    if let Some(check) = check {
        refuse_checking_against_itself(&check.reference, &out.dir)?;
        if let Some(junit) = &check.junit {
            super::check::check_junit_path(junit)?;
        }
    }
    if !frames.is_empty() {
        let settings = renderer.settings();
        check_frame_memory(
            settings.width,
            settings.height,
            frame_pixel_bytes(out),
            || {
                format!(
                    "rendering and writing a frame this size as {}",
                    out.format.extension().to_uppercase()
                )
            },
        )?;
    }
    let resume = out.resume == Resume::SkipComplete;
    let (mut output, previous) = OutputDir::open(
        &out.dir,
        out.format,
        out.shard,
        frames.clone(),
        resume,
        &out.identity,
    )?;
    let mut records = complete_frames(&output, &frames, previous, progress);
    let done: BTreeSet<u32> = records.iter().map(|r| r.frame).collect();
    if !done.is_empty() {
        progress.resumed(done.len(), frames.len());
    }
    let mut checked: Vec<FrameDiff> = Vec::new();
    // Frames a resume keeps are judged too, before any new frame is rendered: a check
    // speaks for the whole range, not only for the frames this run wrote.
    let mut stopped = false;
    if let Some(check) = check {
        for &frame in &done {
            let path = output.frame_path(frame);
            if judge_frame(frame, &path, out.format, check, progress, &mut checked)? {
                stopped = true;
                break;
            }
        }
    }
    let to_render = if stopped {
        0
    } else {
        frames.len() as u64 - done.len() as u64
    };
    progress.started(to_render);
    let start = Instant::now();
    // A stop while judging the kept frames renders nothing (and the range, which may be
    // billions of frames long, is not walked).
    let pending = if stopped {
        frames.end..frames.end
    } else {
        frames.clone()
    };
    for frame in pending.filter(|f| !done.contains(f)) {
        let time_s = clock.time(frame);
        let (image, mut record, view) =
            renderer.render_frame_with_view(frame, time_s, out.level_image)?;
        out.identity.stamp(&mut record);
        let path = output.write_frame(frame, &image)?;
        if let Some(view) = view {
            let view_path = output.path().join(format!("lod_{frame:04}.png"));
            write_image_atomically_as(&view_path, output.owner(), &view, ImageFormat::Png)
                .with_context(|| format!("cannot write {}", view_path.display()))?;
        }
        // Written: a check below decodes the frame again, without this copy beside it.
        drop(image);
        output.append_record(&record)?;
        progress.frame_written(&WrittenFrame {
            frame,
            time_s,
            record: &record,
            path: &path,
        });
        records.push(record);
        if let Some(check) = check
            && judge_frame(frame, &path, out.format, check, progress, &mut checked)?
        {
            break;
        }
    }
    progress.finished();
    records.sort_by_key(|r| r.frame);
    let summary = output.write_summary(&records)?;
    let elapsed = start.elapsed();
    let page = crate::pages::write_render_page(
        std::slice::from_ref(&out.dir),
        &out.dir,
        None,
        output.owner(),
    )?;
    let check = match check {
        None => None,
        Some(check) => Some(finish_sequence_check(check, &out.dir, checked)?),
    };
    Ok(SequenceReport {
        frames,
        records: records.len(),
        elapsed,
        dir: output.path().to_path_buf(),
        summary,
        page,
        check,
    })
}

/// The kept records (of a resume) whose frames are complete: in `frames`, with a frame file
/// that decodes at the record's size (a record is written after its frame, so the pair
/// means the frame was finished). A damaged file is told to `progress` and its frame is
/// rendered again. Files are decoded in parallel: milliseconds each.
fn complete_frames(
    output: &OutputDir,
    frames: &Range<u32>,
    previous: Vec<FrameRecord>,
    progress: &mut dyn SequenceProgress,
) -> Vec<FrameRecord> {
    let judged: Vec<(FrameRecord, Option<String>)> = previous
        .into_par_iter()
        .filter(|r| frames.contains(&r.frame) && output.frame_path(r.frame).exists())
        .map(|r| {
            let problem =
                frame_file_problem(&output.frame_path(r.frame), Some((r.width, r.height)));
            (r, problem)
        })
        .collect();
    let mut complete = Vec::with_capacity(judged.len());
    for (record, problem) in judged {
        match problem {
            None => complete.push(record),
            Some(problem) => {
                progress.frame_damaged(record.frame, &output.frame_path(record.frame), &problem);
            }
        }
    }
    complete
}

/// Compares a written frame with the reference's frame of the same number (found as
/// `mipray diff` finds it: a PNG or EXR frame of that number). Bad input (no reference
/// frame, sizes that differ, a file that cannot be read) makes a frame not compared rather
/// than an error: the render goes on, and the check reports it.
///
/// # Errors
/// The failure images cannot be written.
fn check_frame(frame: u32, path: &Path, format: FrameFormat, check: &Check) -> Result<FrameDiff> {
    let reference = frame_file(&check.reference, frame)
        .unwrap_or_else(|| check.reference.join(frame_file_name(frame, format)));
    match diff_frame(frame, &reference, path, &check.options) {
        Ok(judged) => Ok(judged),
        Err(error @ DiffInputError::Folder { .. }) => Err(error.into()),
        Err(error) => Ok(FrameDiff::not_compared(frame, &reference, path, &error)),
    }
}

/// Judges frame `frame` (its file at `path`) against the reference, tells `progress` and
/// keeps the verdict in `checked`; returns whether `--fail-fast` stops the sequence here.
fn judge_frame(
    frame: u32,
    path: &Path,
    format: FrameFormat,
    check: &Check,
    progress: &mut dyn SequenceProgress,
    checked: &mut Vec<FrameDiff>,
) -> Result<bool> {
    let judged = check_frame(frame, path, format, check)?;
    progress.frame_checked(&judged);
    let stop = !judged.passed && check.fail_fast;
    checked.push(judged);
    if stop {
        progress.stopping(frame);
    }
    Ok(stop)
}

/// `render --check REF` writing into `REF` itself would judge each frame against itself
/// after overwriting the reference: refused.
fn refuse_checking_against_itself(reference: &Path, out: &Path) -> Result<()> {
    let same = match (reference.canonicalize(), out.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => reference == out,
    };
    if same {
        anyhow::bail!(
            "--check {}: is the output folder itself (its frames would be overwritten and then \
             compared with themselves); give the reference and the output different folders",
            reference.display()
        );
    }
    Ok(())
}

/// The check's report over the frames judged, with the two folders' stats compared.
fn finish_sequence_check(
    check: &Check,
    dir: &Path,
    frames: Vec<FrameDiff>,
) -> Result<CheckFinished> {
    let mut report = DiffReport {
        reference_dir: check.reference.clone(),
        test_dir: dir.to_path_buf(),
        metric: check.options.metric,
        threshold: check.options.threshold,
        frames,
        stats_note: None,
    };
    report.stats_note = compare_stats(&check.reference, dir, &mut report.frames).err();
    finish_check(&report, &check.options.out, check.junit.as_deref())
}

/// The bytes per pixel a frame holds at once while it is rendered and written (`out`'s
/// format and views): its linear pixels, which the tiles write into, and while its PNG (an
/// EXR frame's PNG preview) is encoded their 8-bit sRGB codes; with `--view lod` also the
/// level image. A lower bound: the PNG encoder's compressed stream, small for rendered
/// frames, comes on top.
fn frame_pixel_bytes(out: &SequenceOutput) -> u64 {
    let view = match out.level_image {
        LevelImage::Make => SRGB8_PIXEL_BYTES,
        LevelImage::Skip => 0,
    };
    LINEAR_PIXEL_BYTES + SRGB8_PIXEL_BYTES + view
}
