//! A static background learned from the first seconds of scans, for a Lidar that does not
//! move and has no map (a Lidar fixed in the room, or a recording without odometry).
//!
//! The background is kept per bearing, not per beam index: some drivers (`sllidar_ros2`
//! with `angle_compensate` false) publish a few beams more or fewer each rotation, over the
//! same turn, so beam `i` of one scan is not where beam `i` of the next points. The learning
//! scan with the median `angle_increment` sets the bins when learning ends: a full turn of
//! them, as wide as its increment, from one centred on its `angle_min`, whatever part of the
//! turn that scan covers (a driver's first rotation may be cut short: bins sized to it had
//! left the rest of the turn open space, and every later return there foreground; or sparse:
//! bins as coarse as it had hidden a person beside furniture; or, finest, one dense rotation:
//! bins too fine for the others, most of them open space). Every beam of every scan,
//! learning or classified, goes to the bin nearest its angle; bins that no learning beam
//! fell in look into open space.
//!
//! Per bin, the background range is the median of the returns seen while learning. Where a
//! wall or furniture stands behind, that ignores a person who crosses the bearing for less
//! than half of the learning. A bin that returned in fewer than `min_return_fraction` of the
//! learning scans looks into open space (beyond `range_max`): its background is infinite, and
//! anything it returns later is foreground; but a bin that looks into open space and sees a
//! person in `min_return_fraction` (20 %) of the learning scans or more has only the person's
//! returns, and their range becomes its background. So does the range of a person who stays
//! still through the learning, anywhere. Hence, after learning, a bin that sees only returns
//! more than `margin_m` behind its background, or, if it returned in under half of the
//! learning scans, nothing (beyond `range_max`, NaN or 0), for `raise_after_s` takes the
//! nearest of those returns (infinite if none) as its background. The background only ever
//! moves farther, so a person who keeps still in front of it later stays foreground; nothing
//! in a bin that mostly returned may be a dark coat in front of the wall, and a scan with no
//! return at all a covered Lidar: neither moves it (so a person still through the learning
//! in front of open space, where nothing shows once they leave, stays background there).
//!
//! A point is foreground when it is closer than `margin_m` in front of the background of its
//! bin and of both neighbour bins (the neighbours absorb the angular jitter at depth edges,
//! where a beam alternates between a near and a far surface).

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
    /// After learning, a bearing that sees only returns `margin_m` or more behind its
    /// background (or nothing, where it returned in under half of the learning scans), for
    /// this many seconds (a gap between two scans counts at most half a second) moves its
    /// background out to the nearest of them (infinite if none), never nearer: a person
    /// present while learning stops being background once they have left. 0 keeps the
    /// learned background.
    pub raise_after_s: f64,
}

impl Default for BackgroundConfig {
    fn default() -> Self {
        Self {
            learn_duration_s: 3.0,
            margin_m: 0.2,
            min_return_fraction: 0.2,
            raise_after_s: 5.0,
        }
    }
}

/// Learns per-bearing background ranges, then classifies points.
#[derive(Debug, Clone)]
pub struct LearnedBackground {
    config: BackgroundConfig,
    state: State,
}

/// The most one gap between scans adds to the learning time, or to the time a bearing has
/// seen past its background (nanoseconds): a clock stepped forward (NTP at boot) or a
/// stalled driver must not end learning on one or two scans, nor move the background.
const MAX_GAP_NS: i64 = 500_000_000;

/// The background's bins: a full turn of them at a learning scan's `angle_increment`, bin `i`
/// centred on `angle_min + i * angle_increment` and as wide as the increment; the last one
/// neighbours the first.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Bins {
    /// The angle in the middle of the learning scan's beams (radians, Lidar frame): the
    /// seam, where the turn's bins may fall a fraction of a bin short of a turn, is half a
    /// turn from it (behind a Lidar that scans less than a turn).
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
    /// The learning scans (those with a return), binned when learning ends.
    scans: Vec<Scan>,
}

/// The bins and thresholds of one scan geometry's beams, kept while the geometry stays the
/// same.
#[derive(Debug, Clone, Default)]
struct BeamThresholds {
    /// `angle_min`, `angle_increment` (bits) and beam count of the scans they are for.
    key: Option<(u32, u32, usize)>,
    bin: Vec<usize>,
    threshold: Vec<f32>,
}

impl BeamThresholds {
    /// Makes these the thresholds of `scan`'s beams.
    fn follow(&mut self, scan: &Scan, bins: &Bins, threshold: &[f32]) {
        let key = (
            scan.angle_min.to_bits(),
            scan.angle_increment.to_bits(),
            scan.ranges.len(),
        );
        if self.key != Some(key) {
            self.key = Some(key);
            self.bin.clear();
            self.bin.extend(bins.of_beams(scan));
            self.refresh(threshold);
        }
    }

    /// Takes the bins' thresholds again (after the background moved).
    fn refresh(&mut self, threshold: &[f32]) {
        self.threshold.clear();
        self.threshold
            .extend(self.bin.iter().map(|&bin| threshold[bin]));
    }
}

/// What moves the background farther after learning: per bin, since when it has seen
/// nothing in front of its background, and the nearest return past it since then.
#[derive(Debug, Clone)]
struct Raising {
    after_ns: i64,
    /// Scan time since learning ended, each gap counted at most [`MAX_GAP_NS`].
    clock_ns: i64,
    last_ns: i64,
    /// Per bin: `clock_ns` of the last scan in which it returned at or in front of its
    /// background (or closer than `range_min`), or of its last move or due check.
    blocked_ns: Vec<i64>,
    /// Per bin: the nearest return past its background since `blocked_ns` (infinite if none).
    nearest_past: Vec<f32>,
    /// Per bin: whether it returned in under half of the learning scans, so that seeing
    /// nothing there moves it. Where it mostly returned, nothing may be a dark coat or a
    /// black chair in front of the wall, not the wall gone: only returns behind move it,
    /// else the wall would be foreground for good once they left.
    nothing_raises: Vec<bool>,
    /// The bins due to move in this scan (kept to reuse its allocation).
    due: Vec<usize>,
}

#[derive(Debug, Clone)]
enum State {
    /// Collecting learning scans.
    Learning(Learning),
    /// `threshold[b]`: a return in bin `b` closer than this is foreground.
    Ready {
        bins: Bins,
        background: Vec<f32>,
        threshold: Vec<f32>,
        beams: BeamThresholds,
        /// None when `raise_after_s` is 0.
        raising: Option<Box<Raising>>,
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

/// Bin `i`'s threshold: `margin` in front of the nearest background of it and its neighbours,
/// around the turn (the last bin neighbours the first). A bin past the end of a Lidar's field
/// of view takes the end's background, as a beam there may be the end's beam a fraction of a
/// bin further on; the next one is open space.
fn threshold_of(background: &[f32], i: usize, margin: f32) -> f32 {
    let n = background.len();
    let (before, after) = ((i + n - 1) % n, (i + 1) % n);
    background[before].min(background[i]).min(background[after]) - margin
}

/// The learning scan whose `angle_increment` is the median's (the learning has one at
/// least): its bins are the background's. The finest one let a single dense rotation make
/// bins too fine for every other scan, most of them then looking into open space.
fn median_increment_scan(scans: &[Scan]) -> &Scan {
    let mut by_increment: Vec<&Scan> = scans.iter().collect();
    let mid = by_increment.len() / 2;
    by_increment.select_nth_unstable_by(mid, |a, b| {
        a.angle_increment.abs().total_cmp(&b.angle_increment.abs())
    });
    by_increment[mid]
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
    /// afterwards moves the background of bearings that have seen past it for
    /// `raise_after_s`. The scan that first falls after the period completes the background
    /// and is itself classifiable. A stamp before the previous one (a restarted recording)
    /// starts learning again.
    pub fn observe(&mut self, scan: &Scan) -> BackgroundStatus {
        // A scan without a single return (a motor spinning up, a covered or blinded Lidar, a
        // driver's empty rotation) shows nothing of the room: learning from it made every
        // bearing open space, and all furniture foreground for good; after learning, five
        // seconds of them did the same. It counts neither as a scan nor as time.
        let has_returns = scan.ranges.iter().any(|&r| scan.is_return(r));
        let State::Learning(learning) = &mut self.state else {
            self.raise(scan, has_returns);
            return BackgroundStatus::Ready;
        };
        match learning.last_ns {
            Some(last) if scan.stamp_ns < last => *learning = Learning::default(),
            Some(last) if has_returns => {
                let gap_ns = scan.stamp_ns.saturating_sub(last).min(MAX_GAP_NS);
                learning.learned_ns = learning.learned_ns.saturating_add(gap_ns);
            }
            _ => {}
        }
        learning.last_ns = Some(scan.stamp_ns);
        if !has_returns {
            return BackgroundStatus::Learning;
        }
        if (learning.learned_ns as f64) * 1e-9 < self.config.learn_duration_s
            || learning.scans.is_empty()
        {
            learning.scans.push(scan.clone());
            return BackgroundStatus::Learning;
        }
        let bins = Bins::of(median_increment_scan(&learning.scans));
        let mut samples = vec![Vec::new(); bins.count];
        for learned in &learning.scans {
            for (&r, bin) in learned.ranges.iter().zip(bins.of_beams(learned)) {
                if learned.is_return(r) {
                    samples[bin].push(r);
                }
            }
        }
        let min_returns = (self.config.min_return_fraction * learning.scans.len() as f64)
            .ceil()
            .max(1.0) as usize;
        let margin = self.config.margin_m as f32;
        let half = learning.scans.len().div_ceil(2);
        let nothing_raises = samples.iter().map(|returns| returns.len() < half).collect();
        let background: Vec<f32> = samples
            .iter_mut()
            .map(|returns: &mut Vec<f32>| {
                if returns.len() < min_returns {
                    return f32::INFINITY;
                }
                let mid = returns.len() / 2;
                *returns.select_nth_unstable_by(mid, f32::total_cmp).1
            })
            .collect();
        let threshold = (0..background.len())
            .map(|i| threshold_of(&background, i, margin))
            .collect();
        let raising = (self.config.raise_after_s > 0.0).then(|| {
            Box::new(Raising {
                after_ns: (self.config.raise_after_s * 1e9).min(i64::MAX as f64) as i64,
                clock_ns: 0,
                last_ns: scan.stamp_ns,
                blocked_ns: vec![0; bins.count],
                nearest_past: vec![f32::INFINITY; bins.count],
                nothing_raises,
                due: Vec::new(),
            })
        });
        self.state = State::Ready {
            bins,
            background,
            threshold,
            beams: BeamThresholds::default(),
            raising,
        };
        BackgroundStatus::Ready
    }

    /// Moves the background of the bins of `scan` (validated) that have seen only returns
    /// more than `margin_m` past it (or nothing, where `nothing_raises`) for `raise_after_s`,
    /// to the nearest of those returns (infinite if none); never nearer. A scan without
    /// returns (`has_returns` false) neither counts nor adds time.
    fn raise(&mut self, scan: &Scan, has_returns: bool) {
        let State::Ready {
            bins,
            background,
            threshold,
            beams,
            raising: Some(raising),
        } = &mut self.state
        else {
            return;
        };
        let gap_ns = scan.stamp_ns.saturating_sub(raising.last_ns);
        raising.last_ns = scan.stamp_ns;
        if !has_returns {
            return;
        }
        raising.clock_ns = raising.clock_ns.saturating_add(gap_ns.clamp(0, MAX_GAP_NS));
        let clock_ns = raising.clock_ns;
        let margin = self.config.margin_m as f32;
        beams.follow(scan, bins, threshold);
        // One pass over the beams (this runs on every scan); a bin due to move moves after
        // it, unless a beam of this scan saw something in front of its background.
        raising.due.clear();
        for (&r, &bin) in scan.ranges.iter().zip(&beams.bin) {
            // Open space already (most beams of a Lidar in a large room): nothing is farther.
            let behind = background[bin];
            if behind == f32::INFINITY {
                continue;
            }
            // In front of the background, too close for the Lidar included; not nothing
            // (NaN, 0 as some drivers encode no return, or beyond range_max) nor a return
            // more than the margin behind it.
            if r <= scan.range_max && r != 0.0 && r < behind + margin {
                raising.blocked_ns[bin] = clock_ns;
                raising.nearest_past[bin] = f32::INFINITY;
            } else if raising.blocked_ns[bin] != clock_ns {
                if scan.is_return(r) {
                    raising.nearest_past[bin] = raising.nearest_past[bin].min(r);
                } else if !raising.nothing_raises[bin] {
                    continue;
                }
                if clock_ns - raising.blocked_ns[bin] >= raising.after_ns {
                    raising.due.push(bin);
                }
            }
        }
        let mut moved = false;
        for &bin in &raising.due {
            if raising.blocked_ns[bin] == clock_ns {
                continue;
            }
            // Farther: only returns more than the margin behind it went into nearest_past.
            background[bin] = raising.nearest_past[bin];
            let n = background.len();
            for i in [(bin + n - 1) % n, bin, (bin + 1) % n] {
                threshold[i] = threshold_of(background, i, margin);
            }
            raising.blocked_ns[bin] = clock_ns;
            raising.nearest_past[bin] = f32::INFINITY;
            moved = true;
        }
        if moved {
            beams.refresh(threshold);
        }
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
            ..
        } = &mut self.state
        else {
            return &[];
        };
        beams.follow(scan, bins, threshold);
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

    /// Feeds `bg` (learned) the scans `ranges(k)` at `from_s + k * 0.1` s for `k` in `0..count`.
    fn watch(
        bg: &mut LearnedBackground,
        from_s: f64,
        count: usize,
        ranges: impl Fn(usize) -> Vec<f32>,
    ) {
        for k in 0..count {
            let status = bg.observe(&scan(from_s + k as f64 * 0.1, ranges(k)));
            assert_eq!(status, BackgroundStatus::Ready);
        }
    }

    #[test]
    fn a_doorway_a_person_stood_in_while_learning_is_open_space_once_seen_empty() {
        // Beams 3..7 look through a doorway into open space (no return), the others see a
        // wall at 4 m; a person stands in the doorway at 3 m on beams 4..6 for the first
        // second of learning (10 of 31 scans): all of those bins' returns, so 3 m became
        // their background, and anyone there at 3 m or beyond was never foreground again.
        let doorway = |person: bool| -> Vec<f32> {
            (0..10)
                .map(|b| match b {
                    4..6 if person => 3.0,
                    3..7 => f32::INFINITY,
                    _ => 4.0,
                })
                .collect()
        };
        // No return, as some drivers encode it: 0.
        let empty_doorway = |k: usize| -> Vec<f32> {
            let mut ranges = doorway(false);
            if k % 2 == 1 {
                ranges[3..7].fill(0.0);
            }
            ranges
        };
        let mut bg = learned(|k| doorway(k < 10));
        assert!(!is_foreground(&mut bg, at(5), 3.0), "as learned");
        // The doorway stays empty: 4.9 s after learning is not yet raise_after_s (5 s).
        watch(&mut bg, 3.1, 49, empty_doorway);
        assert!(!is_foreground(&mut bg, at(5), 3.0));
        watch(&mut bg, 8.0, 2, empty_doorway);
        for range in [2.9, 3.0, 4.5] {
            assert!(is_foreground(&mut bg, at(5), range), "{range} m");
        }
        // The wall beside the doorway stays background.
        assert!(!is_foreground(&mut bg, at(8), 4.0));
    }

    #[test]
    fn a_person_still_through_the_learning_is_foreground_again_when_they_come_back() {
        // Someone sits still in their armchair (1.5 m, beams 4..6, a wall at 4 m behind)
        // through the whole learning, then leaves: the wall shows behind them.
        let room = |person: bool| -> Vec<f32> {
            (0..10)
                .map(|b| {
                    if person && (4..6).contains(&b) {
                        1.5
                    } else {
                        4.0
                    }
                })
                .collect()
        };
        let mut bg = learned(|_| room(true));
        watch(&mut bg, 3.1, 30, |_| room(false));
        assert!(
            !is_foreground(&mut bg, at(5), 1.5),
            "3 s gone: not yet raise_after_s"
        );
        watch(&mut bg, 6.1, 30, |_| room(false));
        // Back in the armchair: foreground, and the wall is still background.
        assert!(is_foreground(&mut bg, at(5), 1.5));
        assert!(is_foreground(&mut bg, at(4), 1.5));
        assert!(!is_foreground(&mut bg, at(5), 4.0));
        assert!(
            !is_foreground(&mut bg, at(5), 3.85),
            "within the margin of the wall"
        );
    }

    #[test]
    fn the_background_never_moves_nearer_nor_for_a_bearing_that_returns_at_times() {
        // Beams 0..5 see a far wall at 4.9 m in one scan out of three (inf otherwise), beams
        // 5..10 a wall at 4 m.
        let room = |k: usize, person: bool| -> Vec<f32> {
            (0..10)
                .map(|b| match b {
                    5..7 if person => 1.5,
                    0..5 if !k.is_multiple_of(3) => f32::INFINITY,
                    0..5 => 4.9,
                    _ => 4.0,
                })
                .collect()
        };
        let mut bg = learned(|k| room(k, false));
        // A person keeps still in front of the wall for a minute: still foreground.
        watch(&mut bg, 3.1, 600, |k| room(k, true));
        assert!(is_foreground(&mut bg, at(5), 1.5));
        assert!(is_foreground(&mut bg, at(6), 1.5));
        // The far wall that returns now and then is still background.
        assert!(!is_foreground(&mut bg, at(2), 4.9));
    }

    #[test]
    fn a_clock_stepped_forward_does_not_move_the_background() {
        let wall = |_| vec![4.0; 10];
        let mut bg = learned(wall);
        // Beams 5..10 return past the wall in two scans 1000 s apart (NTP at boot): 0.6 s
        // counted, not 1000.
        let past = |_| [[4.0; 5], [4.5; 5]].concat();
        watch(&mut bg, 3.1, 1, past);
        watch(&mut bg, 1003.1, 1, past);
        assert!(!is_foreground(&mut bg, at(7), 3.9));
    }

    #[test]
    fn a_lidar_that_returns_nothing_for_a_while_leaves_the_background_as_it_was() {
        // Covered or blinded for 10 s: inf, NaN and 0 (as drivers encode no return) on every
        // beam. Counted, every bearing that returned in under half of the learning (beams
        // 0..4: a far wall, in one scan out of three) became open space, and its wall
        // foreground for good.
        let mut bg = learned(|k| {
            (0..10)
                .map(|b| match b {
                    0..4 if k.is_multiple_of(3) => 4.9,
                    0..4 => f32::INFINITY,
                    _ => 4.0,
                })
                .collect()
        });
        for (k, nothing) in [f32::INFINITY, f32::NAN, 0.0].into_iter().enumerate() {
            watch(&mut bg, 3.1 + 40.0 * k as f64, 100, |_| vec![nothing; 10]);
        }
        assert!(!is_foreground(&mut bg, at(1), 4.9));
        for beam in 4..10 {
            assert!(!is_foreground(&mut bg, at(beam), 4.0), "beam {beam}");
        }
    }

    #[test]
    fn nothing_in_front_of_a_wall_that_always_returned_does_not_move_it() {
        // A person in a dark coat, or a black chair, returns nothing on beams 4..7 for 10 s
        // in front of a wall that returned in every learning scan: the wall is still there.
        let mut bg = learned(|_| vec![4.0; 10]);
        watch(&mut bg, 3.1, 100, |_| {
            (0..10)
                .map(|b| {
                    if (4..7).contains(&b) {
                        f32::INFINITY
                    } else {
                        4.0
                    }
                })
                .collect()
        });
        assert!(!is_foreground(&mut bg, at(5), 4.0));
        // Returns behind it still move it (the wall was someone standing there).
        watch(&mut bg, 13.1, 60, |_| {
            [&[4.0f32; 4][..], &[4.6; 6]].concat()
        });
        assert!(is_foreground(&mut bg, at(8), 4.0));
    }

    #[test]
    fn raise_after_s_0_keeps_the_learned_background() {
        let config = BackgroundConfig {
            raise_after_s: 0.0,
            ..BackgroundConfig::default()
        };
        let mut bg = LearnedBackground::new(config);
        for k in 0..=30 {
            bg.observe(&scan(k as f64 * 0.1, vec![1.5; 10]));
        }
        assert!(bg.is_ready());
        watch(&mut bg, 3.1, 100, |_| vec![4.0; 10]);
        assert!(!is_foreground(&mut bg, at(5), 1.5));
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

    #[test]
    fn a_sparse_first_learning_scan_does_not_coarsen_the_bins() {
        // The driver's first rotation came with 40 beams over the turn, the rest with 1080:
        // bins as coarse as the first scan's spread the pole's 1 m over the person beside it
        // (at 1.2 m, 0.1-0.3 rad from the pole's edge, moved here).
        let tau = std::f64::consts::TAU;
        let pi = -std::f32::consts::PI;
        let person_by_the_pole = |mut s: Scan| {
            for i in 0..s.ranges.len() {
                let off = crate::geometry::normalize_angle(s.beam_angle(i) - 2.5);
                if (0.2..0.3).contains(&off) {
                    s.ranges[i] = 1.2;
                }
            }
            s
        };
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        bg.observe(&room_scan(0.0, pi, tau, 40, false));
        for k in 1..=31 {
            bg.observe(&room_scan(k as f64 * 0.1, pi, tau, 1080, false));
        }
        assert!(bg.is_ready());
        let empty = room_scan(3.2, pi, tau, 1080, false);
        assert_eq!(foreground(&mut bg, &empty), [] as [usize; 0]);
        let person = person_by_the_pole(room_scan(3.2, pi, tau, 1080, false));
        let expected: Vec<usize> = (0..1080).filter(|&i| person.ranges[i] == 1.2).collect();
        assert!(!expected.is_empty());
        assert_eq!(foreground(&mut bg, &person), expected);
    }

    #[test]
    fn one_dense_learning_scan_does_not_set_the_bins() {
        // 1078-1084 beams a turn (sllidar_ros2 without angle compensation), one rotation in
        // the middle of the learning with eight times as many: bins that fine left most of
        // them open space, and a quarter of an empty room's beams foreground.
        let tau = std::f64::consts::TAU;
        let pi = -std::f32::consts::PI;
        let beams = |k: usize| 1078 + k % 7;
        let mut bg = LearnedBackground::new(BackgroundConfig::default());
        for k in 0..=31 {
            let count = if k == 15 { 8 * 1080 } else { beams(k) };
            bg.observe(&room_scan(k as f64 * 0.1, pi, tau, count, false));
        }
        assert!(bg.is_ready());
        for k in 32..40 {
            let empty = room_scan(k as f64 * 0.1, pi, tau, beams(k), false);
            assert_eq!(foreground(&mut bg, &empty), [] as [usize; 0], "scan {k}");
        }
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
