//! `mipray diff` and `render --check`: the regression-testing contract.

use std::path::Path;
use std::process::Output;

mod common;

use common::mipray;

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Renders frames 0..3 of the default animation at 48x27 into `dir/name`.
fn render(dir: &Path, name: &str) {
    let out = mipray(
        &[
            "render", "default", "--size", "48x27", "--frames", "0..3", "--out", name,
        ],
        dir,
    );
    assert!(out.status.success(), "{}", text(&out));
}

fn csv_rows(path: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

#[test]
fn identical_sequences_pass() {
    let dir = tempfile::tempdir().unwrap();
    render(dir.path(), "a");
    render(dir.path(), "b");
    let out = mipray(&["diff", "a", "b", "--out", "d"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(
        text(&out).contains("PASS: 0 of 3 frame(s)"),
        "{}",
        text(&out)
    );
    let rows = csv_rows(&dir.path().join("d/diff.csv"));
    assert_eq!(rows.len(), 3);
    for row in &rows {
        assert_eq!(
            (row[1].as_str(), row[2].as_str(), row[4].as_str()),
            ("true", "inf", "0"),
            "{row:?}"
        );
        // Stats compared: the same rays on both sides.
        assert_eq!(row[8], "0", "{row:?}");
    }
    assert!(dir.path().join("d/diff.md").is_file());
    // A JUnit report that could not be written is refused before the comparison.
    let out = mipray(&["diff", "a", "b", "--junit", "no/such/j.xml"], dir.path());
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("does not exist"), "{}", text(&out));
    let out = mipray(
        &[
            "render", "default", "--size", "48x27", "--frames", "0", "--out", "j", "--check", "a",
            "--junit", "a",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("is a folder"), "{}", text(&out));
    assert!(
        !dir.path().join("j/frame_0000.png").exists(),
        "rendered before refusing"
    );
    // A NaN threshold would fail every frame whatever it held: refused as a usage error.
    let out = mipray(&["diff", "a", "b", "--threshold", "nan"], dir.path());
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("NaN"), "{}", text(&out));
}

#[test]
fn one_changed_pixel_fails_exactly_that_frame() {
    let dir = tempfile::tempdir().unwrap();
    render(dir.path(), "a");
    render(dir.path(), "b");
    let frame = dir.path().join("b/frame_0001.png");
    let mut image = image::open(&frame).unwrap().to_rgb8();
    let p = image.get_pixel_mut(10, 5);
    p.0[0] = if p.0[0] > 127 {
        p.0[0] - 60
    } else {
        p.0[0] + 60
    };
    image.save(&frame).unwrap();
    for metric in ["psnr", "max-abs"] {
        let junit = format!("junit-{metric}.xml");
        let out = mipray(
            &[
                "diff",
                "a",
                "b",
                "--metric",
                metric,
                "--threshold",
                if metric == "psnr" { "60" } else { "0" },
                "--out",
                "d",
                "--junit",
                &junit,
            ],
            dir.path(),
        );
        assert_eq!(out.status.code(), Some(1), "{metric}: {}", text(&out));
        let rows = csv_rows(&dir.path().join("d/diff.csv"));
        let failing: Vec<&str> = rows
            .iter()
            .filter(|r| r[1] == "false")
            .map(|r| r[0].as_str())
            .collect();
        assert_eq!(failing, vec!["1"], "{metric}");
        let row = &rows[1];
        // One channel of one pixel off by 60: MSE = 3600 / (3 * 48 * 27).
        let expected = 10.0 * (255.0f64 * 255.0 / (3600.0 / (3.0 * 48.0 * 27.0))).log10();
        let psnr: f64 = row[2].parse().unwrap();
        assert!((psnr - expected).abs() < 1e-6, "{psnr} vs {expected}");
        assert_eq!((row[4].as_str(), row[5].as_str()), ("60", "1"));
        let flip: f64 = row[3].parse().unwrap();
        assert!(flip > 0.0, "FLIP sees the change");
        assert!(dir.path().join("d/frame_0001_diff.png").is_file());
        assert!(
            !dir.path().join("d/frame_0000_diff.png").exists()
                && !dir.path().join("d/frame_0002_diff.png").exists()
        );
        // The table lists the failing frame first.
        let first_row = text(&out)
            .lines()
            .find(|l| l.starts_with("| ") && !l.starts_with("| frame"))
            .unwrap_or_default()
            .to_string();
        assert!(first_row.starts_with("| 1 | FAIL"), "{first_row}");
        // JUnit: well-formed, one case per frame, one failure.
        let xml = std::fs::read_to_string(dir.path().join(&junit)).unwrap();
        let doc = roxmltree::Document::parse(&xml).expect("well-formed XML");
        let cases: Vec<_> = doc
            .descendants()
            .filter(|n| n.has_tag_name("testcase"))
            .collect();
        assert_eq!(cases.len(), 3);
        let failed: Vec<&str> = cases
            .iter()
            .filter(|c| c.children().any(|k| k.has_tag_name("failure")))
            .filter_map(|c| c.attribute("name"))
            .collect();
        assert_eq!(failed, vec!["frame_0001"]);
    }
}

#[test]
fn missing_frame_or_size_mismatch_is_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    render(dir.path(), "a");
    render(dir.path(), "b");
    std::fs::remove_file(dir.path().join("b/frame_0002.png")).unwrap();
    let out = mipray(&["diff", "a", "b"], dir.path());
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        text(&out).contains("frame 2") && text(&out).contains("frame_0002.png"),
        "{}",
        text(&out)
    );

    // A frame that is not an image: named once, its problem said once.
    std::fs::write(dir.path().join("b/frame_0002.png"), "not a picture").unwrap();
    let out = mipray(&["diff", "a", "b"], dir.path());
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(stderr.matches("frame_0002.png").count(), 1, "{stderr}");
    assert_eq!(stderr.matches("cannot read image").count(), 1, "{stderr}");
    std::fs::remove_file(dir.path().join("b/frame_0002.png")).unwrap();

    let out = mipray(
        &[
            "render", "default", "--size", "40x20", "--frames", "0..3", "--out", "c",
        ],
        dir.path(),
    );
    assert!(out.status.success());
    let out = mipray(&["diff", "a", "c"], dir.path());
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        text(&out).contains("48x27") && text(&out).contains("40x20"),
        "{}",
        text(&out)
    );
    assert!(!text(&out).contains("panicked"));
}

#[test]
fn render_check_passes_on_an_unchanged_scene_and_fails_fast_on_a_changed_one() {
    let dir = tempfile::tempdir().unwrap();
    render(dir.path(), "reference");
    let out = mipray(
        &[
            "render",
            "default",
            "--size",
            "48x27",
            "--frames",
            "0..3",
            "--out",
            "t",
            "--check",
            "reference",
            "--junit",
            "j.xml",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert_eq!(text(&out).matches("check frame").count(), 3);
    assert!(
        roxmltree::Document::parse(&std::fs::read_to_string(dir.path().join("j.xml")).unwrap())
            .is_ok()
    );

    // Break the reference's frame 1: a check of the same scene now fails there and stops.
    let frame = dir.path().join("reference/frame_0001.png");
    let image = image::open(&frame).unwrap().to_rgb8();
    image::imageops::flip_horizontal(&image)
        .save(&frame)
        .unwrap();
    let out = mipray(
        &[
            "render",
            "default",
            "--size",
            "48x27",
            "--frames",
            "0..3",
            "--out",
            "u",
            "--check",
            "reference",
            "--fail-fast",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        text(&out).contains("check frame 0001: FAIL"),
        "{}",
        text(&out)
    );
    assert!(
        !dir.path().join("u/frame_0002.png").exists(),
        "--fail-fast rendered past the failing frame"
    );
}

/// `render --resume --check REF` judges the frames the resume keeps as well as those it
/// renders (it passed 0 of 0 frames before), and `--check` into its own output folder is
/// refused before anything is overwritten.
#[test]
fn a_resumed_check_judges_every_frame_and_a_check_against_itself_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let render = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "render", "default", "--size", "48x27", "--frames", "0..3", "--out", out,
        ];
        args.extend_from_slice(extra);
        mipray(&args, dir.path())
    };
    assert!(render("shallow", &["--max-depth", "1"]).status.success());
    assert!(render("full", &[]).status.success());
    // Every frame is complete: nothing is rendered, and all three are judged (and fail).
    let out = render("full", &["--resume", "--check", "shallow"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert_eq!(
        text(&out).matches("check frame").count(),
        3,
        "{}",
        text(&out)
    );
    assert!(text(&out).contains("FAIL"), "{}", text(&out));
    // With --fail-fast the first kept frame that fails stops the run.
    let out = render("full", &["--resume", "--check", "shallow", "--fail-fast"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert_eq!(
        text(&out).matches("check frame").count(),
        1,
        "{}",
        text(&out)
    );
    // Against its own folder: refused, and the frames are left as they were.
    let before = std::fs::read(dir.path().join("full/frame_0000.png")).unwrap();
    let out = render("full", &["--max-depth", "1", "--check", "full"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        text(&out).contains("is the output folder itself"),
        "{}",
        text(&out)
    );
    let after = std::fs::read(dir.path().join("full/frame_0000.png")).unwrap();
    assert!(before == after, "the reference frame was overwritten");
}

/// `render default --size SIZE --frames 0..3 --out out --check reference` and `extra`, in
/// `dir`.
fn render_checked(dir: &Path, size: &str, extra: &[&str]) -> Output {
    let mut args = vec![
        "render",
        "default",
        "--size",
        size,
        "--frames",
        "0..3",
        "--out",
        "out",
        "--check",
        "reference",
        "--junit",
        "j.xml",
    ];
    args.extend_from_slice(extra);
    mipray(&args, dir)
}

/// The JUnit report's test cases with an `<error>` (bad input), by name.
fn junit_errors(dir: &Path) -> Vec<String> {
    let xml = std::fs::read_to_string(dir.join("j.xml")).unwrap();
    let doc = roxmltree::Document::parse(&xml).expect("well-formed XML");
    doc.descendants()
        .filter(|n| n.has_tag_name("testcase"))
        .filter(|c| c.children().any(|k| k.has_tag_name("error")))
        .filter_map(|c| c.attribute("name").map(str::to_string))
        .collect()
}

/// A reference frame missing (or of another size) in `render --check`: the render goes on
/// (the frames are the product), the frame is reported as not compared in the report and
/// the JUnit file, the summary and page are written, and the exit status is 2 (bad input,
/// as `mipray diff` says of a frame missing on one side). `--fail-fast` stops there.
#[test]
fn a_check_without_a_reference_frame_renders_on_and_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    render(dir.path(), "reference");
    std::fs::remove_file(dir.path().join("reference/frame_0001.png")).unwrap();
    let out = render_checked(dir.path(), "48x27", &[]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    for file in [
        "frame_0002.png",
        "summary.json",
        "index.html",
        "check/diff.md",
    ] {
        assert!(
            dir.path().join("out").join(file).is_file(),
            "{file}: {}",
            text(&out)
        );
    }
    assert!(
        text(&out).contains("check frame 0001: not compared: frame 1: reference/frame_0001.png is missing (reference side)"),
        "{}",
        text(&out)
    );
    assert_eq!(junit_errors(dir.path()), ["frame_0001"]);
    let rows = csv_rows(&dir.path().join("out/check/diff.csv"));
    assert_eq!((rows[1][0].as_str(), rows[1][1].as_str()), ("1", "false"));
    assert!(
        rows[1].last().unwrap().contains("is missing"),
        "{:?}",
        rows[1]
    );

    std::fs::remove_dir_all(dir.path().join("out")).unwrap();
    let out = render_checked(dir.path(), "48x27", &["--fail-fast"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        !dir.path().join("out/frame_0002.png").exists(),
        "--fail-fast rendered on"
    );
    assert!(
        dir.path().join("out/summary.json").is_file()
            && dir.path().join("out/check/diff.md").is_file()
    );

    // Frames of another size than the reference's: the same.
    render(dir.path(), "reference");
    let out = render_checked(dir.path(), "40x20", &[]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        text(&out).contains("48x27") && text(&out).contains("40x20"),
        "{}",
        text(&out)
    );
    assert_eq!(junit_errors(dir.path()).len(), 3);
    assert!(dir.path().join("out/frame_0002.png").is_file());
}

/// `render --check` pairs a PNG frame with an EXR reference frame of the same number, as
/// `mipray diff` does.
#[test]
fn a_check_pairs_png_frames_with_an_exr_reference() {
    let dir = tempfile::tempdir().unwrap();
    let out = mipray(
        &[
            "render",
            "default",
            "--size",
            "48x27",
            "--frames",
            "0..3",
            "--out",
            "reference",
            "--format",
            "exr",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out));
    let out = render_checked(dir.path(), "48x27", &[]);
    assert_ne!(out.status.code(), Some(2), "{}", text(&out));
    let compared = text(&out)
        .lines()
        .filter(|l| l.starts_with("check frame") && l.contains(" psnr "))
        .count();
    assert_eq!(compared, 3, "{}", text(&out));
    assert!(junit_errors(dir.path()).is_empty());
}

/// A `--out` that cannot hold the report (a file, or a folder below a file) is bad input
/// to the comparison, as a `--junit` path whose folder does not exist: refused with status
/// 2, naming the path and the problem, before any frame is compared.
#[test]
fn an_out_folder_that_cannot_be_written_is_refused_before_comparing() {
    let dir = tempfile::tempdir().unwrap();
    render(dir.path(), "a");
    render(dir.path(), "b");
    std::fs::write(dir.path().join("file"), b"not a folder").unwrap();
    for (out, problem) in [
        ("file", "exists and is not a folder"),
        ("file/diff", "cannot create the report folder"),
    ] {
        let run = mipray(&["diff", "a", "b", "--out", out], dir.path());
        assert_eq!(run.status.code(), Some(2), "{}", text(&run));
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(
            stderr.contains(&format!("error: {out}: {problem}")),
            "{stderr}"
        );
        // Nothing compared: no table on stdout.
        assert!(run.stdout.is_empty(), "{}", text(&run));
    }
    assert_eq!(
        std::fs::read(dir.path().join("file")).unwrap(),
        b"not a folder"
    );
}
