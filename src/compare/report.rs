//! The files `mipray compare` writes from a [`CompareReport`].
//!
//! - `compare.csv`: one row per method, in report order, with the columns
//!   `method,bytes_per_ray,ms_per_frame,overhead_pct,psnr,ssim,flip,lod_bias,lod_rms,lod_under,flicker`
//!   (the means over the frame range; see [`MethodSummary`]).
//! - `compare_frames.csv`: long format, one row per (method, frame), with the columns
//!   `method,frame,ms,psnr,ssim,flip,lod_bias,lod_rms,lod_under,lod_pixels,flicker`;
//!   `flicker` is empty for the first frame of the range, which has no previous frame.
//! - `compare.md`: the run's settings, the method table (the columns of `compare.csv`), how
//!   to read it, Table 1 of Park & Kim (`none` vs `paper` by light count) when it was
//!   measured, and the share of texture lookups per MIP level.
//! - `pareto.svg`: error against time, one labelled point per method; left panel mean
//!   FLIP, right panel LOD RMS error (levels), both against ms per frame.
//! - `error_per_frame.svg`: mean FLIP of every frame, one line per method.
//! - `mip_levels.svg`: share of lookups per MIP level, grouped bars per method (the
//!   paper's Fig. 4).
//!
//! Numbers have a fixed number of decimals per column (ms 3, overhead 2, PSNR 2, SSIM 5,
//! FLIP 5, LOD 3, flicker 3). In the CSV files NaN is written `nan` and infinities `inf` /
//! `-inf`, so every column stays numeric for Python's `float()` and Rust's `parse`; the
//! Markdown writes `n/a` for NaN, for people.
//!
//! A method keeps its colour in every plot (its index in the report, over a palette of 8;
//! more methods reuse colours). Non-finite values are left out of the plots; a plot with
//! nothing to draw still is a valid SVG whose caption says so.
//!
//! A report without methods is not an error: every file is still written (CSV headers only,
//! plots whose captions say there is no data), so a run that measured nothing leaves a complete,
//! self-describing folder instead of a partial one.
//!
//! Every file is written to a temporary sibling and renamed into place.

use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{CompareReport, LightsRow, MethodSummary};
use crate::output::write_text_atomically;
use crate::report::plot::PALETTE;

/// Why the compare report could not be written; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum CompareReportError {
    /// A folder or file could not be created or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// plotters could not draw the plot.
    #[error("{path}: cannot draw the plot: {message}")]
    Plot { path: PathBuf, message: String },
}

const SUMMARY_HEADER: &str = "method,bytes_per_ray,ms_per_frame,overhead_pct,psnr,ssim,flip,lod_bias,lod_rms,lod_under,flicker";
const FRAMES_HEADER: &str =
    "method,frame,ms,psnr,ssim,flip,lod_bias,lod_rms,lod_under,lod_pixels,flicker";

// Decimals per kind of quantity, shared by the CSV files and the Markdown.
const MS_DECIMALS: usize = 3;
const OVERHEAD_DECIMALS: usize = 2;
const PSNR_DECIMALS: usize = 2;
const SSIM_DECIMALS: usize = 5;
const FLIP_DECIMALS: usize = 5;
const LOD_DECIMALS: usize = 3;
const FLICKER_DECIMALS: usize = 3;

/// `compare.csv`: the header and one row per method, in report order.
pub fn csv(report: &CompareReport) -> String {
    let rows = report.methods.iter().map(|m| {
        let mut fields = vec![csv_field(&m.method)];
        fields.extend(summary_numbers(m, fixed));
        fields.join(",")
    });
    csv_lines(SUMMARY_HEADER, rows)
}

/// `compare_frames.csv`: the header and one row per (method, frame), methods in report
/// order, frames in the order measured.
pub fn frames_csv(report: &CompareReport) -> String {
    let rows = report.methods.iter().flat_map(|m| {
        let method = csv_field(&m.method);
        m.frames.iter().map(move |f| {
            let fields = [
                method.clone(),
                f.frame.to_string(),
                fixed(f.ms, MS_DECIMALS),
                fixed(f.psnr, PSNR_DECIMALS),
                fixed(f.ssim, SSIM_DECIMALS),
                fixed(f.flip, FLIP_DECIMALS),
                fixed(f.lod_bias, LOD_DECIMALS),
                fixed(f.lod_rms, LOD_DECIMALS),
                fixed(f.lod_under, LOD_DECIMALS),
                f.lod_pixels.to_string(),
                f.flicker
                    .map_or_else(String::new, |v| fixed(v, FLICKER_DECIMALS)),
            ];
            fields.join(",")
        })
    });
    csv_lines(FRAMES_HEADER, rows)
}

/// The header and rows, each ending in a newline.
fn csv_lines(header: &str, rows: impl Iterator<Item = String>) -> String {
    let mut out = String::from(header);
    out.push('\n');
    for row in rows {
        out.push_str(&row);
        out.push('\n');
    }
    out
}

/// A method's numeric columns after `method`, as `compare.csv` and the Markdown table
/// order them; `number` decides how NaN reads.
fn summary_numbers(m: &MethodSummary, number: fn(f64, usize) -> String) -> Vec<String> {
    vec![
        m.bytes_per_ray.to_string(),
        number(m.ms_per_frame, MS_DECIMALS),
        number(m.overhead_pct, OVERHEAD_DECIMALS),
        number(m.psnr, PSNR_DECIMALS),
        number(m.ssim, SSIM_DECIMALS),
        number(m.flip, FLIP_DECIMALS),
        number(m.lod_bias, LOD_DECIMALS),
        number(m.lod_rms, LOD_DECIMALS),
        number(m.lod_under, LOD_DECIMALS),
        number(m.flicker, FLICKER_DECIMALS),
    ]
}

/// `v` with `decimals` decimals; NaN and infinities spelled as Python's `float()` reads
/// them (`nan`, `inf`, `-inf`), so a column stays numeric.
fn fixed(v: f64, decimals: usize) -> String {
    if v.is_nan() {
        "nan".to_owned()
    } else if v.is_infinite() {
        if v > 0.0 { "inf" } else { "-inf" }.to_owned()
    } else {
        format!("{v:.decimals$}")
    }
}

/// Like [`fixed`], but NaN (not measured) reads `n/a` for a person.
fn readable(v: f64, decimals: usize) -> String {
    if v.is_nan() {
        "n/a".to_owned()
    } else {
        fixed(v, decimals)
    }
}

/// `text` as one CSV field: quoted (quotes doubled) only if it holds a separator, quote or
/// line break. Method names are fixed identifiers, so this is a safeguard.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_owned()
    }
}

/// `text` as one Markdown table cell (a `|` would end the cell).
fn md_cell(text: &str) -> String {
    text.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// `compare.md`: settings, method table, how to read it, Table 1 (when measured) and the
/// MIP level shares.
pub fn markdown(report: &CompareReport) -> String {
    let mut lines = vec![
        format!("# LOD methods compared on {}", report.scene),
        String::new(),
        run_settings(report),
        String::new(),
    ];
    lines.extend(methods_table(&report.methods));
    lines.push(String::new());
    lines.push(HOW_TO_READ.to_owned());
    if !report.table1.is_empty() {
        lines.push(String::new());
        lines.extend(table1_section(&report.table1));
    }
    lines.push(String::new());
    lines.extend(mip_share_section(&report.methods));
    let mut md = lines.join("\n");
    md.push('\n');
    md
}

const HOW_TO_READ: &str = "**How to read.** `ms/frame` is the mean per-frame render time \
(median over the repeats) plus the method's share of the frame update; `overhead %` is \
against `none` measured in the same interleaved run, so both saw the same machine state. \
PSNR, SSIM and FLIP compare every frame with the level-0 supersampled reference (PSNR `inf`: \
identical). `LOD bias` is the mean of the method's MIP level minus the finite-difference \
reference level, in levels: above 0 the method is blurrier than the reference, below 0 \
sharper; `LOD RMS` is the root mean square of the same difference. `LOD under` is the share \
of pixels under-filtered by more than half a level, i.e. at risk of aliasing. `flicker` is \
the mean absolute difference between the method's and the reference's frame-to-frame \
change, in 8-bit code values. `n/a`: not measured (flicker needs two frames).";

/// One line: size, frame range, reference spp, repeats, lights, LOD bias, shared update.
fn run_settings(report: &CompareReport) -> String {
    format!(
        "{}x{} px, {}, reference {} spp, {} repeats, {} lights, LOD bias {}, shared update {} ms/frame",
        report.width,
        report.height,
        frame_span(&report.frames),
        report.reference_spp,
        report.repeats,
        report.lights,
        report.lod_bias,
        readable(report.shared_update_ms, MS_DECIMALS),
    )
}

/// `frames first..last (count)`, or `no frames`.
fn frame_span(frames: &[u32]) -> String {
    match (frames.iter().min(), frames.iter().max()) {
        (Some(first), Some(last)) => format!("frames {first}..{last} ({} frames)", frames.len()),
        _ => "no frames".to_owned(),
    }
}

/// The method table: the columns of `compare.csv`, numbers right-aligned.
fn methods_table(methods: &[MethodSummary]) -> Vec<String> {
    if methods.is_empty() {
        return vec!["No methods were measured.".to_owned()];
    }
    let header = [
        "method",
        "bytes/ray",
        "ms/frame",
        "overhead %",
        "PSNR (dB)",
        "SSIM",
        "FLIP",
        "LOD bias",
        "LOD RMS",
        "LOD under",
        "flicker",
    ];
    let mut lines = table_head(&header);
    lines.extend(methods.iter().map(|m| {
        let mut cells = vec![md_cell(&m.method)];
        cells.extend(summary_numbers(m, readable));
        table_row(&cells)
    }));
    lines
}

/// Header and alignment rows: first column left-aligned, the numbers right-aligned.
fn table_head<S: AsRef<str>>(header: &[S]) -> Vec<String> {
    let align: Vec<&str> = (0..header.len())
        .map(|i| if i == 0 { ":---" } else { "---:" })
        .collect();
    vec![table_row(header), table_row(&align)]
}

fn table_row<S: AsRef<str>>(cells: &[S]) -> String {
    let cells: Vec<&str> = cells.iter().map(AsRef::as_ref).collect();
    format!("| {} |", cells.join(" | "))
}

/// Table 1 of Park & Kim: `none` against `paper` by light count.
fn table1_section(rows: &[LightsRow]) -> Vec<String> {
    let mut lines = vec![
        "## Table 1 (Park & Kim): none vs paper by light count".to_owned(),
        String::new(),
    ];
    lines.extend(table_head(&["lights", "none ms", "paper ms", "overhead %"]));
    lines.extend(rows.iter().map(|r| {
        table_row(&[
            r.lights.to_string(),
            readable(r.none_ms, MS_DECIMALS),
            readable(r.paper_ms, MS_DECIMALS),
            readable(r.overhead_pct, OVERHEAD_DECIMALS),
        ])
    }));
    lines
}

/// Methods as rows, levels 0 up to the highest level any method used as columns, in %.
fn mip_share_section(methods: &[MethodSummary]) -> Vec<String> {
    let mut lines = vec!["## MIP level share".to_owned(), String::new()];
    let Some(highest) = highest_used_level(methods) else {
        lines.push("No texture lookups were recorded.".to_owned());
        return lines;
    };
    lines.push("Share of texture lookups per MIP level, in %.".to_owned());
    lines.push(String::new());
    let header: Vec<String> = std::iter::once("method".to_owned())
        .chain((0..=highest).map(|level| format!("L{level}")))
        .collect();
    lines.extend(table_head(&header));
    lines.extend(methods.iter().map(|m| {
        let mut cells = vec![md_cell(&m.method)];
        cells.extend((0..=highest).map(|level| format!("{:.1}", share(m, level) * 100.0)));
        table_row(&cells)
    }));
    lines
}

/// The highest level with a positive share in any method; `None` without lookups.
fn highest_used_level(methods: &[MethodSummary]) -> Option<usize> {
    methods
        .iter()
        .filter_map(|m| (0..m.mip_share.len()).rev().find(|&l| share(m, l) > 0.0))
        .max()
}

/// A method's share of lookups at `level`; 0 beyond its levels or when not finite (nothing
/// to show for it).
fn share(m: &MethodSummary, level: usize) -> f64 {
    m.mip_share
        .get(level)
        .copied()
        .filter(|s| s.is_finite())
        .unwrap_or(0.0)
}

/// File names of the plots, with the function drawing each.
type Renderer = fn(&CompareReport) -> Result<String, String>;
const PLOTS: [(&str, Renderer); 3] = [
    ("pareto.svg", render_pareto),
    ("error_per_frame.svg", render_error_per_frame),
    ("mip_levels.svg", render_mip_levels),
];

/// Writes `pareto.svg`, `error_per_frame.svg` and `mip_levels.svg` into `dir` (created if
/// needed); returns their paths in that order.
pub fn write_plots(report: &CompareReport, dir: &Path) -> Result<Vec<PathBuf>, CompareReportError> {
    create_dir(dir)?;
    PLOTS
        .iter()
        .map(|(name, render)| {
            let path = dir.join(name);
            let svg = render(report).map_err(|message| CompareReportError::Plot {
                path: path.clone(),
                message,
            })?;
            write_file(&path, &svg)?;
            Ok(path)
        })
        .collect()
}

/// Writes `compare.csv`, `compare_frames.csv`, `compare.md` and the three plots into `dir`
/// (created if needed); returns the six paths in that order. A report without methods
/// still gets all six files (see the module comment).
pub fn write_all(report: &CompareReport, dir: &Path) -> Result<Vec<PathBuf>, CompareReportError> {
    create_dir(dir)?;
    let texts = [
        ("compare.csv", csv(report)),
        ("compare_frames.csv", frames_csv(report)),
        ("compare.md", markdown(report)),
    ];
    let mut written = Vec::with_capacity(texts.len() + PLOTS.len());
    for (name, text) in texts {
        let path = dir.join(name);
        write_file(&path, &text)?;
        written.push(path);
    }
    written.extend(write_plots(report, dir)?);
    Ok(written)
}

fn create_dir(dir: &Path) -> Result<(), CompareReportError> {
    std::fs::create_dir_all(dir).map_err(|source| CompareReportError::Io {
        path: dir.to_path_buf(),
        source,
    })
}

fn write_file(path: &Path, text: &str) -> Result<(), CompareReportError> {
    write_text_atomically(path, text).map_err(|source| CompareReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Method colours, by index in the report, so a method looks the same in every plot (the
/// palette of `mipray report`).
fn method_color(index: usize) -> RGBColor {
    PALETTE[index % PALETTE.len()]
}

const PARETO_SIZE: (u32, u32) = (1400, 600);
const PER_FRAME_SIZE: (u32, u32) = (1000, 500);
const MIP_LEVELS_SIZE: (u32, u32) = (1000, 500);
const FONT: &str = "sans-serif";
/// Height of the strip under a Pareto panel naming the methods it could not place.
const NOTE_HEIGHT: u32 = 26;

fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// Share of a plot's y range kept above the data for a legend of `entries` lines, so the
/// legend never covers data.
fn legend_headroom(entries: usize) -> f64 {
    (0.05 + 0.055 * entries as f64).min(0.6)
}

/// The error a Pareto panel plots against time.
struct ErrorAxis {
    caption: &'static str,
    y_desc: &'static str,
    value: fn(&MethodSummary) -> f64,
}

fn mean_flip(m: &MethodSummary) -> f64 {
    m.flip
}

fn lod_rms(m: &MethodSummary) -> f64 {
    m.lod_rms
}

const FLIP_AXIS: ErrorAxis = ErrorAxis {
    caption: "Mean FLIP",
    y_desc: "mean FLIP (lower is better)",
    value: mean_flip,
};
const LOD_RMS_AXIS: ErrorAxis = ErrorAxis {
    caption: "LOD RMS error",
    y_desc: "LOD RMS error (levels)",
    value: lod_rms,
};

/// A method placed in a Pareto panel: (index in the report, ms per frame, error).
type ParetoPoint = (usize, f64, f64);

/// `pareto.svg`: FLIP (left) and LOD RMS (right) against ms per frame.
fn render_pareto(report: &CompareReport) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, PARETO_SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let title = format!("Error against time per frame: {}", report.scene);
        let body = root.titled(&title, (FONT, 24)).map_err(text)?;
        let (left, right) = body.split_horizontally(PARETO_SIZE.0 / 2);
        pareto_panel(&left, &report.methods, &FLIP_AXIS)?;
        pareto_panel(&right, &report.methods, &LOD_RMS_AXIS)?;
        root.present().map_err(text)?;
    }
    Ok(svg)
}

/// One Pareto panel; methods without a finite (time, error) pair are named under it.
fn pareto_panel(
    area: &DrawingArea<SVGBackend, Shift>,
    methods: &[MethodSummary],
    axis: &ErrorAxis,
) -> Result<(), String> {
    let (points, unplaced) = pareto_points(methods, axis.value);
    let (plot, note) = area.split_vertically(area.dim_in_pixel().1.saturating_sub(NOTE_HEIGHT));
    let caption = if points.is_empty() {
        format!("{}: no data", axis.caption)
    } else {
        format!("{} vs time per frame", axis.caption)
    };
    let (x, y) = pareto_ranges(&points);
    let mut chart = ChartBuilder::on(&plot)
        .caption(caption, (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x, y)
        .map_err(text)?;
    chart
        .configure_mesh()
        .x_desc("time per frame (ms)")
        .y_desc(axis.y_desc)
        .draw()
        .map_err(text)?;
    let anchors: Vec<(i32, i32)> = points
        .iter()
        .map(|&(_, x, y)| chart.backend_coord(&(x, y)))
        .collect();
    let widths: Vec<i32> = points
        .iter()
        .map(|&(i, _, _)| label_width(&methods[i].method))
        .collect();
    let (x_px, y_px) = chart.plotting_area().get_pixel_range();
    let offsets = place_labels(
        &anchors,
        &widths,
        (x_px.start, y_px.start, x_px.end, y_px.end),
    );
    chart
        .draw_series(points.iter().zip(offsets).map(|(&(i, x, y), offset)| {
            EmptyElement::at((x, y))
                + Circle::new((0, 0), POINT_RADIUS, method_color(i).filled())
                // In the point's colour, so a label placed away from its point still
                // says which point it names.
                + Text::new(
                    methods[i].method.clone(),
                    offset,
                    (FONT, LABEL_FONT_SIZE).into_font().color(&method_color(i)),
                )
        }))
        .map_err(text)?;
    if !unplaced.is_empty() {
        let message = format!("not plotted (no finite value): {}", unplaced.join(", "));
        note.draw(&Text::new(message, (12, 4), (FONT, 14)))
            .map_err(text)?;
    }
    Ok(())
}

const POINT_RADIUS: i32 = 5;
const LABEL_FONT_SIZE: i32 = 15;

/// A pixel rectangle: left, top, right, bottom.
type PixelBox = (i32, i32, i32, i32);

/// Estimated pixel width of a point label: the SVG has no font metrics, and 0.6 em per
/// character is a safe average for sans-serif.
fn label_width(label: &str) -> i32 {
    (label.chars().count() as f64 * 0.6 * f64::from(LABEL_FONT_SIZE)).ceil() as i32
}

/// Pixel offset (top-left of the text from its point) of each label, chosen greedily in
/// order: the first spot around the point that overlaps neither a point, an earlier label,
/// nor the plot's edge; failing that, the spot overlapping least. Methods with near-equal
/// values would otherwise print their names over each other.
fn place_labels(anchors: &[(i32, i32)], widths: &[i32], plot: PixelBox) -> Vec<(i32, i32)> {
    let r = POINT_RADIUS;
    let mut taken: Vec<PixelBox> = anchors
        .iter()
        .map(|&(x, y)| (x - r, y - r, x + r, y + r))
        .collect();
    let mut offsets = Vec::with_capacity(anchors.len());
    for (&(x, y), &width) in anchors.iter().zip(widths) {
        let candidates = label_candidates(width);
        let cost = |&(dx, dy): &(i32, i32)| {
            let rect = (x + dx, y + dy, x + dx + width, y + dy + LABEL_FONT_SIZE + 2);
            let overlap: i64 = taken.iter().map(|t| overlap_area(rect, *t)).sum();
            let outside = area(rect) - overlap_area(rect, plot);
            overlap + 4 * outside
        };
        // min_by_key keeps the first of equal costs: the preferred spot wins ties.
        let best = *candidates
            .iter()
            .min_by_key(|c| cost(c))
            .expect("candidates");
        let (dx, dy) = best;
        taken.push((x + dx, y + dy, x + dx + width, y + dy + LABEL_FONT_SIZE + 2));
        offsets.push(best);
    }
    offsets
}

/// Spots for a label of `width` pixels, in order of preference: right of the point (above,
/// below), left of it, then one line further out.
fn label_candidates(width: i32) -> [(i32, i32); 8] {
    let (right, left) = (POINT_RADIUS + 3, -POINT_RADIUS - 3 - width);
    let (above, below) = (-LABEL_FONT_SIZE - 3, 3);
    let line = LABEL_FONT_SIZE + 3;
    [
        (right, above),
        (right, below),
        (left, above),
        (left, below),
        (right, above - line),
        (right, below + line),
        (left, above - line),
        (left, below + line),
    ]
}

fn area(b: PixelBox) -> i64 {
    i64::from((b.2 - b.0).max(0)) * i64::from((b.3 - b.1).max(0))
}

fn overlap_area(a: PixelBox, b: PixelBox) -> i64 {
    area((a.0.max(b.0), a.1.max(b.1), a.2.min(b.2), a.3.min(b.3)))
}

/// The methods with a finite (ms per frame, `error`) pair, and the names of the others.
fn pareto_points(
    methods: &[MethodSummary],
    error: fn(&MethodSummary) -> f64,
) -> (Vec<ParetoPoint>, Vec<&str>) {
    let mut points = Vec::new();
    let mut unplaced = Vec::new();
    for (i, m) in methods.iter().enumerate() {
        let (x, y) = (m.ms_per_frame, error(m));
        if x.is_finite() && y.is_finite() {
            points.push((i, x, y));
        } else {
            unplaced.push(m.method.as_str());
        }
    }
    (points, unplaced)
}

/// Axis ranges of a Pareto panel. x: 10 % of the spread free on the left and 30 % on the
/// right, where the labels go (times of methods differ by a few %, so x does not start at
/// 0). y: from 0 (errors are non-negative) to 25 % above the largest error.
fn pareto_ranges(points: &[ParetoPoint]) -> (Range<f64>, Range<f64>) {
    let Some((x_lo, x_hi)) = bounds(points.iter().map(|p| p.1)) else {
        return (0.0..1.0, 0.0..1.0);
    };
    let (y_lo, y_hi) = bounds(points.iter().map(|p| p.2)).expect("points is not empty");
    (
        padded(x_lo, x_hi, 0.1, 0.3),
        padded(y_lo.min(0.0), y_hi, 0.0, 0.25),
    )
}

/// `lo..hi` widened by `below` and `above` times its spread; a single value gets a spread
/// of 10 % of itself (1 at zero) so the range is never empty.
fn padded(lo: f64, hi: f64, below: f64, above: f64) -> Range<f64> {
    let spread = if hi > lo {
        hi - lo
    } else if lo != 0.0 {
        lo.abs() * 0.1
    } else {
        1.0
    };
    (lo - below * spread)..(hi + above * spread)
}

/// Smallest and largest of `values`, `None` when there are none.
fn bounds(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// Points of one line segment: (frame, value).
type Run = Vec<(i64, f64)>;

/// `error_per_frame.svg`: mean FLIP of every frame, one line per method.
fn render_error_per_frame(report: &CompareReport) -> Result<String, String> {
    let lines: Vec<Vec<Run>> = report.methods.iter().map(flip_runs).collect();
    let highest = bounds(lines.iter().flatten().flatten().map(|p| p.1)).map(|b| b.1);
    let caption = match highest {
        Some(_) => format!("Mean FLIP per frame: {}", report.scene),
        None => format!("Mean FLIP per frame: {}: no data", report.scene),
    };
    let data_top = highest.filter(|h| *h > 0.0).unwrap_or(1.0);
    let top = data_top / (1.0 - legend_headroom(report.methods.len()));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, PER_FRAME_SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, (FONT, 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(frame_range(report), 0.0..top)
            .map_err(text)?;
        chart
            .configure_mesh()
            .x_desc("frame")
            .y_desc("mean FLIP (lower is better)")
            .x_label_formatter(&|f| f.to_string())
            .draw()
            .map_err(text)?;
        for (i, (m, runs)) in report.methods.iter().zip(&lines).enumerate() {
            let color = method_color(i);
            let style = color.stroke_width(2);
            chart
                .draw_series(runs.iter().map(|run| PathElement::new(run.clone(), style)))
                .map_err(text)?
                .label(m.method.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
            // A segment of one frame has no line; a dot shows it.
            let dots = runs.iter().filter(|run| run.len() == 1).flatten();
            chart
                .draw_series(dots.map(|&p| Circle::new(p, 3, color.filled())))
                .map_err(text)?;
        }
        draw_legend(&mut chart, report.methods.len())?;
        root.present().map_err(text)?;
    }
    Ok(svg)
}

/// A method's FLIP by frame, split where the value is not finite (nothing is drawn for a
/// value that is not there).
fn flip_runs(m: &MethodSummary) -> Vec<Run> {
    let mut frames: Vec<(i64, f64)> = m
        .frames
        .iter()
        .map(|f| (i64::from(f.frame), f.flip))
        .collect();
    frames.sort_by_key(|p| p.0);
    frames
        .split(|p| !p.1.is_finite())
        .filter(|run| !run.is_empty())
        .map(<[_]>::to_vec)
        .collect()
}

/// First to last frame of the report and of every method (widened by one when there is a
/// single frame, 0..1 when there is none).
fn frame_range(report: &CompareReport) -> Range<i64> {
    let method_frames = report
        .methods
        .iter()
        .flat_map(|m| &m.frames)
        .map(|f| f.frame);
    let all = report.frames.iter().copied().chain(method_frames);
    let (first, last) = all
        .fold(None, |acc: Option<(u32, u32)>, f| match acc {
            None => Some((f, f)),
            Some((lo, hi)) => Some((lo.min(f), hi.max(f))),
        })
        .map_or((0, 0), |(lo, hi)| (i64::from(lo), i64::from(hi)));
    first..last.max(first + 1)
}

/// `mip_levels.svg`: share of lookups per MIP level, one bar per method in each level's
/// group (the paper's Fig. 4).
fn render_mip_levels(report: &CompareReport) -> Result<String, String> {
    let methods = &report.methods;
    let highest = highest_used_level(methods);
    let levels = highest.unwrap_or(0);
    let caption = match highest {
        Some(_) => format!("Share of texture lookups per MIP level: {}", report.scene),
        None => format!(
            "Share of texture lookups per MIP level: {}: no lookups",
            report.scene
        ),
    };
    let largest = (0..=levels)
        .flat_map(|l| methods.iter().map(move |m| share(m, l) * 100.0))
        .fold(0.0, f64::max);
    let data_top = if largest > 0.0 { largest } else { 100.0 };
    let top = data_top / (1.0 - legend_headroom(methods.len()));
    // Each level is a slot of width 1 centred on the level.
    let x = -0.5..levels as f64 + 0.5;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, MIP_LEVELS_SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, (FONT, 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x, 0.0..top)
            .map_err(text)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc("MIP level")
            .y_desc("share of lookups (%)")
            // One tick per level asked for; only whole levels are labelled.
            .x_labels(levels + 2)
            .x_label_formatter(&level_label)
            .y_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(text)?;
        for (i, m) in methods.iter().enumerate() {
            let color = method_color(i);
            let bars = (0..=levels)
                .map(|l| (l, share(m, l) * 100.0))
                .filter(|&(_, pct)| pct > 0.0)
                .map(|(l, pct)| {
                    let (x0, x1) = bar_span(l, i, methods.len());
                    Rectangle::new([(x0, 0.0), (x1, pct)], color.filled())
                });
            chart
                .draw_series(bars)
                .map_err(text)?
                .label(m.method.as_str())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 6), (x + 14, y + 6)], color.filled())
                });
        }
        draw_legend(&mut chart, methods.len())?;
        root.present().map_err(text)?;
    }
    Ok(svg)
}

/// A tick on the level axis: the level if whole, nothing between levels.
fn level_label(x: &f64) -> String {
    if (x - x.round()).abs() < 1e-9 && *x >= 0.0 {
        format!("{x:.0}")
    } else {
        String::new()
    }
}

/// x extent of method `index`'s bar (of `count`) at `level`: the bars of a level share the
/// middle 80 % of its slot, leaving a gap between levels.
fn bar_span(level: usize, index: usize, count: usize) -> (f64, f64) {
    let width = 0.8 / count as f64;
    let x0 = level as f64 - 0.4 + index as f64 * width;
    (x0, x0 + width)
}

/// The legend in the upper right (the headroom kept free), when there are methods.
fn draw_legend<'a, 'b: 'a, C>(
    chart: &mut ChartContext<'a, SVGBackend<'b>, C>,
    entries: usize,
) -> Result<(), String>
where
    C: CoordTranslate,
{
    if entries == 0 {
        return Ok(());
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(text)
}

#[cfg(test)]
mod tests {
    use super::super::FrameErrors;
    use super::*;

    const METHODS: [&str; 3] = ["none", "paper", "ray_cones"];

    fn frame(frame: u32, ms: f64, flip: f64) -> FrameErrors {
        FrameErrors {
            frame,
            ms,
            psnr: 38.5,
            ssim: 0.98765,
            flip,
            lod_bias: 0.25,
            lod_rms: 0.5,
            lod_under: 0.125,
            lod_pixels: 1000,
            flicker: (frame > 10).then_some(1.5),
        }
    }

    fn method(name: &str, ms: f64, flip: f64, mip_share: Vec<f64>) -> MethodSummary {
        MethodSummary {
            method: name.to_owned(),
            bytes_per_ray: 4,
            ms_per_frame: ms,
            overhead_pct: 1.5,
            psnr: 38.5,
            ssim: 0.98765,
            flip,
            lod_bias: 0.25,
            lod_rms: 0.5,
            lod_under: 0.125,
            flicker: 1.5,
            mip_share,
            frames: (10..13).map(|f| frame(f, ms, flip)).collect(),
        }
    }

    /// 3 methods on frames 10..=12: `none` has an infinite PSNR (mean and first frame), `ray_cones` a NaN
    /// flicker; Table 1 has two rows.
    fn sample_report() -> CompareReport {
        let mut none = method("none", 12.3456, 0.05, vec![1.0]);
        none.psnr = f64::INFINITY;
        none.frames[0].psnr = f64::INFINITY;
        let paper = method("paper", 12.9, 0.03, vec![0.5, 0.3, 0.2, 0.0, 0.0]);
        let mut cones = method("ray_cones", 13.5, 0.025, vec![0.6, 0.4]);
        cones.flicker = f64::NAN;
        CompareReport {
            scene: "sponza".to_owned(),
            width: 320,
            height: 240,
            frames: vec![10, 11, 12],
            reference_spp: 64,
            repeats: 5,
            lights: 2,
            shared_update_ms: 0.75,
            lod_bias: 0.0,
            methods: vec![none, paper, cones],
            table1: vec![
                LightsRow {
                    lights: 1,
                    none_ms: 10.0,
                    paper_ms: 10.4,
                    overhead_pct: 4.0,
                },
                LightsRow {
                    lights: 8,
                    none_ms: 30.0,
                    paper_ms: 30.6,
                    overhead_pct: 2.0,
                },
            ],
        }
    }

    /// Every float of every method and frame set to NaN (flicker too).
    fn all_nan_report() -> CompareReport {
        let mut report = sample_report();
        for m in &mut report.methods {
            m.ms_per_frame = f64::NAN;
            m.flip = f64::NAN;
            m.lod_rms = f64::NAN;
            m.mip_share = vec![f64::NAN; 3];
            for f in &mut m.frames {
                f.ms = f64::NAN;
                f.flip = f64::NAN;
                f.flicker = Some(f64::NAN);
            }
        }
        report
    }

    /// The text of every `<text>` element of the SVG at `path`, which must parse as XML.
    fn svg_texts(path: &Path) -> Vec<String> {
        let svg = std::fs::read_to_string(path).unwrap();
        let doc = roxmltree::Document::parse(&svg)
            .unwrap_or_else(|e| panic!("{}: invalid XML: {e}", path.display()));
        doc.descendants()
            .filter(|n| n.has_tag_name("text"))
            .map(|n| {
                n.descendants()
                    .filter(|t| t.is_text())
                    .filter_map(|t| t.text())
                    .collect()
            })
            .collect()
    }

    #[test]
    fn csv_has_the_header_and_one_parseable_row_per_method() {
        let report = sample_report();
        let csv = csv(&report);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], SUMMARY_HEADER);
        assert_eq!(lines.len(), 1 + METHODS.len());
        let columns = SUMMARY_HEADER.split(',').count();
        for (line, m) in lines[1..].iter().zip(&report.methods) {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields.len(), columns, "{line}");
            assert_eq!(fields[0], m.method);
            for field in &fields[1..] {
                field
                    .parse::<f64>()
                    .unwrap_or_else(|_| panic!("{field} in {line}"));
            }
            let ms: f64 = fields[2].parse().unwrap();
            assert!(
                (ms - m.ms_per_frame).abs() <= 0.0005,
                "{ms} vs {}",
                m.ms_per_frame
            );
        }
        assert_eq!(lines[1].split(',').nth(4), Some("inf"));
        assert_eq!(lines[3].split(',').nth(10), Some("nan"));
    }

    #[test]
    fn numbers_have_fixed_decimals_and_python_spellings() {
        assert_eq!(fixed(12.3456, MS_DECIMALS), "12.346");
        assert_eq!(fixed(f64::NAN, 3), "nan");
        assert_eq!(fixed(f64::INFINITY, 2), "inf");
        assert_eq!(fixed(f64::NEG_INFINITY, 2), "-inf");
        assert_eq!(readable(f64::NAN, 3), "n/a");
    }

    #[test]
    fn csv_quotes_only_fields_that_need_it() {
        assert_eq!(csv_field("paper"), "paper");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
    }

    #[test]
    fn frames_csv_has_one_row_per_method_and_frame() {
        let report = sample_report();
        let csv = frames_csv(&report);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], FRAMES_HEADER);
        assert_eq!(lines.len(), 1 + METHODS.len() * 3);
        let columns = FRAMES_HEADER.split(',').count();
        for line in &lines[1..] {
            assert_eq!(line.split(',').count(), columns, "{line}");
        }
        // The first frame has no flicker: an empty last field.
        assert_eq!(
            lines[1],
            "none,10,12.346,inf,0.98765,0.05000,0.250,0.500,0.125,1000,"
        );
        assert!(lines[2].ends_with(",1000,1.500"), "{}", lines[2]);
    }

    #[test]
    fn markdown_names_every_method_and_has_table1_only_when_measured() {
        let mut report = sample_report();
        let md = markdown(&report);
        assert!(md.starts_with("# LOD methods compared on sponza\n"));
        assert!(md.contains("320x240 px, frames 10..12 (3 frames), reference 64 spp"));
        for name in METHODS {
            assert!(md.contains(&format!("| {name} |")), "{name} missing:\n{md}");
        }
        assert!(md.contains("## Table 1 (Park & Kim)"));
        assert!(md.contains("| 8 | 30.000 | 30.600 | 2.00 |"));
        assert!(md.contains("**How to read.**"));
        report.table1.clear();
        assert!(!markdown(&report).contains("Table 1"));
    }

    #[test]
    fn markdown_mip_columns_stop_at_the_highest_used_level() {
        let md = markdown(&sample_report());
        assert!(md.contains("| method | L0 | L1 | L2 |\n"), "{md}");
        assert!(md.contains("| paper | 50.0 | 30.0 | 20.0 |"), "{md}");
        assert!(md.contains("| none | 100.0 | 0.0 | 0.0 |"), "{md}");
    }

    #[test]
    fn bars_of_a_level_share_its_slot_without_overlap() {
        let (start, end) = bar_span(2, 0, 1);
        assert!((start - 1.6).abs() < 1e-12 && (end - 2.4).abs() < 1e-12);
        let (_, end_first) = bar_span(1, 0, 4);
        let (start_second, _) = bar_span(1, 1, 4);
        assert!((end_first - start_second).abs() < 1e-12);
    }

    #[test]
    fn pareto_ranges_keep_a_single_point_inside() {
        let (x, y) = pareto_ranges(&[(0, 12.0, 0.05)]);
        assert!(x.start < 12.0 && 12.0 < x.end, "{x:?}");
        assert!(y.start <= 0.0 && 0.05 < y.end, "{y:?}");
        assert_eq!(pareto_ranges(&[]), (0.0..1.0, 0.0..1.0));
    }

    #[test]
    fn labels_of_coinciding_points_do_not_overlap() {
        let plot = (0, 0, 600, 400);
        let offsets = place_labels(&[(300, 200); 4], &[60; 4], plot);
        let boxes: Vec<PixelBox> = offsets
            .iter()
            .map(|&(dx, dy)| (300 + dx, 200 + dy, 360 + dx, 200 + dy + LABEL_FONT_SIZE + 2))
            .collect();
        for (i, a) in boxes.iter().enumerate() {
            for b in &boxes[i + 1..] {
                assert_eq!(overlap_area(*a, *b), 0, "{boxes:?}");
            }
        }
        // A lone point near the right edge puts its label on the left.
        assert!(place_labels(&[(590, 200)], &[60], plot)[0].0 < 0);
    }

    #[test]
    fn write_all_writes_six_files_and_svgs_name_every_method() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("compare");
        let written = write_all(&sample_report(), &out).unwrap();
        let names: Vec<_> = written
            .iter()
            .map(|p| p.file_name().unwrap().to_str().unwrap())
            .collect();
        assert_eq!(
            names,
            [
                "compare.csv",
                "compare_frames.csv",
                "compare.md",
                "pareto.svg",
                "error_per_frame.svg",
                "mip_levels.svg"
            ]
        );
        for path in &written {
            assert!(path.is_file(), "{}", path.display());
        }
        for svg in &written[3..] {
            let texts = svg_texts(svg);
            for name in METHODS {
                assert!(
                    texts.iter().any(|t| t.trim() == name),
                    "{name} not in {}: {texts:?}",
                    svg.display()
                );
            }
        }
        // Nothing left behind but the six files (no temporaries).
        assert_eq!(std::fs::read_dir(&out).unwrap().count(), 6);
    }

    #[test]
    fn all_nan_report_still_writes_valid_svgs() {
        let dir = tempfile::tempdir().unwrap();
        let written = write_plots(&all_nan_report(), dir.path()).unwrap();
        assert_eq!(written.len(), 3);
        for svg in &written {
            let texts = svg_texts(svg);
            assert!(
                texts
                    .iter()
                    .any(|t| t.contains("no data") || t.contains("no lookups")),
                "{}: {texts:?}",
                svg.display()
            );
        }
        // The Pareto plot says which methods it could not place.
        let pareto = svg_texts(&written[0]);
        assert!(
            pareto
                .iter()
                .any(|t| t.contains("not plotted") && t.contains("ray_cones"))
        );
    }

    #[test]
    fn zero_methods_still_write_every_file() {
        let mut report = sample_report();
        report.methods.clear();
        report.table1.clear();
        report.frames.clear();
        let dir = tempfile::tempdir().unwrap();
        let written = write_all(&report, dir.path()).unwrap();
        assert_eq!(written.len(), 6);
        assert_eq!(
            std::fs::read_to_string(&written[0]).unwrap(),
            format!("{SUMMARY_HEADER}\n")
        );
        let md = std::fs::read_to_string(&written[2]).unwrap();
        assert!(md.contains("No methods were measured."));
        assert!(md.contains("No texture lookups were recorded."));
        for svg in &written[3..] {
            svg_texts(svg);
        }
    }

    #[test]
    fn single_method_plots_its_point() {
        let mut report = sample_report();
        report.methods.truncate(1);
        let dir = tempfile::tempdir().unwrap();
        let written = write_plots(&report, dir.path()).unwrap();
        let pareto = svg_texts(&written[0]);
        assert!(pareto.iter().any(|t| t.trim() == "none"), "{pareto:?}");
        assert!(
            !pareto
                .iter()
                .any(|t| t.contains("no data") || t.contains("not plotted"))
        );
    }
}
