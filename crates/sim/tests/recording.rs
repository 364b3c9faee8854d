//! Recording: the bag holds every topic of the contract with consistent stamps, the same
//! scene and seed give byte-identical output, and every shipped scene runs.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use lidar_har_bag::BagReader;
use lidar_har_msgs::lidar_har_msgs::Activity as ActivityMsg;
use lidar_har_msgs::nav_msgs::{OccupancyGrid, Odometry};
use lidar_har_msgs::rosgraph_msgs::Clock;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_sim::record::record;
use lidar_har_sim::{Scene, Simulator};

fn scenes_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes")
}

fn short(name: &str, seconds: f64) -> Scene {
    let mut s = Scene::load(&scenes_dir().join(name)).expect("shipped scene loads");
    s.duration = seconds;
    s
}

fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect()
}

#[test]
fn same_scene_and_seed_give_byte_identical_bags() {
    let tmp = tempfile::tempdir().unwrap();
    let mut outputs = Vec::new();
    for (k, seed) in [(0, 5u64), (1, 5), (2, 6)] {
        // Same directory name each time: the storage file is named after it.
        let dir = tmp.path().join(format!("run{k}")).join("bag");
        let mut sim = Simulator::new(short("living_room.yaml", 2.0), seed).unwrap();
        record(&mut sim, &dir, 0.05, |_| {}).unwrap();
        outputs.push(files(&dir));
    }
    assert_eq!(
        outputs[0].keys().collect::<Vec<_>>(),
        vec!["bag_0.mcap", "map.pgm", "map.yaml", "metadata.yaml"]
    );
    assert!(outputs[0] == outputs[1], "same seed, different bytes");
    assert_ne!(
        outputs[0]["bag_0.mcap"], outputs[2]["bag_0.mcap"],
        "another seed must change the noise"
    );
    assert_eq!(outputs[0]["map.pgm"], outputs[2]["map.pgm"]);
}

#[test]
fn bag_holds_the_contract_topics_with_consistent_stamps() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("living");
    let mut sim = Simulator::new(short("living_room.yaml", 1.5), 1).unwrap();
    let summary = record(&mut sim, &dir, 0.05, |_| {}).unwrap();
    assert_eq!(summary.frames, 30);
    let bag = BagReader::open(&dir).unwrap();
    let count = |t: &str| bag.topic(t).map(|t| t.message_count).unwrap_or(0);
    for t in [
        "/scan",
        "/odom",
        "/tf",
        "/clock",
        "/ground_truth/human_pose",
        "/ground_truth/activity",
    ] {
        assert_eq!(count(t), 30, "{t}");
    }
    assert_eq!(count("/map"), 1);
    assert_eq!(count("/tf_static"), 1);
    assert_eq!(bag.topic("/map").unwrap().offered_qos.len(), 1);

    let start = 1_700_000_000_000_000_000i64;
    let mut scans = 0i64;
    for m in bag.messages().unwrap() {
        let m = m.unwrap();
        match &*m.topic {
            "/scan" => {
                let s: LaserScan = bag.decode(&m).unwrap();
                assert_eq!(s.header.frame_id, "laser");
                assert_eq!(s.ranges.len(), 720);
                assert_eq!(s.header.stamp.to_nanos(), m.log_time_ns);
                assert_eq!(m.log_time_ns, start + scans * 50_000_000);
                assert!(
                    s.ranges
                        .iter()
                        .all(|r| r.is_infinite() || (s.range_min..=s.range_max).contains(r))
                );
                scans += 1;
            }
            "/clock" => {
                let c: Clock = bag.decode(&m).unwrap();
                assert_eq!(c.clock.to_nanos(), m.log_time_ns);
            }
            "/odom" => {
                let o: Odometry = bag.decode(&m).unwrap();
                assert_eq!(
                    (o.header.frame_id.as_str(), o.child_frame_id.as_str()),
                    ("odom", "base_link")
                );
                assert!(o.twist.twist.linear.x.abs() <= 0.2 + 1e-12);
            }
            "/tf_static" => {
                let tf: TFMessage = bag.decode(&m).unwrap();
                assert_eq!(tf.transforms[0].child_frame_id, "laser");
                assert!((tf.transforms[0].transform.translation.z - 0.10).abs() < 1e-12);
            }
            "/map" => {
                let g: OccupancyGrid = bag.decode(&m).unwrap();
                assert_eq!(g.data.len(), (g.info.width * g.info.height) as usize);
                assert!(g.data.contains(&100) && g.data.contains(&0) && g.data.contains(&-1));
            }
            "/ground_truth/activity" => {
                let a: ActivityMsg = bag.decode(&m).unwrap();
                assert_eq!(a.label, "standing");
                assert_eq!(a.probabilities.iter().sum::<f32>(), 1.0);
                assert_eq!(a.probabilities[a.activity as usize], 1.0);
            }
            _ => {}
        }
    }
    assert_eq!(scans, 30);
}

#[test]
fn every_shipped_scene_simulates() {
    let mut names: Vec<String> = std::fs::read_dir(scenes_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".yaml"))
        .collect();
    names.sort();
    assert!(names.len() >= 6, "{names:?}");
    for (name, seed) in names.iter().flat_map(|n| (0..4u64).map(move |s| (n, s))) {
        let mut sim = Simulator::new(short(name, 1.0), seed)
            .unwrap_or_else(|e| panic!("{name} seed {seed}: {e}"));
        let mut n = 0;
        while let Some(f) = sim.step() {
            assert!(f.robot.is_finite(), "{name}");
            n += 1;
        }
        assert_eq!(n, 20, "{name}");
    }
}

#[test]
fn living_room_script_contains_a_fall() {
    let scene = short("living_room.yaml", 60.0);
    let person = scene.person.as_ref().unwrap();
    assert!(
        person
            .script
            .iter()
            .any(|s| s.activity == lidar_har_core::activity::Activity::FallingDown)
    );
}
