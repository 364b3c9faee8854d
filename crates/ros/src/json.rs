//! Messages of known types as JSON, for `lidar-har topic echo` and tests: the serde mirrors of
//! `lidar_har_msgs` decoded from CDR, then serialised field by field.

use lidar_har_msgs::{
    RosMessage, diagnostic_msgs, geometry_msgs, lidar_har_msgs as har, nav_msgs, rosgraph_msgs,
    sensor_msgs, tf2_msgs, visualization_msgs,
};

use crate::RosError;

fn convert<M: RosMessage>(bytes: &[u8]) -> Result<serde_json::Value, RosError> {
    let msg: M = lidar_har_msgs::decode(bytes)?;
    serde_json::to_value(&msg).map_err(|e| RosError::Topic {
        topic: M::TYPE_NAME.into(),
        reason: e.to_string(),
    })
}

/// `bytes` decoded as `type_name` and turned into JSON; `None` for a type this project does
/// not mirror.
pub fn decode_to_json(
    type_name: &str,
    bytes: &[u8],
) -> Option<Result<serde_json::Value, RosError>> {
    macro_rules! dispatch {
        ($($ty:ty),* $(,)?) => {
            $(if type_name == <$ty as RosMessage>::TYPE_NAME { return Some(convert::<$ty>(bytes)); })*
        };
    }
    dispatch!(
        sensor_msgs::LaserScan,
        nav_msgs::Odometry,
        nav_msgs::OccupancyGrid,
        tf2_msgs::TFMessage,
        rosgraph_msgs::Clock,
        geometry_msgs::PoseStamped,
        geometry_msgs::PoseWithCovarianceStamped,
        har::Activity,
        har::FallAlert,
        har::HumanObservation,
        visualization_msgs::MarkerArray,
        diagnostic_msgs::DiagnosticArray,
    );
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_types_decode_unknown_are_none_garbage_is_an_error() {
        let activity = har::Activity {
            activity: 3,
            label: "lying_down".into(),
            confidence: 0.5,
            ..Default::default()
        };
        let bytes = lidar_har_msgs::encode(&activity).unwrap();
        let json = decode_to_json("lidar_har_msgs/msg/Activity", &bytes)
            .unwrap()
            .unwrap();
        assert_eq!(json["label"], "lying_down");
        assert_eq!(json["activity"], 3);
        assert!(decode_to_json("foo_msgs/msg/Bar", &bytes).is_none());
        assert!(
            decode_to_json("lidar_har_msgs/msg/Activity", &bytes[..6])
                .unwrap()
                .is_err()
        );
        assert!(
            decode_to_json("lidar_har_msgs/msg/Activity", &[])
                .unwrap()
                .is_err()
        );
    }
}
