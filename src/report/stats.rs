//! Statistics over a sequence: per-quantity percentiles, the preprocessing share of frame
//! time and the rebuild count.
//!
//! Quantities absent from every record are left out (not reported as 0). A quantity present
//! in only some records is summarised over those, and the row says over how many frames.

use super::metrics::{Metric, PREPROCESSING_PHASES, TOTAL_MS};
use super::percentiles::Percentiles;
use super::record::Record;

/// The spread of one quantity over the frames that have it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseRow {
    pub name: &'static str,
    /// Frames with a finite value of this quantity.
    pub frames: usize,
    pub percentiles: Percentiles,
}

impl PhaseRow {
    /// The row of `metric`, `None` when no record has it.
    pub fn of(metric: &Metric, records: &[Record]) -> Option<PhaseRow> {
        if !metric.present_in(records) {
            return None;
        }
        let values = metric.series(records);
        Some(PhaseRow {
            name: metric.name,
            frames: values.len(),
            percentiles: Percentiles::of(values.into_iter().map(|(_, v)| v)),
        })
    }

    /// The rows of those of `metrics` that some record has, in order.
    pub fn all_present(metrics: &[Metric], records: &[Record]) -> Vec<PhaseRow> {
        metrics
            .iter()
            .filter_map(|m| PhaseRow::of(m, records))
            .collect()
    }
}

/// Time spent before the render, as a share of frame time over the whole sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct PreprocessingShare {
    /// `sum(preprocessing phases) / sum(total_ms)`, over frames with a finite `total_ms`.
    pub share: f64,
    /// The preprocessing phases that some of those frames have (the others count as
    /// absent, e.g. `dirty_ms` and `refit_ms` in records written before the refit).
    pub phases: Vec<&'static str>,
}

impl PreprocessingShare {
    /// `None` when no frame has a finite, positive `total_ms` sum.
    pub fn of(records: &[Record]) -> Option<PreprocessingShare> {
        let timed: Vec<&Record> = records
            .iter()
            .filter(|r| (TOTAL_MS.get)(r).is_some_and(f64::is_finite))
            .collect();
        let total: f64 = timed.iter().filter_map(|r| (TOTAL_MS.get)(r)).sum();
        if total <= 0.0 {
            return None;
        }
        let mut phases = Vec::new();
        let mut preprocessing = 0.0;
        for metric in &PREPROCESSING_PHASES {
            let values: Vec<f64> = timed
                .iter()
                .filter_map(|r| (metric.get)(r))
                .filter(|v| v.is_finite())
                .collect();
            if !values.is_empty() {
                phases.push(metric.name);
                preprocessing += values.iter().sum::<f64>();
            }
        }
        Some(PreprocessingShare {
            share: preprocessing / total,
            phases,
        })
    }
}

/// Frames whose BVH was rebuilt; `None` when no record has `rebuild`.
pub fn rebuild_count(records: &[Record]) -> Option<usize> {
    let flags: Vec<bool> = records.iter().filter_map(|r| r.rebuild).collect();
    (!flags.is_empty()).then(|| flags.iter().filter(|&&rebuilt| rebuilt).count())
}

#[cfg(test)]
mod tests {
    use super::super::metrics::{DIRTY_MS, RENDER_MS};
    use super::*;

    fn timed(frame: u32, pre: [Option<f64>; 5], total: Option<f64>) -> Record {
        let [animate_ms, dirty_ms, refit_ms, build_ms, lod_update_ms] = pre;
        Record {
            frame,
            animate_ms,
            dirty_ms,
            refit_ms,
            build_ms,
            lod_update_ms,
            total_ms: total,
            ..Record::default()
        }
    }

    #[test]
    fn share_sums_phases_over_total() {
        let records = [
            timed(
                0,
                [Some(1.0), Some(0.5), Some(1.5), Some(0.0), Some(1.0)],
                Some(10.0),
            ),
            timed(
                1,
                [Some(2.0), Some(1.0), Some(0.0), Some(2.0), Some(1.0)],
                Some(20.0),
            ),
        ];
        let share = PreprocessingShare::of(&records).unwrap();
        assert!((share.share - 10.0 / 30.0).abs() < 1e-12, "{}", share.share);
        assert_eq!(
            share.phases,
            [
                "animate_ms",
                "dirty_ms",
                "refit_ms",
                "build_ms",
                "lod_update_ms"
            ]
        );
    }

    #[test]
    fn share_skips_absent_phases_and_untimed_frames() {
        let records = [
            timed(0, [Some(1.0), None, None, Some(2.0), Some(1.0)], Some(8.0)),
            // No total: its phases do not count either.
            timed(1, [Some(100.0), None, None, Some(100.0), None], None),
        ];
        let share = PreprocessingShare::of(&records).unwrap();
        assert_eq!(share.share, 0.5);
        assert_eq!(share.phases, ["animate_ms", "build_ms", "lod_update_ms"]);
        assert_eq!(PreprocessingShare::of(&records[1..]), None);
    }

    #[test]
    fn rebuilds_count_true_flags_only() {
        let flag = |frame, rebuild| Record {
            frame,
            rebuild,
            ..Record::default()
        };
        assert_eq!(
            rebuild_count(&[flag(0, Some(true)), flag(1, Some(false)), flag(2, None)]),
            Some(1)
        );
        assert_eq!(rebuild_count(&[flag(0, None)]), None);
    }

    #[test]
    fn rows_only_for_present_quantities() {
        let records = [
            Record {
                frame: 0,
                render_ms: Some(4.0),
                ..Record::default()
            },
            Record {
                frame: 1,
                render_ms: Some(2.0),
                dirty_ms: Some(1.0),
                ..Record::default()
            },
        ];
        let rows = PhaseRow::all_present(&[DIRTY_MS, RENDER_MS, TOTAL_MS], &records);
        let names: Vec<(&str, usize)> = rows.iter().map(|r| (r.name, r.frames)).collect();
        assert_eq!(names, [("dirty_ms", 1), ("render_ms", 2)]);
        assert_eq!(rows[1].percentiles.median, 3.0);
    }
}
