//! Assembly of decoded samples into full rotations, stamped with the host's arrival times.
//!
//! A rotation starts at a sample with the start flag, or where the angle jumps back by
//! more than half a turn (a start flag lost to corruption). A start that comes less than
//! half a turn after the previous one is ignored, so a flag and a wrap a few samples apart
//! do not make a one-sample rotation. Samples before the first start are dropped: a scan
//! starts mid-rotation.

use std::time::Instant;

use crate::decode::Sample;

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
    /// Arrival of the bytes holding this rotation's first sample.
    pub started: Instant,
    /// Arrival of the bytes holding the next rotation's first sample: `ended - started` is
    /// the measured rotation period.
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
    last_angle: Option<f32>,
    swept_deg: f32,
    max_samples: usize,
    discarded: u64,
}

/// Far more samples than any device delivers per turn (S3 at its slowest: ~32 kHz / 5 Hz).
const DEFAULT_MAX_SAMPLES: usize = 20_000;

impl Default for RotationAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl RotationAssembler {
    pub fn new() -> Self {
        Self {
            current: Vec::with_capacity(2048),
            started: None,
            last_angle: None,
            swept_deg: 0.0,
            max_samples: DEFAULT_MAX_SAMPLES,
            discarded: 0,
        }
    }

    /// Samples dropped because they came before the first start or made a "rotation" that
    /// never wrapped.
    pub fn discarded(&self) -> u64 {
        self.discarded
    }

    /// Forgets the rotation in progress (after a restart of the scan).
    pub fn reset(&mut self) {
        self.discarded += self.current.len() as u64;
        self.current.clear();
        self.started = None;
        self.last_angle = None;
        self.swept_deg = 0.0;
    }

    /// Adds samples that arrived at `arrival`; completed rotations are appended to `out`.
    pub fn push(&mut self, samples: &[Sample], arrival: Instant, out: &mut Vec<Rotation>) {
        for s in samples {
            let wrapped = self
                .last_angle
                .is_some_and(|last| last - s.angle_deg > 180.0);
            if let Some(last) = self.last_angle {
                let delta = (s.angle_deg - last).rem_euclid(360.0);
                if delta < 180.0 {
                    self.swept_deg += delta;
                }
            }
            self.last_angle = Some(s.angle_deg);
            let trigger = s.start_of_rotation || wrapped;
            if trigger && (self.started.is_none() || self.swept_deg >= 180.0) {
                if let Some(started) = self.started {
                    let capacity = self.current.capacity();
                    let samples =
                        std::mem::replace(&mut self.current, Vec::with_capacity(capacity));
                    out.push(Rotation {
                        samples,
                        started,
                        ended: arrival,
                    });
                }
                self.started = Some(arrival);
                self.swept_deg = 0.0;
            }
            if self.started.is_none() {
                self.discarded += 1;
                continue;
            }
            if self.current.len() >= self.max_samples {
                // The angle never wrapped: no motor, or nonsense angles. Start over.
                self.reset();
                continue;
            }
            self.current.push(RotationSample {
                angle_deg: s.angle_deg,
                distance_mm: s.distance_mm,
                quality: s.quality,
            });
        }
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
