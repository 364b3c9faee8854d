//! Where the Lidar was when it measured each beam (motion de-skew).
//!
//! A spinning Lidar takes a whole rotation (50-100 ms) to measure one scan. A cleaning robot
//! turning on the spot at 1.5 rad/s turns 0.08-0.15 rad meanwhile, which moves a wall 3 m
//! away by 0.2-0.45 m: more than the margin that tells the room from a person. Placing each
//! beam from its own pose keeps the walls on the map. As in ROS's `laser_geometry`
//! high-fidelity projection, the poses at the first and the last beam are interpolated across
//! the beams: odometry is smooth over one rotation.

use glam::{DAffine2, DMat2, DVec2};

use crate::geometry::{Pose2, normalize_angle};

/// How the Lidar moved over a scan: beam 0 measured from `first`, the last beam from where
/// it had turned and moved to, the beams between from poses in between (shortest turn).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sweep {
    first: Pose2,
    turn_per_beam: f64,
    step_per_beam: DVec2,
}

impl Sweep {
    /// From `first` at beam 0 to `last` at beam `beams - 1`. `first == last`: every beam
    /// from one pose (a scan taken at one instant, or a Lidar that does not move).
    pub fn new(first: Pose2, last: Pose2, beams: usize) -> Self {
        let steps = beams.saturating_sub(1).max(1) as f64;
        Self {
            first,
            turn_per_beam: normalize_angle(last.theta - first.theta) / steps,
            step_per_beam: (last.position() - first.position()) / steps,
        }
    }

    /// The Lidar's pose at beam 0.
    pub fn first(&self) -> Pose2 {
        self.first
    }

    /// How far the Lidar turns from one beam to the next (radians).
    pub fn turn_per_beam(&self) -> f64 {
        self.turn_per_beam
    }

    /// The Lidar's heading when it measured `beam` (fractional beams between).
    pub fn heading_at(&self, beam: f64) -> f64 {
        self.first.theta + self.turn_per_beam * beam
    }

    /// The Lidar's position when it measured `beam`.
    pub fn position_at(&self, beam: f64) -> DVec2 {
        self.first.position() + self.step_per_beam * beam
    }
}

/// The Lidar's pose in the map for each beam of a scan, in beam order.
#[derive(Debug, Clone)]
pub struct BeamPoses {
    sweep: Sweep,
    /// Heading of the next beam as a unit complex number (cos, sin).
    heading: DVec2,
    /// Turn from one beam to the next, as a unit complex number.
    turn: DVec2,
    beam: usize,
    beams: usize,
}

impl BeamPoses {
    /// The poses of `beams` beams swept from `first` to `last` ([`Sweep::new`]).
    pub fn sweep(first: Pose2, last: Pose2, beams: usize) -> Self {
        let sweep = Sweep::new(first, last, beams);
        Self {
            sweep,
            heading: DVec2::from_angle(first.theta),
            turn: DVec2::from_angle(sweep.turn_per_beam),
            beam: 0,
            beams,
        }
    }
}

impl Iterator for BeamPoses {
    /// The Lidar frame -> map transform of the next beam.
    type Item = DAffine2;

    fn next(&mut self) -> Option<DAffine2> {
        if self.beam >= self.beams {
            return None;
        }
        let (c, s) = (self.heading.x, self.heading.y);
        let pose = DAffine2 {
            matrix2: DMat2::from_cols(DVec2::new(c, s), DVec2::new(-s, c)),
            translation: self.sweep.position_at(self.beam as f64),
        };
        // Composing unit complex numbers keeps the heading within 1e-10 rad over 100,000
        // beams, without a sine per beam.
        self.heading = self.heading.rotate(self.turn);
        self.beam += 1;
        Some(pose)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = self.beams - self.beam;
        (left, Some(left))
    }
}

impl ExactSizeIterator for BeamPoses {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_beam_is_placed_from_its_share_of_the_motion() {
        // Half a turn and a metre over 721 beams, across the +-pi seam.
        let first = Pose2::new(1.0, 2.0, 3.0);
        let last = Pose2::new(2.0, 2.0, 3.0 + 0.5 - std::f64::consts::TAU);
        let beams = 721;
        let poses: Vec<_> = BeamPoses::sweep(first, last, beams).collect();
        assert_eq!(poses.len(), beams);
        let point = DVec2::new(3.0, 0.0);
        for (i, pose) in poses.iter().enumerate() {
            let expected = first.lerp(&last, i as f64 / 720.0).transform_point(point);
            let got = pose.transform_point2(point);
            assert!(
                (got - expected).length() < 1e-9,
                "beam {i}: {got} != {expected}"
            );
        }
    }

    #[test]
    fn a_fixed_pose_places_every_beam_alike() {
        let pose = Pose2::new(-1.0, 0.5, -2.0);
        let point = DVec2::new(0.3, -4.0);
        for (i, beam) in BeamPoses::sweep(pose, pose, 100_000).enumerate() {
            let got = beam.transform_point2(point);
            assert!(
                (got - pose.transform_point(point)).length() < 1e-9,
                "beam {i}"
            );
        }
    }

    #[test]
    fn the_heading_stays_exact_over_the_longest_scan() {
        // 100,000 beams (the most a scan may have) and a turn of 1.5 rad.
        let (first, last) = (Pose2::new(0.0, 0.0, -0.7), Pose2::new(0.2, 0.1, 0.8));
        let beams = crate::scan::MAX_BEAMS;
        let point = DVec2::new(10.0, 0.0);
        let (mut count, mut worst) = (0, 0.0f64);
        for (i, pose) in BeamPoses::sweep(first, last, beams).enumerate() {
            let expected = first.lerp(&last, i as f64 / (beams - 1) as f64);
            let error = pose.transform_point2(point) - expected.transform_point(point);
            worst = worst.max(error.length());
            count += 1;
        }
        assert_eq!(count, beams);
        assert!(worst < 1e-9, "{worst} m at 10 m");
    }
}
