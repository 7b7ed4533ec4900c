//! The SVG plot of a sequence (plotters' SVG backend; text is written as `<text>`, so no
//! fonts are needed).
//!
//! Layout: 1000 x 900 px, two panels stacked, frame number on both x axes.
//! - Top: time per frame of each timing phase present (`animate_ms` ... `total_ms`), one
//!   line per phase, on a log y axis in ms because phases differ by orders of magnitude.
//!   Zero times cannot be drawn on a log axis and are left out. The top of the panel is
//!   kept free for the legend.
//! - Bottom: `moved_triangles`, `deformed_triangles`, `lod_recomputed` per frame, linear.
//!
//! Each panel has a caption, axis labels and a legend naming the fields as in
//! `stats.jsonl`. A line is broken where a frame lacks the value or frame numbers jump
//! (a missing shard): nothing is drawn for data that is not there.

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordi64;
use plotters::prelude::*;

use super::error::ReportError;
use super::metrics::{Metric, PLOTTED_COUNTS, Quantities, TIMING_PHASES};
use crate::atomic_file::{REPORT_OWNER, write_bytes_atomically_as};
use crate::chart::{Run, chart_on, draw_legend, draw_runs, series_color, text};
use crate::record::Record;

/// Size of the whole plot in pixels.
pub const SVG_SIZE: (u32, u32) = (1000, 900);

/// Share of the time panel's height kept above the data for the legend.
const LEGEND_HEADROOM: f64 = 0.4;

/// Draws the plot of ascending `records` and writes it to `path` atomically (its temporary
/// file is `mipray report`'s, [`REPORT_OWNER`]).
pub fn write_svg(records: &[Record], path: &Path) -> Result<(), ReportError> {
    let svg = render_svg(records).map_err(|message| ReportError::Plot {
        path: path.to_path_buf(),
        message,
    })?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(ReportError::io(dir))?;
    }
    write_bytes_atomically_as(path, Some(REPORT_OWNER), svg.as_bytes())
        .map_err(|(path, source)| ReportError::Io { path, source })
}

/// The plot of ascending `records` as SVG text.
pub fn render_svg(records: &[Record]) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SVG_SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let (top, bottom) = root.split_vertically(SVG_SIZE.1 / 2);
        let frames = frame_range(records);
        times_panel(&top, records, frames.clone())?;
        counts_panel(&bottom, records, frames)?;
        root.present().map_err(text)?;
    }
    Ok(svg)
}

/// The x range: first to last frame (widened by one when there is a single frame).
fn frame_range(records: &[Record]) -> Range<i64> {
    let first = records.first().map_or(0, |r| i64::from(r.frame()));
    let last = records.last().map_or(0, |r| i64::from(r.frame()));
    first..last.max(first + 1)
}

/// The line segments of `metric`: consecutive frames with a finite value that `keep`
/// accepts.
fn runs(records: &[Record], metric: &Metric, keep: fn(f64) -> bool) -> Vec<Run> {
    let mut runs: Vec<Run> = Vec::new();
    let mut open = false;
    for r in records {
        let frame = i64::from(r.frame());
        match r.value(metric).filter(|v| v.is_finite() && keep(*v)) {
            Some(v) => {
                let run = match runs.last_mut() {
                    Some(run) if open && run.last().is_some_and(|p| p.0 + 1 == frame) => run,
                    _ => {
                        runs.push(Vec::new());
                        runs.last_mut().expect("just pushed")
                    }
                };
                run.push((frame, v));
                open = true;
            }
            None => open = false,
        }
    }
    runs
}

fn positive(v: f64) -> bool {
    v > 0.0
}

fn any(_: f64) -> bool {
    true
}

/// Top panel: per-phase times on a log axis.
fn times_panel(
    area: &DrawingArea<SVGBackend, Shift>,
    records: &[Record],
    frames: Range<i64>,
) -> Result<(), String> {
    let lines: Vec<(&Metric, Vec<Run>)> = present(&TIMING_PHASES, records, positive);
    let (lo, hi) = value_bounds(&lines).unwrap_or((1e-3, 1.0));
    let (lo, hi) = (lo / 1.5, hi * 1.5);
    // Free the top ~40 % (in log space) for the legend of up to seven lines.
    let top = hi * (hi / lo).powf(LEGEND_HEADROOM / (1.0 - LEGEND_HEADROOM));
    let caption = format!("Per-frame phase times ({} frames)", records.len());
    let mut chart = chart_on(area, caption, 22)
        .build_cartesian_2d(frames, (lo..top).log_scale())
        .map_err(text)?;
    chart
        .configure_mesh()
        .x_desc("frame")
        .y_desc("time per frame (ms, log scale)")
        .y_label_formatter(&|v| tick(*v))
        .draw()
        .map_err(text)?;
    draw_lines(&mut chart, &lines)
}

/// Bottom panel: update counts on a linear axis.
fn counts_panel(
    area: &DrawingArea<SVGBackend, Shift>,
    records: &[Record],
    frames: Range<i64>,
) -> Result<(), String> {
    let lines: Vec<(&Metric, Vec<Run>)> = present(&PLOTTED_COUNTS, records, any);
    let hi = value_bounds(&lines).map_or(1.0, |(_, hi)| hi.max(1.0));
    let mut chart = chart_on(area, "Per-frame update counts", 22)
        .build_cartesian_2d(frames, 0.0..hi * 1.3)
        .map_err(text)?;
    chart
        .configure_mesh()
        .x_desc("frame")
        .y_desc("triangles per frame")
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(text)?;
    draw_lines(&mut chart, &lines)
}

/// The metrics some record has, with their line segments.
fn present<'m>(
    metrics: &'m [Metric],
    records: &[Record],
    keep: fn(f64) -> bool,
) -> Vec<(&'m Metric, Vec<Run>)> {
    metrics
        .iter()
        .filter(|m| m.present_in(records))
        .map(|m| (m, runs(records, m, keep)))
        .collect()
}

/// Smallest and largest plotted value, `None` when nothing is plotted.
fn value_bounds(lines: &[(&Metric, Vec<Run>)]) -> Option<(f64, f64)> {
    let values = lines
        .iter()
        .flat_map(|(_, runs)| runs.iter().flatten().map(|p| p.1));
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// A y tick label in ms: fewer decimals for larger values.
fn tick(v: f64) -> String {
    match v {
        v if v >= 10.0 => format!("{v:.0}"),
        v if v >= 1.0 => format!("{v:.1}"),
        v if v >= 1e-3 => format!("{v:.3}"),
        v => format!("{v:.0e}"),
    }
}

/// Draws one line (with a legend entry) per metric; single-frame segments as dots.
fn draw_lines<'a, 'b: 'a, Y>(
    chart: &mut ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordi64, Y>>,
    lines: &[(&Metric, Vec<Run>)],
) -> Result<(), String>
where
    Y: Ranged<ValueType = f64>,
{
    for (i, (metric, runs)) in lines.iter().enumerate() {
        draw_runs(chart, metric.name, runs, series_color(i))?;
    }
    draw_legend(chart, lines.len())
}

#[cfg(test)]
mod tests {
    use super::super::metrics::RENDER_MS;
    use super::*;
    use crate::record::{FrameRecord, Phase};

    const DIRTY_MS: Metric = Metric::phase(Phase::Dirty);

    fn record(frame: u32, dirty_ms: Option<f64>) -> Record {
        let mut values = FrameRecord {
            frame,
            ..FrameRecord::default()
        };
        values.update.dirty_ms = dirty_ms.unwrap_or_default();
        Record::new(values, dirty_ms.map(|_| "dirty_ms"))
    }

    #[test]
    fn lines_break_at_absent_values_and_frame_gaps() {
        let records = [
            record(0, Some(1.0)),
            record(1, Some(2.0)),
            record(2, None),
            record(3, Some(3.0)),
            record(5, Some(4.0)),
            record(6, Some(0.0)),
        ];
        assert_eq!(
            runs(&records, &DIRTY_MS, any),
            [
                vec![(0, 1.0), (1, 2.0)],
                vec![(3, 3.0)],
                vec![(5, 4.0), (6, 0.0)]
            ]
        );
        assert_eq!(runs(&records, &DIRTY_MS, positive)[2], [(5, 4.0)]);
        assert!(runs(&records, &RENDER_MS, any).is_empty());
    }

    #[test]
    fn single_frame_range_is_not_empty() {
        assert_eq!(frame_range(&[record(7, None)]), 7..8);
        assert_eq!(frame_range(&[record(2, None), record(9, None)]), 2..9);
    }

    #[test]
    fn tick_labels() {
        assert_eq!(tick(200.0), "200");
        assert_eq!(tick(2.5), "2.5");
        assert_eq!(tick(0.02), "0.020");
    }
}
