//! Planar geometry shared by the simulator and the localiser (f64, metres and radians, REP-103).

use glam::DVec2;
use serde::{Deserialize, Serialize};

/// A pose in the plane: position and heading (counter-clockwise from +x).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Pose2 {
    pub const IDENTITY: Pose2 = Pose2 {
        x: 0.0,
        y: 0.0,
        theta: 0.0,
    };

    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }

    pub fn position(&self) -> DVec2 {
        DVec2::new(self.x, self.y)
    }

    /// Maps a point from this pose's frame into the parent frame.
    pub fn transform_point(&self, p: DVec2) -> DVec2 {
        let (s, c) = self.theta.sin_cos();
        DVec2::new(self.x + c * p.x - s * p.y, self.y + s * p.x + c * p.y)
    }

    /// `self ∘ other`: `other` expressed in `self`'s frame, moved to the parent frame.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let p = self.transform_point(other.position());
        Pose2::new(p.x, p.y, normalize_angle(self.theta + other.theta))
    }

    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            -(c * self.x + s * self.y),
            s * self.x - c * self.y,
            normalize_angle(-self.theta),
        )
    }

    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }

    /// Linear interpolation of position and shortest-arc interpolation of heading, `t` in [0, 1].
    pub fn lerp(&self, other: &Pose2, t: f64) -> Pose2 {
        let dtheta = normalize_angle(other.theta - self.theta);
        Pose2::new(
            self.x + (other.x - self.x) * t,
            self.y + (other.y - self.y) * t,
            normalize_angle(self.theta + dtheta * t),
        )
    }
}

/// How a set of points stretches along its main axis (the direction of largest scatter): a
/// person's outline at ankle height is two legs, under 0.8 m across, while a body on the
/// floor stretches well over a metre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MainAxisSpan {
    pub mean: DVec2,
    /// Unit vector along the main axis.
    pub axis: DVec2,
    /// Smallest and largest offset of a point from `mean` along `axis`.
    pub lo: f64,
    pub hi: f64,
}

impl MainAxisSpan {
    /// `None` for fewer than two points.
    pub fn of(points: &[DVec2]) -> Option<Self> {
        if points.len() < 2 {
            return None;
        }
        let mean = points.iter().copied().sum::<DVec2>() / points.len() as f64;
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for p in points {
            let d = *p - mean;
            (sxx, sxy, syy) = (sxx + d.x * d.x, sxy + d.x * d.y, syy + d.y * d.y);
        }
        // The eigenvector of the scatter's larger eigenvalue.
        let axis = DVec2::from_angle(0.5 * (2.0 * sxy).atan2(sxx - syy));
        let (lo, hi) = points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                let t = (*p - mean).dot(axis);
                (lo.min(t), hi.max(t))
            });
        Some(Self { mean, axis, lo, hi })
    }

    pub fn length(&self) -> f64 {
        self.hi - self.lo
    }

    /// The middle of the stretch.
    pub fn midpoint(&self) -> DVec2 {
        self.mean + self.axis * (0.5 * (self.lo + self.hi))
    }
}

/// Wraps an angle into (-pi, pi].
pub fn normalize_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r <= -PI { r + TAU } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_with_inverse_is_identity() {
        let p = Pose2::new(1.5, -2.0, 2.8);
        let id = p.compose(&p.inverse());
        assert!(id.x.abs() < 1e-12 && id.y.abs() < 1e-12 && id.theta.abs() < 1e-12);
    }

    #[test]
    fn a_line_of_points_spans_its_length_along_its_direction() {
        let dir = DVec2::from_angle(0.7);
        let points: Vec<DVec2> = (0..=10)
            .map(|i| DVec2::new(2.0, -1.0) + dir * (0.15 * i as f64))
            .collect();
        let span = MainAxisSpan::of(&points).unwrap();
        assert!((span.length() - 1.5).abs() < 1e-9, "{span:?}");
        assert!(span.axis.dot(dir).abs() > 1.0 - 1e-9, "{span:?}");
        let middle = DVec2::new(2.0, -1.0) + dir * 0.75;
        assert!(span.midpoint().distance(middle) < 1e-9, "{span:?}");
        assert_eq!(MainAxisSpan::of(&points[..1]), None);
    }

    #[test]
    fn angles_wrap_into_half_open_interval() {
        use std::f64::consts::PI;
        assert!((normalize_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((normalize_angle(-PI) - PI).abs() < 1e-12);
        assert!(normalize_angle(0.1).abs() - 0.1 < 1e-15);
    }
}
