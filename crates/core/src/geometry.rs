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
    fn angles_wrap_into_half_open_interval() {
        use std::f64::consts::PI;
        assert!((normalize_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((normalize_angle(-PI) - PI).abs() < 1e-12);
        assert!(normalize_angle(0.1).abs() - 0.1 < 1e-15);
    }
}
