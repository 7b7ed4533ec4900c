//! The SVG plots of `mipray compare`: `pareto.svg` (error against time, one labelled
//! point per method), `error_per_frame.svg` (mean FLIP per frame, one line per method) and
//! `mip_levels.svg` (share of lookups per MIP level, the paper's Fig. 4). A method keeps
//! its colour in every plot; non-finite values are left out, and a plot with nothing to
//! draw says so in its caption.

use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::markdown::{highest_used_level, share};
use super::{CompareReportError, create_dir, write_file};
use crate::chart::{FONT, Run, chart_on, draw_legend, draw_runs, series_color, text};
use crate::compare::{CompareReport, MethodSummary};

/// File names of the plots, with the function drawing each.
type Renderer = fn(&CompareReport) -> Result<String, String>;
pub(super) const PLOTS: [(&str, Renderer); 3] = [
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

/// Method colours, by index in the report, so a method looks the same in every plot (the
/// palette of `mipray report`).
fn method_color(index: usize) -> RGBColor {
    series_color(index)
}

const PARETO_SIZE: (u32, u32) = (1400, 600);
const PER_FRAME_SIZE: (u32, u32) = (1000, 500);
const MIP_LEVELS_SIZE: (u32, u32) = (1000, 500);
/// Height of the strip under a Pareto panel naming the methods it could not place.
const NOTE_HEIGHT: u32 = 26;

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
    let mut chart = chart_on(&plot, caption, 20)
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
        let mut chart = chart_on(&root, caption, 22)
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
            draw_runs(&mut chart, &m.method, runs, method_color(i))?;
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
        let mut chart = chart_on(&root, caption, 22)
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

#[cfg(test)]
mod tests {
    use super::super::fixtures::{all_nan_report, sample_report, svg_texts};
    use super::*;

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
