//! `geometry_msgs`: points, vectors, poses, twists and transforms (SI units: m, rad, m/s, rad/s).

use serde::{Deserialize, Serialize};
use serde_big_array::BigArray;

use crate::ros_message;
use crate::std_msgs::Header;

/// `geometry_msgs/msg/Point`: a position, m.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}
ros_message!(
    Point,
    "geometry_msgs/msg/Point",
    "float64 x\nfloat64 y\nfloat64 z\n",
    [],
    "RIHS01_6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881"
);

impl Point {
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Self { x, y, z }
    }
}

/// `geometry_msgs/msg/Point32`: a position in single precision, m (point clouds).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point32 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}
ros_message!(
    Point32,
    "geometry_msgs/msg/Point32",
    "float32 x\nfloat32 y\nfloat32 z\n",
    [],
    "RIHS01_2fc4db7cae16a4582c79a56b66173a8d48d52c7dc520ddc55a0d4bcf2a4bfdbc"
);

impl Point32 {
    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }
}

/// `geometry_msgs/msg/Quaternion`: an orientation. As in ROS 2, the default is the
/// identity (`w = 1`), not all zeros.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}
ros_message!(
    Quaternion,
    "geometry_msgs/msg/Quaternion",
    "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    [],
    "RIHS01_8a765f66778c8ff7c8ab94afcc590a2ed5325a1d9a076ffff38fbce36f458684"
);

impl Default for Quaternion {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Quaternion {
    /// No rotation.
    pub const IDENTITY: Self = Self {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    /// A rotation of `yaw` rad about +z (counter-clockwise seen from above, REP-103).
    pub fn from_yaw(yaw: f64) -> Self {
        let (sin, cos) = (yaw * 0.5).sin_cos();
        Self {
            x: 0.0,
            y: 0.0,
            z: sin,
            w: cos,
        }
    }

    /// The heading about +z, rad in [-pi, pi], of this rotation (its yaw in the ZYX
    /// convention); the quaternion need not be normalised. NaN components give NaN.
    pub fn yaw(&self) -> f64 {
        let Self { x, y, z, w } = *self;
        (2.0 * (w * z + x * y)).atan2(w * w + x * x - y * y - z * z)
    }
}

/// `geometry_msgs/msg/Vector3`: a direction and magnitude (m, m/s, rad/s, ... by context).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}
ros_message!(
    Vector3,
    "geometry_msgs/msg/Vector3",
    "float64 x\nfloat64 y\nfloat64 z\n",
    [],
    "RIHS01_cc12fe83e4c02719f1ce8070bfd14aecd40f75a96696a67a2a1f37f7dbb0765d"
);

impl Vector3 {
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Self { x, y, z }
    }
}

/// `geometry_msgs/msg/Pose`: a position and an orientation.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}
ros_message!(
    Pose,
    "geometry_msgs/msg/Pose",
    "Point position\nQuaternion orientation\n",
    [Point, Quaternion],
    "RIHS01_d501954e9476cea2996984e812054b68026ae0bfae789d9a10b23daf35cc90fa"
);

impl Pose {
    /// A planar pose: (`x`, `y`) m on the ground, heading `yaw` rad.
    pub fn from_xy_yaw(x: f64, y: f64, yaw: f64) -> Self {
        Self {
            position: Point::new(x, y, 0.0),
            orientation: Quaternion::from_yaw(yaw),
        }
    }
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}
ros_message!(
    PoseStamped,
    "geometry_msgs/msg/PoseStamped",
    "std_msgs/Header header\nPose pose\n",
    [Header, Pose],
    "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"
);

/// `geometry_msgs/msg/PoseWithCovariance`: a pose with the row-major 6x6 covariance of
/// (x, y, z, rotation about X, about Y, about Z), m^2 / rad^2.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}
ros_message!(
    PoseWithCovariance,
    "geometry_msgs/msg/PoseWithCovariance",
    "Pose pose\nfloat64[36] covariance\n",
    [Pose],
    "RIHS01_9a7c0fd234b7f45c6098745ecccd773ca1085670e64107135397aee31c02e1bb"
);

impl Default for PoseWithCovariance {
    fn default() -> Self {
        Self {
            pose: Pose::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `geometry_msgs/msg/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}
ros_message!(
    PoseWithCovarianceStamped,
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "std_msgs/Header header\nPoseWithCovariance pose\n",
    [Header, PoseWithCovariance],
    "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e"
);

/// `geometry_msgs/msg/Twist`: linear (m/s) and angular (rad/s) velocity.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}
ros_message!(
    Twist,
    "geometry_msgs/msg/Twist",
    "Vector3 linear\nVector3 angular\n",
    [Vector3],
    "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
);

/// `geometry_msgs/msg/TwistWithCovariance`: a twist with its row-major 6x6 covariance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}
ros_message!(
    TwistWithCovariance,
    "geometry_msgs/msg/TwistWithCovariance",
    "Twist twist\nfloat64[36] covariance\n",
    [Twist],
    "RIHS01_49f574f033f095d8b6cd1beaca5ca7925e296e84af1716d16c89d38b059c8c18"
);

impl Default for TwistWithCovariance {
    fn default() -> Self {
        Self {
            twist: Twist::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `geometry_msgs/msg/Transform`: a translation (m) and a rotation.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}
ros_message!(
    Transform,
    "geometry_msgs/msg/Transform",
    "Vector3 translation\nQuaternion rotation\n",
    [Vector3, Quaternion],
    "RIHS01_beb83fbe698636351461f6f35d1abb20010c43d55374d81bd041f1ba2581fddc"
);

/// `geometry_msgs/msg/TransformStamped`: the pose of `child_frame_id` in `header.frame_id`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub child_frame_id: String,
    pub transform: Transform,
}
ros_message!(
    TransformStamped,
    "geometry_msgs/msg/TransformStamped",
    "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    [Header, Transform],
    "RIHS01_0a241f87d04668d94099cbb5ba11691d5ad32c2f29682e4eb5653424bd275206"
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaw_round_trips_through_a_quaternion() {
        for yaw in [0.0, 0.3, -1.2, 3.0, -3.0, std::f64::consts::FRAC_PI_2] {
            let q = Quaternion::from_yaw(yaw);
            assert!((q.yaw() - yaw).abs() < 1e-12, "{yaw} -> {}", q.yaw());
            assert!((q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0).abs() < 1e-12);
        }
        // Wraps into [-pi, pi]; a scaled (non-unit) quaternion has the same yaw.
        let q = Quaternion::from_yaw(2.0 * std::f64::consts::PI + 0.5);
        assert!((q.yaw() - 0.5).abs() < 1e-12);
        let scaled = Quaternion {
            x: 0.0,
            y: 0.0,
            z: q.z * 3.0,
            w: q.w * 3.0,
        };
        assert!((scaled.yaw() - 0.5).abs() < 1e-12);
        assert!(
            Quaternion {
                x: f64::NAN,
                ..Quaternion::IDENTITY
            }
            .yaw()
            .is_nan()
        );
    }

    #[test]
    fn defaults_are_ros_defaults() {
        assert_eq!(Quaternion::default(), Quaternion::IDENTITY);
        assert_eq!(Pose::default().orientation.w, 1.0);
        assert_eq!(PoseWithCovariance::default().covariance, [0.0; 36]);
        assert_eq!(Quaternion::default().yaw(), 0.0);
    }
}
