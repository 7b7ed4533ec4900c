//! The compare page: the method table of `compare.csv` (click a row to select a method),
//! `pareto.svg` inlined so clicking a point or label selects its method, and for the
//! selected method and frame the reference beside the method's frame with a swipe divider,
//! the FLIP heat map and the `--view lod` level image; then the other plots and the
//! Markdown sections of `compare.md` (Table 1, MIP level shares).
//!
//! Frames are shown only when compare saved them (`--save-frames` writes `frames/`,
//! `--view lod` writes `lod/`); the page says so otherwise. FLIP heat maps are not written
//! by compare itself: this page computes them from the saved frames into
//! `heat/<method>/frame_NNNN.png` (skipped when the heat map is newer than both frames).

use std::path::{Path, PathBuf};

use serde_json::{Map, Value, json};

use super::html::{
    document, escape, inline_svg, json_data, markdown, read_csv, relative_url, table,
};
use super::{PageError, write_page};

const COMPARE_JS: &str = include_str!("assets/compare.js");

/// Writes `dir/index.html` for the `mipray compare` output in `dir` (and the FLIP heat
/// maps of its saved frames).
///
/// # Errors
/// `compare.csv` or `compare_frames.csv` is missing or malformed, a saved frame cannot be
/// decoded, or a file cannot be written.
pub fn write_compare_page(dir: &Path) -> Result<PathBuf, PageError> {
    let summary = read_csv(&dir.join("compare.csv"))?;
    let per_frame = read_csv(&dir.join("compare_frames.csv"))?;
    let methods: Vec<String> = summary.iter().skip(1).map(|r| r[0].clone()).collect();
    let frames = frame_numbers(&per_frame, &dir.join("compare_frames.csv"))?;
    let images = frame_images(dir, &methods, &frames)?;
    let pareto = match dir.join("pareto.svg") {
        p if p.is_file() => inline_svg(&p)?,
        _ => "<p class=\"note\">pareto.svg is missing.</p>".to_string(),
    };
    let markdown_sections = match std::fs::read_to_string(dir.join("compare.md")) {
        Ok(text) => sections_after_method_table(&text),
        Err(_) => String::new(),
    };
    let data = json!({
        "methods": methods,
        "frames": frames,
        "images": images,
        "perFrame": rows_as_objects(&per_frame),
    });
    let title = format!("mipray compare: {}", dir.display());
    let body = format!(
        "<h1>{}</h1>\n{}<h2>Methods</h2>\n<p class=\"note\">Click a row or a point of the plot to select a method.</p>\n{}\
         <div class=\"pareto\" id=\"pareto\">{pareto}</div>\n{}\n{}{}{}{}",
        escape(&title),
        settings_line(dir),
        table("methods", &summary, 0),
        frames_section(&images),
        plot_image(dir, "error_per_frame.svg", "FLIP per frame")?,
        plot_image(dir, "mip_levels.svg", "Share of lookups per MIP level")?,
        markdown_sections,
        json_data("compare-data", &data),
    );
    write_page(dir, &document(&title, &body, COMPARE_JS), None)
}

/// The frame numbers of `compare_frames.csv`, ascending, without repeats.
fn frame_numbers(rows: &[Vec<String>], path: &Path) -> Result<Vec<u32>, PageError> {
    let column = rows[0].iter().position(|h| h == "frame");
    let column = column.ok_or_else(|| PageError::input(path, "no `frame` column"))?;
    let mut frames = Vec::new();
    for (i, row) in rows.iter().enumerate().skip(1) {
        let frame: u32 = row[column].parse().map_err(|_| {
            PageError::input(path, format!("line {}: bad frame `{}`", i + 1, row[column]))
        })?;
        frames.push(frame);
    }
    frames.sort_unstable();
    frames.dedup();
    Ok(frames)
}

/// `{"reference": {frame: url}, "<method>": {frame: {"image", "heat", "lod"}}}` for the
/// frames saved on disk; heat maps are written here when missing or stale.
fn frame_images(dir: &Path, methods: &[String], frames: &[u32]) -> Result<Value, PageError> {
    let mut all = Map::new();
    let mut reference = Map::new();
    for &frame in frames {
        let path = dir.join("frames/reference").join(frame_name(frame));
        if path.is_file() {
            reference.insert(frame.to_string(), relative_url(dir, &path)?.into());
        }
    }
    for method in methods {
        let mut per_frame = Map::new();
        for &frame in frames {
            let name = frame_name(frame);
            let image = dir.join("frames").join(method).join(&name);
            let lod = dir.join("lod").join(method).join(&name);
            let reference_image = dir.join("frames/reference").join(&name);
            let heat = if image.is_file() && reference_image.is_file() {
                let heat = dir.join("heat").join(method).join(&name);
                write_heat_map(&reference_image, &image, &heat)?;
                Some(relative_url(dir, &heat)?)
            } else {
                None
            };
            let url = |p: &Path| -> Result<Value, PageError> {
                Ok(if p.is_file() {
                    relative_url(dir, p)?.into()
                } else {
                    Value::Null
                })
            };
            per_frame.insert(
                frame.to_string(),
                json!({ "image": url(&image)?, "lod": url(&lod)?, "heat": heat }),
            );
        }
        all.insert(method.clone(), Value::Object(per_frame));
    }
    all.insert("reference".into(), Value::Object(reference));
    Ok(Value::Object(all))
}

fn frame_name(frame: u32) -> String {
    format!("frame_{frame:04}.png")
}

/// The FLIP heat map of `test` against `reference` (as `mipray diff` draws it), unless
/// `out` is already newer than both.
fn write_heat_map(reference: &Path, test: &Path, out: &Path) -> Result<(), PageError> {
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if let (Some(h), Some(a), Some(b)) = (modified(out), modified(reference), modified(test)) {
        if h >= a && h >= b {
            return Ok(());
        }
    }
    let read =
        |p: &Path| crate::metrics::read_srgb8(p).map_err(|e| PageError::input(p, e.to_string()));
    let (a, b) = (read(reference)?, read(test)?);
    if a.dimensions() != b.dimensions() {
        return Err(PageError::input(
            test,
            format!("size differs from {}", reference.display()),
        ));
    }
    let (_, error_map) = crate::metrics::compare(&a, &b);
    let folder = out.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(folder).map_err(|source| PageError::Io {
        path: folder.to_path_buf(),
        source,
    })?;
    crate::atomic_file::write_rgb8_atomically(out, &crate::metrics::heat_map(&error_map))
        .map_err(|e| PageError::input(out, e.to_string()))
}

/// The CSV rows after the header as objects keyed by the header.
fn rows_as_objects(rows: &[Vec<String>]) -> Value {
    let header = &rows[0];
    rows.iter()
        .skip(1)
        .map(|row| {
            Value::Object(
                header
                    .iter()
                    .cloned()
                    .zip(row.iter().map(|c| Value::String(c.clone())))
                    .collect(),
            )
        })
        .collect()
}

/// The run's settings line of `compare.md` (its first paragraph after the title).
fn settings_line(dir: &Path) -> String {
    let text = std::fs::read_to_string(dir.join("compare.md")).unwrap_or_default();
    text.lines()
        .skip(1)
        .find(|l| !l.trim().is_empty())
        .map_or(String::new(), |l| {
            format!("<p class=\"note\">{}</p>\n", escape(l))
        })
}

/// The Markdown from the first `## ` heading on (Table 1, MIP level shares); the title,
/// settings and method table are shown from `compare.csv` instead.
fn sections_after_method_table(text: &str) -> String {
    text.find("\n## ")
        .map_or(String::new(), |at| markdown(&text[at + 1..]))
}

fn frames_section(images: &Value) -> String {
    let saved = images["reference"]
        .as_object()
        .is_some_and(|r| !r.is_empty());
    let body = if saved {
        r#"<div class="controls"><span>method <b id="selected-method"></b></span>
<label>frame <select id="frame-select"></select></label><span id="frame-metrics" class="note"></span></div>
<div class="row">
<figure><div class="swipe" id="swipe"><img alt="method frame"><img alt="reference frame"></div>
<figcaption>reference (left of the divider) against the method; move the pointer to swipe</figcaption></figure>
<figure><img id="heat" alt="FLIP heat map"><figcaption>FLIP heat map against the reference</figcaption></figure>
<figure id="lod-figure"><img id="lod" alt="LOD level view"><figcaption>MIP level (<code>--view lod</code>)</figcaption></figure>
</div>
<p class="note" id="lod-note"></p>"#
    } else {
        "<p class=\"note\" id=\"no-frames\">No frames were saved: run <code>mipray compare ... --save-frames</code> \
         to see each method's frames against the reference with FLIP heat maps here, and add \
         <code>--view lod</code> for the MIP level images.</p>"
    };
    format!("<h2>Frames</h2>\n{body}\n")
}

fn plot_image(dir: &Path, name: &str, alt: &str) -> Result<String, PageError> {
    let path = dir.join(name);
    Ok(if path.is_file() {
        format!(
            "<h2>{alt}</h2>\n<img src=\"{}\" alt=\"{alt}\" style=\"max-width:100%\">\n",
            escape(&relative_url(dir, &path)?)
        )
    } else {
        String::new()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_sections_start_after_the_method_table() {
        let md = "# LOD methods\n\nsettings\n\n| method |\n| --- |\n| none |\n\n## Table 1\n\n| lights | none |\n| --- | --- |\n| 1 | 2.0 |\n";
        let html = sections_after_method_table(md);
        assert!(html.starts_with("<h3>Table 1</h3>"), "{html}");
        assert!(
            html.contains("<td>2.0</td>") && !html.contains("LOD methods"),
            "{html}"
        );
    }

    #[test]
    fn frame_numbers_are_sorted_unique_and_bad_ones_name_the_line() {
        let rows = |frames: &[&str]| {
            let mut rows = vec![vec!["method".to_string(), "frame".to_string()]];
            rows.extend(
                frames
                    .iter()
                    .map(|f| vec!["none".to_string(), f.to_string()]),
            );
            rows
        };
        let path = Path::new("compare_frames.csv");
        assert_eq!(
            frame_numbers(&rows(&["2", "0", "2"]), path).unwrap(),
            [0, 2]
        );
        let message = frame_numbers(&rows(&["0", "x"]), path)
            .unwrap_err()
            .to_string();
        assert!(message.contains("line 3"), "{message}");
    }

    #[test]
    fn without_saved_frames_the_page_says_how_to_get_them() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("compare.csv"),
            "method,flip\nnone,0.1\npaper,0.05\n",
        )
        .unwrap();
        std::fs::write(
            dir.path().join("compare_frames.csv"),
            "method,frame,flip\nnone,0,0.1\npaper,0,0.05\n",
        )
        .unwrap();
        let html = std::fs::read_to_string(write_compare_page(dir.path()).unwrap()).unwrap();
        assert!(html.contains("--save-frames"), "{html}");
        assert!(html.contains("<tr data-key=\"paper\"><td>paper</td><td>0.05</td></tr>"));
        assert!(!dir.path().join("heat").exists());
    }
}
