//! The Open Job Description template (`examples/cluster/openjd/render.template.yaml`) run
//! by the reference runtime, `openjd-cli` from PyPI (`.ci/run` installs it): `openjd run
//! --step Merge --run-dependencies` runs every Render task (one per shard, one after
//! another in a local session), then the Merge step; the output must equal a
//! single-machine render. A scene whose frames fail stops the job with a failed task, the
//! Merge step never runs, and the frames written before the failure are whole. Without
//! `openjd-cli` the tests print why they skipped, and fail when `CI` is set.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use common::farm::{
    FIRST_FAILING_FRAME, MIPRAY, SCENE, assert_complete_sequence, assert_records_match_reference,
    example, frame_files, frame_name, frames_arg, render_reference, shard_starts, temporaries,
    write_failing_scene,
};
use common::shared_data::skip_or_fail;

/// `python3 -m openjd` when openjd-cli is installed (the module form needs no script on
/// PATH).
fn openjd() -> Option<Command> {
    let probe = Command::new("python3")
        .args(["-m", "openjd", "--version"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        skip_or_fail("openjd-cli is not installed (pip install openjd-cli)");
        return None;
    }
    let mut command = Command::new("python3");
    command.args(["-m", "openjd"]);
    Some(command)
}

fn template() -> String {
    example("openjd/render.template.yaml").display().to_string()
}

/// `openjd run` of the whole job with the test's parameters.
fn run_job(
    mut openjd: Command,
    scene: &Path,
    frames: &str,
    size: &str,
    shards: u32,
    out: &Path,
) -> Output {
    openjd
        .args(["run", &template(), "--step", "Merge", "--run-dependencies"])
        .args(["-p", &format!("Mipray={MIPRAY}")])
        .args(["-p", &format!("Scene={}", scene.display())])
        .args(["-p", &format!("Frames={frames}")])
        .args(["-p", &format!("Size={size}")])
        .args(["-p", &format!("Shards={shards}")])
        .args(["-p", &format!("OutputDir={}", out.display())])
        .output()
        .expect("run openjd")
}

fn text(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned() + &String::from_utf8_lossy(&output.stderr)
}

#[test]
fn template_checks() {
    let Some(mut openjd) = openjd() else { return };
    let output = openjd.args(["check", &template()]).output().unwrap();
    assert!(output.status.success(), "{}", text(&output));
}

#[test]
fn template_renders_shards_and_merges_like_one_machine() {
    let Some(openjd) = openjd() else { return };
    let started = std::time::Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let frames = 0..9;
    let (size, shards) = ("160x90", 3);
    let out = dir.path().join("farm");
    let output = run_job(
        openjd,
        Path::new(SCENE),
        &frames_arg(&frames),
        size,
        shards,
        &out,
    );
    let log = text(&output);
    assert!(output.status.success(), "openjd run: {log}");
    // Every shard ran as its own task, then the merge checked the whole range.
    for index in 0..shards {
        assert!(
            log.contains(&format!("mipray shard {index}/{shards} of")),
            "{log}"
        );
    }
    assert!(
        log.contains(&format!("complete: every frame of {}", frames_arg(&frames))),
        "{log}"
    );
    assert!(out.join("report.svg").is_file());
    let reference = dir.path().join("reference");
    render_reference(&frames, size, &reference);
    assert_complete_sequence(&reference, &out, &frames);
    let first_frames = shard_starts(&out);
    assert_eq!(first_frames.len(), shards as usize);
    assert_records_match_reference(&reference, &out, &frames, Some(&first_frames));
    println!(
        "OpenJD job done in {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

#[test]
fn failing_task_stops_the_job_before_the_merge() {
    let Some(openjd) = openjd() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = write_failing_scene(dir.path());
    let out = dir.path().join("farm");
    // Shard 0 renders frames 0..3; shard 1 renders frame 3, then fails on frame 4.
    let output = run_job(openjd, &scene, "0..6", "32x18", 2, &out);
    let log = text(&output);
    assert!(!output.status.success(), "openjd run exited 0: {log}");
    assert!(log.contains("non-finite vertex"), "{log}");
    assert!(
        !log.contains("complete: every frame"),
        "the merge ran: {log}"
    );
    assert!(!out.join("report.svg").exists(), "the merge ran");
    let expected: std::collections::BTreeSet<String> =
        (0..FIRST_FAILING_FRAME).map(frame_name).collect();
    assert_eq!(frame_files(&out), expected);
    for name in &expected {
        image::open(out.join(name)).unwrap_or_else(|e| panic!("{name} is not a whole PNG: {e}"));
    }
    assert_eq!(temporaries(&out), Vec::<String>::new());
}
