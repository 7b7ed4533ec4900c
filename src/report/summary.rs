//! What a report found, printed as Markdown: one table row per quantity, then lines for
//! the sequence (frames, shards, duplicates, preprocessing share, rebuilds, plot).

use std::fmt;
use std::path::PathBuf;

use super::metrics::{COUNTS, TIMING_PHASES};
use super::stats::{PhaseRow, PreprocessingShare, rebuild_count};
use crate::record::Record;
use crate::record::Sequence;

/// The result of [`super::report`]; `Display` renders it as Markdown.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportSummary {
    /// Frames after de-duplication.
    pub frames: usize,
    pub first_frame: u32,
    pub last_frame: u32,
    /// The stats files merged (one per shard).
    pub stats_files: Vec<PathBuf>,
    pub duplicates_dropped: usize,
    /// Timing phases present in some record, in frame-loop order (milliseconds).
    pub timings: Vec<PhaseRow>,
    /// Counts present in some record.
    pub counts: Vec<PhaseRow>,
    /// `None` when no frame has a positive `total_ms`.
    pub preprocessing: Option<PreprocessingShare>,
    /// Frames with `rebuild == true`; `None` when no record has `rebuild`.
    pub rebuilds: Option<usize>,
    /// Where the plot was written.
    pub svg: PathBuf,
    /// Records of different runs among those merged (a warning: the statistics mix them).
    pub mixed_runs: Option<crate::record::MixedRuns>,
}

impl ReportSummary {
    /// Summarises a loaded, non-empty sequence whose plot is (to be) at `svg`.
    pub fn of(sequence: &Sequence, svg: PathBuf) -> ReportSummary {
        let records = &sequence.records;
        ReportSummary {
            frames: records.len(),
            first_frame: records.first().map_or(0, Record::frame),
            last_frame: records.last().map_or(0, Record::frame),
            stats_files: sequence.files.clone(),
            duplicates_dropped: sequence.duplicates_dropped,
            timings: PhaseRow::all_present(&TIMING_PHASES, records),
            counts: PhaseRow::all_present(&COUNTS, records),
            preprocessing: PreprocessingShare::of(records),
            rebuilds: rebuild_count(records),
            svg,
            mixed_runs: sequence.mixed_runs.clone(),
        }
    }

    /// Frame numbers between the first and last with no record (e.g. a shard not given).
    pub fn missing_frames(&self) -> usize {
        let span = (self.last_frame - self.first_frame) as usize + 1;
        span.saturating_sub(self.frames)
    }

    fn write_row(
        &self,
        f: &mut fmt::Formatter<'_>,
        row: &PhaseRow,
        value: fn(f64) -> String,
    ) -> fmt::Result {
        let p = row.percentiles;
        let name = if row.frames < self.frames {
            format!("{} ({} of {} frames)", row.name, row.frames, self.frames)
        } else {
            row.name.to_string()
        };
        let cells = [p.min, p.median, p.p95, p.max].map(value);
        writeln!(f, "| {name} | {} |", cells.join(" | "))
    }
}

/// Milliseconds with three decimals (microseconds).
fn milliseconds(v: f64) -> String {
    if v.is_nan() {
        "n/a".into()
    } else {
        format!("{v:.3}")
    }
}

/// A count: an integer, or one decimal for a median between two integers.
fn count(v: f64) -> String {
    if v.is_nan() {
        "n/a".into()
    } else if v.fract() == 0.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

impl fmt::Display for ReportSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "| phase | min | median | p95 | max |")?;
        writeln!(f, "| --- | ---: | ---: | ---: | ---: |")?;
        for row in &self.timings {
            self.write_row(f, row, milliseconds)?;
        }
        for row in &self.counts {
            self.write_row(f, row, count)?;
        }
        writeln!(f)?;
        writeln!(
            f,
            "- frames: {} ({} to {}, {} missing)",
            self.frames,
            self.first_frame,
            self.last_frame,
            self.missing_frames()
        )?;
        let files: Vec<String> = self
            .stats_files
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        writeln!(f, "- shards merged: {} ({})", files.len(), files.join(", "))?;
        writeln!(f, "- duplicates dropped: {}", self.duplicates_dropped)?;
        match &self.preprocessing {
            Some(p) => writeln!(
                f,
                "- preprocessing share: {:.1} % of total_ms ({})",
                100.0 * p.share,
                p.phases.join(" + ")
            )?,
            None => writeln!(f, "- preprocessing share: n/a (no total_ms)")?,
        }
        match self.rebuilds {
            Some(n) => writeln!(f, "- rebuilds: {n}")?,
            None => writeln!(f, "- rebuilds: n/a (no rebuild field)")?,
        }
        writeln!(f, "- plot: {}", self.svg.display())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::FrameRecord;

    fn sequence() -> Sequence {
        let record = |frame: u32, ms: f64| {
            let mut values = FrameRecord {
                frame,
                total_ms: 4.0 * ms,
                rays: u64::from(frame) + 1,
                ..FrameRecord::default()
            };
            values.update.animate_ms = ms;
            Record::new(values, ["animate_ms", "total_ms", "rays"])
        };
        Sequence {
            records: vec![record(0, 1.0), record(1, 2.0), record(3, 3.0)],
            files: vec![
                PathBuf::from("a/stats.jsonl"),
                PathBuf::from("b/stats.jsonl"),
            ],
            duplicates_dropped: 1,
            mixed_runs: None,
        }
    }

    #[test]
    fn markdown_table_and_lines() {
        let summary = ReportSummary::of(&sequence(), PathBuf::from("out/report.svg"));
        let expected = "\
| phase | min | median | p95 | max |
| --- | ---: | ---: | ---: | ---: |
| animate_ms | 1.000 | 2.000 | 3.000 | 3.000 |
| total_ms | 4.000 | 8.000 | 12.000 | 12.000 |
| rays | 1 | 2 | 4 | 4 |

- frames: 3 (0 to 3, 1 missing)
- shards merged: 2 (a/stats.jsonl, b/stats.jsonl)
- duplicates dropped: 1
- preprocessing share: 25.0 % of total_ms (animate_ms)
- rebuilds: n/a (no rebuild field)
- plot: out/report.svg
";
        assert_eq!(summary.to_string(), expected);
    }

    #[test]
    fn partial_quantities_say_over_how_many_frames() {
        let mut seq = sequence();
        let mark = |r: &Record, name| {
            Record::new(r.values.clone(), ["animate_ms", "total_ms", "rays", name])
        };
        seq.records[0].values.update.rebuild = true;
        seq.records[0] = mark(&seq.records[0], "rebuild");
        seq.records[1].values.update.lod_recomputed = 3;
        seq.records[1] = mark(&seq.records[1], "lod_recomputed");
        seq.records[2].values.update.lod_recomputed = 4;
        seq.records[2] = mark(&seq.records[2], "lod_recomputed");
        let text = ReportSummary::of(&seq, PathBuf::from("p.svg")).to_string();
        assert!(
            text.contains("| lod_recomputed (2 of 3 frames) | 3 | 3.5 | 4 | 4 |\n"),
            "{text}"
        );
        assert!(text.contains("- rebuilds: 1\n"), "{text}");
    }
}
