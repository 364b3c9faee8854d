//! Medians and quantiles, each rule named once: nearest rank (the figures of `summary.json`
//! and the reports), the median as the mean of the middle two (per-episode accuracy), and
//! the upper median (thresholds over a few scans); and the same spread gathered in fixed
//! memory over a run of any length ([`SpreadTally`]).

use hdrhistogram::Histogram;
use serde::Serialize;

/// Nearest-rank quantile `q` (0..=1) of ascending `sorted` values: the smallest value with
/// at least a fraction `q` of them at or below it, so always a value that occurred. `None`
/// when empty.
pub fn nearest_rank(sorted: &[f64], q: f64) -> Option<f64> {
    let n = sorted.len();
    (n > 0).then(|| sorted[((q * n as f64).ceil() as usize).clamp(1, n) - 1])
}

/// The median of `values` (reordered): the middle value, or the mean of the middle two for
/// an even count; `None` when empty.
pub fn median(values: &mut [f64]) -> Option<f64> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let (_, &mut upper, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        return Some(upper);
    }
    // The lower middle is the largest of the values the selection put before the upper one.
    let lower = values[..n / 2]
        .iter()
        .copied()
        .max_by(f64::total_cmp)
        .unwrap_or(upper);
    Some((lower + upper) / 2.0)
}

/// The upper of the middle two of `values` (reordered) for an even count, else the middle
/// one; `None` when empty. A value that occurred: the rule of the thresholds decided on the
/// median of a few scans (the fall alerts), where a mean of two would be a reading no scan gave.
pub fn upper_median(values: &mut [f64]) -> Option<f64> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let (_, &mut upper, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    Some(upper)
}

/// Median and tail of a distribution, all nearest-rank quantiles: exact from [`Spread::of`]
/// (so the median of an even count is the lower of the middle two, a value that occurred),
/// to three significant digits from a [`SpreadTally`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    pub median: f64,
    pub p95: f64,
    pub p99: f64,
    pub max: f64,
    pub count: usize,
}

impl Spread {
    /// The spread of the finite `values`; `None` when there are none.
    pub fn of(mut values: Vec<f64>) -> Option<Spread> {
        values.retain(|v| v.is_finite());
        values.sort_by(f64::total_cmp);
        let q = |p: f64| nearest_rank(&values, p);
        Some(Spread {
            median: q(0.5)?,
            p95: q(0.95)?,
            p99: q(0.99)?,
            max: q(1.0)?,
            count: values.len(),
        })
    }
}

/// A [`Spread`] gathered one value at a time in fixed memory: a day's bag at 20 Hz would
/// otherwise keep every scan's figure to the end. Its quantiles are the nearest ranks to
/// within 0.1 % (three significant digits) or one step, whichever is larger; its `max` and
/// `count` are exact.
#[derive(Debug, Clone)]
pub struct SpreadTally {
    histogram: Histogram<u64>,
    /// Values are counted in whole steps of `1 / steps_per_unit`: their resolution.
    steps_per_unit: f64,
    max: Option<f64>,
}

impl SpreadTally {
    /// Significant digits the histogram keeps.
    const DIGITS: u8 = 3;
    /// Steps beyond this count as this (a scan taking over 1000 s, an error over 1000 km at
    /// the steps the run uses); the histogram grows with the largest value up to it.
    const TOP_STEPS: u64 = 1_000_000_000_000;

    /// A tally of values at or above zero, resolved to `1 / steps_per_unit` (1e6 for
    /// metres to the micrometre).
    pub fn with_steps_per_unit(steps_per_unit: f64) -> Self {
        Self {
            histogram: Histogram::new(Self::DIGITS).expect("three significant digits is valid"),
            steps_per_unit,
            max: None,
        }
    }

    /// Counts `value`; a value that is not finite is left out (as [`Spread::of`] does), one
    /// below zero counts as zero.
    pub fn record(&mut self, value: f64) {
        if !value.is_finite() {
            return;
        }
        let value = value.max(0.0);
        let steps = ((value * self.steps_per_unit).round() as u64).min(Self::TOP_STEPS);
        self.histogram
            .record(steps)
            .expect("an auto-resizing histogram takes values up to TOP_STEPS");
        self.max = Some(self.max.map_or(value, |max| max.max(value)));
    }

    /// The spread of the values counted; `None` before any.
    pub fn spread(&self) -> Option<Spread> {
        let max = self.max?;
        // The middle of the quantile's bucket: within half a bucket either side.
        let q = |p: f64| {
            let steps = self.histogram.value_at_quantile(p);
            (self.histogram.median_equivalent(steps) as f64 / self.steps_per_unit).min(max)
        };
        Some(Spread {
            median: q(0.5),
            p95: q(0.95),
            p99: q(0.99),
            max,
            count: self.histogram.len() as usize,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_picks_a_value_that_occurred() {
        let sorted: Vec<f64> = (1..=20).map(f64::from).collect();
        assert_eq!(nearest_rank(&sorted, 0.5), Some(10.0));
        assert_eq!(nearest_rank(&sorted, 0.95), Some(19.0));
        assert_eq!(nearest_rank(&sorted, 0.951), Some(20.0));
        assert_eq!(nearest_rank(&sorted, 0.0), Some(1.0));
        assert_eq!(nearest_rank(&sorted, 1.0), Some(20.0));
        assert_eq!(nearest_rank(&[], 0.5), None);
    }

    #[test]
    fn the_median_of_an_even_count_is_the_mean_of_the_middle_two() {
        assert_eq!(median(&mut []), None);
        assert_eq!(median(&mut [0.5]), Some(0.5));
        assert_eq!(median(&mut [0.9, 0.1, 0.2]), Some(0.2));
        assert_eq!(median(&mut [0.949, 0.915]), Some((0.915 + 0.949) / 2.0));
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0, 8.0, 0.0]), Some(2.5));
        assert_eq!(upper_median(&mut [4.0, 1.0, 3.0, 2.0, 8.0, 0.0]), Some(3.0));
        assert_eq!(upper_median(&mut [0.9, 0.1, 0.2]), Some(0.2));
        assert_eq!(upper_median(&mut []), None);
    }

    #[test]
    fn a_spread_takes_nearest_ranks() {
        let s = Spread::of((1..=100).map(f64::from).collect()).unwrap();
        assert_eq!(
            (s.median, s.p95, s.p99, s.max, s.count),
            (50.0, 95.0, 99.0, 100.0, 100)
        );
    }

    #[test]
    fn a_spread_ignores_values_that_are_not_finite() {
        let spread = Spread::of(vec![3.0, f64::NAN, 1.0, 2.0, f64::INFINITY]).unwrap();
        assert_eq!((spread.median, spread.max, spread.count), (2.0, 3.0, 3));
        assert_eq!(Spread::of(vec![f64::NAN]), None);
        assert_eq!(Spread::of(Vec::new()), None);
    }

    #[test]
    fn a_tally_gives_the_spread_of_its_values_to_three_digits() {
        // Spread over five decades, as scan times or position errors are.
        let values: Vec<f64> = (0..10_000)
            .map(|i| 0.001 * 10f64.powf(f64::from(i % 997) / 200.0) + f64::from(i) * 1e-7)
            .collect();
        let mut tally = SpreadTally::with_steps_per_unit(1e6);
        values.iter().for_each(|&v| tally.record(v));
        let streamed = tally.spread().unwrap();
        let exact = Spread::of(values).unwrap();
        for (s, e) in [
            (streamed.median, exact.median),
            (streamed.p95, exact.p95),
            (streamed.p99, exact.p99),
        ] {
            assert!((s - e).abs() <= e * 1e-3 + 1e-6, "{s} against {e}");
        }
        assert_eq!((streamed.max, streamed.count), (exact.max, exact.count));
    }

    #[test]
    fn a_tally_leaves_out_values_that_are_not_finite() {
        let mut tally = SpreadTally::with_steps_per_unit(1e3);
        assert_eq!(tally.spread(), None);
        tally.record(f64::NAN);
        tally.record(f64::INFINITY);
        assert_eq!(tally.spread(), None);
        for v in [3.0, 1.0, 2.0, -1.0, 1e300] {
            tally.record(v);
        }
        let spread = tally.spread().unwrap();
        assert_eq!((spread.median, spread.max, spread.count), (2.0, 1e300, 5));
        assert!(spread.p99 <= spread.max);
    }
}
