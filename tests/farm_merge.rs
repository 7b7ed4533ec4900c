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
        let rendered = mipray(&[
            "render", SCENE, "--frames", "0..9", "--size", "32x18", "--out", out, "--shard", shard,
        ]);
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
