//! What the integration tests of this crate share: the list of every mirrored type and the
//! fixed values of `tests/golden/values.json` (written by `scripts/make_golden_cdr.py`).

#![allow(dead_code)] // each test binary uses a different part

use std::path::{Path, PathBuf};

use lidar_har_msgs::RosMessage;

/// Calls `$mac!(Type)` for every mirrored message type (keep in step with `schema::ALL`;
/// a test checks both lists name the same types).
#[macro_export]
macro_rules! for_every_type {
    ($mac:ident) => {{
        use lidar_har_msgs::{
            builtin_interfaces as bi, diagnostic_msgs as dm, geometry_msgs as gm,
            lidar_har_msgs as lh, nav_msgs as nm, rcl_interfaces as rc, rosgraph_msgs as rg,
            sensor_msgs as sm, std_msgs as st, tf2_msgs as tf, visualization_msgs as vm,
        };
        vec![
            $mac!(bi::Time),
            $mac!(bi::Duration),
            $mac!(st::Header),
            $mac!(st::ColorRGBA),
            $mac!(gm::Point),
            $mac!(gm::Point32),
            $mac!(gm::Quaternion),
            $mac!(gm::Vector3),
            $mac!(gm::Pose),
            $mac!(gm::PoseStamped),
            $mac!(gm::PoseWithCovariance),
            $mac!(gm::PoseWithCovarianceStamped),
            $mac!(gm::Twist),
            $mac!(gm::TwistWithCovariance),
            $mac!(gm::Transform),
            $mac!(gm::TransformStamped),
            $mac!(sm::LaserScan),
            $mac!(sm::CompressedImage),
            $mac!(nm::Odometry),
            $mac!(nm::OccupancyGrid),
            $mac!(nm::MapMetaData),
            $mac!(tf::TFMessage),
            $mac!(rg::Clock),
            $mac!(vm::Marker),
            $mac!(vm::MarkerArray),
            $mac!(vm::UVCoordinate),
            $mac!(vm::MeshFile),
            $mac!(dm::DiagnosticArray),
            $mac!(dm::DiagnosticStatus),
            $mac!(dm::KeyValue),
            $mac!(rc::Log),
            $mac!(lh::Activity),
            $mac!(lh::FallAlert),
            $mac!(lh::HumanObservation),
        ]
    }};
}

pub fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

/// The golden file of a type: `sensor_msgs/msg/LaserScan` -> `sensor_msgs__LaserScan.cdr`.
pub fn golden_path(type_name: &str) -> PathBuf {
    golden_dir().join(format!("{}.cdr", type_name.replace("/msg/", "__")))
}

/// The fixed value of `M` from values.json, read through the serde mirror.
pub fn sample<M: RosMessage>() -> M {
    let path = golden_dir().join("values.json");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (run scripts/make_golden_cdr.py)", path.display()));
    let all: serde_json::Value = serde_json::from_str(&text).expect("values.json is JSON");
    let value = all
        .get(M::TYPE_NAME)
        .unwrap_or_else(|| panic!("values.json has no value for {}", M::TYPE_NAME))
        .clone();
    serde_json::from_value(value)
        .unwrap_or_else(|e| panic!("values.json: {} does not fit the mirror: {e}", M::TYPE_NAME))
}
