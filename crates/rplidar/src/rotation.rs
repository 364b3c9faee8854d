//! Assembly of decoded samples into full rotations, stamped with the host's arrival times.
//!
//! A rotation starts where the angle wraps (jumps back by more than half a turn), or at a
//! sample with the device's start flag near the zero mark (the flag marks the first sample
//! of a turn; one elsewhere is corruption and is ignored). A start that comes less than half
//! a turn after the previous one is ignored, so a flag and a wrap a few samples apart do not
//! make a one-sample rotation. The angle swept counts forward jumps over lost samples, so a
//! gap does not hide the next wrap; a "jump" of nearly a turn is a step back across the zero
//! mark instead (a close return compensated past it, see `MAX_STEP_BACK_DEG`), so such a
//! return moves the start of its turn by a few samples but never splits the turn. Samples
//! before the first start are dropped: a scan starts mid-rotation.
//!
//! Outliers: a standard node falsely accepted after a lost byte carries an arbitrary angle;
//! taken as it is, one more than half a turn behind its predecessor would close the rotation
//! there and split the turn in two. So a sample that does not continue the last one kept
//! (more than `MAX_STEP_AHEAD_DEG` ahead or the compensation spread behind) waits: when one
//! of the next `MAX_OUTLIER_RUN` samples continues the last one kept, the samples before it
//! are dropped as outliers; when none does, the angle really jumped (samples were lost) and
//! they are all kept. A wrap therefore counts only once a sample after it confirms it.
//!
//! Arrival times: one read from the port can hold many samples (after a stall of the host,
//! several turns), all arriving at once, yet the device measured them one sample interval
//! apart. Each sample is therefore dated back from the read's arrival by the samples after
//! it times the device's sample interval, and never before the sample preceding it, so that
//! rotations read together keep their own periods and every rotation lasts a positive time.
//! The samples after it include those the decoder has received but still holds back (see
//! [`RotationAssembler::push_with_held_back`]): a capsule's samples are only released when
//! the next capsule arrives, so the last sample released was measured a whole capsule before
//! the read's arrival. Dating back from the read is exact when one read takes the whole
//! backlog and the packets take no time on the wire: the driver reads a backlog that the
//! kernel hands over in pieces (at most 4095 bytes at a time) to its end before passing it
//! here, up to 256 KiB. Past that, the next piece cannot be told from fresh data, and its
//! rotations crowd together in time. On a real serial line every stamp is also late by the
//! transfer of the packet that completed the read (an 84-byte capsule takes 7.3 ms at
//! 115200 baud, a 5-byte node 0.4 ms), which is not taken off.

use std::time::{Duration, Instant};

use crate::decode::{Sample, angle_continues};

/// One sample of a rotation, in the device's frame (clockwise degrees, millimetres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationSample {
    pub angle_deg: f32,
    pub distance_mm: f32,
    pub quality: u8,
}

/// One full turn of the device.
#[derive(Debug, Clone, PartialEq)]
pub struct Rotation {
    pub samples: Vec<RotationSample>,
    /// Arrival of this rotation's first sample (dated back within its read, see the module
    /// documentation).
    pub started: Instant,
    /// Arrival of the next rotation's first sample: `ended - started` is the measured
    /// rotation period, always positive.
    pub ended: Instant,
}

impl Rotation {
    /// Measured period in seconds.
    pub fn period_s(&self) -> f64 {
        self.ended
            .saturating_duration_since(self.started)
            .as_secs_f64()
    }
}

/// Collects samples into [`Rotation`]s.
#[derive(Debug, Clone)]
pub struct RotationAssembler {
    current: Vec<RotationSample>,
    started: Option<Instant>,
    /// Angle of the last sample kept.
    last_angle: Option<f32>,
    /// Samples in a row (with their dates) that do not continue the last one kept: outliers
    /// or the start of a jump, which the samples after them tell apart.
    suspects: Vec<(Sample, Instant)>,
    /// A kept sample more than half a turn behind the one before it, waiting for the next
    /// sample to confirm the wrap.
    unconfirmed_wrap: Option<(Sample, Instant)>,
    swept_deg: f32,
    /// Arrival given to the last sample pushed.
    last_time: Option<Instant>,
    sample_interval: Duration,
    max_samples: usize,
    discarded: u64,
}

/// Far more samples than any device delivers per turn (S3 at its slowest: ~32 kHz / 5 Hz).
const DEFAULT_MAX_SAMPLES: usize = 20_000;

/// Largest step back of the angle between neighbouring samples that is jitter, not a jump
/// forward over lost samples. A close return just before the zero mark is compensated past
/// it, ahead of its neighbours by up to the compensation spread: the next sample, back
/// before the zero mark, must not count as nearly a turn of progress, or the turn splits in
/// two at the real zero mark a few samples later.
const MAX_STEP_BACK_DEG: f32 = crate::decode::COMPENSATION_SPREAD_DEG;

/// How far from the zero mark a start flag may lie (the first sample of a turn).
const START_FLAG_WINDOW_DEG: f32 = 10.0;

/// A wrap that lands more than this far ahead of the last sample waits for the next sample
/// to confirm it. Consecutive samples of a turn lie at most a few degrees apart, so a wrap
/// landing far ahead is a close return compensated past the zero mark or a false sample
/// that still continued the last one; either way the samples after it fall back before
/// the zero mark. A plain wrap closes its rotation at once.
const UNCONFIRMED_WRAP_STEP_DEG: f32 = 5.0;

/// Longest run of samples dropped as outliers. The standard decoder takes a node that does
/// not continue its predecessor only at the head of a chain of four, so false nodes come in
/// short runs; a real jump of the angle is followed by samples that continue each other for
/// the rest of the turn.
const MAX_OUTLIER_RUN: usize = 8;

impl Default for RotationAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl RotationAssembler {
    /// An assembler that gives every sample of a read the read's arrival time (kept in
    /// order); see [`RotationAssembler::with_sample_interval`].
    pub fn new() -> Self {
        Self::with_sample_interval(Duration::ZERO)
    }

    /// An assembler that dates samples back from their read's arrival at `interval`, the
    /// time between two samples of the device.
    pub fn with_sample_interval(interval: Duration) -> Self {
        Self {
            current: Vec::with_capacity(2048),
            started: None,
            last_angle: None,
            suspects: Vec::with_capacity(MAX_OUTLIER_RUN),
            unconfirmed_wrap: None,
            swept_deg: 0.0,
            last_time: None,
            sample_interval: interval,
            max_samples: DEFAULT_MAX_SAMPLES,
            discarded: 0,
        }
    }

    /// Samples dropped because they came before the first start, made a "rotation" that
    /// never wrapped, or were outliers.
    pub fn discarded(&self) -> u64 {
        self.discarded
    }

    /// Forgets the rotation in progress (after a restart of the scan).
    pub fn reset(&mut self) {
        self.discarded += (self.current.len() + self.suspects.len()) as u64;
        self.discarded += u64::from(self.unconfirmed_wrap.take().is_some());
        self.current.clear();
        self.suspects.clear();
        self.started = None;
        self.last_angle = None;
        self.swept_deg = 0.0;
    }

    /// Adds the samples of one read that arrived at `arrival`, the last of them measured
    /// just before it; completed rotations are appended to `out`.
    pub fn push(&mut self, samples: &[Sample], arrival: Instant, out: &mut Vec<Rotation>) {
        self.push_with_held_back(samples, 0, arrival, out);
    }

    /// Adds the samples of one read that arrived at `arrival` while `held_back` more samples
    /// measured after them came with it but are not decoded yet
    /// ([`crate::StreamDecoder::held_back_samples`]); completed rotations are appended to
    /// `out`.
    pub fn push_with_held_back(
        &mut self,
        samples: &[Sample],
        held_back: usize,
        arrival: Instant,
        out: &mut Vec<Rotation>,
    ) {
        for (i, s) in samples.iter().enumerate() {
            let time = self.date(arrival, samples.len() - 1 - i + held_back);
            self.screen(*s, time, out);
        }
    }

    /// Keeps samples that continue the last one kept; holds the others until the samples
    /// after them show whether they are outliers (see the module documentation).
    fn screen(&mut self, s: Sample, time: Instant, out: &mut Vec<Rotation>) {
        if self
            .last_angle
            .is_none_or(|last| angle_continues(last, s.angle_deg))
        {
            self.discarded += self.suspects.len() as u64;
            self.suspects.clear();
            self.assemble(&s, time, out);
        } else if self.suspects.len() < MAX_OUTLIER_RUN {
            self.suspects.push((s, time));
        } else {
            let mut jump = std::mem::take(&mut self.suspects);
            for (suspect, suspect_time) in jump.drain(..) {
                self.assemble(&suspect, suspect_time, out);
            }
            self.suspects = jump;
            self.assemble(&s, time, out);
        }
    }

    /// Adds a kept sample, holding one that wraps far ahead until the next sample confirms
    /// the wrap.
    fn assemble(&mut self, s: &Sample, time: Instant, out: &mut Vec<Rotation>) {
        let step = self.last_angle.map_or(0.0, |last| s.angle_deg - last);
        if let Some((wrap, wrap_time)) = self.unconfirmed_wrap.take() {
            if step < -180.0 {
                self.add(&wrap, wrap_time, out);
            } else {
                // Back before the zero mark: a close return compensated past it, or a false
                // sample. It stays in its turn and moves nothing.
                self.keep_in_place(&wrap);
            }
        } else if (-360.0 + UNCONFIRMED_WRAP_STEP_DEG..-180.0).contains(&step) {
            self.unconfirmed_wrap = Some((*s, time));
            return;
        }
        self.add(s, time, out);
    }

    /// Adds a sample to the rotation in progress without taking its angle as progress.
    fn keep_in_place(&mut self, s: &Sample) {
        if self.started.is_none() || self.current.len() >= self.max_samples {
            self.discarded += 1;
        } else {
            self.current.push(RotationSample {
                angle_deg: s.angle_deg,
                distance_mm: s.distance_mm,
                quality: s.quality,
            });
        }
    }

    /// Adds a sample to the rotation in progress, closing it at a start.
    fn add(&mut self, s: &Sample, time: Instant, out: &mut Vec<Rotation>) {
        let (progress, wrapped) = match self.last_angle {
            None => (0.0, false),
            Some(last) => {
                let step = s.angle_deg - last;
                if step < -180.0 {
                    (step + 360.0, true)
                } else if (0.0..=360.0 - MAX_STEP_BACK_DEG).contains(&step) {
                    // The motor only turns forward: a jump is samples lost in between.
                    (step, false)
                } else {
                    // A step back, across the zero mark or not: jitter or corruption.
                    (0.0, false)
                }
            }
        };
        self.swept_deg += progress;
        self.last_angle = Some(s.angle_deg);
        let flagged = s.start_of_rotation
            && (s.angle_deg <= START_FLAG_WINDOW_DEG
                || s.angle_deg >= 360.0 - START_FLAG_WINDOW_DEG);
        if (flagged || wrapped) && (self.started.is_none() || self.swept_deg >= 180.0) {
            if let Some(started) = self.started {
                let capacity = self.current.capacity();
                let samples = std::mem::replace(&mut self.current, Vec::with_capacity(capacity));
                out.push(Rotation {
                    samples,
                    started,
                    ended: time,
                });
            }
            self.started = Some(time);
            self.swept_deg = 0.0;
        }
        if self.started.is_none() {
            self.discarded += 1;
            return;
        }
        if self.current.len() >= self.max_samples {
            // The angle never wrapped: no motor, or nonsense angles. Start over.
            self.reset();
            return;
        }
        self.current.push(RotationSample {
            angle_deg: s.angle_deg,
            distance_mm: s.distance_mm,
            quality: s.quality,
        });
    }

    /// Arrival of a sample with `after` more samples behind it in a read that arrived at
    /// `arrival`: dated back at the sample interval, and after the sample before it.
    fn date(&mut self, arrival: Instant, after: usize) -> Instant {
        let back = u32::try_from(after)
            .ok()
            .and_then(|after| self.sample_interval.checked_mul(after))
            .and_then(|d| arrival.checked_sub(d))
            .unwrap_or(arrival);
        let time = match self.last_time {
            Some(last) => back.max(last.checked_add(Duration::from_nanos(1)).unwrap_or(last)),
            None => back,
        };
        self.last_time = Some(time);
        time
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn sample(angle: f32, start: bool) -> Sample {
        Sample {
            angle_deg: angle,
            distance_mm: 1000.0,
            quality: 100,
            start_of_rotation: start,
        }
    }

    fn turn(n: usize, with_flag: bool) -> Vec<Sample> {
        (0..n)
            .map(|k| sample(k as f32 * 360.0 / n as f32, with_flag && k == 0))
            .collect()
    }

    #[test]
    fn rotations_start_at_flags_and_carry_arrival_times() {
        let mut a = RotationAssembler::new();
        let t0 = Instant::now();
        let mut out = Vec::new();
        // Half a turn before the first start is dropped.
        let half: Vec<Sample> = (180..360).map(|k| sample(k as f32, false)).collect();
        a.push(&half, t0, &mut out);
        for i in 1..=3 {
            a.push(
                &turn(360, true),
                t0 + Duration::from_millis(100 * i),
                &mut out,
            );
        }
        a.push(
            &[sample(0.0, true)],
            t0 + Duration::from_millis(400),
            &mut out,
        );
        assert_eq!(out.len(), 3);
        assert!(out.iter().all(|r| r.samples.len() == 360));
        assert!((out[0].period_s() - 0.1).abs() < 1e-9);
        assert_eq!(a.discarded(), 180);
    }

    #[test]
    fn a_lost_flag_is_replaced_by_the_wrap() {
        let mut a = RotationAssembler::new();
        let t0 = Instant::now();
        let mut out = Vec::new();
        a.push(&turn(100, true), t0, &mut out);
        a.push(&turn(100, false), t0, &mut out);
        a.push(&turn(100, true), t0, &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(out[1].samples.len(), 100);
    }

    #[test]
    fn flag_and_wrap_close_together_make_one_boundary() {
        let mut a = RotationAssembler::new();
        let t0 = Instant::now();
        let mut out = Vec::new();
        for _ in 0..3 {
            // Flag on the sample at 359.5, wrap two samples later.
            let mut s: Vec<Sample> = (0..720).map(|k| sample(k as f32 * 0.5, false)).collect();
            s[719].start_of_rotation = true;
            a.push(&s, t0, &mut out);
        }
        assert_eq!(out.len(), 2);
        assert!(out.iter().all(|r| r.samples.len() == 720));
    }

    /// Rotation sizes of a stream of samples read in one go.
    fn sizes(samples: &[Sample]) -> Vec<usize> {
        let mut a = RotationAssembler::new();
        let mut out = Vec::new();
        a.push(samples, Instant::now(), &mut out);
        out.iter().map(|r| r.samples.len()).collect()
    }

    fn degrees(range: std::ops::Range<u32>) -> impl Iterator<Item = Sample> {
        range.map(|k| sample(k as f32, k == 0))
    }

    #[test]
    fn a_backlog_read_at_once_keeps_every_rotation_s_period() {
        // 360 samples per 0.1 s turn, each read one interval after its last sample was
        // measured. The first turn comes in 10 reads 10 ms apart; then the host stalls and
        // three turns and the next start arrive in one read at 400 ms.
        let interval = Duration::from_nanos(277_778);
        let arrival_after = |t0: Instant, samples: u32| t0 + interval * samples;
        let mut a = RotationAssembler::with_sample_interval(interval);
        let t0 = Instant::now();
        let mut out = Vec::new();
        let stream: Vec<Sample> = (0..4)
            .flat_map(|_| turn(360, true))
            .chain([sample(0.0, true)])
            .collect();
        for k in 0..10 {
            let read = &stream[36 * k..36 * (k + 1)];
            a.push(read, arrival_after(t0, 36 * (k as u32 + 1)), &mut out);
        }
        a.push(&stream[360..], arrival_after(t0, 1441), &mut out);
        assert_eq!(out.len(), 4);
        for (k, r) in out.iter().enumerate() {
            // Every rotation starts when its first sample was measured, one interval late.
            assert_eq!(
                r.started,
                arrival_after(t0, 360 * k as u32 + 1),
                "rotation {k}"
            );
            assert!(
                (r.period_s() - 0.1).abs() < 1e-6,
                "rotation {k}: {}",
                r.period_s()
            );
        }
    }

    #[test]
    fn rotations_read_together_without_an_interval_still_last_a_positive_time() {
        let mut a = RotationAssembler::new();
        let mut out = Vec::new();
        let mut stream: Vec<Sample> = (0..4).flat_map(|_| turn(100, true)).collect();
        stream.push(sample(0.0, true));
        a.push(&stream, Instant::now(), &mut out);
        assert_eq!(out.len(), 4);
        for pair in out.windows(2) {
            assert!(pair[0].started < pair[0].ended && pair[0].ended == pair[1].started);
        }
        assert!(out[3].period_s() > 0.0);
    }

    #[test]
    fn a_gap_of_half_a_turn_or_more_does_not_merge_two_rotations() {
        // Turn, then 0..99, samples 100..299 lost, 300..359, then two full turns.
        let stream: Vec<Sample> = degrees(0..360)
            .chain(degrees(0..100))
            .chain(degrees(300..360))
            .chain(degrees(0..360))
            .chain(degrees(0..360))
            .chain(degrees(0..1))
            .collect();
        assert_eq!(sizes(&stream), [360, 160, 360, 360]);
    }

    #[test]
    fn a_start_flag_away_from_the_zero_mark_is_ignored() {
        let mut stream: Vec<Sample> = degrees(0..360).chain(degrees(0..360)).collect();
        stream[360 + 200].start_of_rotation = true;
        stream.extend(degrees(0..360).chain(degrees(0..1)));
        assert_eq!(sizes(&stream), [360, 360, 360]);
    }

    #[test]
    fn jitter_back_across_the_zero_mark_is_no_jump_forward() {
        // Compensated capsule angles can step back a little, also across the zero mark.
        let mut stream = Vec::new();
        for _ in 0..3 {
            stream.extend((0..360).map(|k| sample(k as f32, false)));
            stream.extend([0.1, 359.9, 0.4, 359.95].map(|a| sample(a, false)));
        }
        stream.push(sample(0.5, false));
        let sizes = sizes(&stream);
        assert_eq!(sizes.len(), 2, "{sizes:?}");
        assert!(sizes.iter().all(|n| (360..=364).contains(n)), "{sizes:?}");
    }

    #[test]
    fn a_close_return_compensated_past_the_zero_mark_does_not_split_its_turn() {
        // 720 samples a turn; in each, the return at 357° is a close one that the (negative)
        // compensation of a triangulation device puts 17.5° ahead, past the zero mark.
        let mut stream = Vec::new();
        for _ in 0..4 {
            stream.extend((0..720).map(|k| {
                let angle = k as f32 * 0.5;
                let angle = if k == 714 {
                    angle + 17.5 - 360.0
                } else {
                    angle
                };
                sample(angle, false)
            }));
        }
        stream.push(sample(0.0, false));
        let sizes = sizes(&stream);
        // The first turn starts at its close return; each later one is one whole turn.
        assert_eq!(sizes, [720, 720, 720], "{sizes:?}");
    }

    #[test]
    fn never_wrapping_angles_are_bounded() {
        let mut a = RotationAssembler::new();
        let mut out = Vec::new();
        a.push(&[sample(10.0, true)], Instant::now(), &mut out);
        let stuck: Vec<Sample> = (0..30_000).map(|_| sample(10.0, false)).collect();
        a.push(&stuck, Instant::now(), &mut out);
        assert!(out.is_empty());
        assert!(a.current.len() < DEFAULT_MAX_SAMPLES);
    }
}
