//! The two renders' `stats.jsonl`, compared frame by frame.

use std::path::Path;

use super::FrameDiff;
use crate::record::{Record, load_records};

/// How a frame's render record changed from reference to test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StatsDelta {
    /// `total_ms` test / reference.
    pub time_ratio: f64,
    /// Rays traced, test minus reference.
    pub rays_delta: i64,
    /// `lod_recomputed`, test minus reference.
    pub lod_recomputed_delta: i64,
    /// Mean MIP level of the texture lookups, test minus reference.
    pub mip_level_shift: f64,
}

/// Fills `FrameDiff::stats` where both sides have a record; `Err` says why nothing could be
/// compared (a side without stats).
pub fn compare_stats(
    reference_dir: &Path,
    test_dir: &Path,
    frames: &mut [FrameDiff],
) -> Result<(), String> {
    let reference = load_records(&[reference_dir.to_path_buf()]).map_err(|e| e.to_string())?;
    let test = load_records(&[test_dir.to_path_buf()]).map_err(|e| e.to_string())?;
    for f in frames.iter_mut() {
        let a = reference.iter().find(|r| r.frame() == f.frame);
        let b = test.iter().find(|r| r.frame() == f.frame);
        if let (Some(a), Some(b)) = (a, b) {
            f.stats = Some(delta(a, b));
        }
    }
    Ok(())
}

fn delta(a: &Record, b: &Record) -> StatsDelta {
    let total_ms = |r: &Record| r.if_present("total_ms", r.values.total_ms);
    let ratio = match (total_ms(a), total_ms(b)) {
        (Some(x), Some(y)) if x > 0.0 => y / x,
        _ => f64::NAN,
    };
    // An absent count counts as 0 (the difference says what the other side has).
    let count = |r: &Record, name: &str, value: u64| r.if_present(name, value).unwrap_or(0) as i64;
    StatsDelta {
        time_ratio: ratio,
        rays_delta: count(b, "rays", b.values.rays) - count(a, "rays", a.values.rays),
        lod_recomputed_delta: count(b, "lod_recomputed", b.values.update.lod_recomputed as u64)
            - count(a, "lod_recomputed", a.values.update.lod_recomputed as u64),
        mip_level_shift: mean_level(histogram(b)) - mean_level(histogram(a)),
    }
}

/// The record's MIP histogram, `None` when its line had none.
fn histogram(r: &Record) -> Option<&[u64]> {
    r.if_present("mip_histogram", &r.values.mip_histogram[..])
}

/// Mean integer level of a MIP histogram (0 for an empty one).
fn mean_level(histogram: Option<&[u64]>) -> f64 {
    let Some(h) = histogram else { return 0.0 };
    let total: u64 = h.iter().sum();
    if total == 0 {
        return 0.0;
    }
    h.iter()
        .enumerate()
        .map(|(level, &n)| level as f64 * n as f64)
        .sum::<f64>()
        / total as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_level_weights_levels_by_lookups() {
        assert_eq!(mean_level(Some(&[1, 0, 3])), 1.5);
        assert_eq!(mean_level(Some(&[0, 0])), 0.0);
        assert_eq!(mean_level(None), 0.0);
    }
}
