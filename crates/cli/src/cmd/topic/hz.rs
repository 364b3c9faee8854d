//! `lidar-har topic hz`'s arithmetic: the rate of a topic over a window of its latest
//! messages, reported as `ros2 topic hz` reports it.

use std::collections::VecDeque;
use std::fmt;

/// The arrival times (ns, monotonic) of the latest messages of a topic: `capacity` periods.
#[derive(Debug)]
pub struct RateWindow {
    times_ns: VecDeque<i64>,
    capacity: usize,
}

/// The rate over a window: what `ros2 topic hz` prints once a second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateStats {
    /// Messages a second: the inverse of the mean period.
    pub rate_hz: f64,
    /// Shortest, longest period and their standard deviation, seconds.
    pub min_s: f64,
    pub max_s: f64,
    pub std_dev_s: f64,
    /// Periods in the window.
    pub periods: usize,
}

impl RateWindow {
    /// A window of the latest `capacity` periods (`ros2 topic hz --window`; at least 1).
    pub fn new(capacity: usize) -> Self {
        Self {
            times_ns: VecDeque::new(),
            capacity: capacity.max(1),
        }
    }

    /// Adds a message that arrived at `time_ns`, no earlier than the one before it.
    pub fn add(&mut self, time_ns: i64) {
        self.times_ns.push_back(time_ns);
        while self.times_ns.len() > self.capacity.saturating_add(1) {
            self.times_ns.pop_front();
        }
    }

    /// The rate over the window; `None` before two messages.
    pub fn stats(&self) -> Option<RateStats> {
        let periods: Vec<f64> = self
            .times_ns
            .iter()
            .zip(self.times_ns.iter().skip(1))
            .map(|(a, b)| (b - a) as f64 / 1e9)
            .collect();
        if periods.is_empty() {
            return None;
        }
        let n = periods.len() as f64;
        let mean = periods.iter().sum::<f64>() / n;
        let variance = periods.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / n;
        Some(RateStats {
            // As ros2: messages that all came at once have no rate to show.
            rate_hz: if mean > 0.0 { 1.0 / mean } else { 0.0 },
            min_s: periods.iter().copied().fold(f64::INFINITY, f64::min),
            max_s: periods.iter().copied().fold(0.0, f64::max),
            std_dev_s: variance.sqrt(),
            periods: periods.len(),
        })
    }
}

/// As `ros2 topic hz` prints it: the rate, then its spread on an indented line.
impl fmt::Display for RateStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "average rate: {:.3}", self.rate_hz)?;
        write!(
            f,
            "\tmin: {:.3}s max: {:.3}s std dev: {:.5}s window: {}",
            self.min_s, self.max_s, self.std_dev_s, self.periods
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    #[test]
    fn a_steady_topic_has_its_rate_and_no_spread() {
        let mut window = RateWindow::new(100);
        assert_eq!(window.stats(), None);
        window.add(0);
        assert_eq!(window.stats(), None, "one message has no period");
        for k in 1..=10 {
            window.add(k * 50 * MS);
        }
        let stats = window.stats().unwrap();
        assert!((stats.rate_hz - 20.0).abs() < 1e-9, "{stats:?}");
        assert_eq!((stats.min_s, stats.max_s, stats.periods), (0.05, 0.05, 10));
        assert!(stats.std_dev_s < 1e-12);
        assert_eq!(
            stats.to_string(),
            "average rate: 20.000\n\tmin: 0.050s max: 0.050s std dev: 0.00000s window: 10"
        );
    }

    /// Periods of 0.1 and 0.3 s: mean 0.2 s (5 Hz), standard deviation 0.1 s.
    #[test]
    fn an_uneven_topic_has_the_inverse_of_its_mean_period_and_its_spread() {
        let mut window = RateWindow::new(100);
        for t in [0, 100, 400, 500, 800] {
            window.add(t * MS);
        }
        let stats = window.stats().unwrap();
        assert!((stats.rate_hz - 5.0).abs() < 1e-9, "{stats:?}");
        assert!((stats.std_dev_s - 0.1).abs() < 1e-9, "{stats:?}");
        assert_eq!((stats.min_s, stats.max_s), (0.1, 0.3));
    }

    /// Only the latest `capacity` periods count: a topic that sped up shows its new rate.
    #[test]
    fn the_window_holds_the_latest_periods() {
        let mut window = RateWindow::new(4);
        let mut t = 0;
        for period in [1000, 1000, 1000, 100, 100, 100, 100] {
            t += period * MS;
            window.add(t);
        }
        let stats = window.stats().unwrap();
        assert_eq!(stats.periods, 4);
        assert!((stats.rate_hz - 10.0).abs() < 1e-9, "{stats:?}");
    }

    /// Messages that arrived together have a rate of 0, as ros2 prints it, not an infinite
    /// or NaN one; the largest window does not overflow.
    #[test]
    fn equal_times_give_a_rate_of_0_and_any_window_holds() {
        let mut same = RateWindow::new(usize::MAX);
        same.add(7);
        same.add(7);
        let stats = same.stats().unwrap();
        assert_eq!((stats.rate_hz, stats.periods), (0.0, 1));
        assert!(!stats.std_dev_s.is_nan());
    }
}
