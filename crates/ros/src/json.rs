//! Messages of known types as JSON, for `lidar-har topic echo` and tests: the serde mirrors of
//! `lidar_har_msgs` decoded from CDR, then serialised field by field. JSON has no infinity or
//! NaN, which LaserScan ranges use with distinct meanings (REP 117: +inf nothing within
//! range, -inf too close, NaN no measurement): they are written as the strings "inf", "-inf"
//! and "nan".

use lidar_har_msgs::{
    RosMessage, diagnostic_msgs, geometry_msgs, lidar_har_msgs as har, nav_msgs, rosgraph_msgs,
    sensor_msgs, tf2_msgs, visualization_msgs,
};

use crate::RosError;

/// serde_json turns every non-finite float into `null` as it serialises, so the message is
/// serialised into serde_yaml_ng's `Value`, which keeps them, and converted from there.
fn convert<M: RosMessage>(bytes: &[u8]) -> Result<serde_json::Value, RosError> {
    let msg: M = lidar_har_msgs::decode(bytes)?;
    let value = serde_yaml_ng::to_value(&msg).map_err(|e| RosError::Topic {
        topic: M::TYPE_NAME.into(),
        reason: e.to_string(),
    })?;
    Ok(json_from(value))
}

fn json_from(value: serde_yaml_ng::Value) -> serde_json::Value {
    use serde_json::Value as Json;
    use serde_yaml_ng::Value as Yaml;
    match value {
        Yaml::Null => Json::Null,
        Yaml::Bool(b) => Json::Bool(b),
        Yaml::Number(n) => {
            if let Some(i) = n.as_i64() {
                Json::from(i)
            } else if let Some(u) = n.as_u64() {
                Json::from(u)
            } else {
                float(n.as_f64().unwrap_or(f64::NAN))
            }
        }
        Yaml::String(s) => Json::String(s),
        Yaml::Sequence(items) => Json::Array(items.into_iter().map(json_from).collect()),
        Yaml::Mapping(entries) => Json::Object(
            entries
                .into_iter()
                .map(|(key, value)| (key_text(key), json_from(value)))
                .collect(),
        ),
        // An enum variant with data (no message has one): `{"Variant": data}`, as serde_json.
        Yaml::Tagged(tagged) => {
            let variant = tagged.tag.to_string().trim_start_matches('!').to_string();
            Json::Object([(variant, json_from(tagged.value))].into_iter().collect())
        }
    }
}

fn float(f: f64) -> serde_json::Value {
    match serde_json::Number::from_f64(f) {
        Some(n) => serde_json::Value::Number(n),
        None if f.is_nan() => "nan".into(),
        None if f > 0.0 => "inf".into(),
        None => "-inf".into(),
    }
}

/// Message fields are named by strings; any other key (none in messages) as JSON text.
fn key_text(key: serde_yaml_ng::Value) -> String {
    match key {
        serde_yaml_ng::Value::String(s) => s,
        other => json_from(other).to_string(),
    }
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

    #[test]
    fn non_finite_ranges_keep_their_meaning() {
        let scan = sensor_msgs::LaserScan {
            angle_increment: 0.1,
            range_max: 12.0,
            ranges: vec![1.5, f32::INFINITY, f32::NEG_INFINITY, f32::NAN],
            ..Default::default()
        };
        let bytes = lidar_har_msgs::encode(&scan).unwrap();
        let json = decode_to_json("sensor_msgs/msg/LaserScan", &bytes)
            .unwrap()
            .unwrap();
        assert_eq!(
            json["ranges"],
            serde_json::json!([1.5, "inf", "-inf", "nan"])
        );
        // Finite values are written as before: f32 widened to f64.
        assert_eq!(json["angle_increment"], f64::from(0.1f32));
        assert_eq!(json["range_max"], 12.0);
        assert_eq!(json["header"]["stamp"]["sec"], 0);
        assert_eq!(json["intensities"], serde_json::json!([]));
    }
}
