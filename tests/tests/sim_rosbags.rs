//! `lidar-har simulate` makes a bag that independent readers decode: `rosbags` (every
//! message, with its types registered from the bag's own schemas) and `mcap` +
//! `mcap-ros2-support`. Also checks the map_server files and the render.

use lidar_har_bag::BagReader;
use lidar_har_core::map::{MAP_SERVER_OCCUPIED_THRESH, OccupancyMap};
use lidar_har_e2e::{checker_python, lidar_har, repo_root};
use lidar_har_msgs::nav_msgs::OccupancyGrid;
use lidar_har_msgs::topics;
use lidar_har_pipeline::{convert, files};

const CHECK: &str = r#"
import sys, math, collections
from pathlib import Path
from rosbags.highlevel import AnyReader
bag = Path(sys.argv[1])
counts = collections.Counter()
frames = {}
with AnyReader([bag]) as reader:
    for conn, t, raw in reader.messages():
        msg = reader.deserialize(raw, conn.msgtype)
        counts[conn.topic] += 1
        if conn.topic == '/scan':
            assert msg.header.frame_id == 'laser'
            assert len(msg.ranges) == 720
            assert all(math.isinf(r) or msg.range_min <= r <= msg.range_max for r in msg.ranges)
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == t
        if conn.topic == '/ground_truth/activity':
            assert msg.probabilities[msg.activity] == 1.0 and len(msg.probabilities) == 9
        if conn.topic == '/tf_static':
            frames['static'] = (msg.transforms[0].header.frame_id, msg.transforms[0].child_frame_id)
        if conn.topic == '/map':
            assert len(msg.data) == msg.info.width * msg.info.height
from mcap_ros2.reader import read_ros2_messages
mcap_counts = collections.Counter()
for f in bag.glob('*.mcap'):
    for m in read_ros2_messages(str(f)):
        mcap_counts[m.channel.topic] += 1
assert mcap_counts == counts, (mcap_counts, counts)
assert frames['static'] == ('base_link', 'laser')
print(dict(sorted(counts.items())))
"#;

#[test]
fn simulated_bag_reads_in_rosbags_and_mcap() {
    let Some(mut python) = checker_python() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("living");
    let png = tmp.path().join("living.png");
    let status = lidar_har()
        .current_dir(repo_root())
        .args([
            "simulate",
            "--scene",
            "config/scenes/living_room.yaml",
            "--duration",
            "2",
            "--seed",
            "3",
            "--out",
        ])
        .arg(&out)
        .arg("--render")
        .arg(&png)
        .status()
        .unwrap();
    assert!(status.success());
    assert!(out.join("map.pgm").is_file() && out.join("map.yaml").is_file());
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
    let result = python.arg("-c").arg(CHECK).arg(&out).output().unwrap();
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "checker failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&result.stderr)
    );
    for topic in [
        "'/scan': 40",
        "'/odom': 40",
        "'/tf': 40",
        "'/clock': 40",
        "'/map': 1",
        "'/tf_static': 1",
        "'/ground_truth/activity': 40",
        "'/ground_truth/human_pose': 40",
    ] {
        assert!(stdout.contains(topic), "{topic} missing from {stdout}");
    }
}

#[test]
fn simulate_rejects_a_bad_scene_naming_the_key() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("bad.yaml");
    std::fs::write(
        &scene,
        "duration: 5\nroom: {outline: [[0,0],[4,0],[4,4],[0,4]]}\nfurniture: [{kind: box, center: [2,2], size: [-1, 1], height: 1}]\nrobot: {start: {x: 0.5, y: 0.5}}\n",
    )
    .unwrap();
    let output = lidar_har()
        .args(["simulate", "--scene"])
        .arg(&scene)
        .arg("--out")
        .arg(tmp.path().join("out"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("furniture[0].size[0]: must be positive"),
        "{stderr}"
    );
}

#[test]
fn simulate_renders_an_animation_and_refuses_other_formats() {
    let tmp = tempfile::tempdir().unwrap();
    let simulate = |render: &str| {
        lidar_har()
            .current_dir(repo_root())
            .args(["simulate", "--duration", "2", "--out"])
            .arg(tmp.path().join(render.replace('.', "_")))
            .arg("--render")
            // A folder that does not exist yet is made (it failed after the bag was written).
            .arg(tmp.path().join("pictures").join(render))
            .output()
            .unwrap()
    };
    let output = simulate("top.gif");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        std::fs::read(tmp.path().join("pictures/top.gif"))
            .unwrap()
            .starts_with(b"GIF89a")
    );
    let output = simulate("top.jpg");
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("top.jpg") && stderr.contains(".gif"),
        "{stderr}"
    );
}

/// `lidar-har simulate | head -1`, `lidar-har bag info BAG | head -1` and `lidar-har run ...
/// 2>&1 | head -1`: the text stops where the reader left (`println!` and `eprintln!` used to
/// panic there), and the files are written in full.
#[test]
fn commands_finish_their_work_when_the_reader_of_stdout_has_gone() {
    let tmp = tempfile::tempdir().unwrap();
    let bag = tmp.path().join("bag");
    let spawn = |args: &[&std::ffi::OsStr]| {
        let mut child = lidar_har()
            .current_dir(repo_root())
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        child
    };
    let with_stdout_closed = |args: &[&std::ffi::OsStr]| {
        let output = spawn(args).wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr).to_string();
        assert!(output.status.success(), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    };
    // Both closed (`... 2>&1 | head -1`, the reader gone): only the exit status can tell.
    let with_both_closed = |args: &[&std::ffi::OsStr]| {
        let mut child = spawn(args);
        drop(child.stderr.take());
        assert!(child.wait().unwrap().success(), "{args:?}");
    };
    let duration = "2".as_ref();
    with_stdout_closed(&[
        "simulate".as_ref(),
        "--duration".as_ref(),
        duration,
        "--out".as_ref(),
        bag.as_os_str(),
    ]);
    with_stdout_closed(&["bag".as_ref(), "info".as_ref(), bag.as_os_str()]);
    let out = tmp.path().join("run");
    with_both_closed(&[
        "run".as_ref(),
        "--bag".as_ref(),
        bag.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--no-classifier".as_ref(),
    ]);
    assert!(out.join("summary.json").is_file());
    let reader = lidar_har_bag::BagReader::open(&bag).unwrap();
    let scans = reader.topics().iter().find(|t| t.name == "/scan").unwrap();
    assert_eq!(scans.message_count, 40, "2 s of 20 Hz scans");
}

/// The map files the simulator writes beside its bag load as the bag's /map: the same
/// occupied and unknown cells (with map_server's reading of the grey, unknown is not floor).
#[test]
fn the_simulators_map_files_are_its_map_topic() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("living");
    let status = lidar_har()
        .current_dir(repo_root())
        .args(["simulate", "--scene", "config/scenes/living_room.yaml"])
        .args(["--duration", "1", "--seed", "1", "--out"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let from_files = files::load_map(&out.join("map.yaml")).unwrap();
    let grid = BagReader::open(&out)
        .unwrap()
        .messages_on(&[topics::MAP.name])
        .unwrap()
        .map(|m| lidar_har_msgs::decode::<OccupancyGrid>(&m.unwrap().data).unwrap())
        .next()
        .expect("a /map message");
    let from_topic = convert::map_from_grid(&grid, MAP_SERVER_OCCUPIED_THRESH).unwrap();
    let g = from_topic.geometry();
    let f = from_files.geometry();
    // The message carries the resolution as a float32.
    assert!((f.resolution - g.resolution).abs() < 1e-6, "{f:?} {g:?}");
    assert_eq!((f.origin, f.width, f.height), (g.origin, g.width, g.height));
    let cells = |map: &OccupancyMap, test: fn(&OccupancyMap, usize, usize) -> bool| {
        (0..g.height)
            .flat_map(|row| (0..g.width).map(move |col| (col, row)))
            .filter(|&(col, row)| test(map, col, row))
            .collect::<Vec<_>>()
    };
    let unknown = cells(&from_topic, OccupancyMap::is_unknown);
    assert!(
        !unknown.is_empty(),
        "the living room's map has unknown cells"
    );
    assert_eq!(cells(&from_files, OccupancyMap::is_unknown), unknown);
    assert_eq!(
        cells(&from_files, OccupancyMap::is_occupied),
        cells(&from_topic, OccupancyMap::is_occupied)
    );
}

/// The metadata.yaml `version` of the bag in `dir`, and whether its topics' QoS are the
/// YAML string that versions 8 and older store (Humble and Iron read only that form).
fn metadata_version_and_qos_form(dir: &std::path::Path) -> (u64, Vec<bool>) {
    let text = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
    let yaml: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).unwrap();
    let info = &yaml["rosbag2_bagfile_information"];
    let qos_as_string = info["topics_with_message_count"]
        .as_sequence()
        .unwrap()
        .iter()
        .map(|t| t["topic_metadata"]["offered_qos_profiles"].is_string())
        .collect();
    (info["version"].as_u64().unwrap(), qos_as_string)
}

/// `simulate` and `run` wrote only version 9, which Humble's and Iron's `ros2 bag info` and
/// `play` cannot parse (ros2/rosbag2#2013), even over a Humble recording. `simulate
/// --rosbag2-version 8` writes 8, and `run` keeps its input's 8 unless told otherwise; Humble
/// reads their QoS (bag_qos_humble.py, as for `bag convert`).
#[test]
fn simulate_and_run_write_version_8_for_humble_and_iron() {
    let tmp = tempfile::tempdir().unwrap();
    let [sim, run8, run9] = ["sim", "run8", "run9"].map(|name| tmp.path().join(name));
    let ok = |command: &mut std::process::Command| {
        let output = command.current_dir(repo_root()).output().unwrap();
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
    };
    ok(lidar_har()
        .args([
            "simulate",
            "--duration",
            "1",
            "--rosbag2-version",
            "8",
            "--out",
        ])
        .arg(&sim));
    ok(lidar_har()
        .args(["run", "--no-classifier", "--bag"])
        .arg(&sim)
        .arg("--out")
        .arg(&run8));
    ok(lidar_har()
        .args(["run", "--no-classifier", "--rosbag2-version", "9", "--bag"])
        .arg(&sim)
        .arg("--out")
        .arg(&run9));
    for (dir, version) in [(&sim, 8), (&run8, 8), (&run9, 9)] {
        let (written, qos_as_string) = metadata_version_and_qos_form(dir);
        assert_eq!(written, version, "{}", dir.display());
        assert!(!qos_as_string.is_empty(), "{}", dir.display());
        assert!(
            qos_as_string.iter().all(|&string| string == (version == 8)),
            "{}: {qos_as_string:?}",
            dir.display()
        );
    }
    for dir in [&sim, &run8] {
        let Some(mut python) = checker_python() else {
            return;
        };
        let out = python
            .arg("tests/python/bag_qos_humble.py")
            .arg(dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let seen: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(seen["version"], 8, "{seen}");
        for (topic, read) in seen["topics"].as_object().unwrap() {
            for place in ["metadata", "storage"] {
                assert!(
                    read[place].as_array().is_some_and(|p| !p.is_empty()),
                    "{}: Humble would read {topic}'s {place} QoS as {}",
                    dir.display(),
                    read[place]
                );
            }
        }
    }
}
