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
    /// Seconds of scans, from the first one, that make the background.
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

#[derive(Debug, Clone)]
enum State {
    /// Collecting returns per beam since `start_ns`.
    Learning {
        start_ns: Option<i64>,
        scans: usize,
        samples: Vec<Vec<f32>>,
    },
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
            state: State::Learning {
                start_ns: None,
                scans: 0,
                samples: Vec::new(),
            },
        }
    }

    pub fn is_ready(&self) -> bool {
        matches!(self.state, State::Ready { .. })
    }

    /// Learns from `scan` while in the learning period; afterwards does nothing. The scan that
    /// first falls after the period completes the background and is itself classifiable.
    pub fn observe(&mut self, scan: &Scan) -> BackgroundStatus {
        let State::Learning {
            start_ns,
            scans,
            samples,
        } = &mut self.state
        else {
            return BackgroundStatus::Ready;
        };
        let start = *start_ns.get_or_insert(scan.stamp_ns);
        let elapsed_s = (scan.stamp_ns.saturating_sub(start)) as f64 * 1e-9;
        if elapsed_s < self.config.learn_duration_s || *scans == 0 {
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
            State::Learning { .. } => false,
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
}
