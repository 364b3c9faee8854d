//! The topic contract of DESIGN.md in one place: names, types and QoS.

use crate::qos::QosProfile;

/// A topic of the contract: its default name, its message type and the QoS it is offered with.
#[derive(Debug, Clone, Copy)]
pub struct TopicSpec {
    pub name: &'static str,
    pub type_name: &'static str,
    pub qos: QosProfile,
}

macro_rules! topics {
    ($($(#[$doc:meta])* $id:ident = $name:literal, $ty:literal, $qos:expr;)*) => {
        $($(#[$doc])* pub const $id: TopicSpec = TopicSpec { name: $name, type_name: $ty, qos: $qos };)*
        /// Every topic of the contract.
        pub const ALL: &[TopicSpec] = &[$($id),*];
    };
}

topics! {
    SCAN = "/scan", "sensor_msgs/msg/LaserScan", QosProfile::sensor_data();
    ODOM = "/odom", "nav_msgs/msg/Odometry", QosProfile::reliable(50);
    MAP = "/map", "nav_msgs/msg/OccupancyGrid", QosProfile::latched(1);
    TF = "/tf", "tf2_msgs/msg/TFMessage", QosProfile::reliable(100);
    TF_STATIC = "/tf_static", "tf2_msgs/msg/TFMessage", QosProfile::latched(1);
    CLOCK = "/clock", "rosgraph_msgs/msg/Clock", QosProfile::sensor_data();
    HUMAN_POSE = "/human/pose", "geometry_msgs/msg/PoseWithCovarianceStamped", QosProfile::reliable(10);
    HUMAN_OBSERVATION = "/human/observation", "lidar_har_msgs/msg/HumanObservation", QosProfile::reliable(10);
    /// The pelvis as the classifier's pose head places it, on the scans where it does so
    /// better than /human/pose (docs/model_contract.md, "Pose head").
    HUMAN_PELVIS = "/human/pelvis", "geometry_msgs/msg/PoseWithCovarianceStamped", QosProfile::reliable(10);
    HUMAN_ACTIVITY = "/human/activity", "lidar_har_msgs/msg/Activity", QosProfile::reliable(10);
    FALL_ALERT = "/human/fall_alert", "lidar_har_msgs/msg/FallAlert", QosProfile::latched(10);
    HUMAN_MARKERS = "/human/markers", "visualization_msgs/msg/MarkerArray", QosProfile::reliable(10);
    DIAGNOSTICS = "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", QosProfile::reliable(10);
    GROUND_TRUTH_POSE = "/ground_truth/human_pose", "geometry_msgs/msg/PoseStamped", QosProfile::reliable(10);
    GROUND_TRUTH_ACTIVITY = "/ground_truth/activity", "lidar_har_msgs/msg/Activity", QosProfile::reliable(10);
}
