//! The diff page: the verdict and threshold, the per-frame metrics of `diff.csv` worst
//! frame first, and for each failing frame (the ones `mipray diff` wrote images for) the
//! reference and test with a swipe divider, a toggle that flips between reference, test
//! and heat map in place, and the FLIP heat map.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use super::html::{document, escape, json_data, read_csv, relative_url, table};
use super::{PageError, write_page};

const DIFF_JS: &str = include_str!("assets/diff.js");

/// Columns of `diff.csv` the page needs.
const FRAME: &str = "frame";
const PASSED: &str = "passed";
/// Why a frame was not compared (empty when it was; absent from older reports).
const PROBLEM: &str = "problem";

/// Writes `out/index.html` for the `mipray diff` report in `out` (`diff.csv` and the
/// failing frames' `frame_NNNN_{ref,test,diff}.png`). `metric` is the metric's CLI name
/// (`psnr`, `flip`, `max-abs`), which also orders the frames worst first.
///
/// # Errors
/// `diff.csv` is missing or malformed (no `frame`/`passed` column, a value that is not a
/// number), or the page cannot be written.
pub fn write_diff_page(
    out: &Path,
    metric: &str,
    threshold: f64,
    verdict: &str,
) -> Result<PathBuf, PageError> {
    let csv_path = out.join("diff.csv");
    let rows = read_csv(&csv_path)?;
    let column = |name: &str| {
        rows[0]
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| PageError::input(&csv_path, format!("no `{name}` column")))
    };
    let (frame_col, passed_col) = (column(FRAME)?, column(PASSED)?);
    let metric_col = column(metric_column(metric))?;
    let mut body_rows: Vec<Vec<String>> = rows[1..].to_vec();
    let problem_col = column(PROBLEM).ok();
    let badness = |row: &Vec<String>| -> Result<f64, PageError> {
        // A frame not compared has no metrics: listed first.
        if row[metric_col].is_empty() {
            return Ok(f64::INFINITY);
        }
        let value: f64 = row[metric_col].parse().map_err(|_| {
            PageError::input(
                &csv_path,
                format!(
                    "frame {}: bad {metric} value `{}`",
                    row[frame_col], row[metric_col]
                ),
            )
        })?;
        Ok(if metric == "psnr" { -value } else { value })
    };
    let mut keyed = Vec::with_capacity(body_rows.len());
    for row in body_rows.drain(..) {
        keyed.push((badness(&row)?, row));
    }
    keyed.sort_by(|(a, ra), (b, rb)| {
        b.total_cmp(a)
            .then_with(|| frame_order(ra, frame_col).cmp(&frame_order(rb, frame_col)))
    });
    let mut frames = Vec::with_capacity(keyed.len());
    for (_, row) in &keyed {
        let mut entry = frame_images(out, &row[frame_col], row[passed_col] == "true")?;
        if let Some(problem) = problem_col.map(|i| &row[i]).filter(|p| !p.is_empty()) {
            entry["problem"] = problem.as_str().into();
        }
        frames.push(entry);
    }
    // The table without the two path columns, which are long and shown nowhere else.
    let shown: Vec<usize> = (0..rows[0].len())
        .filter(|&i| !matches!(rows[0][i].as_str(), "reference" | "test"))
        .collect();
    let pick = |row: &Vec<String>| shown.iter().map(|&i| readable(&row[i])).collect::<Vec<_>>();
    let table_rows: Vec<Vec<String>> = std::iter::once(pick(&rows[0]))
        .chain(keyed.iter().map(|(_, r)| pick(r)))
        .collect();
    let not_compared = |row: &Vec<String>| problem_col.is_some_and(|i| !row[i].is_empty());
    let failed = keyed
        .iter()
        .filter(|(_, r)| r[passed_col] != "true" && !not_compared(r))
        .count();
    let unjudged = match keyed.iter().filter(|(_, r)| not_compared(r)).count() {
        0 => String::new(),
        n => format!(", {n} not compared (bad input)"),
    };
    let title = format!("mipray diff: {}", out.display());
    let body = format!(
        "<h1>{}</h1>\n<p class=\"{}\" id=\"verdict\">{}</p>\n<p class=\"note\">metric <code>{}</code>, threshold {}; \
         {failed} of {} frame(s) outside it{unjudged}. Frames are listed worst first; click a row to show it.</p>\n\
         <h2>Frame</h2>\n{}<h2>Per-frame metrics</h2>\n{}{}",
        escape(&title),
        if failed == 0 && unjudged.is_empty() {
            "verdict-pass"
        } else {
            "verdict-fail"
        },
        escape(verdict),
        escape(metric),
        escape(&format_threshold(metric, threshold)),
        keyed.len(),
        FRAME_VIEW,
        table("frames", &table_rows, 0),
        json_data("diff-data", &json!({ "frames": frames })),
    );
    write_page(out, &document(&title, &body, DIFF_JS), None)
}

/// A CSV cell for people: fractions to 5 decimals below 1, 2 above (the CSV keeps every
/// digit); integers, words and `inf` as they are.
fn readable(cell: &str) -> String {
    match cell.parse::<f64>() {
        Ok(v) if v.is_finite() && cell.contains('.') => {
            if v.abs() < 1.0 {
                format!("{v:.5}")
            } else {
                format!("{v:.2}")
            }
        }
        _ => cell.to_string(),
    }
}

/// The `diff.csv` column a metric's verdict reads.
fn metric_column(metric: &str) -> &'static str {
    match metric {
        "flip" => "mean_flip",
        "max-abs" => "max_abs",
        _ => "psnr_db",
    }
}

fn format_threshold(metric: &str, threshold: f64) -> String {
    match metric {
        "psnr" => format!("{threshold} dB"),
        _ => format!("{threshold}"),
    }
}

fn frame_order(row: &[String], frame_col: usize) -> u64 {
    row[frame_col].parse().unwrap_or(u64::MAX)
}

/// The frame's entry: its number, verdict and the images `mipray diff` wrote for it (only
/// failing frames have them).
fn frame_images(out: &Path, frame: &str, passed: bool) -> Result<Value, PageError> {
    let number: u32 = frame.parse().unwrap_or(u32::MAX);
    let mut entry = json!({ "frame": frame, "passed": passed });
    for suffix in ["ref", "test", "diff"] {
        let path = out.join(format!("frame_{number:04}_{suffix}.png"));
        entry[suffix] = if path.is_file() {
            relative_url(out, &path)?.into()
        } else {
            Value::Null
        };
    }
    Ok(entry)
}

const FRAME_VIEW: &str = r#"<div class="controls"><b id="frame-title"></b>
<button id="toggle">toggle (t)</button><span id="toggle-state" class="note"></span></div>
<div class="row" id="frame-images">
<figure><div class="swipe" id="swipe"><img alt="test frame"><img alt="reference frame"></div>
<figcaption>reference (left of the divider) against test; move the pointer to swipe</figcaption></figure>
<figure><img id="flip" alt="toggled frame"><figcaption id="flip-caption">toggle view</figcaption></figure>
<figure><img id="heat" alt="FLIP heat map"><figcaption>FLIP heat map</figcaption></figure>
</div>
<p class="note" id="no-images"></p>
"#;

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "frame,passed,psnr_db,mean_flip,max_abs,differing_pixels,differing_share,time_ratio,rays_delta,lod_recomputed_delta,mip_level_shift,reference,test\n\
        0,true,inf,0,0,0,0,,,,,r/frame_0000.png,t/frame_0000.png\n\
        1,false,18.5,0.04,255,10,0.1,,,,,r/frame_0001.png,t/frame_0001.png\n\
        2,false,30.0,0.02,80,5,0.05,,,,,r/frame_0002.png,t/frame_0002.png\n";

    fn page(metric: &str) -> String {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("diff.csv"), CSV).unwrap();
        std::fs::write(dir.path().join("frame_0001_diff.png"), b"png").unwrap();
        let path = write_diff_page(dir.path(), metric, 40.0, "FAIL: 2 of 3").unwrap();
        std::fs::read_to_string(path).unwrap()
    }

    #[test]
    fn frames_are_worst_first_for_the_chosen_metric() {
        let html = page("psnr");
        let order: Vec<usize> = ["data-key=\"1\"", "data-key=\"2\"", "data-key=\"0\""]
            .iter()
            .map(|k| html.find(k).unwrap())
            .collect();
        assert!(order.windows(2).all(|w| w[0] < w[1]), "{html}");
        assert!(html.contains("threshold 40 dB") && html.contains("verdict-fail"));
        assert!(html.contains("\"diff\":\"frame_0001_diff.png\""), "{html}");
        assert!(
            !html.contains("r/frame_0000.png"),
            "path columns are left out"
        );
        let by_max_abs = page("max-abs");
        assert!(
            by_max_abs.find("data-key=\"1\"").unwrap() < by_max_abs.find("data-key=\"2\"").unwrap()
        );
    }

    #[test]
    fn table_cells_are_rounded_for_reading() {
        assert_eq!(readable("18.52378326969016"), "18.52");
        assert_eq!(readable("0.046419791877269745"), "0.04642");
        assert_eq!(readable("3479"), "3479");
        assert_eq!(readable("inf"), "inf");
        assert_eq!(readable("false"), "false");
    }

    #[test]
    fn a_missing_or_bad_csv_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = write_diff_page(dir.path(), "psnr", 40.0, "")
            .unwrap_err()
            .to_string();
        assert!(missing.contains("diff.csv"), "{missing}");
        std::fs::write(
            dir.path().join("diff.csv"),
            "frame,passed,psnr_db\n0,true,abc\n",
        )
        .unwrap();
        let bad = write_diff_page(dir.path(), "psnr", 40.0, "")
            .unwrap_err()
            .to_string();
        assert!(
            bad.contains("diff.csv") && bad.contains("bad psnr value `abc`"),
            "{bad}"
        );
    }
}
