//! External checks of the bag format: a bag written by the project is decoded field by field
//! by `rosbags` and by `mcap` + `mcap-ros2-support`; bags written by `rosbags` (MCAP and
//! sqlite3, versions 8 and 9) are read by the project and decoded with lidar-har-msgs.

use std::path::Path;

use lidar_har_bag::{BagReader, BagWriter, StorageId, WriterOptions};
use lidar_har_e2e::{checker_python, workspace_bin};
use lidar_har_msgs::RosMessage;
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::geometry_msgs::{Point, Quaternion, TransformStamped, Vector3};
use lidar_har_msgs::lidar_har_msgs::Activity;
use lidar_har_msgs::nav_msgs::Odometry;
use lidar_har_msgs::qos::QosProfile;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::{ColorRGBA, Header};
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_msgs::visualization_msgs::{Marker, MarkerArray};
use serde_json::Value as Json;
use serde_yaml_ng::Value as Yaml;

fn header(i: i32, frame: &str) -> Header {
    Header {
        stamp: Time {
            sec: 1000 + i,
            nanosec: 250_000_000,
        },
        frame_id: frame.into(),
    }
}

fn scan(i: i32) -> LaserScan {
    LaserScan {
        header: header(i, "laser"),
        angle_min: -3.1,
        angle_max: 3.1,
        angle_increment: 0.1,
        time_increment: 1e-4,
        scan_time: 0.05,
        range_min: 0.15,
        range_max: 12.0,
        ranges: vec![
            0.5 + i as f32,
            f32::INFINITY,
            f32::NAN,
            f32::NEG_INFINITY,
            0.1,
        ],
        intensities: vec![1.0, 0.0, 255.0],
    }
}

fn odom(i: i32) -> Odometry {
    let mut odom = Odometry {
        header: header(i, "odom"),
        child_frame_id: "base_link".into(),
        ..Odometry::default()
    };
    odom.pose.pose.position = Point {
        x: 0.1 * f64::from(i),
        y: -1.5,
        z: 0.0,
    };
    odom.pose.pose.orientation = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.38268343236,
        w: 0.92387953251,
    };
    odom.pose.covariance = std::array::from_fn(|k| k as f64 * 0.25 - 3.0);
    odom.twist.twist.linear = Vector3 {
        x: 0.2,
        y: 0.0,
        z: 0.0,
    };
    odom.twist.covariance[35] = 1e-9;
    odom
}

fn markers(i: i32) -> MarkerArray {
    let marker = |id: i32| Marker {
        header: header(i, "map"),
        ns: "people".into(),
        id,
        r#type: 2,
        action: 0,
        scale: Vector3 {
            x: 0.3,
            y: 0.3,
            z: 1.7,
        },
        color: ColorRGBA {
            r: 1.0,
            g: 0.2,
            b: 0.0,
            a: 0.8,
        },
        points: vec![
            Point {
                x: 1.0,
                y: 2.0,
                z: 0.0,
            },
            Point {
                x: -1.0,
                y: 0.5,
                z: 0.0,
            },
        ],
        frame_locked: id % 2 == 0,
        ..Marker::default()
    };
    MarkerArray {
        markers: vec![marker(0), marker(1)],
    }
}

fn activity(i: i32) -> Activity {
    Activity {
        header: header(i, "map"),
        activity: Activity::WALKING,
        label: "walking".into(),
        confidence: 0.875,
        probabilities: (0..9).map(|k| k as f32 / 36.0).collect(),
    }
}

fn tf(i: i32) -> TFMessage {
    let mut t = TransformStamped {
        header: header(i, "odom"),
        child_frame_id: "base_link".into(),
        ..Default::default()
    };
    t.transform.translation = Vector3 {
        x: 1.0,
        y: 2.0,
        z: 0.0,
    };
    t.transform.rotation.w = 1.0;
    TFMessage {
        transforms: vec![t.clone(), t],
    }
}

/// Writes 3 messages per topic; returns (topic, log time, the message as a serde tree).
fn write_project_bag(dir: &Path, storage: StorageId) -> Vec<(String, i64, Yaml)> {
    let mut writer = BagWriter::create(
        dir,
        WriterOptions {
            storage,
            ..WriterOptions::default()
        },
    )
    .unwrap();
    let mut expected = Vec::new();
    let s = writer
        .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
        .unwrap();
    let o = writer
        .add_topic_for::<Odometry>("/odom", QosProfile::reliable(50))
        .unwrap();
    let m = writer
        .add_topic_for::<MarkerArray>("/human/markers", QosProfile::reliable(10))
        .unwrap();
    let a = writer
        .add_topic_for::<Activity>("/human/activity", QosProfile::reliable(10))
        .unwrap();
    let t = writer
        .add_topic_for::<TFMessage>("/tf", QosProfile::reliable(100))
        .unwrap();
    fn put<M: RosMessage>(
        w: &mut BagWriter,
        h: lidar_har_bag::TopicHandle,
        topic: &str,
        time: i64,
        msg: &M,
        out: &mut Vec<(String, i64, Yaml)>,
    ) {
        w.write_message(h, time, msg).unwrap();
        out.push((
            topic.to_string(),
            time,
            serde_yaml_ng::to_value(msg).unwrap(),
        ));
    }
    for i in 0..3 {
        let time = 1_700_000_000_000_000_000 + i64::from(i) * 100_000_000;
        put(&mut writer, s, "/scan", time, &scan(i), &mut expected);
        put(&mut writer, o, "/odom", time + 1, &odom(i), &mut expected);
        put(
            &mut writer,
            m,
            "/human/markers",
            time + 2,
            &markers(i),
            &mut expected,
        );
        put(
            &mut writer,
            a,
            "/human/activity",
            time + 3,
            &activity(i),
            &mut expected,
        );
        put(&mut writer, t, "/tf", time + 4, &tf(i), &mut expected);
    }
    writer.finish().unwrap();
    expected
}

fn same_float(py: &str, rs: f64) -> bool {
    let Ok(py) = py.parse::<f64>() else {
        return false;
    };
    (py.is_nan() && rs.is_nan()) || py == rs || (py as f32).to_bits() == (rs as f32).to_bits()
}

/// Compares a message decoded by Python (floats as repr strings) with the Rust value.
fn compare(path: &str, py: &Json, rs: &Yaml) -> Result<(), String> {
    let mismatch = || Err(format!("{path}: python {py} vs rust {rs:?}"));
    match (rs, py) {
        (Yaml::Mapping(map), Json::Object(obj)) => {
            for (key, value) in map {
                let key = key.as_str().unwrap_or_default();
                let Some(other) = obj.get(key) else {
                    return Err(format!("{path}.{key}: missing in python"));
                };
                compare(&format!("{path}.{key}"), other, value)?;
            }
            Ok(())
        }
        (Yaml::Sequence(items), Json::Array(others)) if items.len() == others.len() => items
            .iter()
            .zip(others)
            .enumerate()
            .try_for_each(|(i, (r, p))| compare(&format!("{path}[{i}]"), p, r)),
        (Yaml::Number(n), Json::String(s)) if n.is_f64() => {
            if same_float(s, n.as_f64().unwrap_or(f64::NAN)) {
                Ok(())
            } else {
                mismatch()
            }
        }
        (Yaml::Number(n), Json::Number(m)) if !n.is_f64() => {
            if n.as_i64() == m.as_i64() && n.as_u64() == m.as_u64() {
                Ok(())
            } else {
                mismatch()
            }
        }
        (Yaml::String(a), Json::String(b)) if a == b => Ok(()),
        (Yaml::Bool(a), Json::Bool(b)) if a == b => Ok(()),
        _ => mismatch(),
    }
}

fn run_python(script: &str, arg: &Path) -> Option<std::process::Output> {
    let mut python = checker_python()?;
    let out = python
        .arg(format!("tests/python/{script}"))
        .arg(arg)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{script} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(out)
}

#[test]
fn rosbags_and_mcap_ros2_decode_the_project_bag_field_by_field() {
    let tmp = tempfile::tempdir().unwrap();
    for storage in [StorageId::Mcap, StorageId::Sqlite3] {
        let dir = tmp.path().join(format!("project_{storage}"));
        let expected = write_project_bag(&dir, storage);
        let Some(out) = run_python("bag_decode.py", &dir) else {
            return;
        };
        let decoded: Json = serde_json::from_slice(&out.stdout).unwrap();
        let decoders: &[&str] = if storage == StorageId::Mcap {
            &["rosbags", "mcap_ros2"]
        } else {
            &["rosbags"]
        };
        for decoder in decoders {
            for topic in ["/scan", "/odom", "/human/markers", "/human/activity", "/tf"] {
                let got = decoded[decoder][topic]
                    .as_array()
                    .unwrap_or_else(|| panic!("{decoder}: no {topic}"));
                let want: Vec<_> = expected.iter().filter(|(t, _, _)| t == topic).collect();
                assert_eq!(got.len(), want.len(), "{decoder} {topic}");
                for (g, (_, time, value)) in got.iter().zip(want) {
                    assert_eq!(g["log_time"].as_i64(), Some(*time), "{decoder} {topic}");
                    if let Err(e) =
                        compare(&format!("{decoder} {storage} {topic}"), &g["msg"], value)
                    {
                        panic!("{e}");
                    }
                }
            }
        }
        assert_eq!(
            decoded["topics"]["/human/activity"]["type"],
            "lidar_har_msgs/msg/Activity"
        );
    }
}

/// Bags record each topic's RIHS01 type hash, a constant next to each definition
/// (`MessageDefinition::type_hash`). rosbags recomputes every one from our schema text, and,
/// for the standard types, from its own Jazzy definitions: a wrong or missing constant fails.
/// Three of them equal values published elsewhere: LaserScan `RIHS01_64c19139…bd828`,
/// TFMessage `RIHS01_e369d0f0…0f087`, Odometry `RIHS01_3cc97dc7…ec6e0` (see docs/msgs.md).
#[test]
fn every_type_hash_is_the_rihs01_hash_rosbags_computes_from_its_schema() {
    let tmp = tempfile::tempdir().unwrap();
    let schemas: Vec<Json> = lidar_har_msgs::schema::ALL
        .iter()
        .map(|def| serde_json::json!({"type": def.type_name, "schema": def.schema_text()}))
        .collect();
    let input = tmp.path().join("schemas.json");
    std::fs::write(&input, serde_json::to_vec(&schemas).unwrap()).unwrap();
    let Some(out) = run_python("type_hashes.py", &input) else {
        return;
    };
    let computed: Json = serde_json::from_slice(&out.stdout).unwrap();
    let mut standard = 0;
    for def in lidar_har_msgs::schema::ALL {
        let by_rosbags = &computed[def.type_name];
        assert_eq!(
            by_rosbags["ours"].as_str(),
            Some(def.type_hash),
            "{}: the type_hash constant is not the hash of its schema",
            def.type_name
        );
        if def.package() == "lidar_har_msgs" {
            assert!(by_rosbags["jazzy"].is_null(), "{}", def.type_name);
        } else {
            assert_eq!(
                by_rosbags["jazzy"].as_str(),
                Some(def.type_hash),
                "{}: not Jazzy's hash",
                def.type_name
            );
            standard += 1;
        }
    }
    assert_eq!(standard, lidar_har_msgs::schema::ALL.len() - 3);
}

/// Sqlite3 bags of Foxy and Humble store no message definitions; `bag convert` gives their
/// topics lidar-har's, which are Humble's. Foxy's Marker lacks fields Humble's has: its
/// messages were written under Humble's definition, and no reader could decode the new bag.
/// A damaged message of a Humble bag is copied as it is, as in a bag with definitions.
#[test]
fn bag_convert_refuses_a_type_whose_layout_is_not_its_definitions() {
    let tmp = tempfile::tempdir().unwrap();
    if run_python("bag_write_sqlite_markers.py", tmp.path()).is_none() {
        return;
    }
    let convert = |name: &str| {
        let out = tmp.path().join(format!("{name}_out"));
        let run = std::process::Command::new(workspace_bin("lidar-har"))
            .args(["bag", "convert"])
            .arg(tmp.path().join(name))
            .arg(&out)
            .output()
            .unwrap();
        (run, out)
    };
    let (run, out) = convert("foxy");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("topic `/human/markers` (visualization_msgs/msg/MarkerArray)")
            && stderr.contains("3 of its 3 messages do not decode")
            && stderr.contains("Foxy"),
        "{stderr}"
    );
    assert!(!out.exists(), "a refusal leaves nothing behind");

    let (run, out) = convert("humble");
    assert!(run.status.success(), "{run:?}");
    let reader = BagReader::open(&out).unwrap();
    // Humble records no type hash; the definitions given are ours, and so is the hash.
    assert_eq!(
        reader
            .topic("/human/markers")
            .unwrap()
            .type_description_hash,
        MarkerArray::DEFINITION.type_hash
    );
    let mut decoded_markers = 0;
    for message in reader.messages().unwrap() {
        let message = message.unwrap();
        if message.topic.as_ref() == "/human/markers" && message.log_time_ns < 1_300_000_000 {
            let markers: MarkerArray = reader.decode(&message).unwrap();
            assert_eq!(markers.markers.len(), 2);
            assert_eq!(markers.markers[1].text, "hi");
            decoded_markers += 1;
        }
    }
    assert_eq!(decoded_markers, 3);
    assert_eq!(
        reader.metadata().message_count,
        8,
        "the damaged rows copied too"
    );
}

#[test]
fn the_project_reads_bags_written_by_rosbags() {
    let tmp = tempfile::tempdir().unwrap();
    if run_python("bag_write_rosbags.py", tmp.path()).is_none() {
        return;
    }
    for name in ["mcap_v8", "mcap_v9", "sqlite3_v8", "sqlite3_v9"] {
        let reader =
            BagReader::open(tmp.path().join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(reader.metadata().message_count, 40, "{name}");
        assert_eq!(
            reader.topic("/odom").unwrap().offered_qos[0].to_profile(),
            Some(QosProfile::reliable(7)),
            "{name}: QoS"
        );
        let (mut scans, mut odoms) = (0, 0);
        for message in reader.messages().unwrap() {
            let message = message.unwrap();
            let i = ((message.log_time_ns - 1_000_000_000) / 50_000_000) as i32;
            match &*message.topic {
                "/scan" => {
                    let s: LaserScan = reader.decode(&message).unwrap();
                    assert_eq!(s.header.stamp.sec, i);
                    assert_eq!(s.header.frame_id, "laser");
                    assert_eq!(s.ranges[0], 0.5 * i as f32);
                    assert!(
                        s.ranges[1] == f32::INFINITY && s.ranges[2].is_nan() && s.ranges[3] == 1.25
                    );
                    assert_eq!(s.intensities, [1.0, 2.0, 3.0, 4.0]);
                    scans += 1;
                }
                "/odom" => {
                    let o: Odometry = reader.decode(&message).unwrap();
                    assert_eq!(o.pose.pose.position.x, 0.1 * f64::from(i));
                    assert_eq!(o.child_frame_id, "base_link");
                    assert!(
                        o.pose
                            .covariance
                            .iter()
                            .enumerate()
                            .all(|(k, c)| *c == 0.5 * k as f64)
                    );
                    assert_eq!(o.twist.twist.angular.z, 0.3);
                    odoms += 1;
                }
                other => panic!("{name}: unexpected topic {other}"),
            }
        }
        assert_eq!((scans, odoms), (20, 20), "{name}");
    }
}

/// rosbag2 Humble reads metadata.yaml's `offered_qos_profiles` as a string and each QoS enum
/// as an integer, in metadata.yaml and in the storage file: a version-9 bag stops its
/// `ros2 bag info` and `play` (ros2/rosbag2#2013). `bag convert --rosbag2-version 8` writes
/// that form in both (MCAP channel metadata, sqlite `topics` rows), which `rosbags` and the
/// project read back with `/map` still transient local.
#[test]
fn bag_convert_to_version_8_writes_qos_as_humble_reads_it() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("jazzy");
    let mut writer = BagWriter::create(&src, WriterOptions::default()).unwrap();
    let map = writer
        .add_topic_for::<Activity>("/map", QosProfile::latched(1))
        .unwrap();
    let scan_topic = writer
        .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
        .unwrap();
    for i in 0..3 {
        let time = 1_000_000_000 + i64::from(i);
        writer.write_message(map, time, &activity(i)).unwrap();
        writer.write_message(scan_topic, time, &scan(i)).unwrap();
    }
    writer.finish().unwrap();
    for storage in [StorageId::Mcap, StorageId::Sqlite3] {
        let dst = tmp.path().join(format!("humble_{storage}"));
        let run = std::process::Command::new(workspace_bin("lidar-har"))
            .args(["bag", "convert"])
            .arg(&src)
            .arg(&dst)
            .args(["--storage", storage.as_str(), "--rosbag2-version", "8"])
            .output()
            .unwrap();
        assert!(run.status.success(), "{run:?}");
        assert!(
            String::from_utf8_lossy(&run.stdout).contains("metadata version 8"),
            "{run:?}"
        );
        let Some(out) = run_python("bag_qos_humble.py", &dst) else {
            return;
        };
        let seen: Json = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(seen["version"], 8, "{storage}: {seen}");
        assert_eq!(seen["messages"], 6, "{storage}: {seen}");
        for (topic, reliability, durability) in [("/map", 1, 1), ("/scan", 2, 2)] {
            for place in ["metadata", "storage"] {
                let profile = &seen["topics"][topic][place][0];
                assert!(
                    profile["reliability"] == reliability && profile["durability"] == durability,
                    "{storage} {topic} {place}: Humble would read {}",
                    seen["topics"][topic][place]
                );
            }
            let by_rosbags = &seen["topics"][topic]["rosbags"][0];
            assert_eq!(by_rosbags["durability"], durability, "{storage}: {seen}");
        }
        let reader = BagReader::open(&dst).unwrap();
        assert_eq!(reader.metadata().metadata_version, Some(8));
        assert_eq!(
            reader.topic("/map").unwrap().offered_qos[0].to_profile(),
            Some(QosProfile::latched(1))
        );
    }
    let Some(out) = run_python("bag_qos_humble.py", &src) else {
        return;
    };
    let seen: Json = serde_json::from_slice(&out.stdout).unwrap();
    assert!(
        seen["topics"]["/map"]["metadata"]
            .as_str()
            .is_some_and(|why| why.contains("not a string")),
        "version 9 is what Humble cannot read: {seen}"
    );
}
