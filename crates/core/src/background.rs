//! A static background learned from the first seconds of scans, for a Lidar that does not
//! move and has no map (a Lidar fixed in the room, or a recording without odometry).
//!
//! The background is kept per bearing, not per beam index: some drivers (`sllidar_ros2`
//! with `angle_compensate` false) publish a few beams more or fewer each rotation, over the
//! same turn, so beam `i` of one scan is not where beam `i` of the next points. The first
//! learning scan with beams sets the bins: a full turn of them, as wide as its
//! `angle_increment`, from one centred on its `angle_min`, whatever part of the turn that
//! scan covers (a driver's first rotation may be cut short: bins sized to it had left the
//! rest of the turn open space, and every later return there foreground). Every beam of
//! every scan, learning or classified, goes to the bin nearest its angle; bins that no
//! learning beam fell in look into open space.
//!
//! Per bin, the background range is the median of the returns seen while learning, which
//! ignores a person who crosses the bearing for less than half of that time. A bin that
//! returned in fewer than `min_return_fraction` of the learning scans looks into open space
//! (beyond `range_max`): its background is infinite, and anything it returns later is
//! foreground. A point is foreground when it is closer than `margin_m` in front of the
//! background of its bin and of both neighbour bins (the neighbours absorb the angular
//! jitter at depth edges, where a beam alternates between a near and a far surface).

use std::f64::consts::TAU;

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
    /// Bearings that returned in fewer learning scans than this fraction look into open space.
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

/// Learns per-bearing background ranges, then classifies points.
#[derive(Debug, Clone)]
pub struct LearnedBackground {
    config: BackgroundConfig,
    state: State,
}

/// The most one gap between scans adds to the learning time (nanoseconds): a clock stepped
/// forward (NTP at boot) or a stalled driver must not end learning on one or two scans.
const MAX_LEARNING_GAP_NS: i64 = 500_000_000;

/// The background's bins: a full turn of them at the first learning scan's `angle_increment`,
/// bin `i` centred on `angle_min + i * angle_increment` and as wide as the increment; the
/// last one neighbours the first.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Bins {
    /// The angle in the middle of the first learning scan's beams (radians, Lidar frame):
    /// the seam, where the turn's bins may fall a fraction of a bin short of a turn, is half
    /// a turn from it (behind a Lidar that scans less than a turn).
    centre: f64,
    /// Where `centre` lies, in bins from bin 0's centre.
    middle: f64,
    /// The learning scan's `angle_increment` (radians, negative for a clockwise scan).
    increment: f64,
    /// Bins a turn, rounded: `per_turn`, give or take a fraction.
    count: usize,
    /// Bins a turn: `2 pi / |increment|`.
    per_turn: f64,
    /// Whole bins added to a position before it is rounded by truncation, so that it is
    /// positive (a cast rounds a positive number down, at a fraction of `f64::round`'s
    /// cost): more than any position's distance below bin 0.
    bias: i64,
}

impl Bins {
    /// The bins of `scan`'s beams (a validated scan with at least one beam).
    fn of(scan: &Scan) -> Self {
        let increment = f64::from(scan.angle_increment);
        let beams = scan.ranges.len();
        // Scan::validate bounds the increment to [MIN_ANGLE_INCREMENT, MAX_SPAN_RAD]: at
        // least one bin a turn, at most MAX_BEAMS.
        let per_turn = TAU / increment.abs();
        let middle = (beams - 1) as f64 / 2.0;
        Self {
            centre: f64::from(scan.angle_min) + increment * middle,
            middle,
            increment,
            count: per_turn.round().max(1.0) as usize,
            per_turn,
            // Positions are brought within half a turn of the middle.
            bias: (middle + per_turn) as i64 + 8,
        }
    }

    /// Where `angle` (radians, Lidar frame, any turn) lies, in bins from bin 0's centre:
    /// within half a turn of the bins' centre.
    fn position(&self, angle: f64) -> f64 {
        let mut from_centre = angle - self.centre;
        from_centre -= TAU * (from_centre / TAU).round();
        from_centre / self.increment + self.middle
    }

    /// The bin nearest `position` (within a turn or two of the bins' centre), around the
    /// turn.
    fn at(&self, mut position: f64) -> usize {
        let count = self.count as i64;
        let middle = self.middle;
        let half_turn = self.per_turn / 2.0;
        while position - middle > half_turn {
            position -= self.per_turn;
        }
        while position - middle < -half_turn {
            position += self.per_turn;
        }
        let mut k = (position + 0.5 + self.bias as f64) as i64 - self.bias;
        while k < 0 {
            k += count;
        }
        while k >= count {
            k -= count;
        }
        k as usize
    }

    /// The bin nearest `angle`.
    #[cfg(test)]
    fn of_angle(&self, angle: f64) -> usize {
        self.at(self.position(angle))
    }

    /// The bin of each beam of `scan` (validated), in beam order: stepped along from beam
    /// 0's, as this runs on every beam of a scan whose geometry changed (a validated scan's
    /// beams lie within little more than a turn of its first).
    fn of_beams(&self, scan: &Scan) -> impl Iterator<Item = usize> + use<> {
        let bins = *self;
        let first = bins.position(f64::from(scan.angle_min));
        let step = f64::from(scan.angle_increment) / bins.increment;
        (0..scan.ranges.len()).map(move |beam| bins.at(first + beam as f64 * step))
    }
}

#[derive(Debug, Clone, Default)]
struct Learning {
    last_ns: Option<i64>,
    learned_ns: i64,
    scans: usize,
    /// Set by the first learning scan (one with a return).
    bins: Option<Bins>,
    /// The returns of each bin.
    samples: Vec<Vec<f32>>,
}

/// The thresholds of one scan geometry's beams, kept while the geometry stays the same.
#[derive(Debug, Clone, Default)]
struct BeamThresholds {
    /// `angle_min`, `angle_increment` (bits) and beam count of the scans they are for.
    key: Option<(u32, u32, usize)>,
    threshold: Vec<f32>,
}

#[derive(Debug, Clone)]
enum State {
    /// Collecting returns per bin.
    Learning(Learning),
    /// `threshold[b]`: a return in bin `b` closer than this is foreground.
    Ready {
        bins: Bins,
        threshold: Vec<f32>,
        beams: BeamThresholds,
    },
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

    /// Learns from `scan` (validated: [`Scan::validate`]) while in the learning period;
    /// afterwards does nothing. The scan that first falls after the period completes the
    /// background and is itself classifiable. A stamp before the previous one (a restarted
    /// recording) starts learning again.
    pub fn observe(&mut self, scan: &Scan) -> BackgroundStatus {
        let State::Learning(learning) = &mut self.state else {
            return BackgroundStatus::Ready;
        };
        // A scan without a single return (a motor spinning up, a covered window, a driver's
        // empty rotation) shows nothing of the room: learning from it made every bearing
        // open space, and all furniture foreground for good. It counts neither as a
        // learning scan nor as learning time.
        let has_returns = scan.ranges.iter().any(|&r| scan.is_return(r));
        match learning.last_ns {
            Some(last) if scan.stamp_ns < last => *learning = Learning::default(),
            Some(last) if has_returns => {
                let gap_ns = scan.stamp_ns.saturating_sub(last).min(MAX_LEARNING_GAP_NS);
                learning.learned_ns = learning.learned_ns.saturating_add(gap_ns);
            }
            _ => {}
        }
        learning.last_ns = Some(scan.stamp_ns);
        if !has_returns {
            return BackgroundStatus::Learning;
        }
        let Learning {
            learned_ns,
            scans,
            bins,
            samples,
            ..
        } = learning;
        if (*learned_ns as f64) * 1e-9 < self.config.learn_duration_s || *scans == 0 {
            if bins.is_none() {
                let learned = Bins::of(scan);
                samples.resize_with(learned.count, Vec::new);
                *bins = Some(learned);
            }
            if let Some(bins) = bins {
                for (&r, bin) in scan.ranges.iter().zip(bins.of_beams(scan)) {
                    if scan.is_return(r) {
                        samples[bin].push(r);
                    }
                }
            }
            *scans += 1;
            return BackgroundStatus::Learning;
        }
        // Set by the learning scans, of which there was one at least.
        let Some(bins) = *bins else {
            return BackgroundStatus::Learning;
        };
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
        // Around the turn: the last bin neighbours the first. A bin past the end of a
        // Lidar's field of view takes the end's background, as a beam there may be the
        // end's beam a fraction of a bin further on; the next one is open space.
        let n = background.len();
        let threshold = (0..n)
            .map(|i| {
                let (before, after) = ((i + n - 1) % n, (i + 1) % n);
                background[before].min(background[i]).min(background[after]) - margin
            })
            .collect();
        self.state = State::Ready {
            bins,
            threshold,
            beams: BeamThresholds::default(),
        };
        BackgroundStatus::Ready
    }

    /// For each beam of `scan` (validated), the range below which its return is foreground
    /// (in front of the background of its bearing; infinite at bearings the learning never
    /// saw, past the field of view of a Lidar that scans less than a turn: open space);
    /// empty while learning, when nothing is foreground. Computed once per scan
    /// geometry, so classifying a scan costs a comparison a beam, as long as the geometry
    /// stays; a driver whose beam count changes every rotation pays an angle-to-bin step a
    /// beam.
    pub fn thresholds(&mut self, scan: &Scan) -> &[f32] {
        let State::Ready {
            bins,
            threshold,
            beams,
        } = &mut self.state
        else {
            return &[];
        };
        let key = (
            scan.angle_min.to_bits(),
            scan.angle_increment.to_bits(),
            scan.ranges.len(),
        );
        if beams.key != Some(key) {
            beams.key = Some(key);
            beams.threshold.clear();
            beams
                .threshold
                .extend(bins.of_beams(scan).map(|bin| threshold[bin]));
        }
        &beams.threshold
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

    /// The angle of beam `beam` of [`scan`]'s scans.
    fn at(beam: usize) -> f64 {
        beam as f64 * f64::from(0.01f32)
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
        let mut bg = learned(|k| {
            (0..10)
                .map(|b| if b == 5 && k < 10 { 1.5 } else { 4.0 })
                .collect()
        });
        assert!(is_foreground(&mut bg, at(5), 1.5));
        assert!(
            !is_foreground(&mut bg, at(5), 3.9),
            "within the margin of the wall"
        );
        assert!(!is_foreground(&mut bg, at(2), 4.0));
    }

    #[test]
    fn open_space_beams_make_any_return_foreground() {
        // Beams 0..5 never return (inf or NaN), beams 5..10 see a wall at 3 m.
        let mut bg = learned(|k| {
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
        assert!(is_foreground(&mut bg, at(1), 4.5));
        assert!(!is_foreground(&mut bg, at(7), 3.0));
        // Beam 4 borders the wall: its neighbour's background applies.
        assert!(!is_foreground(&mut bg, at(4), 2.9));
        assert!(is_foreground(&mut bg, at(4), 2.7));
        assert!(
            is_foreground(&mut bg, at(42), 1.0),
            "bearings never learned are open space"
        );
    }

    /// A room seen from a fixed Lidar, by bearing: walls 1.5-3 m away, a pole 0.3 m wide
    /// at 2.5 rad, 1 m away; and a person 0.4 m wide at 1 rad, 1.2 m away, if `person`.
    fn room_at(angle: f64, person: bool) -> f32 {
        let d = glam::DVec2::from_angle(angle);
        let wall = (2.5 / d.x.abs()).min(1.8 / d.y.abs()).min(3.0);
        let pole = crate::geometry::normalize_angle(angle - 2.5).abs() < 0.15;
        let body = person && crate::geometry::normalize_angle(angle - 1.0).abs() < 0.17;
        (if body {
            1.2
        } else if pole {
            1.0
        } else {
            wall
        }) as f32
    }

    /// `beams` beams over `span` radians from `angle_min` of [`room_at`].
    fn room_scan(stamp_s: f64, angle_min: f32, span: f64, beams: usize, person: bool) -> Scan {
        let increment = (span / beams as f64) as f32;
        let mut s = scan(stamp_s, Vec::new());
        (s.angle_min, s.angle_increment) = (angle_min, increment);
        s.ranges = (0..beams)
            .map(|i| {
                room_at(
                    f64::from(angle_min) + i as f64 * f64::from(increment),
                    person,
                )
            })
            .collect();
        s
    }

    /// Whether a return of `range` metres at `angle` radians is in front of the background:
    /// by [`LearnedBackground::thresholds`] for a scan of that one beam.
    fn is_foreground(bg: &mut LearnedBackground, angle: f64, range: f32) -> bool {
        let mut s = scan(0.0, vec![range]);
        s.angle_min = angle as f32;
        s.validate().expect("a valid scan");
        bg.thresholds(&s)
            .first()
            .is_some_and(|&threshold| s.is_return(range) && range < threshold)
    }

    /// The beams of `s` in front of the background.
    fn foreground(bg: &mut LearnedBackground, s: &Scan) -> Vec<usize> {
        let thresholds = bg.thresholds(s).to_vec();
        assert_eq!(thresholds.len(), s.ranges.len());
        (0..s.ranges.len())
            .filter(|&i| s.is_return(s.ranges[i]) && s.ranges[i] < thresholds[i])
            .collect()
    }

    #[test]
    fn the_background_is_kept_by_bearing_whatever_the_beam_count() {
        // A full turn in 1080 beams while learning, then 1078-1084 over the same turn
        // (sllidar_ros2 without angle compensation): by beam index, the pole's edges had
        // moved by up to four beams at the end of the turn and come out as foreground.
        let tau = std::f64::consts::TAU;
        let pi = -std::f32::consts::PI;
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        for k in 0..30 {
            bg.observe(&room_scan(k as f64 * 0.1, pi, tau, 1080, false));
        }
        let first = room_scan(3.0, pi, tau, 1080, false);
        assert_eq!(bg.observe(&first), BackgroundStatus::Ready);
        for beams in [1080, 1078, 1084, 1081, 1079] {
            let empty = room_scan(3.1, pi, tau, beams, false);
            assert_eq!(
                foreground(&mut bg, &empty),
                [] as [usize; 0],
                "{beams} beams"
            );
            // The person is foreground, at their bearing, on every beam that sees them.
            let person = room_scan(3.1, pi, tau, beams, true);
            let fg = foreground(&mut bg, &person);
            let expected: Vec<usize> = (0..beams)
                .filter(|&i| (person.beam_angle(i) - 1.0).abs() < 0.17)
                .collect();
            assert_eq!(fg, expected, "{beams} beams");
        }
        // The same turn from another angle_min, a turn further on: the same bearings.
        let shifted = room_scan(3.2, 0.5 + std::f32::consts::TAU, tau, 1083, false);
        assert_eq!(foreground(&mut bg, &shifted), [] as [usize; 0]);
    }

    #[test]
    fn a_full_turn_wraps_its_first_bin_onto_its_last() {
        // 360 beams from 0; the last one sees a post at 0.5 m, the others a wall at 3 m.
        let ranges = |_| {
            let mut r = vec![3.0; 360];
            r[359] = 0.5;
            r
        };
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        let full_turn = |stamp_s: f64, ranges: Vec<f32>| {
            let mut s = scan(stamp_s, ranges);
            s.angle_increment = (std::f64::consts::TAU / 360.0) as f32;
            s
        };
        for k in 0..=30 {
            bg.observe(&full_turn(k as f64 * 0.1, ranges(k)));
        }
        assert!(bg.is_ready());
        // Beam 0 neighbours beam 359 across the seam: the post's edge jitters onto it.
        let mut post_on_first = ranges(0);
        post_on_first[0] = 0.5;
        let s = full_turn(3.1, post_on_first);
        assert_eq!(foreground(&mut bg, &s), [] as [usize; 0]);
        // The bearing just below 0 is the last bin's.
        assert!(!is_foreground(&mut bg, -0.001, 0.5));
        assert!(is_foreground(&mut bg, std::f64::consts::PI, 0.5));
    }

    #[test]
    fn a_lidar_scanning_less_than_a_turn_keeps_its_field_of_view() {
        // 270 degrees in 1081 beams while learning, 1083 over the same span later.
        let span = 1.5 * std::f64::consts::PI;
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        for k in 0..=30 {
            bg.observe(&room_scan(k as f64 * 0.1, -2.35, span, 1081, false));
        }
        assert!(bg.is_ready());
        let s = room_scan(3.1, -2.35, span, 1083, false);
        assert_eq!(foreground(&mut bg, &s), [] as [usize; 0]);
        // Behind the Lidar, where the learning never looked, is open space.
        assert!(is_foreground(&mut bg, -2.35 - 0.5, 2.0));
        assert!(is_foreground(&mut bg, 2.9, 2.0));
    }

    #[test]
    fn a_first_learning_scan_of_part_of_a_turn_still_learns_the_whole_turn() {
        // The driver's first rotation is cut short (540 of 1080 beams, half a turn); the
        // rest are full turns. Bins sized to the first scan had made the other half open
        // space: 538 beams of an empty full-turn scan came out foreground.
        let tau = std::f64::consts::TAU;
        let pi = -std::f32::consts::PI;
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        bg.observe(&room_scan(0.0, pi, tau / 2.0, 540, false));
        for k in 1..=30 {
            bg.observe(&room_scan(k as f64 * 0.1, pi, tau, 1080, false));
        }
        assert!(bg.is_ready());
        for beams in [1080, 1083] {
            let empty = room_scan(3.1, pi, tau, beams, false);
            assert_eq!(foreground(&mut bg, &empty), [] as [usize; 0], "{beams}");
        }
        // The person, in the half the first scan did not cover, is foreground.
        let person = room_scan(3.1, pi, tau, 1080, true);
        let expected: Vec<usize> = (0..1080)
            .filter(|&i| (person.beam_angle(i) - 1.0).abs() < 0.17)
            .collect();
        assert!(!expected.is_empty());
        assert_eq!(foreground(&mut bg, &person), expected);
    }

    proptest::proptest! {
        #[test]
        fn stepping_along_the_beams_finds_the_bin_of_each_beams_angle(
            learned in (-10.0..10.0f32, -3.0..0.0f32, 1usize..7000, proptest::bool::ANY),
            later in (-10.0..10.0f32, -3.0..0.0f32, 1usize..7000, proptest::bool::ANY),
        ) {
            // Increments from 0.001 to 1 rad, as many of each decade.
            let geometry = |(angle_min, log_increment, beams, clockwise): (f32, f32, usize, bool)| {
                let increment = 10f32.powf(log_increment);
                // Within a turn, as Scan::validate requires.
                let beams = beams.min((crate::scan::MAX_SPAN_RAD / increment) as usize + 1);
                let mut s = scan(0.0, vec![1.0; beams]);
                s.angle_min = angle_min;
                s.angle_increment = if clockwise { -increment } else { increment };
                proptest::prop_assume!(s.validate().is_ok());
                Ok(s)
            };
            let (learned, later) = (geometry(learned)?, geometry(later)?);
            let bins = Bins::of(&learned);
            for (beam, bin) in bins.of_beams(&later).enumerate() {
                let angle = later.beam_angle(beam);
                let position = bins.position(angle);
                // Off by one only on a tie between two bins (rounding differs there).
                let tie = (position - position.floor() - 0.5).abs() < 1e-6;
                proptest::prop_assert!(
                    bin == bins.of_angle(angle) || tie,
                    "beam {beam}: {bin} against {} at {position}",
                    bins.of_angle(angle)
                );
                proptest::prop_assert!(bin < bins.count);
            }
            // Every learning beam falls in its own bin, or wraps onto the first ones.
            for (beam, bin) in bins.of_beams(&learned).enumerate() {
                proptest::prop_assert_eq!(bin, beam % bins.count);
            }
        }
    }

    #[test]
    fn nothing_is_foreground_while_learning() {
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        assert_eq!(
            bg.observe(&scan(0.0, vec![1.0; 4])),
            BackgroundStatus::Learning
        );
        assert!(!is_foreground(&mut bg, at(0), 0.1));
    }

    #[test]
    fn scans_without_returns_are_not_learned_from() {
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        // 3.1 s of rotations without a return (no beams, or none in range), then the room.
        for k in 0..31 {
            let ranges = if k % 2 == 0 {
                Vec::new()
            } else {
                vec![f32::INFINITY; 4]
            };
            assert_eq!(
                bg.observe(&scan(k as f64 * 0.1, ranges)),
                BackgroundStatus::Learning,
                "scan {k}"
            );
        }
        // Before, these scans had made every bearing open space, so the wall at 1 m became
        // foreground for good. Now the room's own 3 s are learned, the wall with them.
        for k in 31..60 {
            let status = bg.observe(&scan(k as f64 * 0.1, vec![1.0; 4]));
            assert_eq!(status, BackgroundStatus::Learning, "scan {k}");
        }
        assert_eq!(
            bg.observe(&scan(6.0, vec![1.0; 4])),
            BackgroundStatus::Ready
        );
        assert!(!is_foreground(&mut bg, at(0), 1.0));
        assert!(is_foreground(&mut bg, at(0), 0.5));
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
        assert!(!is_foreground(&mut bg, at(0), 1.9));
        assert!(is_foreground(&mut bg, at(0), 1.5));
    }
}
