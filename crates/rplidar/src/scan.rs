//! Conversion of a [`Rotation`] to a fixed-size laser scan.
//!
//! Frames: RPLIDAR angles grow clockwise seen from above; ROS angles (REP-103) grow
//! counter-clockwise about +z. The ROS angle of a device angle `θ` is `π − θ`, the same
//! convention as Slamtec's `rplidar_ros` (the laser frame's +x points at the device's 180°
//! mark), so URDFs written for that driver fit. Beam `i` is centred on
//! `angle_min + i·angle_increment` with `angle_min = −π + 2π/beams` and `angle_max = π`.
//!
//! Because the device turns clockwise, a higher beam index was measured *earlier*: beam
//! `beams−1` (device angle 0) starts the rotation and beam 0 ends it. The header stamp is
//! the time of beam 0 as ROS asks ("acquisition time of the first ray") and
//! `time_increment` is negative, `−scan_time/beams`, so `stamp + i·time_increment` is the
//! time of beam `i`.
//!
//! Every scan has the same number of beams. A beam without a valid return is `+inf`, or
//! `-inf` when its only returns were closer than `range_min` (REP 117: too close to
//! measure, so that consumers do not take it for free space); when several valid samples
//! fall into one beam the nearest wins (the conservative choice for a safety sensor).
//! `intensities` are the sample quality on `rplidar_ros`'s scale, 0..=63.

use std::f32::consts::PI;

use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;

use crate::config::{ConfigField, invalid};
use crate::error::Result;
use crate::rotation::Rotation;

/// Fixed geometry of the scans produced.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanGeometry {
    pub beams: usize,
    pub range_min_m: f32,
    pub range_max_m: f32,
}

impl ScanGeometry {
    pub fn validate(&self) -> Result<()> {
        if !(2..=100_000).contains(&self.beams) {
            return Err(invalid(
                ConfigField::Beams,
                format!("beams = {} must be in 2..=100000", self.beams),
            ));
        }
        if !(self.range_min_m.is_finite() && self.range_min_m >= 0.0) {
            return Err(invalid(
                ConfigField::RangeMin,
                format!("range_min = {} m must be finite and >= 0", self.range_min_m),
            ));
        }
        if !(self.range_max_m.is_finite() && self.range_max_m > self.range_min_m) {
            return Err(invalid(
                ConfigField::RangeMax,
                format!(
                    "range_max = {} m must be finite and above range_min = {} m",
                    self.range_max_m, self.range_min_m
                ),
            ));
        }
        Ok(())
    }

    pub fn angle_increment(&self) -> f32 {
        2.0 * PI / self.beams as f32
    }

    pub fn angle_min(&self) -> f32 {
        -PI + self.angle_increment()
    }

    /// Beam index of a device angle in degrees.
    pub fn beam_of(&self, device_angle_deg: f32) -> usize {
        let ros = PI - device_angle_deg.to_radians();
        let index = ((ros - self.angle_min()) / self.angle_increment()).round() as i64;
        index.rem_euclid(self.beams as i64) as usize
    }

    /// Device angle in degrees at the centre of a beam.
    pub fn device_angle_of(&self, beam: usize) -> f32 {
        let ros = self.angle_min() + beam as f32 * self.angle_increment();
        (PI - ros).to_degrees().rem_euclid(360.0)
    }
}

/// One scan, independent of any message type.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanFrame {
    /// Time of beam 0 in nanoseconds of the caller's clock.
    pub stamp_ns: i64,
    pub angle_min: f32,
    pub angle_max: f32,
    pub angle_increment: f32,
    /// Negative: see the module documentation.
    pub time_increment: f32,
    /// Measured rotation period in seconds.
    pub scan_time: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: Vec<f32>,
    /// Sample quality >> 2, 0..=63 as `rplidar_ros` publishes it (0 where no return).
    pub intensities: Vec<f32>,
    /// Samples the device delivered in this rotation (whatever the beam count).
    pub samples_in_rotation: usize,
    /// Beams with a valid return.
    pub valid_beams: usize,
}

impl ScanFrame {
    /// Builds a scan from a rotation; `start_ns` is the caller-clock time of the rotation's
    /// first sample.
    pub fn from_rotation(rotation: &Rotation, start_ns: i64, geometry: &ScanGeometry) -> Self {
        let beams = geometry.beams;
        let mut ranges = vec![f32::INFINITY; beams];
        let mut intensities = vec![0.0f32; beams];
        for s in &rotation.samples {
            let r = s.distance_mm / 1000.0;
            // Distance 0 is the device's "no return"; beyond range_max the beam stays +inf.
            if !(r > 0.0 && r <= geometry.range_max_m) {
                continue;
            }
            let beam = geometry.beam_of(s.angle_deg);
            if r < geometry.range_min_m {
                // Something too close to measure, unless the beam has a valid return.
                if ranges[beam] == f32::INFINITY {
                    ranges[beam] = f32::NEG_INFINITY;
                }
            } else if !ranges[beam].is_finite() || r < ranges[beam] {
                ranges[beam] = r;
                // rplidar_ros's scale (quality >> 2), so thresholds tuned on it carry over.
                intensities[beam] = f32::from(s.quality >> 2);
            }
        }
        let scan_time = rotation.period_s() as f32;
        let time_increment = -scan_time / beams as f32;
        let beam0_offset_ns =
            (rotation.period_s() * (beams - 1) as f64 / beams as f64 * 1e9) as i64;
        Self {
            stamp_ns: start_ns.saturating_add(beam0_offset_ns),
            angle_min: geometry.angle_min(),
            angle_max: PI,
            angle_increment: geometry.angle_increment(),
            time_increment,
            scan_time,
            range_min: geometry.range_min_m,
            range_max: geometry.range_max_m,
            valid_beams: ranges.iter().filter(|r| r.is_finite()).count(),
            ranges,
            intensities,
            samples_in_rotation: rotation.samples.len(),
        }
    }

    /// The ROS message of this scan in `frame_id`.
    pub fn to_laser_scan(&self, frame_id: &str) -> LaserScan {
        LaserScan {
            header: Header {
                stamp: Time::from_nanos(self.stamp_ns),
                frame_id: frame_id.to_owned(),
            },
            angle_min: self.angle_min,
            angle_max: self.angle_max,
            angle_increment: self.angle_increment,
            time_increment: self.time_increment,
            scan_time: self.scan_time,
            range_min: self.range_min,
            range_max: self.range_max,
            ranges: self.ranges.clone(),
            intensities: self.intensities.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::RotationSample;
    use std::time::{Duration, Instant};

    fn geometry(beams: usize) -> ScanGeometry {
        ScanGeometry {
            beams,
            range_min_m: 0.15,
            range_max_m: 12.0,
        }
    }

    #[test]
    fn beam_mapping_turns_clockwise_into_counter_clockwise() {
        let g = geometry(720);
        // Device 0 deg is ROS +pi: the last beam.
        assert_eq!(g.beam_of(0.0), 719);
        // Device 90 deg clockwise is ROS +pi/2 (left of the laser frame's +x).
        let b = g.beam_of(90.0);
        let ros = g.angle_min() + b as f32 * g.angle_increment();
        assert!((ros - PI / 2.0).abs() < 1e-4, "{ros}");
        // Device 180 deg is ROS 0.
        let b = g.beam_of(180.0);
        assert!((g.angle_min() + b as f32 * g.angle_increment()).abs() < 1e-4);
        for beam in [0, 1, 359, 718, 719] {
            assert_eq!(g.beam_of(g.device_angle_of(beam)), beam);
        }
        assert!((g.angle_min() + 719.0 * g.angle_increment() - PI).abs() < 1e-5);
    }

    #[test]
    fn fixed_beam_count_with_inf_for_missing_and_nearest_wins() {
        let g = geometry(360);
        let t = Instant::now();
        let samples = vec![
            RotationSample {
                angle_deg: 10.0,
                distance_mm: 2000.0,
                quality: 50,
            },
            RotationSample {
                angle_deg: 10.2,
                distance_mm: 1500.0,
                quality: 60,
            },
            RotationSample {
                angle_deg: 20.0,
                distance_mm: 0.0,
                quality: 0,
            },
            RotationSample {
                angle_deg: 30.0,
                distance_mm: 50.0,
                quality: 10,
            },
            RotationSample {
                angle_deg: 40.0,
                distance_mm: 20000.0,
                quality: 10,
            },
        ];
        let rotation = Rotation {
            samples,
            started: t,
            ended: t + Duration::from_millis(100),
        };
        let f = ScanFrame::from_rotation(&rotation, 1_000_000_000, &g);
        assert_eq!(f.ranges.len(), 360);
        assert_eq!(f.intensities.len(), 360);
        assert_eq!(f.valid_beams, 1);
        assert_eq!(f.ranges[g.beam_of(10.0)], 1.5);
        // rplidar_ros's scale: quality >> 2.
        assert_eq!(f.intensities[g.beam_of(10.0)], 15.0);
        // No return (distance 0) and beyond range_max: +inf; closer than range_min: -inf.
        assert_eq!(f.ranges[g.beam_of(20.0)], f32::INFINITY);
        assert_eq!(f.ranges[g.beam_of(30.0)], f32::NEG_INFINITY);
        assert_eq!(f.intensities[g.beam_of(30.0)], 0.0);
        assert_eq!(f.ranges[g.beam_of(40.0)], f32::INFINITY);
        assert!((f.scan_time - 0.1).abs() < 1e-6);
        assert!((f.time_increment + 0.1 / 360.0).abs() < 1e-9);
        // Beam 0 is measured last, just before the rotation ends.
        assert_eq!(f.stamp_ns, 1_000_000_000 + 100_000_000 * 359 / 360);
        let msg = f.to_laser_scan("laser");
        assert_eq!(msg.header.frame_id, "laser");
        assert_eq!(msg.ranges.len(), 360);
    }

    #[test]
    fn a_valid_return_beats_one_too_close_to_measure_in_either_order() {
        let g = geometry(360);
        let t = Instant::now();
        let sample = |angle_deg: f32, distance_mm: f32| RotationSample {
            angle_deg,
            distance_mm,
            quality: 188,
        };
        let rotation = Rotation {
            samples: vec![
                // Too close, then valid; valid, then too close; only too close.
                sample(10.0, 100.0),
                sample(10.2, 800.0),
                sample(20.0, 900.0),
                sample(20.2, 100.0),
                sample(30.0, 100.0),
                sample(30.2, 120.0),
            ],
            started: t,
            ended: t + Duration::from_millis(100),
        };
        let f = ScanFrame::from_rotation(&rotation, 0, &g);
        assert_eq!(f.ranges[g.beam_of(10.0)], 0.8);
        assert_eq!(f.ranges[g.beam_of(20.0)], 0.9);
        assert_eq!(f.ranges[g.beam_of(30.0)], f32::NEG_INFINITY);
        assert_eq!(f.valid_beams, 2);
        // A capsule sample's quality 188 is rplidar_ros's 47.
        assert_eq!(f.intensities[g.beam_of(10.0)], 47.0);
        assert_eq!(f.intensities[g.beam_of(30.0)], 0.0);
    }

    #[test]
    fn empty_rotation_gives_all_inf() {
        let t = Instant::now();
        let rotation = Rotation {
            samples: vec![],
            started: t,
            ended: t,
        };
        let f = ScanFrame::from_rotation(&rotation, 0, &geometry(720));
        assert_eq!(f.ranges.len(), 720);
        assert!(f.ranges.iter().all(|r| *r == f32::INFINITY));
        assert_eq!(f.scan_time, 0.0);
    }

    #[test]
    fn geometry_validation_names_the_problem() {
        assert!(geometry(720).validate().is_ok());
        let e = geometry(1).validate().unwrap_err().to_string();
        assert!(e.contains("beams"), "{e}");
        let e = ScanGeometry {
            beams: 720,
            range_min_m: 1.0,
            range_max_m: 0.5,
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("range_max"), "{e}");
        let e = ScanGeometry {
            beams: 720,
            range_min_m: f32::NAN,
            range_max_m: 5.0,
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("range_min"), "{e}");
    }
}
