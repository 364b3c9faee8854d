//! The codec against `rosbags`: the bytes we encode equal the golden files rosbags wrote for
//! the same values (scripts/make_golden_cdr.py), we decode them back to those values, and
//! every type round-trips.

mod common;

use common::{golden_path, sample};
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;
use lidar_har_msgs::{RosMessage, builtin_interfaces::Time, decode, encode};

/// Checks one type; returns its name and a description of what failed, if anything.
fn check<M: RosMessage + PartialEq + std::fmt::Debug>() -> (&'static str, Option<String>) {
    let value: M = sample();
    let path = golden_path(M::TYPE_NAME);
    let golden = match std::fs::read(&path) {
        Ok(bytes) => bytes,
        Err(e) => return (M::TYPE_NAME, Some(format!("{}: {e}", path.display()))),
    };
    let ours = match encode(&value) {
        Ok(bytes) => bytes,
        Err(e) => return (M::TYPE_NAME, Some(format!("encode: {e}"))),
    };
    if ours != golden {
        let at = ours
            .iter()
            .zip(&golden)
            .position(|(a, b)| a != b)
            .unwrap_or(ours.len().min(golden.len()));
        return (
            M::TYPE_NAME,
            Some(format!(
                "bytes differ from rosbags at offset {at} (ours {} bytes, rosbags {})",
                ours.len(),
                golden.len()
            )),
        );
    }
    match decode::<M>(&golden) {
        Ok(decoded) if decoded == value => (M::TYPE_NAME, None),
        Ok(decoded) => (
            M::TYPE_NAME,
            Some(format!("decoded {decoded:?}, expected {value:?}")),
        ),
        Err(e) => (M::TYPE_NAME, Some(format!("decode: {e}"))),
    }
}

macro_rules! check_type {
    ($ty:ty) => {
        check::<$ty>()
    };
}

#[test]
fn every_type_encodes_to_the_bytes_rosbags_writes_and_decodes_back() {
    let results = for_every_type!(check_type);
    let failures: Vec<String> = results
        .iter()
        .filter_map(|(name, err)| err.as_ref().map(|e| format!("{name}: {e}")))
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} types fail:\n{}",
        failures.len(),
        results.len(),
        failures.join("\n")
    );
    assert_eq!(results.len(), lidar_har_msgs::schema::ALL.len());
}

fn round_trip<M: RosMessage + PartialEq + std::fmt::Debug + Default>() -> &'static str {
    for value in [sample::<M>(), M::default()] {
        let bytes = encode(&value).expect("encodes");
        let back: M = decode(&bytes).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, value, "{}", M::TYPE_NAME);
    }
    M::TYPE_NAME
}

macro_rules! round_trip_type {
    ($ty:ty) => {
        round_trip::<$ty>()
    };
}

#[test]
fn every_type_round_trips_its_sample_and_its_default() {
    let names = for_every_type!(round_trip_type);
    let listed: Vec<&str> = lidar_har_msgs::schema::ALL
        .iter()
        .map(|d| d.type_name)
        .collect();
    assert_eq!(
        names, listed,
        "the test list and schema::ALL name different types"
    );
}

/// The scan of `sensor_msgs__LaserScan_nonfinite.cdr` (see make_golden_cdr.py).
fn nonfinite_scan() -> LaserScan {
    let nan_with_payload = f32::from_bits(0x7FC0_0001);
    LaserScan {
        header: Header::new(
            Time {
                sec: 1_700_000_123,
                nanosec: 456_789_012,
            },
            "laser",
        ),
        angle_min: -std::f32::consts::PI,
        angle_max: std::f32::consts::PI,
        angle_increment: 0.5,
        time_increment: 0.0,
        scan_time: 0.1,
        range_min: 0.15,
        range_max: f32::INFINITY,
        ranges: vec![
            1.5,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.25,
            0.0,
            nan_with_payload,
        ],
        intensities: vec![f32::NAN],
    }
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn inf_and_nan_ranges_match_rosbags_and_keep_their_bits() {
    let scan = nonfinite_scan();
    let golden =
        std::fs::read(golden_path("sensor_msgs/msg/LaserScan_nonfinite")).expect("golden file");
    assert_eq!(encode(&scan).unwrap(), golden);
    let back: LaserScan = decode(&golden).unwrap();
    assert_eq!(bits(&back.ranges), bits(&scan.ranges));
    assert_eq!(bits(&back.intensities), bits(&scan.intensities));
    assert_eq!(back.range_max, f32::INFINITY);
    assert_eq!(
        back.ranges[5].to_bits(),
        0x7FC0_0001,
        "NaN payload survives"
    );
}

#[test]
fn big_endian_payloads_decode_too() {
    // Hand-made big-endian Point: header 00 00, then three float64 in network order.
    let mut bytes = vec![0x00, 0x00, 0x00, 0x00];
    for v in [1.5f64, -2.0, 0.25] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    let point: lidar_har_msgs::geometry_msgs::Point = decode(&bytes).unwrap();
    assert_eq!((point.x, point.y, point.z), (1.5, -2.0, 0.25));
}
