//! The run layer from the library, without the CLI: what `run::render_sequence` tells its
//! `SequenceProgress` (in order) and what it returns, for a fresh run, a resumed one, a
//! passing check and a failing check with `--fail-fast`.

mod common;

use std::path::Path;

use common::scenes::{dynamic_scene, settings};
use mipray::diff::{DiffMetric, DiffOptions, FrameDiff, Verdict};
use mipray::frame::{FrameClock, LevelImage, Renderer};
use mipray::lod::LodMethod;
use mipray::record::RunIdentity;
use mipray::run::{
    Check, FrameFormat, Resume, SequenceOutput, SequenceProgress, SequenceReport, WrittenFrame,
    render_sequence,
};

/// Every call a sequence made, as text.
#[derive(Default)]
struct Recorder(Vec<String>);

impl SequenceProgress for Recorder {
    fn resumed(&mut self, complete: usize, of: usize) {
        self.0.push(format!("resumed {complete}/{of}"));
    }
    fn started(&mut self, frames: u64) {
        self.0.push(format!("started {frames}"));
    }
    fn frame_written(&mut self, frame: &WrittenFrame) {
        assert_eq!(frame.record.frame, frame.frame);
        assert!(frame.path.is_file(), "{}", frame.path.display());
        self.0.push(format!("frame {}", frame.frame));
    }
    fn frame_checked(&mut self, judged: &FrameDiff) {
        self.0
            .push(format!("checked {} {}", judged.frame, judged.passed));
    }
    fn stopping(&mut self, frame: u32) {
        self.0.push(format!("stopping {frame}"));
    }
    fn finished(&mut self) {
        self.0.push("finished".into());
    }
}

fn output(dir: &Path, resume: Resume) -> SequenceOutput {
    SequenceOutput {
        dir: dir.to_path_buf(),
        format: FrameFormat::Png,
        shard: None,
        resume,
        level_image: LevelImage::Skip,
        identity: RunIdentity::default(),
    }
}

fn run(
    lod: LodMethod,
    frames: std::ops::Range<u32>,
    out: &SequenceOutput,
    check: Option<&Check>,
) -> (SequenceReport, Vec<String>) {
    let mut renderer = Renderer::new(dynamic_scene().0, settings(32, 24, lod));
    let mut recorder = Recorder::default();
    let report = render_sequence(
        &mut renderer,
        frames,
        FrameClock::Fps(30.0),
        out,
        check,
        &mut recorder,
    )
    .expect("the sequence renders");
    (report, recorder.0)
}

#[test]
fn a_sequence_tells_each_step_and_returns_what_it_wrote() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("paper");
    let (report, calls) = run(LodMethod::Paper, 0..3, &output(&dir, Resume::Restart), None);
    assert_eq!(
        calls,
        ["started 3", "frame 0", "frame 1", "frame 2", "finished"]
    );
    assert_eq!((report.frames.clone(), report.records), (0..3, 3));
    assert_eq!(report.dir, dir);
    assert_eq!(report.summary, dir.join("summary.json"));
    assert!(report.summary.is_file() && report.page.is_file());
    assert!(report.check.is_none());

    // Resumed over a longer range: the three frames on disk are not rendered again.
    let (report, calls) = run(
        LodMethod::Paper,
        0..5,
        &output(&dir, Resume::SkipComplete),
        None,
    );
    assert_eq!(
        calls,
        ["resumed 3/5", "started 2", "frame 3", "frame 4", "finished"]
    );
    assert_eq!(report.records, 5);
}

#[test]
fn a_checked_sequence_reports_each_judgement_and_the_verdict() {
    let tmp = tempfile::tempdir().unwrap();
    let reference = tmp.path().join("reference");
    run(
        LodMethod::Paper,
        0..2,
        &output(&reference, Resume::Restart),
        None,
    );
    let check = |fail_fast| Check {
        reference: reference.clone(),
        options: DiffOptions {
            metric: DiffMetric::MaxAbs,
            threshold: 0.0,
            out: tmp.path().join("check"),
        },
        fail_fast,
        junit: None,
    };

    let same = output(&tmp.path().join("same"), Resume::Restart);
    let (report, calls) = run(LodMethod::Paper, 0..2, &same, Some(&check(false)));
    assert_eq!(
        calls,
        [
            "started 2",
            "frame 0",
            "checked 0 true",
            "frame 1",
            "checked 1 true",
            "finished"
        ]
    );
    let finished = report.check.expect("a checked run reports its check");
    assert_eq!(finished.verdict, Verdict::Passed);
    assert!(finished.report.is_file() && finished.page.is_file());

    // No texture filtering against the reference's: frame 0 differs and stops the run.
    let other = output(&tmp.path().join("other"), Resume::Restart);
    let (report, calls) = run(LodMethod::None, 0..2, &other, Some(&check(true)));
    assert_eq!(
        calls,
        [
            "started 2",
            "frame 0",
            "checked 0 false",
            "stopping 0",
            "finished"
        ]
    );
    assert_eq!(report.records, 1);
    assert_eq!(report.check.map(|c| c.verdict), Some(Verdict::Failed));
}
