//! A static background learned from the first seconds of scans, for a Lidar that does not
//! move and has no map (a Lidar fixed in the room, or a recording without odometry).
//!
//! Per beam, the background range is the median of the returns seen while learning, which
//! ignores a person who crosses the beam for less than half of that time. A beam that
//! returned in fewer than `min_return_fraction` of the learning scans looks into open space
//! (beyond `range_max`): its background is infinite, and anything it returns later is
//! foreground. A point is foreground when it is closer than `margin_m` in front of the
//! background of its beam and of both neighbour beams (the neighbours absorb the angular
//! jitter at depth edges, where a beam alternates between a near and a far surface).

use serde::{Deserialize, Serialize};

use crate::scan::Scan;

/// How the background is learned; defaults suit a 10-20 Hz Lidar in a room.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BackgroundConfig {
    /// Seconds of scans, from the first one, that make the background (a gap between two
    /// scans counts at most half a second).
    pub learn_duration_s: f64,
    /// A point must be this much closer than the background to be foreground (metres).
    pub margin_m: f64,
    /// Beams that returned in fewer learning scans than this fraction look into open space.
    pub min_return_fraction: f64,
}

impl Default for BackgroundConfig {
    fn default() -> Self {
        Self {
            learn_duration_s: 3.0,
            margin_m: 0.2,
            min_return_fraction: 0.2,
        }
    }
}

/// Learns per-beam background ranges, then classifies points.
#[derive(Debug, Clone)]
pub struct LearnedBackground {
    config: BackgroundConfig,
    state: State,
}

/// The most one gap between scans adds to the learning time (nanoseconds): a clock stepped
/// forward (NTP at boot) or a stalled driver must not end learning on one or two scans.
const MAX_LEARNING_GAP_NS: i64 = 500_000_000;

#[derive(Debug, Clone, Default)]
struct Learning {
    last_ns: Option<i64>,
    learned_ns: i64,
    scans: usize,
    samples: Vec<Vec<f32>>,
}

#[derive(Debug, Clone)]
enum State {
    /// Collecting returns per beam.
    Learning(Learning),
    /// `threshold[i]`: a return on beam `i` closer than this is foreground.
    Ready { threshold: Vec<f32> },
}

/// What feeding a scan to the background did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackgroundStatus {
    /// The scan was used for learning; nothing can be classified yet.
    Learning,
    /// The background is known; the scan can be classified.
    Ready,
}

impl LearnedBackground {
    pub fn new(config: BackgroundConfig) -> Self {
        Self {
            config,
            state: State::Learning(Learning::default()),
        }
    }

    pub fn is_ready(&self) -> bool {
        matches!(self.state, State::Ready { .. })
    }

    /// Learns from `scan` while in the learning period; afterwards does nothing. The scan that
    /// first falls after the period completes the background and is itself classifiable. A
    /// stamp before the previous one (a restarted recording) starts learning again.
    pub fn observe(&mut self, scan: &Scan) -> BackgroundStatus {
        let State::Learning(learning) = &mut self.state else {
            return BackgroundStatus::Ready;
        };
        match learning.last_ns {
            Some(last) if scan.stamp_ns < last => *learning = Learning::default(),
            Some(last) => {
                let gap_ns = scan.stamp_ns.saturating_sub(last).min(MAX_LEARNING_GAP_NS);
                learning.learned_ns += gap_ns;
            }
            None => {}
        }
        learning.last_ns = Some(scan.stamp_ns);
        let Learning {
            learned_ns,
            scans,
            samples,
            ..
        } = learning;
        if (*learned_ns as f64) * 1e-9 < self.config.learn_duration_s || *scans == 0 {
            if samples.len() < scan.ranges.len() {
                samples.resize_with(scan.ranges.len(), Vec::new);
            }
            for (beam, &r) in scan.ranges.iter().enumerate() {
                if scan.is_return(r) {
                    samples[beam].push(r);
                }
            }
            *scans += 1;
            return BackgroundStatus::Learning;
        }
        let min_returns = (self.config.min_return_fraction * *scans as f64)
            .ceil()
            .max(1.0) as usize;
        let margin = self.config.margin_m as f32;
        let background: Vec<f32> = samples
            .iter_mut()
            .map(|returns| {
                if returns.len() < min_returns {
                    return f32::INFINITY;
                }
                let mid = returns.len() / 2;
                *returns.select_nth_unstable_by(mid, f32::total_cmp).1
            })
            .collect();
        let threshold = (0..background.len())
            .map(|i| {
                let lo = i.saturating_sub(1);
                let hi = (i + 1).min(background.len() - 1);
                background[lo..=hi]
                    .iter()
                    .copied()
                    .fold(f32::INFINITY, f32::min)
                    - margin
            })
            .collect();
        self.state = State::Ready { threshold };
        BackgroundStatus::Ready
    }

    /// Whether a return of `range` metres on `beam` is in front of the background. Beams the
    /// learning never saw (a longer scan than before) count as open space.
    pub fn is_foreground(&self, beam: usize, range: f32) -> bool {
        match &self.state {
            State::Ready { threshold } => {
                range < threshold.get(beam).copied().unwrap_or(f32::INFINITY)
            }
            State::Learning(_) => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(stamp_s: f64, ranges: Vec<f32>) -> Scan {
        Scan {
            stamp_ns: (stamp_s * 1e9) as i64,
            angle_min: 0.0,
            angle_increment: 0.01,
            time_increment: 0.0,
            range_min: 0.05,
            range_max: 5.0,
            ranges,
        }
    }

    fn learned(ranges_over_time: impl Fn(usize) -> Vec<f32>) -> LearnedBackground {
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        for k in 0..30 {
            assert_eq!(
                bg.observe(&scan(k as f64 * 0.1, ranges_over_time(k))),
                BackgroundStatus::Learning
            );
        }
        assert_eq!(
            bg.observe(&scan(3.0, ranges_over_time(0))),
            BackgroundStatus::Ready
        );
        assert!(bg.is_ready());
        bg
    }

    #[test]
    fn a_person_crossing_during_learning_is_not_background() {
        // Wall at 4 m on all 10 beams; a person at 1.5 m on beam 5 for 10 of the 30 scans.
        let bg = learned(|k| {
            (0..10)
                .map(|b| if b == 5 && k < 10 { 1.5 } else { 4.0 })
                .collect()
        });
        assert!(bg.is_foreground(5, 1.5));
        assert!(!bg.is_foreground(5, 3.9), "within the margin of the wall");
        assert!(!bg.is_foreground(2, 4.0));
    }

    #[test]
    fn open_space_beams_make_any_return_foreground() {
        // Beams 0..5 never return (inf or NaN), beams 5..10 see a wall at 3 m.
        let bg = learned(|k| {
            (0..10)
                .map(|b| {
                    if b < 5 {
                        if k % 2 == 0 { f32::INFINITY } else { f32::NAN }
                    } else {
                        3.0
                    }
                })
                .collect()
        });
        assert!(bg.is_foreground(1, 4.5));
        assert!(!bg.is_foreground(7, 3.0));
        // Beam 4 borders the wall: its neighbour's background applies.
        assert!(!bg.is_foreground(4, 2.9));
        assert!(bg.is_foreground(4, 2.7));
        assert!(
            bg.is_foreground(42, 1.0),
            "beams never learned are open space"
        );
    }

    #[test]
    fn nothing_is_foreground_while_learning() {
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        assert_eq!(
            bg.observe(&scan(0.0, vec![1.0; 4])),
            BackgroundStatus::Learning
        );
        assert!(!bg.is_foreground(0, 0.1));
    }

    #[test]
    fn empty_learning_scans_give_an_all_open_background() {
        let bg = learned(|_| Vec::new());
        assert!(bg.is_foreground(0, 1.0));
    }

    #[test]
    fn a_clock_stepped_forward_does_not_end_learning() {
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        bg.observe(&scan(0.0, vec![1.0; 4]));
        // 1000 s later (NTP at boot): half a second counted, not the whole jump.
        assert_eq!(
            bg.observe(&scan(1000.0, vec![1.0; 4])),
            BackgroundStatus::Learning
        );
        for k in 1..25 {
            let status = bg.observe(&scan(1000.0 + k as f64 * 0.1, vec![1.0; 4]));
            assert_eq!(status, BackgroundStatus::Learning, "scan {k}");
        }
        assert_eq!(
            bg.observe(&scan(1002.5, vec![1.0; 4])),
            BackgroundStatus::Ready
        );
    }

    #[test]
    fn a_clock_going_back_while_learning_starts_learning_again() {
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        for k in 0..20 {
            bg.observe(&scan(100.0 + k as f64 * 0.1, vec![1.0; 4]));
        }
        // Back to 0 s: before, learning waited for the old 103 s (samples growing all along).
        for k in 0..30 {
            let status = bg.observe(&scan(k as f64 * 0.1, vec![2.0; 4]));
            assert_eq!(status, BackgroundStatus::Learning, "scan {k}");
        }
        assert_eq!(
            bg.observe(&scan(3.0, vec![2.0; 4])),
            BackgroundStatus::Ready
        );
        // Only the new timeline's wall (2 m) is background.
        assert!(!bg.is_foreground(0, 1.9));
        assert!(bg.is_foreground(0, 1.5));
    }
}
