//! `summary.json`: totals over a rendered sequence, the preprocessing share of frame time,
//! and min / median / p95 / max of every per-frame phase and count.
//!
//! Built from the frame loop's own records ([`FrameRecord`], every field present) with the
//! statistics `mipray report` uses ([`PhaseRow`], [`PreprocessingShare`],
//! [`rebuild_count`]), so the file and the report agree by construction. The phase
//! fields come from [`Phase::ALL`]; the field order is fixed (readers may rely on it).

use serde::ser::{Serialize, SerializeMap, Serializer};

use super::metrics::{
    DEFORMED_TRIANGLES, LOD_RECOMPUTED, MOVED_TRIANGLES, Metric, RAYS, RENDER_MS, TOTAL_MS,
    TRIANGLES,
};
use super::stats::{PreprocessingShare, rebuild_count};
use crate::percentiles::Percentiles;
use crate::record::{FrameRecord, Phase};

/// `summary.json` (see the module comment).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Summary {
    pub frames: usize,
    /// The first record's size and method; `null` when there are no frames (a shard
    /// whose block of the range is empty), never an invented 0 or "".
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub lod_method: Option<String>,
    pub total_rays: u64,
    pub total_render_ms: f64,
    pub total_ms: f64,
    pub total_lod_recomputed: u64,
    pub total_nonfinite_samples: u64,
    pub rebuilds: usize,
    /// (sum of every [`Phase`]) / total, over the sequence.
    pub preprocessing_share: f64,
    pub mip_histogram: Vec<u64>,
    pub triangles: Percentiles,
    /// One entry per [`Phase`], in `Phase::ALL` order, named by its field (`animate_ms`...).
    #[serde(flatten)]
    pub phases: PhasePercentiles,
    pub render_ms: Percentiles,
    pub frame_total_ms: Percentiles,
    pub moved_triangles: Percentiles,
    pub deformed_triangles: Percentiles,
    pub lod_recomputed: Percentiles,
    pub rays: Percentiles,
    /// Rays per second of render time over the whole sequence.
    pub rays_per_second: f64,
}

/// The percentiles of each update phase, serialised as one field per phase.
#[derive(Debug, Clone, PartialEq)]
pub struct PhasePercentiles(pub [Percentiles; Phase::ALL.len()]);

impl PhasePercentiles {
    /// The percentiles of `phase`.
    pub fn get(&self, phase: Phase) -> Percentiles {
        let index = Phase::ALL.iter().position(|&p| p == phase);
        self.0[index.expect("every phase is in Phase::ALL")]
    }
}

impl Serialize for PhasePercentiles {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (phase, percentiles) in Phase::ALL.iter().zip(&self.0) {
            map.serialize_entry(phase.field_name(), percentiles)?;
        }
        map.end()
    }
}

impl Summary {
    /// The summary of `records` (any order; an empty slice gives zero totals, null size and
    /// method, and NaN spreads).
    pub fn of(records: &[FrameRecord]) -> Summary {
        let first = records.first();
        let spread = |metric: Metric| Percentiles::of(records.iter().map(|r| metric.of(r)));
        let total_rays = records.iter().map(|r| r.rays).sum();
        let total_render_ms = milliseconds_total(records.iter().map(|r| r.render_ms));
        Summary {
            frames: records.len(),
            width: first.map(|r| r.width),
            height: first.map(|r| r.height),
            lod_method: first.map(|r| r.lod_method.clone()),
            total_rays,
            total_render_ms,
            total_ms: milliseconds_total(records.iter().map(|r| r.total_ms)),
            total_lod_recomputed: records.iter().map(|r| r.update.lod_recomputed as u64).sum(),
            total_nonfinite_samples: records.iter().map(|r| r.nonfinite_samples).sum(),
            rebuilds: rebuild_count(records).unwrap_or(0),
            preprocessing_share: PreprocessingShare::of(records).map_or(0.0, |p| p.share),
            mip_histogram: mip_histogram(records),
            triangles: spread(TRIANGLES),
            phases: PhasePercentiles(Phase::ALL.map(|phase| spread(Metric::phase(phase)))),
            render_ms: spread(RENDER_MS),
            frame_total_ms: spread(TOTAL_MS),
            moved_triangles: spread(MOVED_TRIANGLES),
            deformed_triangles: spread(DEFORMED_TRIANGLES),
            lod_recomputed: spread(LOD_RECOMPUTED),
            rays: spread(RAYS),
            rays_per_second: if total_render_ms > 0.0 {
                total_rays as f64 / (total_render_ms / 1e3)
            } else {
                0.0
            },
        }
    }
}

/// The sum of `values`, 0 (not `-0`, the float sum of nothing) when there are none.
fn milliseconds_total(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(0.0, |total, v| total + v)
}

/// Texture lookups per level over the sequence (as many levels as the first record has).
fn mip_histogram(records: &[FrameRecord]) -> Vec<u64> {
    let mut histogram = vec![0u64; records.first().map_or(0, |r| r.mip_histogram.len())];
    for r in records {
        for (a, b) in histogram.iter_mut().zip(&r.mip_histogram) {
            *a += b;
        }
    }
    histogram
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(frame: u32, ms: f64, rebuild: bool) -> FrameRecord {
        let mut r = FrameRecord {
            frame,
            width: 8,
            height: 4,
            lod_method: "paper".into(),
            render_ms: 10.0 * ms,
            total_ms: 20.0 * ms,
            rays: 1000,
            mip_histogram: vec![1, 2],
            ..FrameRecord::default()
        };
        r.update.animate_ms = ms;
        r.update.build_ms = ms;
        r.update.rebuild = rebuild;
        r
    }

    #[test]
    fn fields_in_file_order_with_phases_after_triangles() {
        let summary = Summary::of(&[record(0, 1.0, true)]);
        let text = serde_json::to_string(&summary).unwrap();
        let fields = serde_json::to_value(&summary)
            .unwrap()
            .as_object()
            .unwrap()
            .len();
        let expected = [
            "frames",
            "width",
            "height",
            "lod_method",
            "total_rays",
            "total_render_ms",
            "total_ms",
            "total_lod_recomputed",
            "total_nonfinite_samples",
            "rebuilds",
            "preprocessing_share",
            "mip_histogram",
            "triangles",
            "animate_ms",
            "dirty_ms",
            "refit_ms",
            "build_ms",
            "lod_update_ms",
            "render_ms",
            "frame_total_ms",
            "moved_triangles",
            "deformed_triangles",
            "lod_recomputed",
            "rays",
            "rays_per_second",
        ];
        assert_eq!(fields, expected.len());
        // Top-level keys in this order (a Value would sort them, so read the text).
        let positions: Vec<usize> = expected
            .iter()
            .map(|key| text.find(&format!("\"{key}\":")).expect(key))
            .collect();
        assert!(positions.is_sorted(), "{text}");
    }

    #[test]
    fn totals_share_and_spreads_on_known_data() {
        let records = [
            record(0, 1.0, true),
            record(1, 2.0, false),
            record(2, 3.0, false),
        ];
        let s = Summary::of(&records);
        assert_eq!(
            (s.frames, s.width, s.lod_method.as_deref()),
            (3, Some(8), Some("paper"))
        );
        assert_eq!((s.total_rays, s.rebuilds), (3000, 1));
        assert_eq!(s.mip_histogram, [3, 6]);
        // (animate + build) = 2 ms per ms of `ms`, total 20: a share of 0.1.
        assert!((s.preprocessing_share - 0.1).abs() < 1e-12);
        assert_eq!(s.phases.get(Phase::Animate).median, 2.0);
        assert_eq!(s.phases.get(Phase::Build).max, 3.0);
        assert_eq!(s.phases.get(Phase::Dirty).max, 0.0);
        assert_eq!(s.frame_total_ms.max, 60.0);
        // 3000 rays in 60 ms of render time.
        assert!((s.rays_per_second - 50_000.0).abs() < 1e-6);
    }

    #[test]
    fn empty_sequence_has_zeros_and_null_spreads() {
        let json = serde_json::to_value(Summary::of(&[])).unwrap();
        assert_eq!(json["frames"], 0);
        // No frames, so no size or method: null, not 0 and "".
        for field in ["width", "height", "lod_method"] {
            assert!(json[field].is_null(), "{field}: {}", json[field]);
        }
        assert_eq!(json["preprocessing_share"], 0.0);
        assert_eq!(json["total_ms"].to_string(), "0.0");
        assert!(json["animate_ms"]["median"].is_null());
    }
}
