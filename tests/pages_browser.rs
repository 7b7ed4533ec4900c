//! The HTML pages in a real browser: a tiny render (PNG and EXR), compare, diff and report
//! are generated, and headless Chromium loads each `index.html` from `file://`.
//!
//! The pages' scripts record what happened on `<html>` (`data-errors`, `data-images`,
//! `data-frames-shown`, ...); `--dump-dom` prints the DOM after the scripts ran (under a
//! virtual time budget, so the player's timers run without waiting), and Chromium's own log
//! (`--enable-logging=stderr`) shows every console message, which must be none. On failure
//! a screenshot of the page is saved under `target/test-failures/`.
//!
//! Without Chromium the test prints that it skipped; with `CI` set it fails instead.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::mipray;

/// Browser executables tried in order.
const BROWSERS: [&str; 3] = ["chromium", "chromium-browser", "google-chrome"];
const BROWSER_TIMEOUT: Duration = Duration::from_secs(90);

fn find_browser() -> Option<&'static str> {
    BROWSERS.into_iter().find(|name| {
        Command::new(name)
            .arg("--version")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    })
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Runs mipray in `dir`; `expect_success` false accepts exit status 1 (a failing diff).
fn run(dir: &Path, args: &[&str], expect_success: bool) {
    let out = mipray(args, dir);
    let ok = out.status.success() || (!expect_success && out.status.code() == Some(1));
    assert!(ok, "mipray {}: {}", args.join(" "), text(&out));
}

/// Renders, compares, diffs and reports tiny sequences into `dir`; returns the pages with
/// the URL fragment each is opened with.
fn generate(dir: &Path) -> Vec<(PathBuf, &'static str)> {
    let size = ["--size", "48x27", "--frames", "0..3"];
    let with =
        |rest: &[&'static str]| -> Vec<&str> { [&rest[..2], &size[..], &rest[2..]].concat() };
    run(
        dir,
        &with(&["render", "default", "--out", "png", "--view", "lod"]),
        true,
    );
    run(
        dir,
        &with(&[
            "render",
            "default",
            "--out",
            "exr",
            "--format",
            "exr",
            "--max-depth",
            "1",
        ]),
        true,
    );
    run(dir, &["diff", "png", "exr", "--out", "diff"], false);
    run(
        dir,
        &[
            "compare",
            "default",
            "--size",
            "48x27",
            "--frames",
            "0..2",
            "--methods",
            "paper,cones",
            "--reference-spp",
            "4",
            "--repeats",
            "1",
            "--save-frames",
            "--view",
            "lod",
            "--out",
            "compare",
        ],
        true,
    );
    run(
        dir,
        &["report", "png", "exr", "--svg", "report/report.svg"],
        true,
    );
    vec![
        (dir.join("png/index.html"), "#play"),
        (dir.join("exr/index.html"), "#play"),
        (dir.join("compare/index.html"), ""),
        (dir.join("diff/index.html"), ""),
        (dir.join("report/index.html"), "#play"),
    ]
}

/// What the browser saw of one page.
struct Loaded {
    /// The `<html ...>` start tag after the scripts ran.
    root: String,
    /// Chromium's console log lines.
    console: Vec<String>,
}

impl Loaded {
    fn attribute(&self, name: &str) -> Option<String> {
        let key = format!(" {name}=\"");
        let start = self.root.find(&key)? + key.len();
        let end = self.root[start..].find('"')? + start;
        Some(self.root[start..end].replace("&quot;", "\""))
    }
}

/// Runs the browser on `args` with a deadline; returns its output. Output goes to files,
/// not pipes: a DOM dump larger than a pipe's buffer would block the browser while this
/// waits for it to exit.
fn browser(name: &str, profile: &Path, args: &[String]) -> Output {
    let (out_path, err_path) = (profile.join("stdout.txt"), profile.join("stderr.txt"));
    let file = |p: &Path| std::fs::File::create(p).expect("create a browser output file");
    let mut child = Command::new(name)
        .args([
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            "--hide-scrollbars",
        ])
        .arg(format!(
            "--user-data-dir={}",
            profile.join("profile").display()
        ))
        .args(args)
        .stdout(file(&out_path))
        .stderr(file(&err_path))
        .spawn()
        .expect("start the browser");
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("poll the browser") {
            break status;
        }
        if start.elapsed() > BROWSER_TIMEOUT {
            let _ = child.kill();
            panic!(
                "{name} {}: no answer in {BROWSER_TIMEOUT:?}",
                args.join(" ")
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let read = |p: &Path| std::fs::read(p).expect("read the browser output");
    Output {
        status,
        stdout: read(&out_path),
        stderr: read(&err_path),
    }
}

fn load(name: &str, profile: &Path, url: &str) -> Loaded {
    let out = browser(
        name,
        profile,
        &[
            "--virtual-time-budget=3000".into(),
            "--enable-logging=stderr".into(),
            "--v=0".into(),
            "--dump-dom".into(),
            url.into(),
        ],
    );
    let dom = String::from_utf8_lossy(&out.stdout);
    let root = dom
        .find("<html")
        .and_then(|s| dom[s..].find('>').map(|e| dom[s..s + e + 1].to_string()))
        .unwrap_or_default();
    let console = String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| l.contains(":CONSOLE"))
        .map(str::to_string)
        .collect();
    Loaded { root, console }
}

/// Everything wrong with a loaded page (empty: fine).
fn problems(page: &Path, loaded: &Loaded) -> Vec<String> {
    let mut problems = Vec::new();
    if loaded.root.is_empty() {
        problems.push("no DOM dumped".to_string());
    }
    if let Some(errors) = loaded.attribute("data-errors") {
        problems.push(format!("script or load errors: {errors}"));
    }
    problems.extend(loaded.console.iter().map(|l| format!("console: {l}")));
    match loaded
        .attribute("data-images")
        .as_deref()
        .and_then(|s| s.split_once('/'))
    {
        Some((ok, all)) if ok == all && all != "0" => {}
        other => problems.push(format!(
            "images loaded/linked: {other:?}, broken: {:?}",
            loaded.attribute("data-broken-images")
        )),
    }
    let name = page.parent().and_then(Path::file_name).unwrap_or_default();
    let number = |attr: &str| loaded.attribute(attr).and_then(|v| v.parse::<u32>().ok());
    match name.to_str() {
        Some("png" | "exr" | "report") => {
            // The player started at frame 0 and must have shown the other frames too.
            if number("data-frames-shown") != Some(3) {
                problems.push(format!(
                    "player showed {:?} of 3 frames",
                    number("data-frames-shown")
                ));
            }
        }
        Some("compare") => {
            if number("data-clickable-points").is_none_or(|n| n < 3) {
                problems.push("pareto.svg points are not clickable (3 methods)".into());
            }
            if loaded.attribute("data-selected-method").as_deref() != Some("paper") {
                problems.push("no method selected".into());
            }
        }
        Some("diff") => {
            if loaded.attribute("data-toggle-view").is_none() {
                problems.push("the toggle view did not start".into());
            }
        }
        _ => problems.push("unknown page".into()),
    }
    problems
}

/// A screenshot of a failing page under `target/test-failures/`.
fn save_screenshot(name: &str, profile: &Path, page: &Path, label: &str) -> PathBuf {
    let folder = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .map_or_else(|| PathBuf::from("target"), Path::to_path_buf)
        .join("test-failures");
    std::fs::create_dir_all(&folder).expect("create target/test-failures");
    let shot = folder.join(format!("page-{label}.png"));
    browser(
        name,
        profile,
        &[
            "--window-size=1200,1400".into(),
            "--virtual-time-budget=3000".into(),
            format!("--screenshot={}", shot.display()),
            format!("file://{}", page.display()),
        ],
    );
    shot
}

#[test]
fn every_page_loads_in_headless_chromium_without_errors() {
    let Some(name) = find_browser() else {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but no Chromium ({BROWSERS:?}) is installed: `.ci/run` installs it"
        );
        println!("skipped: no Chromium ({BROWSERS:?}) on PATH; `apt-get install -y chromium`");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let profile = tempfile::tempdir().unwrap();
    let pages = generate(dir.path());
    let mut failures = Vec::new();
    for (page, fragment) in &pages {
        let page = page.canonicalize().expect("the page was written");
        let loaded = load(
            name,
            profile.path(),
            &format!("file://{}{fragment}", page.display()),
        );
        let found = problems(&page, &loaded);
        if !found.is_empty() {
            let label = page.parent().and_then(Path::file_name).unwrap_or_default();
            let shot = save_screenshot(name, profile.path(), &page, &label.to_string_lossy());
            failures.push(format!(
                "{}: {}\n  root: {}\n  screenshot: {}",
                page.display(),
                found.join("; "),
                loaded.root,
                shot.display()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
