//! `lidar_har_msgs`: this project's messages. Their .msg files in `msg/msg/` (the ROS 2
//! interface package) are the source of truth: the schema texts below are those files,
//! and the tests check that the fields of these mirrors match them.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::geometry_msgs::{Point, Point32, Vector3};
use crate::ros_message;
use crate::std_msgs::Header;

/// `lidar_har_msgs/msg/Activity`: the recognised activity of the tracked person.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Activity {
    pub header: Header,
    /// Class index, one of the class constants.
    pub activity: u8,
    /// Class name in snake_case, see [`Activity::LABELS`].
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub label: String,
    /// Probability of `activity`, 0..1.
    pub confidence: f32,
    /// Probability of every class in class order (empty in ground truth).
    pub probabilities: Vec<f32>,
}
ros_message!(
    Activity,
    "lidar_har_msgs/msg/Activity",
    include_str!("../../../msg/msg/Activity.msg"),
    [Header],
    "RIHS01_b248f59b12ddb0747ed2c2c4bd11ed085dcab4561910daf3524c0607e8f7cbe8"
);

impl Activity {
    pub const CRAWLING: u8 = 0;
    pub const FALLING_DOWN: u8 = 1;
    pub const GETTING_UP: u8 = 2;
    pub const LYING_DOWN: u8 = 3;
    pub const RUNNING: u8 = 4;
    pub const SITTING_ON_FLOOR: u8 = 5;
    pub const STANDING: u8 = 6;
    pub const WALKING: u8 = 7;
    pub const WALKING_UNSTEADILY: u8 = 8;
    pub const NUM_CLASSES: u8 = 9;

    /// The `label` of every class, indexed by class.
    pub const LABELS: [&'static str; 9] = [
        "crawling",
        "falling_down",
        "getting_up",
        "lying_down",
        "running",
        "sitting_on_floor",
        "standing",
        "walking",
        "walking_unsteadily",
    ];

    /// The label of class `activity`, or `None` for an index outside 0..9.
    pub fn label_of(activity: u8) -> Option<&'static str> {
        Self::LABELS.get(usize::from(activity)).copied()
    }
}

/// `lidar_har_msgs/msg/FallAlert`: the person fell or is down on the floor.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FallAlert {
    pub header: Header,
    /// [`FallAlert::FALL_DETECTED`] or [`FallAlert::PERSON_DOWN`].
    pub kind: u8,
    /// Where the person is, m, in `header.frame_id`.
    pub position: Point,
    /// 0..1.
    pub confidence: f32,
    /// When the fall happened, or since when the person is down.
    pub event_time: Time,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub description: String,
}
ros_message!(
    FallAlert,
    "lidar_har_msgs/msg/FallAlert",
    include_str!("../../../msg/msg/FallAlert.msg"),
    [Header, Point, Time],
    "RIHS01_ad5d7ba3d55f3f361957279d989a5cf792fc650cf3aeab168ec67d6ab3e4841e"
);

impl FallAlert {
    pub const FALL_DETECTED: u8 = 0;
    pub const PERSON_DOWN: u8 = 1;
}

/// `lidar_har_msgs/msg/HumanObservation`: the tracked person in one scan, with the
/// person's own points (all in `header.frame_id`, normally `map`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct HumanObservation {
    pub header: Header,
    /// Id of the track; changes when a lost person is found again.
    pub track_id: u32,
    /// True when the person's points were found in this scan.
    pub visible: bool,
    /// s since last visible, 0 when visible.
    pub seconds_since_seen: f32,
    /// Centroid, m (predicted when not visible).
    pub position: Point,
    /// m/s.
    pub velocity: Vector3,
    /// Covariance of (x, y), 2x2 row-major, m^2.
    pub covariance: [f64; 4],
    /// Lidar position when the scan was taken, m.
    pub sensor_position: Point,
    /// The person's scan points, m; empty when not visible.
    pub points: Vec<Point32>,
}
ros_message!(
    HumanObservation,
    "lidar_har_msgs/msg/HumanObservation",
    include_str!("../../../msg/msg/HumanObservation.msg"),
    [Header, Point, Vector3, Point32],
    "RIHS01_12ebdbdbb56dca8037e22488534cbbcadd5f0da8c713779f8debbd1507fe1caa"
);
