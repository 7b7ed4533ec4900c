//! The merge step every farm example ends with, `mipray report DIR --expect-frames A..B`:
//! it passes when every frame of the range has its record and its frame file, and
//! otherwise exits non-zero naming the missing frames, so a shard that failed, was
//! cancelled or never ran cannot go unnoticed.

mod common;

use common::farm::{MIPRAY, SCENE};
use std::process::Command;

fn mipray(args: &[&str]) -> std::process::Output {
    Command::new(MIPRAY)
        .args(args)
        .output()
        .expect("run mipray")
}

#[test]
fn merge_fails_naming_the_frames_a_shard_did_not_render() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    // Shards 0 and 2 of 3 over frames 0..9 render 0..3 and 6..9; shard 1 never runs.
    for shard in ["0/3", "2/3"] {
        let rendered = render(dir.path(), "0..9", "32x18", &["--shard", shard]);
        assert!(rendered.status.success(), "{rendered:?}");
    }
    let merged = mipray(&["report", out, "--expect-frames", "0..9"]);
    let stderr = String::from_utf8_lossy(&merged.stderr);
    assert_eq!(merged.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("3 frame(s) of 0..9 have no record or no frame file: 3..6"),
        "{stderr}"
    );
    // The report itself is still written, for a look at what is there.
    assert!(dir.path().join("report.svg").is_file());

    // A frame needs both its file and its record: here frames 6..9 have files but no
    // records, and 0..3 records but no files.
    let alone = dir.path().join("alone");
    std::fs::create_dir(&alone).unwrap();
    for frame in 6..9 {
        let name = format!("frame_{frame:04}.png");
        std::fs::copy(dir.path().join(&name), alone.join(&name)).unwrap();
    }
    let stats = "stats.shard-0-of-3.jsonl";
    std::fs::copy(dir.path().join(stats), alone.join(stats)).unwrap();
    let merged = mipray(&["report", alone.to_str().unwrap(), "--expect-frames", "0..9"]);
    let stderr = String::from_utf8_lossy(&merged.stderr);
    assert!(!merged.status.success());
    assert!(
        stderr.contains("9 frame(s) of 0..9 have no record or no frame file: 0..9"),
        "{stderr}"
    );

    // The frames the shards did render are complete.
    let merged = mipray(&["report", out, "--expect-frames", "6..9"]);
    assert!(merged.status.success(), "{merged:?}");
    let stdout = String::from_utf8_lossy(&merged.stdout);
    assert!(
        stdout.contains("complete: every frame of 6..9 has its record and frame file"),
        "{stdout}"
    );

    // A bad range is an argument error naming the flag.
    let bad = mipray(&["report", out, "--expect-frames", "9..3"]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--expect-frames"));
}

/// `mipray render SCENE --frames FRAMES --size SIZE --out OUT` and `extra`.
fn render(out: &std::path::Path, frames: &str, size: &str, extra: &[&str]) -> std::process::Output {
    let out = out.to_str().unwrap();
    let mut args = vec![
        "render", SCENE, "--frames", frames, "--size", size, "--out", out,
    ];
    args.extend_from_slice(extra);
    mipray(&args)
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A resume, a shard beside other shards, and a merge each refuse frames of another run
/// (here another size), naming the file and the setting; a resume is refused before
/// anything is rendered or rewritten.
#[test]
fn frames_of_other_settings_are_never_mixed() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seq");
    assert!(render(&out, "0..3", "48x27", &[]).status.success());
    let stats_before = std::fs::read(out.join("stats.jsonl")).unwrap();
    let resumed = render(&out, "0..5", "40x20", &["--resume"]);
    let message = stderr(&resumed);
    assert_eq!(resumed.status.code(), Some(1), "{message}");
    assert!(
        message.contains(&format!("{}: cannot resume", out.display()))
            && message.contains("size 48x27 there, 40x20 in this render")
            && message.contains("without --resume"),
        "{message}"
    );
    assert!(
        !out.join("frame_0003.png").exists(),
        "rendered before refusing"
    );
    assert_eq!(
        std::fs::read(out.join("stats.jsonl")).unwrap(),
        stats_before
    );
    // Another scene is refused too, by its file name and digest.
    let other_scene = common::farm::write_failing_scene(dir.path());
    let resumed = mipray(&[
        "render",
        other_scene.to_str().unwrap(),
        "--frames",
        "0..3",
        "--size",
        "48x27",
        "--out",
        out.to_str().unwrap(),
        "--resume",
    ]);
    assert!(
        stderr(&resumed).contains("scene default.gltf#"),
        "{}",
        stderr(&resumed)
    );
    // The same settings resume (the identity is the same on every run).
    assert!(
        render(&out, "0..4", "48x27", &["--resume"])
            .status
            .success()
    );

    // Shards of one folder rendered at two sizes: the second is refused.
    let farm = dir.path().join("farm");
    assert!(
        render(&farm, "0..6", "32x18", &["--shard", "0/2"])
            .status
            .success()
    );
    let second = render(&farm, "0..6", "40x20", &["--shard", "1/2"]);
    assert_eq!(second.status.code(), Some(1), "{}", stderr(&second));
    assert!(
        stderr(&second)
            .contains("stats.shard-0-of-2.jsonl: its frames were rendered with other settings")
            && stderr(&second).contains("size 32x18 there, 40x20 in this render"),
        "{}",
        stderr(&second)
    );
    assert!(!farm.join("frame_0003.png").exists());

    // Two folders of different sizes merged: a warning without a completeness claim, a
    // failure with one.
    let small = dir.path().join("small");
    assert!(render(&small, "3..6", "32x18", &[]).status.success());
    let (seq, small) = (out.to_str().unwrap(), small.to_str().unwrap());
    let merged = mipray(&["report", seq, small]);
    assert!(merged.status.success(), "{}", stderr(&merged));
    assert!(
        stderr(&merged).contains("warning: frame 0 of")
            && stderr(&merged).contains("size 48x27 in the first, 32x18 in the second"),
        "{}",
        stderr(&merged)
    );
    let merged = mipray(&["report", seq, small, "--expect-frames", "0..6"]);
    assert_eq!(merged.status.code(), Some(1));
    assert!(
        stderr(&merged).contains("stats.jsonl were rendered with different settings"),
        "{}",
        stderr(&merged)
    );
}

/// Records written before the run identity existed load, resume and merge: an absent
/// identity is unknown, not a difference.
#[test]
fn records_without_an_identity_still_resume_and_merge() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("old");
    assert!(render(&out, "0..3", "32x18", &[]).status.success());
    let stats = out.join("stats.jsonl");
    let old: Vec<String> = std::fs::read_to_string(&stats)
        .unwrap()
        .lines()
        .map(|line| {
            let mut record: serde_json::Value = serde_json::from_str(line).unwrap();
            let object = record.as_object_mut().unwrap();
            assert!(object.remove("scene").is_some() && object.remove("settings").is_some());
            object.remove("scene_files");
            record.to_string()
        })
        .collect();
    std::fs::write(&stats, old.join("\n") + "\n").unwrap();
    let resumed = render(&out, "0..5", "32x18", &["--resume"]);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    assert!(String::from_utf8_lossy(&resumed.stdout).contains("3 of 5 frame(s) already complete"));
    let merged = mipray(&["report", out.to_str().unwrap(), "--expect-frames", "0..5"]);
    assert!(merged.status.success(), "{}", stderr(&merged));
}

/// A frame file cut short and a text file under a frame's name: a merge fails naming them,
/// and a resume renders them again, saying which and why.
#[test]
fn damaged_frame_files_are_missing_frames() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seq");
    assert!(render(&out, "0..6", "32x18", &[]).status.success());
    let cut = out.join("frame_0002.png");
    let whole = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &whole[..whole.len() / 2]).unwrap();
    std::fs::write(out.join("frame_0004.png"), "not a picture").unwrap();
    let seq = out.to_str().unwrap();
    let merged = mipray(&["report", seq, "--expect-frames", "0..6"]);
    let message = stderr(&merged);
    assert_eq!(merged.status.code(), Some(1), "{message}");
    assert!(
        message.contains("2 frame(s) of 0..6 have no record or no frame file: 2, 4")
            && message.contains("damaged frame files: ")
            && message.contains(&format!("{} cannot be decoded", cut.display())),
        "{message}"
    );
    let resumed = render(&out, "0..6", "32x18", &["--resume"]);
    let stdout = String::from_utf8_lossy(&resumed.stdout).into_owned();
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    assert!(
        stdout.contains("4 of 6 frame(s) already complete"),
        "{stdout}"
    );
    for frame in [2, 4] {
        let line = format!("frame_{frame:04}.png cannot be decoded");
        assert!(stdout.contains(&line), "{stdout}");
        assert!(
            stdout.contains(&format!("frame {frame} is rendered again")),
            "{stdout}"
        );
    }
    assert!(
        std::fs::read(&cut).unwrap() == whole,
        "frame 2 rendered again"
    );
    let merged = mipray(&["report", seq, "--expect-frames", "0..6"]);
    assert!(merged.status.success(), "{}", stderr(&merged));
}

/// A line that is not a record in the middle of a stats file (not the torn last line an
/// interrupted write leaves): `report` and a resume both refuse it, naming the file and
/// line, and the resume says how to go on; none of the records after it is dropped.
#[test]
fn a_bad_line_inside_a_stats_file_is_refused_by_report_and_resume_alike() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seq");
    assert!(render(&out, "0..4", "32x18", &[]).status.success());
    let stats = out.join("stats.jsonl");
    let mut lines: Vec<String> = std::fs::read_to_string(&stats)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    lines.insert(1, "garbage".into());
    std::fs::write(&stats, lines.join("\n") + "\n").unwrap();
    let at = format!("{}:2: invalid JSON", stats.display());
    let merged = mipray(&["report", out.to_str().unwrap()]);
    assert!(!merged.status.success());
    assert!(stderr(&merged).contains(&at), "{}", stderr(&merged));
    let resumed = render(&out, "0..4", "32x18", &["--resume"]);
    let message = stderr(&resumed);
    assert_eq!(resumed.status.code(), Some(1), "{message}");
    assert!(
        message.contains(&at)
            && message.contains("cannot resume")
            && message.contains("Remove or mend that line"),
        "{message}"
    );
    // Once mended, the resume keeps every record: nothing to render.
    lines.remove(1);
    std::fs::write(&stats, lines.join("\n") + "\n").unwrap();
    let resumed = render(&out, "0..4", "32x18", &["--resume"]);
    assert!(String::from_utf8_lossy(&resumed.stdout).contains("4 of 4 frame(s) already complete"));
}

/// A shard whose block of the range is empty (3 frames over 8 shards) succeeds, and its
/// summary says it has no frames instead of a size of 0 and an empty method.
#[test]
fn an_empty_shard_says_it_has_no_frames() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("farm");
    for shard in ["0/8", "7/8"] {
        let rendered = render(&out, "0..3", "32x18", &["--shard", shard]);
        assert!(rendered.status.success(), "{shard}: {}", stderr(&rendered));
    }
    let summary = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join(name)).unwrap()).unwrap()
    };
    let empty = summary("summary.shard-0-of-8.json");
    assert_eq!(empty["frames"], 0);
    for field in ["width", "height", "lod_method"] {
        assert!(empty[field].is_null(), "{field}: {empty}");
    }
    let full = summary("summary.shard-7-of-8.json");
    assert_eq!(
        (full["width"].as_u64(), full["lod_method"].as_str()),
        (Some(32), Some("paper"))
    );
}

/// Temporaries an interrupted writer left in a shared folder: a whole render resumed there
/// removes its own (no owner in the name) and keeps the shards' and `mipray report`'s, which
/// may be in the middle of their writes; a resumed shard removes its own page's; and
/// `mipray report` removes those of its own plot and page.
#[test]
fn each_run_removes_only_the_temporaries_it_owns() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seq");
    let ok = |o: std::process::Output| assert!(o.status.success(), "{}", stderr(&o));
    ok(render(&out, "0..4", "16x9", &["--shard", "1/2"]));
    let shard_1 = [
        ".frame_0003.png.shard-1-of-2.22.tmp",
        ".index.html.shard-1-of-2.22.tmp",
        ".stats.shard-1-of-2.jsonl.shard-1-of-2.22.tmp",
    ];
    let whole = [".frame_0003.png.33.tmp", ".index.html.33.tmp"];
    let report = [".index.html.report.44.tmp", ".report.svg.report.44.tmp"];
    for name in shard_1.iter().chain(&whole).chain(&report) {
        std::fs::write(out.join(name), b"half").unwrap();
    }
    let left = || {
        let mut names = common::farm::temporaries(&out);
        names.sort();
        names
    };
    let sorted = |names: &[&[&str]]| {
        let mut all: Vec<String> = names.concat().iter().map(|n| n.to_string()).collect();
        all.sort();
        all
    };
    ok(render(&out, "0..4", "16x9", &["--resume"]));
    assert_eq!(left(), sorted(&[&shard_1, &report]));
    ok(render(
        &out,
        "0..4",
        "16x9",
        &["--shard", "1/2", "--resume"],
    ));
    assert_eq!(left(), sorted(&[&report]));
    ok(mipray(&["report", out.to_str().unwrap()]));
    assert_eq!(left(), Vec::<String>::new());
}

/// A copy of the default scene (`default.gltf`, its `.bin` and two textures) in `dir`.
fn copy_default_scene(dir: &std::path::Path) -> std::path::PathBuf {
    let animations = std::path::Path::new(SCENE).parent().unwrap();
    std::fs::create_dir_all(dir).unwrap();
    for name in [
        "default.gltf",
        "default.bin",
        "default_box_brick.png",
        "default_floor_checker.png",
    ] {
        std::fs::copy(animations.join(name), dir.join(name)).unwrap();
    }
    dir.join("default.gltf")
}

fn render_scene(
    scene: &std::path::Path,
    out: &std::path::Path,
    extra: &[&str],
) -> std::process::Output {
    let (scene, out) = (scene.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec![
        "render", scene, "--frames", "0..3", "--size", "16x9", "--out", out,
    ];
    args.extend_from_slice(extra);
    mipray(&args)
}

/// A run's identity covers every file the scene load read, not only the scene file: a
/// resume after a texture or the buffer changed (the `.gltf` unchanged) is refused, naming
/// `scene files`; with the files as they were, it resumes.
#[test]
fn a_changed_texture_or_buffer_is_another_run() {
    let dir = tempfile::tempdir().unwrap();
    let scene = copy_default_scene(&dir.path().join("scene"));
    let out = dir.path().join("seq");
    let first = render_scene(&scene, &out, &[]);
    assert!(first.status.success(), "{}", stderr(&first));
    let stats = std::fs::read_to_string(out.join("stats.jsonl")).unwrap();
    assert!(stats.contains(r#""scene_files":"3 files#"#), "{stats}");
    for name in ["default_floor_checker.png", "default.bin"] {
        let path = scene.parent().unwrap().join(name);
        let original = std::fs::read(&path).unwrap();
        // One byte more: the PNG still decodes, the buffer still holds every view.
        let mut changed = original.clone();
        changed.push(0);
        std::fs::write(&path, &changed).unwrap();
        let refused = render_scene(&scene, &out, &["--resume"]);
        assert_eq!(
            refused.status.code(),
            Some(1),
            "{name}: {}",
            stderr(&refused)
        );
        assert!(
            stderr(&refused).contains("cannot resume") && stderr(&refused).contains("scene files"),
            "{name}: {}",
            stderr(&refused)
        );
        std::fs::write(&path, &original).unwrap();
    }
    let resumed = render_scene(&scene, &out, &["--resume"]);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
}

/// Records written before the identity covered the referenced files (the scene file's
/// digest only) still resume, and a resume of them is still refused when the scene file
/// changed.
#[test]
fn records_with_the_scene_file_digest_only_still_resume() {
    let dir = tempfile::tempdir().unwrap();
    let scene = copy_default_scene(&dir.path().join("scene"));
    let out = dir.path().join("seq");
    assert!(render_scene(&scene, &out, &[]).status.success());
    let stats = out.join("stats.jsonl");
    let older: Vec<String> = std::fs::read_to_string(&stats)
        .unwrap()
        .lines()
        .map(|line| {
            let mut record: serde_json::Value = serde_json::from_str(line).unwrap();
            let object = record.as_object_mut().unwrap();
            assert!(object.remove("scene_files").is_some());
            assert!(
                object["scene"]
                    .as_str()
                    .unwrap()
                    .starts_with("default.gltf#")
            );
            record.to_string()
        })
        .collect();
    std::fs::write(&stats, older.join("\n") + "\n").unwrap();
    std::fs::remove_file(out.join("frame_0002.png")).unwrap();
    let resumed = render_scene(&scene, &out, &["--resume"]);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    assert!(
        String::from_utf8_lossy(&resumed.stdout).contains("2 of 3 frame(s) already complete"),
        "{}",
        String::from_utf8_lossy(&resumed.stdout)
    );
    let gltf = std::fs::read_to_string(&scene).unwrap();
    std::fs::write(&scene, gltf + " ").unwrap();
    let refused = render_scene(&scene, &out, &["--resume"]);
    assert_eq!(refused.status.code(), Some(1), "{}", stderr(&refused));
    assert!(
        stderr(&refused).contains("scene default.gltf#"),
        "{}",
        stderr(&refused)
    );
}
