//! `mipray compare` end to end: the files it writes, the numbers in them, the optional
//! frames, level views and Table 1, bad input, and determinism of everything but timing.
//!
//! Every run is tiny (a few dozen pixels, two frames, 4 reference samples, one repeat) so
//! the whole file stays within seconds in release; the numbers are checked for what holds
//! at any size (ranges, signs, order), not for values that depend on resolution.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Output;

mod common;

use common::mipray;

/// Every LOD method, in the order `compare` reports them by default.
const ALL_METHODS: [&str; 7] = [
    "none",
    "paper",
    "paper-cos",
    "cones",
    "diffs",
    "diffs-aniso",
    "diffs-ewa",
];

/// Bytes of LOD state per ray, by method, as the paper's memory column reads.
const BYTES_PER_RAY: [(&str, u32); 7] = [
    ("none", 0),
    ("paper", 4),
    ("paper-cos", 12),
    ("cones", 12),
    ("diffs", 48),
    ("diffs-aniso", 48),
    ("diffs-ewa", 48),
];

/// The columns `compare.csv` promises, in order.
const SUMMARY_COLUMNS: [&str; 11] = [
    "method",
    "bytes_per_ray",
    "ms_per_frame",
    "overhead_pct",
    "psnr",
    "ssim",
    "flip",
    "lod_bias",
    "lod_rms",
    "lod_under",
    "flicker",
];

/// Columns that measure time: they differ from run to run and are left out of the
/// determinism check.
const TIMING_COLUMNS: [&str; 3] = ["ms_per_frame", "overhead_pct", "ms"];

/// The files every run writes into `--out`.
const REPORT_FILES: [&str; 6] = [
    "compare.csv",
    "compare_frames.csv",
    "compare.md",
    "pareto.svg",
    "error_per_frame.svg",
    "mip_levels.svg",
];

/// The tiny run every test starts from; a test's own flags replace these by name.
const BASE_FLAGS: [(&str, &str); 4] = [
    ("--frames", "0..2"),
    ("--size", "48x27"),
    ("--reference-spp", "4"),
    ("--repeats", "1"),
];

/// The crate root: `default` resolves to `animations/default.gltf` relative to it.
fn crate_root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `mipray compare SCENE --out OUT` with [`BASE_FLAGS`], except those named in
/// `flags`, which come after them (a flag given twice would be a clap error, not the
/// error under test).
fn compare(scene: &str, out: &Path, flags: &[&str]) -> Output {
    let out = out.to_str().expect("temporary paths are UTF-8");
    let mut args = vec!["compare", scene, "--out", out];
    for (flag, value) in BASE_FLAGS {
        if !flags.contains(&flag) {
            args.extend([flag, value]);
        }
    }
    args.extend_from_slice(flags);
    mipray(&args, crate_root())
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Asserts that the run succeeded and did not panic on the way (a caught panic in a
/// worker could still end in exit 0).
fn assert_success(output: &Output, what: &str) {
    let err = stderr(output);
    assert!(
        output.status.success(),
        "{what}: expected exit 0, found {:?}; stderr:\n{err}",
        output.status.code()
    );
    assert!(
        !err.contains("panicked"),
        "{what}: expected no panic, found one in stderr:\n{err}"
    );
}

/// The header of a CSV file, split into column names.
fn csv_header(path: &Path) -> Vec<String> {
    let text = read_text(path);
    let first = text.lines().next().unwrap_or_else(|| {
        panic!(
            "{}: expected a header line, found an empty file",
            path.display()
        )
    });
    first.split(',').map(str::to_owned).collect()
}

/// The rows of a CSV file (no quoted fields: the method names need none), each as
/// column name to field, in file order.
fn read_csv(path: &Path) -> Vec<HashMap<String, String>> {
    let header = csv_header(path);
    read_text(path)
        .lines()
        .skip(1)
        .map(|line| {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(
                fields.len(),
                header.len(),
                "{}: expected {} fields per row as in the header, found {} in '{line}'",
                path.display(),
                header.len(),
                fields.len()
            );
            header
                .iter()
                .cloned()
                .zip(fields.into_iter().map(str::to_owned))
                .collect()
        })
        .collect()
}

fn read_text(path: &Path) -> String {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: expected a readable file, found {e}", path.display()))
}

/// The methods of the rows, in order.
fn methods(rows: &[HashMap<String, String>]) -> Vec<&str> {
    rows.iter().map(|r| r["method"].as_str()).collect()
}

/// Column `column` of `row` as a number (`nan`/`inf` parse too; callers check finiteness
/// where it matters).
fn number(row: &HashMap<String, String>, column: &str) -> f64 {
    let method = row.get("method").map_or("?", String::as_str);
    let field = row
        .get(column)
        .unwrap_or_else(|| panic!("{method}: expected a column '{column}', found none"));
    field.parse().unwrap_or_else(|_| {
        panic!("{method}: expected a number in column '{column}', found '{field}'")
    })
}

/// Column `column` of `row` as a finite number.
fn finite(row: &HashMap<String, String>, column: &str) -> f64 {
    let v = number(row, column);
    assert!(
        v.is_finite(),
        "{}: expected a finite {column}, found {v}",
        row["method"]
    );
    v
}

/// Whether `wanted` appears in `found` in the same relative order (other columns may sit
/// between or after them).
fn is_subsequence(wanted: &[&str], found: &[String]) -> bool {
    let mut found = found.iter();
    wanted.iter().all(|w| found.any(|f| f == w))
}

/// Parses an SVG as XML and returns the trimmed text of each of its `<text>` elements.
fn svg_texts(path: &Path) -> Vec<String> {
    let svg = read_text(path);
    let doc = roxmltree::Document::parse(&svg).unwrap_or_else(|e| {
        panic!(
            "{}: expected well-formed SVG, found an XML error: {e}",
            path.display()
        )
    });
    assert_eq!(
        doc.root_element().tag_name().name(),
        "svg",
        "{}: expected an <svg> root element",
        path.display()
    );
    doc.descendants()
        .filter(|n| n.has_tag_name("text"))
        .map(|n| {
            let text: String = n
                .descendants()
                .filter(|t| t.is_text())
                .filter_map(|t| t.text())
                .collect();
            text.trim().to_owned()
        })
        .collect()
}

/// A fresh `--out` folder inside its own temporary directory (the directory lives as
/// long as the returned guard).
fn out_dir() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("create a temporary directory");
    let out = dir.path().join("compare");
    (dir, out)
}

#[test]
fn compare_all_methods_writes_every_file_with_plausible_numbers() {
    let (_dir, out) = out_dir();
    let output = compare("default", &out, &[]);
    assert_success(&output, "compare default");

    for name in REPORT_FILES {
        assert!(
            out.join(name).is_file(),
            "expected {name} in {}, found it missing",
            out.display()
        );
    }

    let summary = out.join("compare.csv");
    let header = csv_header(&summary);
    assert!(
        is_subsequence(&SUMMARY_COLUMNS, &header),
        "compare.csv: expected the columns {SUMMARY_COLUMNS:?} in this order, found {header:?}"
    );

    let rows = read_csv(&summary);
    assert_eq!(
        methods(&rows),
        ALL_METHODS,
        "compare.csv: expected one row per method in the default order"
    );
    for (row, (method, bytes)) in rows.iter().zip(BYTES_PER_RAY) {
        assert_eq!(
            number(row, "bytes_per_ray"),
            f64::from(bytes),
            "{method}: expected {bytes} bytes per ray"
        );
        // Times are noisy at this size, but they must be real, positive durations.
        let ms = finite(row, "ms_per_frame");
        assert!(ms > 0.0, "{method}: expected ms_per_frame > 0, found {ms}");
        finite(row, "overhead_pct");
        let ssim = finite(row, "ssim");
        assert!(
            ssim > 0.0 && ssim <= 1.0,
            "{method}: expected SSIM in (0, 1], found {ssim}"
        );
        let flip = finite(row, "flip");
        assert!(
            (0.0..=1.0).contains(&flip),
            "{method}: expected FLIP in [0, 1], found {flip}"
        );
        // PSNR may be `inf` (identical images) but never NaN or negative.
        let psnr = number(row, "psnr");
        assert!(
            psnr >= 0.0,
            "{method}: expected PSNR >= 0 dB or inf, found {psnr}"
        );
        let rms = finite(row, "lod_rms");
        let bias = finite(row, "lod_bias");
        // The RMS of a difference is at least the magnitude of its mean.
        assert!(
            rms + 1e-3 >= bias.abs(),
            "{method}: expected lod_rms >= |lod_bias|, found rms {rms}, bias {bias}"
        );
        let under = finite(row, "lod_under");
        assert!(
            (0.0..=1.0).contains(&under),
            "{method}: expected lod_under (a share) in [0, 1], found {under}"
        );
        // Two frames give one frame-to-frame change, so flicker is measured.
        let flicker = finite(row, "flicker");
        assert!(
            flicker >= 0.0,
            "{method}: expected flicker >= 0 (a mean absolute difference), found {flicker}"
        );
    }
    let none = &rows[0];
    // Overheads are against `none` itself.
    assert_eq!(
        number(none, "overhead_pct"),
        0.0,
        "none: expected overhead 0 % against itself"
    );
    // `none` always samples level 0; wherever the texture is minified the reference
    // level is higher, so `none` is sharper: a negative bias.
    let bias = number(none, "lod_bias");
    assert!(
        bias < 0.0,
        "none: expected a negative lod_bias, found {bias}"
    );

    // compare_frames.csv: one row per method and frame; the first frame has no flicker.
    let frames = read_csv(&out.join("compare_frames.csv"));
    assert_eq!(
        frames.len(),
        ALL_METHODS.len() * 2,
        "compare_frames.csv: expected 6 methods x 2 frames rows, found {}",
        frames.len()
    );
    for row in &frames {
        let (method, frame) = (&row["method"], &row["frame"]);
        match frame.as_str() {
            "0" => assert_eq!(
                row["flicker"], "",
                "{method} frame 0: expected an empty flicker (no previous frame)"
            ),
            "1" => {
                finite(row, "flicker");
            }
            other => panic!("{method}: expected frames 0 and 1, found frame {other}"),
        }
    }

    // Without `--lights A..B` there is no Table 1.
    let md = read_text(&out.join("compare.md"));
    assert!(
        !md.contains("Table 1"),
        "compare.md: expected no Table 1 without --lights A..B, found:\n{md}"
    );
    for method in ALL_METHODS {
        assert!(
            md.contains(&format!("| {method} |")),
            "compare.md: expected a table row for {method}, found:\n{md}"
        );
    }

    for svg in ["pareto.svg", "error_per_frame.svg", "mip_levels.svg"] {
        let texts = svg_texts(&out.join(svg));
        // Every method has a point, line or bar with its name in the legend or label.
        for method in ALL_METHODS {
            assert!(
                texts.iter().any(|t| t == method),
                "{svg}: expected a label '{method}', found the texts {texts:?}"
            );
        }
    }
}

#[test]
fn compare_one_method_still_reports_none_first() {
    let (_dir, out) = out_dir();
    let output = compare("default", &out, &["--methods", "paper"]);
    assert_success(&output, "compare --methods paper");
    let rows = read_csv(&out.join("compare.csv"));
    // `none` is the baseline of the overheads, so it is always measured and first.
    assert_eq!(
        methods(&rows),
        ["none", "paper"],
        "compare.csv: expected the baseline then the one method asked for"
    );
    assert_eq!(
        number(&rows[0], "overhead_pct"),
        0.0,
        "none: expected overhead 0 % against itself"
    );
}

#[test]
fn compare_light_range_adds_table1_with_a_row_per_count() {
    let (_dir, out) = out_dir();
    let output = compare("default", &out, &["--methods", "paper", "--lights", "1..2"]);
    assert_success(&output, "compare --lights 1..2");
    let md = read_text(&out.join("compare.md"));
    let lines: Vec<&str> = md.lines().collect();
    let heading = lines
        .iter()
        .position(|l| l.starts_with("## ") && l.contains("Table 1"))
        .unwrap_or_else(|| panic!("compare.md: expected a '## ... Table 1' heading, found:\n{md}"));
    // The section runs to the next heading; its table rows are the lines starting with
    // `|` after the header and alignment rows.
    let section: Vec<&str> = lines[heading + 1..]
        .iter()
        .take_while(|l| !l.starts_with("## "))
        .filter(|l| l.starts_with('|'))
        .copied()
        .collect();
    assert!(
        section.len() >= 2 && section[0].contains("lights"),
        "Table 1: expected a header naming 'lights' and an alignment row, found {section:?}"
    );
    let rows: Vec<Vec<&str>> = section[2..]
        .iter()
        .map(|l| l.trim_matches('|').split('|').map(str::trim).collect())
        .collect();
    let counts: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(
        counts,
        ["1", "2"],
        "Table 1: expected one row per light count of the inclusive range 1..2, found {section:?}"
    );
    for row in &rows {
        assert_eq!(
            row.len(),
            4,
            "Table 1: expected lights, none ms, paper ms, overhead %; found {row:?}"
        );
        for cell in &row[1..] {
            let v: f64 = cell.parse().unwrap_or_else(|_| {
                panic!("Table 1: expected a number, found '{cell}' in {row:?}")
            });
            assert!(
                v.is_finite(),
                "Table 1: expected finite numbers, found {v} in {row:?}"
            );
        }
    }
}

#[test]
fn compare_save_frames_and_lod_view_write_an_image_per_method_and_frame() {
    let (_dir, out) = out_dir();
    let output = compare(
        "default",
        &out,
        &["--size", "64x36", "--save-frames", "--view", "lod"],
    );
    assert_success(&output, "compare --save-frames --view lod");
    // Frames: every method and the reference. Level views: every method (the reference
    // has no LOD method to show).
    let frame_dirs = ALL_METHODS
        .iter()
        .chain(&["reference"])
        .map(|m| out.join("frames").join(m));
    let lod_dirs = ALL_METHODS.iter().map(|m| out.join("lod").join(m));
    for dir in frame_dirs.chain(lod_dirs) {
        for frame in 0..2 {
            let path = dir.join(format!("frame_{frame:04}.png"));
            let image = image::open(&path).unwrap_or_else(|e| {
                panic!("{}: expected a decodable PNG, found {e}", path.display())
            });
            assert_eq!(
                (image.width(), image.height()),
                (64, 36),
                "{}: expected the --size 64x36",
                path.display()
            );
        }
    }
}

#[test]
fn compare_bad_input_fails_with_a_message_naming_it() {
    // (flags, scene, words stderr must contain)
    let cases: [(&[&str], &str, &[&str]); 8] = [
        (&["--lights", "0"], "default", &["--lights 0"]),
        (&["--lights", "3..1"], "default", &["--lights 3..1"]),
        (&["--lights", "x"], "default", &["--lights x", "'x'"]),
        (&["--methods", "bogus"], "default", &["bogus", "--methods"]),
        (&["--reference-spp", "0"], "default", &["--reference-spp 0"]),
        // The message spells the value as Rust prints it (`NaN`).
        (&["--lod-bias", "nan"], "default", &["--lod-bias", "NaN"]),
        (&["--lod-bias", "100"], "default", &["--lod-bias 100"]),
        (
            &[],
            "no/such/scene.gltf",
            &["no/such/scene.gltf", "no such file"],
        ),
    ];
    for (flags, scene, words) in cases {
        let (_dir, out) = out_dir();
        let output = compare(scene, &out, flags);
        let what = format!("compare {scene} {}", flags.join(" "));
        let err = stderr(&output);
        assert!(
            !output.status.success(),
            "{what}: expected a non-zero exit, found success; stderr:\n{err}"
        );
        assert!(
            !err.contains("panicked"),
            "{what}: expected an error message, found a panic:\n{err}"
        );
        for word in words {
            assert!(
                err.contains(word),
                "{what}: expected stderr to name '{word}', found:\n{err}"
            );
        }
        // Input is checked before anything is rendered, so nothing is left behind.
        assert!(
            !out.exists(),
            "{what}: expected no output folder after bad input, found {}",
            out.display()
        );
    }
}

#[test]
fn compare_twice_gives_identical_quality_numbers() {
    let (_first_dir, first) = out_dir();
    let (_second_dir, second) = out_dir();
    for out in [&first, &second] {
        assert_success(&compare("default", out, &[]), "compare default");
    }
    // Renders, metrics and LOD errors are deterministic; only the clock differs.
    for file in ["compare.csv", "compare_frames.csv"] {
        let a = read_csv(&first.join(file));
        let b = read_csv(&second.join(file));
        assert_eq!(
            a.len(),
            b.len(),
            "{file}: expected the same number of rows in both runs"
        );
        for (row_a, row_b) in a.iter().zip(&b) {
            let mut columns: Vec<&String> = row_a.keys().collect();
            columns.sort();
            for column in columns {
                if TIMING_COLUMNS.contains(&column.as_str()) {
                    continue;
                }
                assert_eq!(
                    row_a[column],
                    row_b[column],
                    "{file}: {} frame {}: expected the same {column} in both runs",
                    row_a["method"],
                    row_a.get("frame").map_or("(all)", String::as_str)
                );
            }
        }
    }
}

#[test]
fn compare_supersampled_none_and_the_subpixel_reference_have_their_rows() {
    let (_dir, out) = out_dir();
    let output = compare("default", &out, &["--methods", "none@4,paper,diffs"]);
    assert_success(&output, "compare --methods none@4,paper,diffs");
    let rows = read_csv(&out.join("compare.csv"));
    assert_eq!(methods(&rows), ["none", "none@4", "paper", "diffs"]);
    // Four samples per pixel: closer to the 4-spp reference than one, and slower.
    let flip = |i: usize| number(&rows[i], "flip");
    assert!(
        flip(1) < flip(0),
        "none@4 FLIP {} vs none {}",
        flip(1),
        flip(0)
    );
    let sub = read_csv(&out.join("subpixel_reference.csv"));
    assert_eq!(methods(&sub), ["none", "none@4", "paper", "diffs"]);
    for row in &sub {
        for column in ["subpixel_longest_bias", "subpixel_area_bias"] {
            assert!(number(row, column).is_finite(), "{column}: {row:?}");
        }
        let share = number(row, "subpixel_undefined_share");
        assert!((0.0..0.5).contains(&share), "undefined share {share}");
    }
    // `none` reads level 0: sharper than the reference under both conventions.
    assert!(number(&sub[0], "subpixel_longest_bias") < 0.0);
    for bad in ["none@0", "paper@x"] {
        let output = compare("default", &out, &["--methods", bad]);
        assert!(!output.status.success(), "--methods {bad} was accepted");
        assert!(stderr(&output).contains(bad), "{}", stderr(&output));
    }
}
