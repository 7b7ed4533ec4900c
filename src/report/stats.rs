//! Statistics over a sequence: per-quantity percentiles, the preprocessing share of frame
//! time and the rebuild count.
//!
//! Quantities absent from every record are left out (not reported as 0). A quantity present
//! in only some records is summarised over those, and the row says over how many frames.
//! The same functions summarise records read back (`mipray report`) and records the frame
//! loop just made (`summary.json`), which have every quantity.

use super::metrics::{Metric, PREPROCESSING_PHASES, Quantities, TOTAL_MS};
use crate::percentiles::Percentiles;

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
    pub fn of<R: Quantities>(metric: &Metric, records: &[R]) -> Option<PhaseRow> {
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
    pub fn all_present<R: Quantities>(metrics: &[Metric], records: &[R]) -> Vec<PhaseRow> {
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
    pub fn of<R: Quantities>(records: &[R]) -> Option<PreprocessingShare> {
        let timed: Vec<&R> = records
            .iter()
            .filter(|r| r.value(&TOTAL_MS).is_some_and(f64::is_finite))
            .collect();
        let total: f64 = timed.iter().filter_map(|r| r.value(&TOTAL_MS)).sum();
        if total <= 0.0 {
            return None;
        }
        let mut phases = Vec::new();
        let mut preprocessing = 0.0;
        for metric in &PREPROCESSING_PHASES {
            let values: Vec<f64> = timed
                .iter()
                .filter_map(|r| r.value(metric))
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
pub fn rebuild_count<R: Quantities>(records: &[R]) -> Option<usize> {
    let flags: Vec<bool> = records.iter().filter_map(Quantities::rebuilt).collect();
    (!flags.is_empty()).then(|| flags.iter().filter(|&&rebuilt| rebuilt).count())
}

#[cfg(test)]
mod tests {
    use super::super::metrics::RENDER_MS;
    use super::*;
    use crate::record::Record;
    use crate::record::{FrameRecord, Phase};

    /// A record of `frame` with the given phase times (in `Phase::ALL` order) and total;
    /// `None` fields are absent.
    fn timed(frame: u32, pre: [Option<f64>; 5], total: Option<f64>) -> Record {
        let mut values = FrameRecord {
            frame,
            total_ms: total.unwrap_or_default(),
            ..FrameRecord::default()
        };
        let mut present: Vec<&'static str> = total.map(|_| "total_ms").into_iter().collect();
        for (phase, ms) in Phase::ALL.into_iter().zip(pre) {
            if let Some(ms) = ms {
                set_phase(&mut values, phase, ms);
                present.push(phase.field_name());
            }
        }
        Record::new(values, present)
    }

    fn set_phase(values: &mut FrameRecord, phase: Phase, ms: f64) {
        let u = &mut values.update;
        *match phase {
            Phase::Animate => &mut u.animate_ms,
            Phase::Dirty => &mut u.dirty_ms,
            Phase::Refit => &mut u.refit_ms,
            Phase::Build => &mut u.build_ms,
            Phase::LodUpdate => &mut u.lod_update_ms,
        } = ms;
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
        let flag = |frame, rebuild: Option<bool>| {
            let mut values = FrameRecord {
                frame,
                ..FrameRecord::default()
            };
            values.update.rebuild = rebuild.unwrap_or_default();
            Record::new(values, rebuild.map(|_| "rebuild"))
        };
        assert_eq!(
            rebuild_count(&[flag(0, Some(true)), flag(1, Some(false)), flag(2, None)]),
            Some(1)
        );
        assert_eq!(rebuild_count(&[flag(0, None)]), None);
    }

    #[test]
    fn rows_only_for_present_quantities() {
        let render = |frame, render_ms| FrameRecord {
            frame,
            render_ms,
            ..FrameRecord::default()
        };
        let mut second = render(1, 2.0);
        second.update.dirty_ms = 1.0;
        let records = [
            Record::new(render(0, 4.0), ["render_ms"]),
            Record::new(second, ["render_ms", "dirty_ms"]),
        ];
        let dirty_ms = Metric::phase(Phase::Dirty);
        let rows = PhaseRow::all_present(&[dirty_ms, RENDER_MS, TOTAL_MS], &records);
        let names: Vec<(&str, usize)> = rows.iter().map(|r| (r.name, r.frames)).collect();
        assert_eq!(names, [("dirty_ms", 1), ("render_ms", 2)]);
        assert_eq!(rows[1].percentiles.median, 3.0);
    }
}
