//! What the commands show while they work: the progress bar on stderr, and the lines a
//! render prints for each frame and at its end (the library reports them as values, see
//! `run::SequenceProgress`).

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};

use crate::diff::FrameDiff;
use crate::run::{CheckFinished, SequenceProgress, SequenceReport, WrittenFrame};

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

/// `mipray render`'s lines on stdout: one per frame (and per check), under a progress bar.
#[derive(Default)]
pub struct SequenceLines {
    bar: Option<ProgressBar>,
}

impl SequenceLines {
    /// Prints `line` on stdout, above the bar.
    fn print(&self, line: &str) {
        self.above_bar(|| println!("{line}"));
    }

    /// Runs `write` (a print to stdout or stderr) with the bar, if any, out of the way.
    fn above_bar(&self, write: impl FnOnce()) {
        match &self.bar {
            Some(bar) => bar.suspend(write),
            None => write(),
        }
    }
}

impl SequenceProgress for SequenceLines {
    fn frame_damaged(&mut self, frame: u32, path: &std::path::Path, problem: &str) {
        self.print(&format!(
            "resuming: {} {problem}: frame {frame} is rendered again",
            path.display()
        ));
    }

    fn resumed(&mut self, complete: usize, of: usize) {
        self.print(&format!(
            "resuming: {complete} of {of} frame(s) already complete"
        ));
    }

    fn started(&mut self, frames: u64) {
        self.bar = Some(progress_bar(frames));
    }

    fn frame_written(&mut self, frame: &WrittenFrame) {
        self.print(&frame_line(frame));
        if let Some(note) = nonfinite_note(frame) {
            self.above_bar(|| eprintln!("{note}"));
        }
        if let Some(bar) = &self.bar {
            bar.inc(1);
        }
    }

    fn frame_checked(&mut self, judged: &FrameDiff) {
        self.print(&check_line(judged));
    }

    fn stopping(&mut self, frame: u32) {
        self.print(&format!("--fail-fast: stopping at frame {frame}"));
    }

    fn finished(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}

/// The line printed for each rendered frame.
fn frame_line(f: &WrittenFrame) -> String {
    let (frame, record) = (f.frame, f.record);
    format!(
        "frame {frame:04}  t={:.3}s  {:>8.1} ms  {:>6.2} Mrays  moved {:>7}  lod_recomputed {:>7}{}  -> {}",
        f.time_s,
        record.total_ms,
        record.rays as f64 / 1e6,
        record.update.moved_triangles,
        record.update.lod_recomputed,
        if record.update.rebuild {
            "  rebuild"
        } else {
            ""
        },
        f.path.display()
    )
}

/// The note on stderr for a frame some of whose samples came out infinite or NaN (shading
/// overflowed single precision: a light or material far too bright) and were written
/// black, as the frame's record counts them; none for a frame without such samples.
fn nonfinite_note(f: &WrittenFrame) -> Option<String> {
    let n = f.record.nonfinite_samples;
    (n > 0).then(|| {
        format!(
            "note: frame {:04}: {n} sample(s) came out infinite or NaN (a light or material \
             too bright for single precision?) and were written black \
             (`nonfinite_samples` in stats.jsonl)",
            f.frame
        )
    })
}

/// The line printed for each checked frame.
fn check_line(judged: &FrameDiff) -> String {
    if let Some(problem) = &judged.problem {
        return format!("check frame {:04}: not compared: {problem}", judged.frame);
    }
    format!(
        "check frame {:04}: {}  psnr {} dB  flip {:.5}  max abs {}",
        judged.frame,
        if judged.passed { "pass" } else { "FAIL" },
        crate::metrics::format_psnr(judged.metrics.psnr_db),
        judged.metrics.mean_flip,
        judged.metrics.max_abs
    )
}

/// The lines at the end of a render: what was written where, then the check's verdict.
pub fn print_sequence_end(report: &SequenceReport) {
    println!(
        "rendered {} frame(s) {}..{} in {:.1} s into {} ({})",
        report.records,
        report.frames.start,
        report.frames.end,
        report.elapsed.as_secs_f64(),
        report.dir.display(),
        report
            .summary
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    println!("page: {}", report.page.display());
    if let Some(check) = &report.check {
        print_check_end(check);
    }
}

/// The verdict of a check and where its report and page are.
pub fn print_check_end(check: &CheckFinished) {
    println!("{}", check.summary);
    println!("report: {}", check.report.display());
    println!("page: {}", check.page.display());
}
