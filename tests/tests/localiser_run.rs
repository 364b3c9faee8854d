//! `lidar-har run` end to end on a hand-made robot bag: a square room on /map, a robot
//! driving with /odom and a Lidar mounted off-centre (/tf_static), a person walking round,
//! ground truth on /ground_truth/human_pose. Checks the output bag and summary.json, and the
//! errors for a missing map, a garbled map and a missing bag.

use std::path::Path;
use std::process::Command;

use glam::DVec2;
use lidar_har_bag::{BagReader, BagWriter, WriterOptions};
use lidar_har_e2e::workspace_bin;
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::geometry_msgs::{
    Pose, PoseStamped, Quaternion, Transform, TransformStamped, Vector3,
};
use lidar_har_msgs::lidar_har_msgs::HumanObservation;
use lidar_har_msgs::nav_msgs::{MapMetaData, OccupancyGrid, Odometry};
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_msgs::topics;
use lidar_har_msgs::visualization_msgs::MarkerArray;

const HALF: f64 = 5.0;
const RES: f64 = 0.05;
const MOUNT_X: f64 = 0.15;
const PERSON_RADIUS: f64 = 0.2;

fn robot(t: f64) -> (DVec2, f64) {
    (DVec2::new(-2.0 + 0.15 * t, -1.5), 0.2 * t)
}

fn person(t: f64) -> DVec2 {
    DVec2::new(1.0 + 1.8 * (0.4 * t).cos(), 0.5 + 1.8 * (0.4 * t).sin())
}

fn ranges(laser: DVec2, heading: f64, person: DVec2) -> Vec<f32> {
    let wall = HALF - RES;
    (0..720)
        .map(|i| {
            let d = DVec2::from_angle(
                heading - std::f64::consts::PI + i as f64 * std::f64::consts::TAU / 720.0,
            );
            let tx = if d.x > 0.0 {
                (wall - laser.x) / d.x
            } else {
                (-wall - laser.x) / d.x
            };
            let ty = if d.y > 0.0 {
                (wall - laser.y) / d.y
            } else {
                (-wall - laser.y) / d.y
            };
            let oc = laser - person;
            let b = oc.dot(d);
            let disc = b * b - (oc.length_squared() - PERSON_RADIUS * PERSON_RADIUS);
            let hit = if disc >= 0.0 && -b - disc.sqrt() > 0.0 {
                -b - disc.sqrt()
            } else {
                f64::INFINITY
            };
            tx.min(ty).min(hit) as f32
        })
        .collect()
}

fn header(t: f64, frame: &str) -> Header {
    Header::new(Time::from_nanos((t * 1e9) as i64), frame)
}

/// Writes the robot bag: 10 s, scans at 20 Hz, odometry at 50 Hz.
fn write_bag(dir: &Path) {
    let mut w = BagWriter::create(dir, WriterOptions::default()).unwrap();
    let map_t = w
        .add_topic_for::<OccupancyGrid>(topics::MAP.name, topics::MAP.qos)
        .unwrap();
    let tf_t = w
        .add_topic_for::<TFMessage>(topics::TF_STATIC.name, topics::TF_STATIC.qos)
        .unwrap();
    let odom_t = w
        .add_topic_for::<Odometry>(topics::ODOM.name, topics::ODOM.qos)
        .unwrap();
    let scan_t = w
        .add_topic_for::<LaserScan>(topics::SCAN.name, topics::SCAN.qos)
        .unwrap();
    let gt_t = w
        .add_topic_for::<PoseStamped>(
            topics::GROUND_TRUTH_POSE.name,
            topics::GROUND_TRUTH_POSE.qos,
        )
        .unwrap();
    let n = (2.0 * HALF / RES) as usize;
    let data = (0..n * n)
        .map(|i| {
            if i % n == 0 || i % n == n - 1 || i / n == 0 || i / n == n - 1 {
                100
            } else {
                0
            }
        })
        .collect();
    let grid = OccupancyGrid {
        header: header(0.0, "map"),
        info: MapMetaData {
            resolution: RES as f32,
            width: n as u32,
            height: n as u32,
            origin: Pose::from_xy_yaw(-HALF, -HALF, 0.0),
            ..MapMetaData::default()
        },
        data,
    };
    w.write_message(map_t, 0, &grid).unwrap();
    let mount = TransformStamped {
        header: header(0.0, "base_link"),
        child_frame_id: "laser".into(),
        transform: Transform {
            translation: Vector3::new(MOUNT_X, 0.0, 0.2),
            rotation: Quaternion::IDENTITY,
        },
    };
    w.write_message(
        tf_t,
        0,
        &TFMessage {
            transforms: vec![mount],
        },
    )
    .unwrap();
    // Merge both rates in time order: odometry every 20 ms, scans every 50 ms.
    let mut events: Vec<(i64, bool)> = (0..=500).map(|k| (k * 20_000_000, false)).collect();
    events.extend((1..200).map(|k| (k * 50_000_000 + 1, true)));
    events.sort();
    for (ns, is_scan) in events {
        let t = ns as f64 * 1e-9;
        let (base, heading) = robot(t);
        if is_scan {
            let laser = base + DVec2::from_angle(heading) * MOUNT_X;
            let scan = LaserScan {
                header: header(t, "laser"),
                angle_min: -std::f32::consts::PI,
                angle_max: std::f32::consts::PI,
                angle_increment: (std::f64::consts::TAU / 720.0) as f32,
                range_min: 0.1,
                range_max: 12.0,
                ranges: ranges(laser, heading, person(t)),
                ..LaserScan::default()
            };
            w.write_message(scan_t, ns, &scan).unwrap();
            let p = person(t);
            let gt = PoseStamped {
                header: header(t, "map"),
                pose: Pose::from_xy_yaw(p.x, p.y, 0.0),
            };
            w.write_message(gt_t, ns, &gt).unwrap();
        } else {
            let mut odom = Odometry {
                header: header(t, "odom"),
                child_frame_id: "base_link".into(),
                ..Odometry::default()
            };
            odom.pose.pose = Pose::from_xy_yaw(base.x, base.y, heading);
            w.write_message(odom_t, ns, &odom).unwrap();
        }
    }
    w.finish().unwrap();
}

fn lidar_har(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(workspace_bin("lidar-har"))
        .arg("run")
        .args(args)
        .output()
        .expect("lidar-har runs")
}

#[test]
fn run_tracks_the_person_in_a_robot_bag_and_writes_outputs_and_summary() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    let out = tmp.path().join("out");
    write_bag(&input);
    let output = lidar_har(&[
        "--bag".as_ref(),
        input.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    eprintln!("{summary:#}");
    assert_eq!(summary["scans"], 199);
    assert_eq!(summary["room"], "map");
    assert_eq!(summary["motion"], "odometry");
    assert!(summary["visible_ratio"].as_f64().unwrap() > 0.95);
    // The Lidar sees the near half of a 0.2 m cylinder: its centroid is ~0.16 m from the centre.
    let median = summary["position_error_m"]["median"].as_f64().unwrap();
    let p95 = summary["position_error_m"]["p95"].as_f64().unwrap();
    assert!(median < 0.2 && p95 < 0.3, "median {median}, p95 {p95}");
    assert!(summary["scan_time_us"]["median"].as_f64().unwrap() > 0.0);
    assert!(summary["scan_time_us"]["p99"].as_f64().is_some());
    assert_eq!(summary["tracks_confirmed"], 1);

    let reader = BagReader::open(&out).unwrap();
    for topic in [
        topics::HUMAN_POSE,
        topics::HUMAN_OBSERVATION,
        topics::HUMAN_MARKERS,
    ] {
        let info = reader
            .topic(topic.name)
            .unwrap_or_else(|| panic!("{} written", topic.name));
        assert_eq!(info.type_name, topic.type_name);
    }
    let mut observations = 0;
    for m in reader.messages().unwrap() {
        let m = m.unwrap();
        match &*m.topic {
            "/human/observation" => {
                let o: HumanObservation = reader.decode(&m).unwrap();
                assert_eq!(o.header.frame_id, "map");
                assert_eq!(o.track_id, 1);
                observations += 1;
            }
            "/human/markers" => {
                let markers: MarkerArray = reader.decode(&m).unwrap();
                assert!(!markers.markers.is_empty());
            }
            _ => {}
        }
    }
    assert!(observations > 190, "{observations} observations");
}

#[test]
fn run_with_a_map_file_uses_it() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    write_bag(&input);
    // The same room as a map_server map (white free space, black walls).
    let n = (2.0 * HALF / RES) as usize;
    let mut pgm = format!("P5\n{n} {n}\n255\n").into_bytes();
    pgm.extend((0..n * n).map(|i| {
        if i % n == 0 || i % n == n - 1 || i / n == 0 || i / n == n - 1 {
            0u8
        } else {
            254
        }
    }));
    std::fs::write(tmp.path().join("room.pgm"), pgm).unwrap();
    let yaml = tmp.path().join("room.yaml");
    std::fs::write(&yaml, format!("image: room.pgm\nresolution: {RES}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n", -HALF, -HALF)).unwrap();
    let out = tmp.path().join("out");
    let output = lidar_har(&[
        "--bag".as_ref(),
        input.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--map".as_ref(),
        yaml.as_os_str(),
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert!(summary["visible_ratio"].as_f64().unwrap() > 0.95);
}

#[test]
fn bad_inputs_give_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    write_bag(&input);
    let out = tmp.path().join("out");
    let missing_map = tmp.path().join("no_such_map.yaml");
    let output = lidar_har(&[
        "--bag".as_ref(),
        input.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--map".as_ref(),
        missing_map.as_os_str(),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("no_such_map.yaml") && stderr.contains("cannot read"),
        "{stderr}"
    );

    let garbled = tmp.path().join("garbled.yaml");
    std::fs::write(&garbled, "image: [this is not\n").unwrap();
    let output = lidar_har(&[
        "--bag".as_ref(),
        input.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--map".as_ref(),
        garbled.as_os_str(),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("garbled.yaml") && stderr.contains("not a valid map_server map"),
        "{stderr}"
    );

    let no_bag = tmp.path().join("no_such_bag");
    let output = lidar_har(&[
        "--bag".as_ref(),
        no_bag.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("no_such_bag"), "{stderr}");

    let config = tmp.path().join("bad_config.yaml");
    std::fs::write(&config, "gate: 0.8\n").unwrap();
    let output = lidar_har(&[
        "--bag".as_ref(),
        input.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--config".as_ref(),
        config.as_os_str(),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("bad_config.yaml") && stderr.contains("unknown field `gate`"),
        "{stderr}"
    );
}
