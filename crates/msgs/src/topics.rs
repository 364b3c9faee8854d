//! The topic contract in one place: names, types and QoS.

use crate::qos::{QosProfile, Reliability};
use crate::{
    MessageDefinition, RosMessage, diagnostic_msgs, geometry_msgs, lidar_har_msgs, nav_msgs,
    rcl_interfaces, rosgraph_msgs, sensor_msgs, tf2_msgs, visualization_msgs,
};

/// A topic of the contract: its default name, its message type, the QoS its publishers offer
/// (and a bag records, which `ros2 bag play` offers again) and the QoS its subscribers ask for.
#[derive(Debug, Clone, Copy)]
pub struct TopicSpec {
    pub name: &'static str,
    pub type_name: &'static str,
    /// The type's definition, for recording the topic in a bag.
    pub definition: &'static MessageDefinition,
    /// What publishers offer and bags record.
    pub qos: QosProfile,
    /// What subscribers ask for: the offer, except where asking for less matches more
    /// publishers (/scan best effort: many drivers offer it so).
    pub subscribed: QosProfile,
}

macro_rules! topics {
    (@subscribed $qos:expr) => { $qos };
    (@subscribed $qos:expr, $subscribed:expr) => { $subscribed };
    ($($(#[$doc:meta])* $id:ident = $name:literal, $ty:ty, $qos:expr $(, subscribed $subscribed:expr)?;)*) => {
        $($(#[$doc])* pub const $id: TopicSpec = TopicSpec {
            name: $name,
            type_name: <$ty as RosMessage>::TYPE_NAME,
            definition: &<$ty as RosMessage>::DEFINITION,
            qos: $qos,
            subscribed: topics!(@subscribed $qos $(, $subscribed)?),
        };)*
        /// Every topic of the contract.
        pub const ALL: &[TopicSpec] = &[$($id),*];
    };
}

topics! {
    /// Offered reliable, as REP-2003 asks of sensor drivers and Slamtec's drivers do, so that
    /// a reliable subscriber (rclcpp's default `QoS(10)`) matches as well as a best-effort one;
    /// asked best effort, which matches every publisher. Offered (or recorded: `ros2 bag
    /// play` offers the recorded QoS again) best effort, a reliable subscriber got nothing. A
    /// subscriber that stops acknowledging does not hold up the scans (docs/ros.md, "/scan
    /// QoS").
    SCAN = "/scan", sensor_msgs::LaserScan, SCAN_OFFERED, subscribed QosProfile::sensor_data();
    ODOM = "/odom", nav_msgs::Odometry, QosProfile::reliable(50);
    MAP = "/map", nav_msgs::OccupancyGrid, QosProfile::latched(1);
    TF = "/tf", tf2_msgs::TFMessage, QosProfile::reliable(100);
    TF_STATIC = "/tf_static", tf2_msgs::TFMessage, QosProfile::latched(1);
    CLOCK = "/clock", rosgraph_msgs::Clock, QosProfile::sensor_data();
    HUMAN_POSE = "/human/pose", geometry_msgs::PoseWithCovarianceStamped, QosProfile::reliable(10);
    HUMAN_OBSERVATION = "/human/observation", lidar_har_msgs::HumanObservation, QosProfile::reliable(10);
    /// The pelvis as the classifier's pose head places it, on the scans where it does so
    /// better than /human/pose (docs/model_contract.md, "Pose head").
    HUMAN_PELVIS = "/human/pelvis", geometry_msgs::PoseWithCovarianceStamped, QosProfile::reliable(10);
    HUMAN_ACTIVITY = "/human/activity", lidar_har_msgs::Activity, QosProfile::reliable(10);
    FALL_ALERT = "/human/fall_alert", lidar_har_msgs::FallAlert, QosProfile::latched(10);
    HUMAN_MARKERS = "/human/markers", visualization_msgs::MarkerArray, QosProfile::reliable(10);
    DIAGNOSTICS = "/diagnostics", diagnostic_msgs::DiagnosticArray, QosProfile::reliable(10);
    GROUND_TRUTH_POSE = "/ground_truth/human_pose", geometry_msgs::PoseStamped, QosProfile::reliable(10);
    GROUND_TRUTH_ACTIVITY = "/ground_truth/activity", lidar_har_msgs::Activity, QosProfile::reliable(10);
    /// Every node's log records, with rcl's /rosout QoS (`rcl_qos_profile_rosout_default`,
    /// whose 10 s lifespan only writers set), as every ROS 2 node offers them: so
    /// `lidar-har topic echo /rosout` started before the nodes reads them as `rqt_console`
    /// does, with the records they published before it matched them.
    ROSOUT = "/rosout", rcl_interfaces::Log, QosProfile::latched(1000);
}

/// [`SCAN`]'s offer: the sensor-data profile made reliable.
const SCAN_OFFERED: QosProfile = QosProfile {
    reliability: Reliability::Reliable,
    ..QosProfile::sensor_data()
};

/// The topic of the contract with this name, if any.
pub fn find(name: &str) -> Option<&'static TopicSpec> {
    ALL.iter().find(|spec| spec.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// /scan was recorded best effort, the subscription's QoS, so `ros2 bag play` of a
    /// simulated bag offered it so and a reliable subscriber got nothing.
    #[test]
    fn scan_is_offered_reliable_and_asked_best_effort_with_the_same_depth() {
        assert_eq!(SCAN.qos.reliability, Reliability::Reliable);
        assert_eq!(SCAN.subscribed.reliability, Reliability::BestEffort);
        assert_eq!(
            (SCAN.qos.durability, SCAN.qos.history),
            (SCAN.subscribed.durability, SCAN.subscribed.history)
        );
        for spec in ALL.iter().filter(|spec| spec.name != SCAN.name) {
            assert_eq!(spec.subscribed, spec.qos, "{}", spec.name);
        }
    }

    /// The type names the contract's tables give, so a topic cannot change type unnoticed.
    #[test]
    fn every_topic_has_the_type_of_the_contract() {
        let types: Vec<(&str, &str)> = ALL.iter().map(|t| (t.name, t.type_name)).collect();
        assert_eq!(
            types,
            [
                ("/scan", "sensor_msgs/msg/LaserScan"),
                ("/odom", "nav_msgs/msg/Odometry"),
                ("/map", "nav_msgs/msg/OccupancyGrid"),
                ("/tf", "tf2_msgs/msg/TFMessage"),
                ("/tf_static", "tf2_msgs/msg/TFMessage"),
                ("/clock", "rosgraph_msgs/msg/Clock"),
                ("/human/pose", "geometry_msgs/msg/PoseWithCovarianceStamped"),
                ("/human/observation", "lidar_har_msgs/msg/HumanObservation"),
                (
                    "/human/pelvis",
                    "geometry_msgs/msg/PoseWithCovarianceStamped"
                ),
                ("/human/activity", "lidar_har_msgs/msg/Activity"),
                ("/human/fall_alert", "lidar_har_msgs/msg/FallAlert"),
                ("/human/markers", "visualization_msgs/msg/MarkerArray"),
                ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
                ("/ground_truth/human_pose", "geometry_msgs/msg/PoseStamped"),
                ("/ground_truth/activity", "lidar_har_msgs/msg/Activity"),
                ("/rosout", "rcl_interfaces/msg/Log"),
            ]
        );
        for topic in ALL {
            assert_eq!(
                topic.definition.type_name, topic.type_name,
                "{}",
                topic.name
            );
            assert_eq!(find(topic.name).map(|t| t.type_name), Some(topic.type_name));
        }
        assert!(find("/chatter").is_none());
    }
}
