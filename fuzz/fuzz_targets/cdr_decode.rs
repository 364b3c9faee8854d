//! Arbitrary bytes decoded as every message type: the decoder must return an error or a
//! message, never panic, hang or allocate without bound; and what it decodes must re-encode
//! to bytes that decode to the same bytes again (encode . decode is idempotent).
#![no_main]

use libfuzzer_sys::fuzz_target;
use lidar_har_msgs::{
    RosMessage, builtin_interfaces as bi, decode, diagnostic_msgs as dm, encode,
    geometry_msgs as gm, lidar_har_msgs as lh, nav_msgs as nm, rcl_interfaces as rc,
    rosgraph_msgs as rg, sensor_msgs as sm, std_msgs as st, tf2_msgs as tf,
    visualization_msgs as vm,
};

fn check<M: RosMessage>(data: &[u8]) {
    let Ok(message) = decode::<M>(data) else {
        return;
    };
    let bytes = encode(&message).expect("a decoded message encodes");
    let again: M = decode(&bytes).expect("our own encoding decodes");
    assert_eq!(
        encode(&again).expect("encodes"),
        bytes,
        "{}: encode . decode is not stable",
        M::TYPE_NAME
    );
}

fuzz_target!(|data: &[u8]| {
    check::<bi::Time>(data);
    check::<bi::Duration>(data);
    check::<st::Header>(data);
    check::<st::ColorRGBA>(data);
    check::<gm::Point>(data);
    check::<gm::Point32>(data);
    check::<gm::Quaternion>(data);
    check::<gm::Vector3>(data);
    check::<gm::Pose>(data);
    check::<gm::PoseStamped>(data);
    check::<gm::PoseWithCovariance>(data);
    check::<gm::PoseWithCovarianceStamped>(data);
    check::<gm::Twist>(data);
    check::<gm::TwistWithCovariance>(data);
    check::<gm::Transform>(data);
    check::<gm::TransformStamped>(data);
    check::<sm::LaserScan>(data);
    check::<sm::CompressedImage>(data);
    check::<nm::Odometry>(data);
    check::<nm::OccupancyGrid>(data);
    check::<nm::MapMetaData>(data);
    check::<tf::TFMessage>(data);
    check::<rg::Clock>(data);
    check::<vm::Marker>(data);
    check::<vm::MarkerArray>(data);
    check::<vm::UVCoordinate>(data);
    check::<vm::MeshFile>(data);
    check::<dm::DiagnosticArray>(data);
    check::<dm::DiagnosticStatus>(data);
    check::<dm::KeyValue>(data);
    check::<rc::Log>(data);
    check::<lh::Activity>(data);
    check::<lh::FallAlert>(data);
    check::<lh::HumanObservation>(data);
});
