//! `mipray::report` (and the stats-file reader it uses, `mipray::record`) end to end: stats
//! files written to a temporary folder as a render (or
//! several shards of one, or an older version) would leave them, then loaded, summarised
//! and plotted.

use std::fs;
use std::path::{Path, PathBuf};

use mipray::percentiles::Percentiles;
use mipray::record::{Phase, StatsFileError, load_records, load_sequence};
use mipray::report::{
    LOD_RECOMPUTED, MOVED_TRIANGLES, Metric, Quantities, RENDER_MS, TIMING_PHASES, report,
};
use serde_json::json;

/// A current-format record of frame `frame` with `render_ms` = `render_ms`.
///
/// The preprocessing phases add up to 4 ms every frame (`refit_ms` on refit frames,
/// `build_ms` on rebuild frames, which are the multiples of 5) and `total_ms` is
/// `render_ms + 4`.
fn record(frame: u32, render_ms: f64) -> String {
    let rebuild = frame.is_multiple_of(5);
    json!({
        "frame": frame,
        "time_s": f64::from(frame) / 24.0,
        "width": 64,
        "height": 36,
        "lod_method": "paper",
        "triangles": 100,
        "lights": 2,
        "spp": 1,
        "animate_ms": 1.0,
        "dirty_ms": 0.5,
        "refit_ms": if rebuild { 0.0 } else { 1.5 },
        "build_ms": if rebuild { 1.5 } else { 0.0 },
        "rebuild": rebuild,
        "sah_ratio": 1.05,
        "lod_update_ms": 1.0,
        "moved_triangles": frame * 10,
        "deformed_triangles": 5,
        "lod_recomputed": frame * 10 + 5,
        "render_ms": render_ms,
        "total_ms": render_ms + 4.0,
        "rays": 1000 * (u64::from(frame) + 1),
        "mip_histogram": [frame, 1, 0],
        "nonfinite_samples": 0
    })
    .to_string()
}

/// A record as written before the frame-loop fields (`dirty_ms`, `refit_ms`, `rebuild`,
/// `sah_ratio`, `moved_triangles`, `deformed_triangles`) existed.
fn old_record(frame: u32) -> String {
    json!({
        "frame": frame,
        "time_s": f64::from(frame) / 24.0,
        "width": 64,
        "height": 36,
        "lod_method": "paper",
        "triangles": 100,
        "lights": 1,
        "spp": 1,
        "animate_ms": 2.0,
        "build_ms": 3.0,
        "lod_update_ms": 1.0,
        "lod_recomputed": 100,
        "render_ms": 14.0,
        "total_ms": 20.0,
        "rays": 2304,
        "mip_histogram": [10, 5],
        "nonfinite_samples": 0
    })
    .to_string()
}

fn write_lines(path: &Path, lines: &[String]) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    fs::write(path, lines.join("\n") + "\n").unwrap();
}

/// Frames `frames` with `render_ms = frame + 1`.
fn records(frames: impl IntoIterator<Item = u32>) -> Vec<String> {
    frames
        .into_iter()
        .map(|f| record(f, f64::from(f) + 1.0))
        .collect()
}

/// Two shard folders of frames 0..20 (`render_ms` 1..=20): `a` holds the even frames and,
/// appended by a resumed render, frame 4 again; `b` holds the odd frames. The first
/// record of frame 4 has `render_ms` 999, which must be dropped.
fn two_shards(root: &Path) -> Vec<PathBuf> {
    let (a, b) = (root.join("a"), root.join("b"));
    let mut even = records([0, 2]);
    even.push(record(4, 999.0));
    even.extend(records((6..20).step_by(2)));
    even.push(record(4, 5.0));
    write_lines(&a.join("stats.jsonl"), &even);
    write_lines(&b.join("stats.jsonl"), &records((1..20).step_by(2)));
    vec![a, b]
}

/// The contents of the SVG's `<text>` elements, trimmed.
fn svg_texts(svg: &str) -> Vec<&str> {
    svg.split("<text")
        .skip(1)
        .map(|t| {
            t.split_once('>')
                .unwrap()
                .1
                .split("</text>")
                .next()
                .unwrap()
                .trim()
        })
        .collect()
}

fn frames_of(dirs: &[PathBuf]) -> Vec<u32> {
    load_records(dirs)
        .unwrap()
        .iter()
        .map(|r| r.frame())
        .collect()
}

#[test]
fn shards_merge_sorted_keeping_the_last_duplicate() {
    let tmp = tempfile::tempdir().unwrap();
    let dirs = two_shards(tmp.path());
    let sequence = load_sequence(&dirs).unwrap();
    let frames: Vec<u32> = sequence.records.iter().map(|r| r.frame()).collect();
    assert_eq!(frames, (0..20).collect::<Vec<_>>());
    assert_eq!(sequence.records[4].value(&RENDER_MS), Some(5.0));
    assert_eq!(sequence.duplicates_dropped, 1);
    assert_eq!(
        sequence.files,
        [dirs[0].join("stats.jsonl"), dirs[1].join("stats.jsonl")]
    );
}

#[test]
fn shard_files_in_one_folder_merge() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("out");
    write_lines(&dir.join("stats.shard-1-of-2.jsonl"), &records([1, 3]));
    write_lines(&dir.join("stats.shard-0-of-2.jsonl"), &records([0, 2]));
    fs::write(dir.join("summary.json"), "{}").unwrap();
    fs::write(dir.join("notes.jsonl"), "not a record\n").unwrap();
    let sequence = load_sequence(std::slice::from_ref(&dir)).unwrap();
    assert_eq!(
        sequence
            .records
            .iter()
            .map(|r| r.frame())
            .collect::<Vec<_>>(),
        [0, 1, 2, 3]
    );
    assert_eq!(
        sequence.files,
        [
            dir.join("stats.shard-0-of-2.jsonl"),
            dir.join("stats.shard-1-of-2.jsonl")
        ]
    );
    // A stats file may also be named directly; naming it twice reads it once.
    let file = dir.join("stats.shard-0-of-2.jsonl");
    assert_eq!(frames_of(&[file.clone(), file]), [0, 2]);
}

#[test]
fn percentiles_of_one_to_twenty_by_nearest_rank() {
    // Median of an even count: mean of the middle two, (10 + 11) / 2.
    // p95 by nearest rank: the value of rank ceil(0.95 * 20) = 19.
    let p = Percentiles::of((1..=20).rev().map(f64::from));
    assert_eq!((p.min, p.median, p.p95, p.max), (1.0, 10.5, 19.0, 20.0));
    // ceil(0.95 * 21) = 20; ceil(0.95 * 3) = 3.
    assert_eq!(Percentiles::of((1..=21).map(f64::from)).p95, 20.0);
    assert_eq!(Percentiles::of([3.0, 1.0, 2.0]).p95, 3.0);
    // NaN is left out, not sorted in.
    assert_eq!(Percentiles::of([f64::NAN, 2.0, 8.0]).median, 5.0);
}

#[test]
fn report_table_has_exact_values_for_merged_shards() {
    let tmp = tempfile::tempdir().unwrap();
    let dirs = two_shards(tmp.path());
    let summary = report(&dirs, &tmp.path().join("report.svg")).unwrap();

    let row = |name: &str| {
        let mut rows = summary.timings.iter().chain(&summary.counts);
        *rows
            .find(|r| r.name == name)
            .unwrap_or_else(|| panic!("no row {name}"))
    };
    let render = row("render_ms");
    assert_eq!(render.frames, 20);
    assert_eq!(
        render.percentiles,
        Percentiles {
            min: 1.0,
            median: 10.5,
            p95: 19.0,
            max: 20.0
        }
    );
    let rays = row("rays").percentiles;
    assert_eq!(
        (rays.min, rays.median, rays.p95, rays.max),
        (1000.0, 10500.0, 19000.0, 20000.0)
    );
    let moved = row("moved_triangles").percentiles;
    assert_eq!((moved.median, moved.p95), (95.0, 180.0));
    let names: Vec<&str> = summary.timings.iter().map(|r| r.name).collect();
    assert_eq!(
        names,
        [
            "animate_ms",
            "dirty_ms",
            "refit_ms",
            "build_ms",
            "lod_update_ms",
            "render_ms",
            "total_ms"
        ]
    );

    assert_eq!(summary.frames, 20);
    assert_eq!(summary.stats_files.len(), 2);
    assert_eq!(summary.duplicates_dropped, 1);
    assert_eq!(summary.rebuilds, Some(4));

    let text = summary.to_string();
    for line in [
        "| phase | min | median | p95 | max |",
        "| render_ms | 1.000 | 10.500 | 19.000 | 20.000 |",
        "| total_ms | 5.000 | 14.500 | 23.000 | 24.000 |",
        "| refit_ms | 0.000 | 1.500 | 1.500 | 1.500 |",
        "| moved_triangles | 0 | 95 | 180 | 190 |",
        "| lod_recomputed | 5 | 100 | 185 | 195 |",
        "| triangles | 100 | 100 | 100 | 100 |",
        "- frames: 20 (0 to 19, 0 missing)",
        "- duplicates dropped: 1",
        "- rebuilds: 4",
    ] {
        assert!(
            text.lines().any(|l| l == line),
            "missing line {line:?} in\n{text}"
        );
    }
    assert!(text.contains("- shards merged: 2 ("), "{text}");
}

#[test]
fn preprocessing_share_on_known_data() {
    let tmp = tempfile::tempdir().unwrap();
    let dirs = two_shards(tmp.path());
    let summary = report(&dirs, &tmp.path().join("report.svg")).unwrap();
    // Each frame: animate 1 + dirty 0.5 + (refit or build) 1.5 + lod_update 1 = 4 ms;
    // total = render + 4, render 1..=20 sums to 210: 80 / (210 + 80).
    let share = summary.preprocessing.clone().unwrap();
    assert!(
        (share.share - 80.0 / 290.0).abs() < 1e-12,
        "{}",
        share.share
    );
    assert_eq!(
        share.phases,
        [
            "animate_ms",
            "dirty_ms",
            "refit_ms",
            "build_ms",
            "lod_update_ms"
        ]
    );
    let text = summary.to_string();
    assert!(
        text.contains(
            "- preprocessing share: 27.6 % of total_ms \
             (animate_ms + dirty_ms + refit_ms + build_ms + lod_update_ms)"
        ),
        "{text}"
    );
}

#[test]
fn old_format_records_load_with_new_fields_absent() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("old");
    write_lines(
        &dir.join("stats.jsonl"),
        &(0..4).map(old_record).collect::<Vec<_>>(),
    );
    let loaded = load_records(std::slice::from_ref(&dir)).unwrap();
    assert_eq!(loaded.len(), 4);
    let phase = |p| loaded[0].value(&Metric::phase(p));
    assert_eq!(
        (
            phase(Phase::Dirty),
            phase(Phase::Refit),
            loaded[0].rebuilt()
        ),
        (None, None, None)
    );
    assert_eq!(loaded[0].value(&MOVED_TRIANGLES), None);
    assert_eq!(
        (phase(Phase::Build), loaded[0].value(&LOD_RECOMPUTED)),
        (Some(3.0), Some(100.0))
    );

    let svg_path = tmp.path().join("old.svg");
    let summary = report(std::slice::from_ref(&dir), &svg_path).unwrap();
    let names: Vec<&str> = summary
        .timings
        .iter()
        .chain(&summary.counts)
        .map(|r| r.name)
        .collect();
    assert_eq!(
        names,
        [
            "animate_ms",
            "build_ms",
            "lod_update_ms",
            "render_ms",
            "total_ms",
            "lod_recomputed",
            "rays",
            "triangles"
        ]
    );
    assert_eq!(summary.rebuilds, None);
    // (2 + 3 + 1) / 20 per frame.
    let share = summary.preprocessing.clone().unwrap();
    assert_eq!(share.phases, ["animate_ms", "build_ms", "lod_update_ms"]);
    assert!((share.share - 0.3).abs() < 1e-12);
    let text = summary.to_string();
    assert!(
        !text.contains("dirty_ms") && !text.contains("moved_triangles"),
        "{text}"
    );
    assert!(
        text.contains("- rebuilds: n/a (no rebuild field)"),
        "{text}"
    );

    // Absent phases are not plotted either.
    let svg = fs::read_to_string(&svg_path).unwrap();
    let texts = svg_texts(&svg);
    assert!(
        texts.contains(&"animate_ms") && texts.contains(&"lod_recomputed"),
        "{texts:?}"
    );
    assert!(!svg.contains("dirty_ms") && !svg.contains("moved_triangles"));
}

#[test]
fn old_and_new_records_mix_with_partial_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("mixed");
    let mut lines: Vec<String> = (0..2).map(old_record).collect();
    lines.extend(records(2..4));
    write_lines(&dir.join("stats.jsonl"), &lines);
    let summary = report(std::slice::from_ref(&dir), &tmp.path().join("m.svg")).unwrap();
    let text = summary.to_string();
    assert!(
        text.contains("| dirty_ms (2 of 4 frames) | 0.500 | 0.500 | 0.500 | 0.500 |"),
        "{text}"
    );
    // animate_ms: 2, 2 (old) and 1, 1 (new).
    assert!(
        text.contains("| animate_ms | 1.000 | 1.500 | 2.000 | 2.000 |"),
        "{text}"
    );
}

#[test]
fn malformed_line_error_names_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("bad");
    let path = dir.join("stats.jsonl");
    let mut lines = records([0, 1]);
    lines.push(r#"{"frame": 2, "render_ms": "#.to_string());
    lines.extend(records([3]));
    write_lines(&path, &lines);
    let err = load_records(std::slice::from_ref(&dir)).unwrap_err();
    assert!(
        matches!(&err, StatsFileError::Json { line: 3, .. }),
        "{err:?}"
    );
    let message = err.to_string();
    assert!(
        message.starts_with(&format!("{}:3: invalid JSON", path.display())),
        "{message}"
    );
    // `report` fails the same way and writes no plot.
    let svg = tmp.path().join("bad.svg");
    assert!(report(&[dir], &svg).is_err());
    assert!(!svg.exists());
}

#[test]
fn record_errors_name_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        (r#"{"render_ms": 1.0}"#, "missing `frame`"),
        (
            r#"{"frame": 1, "rebuild": "yes"}"#,
            "`rebuild` is \"yes\", expected true or false",
        ),
        (
            r#"{"frame": -1}"#,
            "`frame` is -1, expected a non-negative integer in range",
        ),
    ];
    for (i, (bad, reason)) in cases.into_iter().enumerate() {
        let path = tmp.path().join(format!("case{i}")).join("stats.jsonl");
        // Line 2 after a blank line 1: blank lines are skipped but still counted.
        write_lines(&path, &[String::new(), bad.to_string()]);
        let message = load_records(&[path.parent().unwrap().to_path_buf()])
            .unwrap_err()
            .to_string();
        assert_eq!(message, format!("{}:2: {reason}", path.display()));
    }
}

#[test]
fn no_records_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("empty");
    write_lines(&dir.join("stats.jsonl"), &[String::new()]);
    let message = load_records(std::slice::from_ref(&dir))
        .unwrap_err()
        .to_string();
    assert_eq!(message, format!("no frame records in {}", dir.display()));

    let none = tmp.path().join("none");
    fs::create_dir_all(&none).unwrap();
    let message = load_records(std::slice::from_ref(&none))
        .unwrap_err()
        .to_string();
    assert_eq!(
        message,
        format!("{}: no stats.jsonl or stats.shard-*.jsonl", none.display())
    );

    let missing = tmp.path().join("missing");
    let message = load_records(std::slice::from_ref(&missing))
        .unwrap_err()
        .to_string();
    assert!(
        message.starts_with(&missing.display().to_string()),
        "{message}"
    );
    assert!(matches!(
        load_records(&[]),
        Err(StatsFileError::Empty { .. })
    ));
}

#[test]
fn svg_plot_has_lines_and_a_legend_for_each_phase() {
    let tmp = tempfile::tempdir().unwrap();
    let dirs = two_shards(tmp.path());
    let out = tmp.path().join("plots");
    let svg_path = out.join("report.svg");
    let summary = report(&dirs, &svg_path).unwrap();
    assert_eq!(summary.svg, svg_path);

    let svg = fs::read_to_string(&svg_path).unwrap();
    assert!(svg.trim_start().starts_with("<svg"), "{}", &svg[..80]);
    assert!(svg.trim_end().ends_with("</svg>"));
    assert!(svg.contains("<path") || svg.contains("<polyline"));
    let texts = svg_texts(&svg);
    for name in TIMING_PHASES.iter().map(|m| m.name).chain([
        "moved_triangles",
        "deformed_triangles",
        "lod_recomputed",
    ]) {
        assert!(texts.contains(&name), "no legend text {name}: {texts:?}");
    }
    for label in [
        "frame",
        "time per frame (ms, log scale)",
        "triangles per frame",
    ] {
        assert!(texts.contains(&label), "no axis label {label}: {texts:?}");
    }
    // One line per plotted quantity, 7 phases + 3 counts, each drawn as at least one
    // segment (plus its legend swatch).
    assert!(
        svg.matches("<polyline").count() >= 2 * 10,
        "{}",
        svg.matches("<polyline").count()
    );
    // Written atomically: nothing else left in the folder.
    let names: Vec<_> = fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["report.svg"]);
}
