//! The per-frame quantities the report summarises and plots, by their `stats.jsonl` names.
//!
//! A [`Metric`] reads one number from a [`FrameRecord`]; [`Quantities`] says whether a record
//! has it at all (a record read back from an older file may not; one the frame loop just
//! made has every field). The timing lists are built from [`Phase::ALL`], so a new phase
//! appears in the summary, the report table and the plot without being named here.

use crate::record::Record;
use crate::record::{FrameRecord, Phase};

/// One per-frame quantity: its field name and how to read it from a record.
#[derive(Clone, Copy)]
pub struct Metric {
    pub name: &'static str,
    read: Read,
}

/// Where a metric's value comes from.
#[derive(Clone, Copy)]
enum Read {
    Phase(Phase),
    Field(fn(&FrameRecord) -> f64),
}

impl std::fmt::Debug for Metric {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

/// A record whose quantities may be absent (see the module comment).
pub trait Quantities {
    fn frame_number(&self) -> u32;
    /// The value of `metric`, `None` when the record lacks the field.
    fn value(&self, metric: &Metric) -> Option<f64>;
    /// Whether the BVH was rebuilt, `None` when the record lacks `rebuild`.
    fn rebuilt(&self) -> Option<bool>;
}

impl Quantities for FrameRecord {
    fn frame_number(&self) -> u32 {
        self.frame
    }

    fn value(&self, metric: &Metric) -> Option<f64> {
        Some(metric.of(self))
    }

    fn rebuilt(&self) -> Option<bool> {
        Some(self.update.rebuild)
    }
}

impl Quantities for Record {
    fn frame_number(&self) -> u32 {
        self.values.frame
    }

    fn value(&self, metric: &Metric) -> Option<f64> {
        self.if_present(metric.name, metric.of(&self.values))
    }

    fn rebuilt(&self) -> Option<bool> {
        self.if_present("rebuild", self.values.update.rebuild)
    }
}

impl Metric {
    /// The milliseconds of an update phase, named by its field.
    pub const fn phase(phase: Phase) -> Metric {
        Metric {
            name: phase.field_name(),
            read: Read::Phase(phase),
        }
    }

    const fn field(name: &'static str, get: fn(&FrameRecord) -> f64) -> Metric {
        Metric {
            name,
            read: Read::Field(get),
        }
    }

    /// This quantity's value in a complete record.
    pub fn of(&self, record: &FrameRecord) -> f64 {
        match self.read {
            Read::Phase(phase) => record.phase_ms(phase),
            Read::Field(get) => get(record),
        }
    }

    /// The finite values of this quantity over `records`, with their frame numbers
    /// (frames where it is absent or non-finite are skipped).
    pub fn series<R: Quantities>(&self, records: &[R]) -> Vec<(u32, f64)> {
        records
            .iter()
            .filter_map(|r| r.value(self).map(|v| (r.frame_number(), v)))
            .filter(|(_, v)| v.is_finite())
            .collect()
    }

    /// Whether any record has this quantity.
    pub fn present_in<R: Quantities>(&self, records: &[R]) -> bool {
        records.iter().any(|r| r.value(self).is_some())
    }
}

pub const RENDER_MS: Metric = Metric::field("render_ms", |r| r.render_ms);
pub const TOTAL_MS: Metric = Metric::field("total_ms", |r| r.total_ms);
pub const MOVED_TRIANGLES: Metric =
    Metric::field("moved_triangles", |r| r.update.moved_triangles as f64);
pub const DEFORMED_TRIANGLES: Metric =
    Metric::field("deformed_triangles", |r| r.update.deformed_triangles as f64);
pub const LOD_RECOMPUTED: Metric =
    Metric::field("lod_recomputed", |r| r.update.lod_recomputed as f64);
pub const RAYS: Metric = Metric::field("rays", |r| r.rays as f64);
pub const TRIANGLES: Metric = Metric::field("triangles", |r| r.triangles as f64);

const PHASES: usize = Phase::ALL.len();

/// The phases before the render, in frame-loop order: their sum over `total_ms` is the
/// preprocessing share.
pub const PREPROCESSING_PHASES: [Metric; PHASES] = {
    let mut metrics = [RENDER_MS; PHASES];
    let mut i = 0;
    while i < PHASES {
        metrics[i] = Metric::phase(Phase::ALL[i]);
        i += 1;
    }
    metrics
};

/// Timing phases (milliseconds per frame), in frame-loop order, then the frame total.
pub const TIMING_PHASES: [Metric; PHASES + 2] = {
    let mut metrics = [TOTAL_MS; PHASES + 2];
    let mut i = 0;
    while i < PHASES {
        metrics[i] = PREPROCESSING_PHASES[i];
        i += 1;
    }
    metrics[PHASES] = RENDER_MS;
    metrics
};

/// Per-frame counts summarised in the table.
pub const COUNTS: [Metric; 5] = [
    MOVED_TRIANGLES,
    DEFORMED_TRIANGLES,
    LOD_RECOMPUTED,
    RAYS,
    TRIANGLES,
];

/// Per-frame counts drawn in the plot's second panel (the update's work).
pub const PLOTTED_COUNTS: [Metric; 3] = [MOVED_TRIANGLES, DEFORMED_TRIANGLES, LOD_RECOMPUTED];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_metric_reads_its_own_field() {
        let line = r#"{"frame":0,"animate_ms":1,"dirty_ms":2,"refit_ms":3,"build_ms":4,
            "lod_update_ms":5,"render_ms":6,"total_ms":7,"moved_triangles":8,
            "deformed_triangles":9,"lod_recomputed":10,"rays":11,"triangles":12}"#;
        let r = Record::parse(line).unwrap();
        let all = TIMING_PHASES.iter().chain(&COUNTS);
        let values: Vec<(&str, Option<f64>)> = all.map(|m| (m.name, r.value(m))).collect();
        let expected: Vec<(&str, Option<f64>)> = [
            "animate_ms",
            "dirty_ms",
            "refit_ms",
            "build_ms",
            "lod_update_ms",
            "render_ms",
            "total_ms",
            "moved_triangles",
            "deformed_triangles",
            "lod_recomputed",
            "rays",
            "triangles",
        ]
        .iter()
        .zip(1..)
        .map(|(name, v)| (*name, Some(f64::from(v))))
        .collect();
        assert_eq!(values, expected);
    }

    #[test]
    fn series_skips_absent_values() {
        let dirty = |frame, dirty_ms| {
            let mut values = FrameRecord {
                frame,
                ..FrameRecord::default()
            };
            values.update.dirty_ms = dirty_ms;
            Record::new(values, ["dirty_ms"])
        };
        let records = [
            dirty(0, 1.5),
            Record::new(
                FrameRecord {
                    frame: 1,
                    ..FrameRecord::default()
                },
                [],
            ),
            dirty(2, f64::NAN),
        ];
        let dirty_ms = Metric::phase(Phase::Dirty);
        assert_eq!(dirty_ms.series(&records), [(0, 1.5)]);
        assert!(dirty_ms.present_in(&records));
        assert!(!Metric::phase(Phase::Refit).present_in(&records));
    }

    #[test]
    fn complete_records_have_every_quantity() {
        let record = FrameRecord {
            render_ms: 2.0,
            ..FrameRecord::default()
        };
        assert_eq!(record.value(&RENDER_MS), Some(2.0));
        assert_eq!(record.value(&Metric::phase(Phase::Build)), Some(0.0));
        assert_eq!(record.rebuilt(), Some(false));
    }
}
