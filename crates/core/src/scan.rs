//! One 2D Lidar rotation as plain data, and its points in the Lidar's own frame.
//!
//! The fields mirror `sensor_msgs/LaserScan` (without header and intensities) so a host can
//! convert a message without loss; everything here tolerates the bad values real sensors
//! produce (`NaN`, `inf`, ranges outside the valid interval).

use glam::DVec2;

/// A scan: beam `i` points at `angle_min + i * angle_increment` (radians, counter-clockwise
/// from the Lidar's +x axis) and measured `ranges[i]` metres.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Scan {
    /// Acquisition time of beam 0, nanoseconds (any epoch, monotonic per source).
    pub stamp_ns: i64,
    pub angle_min: f32,
    pub angle_increment: f32,
    /// Seconds from one beam's measurement to the next's: beam `i` was measured at
    /// `stamp + i * time_increment`. Negative when beam 0 is measured last (the RPLIDAR
    /// driver); 0 for a scan taken at one instant.
    pub time_increment: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: Vec<f32>,
}

/// Why a scan's geometry cannot be used at all (its ranges may still be fine).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScanError {
    #[error("scan angle_min {0} is not finite")]
    AngleMin(f32),
    #[error(
        "scan angle_increment {0} is not a finite angle of at least {MIN_ANGLE_INCREMENT} rad \
         (a full turn of at most {MAX_BEAMS} beams)"
    )]
    AngleIncrement(f32),
    #[error(
        "scan angle_increment {increment} rad spreads its {beams} beams over more than one turn \
         (at most {MAX_SPAN_RAD} rad from the first beam to the last)"
    )]
    AngleSpan { increment: f32, beams: usize },
    #[error(
        "scan range interval [{min}, {max}] is not a finite interval with min >= 0 and max > min"
    )]
    RangeInterval { min: f32, max: f32 },
    #[error("scan has {0} beams, more than the {MAX_BEAMS} a 2D Lidar can produce")]
    TooManyBeams(usize),
}

/// More beams than any 2D Lidar delivers per rotation: a scan this long is garbage.
pub const MAX_BEAMS: usize = 100_000;

/// The finest beam spacing accepted (radians): a full turn of `MAX_BEAMS` beams. A finer one
/// is garbage too, and walking the beams across an angle (the shadow search) would take
/// billions of steps.
pub const MIN_ANGLE_INCREMENT: f32 = std::f32::consts::TAU / MAX_BEAMS as f32;

/// The widest angle from a scan's first beam to its last (radians): one turn, and a little
/// more for drivers whose increment is rounded, or that repeat a beam or two past the seam.
/// A scan spread wider has a garbled `angle_increment` (`1e30`, or 7 rad): its beams land at
/// bearings that are pseudo-random once reduced to a turn, and would seed false tracks.
pub const MAX_SPAN_RAD: f32 = std::f32::consts::TAU + 0.05;

/// The longest rotation a 2D Lidar takes (the slowest spin at 1 Hz): a scan whose beams
/// are spread over more time has a garbled `time_increment`.
pub const MAX_SWEEP_S: f64 = 1.0;

/// A usable beam: its index in `ranges`, its range and its point in the Lidar frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanPoint {
    pub beam: usize,
    pub range: f64,
    pub point: DVec2,
}

impl Scan {
    /// Checks the fields that every point depends on.
    pub fn validate(&self) -> Result<(), ScanError> {
        if !self.angle_min.is_finite() {
            return Err(ScanError::AngleMin(self.angle_min));
        }
        if !(self.angle_increment.is_finite() && self.angle_increment.abs() >= MIN_ANGLE_INCREMENT)
        {
            return Err(ScanError::AngleIncrement(self.angle_increment));
        }
        // A single beam still needs an increment of at most a turn; in f64, so no product
        // overflows.
        let gaps = self.ranges.len().saturating_sub(1).max(1);
        if f64::from(self.angle_increment.abs()) * gaps as f64 > f64::from(MAX_SPAN_RAD) {
            return Err(ScanError::AngleSpan {
                increment: self.angle_increment,
                beams: self.ranges.len(),
            });
        }
        let (min, max) = (self.range_min, self.range_max);
        if !(min.is_finite() && max.is_finite() && min >= 0.0 && max > min) {
            return Err(ScanError::RangeInterval { min, max });
        }
        if self.ranges.len() > MAX_BEAMS {
            return Err(ScanError::TooManyBeams(self.ranges.len()));
        }
        Ok(())
    }

    /// The direction of beam `beam` (radians, Lidar frame).
    pub fn beam_angle(&self, beam: usize) -> f64 {
        f64::from(self.angle_min) + beam as f64 * f64::from(self.angle_increment)
    }

    /// Whether `range` is a return: finite, above 0 and inside `[range_min, range_max]`. A
    /// range of exactly 0 is "no return" whatever `range_min` says: drivers that publish
    /// `range_min` 0 encode a missing return as 0, which would put a cluster on the Lidar.
    pub fn is_return(&self, range: f32) -> bool {
        range.is_finite() && range > 0.0 && range >= self.range_min && range <= self.range_max
    }

    /// Nanoseconds from beam 0's measurement to the last beam's (negative when beam 0 is
    /// measured last), or `None` when `time_increment` is not finite or spreads the beams
    /// over more than [`MAX_SWEEP_S`].
    pub fn sweep_ns(&self) -> Option<i64> {
        if self.ranges.len() < 2 {
            return Some(0);
        }
        let sweep_s = f64::from(self.time_increment) * (self.ranges.len() - 1) as f64;
        (sweep_s.is_finite() && sweep_s.abs() <= MAX_SWEEP_S)
            .then(|| (sweep_s * 1e9).round() as i64)
    }

    /// Number of ranges that are `NaN` or infinite (no return, or a sensor fault).
    pub fn non_finite_count(&self) -> usize {
        self.ranges.iter().filter(|r| !r.is_finite()).count()
    }

    /// The returns as points in the Lidar frame, skipping non-finite and out-of-range beams.
    pub fn points(&self) -> impl Iterator<Item = ScanPoint> + '_ {
        self.ranges
            .iter()
            .enumerate()
            .filter(|(_, r)| self.is_return(**r))
            .map(|(beam, &r)| {
                let (s, c) = self.beam_angle(beam).sin_cos();
                let range = f64::from(r);
                ScanPoint {
                    beam,
                    range,
                    point: DVec2::new(range * c, range * s),
                }
            })
    }
}

/// The unit direction of every beam of a scan geometry, cached so the localiser does not
/// evaluate `sin_cos` per beam per scan (a sizeable part of a 50 µs budget).
#[derive(Debug, Clone, Default)]
pub struct BeamDirections {
    key: (u32, u32, usize),
    directions: Vec<DVec2>,
}

impl BeamDirections {
    /// The directions for `scan`'s geometry, recomputed only when the geometry changes.
    pub fn for_scan(&mut self, scan: &Scan) -> &[DVec2] {
        let key = (
            scan.angle_min.to_bits(),
            scan.angle_increment.to_bits(),
            scan.ranges.len(),
        );
        if key != self.key || self.directions.len() != scan.ranges.len() {
            self.key = key;
            self.directions.clear();
            self.directions.extend((0..scan.ranges.len()).map(|beam| {
                let (s, c) = scan.beam_angle(beam).sin_cos();
                DVec2::new(c, s)
            }));
        }
        &self.directions
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::FRAC_PI_2;

    fn scan(ranges: Vec<f32>) -> Scan {
        Scan {
            stamp_ns: 0,
            angle_min: -FRAC_PI_2,
            angle_increment: FRAC_PI_2,
            time_increment: 0.0,
            range_min: 0.1,
            range_max: 10.0,
            ranges,
        }
    }

    #[test]
    fn points_lie_along_their_beams() {
        let s = scan(vec![1.0, 2.0, 3.0]);
        let pts: Vec<_> = s.points().collect();
        assert_eq!(pts.len(), 3);
        assert!((pts[0].point - DVec2::new(0.0, -1.0)).length() < 1e-6);
        assert!((pts[1].point - DVec2::new(2.0, 0.0)).length() < 1e-6);
        assert!((pts[2].point - DVec2::new(0.0, 3.0)).length() < 1e-6);
    }

    #[test]
    fn bad_ranges_are_skipped() {
        let s = scan(vec![
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.05,
            11.0,
            5.0,
        ]);
        let pts: Vec<_> = s.points().collect();
        assert_eq!(pts.len(), 1);
        assert_eq!(pts[0].beam, 5);
        assert_eq!(s.non_finite_count(), 3);
    }

    #[test]
    fn the_sweep_spans_from_beam_zero_to_the_last_beam() {
        let mut s = scan(vec![1.0; 721]);
        assert_eq!(s.sweep_ns(), Some(0));
        // time_increment is an f32: exact to a few nanoseconds.
        let near =
            |got: Option<i64>, expected: i64| got.is_some_and(|ns| (ns - expected).abs() < 10);
        s.time_increment = 0.1 / 720.0;
        assert!(near(s.sweep_ns(), 100_000_000), "{:?}", s.sweep_ns());
        // The RPLIDAR's beam 0 ends the rotation.
        s.time_increment = -0.1 / 720.0;
        assert!(near(s.sweep_ns(), -100_000_000), "{:?}", s.sweep_ns());
        for garbled in [f32::NAN, f32::INFINITY, 0.01] {
            s.time_increment = garbled;
            assert_eq!(s.sweep_ns(), None, "{garbled}");
        }
        assert_eq!(scan(vec![]).sweep_ns(), Some(0));
        // One beam sweeps nothing, whatever its increment says.
        let mut one = scan(vec![1.0]);
        one.time_increment = f32::NAN;
        assert_eq!(one.sweep_ns(), Some(0));
    }

    #[test]
    fn empty_scan_has_no_points_and_is_valid() {
        let s = scan(vec![]);
        assert_eq!(s.points().count(), 0);
        assert!(s.validate().is_ok());
    }

    #[test]
    fn broken_geometry_is_rejected() {
        let mut s = scan(vec![1.0]);
        s.angle_increment = f32::NAN;
        assert!(matches!(s.validate(), Err(ScanError::AngleIncrement(_))));
        s.angle_increment = 0.0;
        assert!(matches!(s.validate(), Err(ScanError::AngleIncrement(_))));
        s.angle_increment = -1e-10;
        assert!(matches!(s.validate(), Err(ScanError::AngleIncrement(_))));
        // The finest real Lidars (about 0.1 degree) and a clockwise one pass.
        s.angle_increment = -0.0017;
        assert!(s.validate().is_ok());
        let mut s = scan(vec![1.0]);
        s.range_max = f32::INFINITY;
        assert!(matches!(s.validate(), Err(ScanError::RangeInterval { .. })));
        let mut s = scan(vec![1.0]);
        s.angle_min = f32::NAN;
        assert!(matches!(s.validate(), Err(ScanError::AngleMin(_))));
    }

    #[test]
    fn an_increment_spreading_the_beams_over_more_than_a_turn_is_rejected() {
        let mut s = scan(vec![1.0; 720]);
        for garbled in [1e30, f32::MAX, -f32::MAX, 3.0e38, 7.0, 0.01] {
            s.angle_increment = garbled;
            let err = s.validate().unwrap_err();
            assert_eq!(
                err,
                ScanError::AngleSpan {
                    increment: garbled,
                    beams: 720
                }
            );
            let message = err.to_string();
            assert!(
                message.contains("angle_increment") && message.contains(&garbled.to_string()),
                "{message}"
            );
        }
        // One beam: its increment may still not exceed a turn.
        let mut one = scan(vec![1.0]);
        one.angle_increment = 7.0;
        assert!(matches!(one.validate(), Err(ScanError::AngleSpan { .. })));
        // A full turn either way, with the last beam on the first's bearing or one short of
        // it, and a 270-degree Lidar, pass.
        for (beams, increment) in [
            (720, std::f32::consts::TAU / 720.0),
            (720, -std::f32::consts::TAU / 719.0),
            (1081, 0.25f32.to_radians()),
        ] {
            let mut s = scan(vec![1.0; beams]);
            s.angle_increment = increment;
            assert_eq!(s.validate(), Ok(()), "{beams} beams of {increment}");
        }
    }

    #[test]
    fn a_range_of_zero_is_no_return_even_with_range_min_zero() {
        // Drivers publishing range_min 0 encode "no return" as 0.
        let mut s = scan(vec![0.0, 2.0, -0.0, 1e-3]);
        s.range_min = 0.0;
        assert!(!s.is_return(0.0) && !s.is_return(-0.0));
        let beams: Vec<usize> = s.points().map(|p| p.beam).collect();
        assert_eq!(beams, [1, 3]);
    }

    #[test]
    fn beam_directions_follow_geometry_changes() {
        let mut cache = BeamDirections::default();
        let a = scan(vec![1.0; 3]);
        assert_eq!(cache.for_scan(&a).len(), 3);
        let mut b = scan(vec![1.0; 5]);
        b.angle_min = 0.0;
        let dirs = cache.for_scan(&b).to_vec();
        assert_eq!(dirs.len(), 5);
        assert!((dirs[0] - DVec2::X).length() < 1e-12);
    }
}
