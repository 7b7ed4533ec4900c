//! `subpixel_reference.csv` and the Markdown section for the sub-pixel LOD reference
//! (`subpixel_reference.rs`): one row per method, errors under the longest-axis and area
//! conventions, and the share of pixels where the fit is undefined.
//!
//! Kept apart from `report.rs` (which writes `compare.csv`, `compare.md` and the plots from
//! [`super::CompareReport`]) so the two can be merged into one table later; the numbers
//! follow the same spellings (`nan` in CSV, `n/a` in Markdown).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use super::{LevelError, SubpixelSummary};
use crate::atomic_file::write_text_atomically;

/// CSV header: the method, then bias / rms / under for each convention, then the share.
pub const CSV_HEADER: &str = "method,subpixel_longest_bias,subpixel_longest_rms,\
subpixel_longest_under,subpixel_area_bias,subpixel_area_rms,subpixel_area_under,\
subpixel_undefined_share";

/// `v` with `decimals` decimals, or `nan` / `inf` / `-inf` (Python's `float()` spellings).
fn csv_number(v: f64, decimals: usize) -> String {
    if v.is_nan() {
        "nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        format!("{v:.decimals$}")
    }
}

fn md_number(v: f64, decimals: usize) -> String {
    if v.is_nan() {
        "n/a".into()
    } else {
        format!("{v:.decimals$}")
    }
}

/// Bias, RMS and under-filtered share as CSV fields.
fn csv_fields(e: &LevelError) -> [String; 3] {
    [
        csv_number(e.bias, 3),
        csv_number(e.rms, 3),
        csv_number(e.under, 3),
    ]
}

/// The same as Markdown cells, the bias with its sign.
fn md_cells(e: &LevelError) -> [String; 3] {
    let bias = if e.bias >= 0.0 {
        format!("+{}", md_number(e.bias, 3))
    } else {
        md_number(e.bias, 3)
    };
    [bias, md_number(e.rms, 3), md_number(e.under, 3)]
}

/// The CSV text (header and one row per method).
pub fn csv(rows: &[SubpixelSummary]) -> String {
    let mut text = format!("{CSV_HEADER}\n");
    for r in rows {
        let mut fields = vec![r.method.replace([',', '"', '\n', '\r'], "_")];
        fields.extend(csv_fields(&r.longest_axis));
        fields.extend(csv_fields(&r.area));
        fields.push(csv_number(r.undefined_share, 4));
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    text
}

/// Writes `subpixel_reference.csv` into `dir` (which exists) and returns its path.
pub fn write_csv(rows: &[SubpixelSummary], dir: &Path) -> Result<PathBuf> {
    let path = dir.join("subpixel_reference.csv");
    write_text_atomically(&path, &csv(rows))
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// The Markdown section: a table and how to read it.
pub fn markdown(rows: &[SubpixelSummary]) -> String {
    let mut lines = vec![
        "## LOD error against the sub-pixel reference".to_string(),
        String::new(),
        format!(
            "Levels from {n}x{n} real sub-pixel rays per pixel (each traced through the scene), \
             the texel footprint fitted to the UVs of those reaching the centre ray's surface. \
             `longest` is the OpenGL convention the methods aim at; `area` the square of the \
             same area (it does not charge the incidence elongation in full). Bias: mean \
             level minus reference (positive: blurrier); under: share more than half a level \
             too sharp. `diffs-aniso` and `diffs-ewa` are compared with the level of the same \
             fit their filters are built on (taps, minor axis) under both. The `lod` columns of the table above use the probe's \
             finite-difference reference instead.",
            n = super::subpixel_reference::GRID
        ),
        String::new(),
        "| method | longest bias | longest rms | longest under | area bias | area rms | area under |"
            .to_string(),
        "|---|---:|---:|---:|---:|---:|---:|".to_string(),
    ];
    for r in rows {
        let mut cells = vec![r.method.replace('|', "\\|")];
        cells.extend(md_cells(&r.longest_axis));
        cells.extend(md_cells(&r.area));
        lines.push(format!("| {} |", cells.join(" | ")));
    }
    if let Some(first) = rows.first() {
        lines.push(String::new());
        lines.push(format!(
            "Fit undefined (silhouettes, seams) on {:.1}% of the textured pixels.",
            first.undefined_share * 100.0
        ));
    }
    lines.push(String::new());
    lines.join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(method: &str, bias: f64) -> SubpixelSummary {
        let e = LevelError {
            bias,
            rms: bias.abs(),
            under: 0.25,
        };
        SubpixelSummary {
            method: method.into(),
            longest_axis: e,
            area: LevelError {
                bias: f64::NAN,
                ..e
            },
            undefined_share: 0.125,
            frames: Vec::new(),
        }
    }

    #[test]
    fn csv_has_the_header_and_one_row_per_method() {
        let text = csv(&[row("none@16", -2.5), row("paper", 0.125)]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], CSV_HEADER);
        assert_eq!(
            lines[1],
            "none@16,-2.500,2.500,0.250,nan,2.500,0.250,0.1250"
        );
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[2].split(',').count(), CSV_HEADER.split(',').count());
    }

    #[test]
    fn markdown_names_every_method_and_the_undefined_share() {
        let text = markdown(&[row("none", -1.0), row("cones", 0.5)]);
        assert!(
            text.contains("| none | -1.000 | 1.000 | 0.250 | n/a |"),
            "{text}"
        );
        assert!(text.contains("| cones | +0.500"));
        assert!(text.contains("12.5%"));
    }
}
