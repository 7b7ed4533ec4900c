//! The per-frame quantities the report summarises and plots, by their `stats.jsonl` names.

use super::record::Record;

/// One per-frame quantity: its field name and how to read it from a record.
#[derive(Clone, Copy)]
pub struct Metric {
    pub name: &'static str,
    pub get: fn(&Record) -> Option<f64>,
}

impl std::fmt::Debug for Metric {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

impl Metric {
    /// The finite values of this quantity over `records`, with their frame numbers
    /// (frames where it is absent or non-finite are skipped).
    pub fn series(&self, records: &[Record]) -> Vec<(u32, f64)> {
        records
            .iter()
            .filter_map(|r| (self.get)(r).map(|v| (r.frame, v)))
            .filter(|(_, v)| v.is_finite())
            .collect()
    }

    /// Whether any record has this quantity.
    pub fn present_in(&self, records: &[Record]) -> bool {
        records.iter().any(|r| (self.get)(r).is_some())
    }
}

macro_rules! metric {
    ($field:ident) => {
        Metric {
            name: stringify!($field),
            get: |r| r.$field,
        }
    };
    ($field:ident as f64) => {
        Metric {
            name: stringify!($field),
            get: |r| r.$field.map(|v| v as f64),
        }
    };
}

pub const ANIMATE_MS: Metric = metric!(animate_ms);
pub const DIRTY_MS: Metric = metric!(dirty_ms);
pub const REFIT_MS: Metric = metric!(refit_ms);
pub const BUILD_MS: Metric = metric!(build_ms);
pub const LOD_UPDATE_MS: Metric = metric!(lod_update_ms);
pub const RENDER_MS: Metric = metric!(render_ms);
pub const TOTAL_MS: Metric = metric!(total_ms);
pub const MOVED_TRIANGLES: Metric = metric!(moved_triangles as f64);
pub const DEFORMED_TRIANGLES: Metric = metric!(deformed_triangles as f64);
pub const LOD_RECOMPUTED: Metric = metric!(lod_recomputed as f64);
pub const RAYS: Metric = metric!(rays as f64);
pub const TRIANGLES: Metric = metric!(triangles as f64);

/// Timing phases (milliseconds per frame), in frame-loop order, then the frame total.
pub const TIMING_PHASES: [Metric; 7] = [
    ANIMATE_MS,
    DIRTY_MS,
    REFIT_MS,
    BUILD_MS,
    LOD_UPDATE_MS,
    RENDER_MS,
    TOTAL_MS,
];

/// The phases before the render: their sum over `total_ms` is the preprocessing share.
pub const PREPROCESSING_PHASES: [Metric; 5] =
    [ANIMATE_MS, DIRTY_MS, REFIT_MS, BUILD_MS, LOD_UPDATE_MS];

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
        let values: Vec<(&str, Option<f64>)> = all.map(|m| (m.name, (m.get)(&r))).collect();
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
        let records = [
            Record {
                frame: 0,
                dirty_ms: Some(1.5),
                ..Record::default()
            },
            Record {
                frame: 1,
                ..Record::default()
            },
            Record {
                frame: 2,
                dirty_ms: Some(f64::NAN),
                ..Record::default()
            },
        ];
        assert_eq!(DIRTY_MS.series(&records), [(0, 1.5)]);
        assert!(DIRTY_MS.present_in(&records));
        assert!(!REFIT_MS.present_in(&records));
    }
}
