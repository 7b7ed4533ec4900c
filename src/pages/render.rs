//! The render page: a player for the sequence (play/pause, slider, fps, arrow keys), the
//! per-frame phase times and triangle counts as a chart with the current frame marked, the
//! current frame's stats record, and the summary (preprocessing share, rebuilds, rays/s).
//!
//! Records come from the stats files of the given folders, read by
//! [`crate::record::load_sequence`] as `mipray report` reads them (shards merged; when a
//! frame has several records, the last one read wins); each frame shows its line as read. Each frame shows
//! `frame_NNNN.png`, or for EXR sequences the `preview_NNNN.png` written beside it, and
//! `lod_NNNN.png` when `--view lod` wrote one.

use std::path::{Path, PathBuf};

#[cfg(test)]
use serde_json::json;
use serde_json::{Map, Value};

use super::html::{document, escape, json_data, relative_url};
use super::{PageError, write_page};
use crate::record::{Phase, Record, StatsFileError, load_sequence};

const RENDER_JS: &str = include_str!("assets/render.js");

/// Writes `page_dir/index.html` for the sequence whose stats files and frames are in `dirs`
/// (folders, or stats files whose folder holds the frames); frames are linked relative to
/// `page_dir`, and `plot` (the `mipray report` SVG) is shown when given. `owner` names the
/// page's temporary file (see [`crate::atomic_file::write_atomically_as`]).
///
/// # Errors
/// The stats files cannot be read (see [`crate::record::load_sequence`]: no stats file, a
/// line other than a torn last one that is not a record; stats files without a record
/// give a page of no frames), or a file cannot be read or written.
pub fn write_render_page(
    dirs: &[PathBuf],
    page_dir: &Path,
    plot: Option<&Path>,
    owner: Option<&str>,
) -> Result<PathBuf, PageError> {
    let page_dir = super::non_empty(page_dir);
    // A folder with no record yet (the first shard to finish had an empty block of the
    // range) gets a page of no frames, which the next shard's page replaces.
    let records = match load_sequence(dirs) {
        Ok(sequence) => sequence.records,
        Err(StatsFileError::Empty { .. }) => Vec::new(),
        Err(error) => return Err(error.into()),
    };
    let folders: Vec<PathBuf> = dirs.iter().map(|d| frame_folder(d)).collect();
    let lines: Vec<&Map<String, Value>> = records.iter().map(Record::line).collect();
    let summary = summary_of(&lines);
    let fps = playback_fps(&lines);
    // Each record's line moves into the page data (a sequence may have hundreds of
    // thousands): never a second copy of it.
    let mut frames = Vec::with_capacity(records.len());
    for record in records {
        let frame = record.frame();
        let mut entry = Map::new();
        entry.insert("frame".into(), frame.into());
        let image = [
            format!("frame_{frame:04}.png"),
            format!("preview_{frame:04}.png"),
        ];
        let image_names: Vec<&str> = image.iter().map(String::as_str).collect();
        entry.insert(
            "image".into(),
            find_image(&folders, page_dir, &image_names)?,
        );
        let lod = format!("lod_{frame:04}.png");
        entry.insert("lod".into(), find_image(&folders, page_dir, &[&lod])?);
        entry.insert("stats".into(), Value::Object(record.into_line()));
        frames.push(Value::Object(entry));
    }
    let plot = match plot {
        Some(p) if p.is_file() => Some(relative_url(page_dir, p)?),
        _ => None,
    };
    let title = format!("mipray render: {}", page_dir.display());
    let mut data = Map::new();
    data.insert("frames".into(), Value::Array(frames));
    data.insert("fps".into(), fps.into());
    let body = render_body(&title, &summary, plot.as_deref())
        + &json_data("render-data", &Value::Object(data));
    write_page(page_dir, &document(&title, &body, RENDER_JS), owner)
}

/// A folder given directly, or the folder of a stats file.
fn frame_folder(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.to_path_buf()
    } else {
        path.parent().map(Path::to_path_buf).unwrap_or_default()
    }
}

/// The first of `names` found in `folders`, as a URL relative to the page; `null` if none.
fn find_image(folders: &[PathBuf], page_dir: &Path, names: &[&str]) -> Result<Value, PageError> {
    for name in names {
        for folder in folders {
            let path = folder.join(name);
            if path.is_file() {
                return Ok(Value::String(relative_url(page_dir, &path)?));
            }
        }
    }
    Ok(Value::Null)
}

/// The sequence's summary, as `summary.json` defines it, over the merged records.
#[derive(Debug, Clone, PartialEq)]
struct PageSummary {
    frames: usize,
    preprocessing_share: f64,
    rebuilds: usize,
    rays_per_second: f64,
    mean_frame_ms: f64,
    size: String,
    lod_method: String,
}

fn summary_of(records: &[&Map<String, Value>]) -> PageSummary {
    let number =
        |r: &Map<String, Value>, key: &str| r.get(key).and_then(Value::as_f64).unwrap_or(0.0);
    let sum = |key: &str| records.iter().map(|r| number(r, key)).sum::<f64>();
    let total_ms = sum("total_ms");
    let render_ms = sum("render_ms");
    let preprocessing: f64 = Phase::ALL.iter().map(|p| sum(p.field_name())).sum();
    let text = |key: &str| {
        records
            .first()
            .and_then(|r| r.get(key))
            .map_or(String::new(), |v| {
                v.as_str().map_or(v.to_string(), str::to_string)
            })
    };
    PageSummary {
        frames: records.len(),
        preprocessing_share: if total_ms > 0.0 {
            preprocessing / total_ms
        } else {
            0.0
        },
        rebuilds: records
            .iter()
            .filter(|r| r.get("rebuild").and_then(Value::as_bool) == Some(true))
            .count(),
        rays_per_second: if render_ms > 0.0 {
            sum("rays") / (render_ms / 1e3)
        } else {
            0.0
        },
        mean_frame_ms: total_ms / records.len().max(1) as f64,
        size: if records.is_empty() {
            "no frames yet".to_string()
        } else {
            format!("{}x{}", text("width"), text("height"))
        },
        lod_method: text("lod_method"),
    }
}

/// Playback speed: the sequence's own frame rate from its frame times, else 30.
fn playback_fps(records: &[&Map<String, Value>]) -> f64 {
    let time = |r: &Map<String, Value>| r.get("time_s").and_then(Value::as_f64);
    let frame = |r: &Map<String, Value>| r.get("frame").and_then(Value::as_f64);
    match records {
        [a, b, ..] => match (time(a), time(b), frame(a), frame(b)) {
            (Some(ta), Some(tb), Some(fa), Some(fb)) if tb > ta => {
                ((fb - fa) / (tb - ta)).round().clamp(1.0, 240.0)
            }
            _ => 30.0,
        },
        _ => 30.0,
    }
}

fn render_body(title: &str, s: &PageSummary, plot: Option<&str>) -> String {
    let plot = plot.map_or(String::new(), |url| {
        format!(
            "<h2>Report plot</h2>\n<p class=\"note\">Written by <code>mipray report</code>.</p>\n\
             <img src=\"{}\" alt=\"report plot\" style=\"max-width:100%\">\n",
            escape(url)
        )
    });
    format!(
        r#"<h1>{title}</h1>
<p class="note">{frames} frame(s), {size}, LOD method <code>{lod}</code>. Keys: space play/pause, left/right arrow step.</p>
<h2>Summary</h2>
<dl class="stats" id="summary">
<dt>preprocessing share</dt><dd>{share:.1}%</dd>
<dt>BVH rebuilds</dt><dd>{rebuilds}</dd>
<dt>rays per second (render time)</dt><dd>{rays:.3e}</dd>
<dt>mean frame time</dt><dd>{mean:.2} ms</dd>
</dl>
<h2>Sequence</h2>
<div class="controls">
<button id="play">play</button>
<input type="range" id="slider" min="0" max="0" value="0" aria-label="frame">
<span id="frame-label"></span>
<label>fps <input type="number" id="fps" min="1" max="240" value="30" style="width:4em"></label>
<label id="lod-toggle-label"><input type="checkbox" id="lod-toggle"> LOD view</label>
</div>
<div class="row">
<figure class="player"><img id="frame-image" alt="current frame"><figcaption id="frame-caption"></figcaption></figure>
<div><h3 style="margin-top:0">Frame stats</h3><dl class="stats" id="frame-stats"></dl></div>
</div>
<h2>Per-frame phases</h2>
<p class="note">Times per phase (ms, log scale) and triangle counts per frame; the marked line is the current frame. Click to jump.</p>
<div id="charts"></div>
{plot}"#,
        title = escape(title),
        frames = s.frames,
        size = escape(&s.size),
        lod = escape(&s.lod_method),
        share = s.preprocessing_share * 100.0,
        rebuilds = s.rebuilds,
        rays = s.rays_per_second,
        mean = s.mean_frame_ms,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(frame: u64, total: f64, rebuild: bool) -> Map<String, Value> {
        let Value::Object(map) = json!({
            "frame": frame, "time_s": frame as f64 / 24.0, "width": 8, "height": 4,
            "lod_method": "paper", "animate_ms": 1.0, "dirty_ms": 0.5, "refit_ms": 0.5,
            "build_ms": 0.0, "lod_update_ms": 0.0, "render_ms": total - 2.0,
            "total_ms": total, "rays": 1000, "rebuild": rebuild,
        }) else {
            unreachable!()
        };
        map
    }

    #[test]
    fn summary_follows_the_summary_json_definitions() {
        let (a, b) = (record(0, 10.0, true), record(1, 6.0, false));
        let s = summary_of(&[&a, &b]);
        assert_eq!(s.frames, 2);
        assert_eq!(s.rebuilds, 1);
        assert!((s.preprocessing_share - 4.0 / 16.0).abs() < 1e-12);
        assert!((s.rays_per_second - 2000.0 / 0.012).abs() < 1e-6);
        assert_eq!(s.size, "8x4");
        assert_eq!(s.lod_method, "paper");
        assert_eq!(playback_fps(&[&a, &b]), 24.0);
    }

    #[test]
    fn a_bad_stats_line_names_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("stats.jsonl"), "[1]\n{\"frame\": 1}\n").unwrap();
        let message = write_render_page(&[dir.path().to_path_buf()], dir.path(), None, None)
            .unwrap_err()
            .to_string();
        assert!(
            message.ends_with("stats.jsonl:1: not a JSON object"),
            "{message}"
        );
        let empty = tempfile::tempdir().unwrap();
        assert!(
            write_render_page(&[empty.path().to_path_buf()], empty.path(), None, None).is_err()
        );
        // Stats files without a record (shards whose block of the range was empty): a page
        // of no frames.
        std::fs::write(empty.path().join("stats.shard-0-of-8.jsonl"), "").unwrap();
        let page =
            write_render_page(&[empty.path().to_path_buf()], empty.path(), None, None).unwrap();
        let html = std::fs::read_to_string(page).unwrap();
        assert!(html.contains("0 frame(s), no frames yet"), "{html}");
    }

    #[test]
    fn the_page_links_pngs_or_exr_previews_relative_to_itself() {
        let dir = tempfile::tempdir().unwrap();
        let frames = dir.path().join("frames");
        std::fs::create_dir_all(&frames).unwrap();
        std::fs::write(
            frames.join("stats.jsonl"),
            Value::Object(record(3, 5.0, false)).to_string() + "\n",
        )
        .unwrap();
        std::fs::write(frames.join("preview_0003.png"), b"png").unwrap();
        let page = write_render_page(&[frames.clone()], dir.path(), None, None).unwrap();
        let html = std::fs::read_to_string(page).unwrap();
        assert!(
            html.contains("\"image\":\"frames/preview_0003.png\""),
            "{html}"
        );
        assert!(html.contains("\"lod\":null"));
    }
}
