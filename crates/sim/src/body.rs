//! The person's body: twelve capsules (feet, shins, thighs, torso, head, upper arms,
//! forearms) on a simple skeleton, posed by joint angles. Poses are parametric functions of
//! time for each activity (see [`crate::person`]); there is no numerical integration, so
//! nothing can drift or go unstable.
//!
//! Frames: the person's root frame has x forward, y left, z up, origin on the floor under the
//! standing feet. The trunk frame has its origin at the pelvis and z along the spine.

use glam::{DMat3, DVec2, DVec3};

/// Limb lengths and radii, metres. Lengths follow Drillis and Contini's ratios of stature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyDims {
    pub height: f64,
    pub shin: f64,
    pub thigh: f64,
    pub ankle_height: f64,
    pub foot: f64,
    pub hip_width: f64,
    pub torso: f64,
    pub shoulder_width: f64,
    pub upper_arm: f64,
    pub forearm: f64,
    pub r_foot: f64,
    pub r_shin: f64,
    pub r_thigh: f64,
    pub r_torso: f64,
    pub r_head: f64,
    pub r_upper_arm: f64,
    pub r_forearm: f64,
}

impl BodyDims {
    /// An adult of stature `height` whose limbs are `girth` times as thick as average.
    pub fn new(height: f64, girth: f64) -> Self {
        let h = height;
        Self {
            height: h,
            shin: 0.246 * h,
            thigh: 0.245 * h,
            ankle_height: 0.039 * h,
            foot: 0.12 * h,
            hip_width: 0.10 * h,
            torso: 0.288 * h,
            shoulder_width: 0.20 * h,
            upper_arm: 0.186 * h,
            forearm: 0.20 * h,
            r_foot: 0.035 * girth,
            r_shin: 0.05 * girth,
            r_thigh: 0.075 * girth,
            r_torso: 0.14 * girth,
            r_head: 0.095 * girth,
            r_upper_arm: 0.045 * girth,
            r_forearm: 0.038 * girth,
        }
    }

    /// Hip joint height when standing straight.
    pub fn leg_length(&self) -> f64 {
        self.thigh + self.shin + self.ankle_height
    }
}

/// Joint angles and trunk placement, radians and metres; index 0 is the left side.
/// Every field blends linearly, which is how activities join without jumps.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseParams {
    /// Pelvis position in the root frame (its height comes from floor contact).
    pub pelvis: DVec2,
    /// Trunk lean forward (+) or backward (-) from upright; pi/2 is face down.
    pub pitch: f64,
    /// Trunk lean to the right (+) or left (-).
    pub roll: f64,
    pub hip_flex: [f64; 2],
    pub hip_abduct: [f64; 2],
    pub knee_flex: [f64; 2],
    /// Foot angle from perpendicular to the shin (negative points the toes away).
    pub ankle: [f64; 2],
    pub shoulder_flex: [f64; 2],
    pub shoulder_abduct: [f64; 2],
    pub elbow_flex: [f64; 2],
    /// Height of the lowest point of the body above the floor (flight while running).
    pub lift: f64,
}

fn lerp2(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
}

impl PoseParams {
    pub fn lerp(&self, o: &PoseParams, t: f64) -> PoseParams {
        let l = |a: f64, b: f64| a + (b - a) * t;
        PoseParams {
            pelvis: self.pelvis.lerp(o.pelvis, t),
            pitch: l(self.pitch, o.pitch),
            roll: l(self.roll, o.roll),
            hip_flex: lerp2(self.hip_flex, o.hip_flex, t),
            hip_abduct: lerp2(self.hip_abduct, o.hip_abduct, t),
            knee_flex: lerp2(self.knee_flex, o.knee_flex, t),
            ankle: lerp2(self.ankle, o.ankle, t),
            shoulder_flex: lerp2(self.shoulder_flex, o.shoulder_flex, t),
            shoulder_abduct: lerp2(self.shoulder_abduct, o.shoulder_abduct, t),
            elbow_flex: lerp2(self.elbow_flex, o.elbow_flex, t),
            lift: l(self.lift, o.lift),
        }
    }
}

/// One body part: all points within `radius` of the segment `a`-`b` (world frame, metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capsule {
    pub a: DVec3,
    pub b: DVec3,
    pub radius: f64,
}

impl Capsule {
    /// A circle in the plane `z = h` that contains the capsule's cross-section there, or
    /// `None` when the plane misses the capsule.
    pub fn section_bound(&self, h: f64) -> Option<(DVec2, f64)> {
        let (a, b, r) = (self.a, self.b, self.radius);
        let (lo, hi) = (h - r, h + r);
        // Part of the axis within r of the plane (height-wise).
        let (s0, s1) = if (b.z - a.z).abs() < 1e-12 {
            if a.z < lo || a.z > hi {
                return None;
            }
            (0.0, 1.0)
        } else {
            let sa = (lo - a.z) / (b.z - a.z);
            let sb = (hi - a.z) / (b.z - a.z);
            let (s0, s1) = (sa.min(sb).max(0.0), sa.max(sb).min(1.0));
            if s0 > s1 {
                return None;
            }
            (s0, s1)
        };
        let p0 = a.lerp(b, s0).truncate();
        let p1 = a.lerp(b, s1).truncate();
        Some(((p0 + p1) / 2.0, (p1 - p0).length() / 2.0 + r))
    }
}

/// Number of capsules in a body.
pub const PARTS: usize = 12;

/// Rotation of the trunk frame: lean (pitch about y), then sideways (roll about x).
fn trunk_rotation(pitch: f64, roll: f64) -> DMat3 {
    DMat3::from_rotation_x(roll) * DMat3::from_rotation_y(pitch)
}

/// Direction in the trunk frame of a limb flexed forward by `flex` and out by `abduct`
/// (`side` +1 left, -1 right), starting from pointing down the spine.
fn limb_dir(flex: f64, abduct: f64, side: f64) -> DVec3 {
    let (sa, ca) = abduct.sin_cos();
    DVec3::new(flex.sin() * ca, side * sa, -flex.cos() * ca)
}

/// The capsules of a body in pose `p`, placed at `root` (floor position) facing `yaw`.
pub fn capsules(d: &BodyDims, p: &PoseParams, root: DVec2, yaw: f64) -> [Capsule; PARTS] {
    let rot = trunk_rotation(p.pitch, p.roll);
    let to_root = |v: DVec3| rot * v; // trunk frame -> root frame (before the pelvis offset)
    let mut parts = [Capsule {
        a: DVec3::ZERO,
        b: DVec3::ZERO,
        radius: 0.0,
    }; PARTS];
    let mut k = 0;
    let mut push = |a: DVec3, b: DVec3, radius: f64| {
        parts[k] = Capsule {
            a: to_root(a),
            b: to_root(b),
            radius,
        };
        k += 1;
    };
    for (i, side) in [(0usize, 1.0f64), (1, -1.0)] {
        let hip = DVec3::new(0.0, side * d.hip_width / 2.0, 0.0);
        let knee = hip + limb_dir(p.hip_flex[i], p.hip_abduct[i], side) * d.thigh;
        let shin_angle = p.hip_flex[i] - p.knee_flex[i];
        let ankle =
            knee + limb_dir(shin_angle, p.hip_abduct[i], side) * (d.shin + d.ankle_height * 0.5);
        let foot_angle = shin_angle + p.ankle[i];
        let toe = ankle + DVec3::new(foot_angle.cos(), 0.0, foot_angle.sin()) * d.foot;
        push(hip, knee, d.r_thigh);
        push(knee, ankle, d.r_shin);
        push(ankle, toe, d.r_foot);
        let shoulder = DVec3::new(
            0.0,
            side * d.shoulder_width / 2.0,
            d.torso - 0.03 * d.height,
        );
        let elbow =
            shoulder + limb_dir(p.shoulder_flex[i], p.shoulder_abduct[i], side) * d.upper_arm;
        let hand = elbow
            + limb_dir(
                p.shoulder_flex[i] + p.elbow_flex[i],
                p.shoulder_abduct[i],
                side,
            ) * d.forearm;
        push(shoulder, elbow, d.r_upper_arm);
        push(elbow, hand, d.r_forearm);
    }
    push(
        DVec3::new(0.0, 0.0, 0.06 * d.height),
        DVec3::new(0.0, 0.0, d.torso),
        d.r_torso,
    );
    let neck = d.torso + 0.04 * d.height;
    push(
        DVec3::new(0.0, 0.0, neck),
        DVec3::new(0.0, 0.0, neck + 0.06 * d.height),
        d.r_head,
    );

    // Floor contact: the lowest surface point rests at `lift`.
    let lowest = parts
        .iter()
        .map(|c| c.a.z.min(c.b.z) - c.radius)
        .fold(f64::INFINITY, f64::min);
    let (s, c) = yaw.sin_cos();
    let place = |v: DVec3| {
        let x = v.x + p.pelvis.x;
        let y = v.y + p.pelvis.y;
        DVec3::new(
            root.x + c * x - s * y,
            root.y + s * x + c * y,
            v.z - lowest + p.lift,
        )
    };
    for part in &mut parts {
        part.a = place(part.a);
        part.b = place(part.b);
    }
    parts
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standing_body_has_expected_extent() {
        let d = BodyDims::new(1.75, 1.0);
        let parts = capsules(&d, &PoseParams::default(), DVec2::ZERO, 0.0);
        let top = parts
            .iter()
            .map(|c| c.a.z.max(c.b.z) + c.radius)
            .fold(0.0, f64::max);
        let bottom = parts
            .iter()
            .map(|c| c.a.z.min(c.b.z) - c.radius)
            .fold(9.0, f64::min);
        assert!(bottom.abs() < 1e-12);
        assert!((top - 1.75).abs() < 0.12, "top of head at {top}");
    }

    #[test]
    fn section_bound_covers_section_and_handles_flat_parts() {
        let flat = Capsule {
            a: DVec3::new(0.0, 0.0, 0.1),
            b: DVec3::new(1.0, 0.0, 0.1),
            radius: 0.1,
        };
        let (c, r) = flat.section_bound(0.15).unwrap();
        assert!((c - DVec2::new(0.5, 0.0)).length() < 1e-12 && (r - 0.6).abs() < 1e-12);
        assert!(flat.section_bound(0.21).is_none());
        let upright = Capsule {
            a: DVec3::new(0.0, 0.0, 0.0),
            b: DVec3::new(0.0, 0.0, 1.0),
            radius: 0.05,
        };
        let (c, r) = upright.section_bound(0.5).unwrap();
        assert!(c.length() < 1e-12 && (r - 0.05).abs() < 1e-12);
    }
}
