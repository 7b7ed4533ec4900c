//! Min / median / p95 / max of one per-frame quantity.
//!
//! Rules (shared with `summary.json`):
//! - Non-finite values (NaN, ±inf) are left out; with no finite value every field is NaN
//!   (serde_json writes NaN as `null`), never an invented 0.
//! - The median of an even count is the mean of the two middle values.
//! - p95 uses the nearest-rank method: sort the `n` values ascending and take the value of
//!   1-based rank `ceil(95 n / 100)` (computed in integers). So `1..=20` gives rank 19,
//!   value 19; `1..=100` gives 95; a single value is its own p95. The result is always one
//!   of the samples, never an interpolation.

use serde::Serialize;

/// Min, median, 95th percentile (nearest rank) and max of a set of values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Percentiles {
    pub min: f64,
    pub median: f64,
    pub p95: f64,
    pub max: f64,
}

impl Percentiles {
    /// Percentiles of the finite values in `values` (all NaN when there are none).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Percentiles {
        let mut sorted: Vec<f64> = values.into_iter().filter(|v| v.is_finite()).collect();
        sorted.sort_by(f64::total_cmp);
        let (Some(&min), Some(&max)) = (sorted.first(), sorted.last()) else {
            return Percentiles {
                min: f64::NAN,
                median: f64::NAN,
                p95: f64::NAN,
                max: f64::NAN,
            };
        };
        Percentiles {
            min,
            median: median_of_sorted(&sorted),
            p95: nearest_rank(&sorted, 95),
            max,
        }
    }

    /// Whether there was no finite value to summarise.
    pub fn is_empty(&self) -> bool {
        self.min.is_nan()
    }
}

/// The median of `values` (any order): the middle value, or the mean of the two middle
/// ones for an even count; NaN when empty. Unlike [`Percentiles::of`] it keeps non-finite
/// values (NaN sorts last).
pub fn median(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    median_of_sorted(&values)
}

/// Median of ascending, non-empty `sorted`: the middle value, or the mean of the two.
fn median_of_sorted(sorted: &[f64]) -> f64 {
    let mid = sorted.len() / 2;
    if sorted.len() % 2 == 1 {
        sorted[mid]
    } else {
        0.5 * (sorted[mid - 1] + sorted[mid])
    }
}

/// The `percent`-th percentile of ascending, non-empty `sorted` by nearest rank: the value
/// at 1-based rank `ceil(percent * n / 100)` (at least 1).
pub fn nearest_rank(sorted: &[f64], percent: u32) -> f64 {
    let n = sorted.len();
    let rank = (percent as usize * n).div_ceil(100).clamp(1, n);
    sorted[rank - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_to_twenty() {
        let p = Percentiles::of((1..=20).map(f64::from));
        assert_eq!(
            p,
            Percentiles {
                min: 1.0,
                median: 10.5,
                p95: 19.0,
                max: 20.0
            }
        );
    }

    #[test]
    fn nearest_rank_rule() {
        let hundred: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(nearest_rank(&hundred, 95), 95.0);
        let twenty_one: Vec<f64> = (1..=21).map(f64::from).collect();
        // ceil(0.95 * 21) = ceil(19.95) = 20
        assert_eq!(nearest_rank(&twenty_one, 95), 20.0);
        assert_eq!(nearest_rank(&[7.0], 95), 7.0);
        assert_eq!(nearest_rank(&[1.0, 2.0], 0), 1.0);
    }

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(vec![]).is_nan());
    }

    #[test]
    fn odd_count_and_unsorted_input() {
        let p = Percentiles::of([5.0, 1.0, 3.0]);
        assert_eq!((p.min, p.median, p.p95, p.max), (1.0, 3.0, 5.0, 5.0));
    }

    #[test]
    fn non_finite_values_are_left_out() {
        let p = Percentiles::of([f64::NAN, 4.0, f64::INFINITY, 2.0, f64::NEG_INFINITY]);
        assert_eq!((p.min, p.median, p.p95, p.max), (2.0, 3.0, 4.0, 4.0));
    }

    #[test]
    fn empty_is_nan_not_zero() {
        let p = Percentiles::of([f64::NAN]);
        assert!(p.is_empty());
        assert!(p.min.is_nan() && p.median.is_nan() && p.p95.is_nan() && p.max.is_nan());
        assert!(Percentiles::of(std::iter::empty()).is_empty());
    }
}
