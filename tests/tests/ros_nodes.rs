//! The ROS 2 nodes as separate processes over real DDS, inside a private network namespace
//! (DESIGN.md "Network rule"): each test runs one shell script under `unshare -rn` with
//! loopback up and multicast routed to it, so nothing leaves the namespace. Every script runs
//! under `timeout`, so a hung process cannot hang the suite. Tests skip with a message where
//! namespaces are unavailable, and fail instead where `LIDAR_HAR_REQUIRE_CHECKERS` is set (CI).
//! Scripts wait for conditions (a file's lines, topics on the graph) with `wait_until`, not
//! for fixed times.

use std::os::unix::ffi::OsStringExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use lidar_har_bag::{BagWriter, WriterOptions};
use lidar_har_e2e::{
    checker_python, lidar_har, output_within, repo_root, runtime_available, skip_or_fail,
    workspace_bin,
};
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::geometry_msgs::{Point, TransformStamped};
use lidar_har_msgs::lidar_har_msgs::{Activity, FallAlert};
use lidar_har_msgs::nav_msgs::{MapMetaData, OccupancyGrid};
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_msgs::topics;

const NETNS_SETUP: &str =
    "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo";
const T0_NS: i64 = 1_700_000_000_000_000_000;

/// Shell functions every script may use:
/// - `poll SECONDS CMD...`: runs CMD every 50 ms until it succeeds (status 0), or status 1
///   once SECONDS (whole) have passed;
/// - `wait_until SECONDS CMD...`: the same, but a timeout is printed and fails the test;
/// - `has_lines FILE N`: FILE has at least N complete lines;
/// - `topics_listed TOPIC...`: `lidar-har topic list` (`$LH`, listening 1 s) shows each TOPIC;
/// - `echo_count TOPIC N SECONDS NAME [ARG...]`: `lidar-har topic echo` of N messages (fewer
///   within SECONDS fail) into `$OUT/NAME.jsonl`, then prints `NAME=<its exit status>`.
const SCRIPT_FUNCTIONS: &str = r#"
poll() { _end=$(( $(date +%s%N) + $1 * 1000000000 )); shift
  until "$@"; do [ "$(date +%s%N)" -lt "$_end" ] || return 1; sleep 0.05; done; }
wait_until() { poll "$@" || echo "wait_until timed out: $*"; }
has_lines() { [ -f "$1" ] && [ "$(wc -l < "$1")" -ge "$2" ]; }
topics_listed() { _t=$("$LH" topic list --wait 1) || return 1
  for _x in "$@"; do printf '%s\n' "$_t" | grep -qx "$_x" || return 1; done; }
echo_count() { _t=$1; _n=$2; _s=$3; _f=$4; shift 4
  "$LH" topic echo "$_t" --count "$_n" --timeout "$_s" --require-count "$@" > "$OUT/$_f.jsonl"
  echo "$_f=$?"; }
"#;

/// Whether `unshare -rn` with a multicast loopback works here. Where it does not, the test
/// skips with the reason, or fails where `LIDAR_HAR_REQUIRE_CHECKERS` is set (CI, where it
/// works: a DDS test must not pass there without running).
fn netns_available() -> bool {
    let why = match Command::new("unshare")
        .args(["-rn", "sh", "-c", NETNS_SETUP])
        .output()
    {
        Ok(o) if o.status.success() => return true,
        Ok(o) => format!(
            "{}: {}",
            o.status,
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => e.to_string(),
    };
    skip_or_fail(
        &format!(
            "cannot create a private network namespace with a multicast loopback \
             (`unshare -rn` + `ip`: {why}); the DDS tests need one"
        ),
        "install util-linux and iproute2 (scripts/setup.sh does) and allow unprivileged user \
         namespaces (sysctl kernel.unprivileged_userns_clone=1; in a container, a seccomp \
         profile that permits unshare)",
    );
    false
}

/// Runs `script` with `sh` in a fresh network namespace, killed after `limit`. `vars` are
/// exported to it. Fails the test if the script ran past `limit` or a `wait_until` timed out.
fn in_netns(script: &str, vars: &[(&str, &Path)], limit: Duration) -> Output {
    let mut cmd = Command::new("timeout");
    cmd.args([
        "-k",
        "3",
        &format!("{}", limit.as_secs()),
        "unshare",
        "-rn",
        "sh",
        "-c",
    ])
    .arg(format!(
        "set -u; {NETNS_SETUP} || exit 90\n{SCRIPT_FUNCTIONS}\n{script}"
    ));
    for (k, v) in vars {
        cmd.env(k, v);
    }
    let out = cmd.output().expect("run timeout/unshare");
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("--- script stdout\n{stdout}");
    eprintln!(
        "--- script stderr\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_ne!(
        out.status.code(),
        Some(124),
        "the script ran past its {limit:?} limit"
    );
    assert_ne!(
        out.status.code(),
        Some(90),
        "the namespace's loopback could not be set up"
    );
    assert!(
        !stdout.contains("wait_until timed out"),
        "a condition the script waited for never came: {stdout}"
    );
    out
}

/// [`in_netns`] with `$LH` (the `lidar-har` tool), `$REPLAY` (the node), `$BAG` and `$OUT`.
fn replay_in_netns(script: &str, bag: &Path, out: &Path, limit: Duration) -> Output {
    let (lh, replay) = (workspace_bin("lidar-har"), workspace_bin("replay"));
    let vars = [
        ("LH", &*lh),
        ("REPLAY", &*replay),
        ("BAG", bag),
        ("OUT", out),
    ];
    in_netns(script, &vars, limit)
}

/// The scripts' waits can fail a test: a condition that never comes is reported, not passed by.
#[test]
fn in_netns_fails_when_a_wait_times_out() {
    if !netns_available() {
        return;
    }
    let quiet = in_netns("wait_until 1 true; echo ok", &[], Duration::from_secs(10));
    assert!(String::from_utf8_lossy(&quiet.stdout).contains("ok"));
    let never = std::panic::catch_unwind(|| {
        in_netns("wait_until 1 false", &[], Duration::from_secs(10));
    });
    assert!(never.is_err(), "a timed-out wait_until must fail the test");
}

fn scan(i: usize) -> LaserScan {
    LaserScan {
        header: Header::new(
            Time::from_nanos(T0_NS + 50_000_000 * (i as i64 + 1)),
            "laser",
        ),
        angle_min: -std::f32::consts::PI,
        angle_max: std::f32::consts::PI,
        angle_increment: std::f32::consts::TAU / 8.0,
        time_increment: 0.0,
        scan_time: 0.05,
        range_min: 0.1,
        range_max: 12.0,
        ranges: vec![i as f32 * 0.25; 8],
        intensities: vec![],
    }
}

/// A bag with a latched /map at the start and `scans` LaserScans at 20 Hz.
fn write_bag(dir: &Path, scans: usize) -> PathBuf {
    let path = dir.join("bag");
    let mut w = BagWriter::create(&path, WriterOptions::default()).unwrap();
    let map_topic = w
        .add_topic_for::<OccupancyGrid>(topics::MAP.name, topics::MAP.qos)
        .unwrap();
    let scan_topic = w
        .add_topic_for::<LaserScan>(topics::SCAN.name, topics::SCAN.qos)
        .unwrap();
    let map = OccupancyGrid {
        header: Header::new(Time::from_nanos(T0_NS), "map"),
        info: MapMetaData {
            resolution: 0.05,
            width: 4,
            height: 3,
            ..Default::default()
        },
        data: vec![0, 100, -1, 0, 0, 0, 100, 100, 0, 0, -1, 0],
    };
    w.write_message(map_topic, T0_NS, &map).unwrap();
    for i in 0..scans {
        let s = scan(i);
        w.write_message(scan_topic, T0_NS + 50_000_000 * (i as i64 + 1), &s)
            .unwrap();
    }
    w.finish().unwrap();
    path
}

fn json_lines(path: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .map(|l| {
            serde_json::from_str(l).unwrap_or_else(|e| {
                panic!("{}: not a complete JSON line: {l:?}: {e}", path.display())
            })
        })
        .collect()
}

/// The scan index a JSON LaserScan was made from (its stamp), checking its content.
fn scan_index(msg: &serde_json::Value) -> usize {
    let stamp = &msg["header"]["stamp"];
    let ns = stamp["sec"].as_i64().unwrap() * 1_000_000_000 + stamp["nanosec"].as_i64().unwrap();
    let i = ((ns - T0_NS) / 50_000_000 - 1) as usize;
    let want = scan(i);
    let ranges: Vec<f32> = msg["ranges"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap() as f32)
        .collect();
    assert_eq!(ranges, want.ranges, "scan {i} content");
    assert_eq!(msg["header"]["frame_id"], "laser");
    i
}

#[test]
fn ros_replay_reaches_topic_echo_skips_missing_topics_and_latches_map() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 60);
    let script = r#"
"$LH" topic echo /scan --count 60 --timeout 15 > "$OUT/scan.jsonl" &
E=$!
# What replay.launch.py asks for; the bag has only /map and /scan, which is fine.
RUST_LOG=warn "$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:=/scan -p topics:="[/scan, /odom, /map, /tf, /tf_static]" \
  -p wait_for_all_acked:=10 2> "$OUT/replay_err.txt" &
R=$!
# /map was published when the replay started, before its first scan; a subscriber joining
# once that scan has come still gets it.
wait_until 20 has_lines "$OUT/scan.jsonl" 1
"$LH" topic echo /map --count 1 --timeout 5 --require-count > "$OUT/map.jsonl"; echo "map_echo=$?"
wait $R; echo "replay=$?"
wait $E; echo "scan_echo=$?"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(40));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["map_echo=0", "replay=0", "scan_echo=0"] {
        assert!(stdout.contains(want), "expected {want}");
    }
    let replay_err = std::fs::read_to_string(dir.path().join("replay_err.txt")).unwrap();
    assert!(
        replay_err.contains("skipping /odom, /tf, /tf_static") && replay_err.contains("/scan"),
        "replay must warn about the requested topics the bag lacks: {replay_err}"
    );
    // Its /clock used to clash with the parameter server's /clock reader of another type.
    assert!(!replay_err.contains("ERROR"), "{replay_err}");
    let map = json_lines(&dir.path().join("map.jsonl"));
    assert_eq!(map.len(), 1);
    assert_eq!(map[0]["type"], "nav_msgs/msg/OccupancyGrid");
    assert_eq!(map[0]["msg"]["info"]["width"], 4);
    assert_eq!(
        map[0]["msg"]["data"],
        serde_json::json!([0, 100, -1, 0, 0, 0, 100, 100, 0, 0, -1, 0])
    );

    let scans = json_lines(&dir.path().join("scan.jsonl"));
    let indices: Vec<usize> = scans.iter().map(|l| scan_index(&l["msg"])).collect();
    // /scan (offered reliable, the echo following it): in order, no duplicates; on loopback
    // at 20 Hz all arrive once the subscriber is matched.
    assert!(
        indices.windows(2).all(|w| w[0] < w[1]),
        "out of order or duplicated: {indices:?}"
    );
    assert!(
        indices.len() >= 55,
        "only {} of 60 scans arrived: {indices:?}",
        indices.len()
    );
}

/// [`write_bag`]'s bag as a killed recorder leaves it: small chunks, the file cut at 60 %
/// (inside a chunk, before its summary), no metadata.yaml (rosbag2 writes it at the end).
/// Returns the bag, its storage file and how many complete scans that file still holds.
fn write_cut_bag(dir: &Path, scans: usize) -> (PathBuf, PathBuf, usize) {
    let path = dir.join("cut_bag");
    let options = WriterOptions {
        chunk_size: 512,
        ..WriterOptions::default()
    };
    let mut w = BagWriter::create(&path, options).unwrap();
    let scan_topic = w
        .add_topic_for::<LaserScan>(topics::SCAN.name, topics::SCAN.qos)
        .unwrap();
    for i in 0..scans {
        w.write_message(scan_topic, T0_NS + 50_000_000 * (i as i64 + 1), &scan(i))
            .unwrap();
    }
    w.finish().unwrap();
    std::fs::remove_file(path.join("metadata.yaml")).unwrap();
    let file = std::fs::read_dir(&path)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .unwrap();
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let reader = lidar_har_bag::BagReader::open(&path).unwrap();
    let complete = reader.messages().unwrap().take_while(Result::is_ok).count();
    assert!(
        (5..scans).contains(&complete),
        "{complete} of {scans} scans before the cut"
    );
    (path, file, complete)
}

/// A bag cut short (a killed recorder) is played up to the cut with a warning naming the file
/// and its complete messages; without `loop` the replay then waits for acknowledgements and
/// exits with status 1 and the error, with `loop` it plays the bag again until a signal
/// (status 0). It used to exit with status 1 at the cut, without the "played" line or the
/// wait, and `loop:=true` never looped.
#[test]
fn ros_replay_plays_a_bag_cut_short_to_the_cut_and_loops_it() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (bag, file, complete) = write_cut_bag(dir.path(), 40);
    let script = format!(
        r#"
"$LH" topic echo /scan --timeout 60 > "$OUT/once.jsonl" & E=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:=/scan 2> "$OUT/once_err.txt"
echo "replay=$?"
poll 2 has_lines "$OUT/once.jsonl" {complete}; kill -TERM $E; wait $E
"$LH" topic echo /scan --timeout 60 > "$OUT/loop.jsonl" & E=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p loop:=true -p rate:=4.0 -p wait_for_subscriber:=/scan 2> "$OUT/loop_err.txt" &
R=$!
# A second pass comes.
wait_until 30 has_lines "$OUT/loop.jsonl" {second_pass}
kill -TERM $R; wait $R; echo "loop_replay=$?"
kill -TERM $E; wait $E
"#,
        second_pass = complete + 3
    );
    let out = replay_in_netns(&script, &bag, dir.path(), Duration::from_secs(90));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=1", "loop_replay=0"] {
        assert!(stdout.contains(want), "expected {want}: {stdout}");
    }
    let warning = format!(
        "{}: MCAP file is truncated (e.g. the recorder was killed) after {complete} complete \
         messages",
        file.display()
    );
    let once_err = std::fs::read_to_string(dir.path().join("once_err.txt")).unwrap();
    let lines: Vec<&str> = once_err.lines().collect();
    let warned = lines
        .iter()
        .position(|l| l.contains("WARN") && l.contains(&warning))
        .unwrap_or_else(|| panic!("no warning naming the cut: {once_err}"));
    let played = lines
        .iter()
        .position(|l| l.contains(&format!("played {complete} messages")))
        .unwrap_or_else(|| panic!("the pass must finish: {once_err}"));
    let last = lines.last().unwrap();
    assert!(
        warned < played && last.contains("replay: error") && last.contains(&warning),
        "the error comes last, after the pass: {once_err}"
    );
    let once: Vec<usize> = json_lines(&dir.path().join("once.jsonl"))
        .iter()
        .map(|l| scan_index(&l["msg"]))
        .collect();
    assert!(
        once.len() + 2 >= complete && once.iter().all(|i| *i < complete),
        "{} of the {complete} scans before the cut arrived: {once:?}",
        once.len()
    );
    let loop_err = std::fs::read_to_string(dir.path().join("loop_err.txt")).unwrap();
    assert_eq!(
        loop_err.matches(&warning).count(),
        1,
        "warned once, not every pass: {loop_err}"
    );
    assert!(!loop_err.contains("replay: error"), "{loop_err}");
    let looped: Vec<usize> = json_lines(&dir.path().join("loop.jsonl"))
        .iter()
        .map(|l| scan_index(&l["msg"]))
        .collect();
    assert!(
        looped.windows(2).any(|w| w[1] < w[0]),
        "the bag was not played again: {looped:?}"
    );
}

/// A subscriber that was already running gets the transient-local /map of a replay that ends
/// at once: the replay used to exit before discovery had matched it (RustDDS's wait for
/// acknowledgements returns at once while no reader has matched).
#[test]
fn ros_a_short_replay_reaches_a_subscriber_that_was_already_running() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 2);
    let script = r#"
"$LH" topic echo /map --count 1 --timeout 30 --require-count > "$OUT/map.jsonl" & E=$!
# The echo's reader is on the graph before the replay starts.
wait_until 20 topics_listed /map
# Discovery may take a while on a loaded machine: allow it 10 s.
"$REPLAY" --ros-args -p bag:="$BAG" -p topics:="[/map]" -p wait_for_all_acked:=10; echo "replay=$?"
wait $E; echo "echo=$?"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=0", "echo=0"] {
        assert!(stdout.contains(want), "expected {want}");
    }
    assert_eq!(json_lines(&dir.path().join("map.jsonl")).len(), 1);
}

/// With `loop`, a pass lasts at least a second of bag time: a selection spanning no bag time
/// (a lone /map) used to be published again and again at once, thousands a second.
#[test]
fn ros_replay_loops_a_lone_map_once_a_second() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 2);
    let script = r#"
"$LH" topic echo /map --timeout 60 > "$OUT/map.jsonl" & E=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p topics:="[/map]" -p loop:=true -p wait_for_subscriber:=/map &
R=$!
# It loops: a second /map comes.
wait_until 20 has_lines "$OUT/map.jsonl" 2
before=$(wc -l < "$OUT/map.jsonl"); sleep 3; after=$(wc -l < "$OUT/map.jsonl")
echo "maps_in_3s=$((after - before))"
kill -TERM $R; wait $R; echo "replay=$?"
kill -TERM $E; wait $E; echo "echo=$?"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=0", "echo=0"] {
        assert!(stdout.contains(want), "expected {want}");
    }
    let maps: usize = stdout
        .lines()
        .find_map(|l| l.strip_prefix("maps_in_3s="))
        .and_then(|v| v.trim().parse().ok())
        .expect("count printed");
    // About three (one a second); a slow machine may show fewer, never many more.
    assert!(maps <= 6, "{maps} /map in 3 s: the loop does not pause");
}

/// Bag time (ns since [`T0_NS`]) of a /clock JSON line.
fn clock_ns(line: &serde_json::Value) -> i64 {
    let clock = &line["msg"]["clock"];
    clock["sec"].as_i64().unwrap() * 1_000_000_000 + clock["nanosec"].as_i64().unwrap() - T0_NS
}

/// /clock ticks at `clock_frequency` (40 Hz, as `ros2 bag play --clock`) with the bag time of
/// the moment: it used to be published once per message, with its stamp, and never in a gap
/// between messages. With `start_offset` the first scans keep their recorded spacing: the
/// pace used to start before the part of the bag before the offset had been read through.
#[test]
fn ros_replay_clock_ticks_through_gaps_and_an_offset_keeps_the_pace() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // Scans 0..20 and 40..60 at 20 Hz: a gap of a second between 1.0 s and 2.05 s.
    let path = dir.path().join("bag");
    let mut w = BagWriter::create(&path, WriterOptions::default()).unwrap();
    let scan_topic = w
        .add_topic_for::<LaserScan>(topics::SCAN.name, topics::SCAN.qos)
        .unwrap();
    for i in (0..20).chain(40..60) {
        w.write_message(scan_topic, T0_NS + 50_000_000 * (i as i64 + 1), &scan(i))
            .unwrap();
    }
    w.finish().unwrap();
    let script = r#"
# From 0.5 s after the first scan (scan 10) to the last (scan 59): 2.45 s at rate 1. The
# echoes start once its writers are on the graph, so they match them before the first scan.
"$REPLAY" --ros-args -p bag:="$BAG" -p start_offset:=0.5 -p wait_for_subscriber:=/scan \
  -p wait_timeout:=30 -p wait_for_all_acked:=0.0 & R=$!
wait_until 20 topics_listed /clock /scan
"$LH" topic echo /clock --timeout 60 > "$OUT/clock.jsonl" & C=$!
"$LH" topic echo /scan --timeout 60 > "$OUT/scan.jsonl" & E=$!
wait $R; echo "replay=$?"
sleep 0.5
kill -TERM $C; wait $C; echo "clock_echo=$?"
kill -TERM $E; wait $E; echo "scan_echo=$?"
"#;
    let out = replay_in_netns(script, &path, dir.path(), Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=0", "clock_echo=0", "scan_echo=0"] {
        assert!(stdout.contains(want), "expected {want}");
    }
    let clock: Vec<i64> = json_lines(&dir.path().join("clock.jsonl"))
        .iter()
        .map(clock_ns)
        .collect();
    // It holds at the offset (0.5 s after the first scan) while waiting for the subscriber,
    // then moves on at every tick.
    let begin = 50_000_000 * 11;
    let playing: Vec<i64> = clock.iter().copied().filter(|&ns| ns > begin).collect();
    assert!(
        playing.windows(2).all(|w| w[0] < w[1]),
        "/clock repeated or went back: {clock:?}"
    );
    assert!(clock.iter().all(|&ns| ns >= begin), "{clock:?}");
    // About 100 in the 2.45 s of play (40 Hz); one per message (30) before.
    assert!(
        (60..=160).contains(&playing.len()),
        "{} /clock while playing: {clock:?}",
        playing.len()
    );
    let in_gap = playing
        .iter()
        .filter(|&&ns| ns > 1_000_000_000 && ns < 2_050_000_000);
    assert!(in_gap.count() >= 20, "/clock stopped in the gap: {clock:?}");
    // The first scan played is the first after the offset, and the next ones follow it at
    // their recorded 50 ms (loosely: a loaded machine delays some).
    let scans = json_lines(&dir.path().join("scan.jsonl"));
    assert_eq!(scan_index(&scans[0]["msg"]), 10);
    let sent: Vec<i64> = scans[..6]
        .iter()
        .map(|s| s["source_time_ns"].as_i64().unwrap())
        .collect();
    let spread_ms = (sent[5] - sent[0]) / 1_000_000;
    assert!(
        spread_ms >= 200,
        "6 scans sent within {spread_ms} ms: {sent:?}"
    );
}

/// `playback_duration` plays the messages logged in `[start_offset, start_offset +
/// playback_duration]` and no others, as `ros2 bag play --playback-duration`.
#[test]
fn ros_replay_plays_playback_duration_from_the_offset() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // The map at T0 starts the bag; scan i at 50 ms * (i + 1) after it: from scan 9 (0.5 s
    // in) for 1 s, up to scan 29, exactly at the end, which rosbag2's player plays too.
    let bag = write_bag(dir.path(), 60);
    let script = r#"
"$REPLAY" --ros-args -p bag:="$BAG" -p start_offset:=0.5 -p playback_duration:=1.0 \
  -p topics:=[/scan] -p wait_for_subscriber:=/scan -p wait_timeout:=30 \
  -p wait_for_all_acked:=5.0 & R=$!
# Started once the replay's writer is on the graph, the echo matches it before any scan.
wait_until 20 topics_listed /scan
"$LH" topic echo /scan --timeout 30 > "$OUT/scan.jsonl" & E=$!
wait $R; echo "replay=$?"
# A loaded machine may print the last scans late; then any scan past the end would show.
wait_until 10 has_lines "$OUT/scan.jsonl" 21
sleep 0.5
kill -TERM $E; wait $E; echo "scan_echo=$?"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=0", "scan_echo=0"] {
        assert!(stdout.contains(want), "expected {want}: {stdout}");
    }
    let played: Vec<usize> = json_lines(&dir.path().join("scan.jsonl"))
        .iter()
        .map(|s| scan_index(&s["msg"]))
        .collect();
    assert_eq!(played, (9..=29).collect::<Vec<_>>());
}

/// `topic hz` reports a topic's rate once a second as `ros2 topic hz` does: a replay's 20 Hz
/// scans (4 s of them, at rate 1) read 20 Hz, timed by the publisher's source timestamps.
#[test]
fn ros_topic_hz_reports_the_rate_of_a_topic() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 80);
    let script = r#"
"$LH" topic hz /scan --timeout 60 > "$OUT/hz.txt" & H=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p topics:=[/scan] -p wait_for_subscriber:=/scan \
  -p wait_timeout:=30 -p wait_for_all_acked:=0.0
echo "replay=$?"
sleep 2
kill -TERM $H; wait $H; echo "hz=$?"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=0", "hz=0"] {
        assert!(stdout.contains(want), "expected {want}: {stdout}");
    }
    let text = std::fs::read_to_string(dir.path().join("hz.txt")).unwrap();
    let rates: Vec<f64> = text
        .lines()
        .filter_map(|l| l.strip_prefix("average rate: "))
        .map(|r| r.parse().unwrap())
        .collect();
    assert!(rates.len() >= 2, "{text}");
    let last = rates[rates.len() - 1];
    assert!((19.0..=21.0).contains(&last), "{text}");
    assert!(
        text.lines()
            .any(|l| l.starts_with("\tmin: ") && l.contains(" window: ")),
        "{text}"
    );
}

#[test]
fn ros_nodes_reject_bad_parameters_naming_them() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 2);
    let params_file = dir.path().join("bad.yaml");
    std::fs::write(
        &params_file,
        "replay:\n  ros__parameters:\n    rate: fast\n",
    )
    .unwrap();
    let cases: &[(&str, &[&str])] = &[
        (r#""$REPLAY""#, &["`bag`", "required"]),
        (
            r#""$REPLAY" --ros-args -p bag:=/nonexistent/bag"#,
            &["`bag`", "/nonexistent/bag"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" -p rate:=-2"#,
            &["`rate`", ">= 0"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" -p rate:=.nan"#,
            &["`rate`"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" -p rate:=fast"#,
            &["`rate`", "expected double"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" -p start_offset:=100.0"#,
            &["`start_offset`", "100 s", "past the end", "s long"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" -p playback_duration:=0.0"#,
            &["`playback_duration`", "negative (to the bag's end)"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" -p speed:=2"#,
            &["`speed`", "unknown"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" -p topics:=[/nope]"#,
            &["`topics`", "/nope"],
        ),
        // A bad name in a remapping used to fail with status 1 once DDS had started.
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" -r /scan:=/robot-1/scan"#,
            &["`/scan:=/robot-1/scan`", "'-'"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" --params-file "$PF""#,
            &["`rate`", "bad.yaml"],
        ),
        (
            r#""$REPLAY" --ros-args -p bag:="$BAG" --params-file /nonexistent.yaml"#,
            &["/nonexistent.yaml"],
        ),
        (
            r#"ROS_DOMAIN_ID=999 "$REPLAY" --ros-args -p bag:="$BAG""#,
            &["ROS_DOMAIN_ID"],
        ),
        (
            r#"ROS_AUTOMATIC_DISCOVERY_RANGE=nearby "$REPLAY" --ros-args -p bag:="$BAG""#,
            &["ROS_AUTOMATIC_DISCOVERY_RANGE `nearby`", "LOCALHOST"],
        ),
        // The localiser and the classifier check their files before they join the graph:
        // they used to join first, and the DDS stack's warnings came before the error. A bad
        // `ROS_DOMAIN_ID`, which only joining reads, shows the order.
        (
            r#""$LOCALISER" --ros-args -p config:=/nonexistent.yaml"#,
            &["`config`", "/nonexistent.yaml"],
        ),
        (
            r#"ROS_DOMAIN_ID=999 "$LOCALISER" --ros-args -p map_file:="$ROBOT_YAML""#,
            &["`map_file`", "robot.yaml", "not a valid map_server map"],
        ),
        (
            r#""$LOCALISER" --ros-args -p map_file:="$ROBOT_YAML" -p learned_background:=true"#,
            &["`map_file`", "learned_background"],
        ),
        (
            r#""$CLASSIFIER" --ros-args -p config:="$LOCALISER_YAML""#,
            &["`config`", "localiser.yaml", "unknown field"],
        ),
        (
            r#"ROS_DOMAIN_ID=999 "$CLASSIFIER" --ros-args -p config:=/nonexistent.yaml"#,
            &["`config`", "/nonexistent.yaml"],
        ),
    ];
    let config = repo_root().join("config");
    for (command, needles) in cases {
        let script = format!("{command} 2> \"$OUT/err.txt\"; echo \"exit=$?\"");
        let out = in_netns(
            &script,
            &[
                ("REPLAY", &workspace_bin("replay")),
                ("LOCALISER", &workspace_bin("localiser")),
                ("CLASSIFIER", &workspace_bin("classifier")),
                ("BAG", &bag),
                ("PF", &params_file),
                ("ROBOT_YAML", &config.join("robot.yaml")),
                ("LOCALISER_YAML", &config.join("localiser.yaml")),
                ("OUT", dir.path()),
            ],
            Duration::from_secs(20),
        );
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = std::fs::read_to_string(dir.path().join("err.txt")).unwrap();
        assert!(
            stdout.contains("exit=2"),
            "{command}: must fail with status 2 (bad argument or parameter): {stdout}"
        );
        assert_eq!(
            stderr.lines().count(),
            1,
            "{command}: one line, the error, before any DDS traffic: {stderr}"
        );
        for needle in *needles {
            assert!(
                stderr.contains(needle),
                "{command}: stderr must name {needle}: {stderr}"
            );
        }
        assert!(
            !stderr.contains("panicked"),
            "{command}: panicked: {stderr}"
        );
    }
}

/// The replay checks its bag before it joins the graph: a bad one used to be found once the
/// participant was up, which, dropped while it registered its writers, logged up to a dozen
/// ERROR lines of the DDS stack before the one-line error. A bad `ROS_DOMAIN_ID`, which only
/// joining the graph reads, shows the order: the bag's error comes first.
#[test]
fn ros_replay_checks_its_bag_before_joining_the_graph() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
for i in 1 2 3 4 5; do
  "$REPLAY" --ros-args -p bag:=/nonexistent/bag 2>> "$OUT/err.txt"; echo "exit=$?"
done
ROS_DOMAIN_ID=999 "$REPLAY" --ros-args -p bag:=/nonexistent/bag 2> "$OUT/domain_err.txt"
echo "domain_exit=$?"
"#;
    let out = in_netns(
        script,
        &[("REPLAY", &workspace_bin("replay")), ("OUT", dir.path())],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(stdout.matches("exit=2").count(), 6, "{stdout}");
    let err = std::fs::read_to_string(dir.path().join("err.txt")).unwrap();
    assert_eq!(err.lines().count(), 5, "one line per run: {err}");
    assert!(err.lines().all(|l| l.contains("`bag`")), "{err}");
    let err = std::fs::read_to_string(dir.path().join("domain_err.txt")).unwrap();
    assert!(
        err.contains("`bag`") && !err.contains("ROS_DOMAIN_ID"),
        "the bag must be checked before the node joins the graph: {err}"
    );
}

/// A learned background takes the Lidar as fixed: the localiser says so at start-up when
/// `moving` (robot.yaml's value) or `wait_for_map_to_odom` asks otherwise, which it used to
/// ignore without a word (a robot's scans placed as a fixed Lidar's), and is quiet with
/// `moving:=false`.
#[test]
fn ros_localiser_warns_that_a_learned_background_ignores_moving() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
"$LOC" --ros-args -p learned_background:=true 2> "$OUT/moving.txt" & L=$!
wait_until 20 has_lines "$OUT/moving.txt" 1
kill -INT $L; wait $L; echo "moving=$?"
"$LOC" --ros-args -p learned_background:=true -p moving:=false 2> "$OUT/fixed.txt" & L=$!
wait_until 20 topics_listed /tf
kill -INT $L; wait $L; echo "fixed=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("LOC", &workspace_bin("localiser")),
            ("OUT", dir.path()),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("moving=0") && stdout.contains("fixed=0"),
        "{stdout}"
    );
    let ignored = "so moving:=true is ignored";
    let moving = std::fs::read_to_string(dir.path().join("moving.txt")).unwrap();
    assert!(moving.contains(ignored), "{moving}");
    let fixed = std::fs::read_to_string(dir.path().join("fixed.txt")).unwrap();
    assert!(!fixed.contains("ignored"), "{fixed}");
}

/// The driver checks its parameters before it joins the graph, as the replay does: a bad one
/// used to be found with the participant up, and runs printed the DDS stack's discovery
/// warnings before the one-line error. A bad `ROS_DOMAIN_ID`, which only joining the graph
/// reads, shows the order: the parameter's error comes first.
#[test]
fn ros_rplidar_driver_checks_its_parameters_before_joining_the_graph() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
for i in 1 2 3 4 5; do
  "$DRIVER" --ros-args -p port:=/nonexistent/tty -p baud:=12 2>> "$OUT/err.txt"; echo "exit=$?"
done
ROS_DOMAIN_ID=999 "$DRIVER" --ros-args -p range_max:=0.1 2> "$OUT/domain_err.txt"
echo "domain_exit=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("DRIVER", &workspace_bin("rplidar_driver")),
            ("OUT", dir.path()),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(stdout.matches("exit=2").count(), 6, "{stdout}");
    let err = std::fs::read_to_string(dir.path().join("err.txt")).unwrap();
    assert_eq!(err.lines().count(), 5, "one line per run: {err}");
    assert!(err.lines().all(|l| l.contains("`baud`")), "{err}");
    let err = std::fs::read_to_string(dir.path().join("domain_err.txt")).unwrap();
    assert!(
        err.contains("`range_max`") && !err.contains("ROS_DOMAIN_ID"),
        "the parameters must be checked before the node joins the graph: {err}"
    );
}

/// `topic echo` reads a topic with the QoS its publishers offer, as `ros2 topic echo`: a
/// latched /map remapped out of the contract (/robot1/map) used to be read best effort and
/// volatile, so a late echo printed nothing; a best-effort publisher of a reliable contract
/// topic (here /scan remapped onto /odom) was never matched. A relative name is in `/`.
#[test]
fn ros_topic_echo_matches_the_qos_of_the_publishers() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 60);
    let script = r#"
"$REPLAY" --ros-args -p bag:="$BAG" -p rate:=0.25 -p wait_for_all_acked:=0 -r /map:=/robot1/map -r /scan:=/odom &
R=$!
# The map was published when the replay started: the echo joins later.
wait_until 20 topics_listed /robot1/map /odom
"$LH" topic echo robot1/map --count 1 --timeout 10 --require-count > "$OUT/map.jsonl"; echo "map_echo=$?"
"$LH" topic echo /odom --type sensor_msgs/msg/LaserScan --count 3 --timeout 10 --require-count > "$OUT/odom.jsonl"; echo "odom_echo=$?"
kill -TERM $R; wait $R; echo "replay=$?"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["map_echo=0", "odom_echo=0", "replay=0"] {
        assert!(stdout.contains(want), "expected {want}");
    }
    let map = json_lines(&dir.path().join("map.jsonl"));
    assert_eq!(map.len(), 1);
    assert_eq!(map[0]["topic"], "/robot1/map");
    assert_eq!(map[0]["type"], "nav_msgs/msg/OccupancyGrid");
    assert_eq!(map[0]["msg"]["info"]["width"], 4);
    let scans = json_lines(&dir.path().join("odom.jsonl"));
    assert_eq!(scans.len(), 3);
    for line in &scans {
        scan_index(&line["msg"]);
    }
}

#[test]
fn the_classifier_tells_a_missing_runtime_from_a_bad_model() {
    if !netns_available() || !runtime_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // (command, exit status, what stderr must name): the installation is at fault (1), or a
    // parameter (2).
    let cases: &[(&str, &str, &[&str])] = &[
        (
            r#"ORT_DYLIB_PATH=/nonexistent/libonnxruntime.so "$CLASSIFIER""#,
            "exit=1",
            &["/nonexistent/libonnxruntime.so", "scripts/setup.sh"],
        ),
        (
            r#""$CLASSIFIER" --ros-args -p model:=/nonexistent/model.onnx"#,
            "exit=2",
            &["`model`", "/nonexistent/model.onnx"],
        ),
        // The model the `config` file names: its key is blamed, not the empty parameter
        // `model` (which it used to be).
        (
            r#""$CLASSIFIER" --ros-args -p config:="$CONFIG""#,
            "exit=2",
            &[
                "parameter `config`: classifier configuration",
                "my_classifier.yaml, key `model`",
                "/nonexistent/retrained.onnx",
            ],
        ),
        // Loaded before the node joins the graph, which alone reads `ROS_DOMAIN_ID`.
        (
            r#"ROS_DOMAIN_ID=999 ORT_DYLIB_PATH=/nonexistent/libonnxruntime.so "$CLASSIFIER""#,
            "exit=1",
            &["/nonexistent/libonnxruntime.so"],
        ),
    ];
    let config = dir.path().join("my_classifier.yaml");
    std::fs::write(&config, "model: /nonexistent/retrained.onnx\n").unwrap();
    for (command, status, needles) in cases {
        let script = format!("{command} 2> \"$OUT/err.txt\"; echo \"exit=$?\"");
        let out = in_netns(
            &script,
            &[
                ("CLASSIFIER", &workspace_bin("classifier")),
                ("CONFIG", &config),
                ("OUT", dir.path()),
            ],
            Duration::from_secs(20),
        );
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = std::fs::read_to_string(dir.path().join("err.txt")).unwrap();
        assert!(
            stdout.contains(status),
            "{command}: want {status}: {stdout}"
        );
        // ONNX Runtime and the model are loaded before the node joins the graph.
        assert_eq!(
            stderr.lines().count(),
            1,
            "{command}: one line, the error, before any DDS traffic: {stderr}"
        );
        for needle in *needles {
            assert!(
                stderr.contains(needle),
                "{command}: stderr must name {needle}: {stderr}"
            );
        }
    }
}

/// `--help` and stray arguments are answered before any DDS traffic, so no namespace is needed;
/// a node that wrongly starts DDS anyway is killed at a deadline rather than hanging the suite.
#[test]
fn ros_nodes_print_help_and_refuse_stray_arguments() {
    let nodes = [
        ("localiser", "map_file"),
        ("classifier", "model"),
        ("replay", "wait_for_all_acked"),
        ("rplidar_driver", "scan_mode"),
    ];
    let limit = Duration::from_secs(20);
    for (node, parameter) in nodes {
        let help = output_within(Command::new(workspace_bin(node)).arg("--help"), limit);
        let text = String::from_utf8_lossy(&help.stdout);
        assert!(help.status.success(), "{node} --help: {help:?}");
        assert!(
            text.contains("--ros-args") && text.contains(&format!("  {parameter} (")),
            "{node} --help must list `{parameter}`: {text}"
        );
        // Every node declares use_sim_time; only rplidar_driver's help used to list it.
        assert!(
            text.contains("  use_sim_time (bool, default false)"),
            "{node} --help must list `use_sim_time`: {text}"
        );
        // A parameter given without `--ros-args -p` used to be ignored: the node ran on.
        let stray = output_within(
            Command::new(workspace_bin(node)).args(["rate:=2.0", "--ros-args", "-r", "__ns:=/a"]),
            limit,
        );
        let err = String::from_utf8_lossy(&stray.stderr);
        assert_eq!(stray.status.code(), Some(2), "{node}: {err}");
        assert!(
            err.contains("`rate:=2.0`") && err.contains("--ros-args"),
            "{node}: {err}"
        );
        // A path that is not UTF-8 used to panic (status 101) in the standard library.
        let not_utf8 = output_within(
            Command::new(workspace_bin(node)).args([
                "--ros-args".into(),
                "-p".into(),
                std::ffi::OsString::from_vec(b"bag:=/caf\xe9".to_vec()),
            ]),
            limit,
        );
        let err = String::from_utf8_lossy(&not_utf8.stderr);
        assert_eq!(not_utf8.status.code(), Some(2), "{node}: {err}");
        assert!(
            err.contains("`bag:=/caf\u{fffd}`: not UTF-8"),
            "{node}: {err}"
        );
        // A namespace rmw refuses used to fail late, with status 1, once DDS had started.
        let bad_ns = output_within(
            Command::new(workspace_bin(node)).args(["--ros-args", "-r", "__ns:=/robot-1"]),
            limit,
        );
        let err = String::from_utf8_lossy(&bad_ns.stderr);
        assert_eq!(bad_ns.status.code(), Some(2), "{node}: {err}");
        assert!(err.contains("`/robot-1`"), "{node}: {err}");
    }
}

/// `ROS_AUTOMATIC_DISCOVERY_RANGE` and `ROS_LOCALHOST_ONLY`, against a second host: a network
/// namespace of its own, joined to the test's by a virtual Ethernet link. A node on the subnet
/// range is seen there; one on the local range is not, yet talks to nodes on its own host;
/// `ROS_LOCALHOST_ONLY=1` wins over the range, as in rcl; a node with discovery off is not
/// seen even on its own host. Each replay waits for a /scan subscriber, so it stays on the
/// graph while the others look for it.
#[test]
fn ros_discovery_range_keeps_a_node_to_its_host() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 20);
    let script = r#"
unshare -n sleep 120 & PEER=$!
apart() { [ "$(readlink /proc/$PEER/ns/net)" != "$(readlink /proc/$$/ns/net)" ]; }
wait_until 5 apart
ip link add va type veth peer name vb && ip link set vb netns $PEER || exit 91
ip addr add 10.77.0.1/24 dev va && ip link set va up || exit 91
nsenter -t $PEER -n sh -c 'ip link set lo up && ip addr add 10.77.0.2/24 dev vb &&
  ip link set vb up && ip route add 224.0.0.0/4 dev vb' || exit 91
seen_from_peer() { nsenter -t $PEER -n "$LH" topic list --wait 2 | grep -qx /scan; }
seen_here() { "$LH" topic list --wait 2 | grep -qx /scan; }
# `replay VAR=value... &`: a function does not pass on variables set in front of its call;
# `exec` makes $! the node's own PID.
replay() { exec env "$@" "$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:=/scan \
  -p wait_timeout:=60 2>> "$OUT/replay.err"; }
stop() { kill -TERM $1; wait $1; }

replay & R=$!
poll 15 seen_from_peer && echo "subnet: peer sees it"
stop $R

replay ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST & R=$!
poll 6 seen_from_peer && echo "localhost: peer sees it"
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST "$LH" topic echo /scan --count 5 --timeout 15 \
  --require-count > "$OUT/scan.jsonl"; echo "localhost: echo on the host=$?"
wait $R; echo "localhost: replay=$?"

replay ROS_LOCALHOST_ONLY=1 ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET & R=$!
poll 6 seen_from_peer && echo "localhost only: peer sees it"
stop $R

replay ROS_AUTOMATIC_DISCOVERY_RANGE=OFF & R=$!
poll 6 seen_here && echo "off: host sees it"
kill -0 $R && echo "off: replay waiting"
stop $R
kill $PEER
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(90));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_ne!(
        out.status.code(),
        Some(91),
        "the veth link could not be set up"
    );
    for want in [
        "subnet: peer sees it",
        "localhost: echo on the host=0",
        "localhost: replay=0",
        "off: replay waiting",
    ] {
        assert!(stdout.contains(want), "expected `{want}`");
    }
    for unwanted in [
        "localhost: peer sees it",
        "localhost only: peer sees it",
        "off: host sees it",
    ] {
        assert!(!stdout.contains(unwanted), "`{unwanted}`");
    }
    assert_eq!(json_lines(&dir.path().join("scan.jsonl")).len(), 5);
}

/// On simulated time a node reads /clock as rosgraph_msgs/msg/Clock; ros2-client's spinner
/// reading it as another type in the same participant made the DDS stack log an ERROR.
/// `-r` rules move a node's /clock reader and /rosout writer, as rcl moves rclcpp's (they
/// stayed at /clock and /rosout).
#[test]
fn ros_nodes_on_simulated_time_start_and_stop_without_errors() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
"$LOC" --ros-args -p use_sim_time:=true -r /clock:=/sim/clock -r /rosout:=/sim/rosout \
  2> "$OUT/localiser.err" & L=$!
"$CLS" --ros-args -p use_sim_time:=true -p model:="$MODEL" 2> "$OUT/classifier.err" & C=$!
# Both are up: the localiser subscribes /tf (only it does), and the classifier advertises
# /human/pelvis once its model is loaded.
wait_until 30 topics_listed /tf /human/pelvis /sim/clock /sim/rosout
"$LH" topic list -t --wait 1 > "$OUT/topics.txt"; echo "list=$?"
kill -TERM $L $C; wait $L; echo "localiser=$?"; wait $C; echo "classifier=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("LOC", &workspace_bin("localiser")),
            ("CLS", &workspace_bin("classifier")),
            ("MODEL", &repo_root().join("models/activity.onnx")),
            ("OUT", dir.path()),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    for node in ["localiser", "classifier"] {
        let log = std::fs::read_to_string(dir.path().join(format!("{node}.err"))).unwrap();
        assert!(
            stdout.contains(&format!("{node}=0")),
            "{node}: {stdout}\n{log}"
        );
        assert!(!log.contains("ERROR"), "{node} logged errors:\n{log}");
    }
    let topics = std::fs::read_to_string(dir.path().join("topics.txt")).unwrap();
    for want in [
        "/sim/clock [rosgraph_msgs/msg/Clock]",
        "/sim/rosout [rcl_interfaces/msg/Log]",
    ] {
        assert!(topics.lines().any(|l| l == want), "no {want} in\n{topics}");
    }
}

/// ros2-client's spinner, which served `ros2 param`, subscribed /clock as
/// builtin_interfaces/msg/Time: every node serving parameters showed a /clock of that type,
/// and beside a real /clock publisher the topic had two types (`ros2 topic echo /clock`
/// refuses it, `ros2 bag record -a` leaves it out). Now no node has it, replay included.
#[test]
fn ros_clock_has_only_the_ros_2_clock_type_beside_nodes_serving_parameters() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 20);
    let script = r#"
"$LOC" 2> "$OUT/localiser.err" & L=$!
"$CLS" --ros-args -p model:="$MODEL" 2> "$OUT/classifier.err" & C=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p loop:=true 2> "$OUT/replay.err" & R=$!
wait_until 30 topics_listed /clock /tf /human/pelvis
"$LH" topic list -t --wait 2 > "$OUT/topics.txt"; echo "list=$?"
kill -TERM $L $C $R; wait $L; echo "localiser=$?"; wait $C; echo "classifier=$?"
wait $R; echo "replay=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("LOC", &workspace_bin("localiser")),
            ("CLS", &workspace_bin("classifier")),
            ("REPLAY", &workspace_bin("replay")),
            ("MODEL", &repo_root().join("models/activity.onnx")),
            ("BAG", &bag),
            ("OUT", dir.path()),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["list=0", "localiser=0", "classifier=0", "replay=0"] {
        assert!(stdout.contains(want), "expected {want}");
    }
    let topics = std::fs::read_to_string(dir.path().join("topics.txt")).unwrap();
    let clock: Vec<&str> = topics
        .lines()
        .filter(|l| l.starts_with("/clock "))
        .collect();
    assert_eq!(clock, ["/clock [rosgraph_msgs/msg/Clock]"], "{topics}");
}

/// The nodes serve `ros2 param` without ros2-client's spinner (whose /clock reader had the
/// wrong type): answered to a DDS client of another stack (Cyclone DDS) framing requests as
/// rclcpp's default RMW does, from the start-up values, every set refused with the restart
/// that would apply it. The replay and nodes on `use_sim_time:=true` used to serve nothing;
/// a set of `use_sim_time` used to succeed and `describe` to say `read_only: false`.
#[test]
fn ros_param_services_answer_a_cyclone_dds_client_from_start_up_values() {
    let Some(python) = cyclone_python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 20);
    let script = r#"
"$LOC" --ros-args -p use_sim_time:=true -p moving:=false 2> "$OUT/localiser.err" & L=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p rate:=2.0 -p loop:=true 2> "$OUT/replay.err" & R=$!
wait_until 30 topics_listed /clock /tf
cd "$PYDIR"
"$PY" ros_param_client.py localiser 15 use_sim_time false > "$OUT/localiser.json"; echo "localiser_client=$?"
"$PY" ros_param_client.py replay 15 rate 2.5 > "$OUT/replay.json"; echo "replay_client=$?"
kill -TERM $L $R; wait $L; echo "localiser=$?"; wait $R; echo "replay=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("LOC", &workspace_bin("localiser")),
            ("REPLAY", &workspace_bin("replay")),
            ("BAG", &bag),
            ("OUT", dir.path()),
            ("PY", &python),
            ("PYDIR", &repo_root().join("tests/python")),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in [
        "localiser_client=0",
        "replay_client=0",
        "localiser=0",
        "replay=0",
    ] {
        assert!(stdout.contains(want), "expected {want}");
    }
    let answers = |node: &str| -> serde_json::Value {
        let path = dir.path().join(format!("{node}.json"));
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
    };
    let localiser = answers("localiser");
    let names: Vec<&str> = localiser["names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert!(
        names.contains(&"map_file") && names.contains(&"use_sim_time"),
        "{names:?}"
    );
    assert_eq!(localiser["values"]["use_sim_time"], true);
    assert_eq!(localiser["values"]["moving"], false);
    let descriptors = localiser["descriptors"].as_array().unwrap();
    assert_eq!(descriptors.len(), names.len());
    assert!(
        descriptors.iter().all(|d| d["read_only"] == true),
        "{descriptors:?}"
    );
    let refused = "read-only: use_sim_time is read at start-up; restart the node with \
                   --ros-args -p use_sim_time:=false";
    assert_eq!(localiser["set"][0]["successful"], false);
    assert_eq!(localiser["set"][0]["reason"], refused);
    assert_eq!(localiser["set_atomically"]["successful"], false);
    assert_eq!(localiser["set_atomically"]["reason"], refused);

    let replay = answers("replay");
    assert_eq!(replay["values"]["rate"], 2.0);
    assert_eq!(replay["values"]["bag"], bag.to_str().unwrap());
    assert_eq!(replay["set"][0]["successful"], false);
    assert_eq!(
        replay["set"][0]["reason"],
        "read-only: rate is read at start-up; restart the node with --ros-args -p rate:=2.5"
    );
    for node in ["localiser", "replay"] {
        let log = std::fs::read_to_string(dir.path().join(format!("{node}.err"))).unwrap();
        assert!(!log.contains("ERROR"), "{node} logged errors:\n{log}");
    }
}

#[test]
fn ros_sigterm_during_replay_stops_cleanly_without_zombies_or_partial_lines() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 200); // 10 s of scans
    let script = r#"
"$LH" topic echo /scan --timeout 30 > "$OUT/scan.jsonl" &
E=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:=/scan &
R=$!
# Cut the replay short once scans flow (its 200 take 10 s).
wait_until 20 has_lines "$OUT/scan.jsonl" 5
t0=$(date +%s%N)
kill -TERM $R
wait $R; echo "replay=$?"
t1=$(date +%s%N)
echo "replay_stop_ms=$(( (t1 - t0) / 1000000 ))"
kill -TERM $E
wait $E; echo "echo=$?"
sleep 0.2
echo "zombies=$(ps -o stat= --ppid $$ | grep -c Z)"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(40));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=0", "echo=0", "zombies=0"] {
        assert!(stdout.contains(want), "expected {want}");
    }
    let stop_ms: u64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("replay_stop_ms="))
        .and_then(|v| v.trim().parse().ok())
        .expect("stop time printed");
    assert!(
        stop_ms < 5000,
        "replay took {stop_ms} ms to stop after SIGTERM"
    );
    let scans = json_lines(&dir.path().join("scan.jsonl"));
    assert!(
        !scans.is_empty() && scans.len() < 200,
        "{} scans: the replay must have been cut short",
        scans.len()
    );
    for s in &scans {
        scan_index(&s["msg"]);
    }
}

/// SIGINT while the replay waits at the end for a subscriber that stopped acknowledging (here
/// stopped with SIGSTOP mid-stream) stops it at once: it used to wait out all of
/// `wait_for_all_acked`.
#[test]
fn ros_sigint_during_the_replays_wait_for_acknowledgements_stops_it() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = write_alert_bag(dir.path());
    let script = r#"
"$LH" topic echo /human/activity --timeout 60 > "$OUT/activity.jsonl" & E=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p topics:="[/human/activity]" \
  -p wait_for_subscriber:=/human/activity -p wait_for_all_acked:=40 2> "$OUT/replay.log" & R=$!
wait_until 20 has_lines "$OUT/activity.jsonl" 3
kill -STOP $E
wait_until 20 grep -q "played" "$OUT/replay.log"
sleep 0.5
t0=$(date +%s%N)
kill -INT $R
wait $R; echo "replay=$?"
t1=$(date +%s%N)
echo "replay_stop_ms=$(( (t1 - t0) / 1000000 ))"
kill -CONT $E; kill -TERM $E; wait $E
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(90));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("replay=0"), "expected replay=0");
    let stop_ms: u64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("replay_stop_ms="))
        .and_then(|v| v.trim().parse().ok())
        .expect("stop time printed");
    // Without the signal the wait would last 40 s.
    assert!(
        stop_ms < 5000,
        "replay took {stop_ms} ms to stop after SIGINT"
    );
}

/// A `.zstd` storage file of `gib` GiB of zeros decompressed, a few KiB on disk: one zstd
/// frame of RLE blocks (block type 1, a byte repeated), written without a compressor.
fn write_zeros_compressed(path: &Path, gib: usize) {
    const BLOCK: u32 = 128 << 10;
    let blocks = gib << 13;
    // The magic, then a frame header without content size or checksum, window 128 KiB.
    let mut frame = vec![0x28, 0xB5, 0x2F, 0xFD, 0x00, 0x38];
    for i in 0..blocks {
        let header = BLOCK << 3 | 1 << 1 | u32::from(i + 1 == blocks);
        frame.extend(&header.to_le_bytes()[..3]);
        frame.push(0);
    }
    std::fs::write(path, frame).unwrap();
}

/// A signal while the replay decompresses a bag (rosbag2 file compression, into `$TMPDIR`)
/// stops the decompression: it used to run to the end first, seconds for a large bag, and
/// only then see the signal. The bag here is 1 GiB of zeros, not a bag: finished, its copy
/// would be refused as no MCAP file.
#[test]
fn ros_a_signal_stops_the_replays_decompression() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    std::fs::create_dir_all(dir.path().join("tmp")).unwrap();
    std::fs::create_dir_all(&bag).unwrap();
    write_zeros_compressed(&bag.join("bag_0.mcap.zstd"), 1);
    let script = r#"
TMPDIR="$OUT/tmp" "$REPLAY" --ros-args -p bag:="$BAG" 2> "$OUT/replay.log" & R=$!
copying() { ls "$OUT"/tmp/lidar-har-bag-*/bag_0.mcap > /dev/null 2>&1; }
until copying || ! kill -0 $R 2> /dev/null; do sleep 0.005; done
kill -TERM $R
wait $R; echo "replay=$?"
echo "left=$(ls "$OUT/tmp" | wc -l)"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let log = std::fs::read_to_string(dir.path().join("replay.log")).unwrap();
    assert!(stdout.contains("replay=0"), "{stdout} {log}");
    assert!(stdout.contains("left=0"), "the copy stays behind: {stdout}");
    assert!(
        log.contains("stopped by signal") && log.contains("the process is ending"),
        "the decompression must stop on the signal: {log}"
    );
}

/// Activity `i` of the alert bag: every field set to something that tells messages apart.
fn activity(i: usize) -> Activity {
    let class = (i % usize::from(Activity::NUM_CLASSES)) as u8;
    let mut probabilities = vec![0.0125 * (i % 7) as f32; usize::from(Activity::NUM_CLASSES)];
    probabilities[usize::from(class)] = 0.6 + 0.01 * i as f32;
    Activity {
        header: Header::new(Time::from_nanos(T0_NS + 50_000_000 * i as i64), "map"),
        activity: class,
        label: Activity::LABELS[usize::from(class)].to_string(),
        confidence: probabilities[usize::from(class)],
        probabilities,
    }
}

/// The fall alerts of the alert bag, with their log times.
fn fall_alerts() -> Vec<(i64, FallAlert)> {
    let alert = |t_ns: i64, kind: u8, x: f64, description: &str| {
        let alert = FallAlert {
            header: Header::new(Time::from_nanos(t_ns), "map"),
            kind,
            position: Point {
                x,
                y: -1.0 / 3.0,
                z: 0.0,
            },
            confidence: 0.875,
            event_time: Time::from_nanos(t_ns - 400_000_000),
            description: description.to_string(),
        };
        (t_ns, alert)
    };
    vec![
        alert(
            T0_NS + 500_000_000,
            FallAlert::FALL_DETECTED,
            2.25,
            "fall detected: falling_down",
        ),
        alert(
            T0_NS + 1_200_000_000,
            FallAlert::PERSON_DOWN,
            2.5e-3,
            "person down for 0.8 s (lying_down) \u{2014} near the bed",
        ),
    ]
}

const ALERT_BAG_ACTIVITIES: usize = 30;

/// A bag with 1.5 s of /human/activity at 20 Hz and two /human/fall_alert messages.
fn write_alert_bag(dir: &Path) -> PathBuf {
    let path = dir.join("alerts");
    let mut w = BagWriter::create(&path, WriterOptions::default()).unwrap();
    let activity_topic = w
        .add_topic_for::<Activity>(topics::HUMAN_ACTIVITY.name, topics::HUMAN_ACTIVITY.qos)
        .unwrap();
    let alert_topic = w
        .add_topic_for::<FallAlert>(topics::FALL_ALERT.name, topics::FALL_ALERT.qos)
        .unwrap();
    let mut alerts = fall_alerts().into_iter().peekable();
    for i in 0..ALERT_BAG_ACTIVITIES {
        let a = activity(i);
        let t = a.header.stamp.to_nanos();
        while let Some((_, alert)) = alerts.next_if(|(at, _)| *at <= t) {
            w.write_message(alert_topic, alert.header.stamp.to_nanos(), &alert)
                .unwrap();
        }
        w.write_message(activity_topic, t, &a).unwrap();
    }
    w.finish().unwrap();
    path
}

/// The checker venv's Python, which has Cyclone DDS, where a private network namespace can
/// be made for it; `None` (the test skips or fails, as the missing piece requires) elsewhere.
fn cyclone_python() -> Option<PathBuf> {
    if !netns_available() {
        return None;
    }
    Some(PathBuf::from(checker_python()?.get_program()))
}

#[test]
fn ros_cyclone_dds_interoperates_with_replay_and_topic_echo() {
    let Some(python) = cyclone_python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 40);
    let alert_bag = write_alert_bag(dir.path());
    let script = r#"
cd "$PYDIR"
# Cyclone decodes our lidar_har_msgs (ROS 2 naming: rt/human/activity,
# lidar_har_msgs::msg::dds_::Activity_), every reader created before the replay starts.
"$PY" ros_cyclone_interop.py receive-topics 15 /human/fall_alert=2 /human/activity=30 > "$OUT/cyclone_alerts.jsonl" &
C=$!
"$REPLAY" --ros-args -p bag:="$ALERT_BAG" -p wait_for_subscriber:=/human/activity; echo "alert_replay=$?"
wait $C; echo "cyclone_alerts=$?"
# Cyclone receives what our replay publishes ...
"$PY" ros_cyclone_interop.py receive /scan 40 15 36 > "$OUT/cyclone_scan.jsonl" &
C=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:=/scan; echo "replay=$?"
# Best effort: what has not come a second after the replay ended will not come.
poll 1 has_lines "$OUT/cyclone_scan.jsonl" 40; kill -TERM $C 2>/dev/null
wait $C; echo "cyclone_receive=$?"
# ... and our transport receives what Cyclone publishes (best effort: see below).
"$LH" topic echo /scan --count 20 --timeout 15 > "$OUT/echo_scan.jsonl" &
E=$!
"$PY" ros_cyclone_interop.py publish-scan 20 20; echo "cyclone_publish=$?"
wait $E; echo "echo=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("REPLAY", &workspace_bin("replay")),
            ("BAG", &bag),
            ("ALERT_BAG", &alert_bag),
            ("OUT", dir.path()),
            ("PY", &python),
            ("PYDIR", &repo_root().join("tests/python")),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in [
        "alert_replay=0",
        "cyclone_alerts=0",
        "replay=0",
        "cyclone_receive=0",
        "cyclone_publish=0",
        "echo=0",
    ] {
        assert!(stdout.contains(want), "expected {want}");
    }
    // Field by field what was written, in order (reliable topics: nothing lost).
    let (mut got_activities, mut got_alerts) = (Vec::new(), Vec::new());
    for line in json_lines(&dir.path().join("cyclone_alerts.jsonl")) {
        let msg = line["msg"].clone();
        match line["topic"].as_str() {
            Some("/human/activity") => got_activities.push(
                serde_json::from_value::<Activity>(msg)
                    .expect("Cyclone's Activity has the fields of ours"),
            ),
            Some("/human/fall_alert") => got_alerts.push(
                serde_json::from_value::<FallAlert>(msg)
                    .expect("Cyclone's FallAlert has the fields of ours"),
            ),
            other => panic!("unexpected topic {other:?}"),
        }
    }
    let want_activities: Vec<Activity> = (0..ALERT_BAG_ACTIVITIES).map(activity).collect();
    assert_eq!(got_activities, want_activities);
    let want_alerts: Vec<FallAlert> = fall_alerts().into_iter().map(|(_, a)| a).collect();
    assert_eq!(got_alerts, want_alerts);

    let received = json_lines(&dir.path().join("cyclone_scan.jsonl"));
    let indices: Vec<usize> = received.iter().map(scan_index).collect();
    assert!(
        indices.windows(2).all(|w| w[0] < w[1]),
        "out of order or duplicated: {indices:?}"
    );
    assert!(
        indices.len() >= 36,
        "Cyclone received only {} of 40 scans: {indices:?}",
        indices.len()
    );
    // Cyclone starts publishing once its writer has matched our reader, but our reader takes
    // data only from writers it has matched in turn, which may come a little later: the first
    // few best-effort scans may be lost, none after them, and none may change.
    let echoed: Vec<Vec<f64>> = json_lines(&dir.path().join("echo_scan.jsonl"))
        .iter()
        .map(|line| {
            let ranges = line["msg"]["ranges"].as_array().unwrap();
            ranges.iter().map(|r| r.as_f64().unwrap()).collect()
        })
        .collect();
    assert!(
        echoed.len() >= 17,
        "our transport received only {} of Cyclone's 20 scans",
        echoed.len()
    );
    eprintln!(
        "our transport received {} of Cyclone's 20 scans",
        echoed.len()
    );
    let first = 20 - echoed.len();
    for (got, i) in echoed.iter().zip(first..) {
        assert_eq!(
            got,
            &vec![i as f64; 8],
            "Cyclone scan {i} arrived changed or out of order (the last {} of 20 came)",
            echoed.len()
        );
    }
}

/// A reliable /scan subscriber, rclcpp's default `QoS(10)` (here Cyclone DDS's), gets the
/// replay's scans: /scan was offered best effort, which a reliable subscriber never matches
/// (RustDDS logged `QoS mismatch Reliability`), so it got none while a best-effort one beside
/// it got them all. The replay offers /scan as `rplidar_driver` does.
#[test]
fn ros_a_reliable_cyclone_scan_subscriber_gets_the_replays_scans() {
    let Some(python) = cyclone_python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 40);
    let reader = r#"
import sys, time
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration
from ros_idl import LaserScan
p = DomainParticipant(0)
topic = Topic(p, "rt/scan", LaserScan)
# rclcpp's QoS(10): reliable, volatile, keep last 10.
qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(10))
reader = DataReader(p, topic, qos=qos)
print("ready", flush=True)
want, got, end = int(sys.argv[1]), 0, time.monotonic() + float(sys.argv[2])
while got < want and time.monotonic() < end:
    for s in reader.take(N=16):
        if getattr(s, "sample_info", None) is None or s.sample_info.valid_data:
            got += 1
            print(s.ranges[0], flush=True)
    time.sleep(0.01)
sys.exit(0 if got == want else 1)
"#;
    let reader_path = dir.path().join("reliable_scan.py");
    std::fs::write(&reader_path, reader).unwrap();
    let script = r#"
PYTHONPATH="$PYDIR" "$PY" "$READER" 40 20 > "$OUT/reliable.txt" & C=$!
wait_until 10 has_lines "$OUT/reliable.txt" 1
"$REPLAY" --ros-args -p bag:="$BAG" -p topics:="[/scan]" -p wait_for_subscriber:=/scan
echo "replay=$?"
wait $C; echo "reliable_reader=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("REPLAY", &workspace_bin("replay")),
            ("BAG", &bag),
            ("OUT", dir.path()),
            ("READER", &reader_path),
            ("PY", &python),
            ("PYDIR", &repo_root().join("tests/python")),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=0", "reliable_reader=0"] {
        assert!(stdout.contains(want), "expected {want}: {stdout}");
    }
    let text = std::fs::read_to_string(dir.path().join("reliable.txt")).unwrap();
    let firsts: Vec<f32> = text.lines().skip(1).map(|l| l.parse().unwrap()).collect();
    let want: Vec<f32> = (0..40).map(|i| scan(i).ranges[0]).collect();
    assert_eq!(firsts, want, "every scan, in order (reliable)");
}

/// A node's log records reach /rosout as rclcpp publishes them (`rcl_interfaces/msg/Log`,
/// rcl's logger name, level and source), read here by Cyclone DDS as `rqt_console` would;
/// the warnings logged before the node joined the graph too. `--disable-rosout-logs` keeps
/// them off. They used to reach only the node's terminal. `lidar-har topic echo /rosout`,
/// started before the node, prints the records decoded (it printed their CDR in hex).
#[test]
fn ros_a_nodes_log_records_reach_rosout() {
    let Some(python) = cyclone_python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // 5 s of scans: each replay lives long enough for the reader to match it and take its
    // records on a loaded machine (nothing waits for /rosout's acknowledgements at exit).
    let bag = write_bag(dir.path(), 100);
    // The quiet replay runs once the reader has the loud one's record: it is matched then.
    let script = r#"
cd "$PYDIR"
"$PY" ros_cyclone_interop.py receive /rosout 1000 40 1 > "$OUT/rosout.jsonl" & C=$!
"$LH" topic echo /rosout --timeout 50 > "$OUT/echo.jsonl" & E=$!
"$REPLAY" --ros-args -r __ns:=/robot1 -p bag:="$BAG" -p topics:="[/scan, /missing_loud]" 2> /dev/null
echo "replay=$?"
wait_until 10 grep -q /missing_loud "$OUT/rosout.jsonl"
wait_until 10 grep -q /missing_loud "$OUT/echo.jsonl"
kill -TERM $E; wait $E; echo "echo=$?"
"$REPLAY" --ros-args -p bag:="$BAG" -p topics:="[/scan, /missing_quiet]" --disable-rosout-logs 2> /dev/null
echo "quiet_replay=$?"
kill -TERM $C; wait $C; echo "reader=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("REPLAY", &workspace_bin("replay")),
            ("BAG", &bag),
            ("OUT", dir.path()),
            ("PY", &python),
            ("PYDIR", &repo_root().join("tests/python")),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in ["replay=0", "echo=0", "quiet_replay=0", "reader=0"] {
        assert!(stdout.contains(want), "expected {want}: {stdout}");
    }
    let records = json_lines(&dir.path().join("rosout.jsonl"));
    let missing = records
        .iter()
        .find(|r| {
            r["msg"]
                .as_str()
                .is_some_and(|m| m.contains("/missing_loud"))
        })
        .unwrap_or_else(|| panic!("no record of the missing topic: {records:?}"));
    assert_eq!(
        missing["name"], "robot1.replay",
        "rcl's logger name: {missing}"
    );
    assert_eq!(missing["level"], 30, "a warning: {missing}");
    assert!(
        missing["file"].as_str().unwrap().ends_with("replay.rs") && missing["line"] != 0,
        "{missing}"
    );
    let sec = missing["stamp"]["sec"].as_i64().unwrap();
    assert!(sec > 1_700_000_000, "wall clock: {missing}");
    assert!(
        records
            .iter()
            .all(|r| !r["msg"].as_str().unwrap_or("").contains("/missing_quiet")),
        "--disable-rosout-logs: {records:?}"
    );
    let echoed = json_lines(&dir.path().join("echo.jsonl"));
    let line = echoed
        .iter()
        .find(|l| {
            l["msg"]["msg"]
                .as_str()
                .is_some_and(|m| m.contains("/missing_loud"))
        })
        .unwrap_or_else(|| panic!("topic echo /rosout: no decoded record: {echoed:?}"));
    assert_eq!(line["type"], "rcl_interfaces/msg/Log", "{line}");
    assert_eq!(line["msg"]["name"], "robot1.replay", "{line}");
    assert_eq!(line["msg"]["level"], 30, "{line}");
}

/// A /map publisher that does not latch it (cartographer's occupancy_grid_node: volatile,
/// reliable), here Cyclone DDS: a transient-local subscription, the localiser's default, never
/// matches it (DDS QoS matching), so the localiser skips every scan for want of a map;
/// `map_transient_local:=false` subscribes volatile and uses it. A volatile subscription
/// still gets our replay's latched /map when it is running before the replay starts.
#[test]
fn ros_localiser_takes_a_volatile_cyclone_map_with_map_transient_local_false() {
    let Some(python) = cyclone_python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), 40);
    let script = r#"
cd "$PYDIR"
# A fixed Lidar: no odometry needed; each scan localised against a map gives /human/markers.
"$LOC" --ros-args -p moving:=false -r __node:=localiser_latched \
  -r /human/markers:=/latched/markers 2> "$OUT/latched.err" & A=$!
"$LOC" --ros-args -p moving:=false -p map_transient_local:=false 2> "$OUT/volatile.err" & B=$!
"$LH" topic echo /human/markers --count 10 --timeout 10 > "$OUT/markers.jsonl" & E=$!
"$LH" topic echo /latched/markers --type visualization_msgs/msg/MarkerArray --timeout 10 \
  > "$OUT/latched_markers.jsonl" & EA=$!
"$PY" ros_cyclone_interop.py publish-map volatile 4 > "$OUT/map.out" 2> "$OUT/map.err" & M=$!
# The map is written twice a second: the scans go once a reader has matched it.
wait_until 10 has_lines "$OUT/map.out" 1
"$PY" ros_cyclone_interop.py publish-scan 40 20; echo "cyclone_scan=$?"
wait $E; echo "echo=$?"
wait $M; echo "cyclone_map=$?"
kill -TERM $EA $A $B; wait $EA; wait $A; echo "latched=$?"; wait $B; echo "volatile=$?"
# Our replay's transient-local /map reaches a volatile subscription running before it.
"$LOC" --ros-args -p moving:=false -p map_transient_local:=false 2> "$OUT/replayed.err" & L=$!
"$LH" topic echo /human/markers --count 30 --timeout 10 > "$OUT/replay_markers.jsonl" & E=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:=/map; echo "replay=$?"
wait $E; echo "replay_echo=$?"
kill -TERM $L; wait $L; echo "replayed=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("LOC", &workspace_bin("localiser")),
            ("REPLAY", &workspace_bin("replay")),
            ("BAG", &bag),
            ("OUT", dir.path()),
            ("PY", &python),
            ("PYDIR", &repo_root().join("tests/python")),
        ],
        Duration::from_secs(40),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let read = |name: &str| std::fs::read_to_string(dir.path().join(name)).unwrap_or_default();
    for name in ["map.err", "latched.err", "volatile.err", "replayed.err"] {
        eprintln!("--- {name}\n{}", read(name));
    }
    for want in [
        "cyclone_scan=0",
        "echo=0",
        "cyclone_map=0",
        "replay=0",
        "replay_echo=0",
    ] {
        assert!(stdout.contains(want), "expected {want}");
    }
    // Only the volatile subscription matched Cyclone's volatile /map, and used it.
    assert!(
        read("map.err").contains("matched 1 reader(s)"),
        "Cyclone's volatile /map must match the volatile subscription alone"
    );
    assert!(json_lines(&dir.path().join("markers.jsonl")).len() >= 10);
    // The default transient-local one never got it: its scans were all skipped.
    assert!(
        read("latched.err").contains("no map received yet"),
        "the transient-local subscription had scans"
    );
    assert_eq!(
        json_lines(&dir.path().join("latched_markers.jsonl")).len(),
        0,
        "a transient-local /map subscription matched a volatile publisher"
    );
    assert!(json_lines(&dir.path().join("replay_markers.jsonl")).len() >= 30);
}

/// Equal JSON, numbers equal to within 1e-9 (relative): the nodes receive /scan and /odom
/// on separate DDS topics, so the last bit of a covariance may differ from the bag run.
fn json_close(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (
                x.as_f64().unwrap_or(f64::NAN),
                y.as_f64().unwrap_or(f64::NAN),
            );
            x == y || (x - y).abs() <= 1e-9 * x.abs().max(y.abs())
        }
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(x, y)| json_close(x, y))
        }
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, v)| y.get(k).is_some_and(|w| json_close(v, w)))
        }
        _ => a == b,
    }
}

/// Fails unless the messages `topic echo` wrote to `echoed` are those of `want` (from
/// `lidar-har run`): the same stamps, then each message equal to within float noise.
fn assert_echo_equals_run(topic: &str, echoed: &Path, want: &[serde_json::Value]) {
    let got: Vec<_> = json_lines(echoed)
        .into_iter()
        .map(|l| l["msg"].clone())
        .collect();
    assert_same_stamps(topic, &got, want);
    for (i, (got, want)) in got.iter().zip(want).enumerate() {
        assert!(
            json_close(got, want),
            "{topic} {i} differs between the nodes and `lidar-har run`:\n{got}\n{want}"
        );
    }
}

/// Fails unless `got` has the messages of `want`, by header stamp: a failure names the
/// stamps missing and those extra.
fn assert_same_stamps(topic: &str, got: &[serde_json::Value], want: &[serde_json::Value]) {
    let stamps = |messages: &[serde_json::Value]| -> Vec<String> {
        messages
            .iter()
            .map(|m| {
                let s = &m["header"]["stamp"];
                format!("{}.{:09}", s["sec"], s["nanosec"].as_u64().unwrap_or(0))
            })
            .collect()
    };
    let (got, want) = (stamps(got), stamps(want));
    if got != want {
        let missing: Vec<_> = want.iter().filter(|s| !got.contains(s)).collect();
        let extra: Vec<_> = got.iter().filter(|s| !want.contains(s)).collect();
        panic!(
            "{topic}: the nodes published {} messages, `lidar-har run` {}; missing stamps \
             {missing:?}, extra {extra:?} (first wanted {:?})",
            got.len(),
            want.len(),
            want.first()
        );
    }
}

/// Messages of `topic` in a bag, as the JSON `lidar-har topic echo` prints for them.
fn bag_topic_json(bag: &Path, topic: &str) -> Vec<serde_json::Value> {
    let reader = lidar_har_bag::BagReader::open(bag).unwrap();
    let type_name = reader.topic(topic).map(|t| t.type_name.clone());
    let Some(type_name) = type_name else {
        return Vec::new();
    };
    reader
        .messages_on(&[topic])
        .unwrap()
        .map(|m| {
            lidar_har_ros::json::decode_to_json(&type_name, &m.unwrap().data)
                .unwrap()
                .unwrap()
        })
        .collect()
}

/// The nodes over DDS publish what `lidar-har run` writes for the same bag. In the same run a
/// second classifier with `pose_head:=none` (its outputs remapped under /no_head) classifies
/// the same observations: it must publish the activity and no pelvis.
#[test]
fn ros_replay_localiser_classifier_processes_equal_the_embedded_run() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("sim");
    let run_out = dir.path().join("run");
    let lh = workspace_bin("lidar-har");
    let status = lidar_har()
        .current_dir(repo_root())
        .args(["simulate", "--duration", "6", "--out"])
        .arg(&bag)
        .status()
        .unwrap();
    assert!(status.success(), "lidar-har simulate failed");
    let status = lidar_har()
        .current_dir(repo_root())
        .arg("run")
        .arg("--bag")
        .arg(&bag)
        .arg("--out")
        .arg(&run_out)
        .status()
        .unwrap();
    assert!(status.success(), "lidar-har run failed");
    let want_poses = bag_topic_json(&run_out, topics::HUMAN_POSE.name);
    let want_activities = bag_topic_json(&run_out, topics::HUMAN_ACTIVITY.name);
    let want_pelvis = bag_topic_json(&run_out, topics::HUMAN_PELVIS.name);
    assert!(
        want_poses.len() > 20,
        "the simulated person should be tracked: {} poses",
        want_poses.len()
    );
    assert!(
        !want_activities.is_empty(),
        "`lidar-har run` wrote no /human/activity: the classifier did not run \
         (models/activity.onnx missing? it is committed)"
    );
    // Else the absence of /human/pelvis with `pose_head:=none` below would prove nothing.
    assert!(
        !want_pelvis.is_empty(),
        "`lidar-har run` wrote no /human/pelvis: the pose head did not run \
         (models/pose_head.onnx missing? it is committed)"
    );
    let script = format!(
        r#"
# From the repository root: the configuration's pose head (models/pose_head.onnx) is relative
# to the working directory (launch files pass the installed one), and without it the
# classifier runs headless, which would leave nothing for `pose_head:=none` to turn off.
cd "$ROOT"
"$LOC" 2> "$OUT/localiser.err" &
L=$!
"$CLS" --ros-args -p model:="$MODEL" 2> "$OUT/classifier.err" & C=$!
"$CLS" --ros-args -p model:="$MODEL" -p pose_head:=none -r __node:=classifier_no_head \
  -r /human/activity:=/no_head/activity -r /human/pelvis:=/no_head/pelvis \
  -r /human/fall_alert:=/no_head/fall_alert -r /human/markers:=/no_head/markers \
  2> "$OUT/classifier_no_head.err" & N=$!
# Whole (a cluster may have more than 128 points), as `bag_topic_json` decodes it.
"$LH" topic echo /human/pose --full-length --count {np} --timeout 40 > "$OUT/pose.jsonl" &
P=$!
"$LH" topic echo /human/activity --count {na} --timeout 40 > "$OUT/activity.jsonl" & A=$!
"$LH" topic echo /human/pelvis --count {nv} --timeout 40 > "$OUT/pelvis.jsonl" & V=$!
# Remapped names have no QoS the echo knows: best effort, so a message may be lost.
"$LH" topic echo /no_head/activity --type lidar_har_msgs/msg/Activity --timeout 60 \
  > "$OUT/no_head_activity.jsonl" & NA=$!
"$LH" topic echo /no_head/pelvis --type geometry_msgs/msg/PoseWithCovarianceStamped \
  --timeout 60 > "$OUT/no_head_pelvis.jsonl" & NV=$!
# All nodes up before the first scan: the localiser subscribes /tf (only it does), the
# classifiers advertise their pelvis topics once their models are loaded.
wait_until 30 topics_listed /tf /human/pelvis /no_head/pelvis
"$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:=/scan -p topics:="[/scan, /odom, /map, /tf, /tf_static]" 2> "$OUT/replay.err"; echo "replay=$?"
wait $P; echo "pose_echo=$?"
wait $A; echo "activity_echo=$?"
wait $V; echo "pelvis_echo=$?"
# The classifier without a head has had the same observations: let it finish them.
poll 5 has_lines "$OUT/no_head_activity.jsonl" {na}
kill -TERM $NA $NV; wait $NA; echo "no_head_activity_echo=$?"
wait $NV; echo "no_head_pelvis_echo=$?"
kill -TERM $L $C $N; wait $L; echo "localiser=$?"
wait $C; echo "classifier=$?"
wait $N; echo "classifier_no_head=$?"
"#,
        np = want_poses.len(),
        na = want_activities.len(),
        nv = want_pelvis.len(),
    );
    let out = in_netns(
        &script,
        &[
            ("LH", &lh),
            ("REPLAY", &workspace_bin("replay")),
            ("LOC", &workspace_bin("localiser")),
            ("CLS", &workspace_bin("classifier")),
            ("MODEL", &repo_root().join("models/activity.onnx")),
            ("ROOT", &repo_root()),
            ("BAG", &bag),
            ("OUT", dir.path()),
        ],
        Duration::from_secs(90),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    for want in [
        "replay=0",
        "pose_echo=0",
        "activity_echo=0",
        "pelvis_echo=0",
        "no_head_activity_echo=0",
        "no_head_pelvis_echo=0",
        "localiser=0",
        "classifier=0",
        "classifier_no_head=0",
    ] {
        assert!(stdout.contains(want), "expected {want}");
    }
    // A clean stop logs no ERROR (the DDS stack once logged one per reader and writer the
    // node's spinner dropped after the participant had stopped).
    let log = |node: &str| std::fs::read_to_string(dir.path().join(format!("{node}.err"))).unwrap();
    for node in ["localiser", "classifier", "classifier_no_head"] {
        let text = log(node);
        assert!(!text.contains("ERROR"), "{node} logged errors:\n{text}");
    }
    // RustDDS warned about every datagram over 1500 bytes: each 720-beam scan the replay sent.
    for node in ["replay", "localiser", "classifier"] {
        let text = log(node);
        assert!(!text.contains("Message size"), "{node}:\n{text}");
    }
    let classifier_log = log("classifier");
    assert!(
        !classifier_log.contains(POSE_HEAD_NOT_USED)
            && classifier_log.contains("pose head models/pose_head.onnx"),
        "the classifier must use the configuration's pose head:\n{classifier_log}"
    );
    assert_echo_equals_run("/human/pose", &dir.path().join("pose.jsonl"), &want_poses);
    assert_echo_equals_run(
        "/human/activity",
        &dir.path().join("activity.jsonl"),
        &want_activities,
    );
    assert_echo_equals_run(
        "/human/pelvis",
        &dir.path().join("pelvis.jsonl"),
        &want_pelvis,
    );
    assert_pose_head_none_publishes_the_activity_and_no_pelvis(
        &dir.path().join("no_head_activity.jsonl"),
        &dir.path().join("no_head_pelvis.jsonl"),
        &log("classifier_no_head"),
        &want_activities,
    );
}

/// What the classifier logs when the pose head it was given cannot be used.
const POSE_HEAD_NOT_USED: &str = "no /human/pelvis";

/// Fails unless the classifier node run with `pose_head:=none` (its /human/activity and
/// /human/pelvis echoed from `activity` and `pelvis`, best effort, and its stderr `log`) turned
/// the head off: no pelvis at all, and no attempt to load a head (`none` is no file name);
/// while its activities are those of `lidar-har run` (`want_activities`, with a head: the head
/// does not change the activity), by stamp, most of them received.
fn assert_pose_head_none_publishes_the_activity_and_no_pelvis(
    activity: &Path,
    pelvis: &Path,
    log: &str,
    want_activities: &[serde_json::Value],
) {
    let pelvis = json_lines(pelvis);
    assert!(
        pelvis.is_empty(),
        "pose_head:=none: the classifier published {} /human/pelvis messages (first stamped {})",
        pelvis.len(),
        pelvis[0]["msg"]["header"]["stamp"]
    );
    assert!(
        !log.contains(POSE_HEAD_NOT_USED) && log.contains("pose head off"),
        "pose_head:=none: the classifier did not turn its pose head off:\n{log}"
    );
    let stamp = |m: &serde_json::Value| m["header"]["stamp"].clone();
    let got: Vec<_> = json_lines(activity)
        .into_iter()
        .map(|l| l["msg"].clone())
        .collect();
    for msg in &got {
        let want = want_activities.iter().find(|w| stamp(w) == stamp(msg));
        assert!(
            want.is_some_and(|w| json_close(msg, w)),
            "pose_head:=none: /human/activity {msg} is not the embedded run's {want:?}"
        );
    }
    assert!(
        got.len() * 2 >= want_activities.len(),
        "pose_head:=none: the classifier published only {} of {} /human/activity messages \
         (best effort: a few may be lost)",
        got.len(),
        want_activities.len()
    );
    eprintln!(
        "pose_head:=none: {} of {} activities received, no pelvis",
        got.len(),
        want_activities.len()
    );
}

/// A sample whose encapsulation is not plain CDR (any peer can send one; here a RustDDS
/// writer with XCDR2's id) is skipped with a warning: it used to end the localiser (and the
/// classifier) with status 1 at once.
#[test]
fn ros_a_sample_that_cannot_be_read_is_skipped_and_the_node_goes_on() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
"$LOC" 2> "$OUT/localiser.err" & L=$!
# Reliable, like the localiser's /tf: the writer ends once its samples are acknowledged.
"$BAD" rt/tf tf2_msgs::msg::dds_::TFMessage_ 3; echo "writer=$?"
wait_until 10 grep -q "skipped a sample that cannot be read" "$OUT/localiser.err"
kill -0 $L && echo "alive"
kill -INT $L; wait $L; echo "localiser=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LOC", &workspace_bin("localiser")),
            (
                "BAD",
                Path::new(env!("CARGO_BIN_EXE_dds_bad_encapsulation")),
            ),
            ("OUT", dir.path()),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let log = std::fs::read_to_string(dir.path().join("localiser.err")).unwrap();
    for want in ["writer=0", "alive", "localiser=0"] {
        assert!(stdout.contains(want), "expected {want}: {stdout}\n{log}");
    }
    assert!(log.contains("/tf: skipped a sample"), "{log}");
}

/// Activity `i` stamped `t_ns`.
fn activity_at(i: usize, t_ns: i64) -> Activity {
    let mut a = activity(i);
    a.header.stamp = Time::from_nanos(t_ns);
    a
}

/// Replays `message(0)` on `topic`, then 3 s later (bag time) `message(1..=burst)` at once,
/// to a `topic echo` stopped (SIGSTOP) once it has the first: the replay's stdout and log.
fn replay_a_burst_to_a_stopped_subscriber<M: lidar_har_msgs::RosMessage>(
    topic: &topics::TopicSpec,
    burst: usize,
    message: impl Fn(usize, i64) -> M,
) -> (String, String) {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("burst");
    let mut w = BagWriter::create(&bag, WriterOptions::default()).unwrap();
    let handle = w.add_topic_for::<M>(topic.name, topic.qos).unwrap();
    w.write_message(handle, T0_NS, &message(0, T0_NS)).unwrap();
    let burst_ns = T0_NS + 3_000_000_000;
    for i in 1..=burst {
        w.write_message(handle, burst_ns, &message(i, burst_ns))
            .unwrap();
    }
    w.finish().unwrap();
    let script = r#"
"$LH" topic echo "$TOPIC" --timeout 60 > "$OUT/echo.jsonl" & E=$!
"$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:="$TOPIC" \
  -p wait_for_all_acked:=0.5 2> "$OUT/replay.log" & R=$!
# The subscriber stops acknowledging before the burst.
wait_until 20 has_lines "$OUT/echo.jsonl" 1
kill -STOP $E
wait $R; echo "replay=$?"
kill -CONT $E; kill -TERM $E; wait $E
"#
    .replace("$TOPIC", topic.name);
    let out = replay_in_netns(&script, &bag, dir.path(), Duration::from_secs(90));
    let log = std::fs::read_to_string(dir.path().join("replay.log")).unwrap();
    (String::from_utf8_lossy(&out.stdout).into_owned(), log)
}

/// A subscriber that stops acknowledging (here stopped with SIGSTOP) costs a keep-last
/// writer the samples RustDDS cannot take any more (its reliable send window, 8192 samples,
/// is full), as in other DDS implementations, where a keep-last writer never waits: the
/// replay used to wait 100 ms at the first of them, then end with status 1.
#[test]
fn ros_a_subscriber_that_stops_acknowledging_costs_samples_not_the_publisher() {
    if !netns_available() {
        return;
    }
    // More samples at once than the window holds.
    let (stdout, log) =
        replay_a_burst_to_a_stopped_subscriber(&topics::HUMAN_ACTIVITY, 10_000, activity_at);
    assert!(stdout.contains("replay=0"), "{stdout}\n{log}");
    assert!(
        log.contains("/human/activity: sample dropped"),
        "the replay must say it dropped samples: {log}"
    );
    // RustDDS's own warning, one per sample, is left out of the nodes' log.
    assert!(!log.contains("Write timed out"), "{log}");
}

/// A latched write that a stopped subscriber holds up (its send window, the topic's depth,
/// is full of samples that subscriber has not acknowledged) waits 2 s, then the sample is
/// dropped with a warning naming the topic, each time, and the publisher goes on.
#[test]
fn ros_a_latched_write_held_up_by_a_stopped_subscriber_is_dropped_after_its_wait() {
    if !netns_available() {
        return;
    }
    // /human/fall_alert keeps 10: 12 alerts after the stop fill the window and drop 2 (3 if
    // the subscriber stopped before acknowledging the first alert).
    let (stdout, log) =
        replay_a_burst_to_a_stopped_subscriber(&topics::FALL_ALERT, 12, numbered_alert);
    assert!(stdout.contains("replay=0"), "{stdout}\n{log}");
    let dropped = log
        .matches("/human/fall_alert: latched sample dropped")
        .count();
    assert!(
        (2..=3).contains(&dropped),
        "{dropped} latched samples dropped, expected those past the window: {log}"
    );
}

/// A fall alert `i` of the latched-topic bag, stamped `t_ns`.
fn numbered_alert(i: usize, t_ns: i64) -> FallAlert {
    FallAlert {
        header: Header::new(Time::from_nanos(t_ns), "map"),
        kind: FallAlert::FALL_DETECTED,
        position: Point {
            x: i as f64,
            y: 0.0,
            z: 0.0,
        },
        confidence: 0.875,
        event_time: Time::from_nanos(t_ns),
        description: format!("alert {i}"),
    }
}

/// A transient-local keep-last writer keeps its depth for subscribers that join late
/// (/human/fall_alert: 10): RustDDS kept every sample while no reader was matched, so a late
/// subscriber got all 25 alerts of a replay (and a /map replayed in a loop grew the process
/// by a map a pass). Its cache cleaning, every 6 s, now trims to the depth (and one more).
/// Subscribers that are there get everything, two /tf_static written at once included
/// (depth 1, so a send window of 1: the second waits, up to 2 s, for the first's
/// acknowledgement, which a subscriber that has just matched may send only at RustDDS's next
/// heartbeat, up to 1 s later; with the 100 ms wait of before, the second was dropped).
#[test]
fn ros_a_latched_topic_keeps_its_depth_for_late_subscribers() {
    if !netns_available() {
        return;
    }
    const ALERTS: usize = 25;
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("latched");
    let mut w = BagWriter::create(&bag, WriterOptions::default()).unwrap();
    let tf_static = w
        .add_topic_for::<TFMessage>(topics::TF_STATIC.name, topics::TF_STATIC.qos)
        .unwrap();
    let alert_topic = w
        .add_topic_for::<FallAlert>(topics::FALL_ALERT.name, topics::FALL_ALERT.qos)
        .unwrap();
    // A reliable topic nobody subscribes: the replay waits `wait_for_all_acked` for one.
    let activity_topic = w
        .add_topic_for::<Activity>(topics::HUMAN_ACTIVITY.name, topics::HUMAN_ACTIVITY.qos)
        .unwrap();
    for child in ["laser", "odom"] {
        let tf = TFMessage {
            transforms: vec![TransformStamped {
                header: Header::new(Time::from_nanos(T0_NS), "base_link"),
                child_frame_id: child.into(),
                transform: Default::default(),
            }],
        };
        w.write_message(tf_static, T0_NS, &tf).unwrap();
    }
    w.write_message(activity_topic, T0_NS, &activity_at(0, T0_NS))
        .unwrap();
    for i in 0..ALERTS {
        let t = T0_NS + 500_000_000 + 20_000_000 * i as i64;
        w.write_message(alert_topic, t, &numbered_alert(i, t))
            .unwrap();
    }
    w.finish().unwrap();
    let script = r#"
"$LH" topic echo /tf_static --count 2 --timeout 30 > "$OUT/live_tf.jsonl" & T=$!
"$LH" topic echo /human/fall_alert --count 25 --timeout 30 > "$OUT/live_alerts.jsonl" & A=$!
wait_until 20 topics_listed /tf_static /human/fall_alert
"$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_subscriber:=/tf_static \
  -p wait_for_all_acked:=40 2> "$OUT/replay.log" & R=$!
wait $T; echo "live_tf=$?"
wait $A; echo "live_alerts=$?"
wait_until 20 grep -q "played" "$OUT/replay.log"
# RustDDS cleans a writer's cache every 6 s: one cleaning after the last alert.
sleep 8
# Held messages come in order: once the newest (alert 24) is printed, all have come.
"$LH" topic echo /human/fall_alert --timeout 30 > "$OUT/late_alerts.jsonl" & L=$!
wait_until 20 grep -q '"x":24.0' "$OUT/late_alerts.jsonl"
kill -TERM $L; wait $L; echo "late=$?"
kill -INT $R; wait $R; echo "replay=$?"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(90));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let log = std::fs::read_to_string(dir.path().join("replay.log")).unwrap();
    for want in ["live_tf=0", "live_alerts=0", "late=0", "replay=0"] {
        assert!(stdout.contains(want), "expected {want}: {stdout}\n{log}");
    }
    assert!(!log.contains("dropped"), "{log}");
    // The replay publishes the static transforms played so far, merged by child frame
    // (`ros_a_late_tf_static_subscriber_gets_every_static_transform_of_a_replay`).
    let children: Vec<Vec<_>> = json_lines(&dir.path().join("live_tf.jsonl"))
        .iter()
        .map(|l| {
            let transforms = l["msg"]["transforms"].as_array().unwrap();
            transforms
                .iter()
                .map(|t| t["child_frame_id"].clone())
                .collect()
        })
        .collect();
    assert_eq!(children, [vec!["laser"], vec!["laser", "odom"]]);
    let alert_numbers = |file: &str| -> Vec<usize> {
        json_lines(&dir.path().join(file))
            .iter()
            .map(|l| l["msg"]["position"]["x"].as_f64().unwrap() as usize)
            .collect()
    };
    assert_eq!(
        alert_numbers("live_alerts.jsonl"),
        (0..ALERTS).collect::<Vec<_>>()
    );
    // The newest 10 (RustDDS's cleaning keeps one more than the limit); all 25 before.
    let late = alert_numbers("late_alerts.jsonl");
    assert!(
        (10..=11).contains(&late.len()) && late.ends_with(&[ALERTS - 1]),
        "a late subscriber got alerts {late:?} of a depth of 10"
    );
    assert!(late.windows(2).all(|w| w[1] == w[0] + 1), "{late:?}");
}

/// A subscriber that joins a replay's /tf_static late (rviz2 opened later, a restarted
/// localiser, `tf2_echo`) gets every static transform of the bag. On a robot each static
/// broadcaster is a latched writer of its own; the replay plays all of them through one of
/// depth 1, and after RustDDS's cache cleaning (every 6 s) a late subscriber got only the two
/// newest messages: base_link -> laser was lost. The replay now publishes the merged set each
/// time, as tf2's StaticTransformBroadcaster does.
#[test]
fn ros_a_late_tf_static_subscriber_gets_every_static_transform_of_a_replay() {
    if !netns_available() {
        return;
    }
    let frames = [
        ("base_link", "laser"),
        ("base_link", "imu"),
        ("map", "odom"),
    ];
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("tf_static");
    let mut w = BagWriter::create(&bag, WriterOptions::default()).unwrap();
    let tf_static = w
        .add_topic_for::<TFMessage>(topics::TF_STATIC.name, topics::TF_STATIC.qos)
        .unwrap();
    // A reliable topic nobody subscribes: the replay waits `wait_for_all_acked` for one.
    let activity_topic = w
        .add_topic_for::<Activity>(topics::HUMAN_ACTIVITY.name, topics::HUMAN_ACTIVITY.qos)
        .unwrap();
    for (i, (parent, child)) in frames.into_iter().enumerate() {
        let t = T0_NS + 10_000_000 * i as i64;
        let tf = TFMessage {
            transforms: vec![TransformStamped {
                header: Header::new(Time::from_nanos(t), parent),
                child_frame_id: child.into(),
                transform: Default::default(),
            }],
        };
        w.write_message(tf_static, t, &tf).unwrap();
    }
    w.write_message(activity_topic, T0_NS, &activity_at(0, T0_NS))
        .unwrap();
    w.finish().unwrap();
    let script = r#"
"$REPLAY" --ros-args -p bag:="$BAG" -p wait_for_all_acked:=40 2> "$OUT/replay.log" & R=$!
wait_until 20 grep -q "played" "$OUT/replay.log"
# RustDDS cleans a writer's cache every 6 s: one cleaning after the last message.
sleep 8
"$LH" topic echo /tf_static --timeout 30 > "$OUT/late_tf.jsonl" & L=$!
wait_until 20 has_lines "$OUT/late_tf.jsonl" 1
sleep 0.5
kill -TERM $L; wait $L; echo "late=$?"
kill -INT $R; wait $R; echo "replay=$?"
"#;
    let out = replay_in_netns(script, &bag, dir.path(), Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let log = std::fs::read_to_string(dir.path().join("replay.log")).unwrap();
    for want in ["late=0", "replay=0"] {
        assert!(stdout.contains(want), "expected {want}: {stdout}\n{log}");
    }
    let late = json_lines(&dir.path().join("late_tf.jsonl"));
    let last = late.last().expect("the late subscriber got no /tf_static");
    let got: Vec<(&str, &str)> = last["msg"]["transforms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            let parent = t["header"]["frame_id"].as_str().unwrap();
            (parent, t["child_frame_id"].as_str().unwrap())
        })
        .collect();
    assert_eq!(
        got,
        frames,
        "the last of {} late /tf_static messages",
        late.len()
    );
}

/// A second SIGINT or SIGTERM ends a node at once, by that signal, as with the `lidar-har`
/// tool: the first asks for a clean stop, which a stuck DDS stack could hold up for ever,
/// and every further signal used to be taken for the first. Two signals of one kind sent
/// together may reach a process as one, so the test sends two kinds, to a stopped process,
/// which takes both once continued.
#[test]
fn ros_a_second_signal_ends_a_node_at_once() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
"$LOC" 2> "$OUT/localiser.err" & L=$!
# Up: it subscribes /tf (its signal handlers are installed before it joins the graph).
wait_until 20 topics_listed /tf
# Both signals pending at once: sent one after the other, the second could come after the
# clean stop the first asked for had ended the process (status 0).
kill -STOP $L; kill -INT $L; kill -TERM $L; kill -CONT $L
wait $L; echo "localiser=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("LOC", &workspace_bin("localiser")),
            ("OUT", dir.path()),
        ],
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    // Ended by SIGTERM or by SIGINT, whichever of the two it took second; 0 was a clean stop.
    assert!(
        stdout.contains("localiser=143") || stdout.contains("localiser=130"),
        "{stdout}"
    );
}

/// `ros2 service call` (a Cyclone DDS client) stops the `rplidar_driver`'s motor and
/// starts it again, as rplidar_ros's services do: no /scan while stopped, a /diagnostics
/// report saying so, scans again after `start_motor`; `-r` moves a service as it moves topics.
#[test]
fn ros_rplidar_driver_stops_and_starts_its_motor_on_service_calls() {
    let Some(python) = cyclone_python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
mkfifo "$OUT/ctl"
"$FAKE" "$OUT/rplidar" < "$OUT/ctl" > "$OUT/fake.out" 2> "$OUT/fake.err" & F=$!
exec 3> "$OUT/ctl"
wait_until 10 has_lines "$OUT/fake.out" 1
"$DRIVER" --ros-args -p port:="$(head -n 1 "$OUT/fake.out")" -p diagnostics_period:=0.5 \
  -r stop_motor:=lidar/stop_motor 2> "$OUT/driver.err" & D=$!
echo_count /scan 2 20 scanning
cd "$PYDIR"
"$PY" ros_empty_service_call.py /lidar/stop_motor 20; echo "stop_call=$?"
echo_count /diagnostics 2 20 stopped
echo_count /scan 1 3 scan_while_stopped
"$PY" ros_empty_service_call.py /start_motor 20; echo "start_call=$?"
echo_count /scan 2 20 restarted
kill -INT $D; wait $D; echo "driver=$?"
exec 3>&-
wait $F; echo "fake=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("DRIVER", &workspace_bin("rplidar_driver")),
            ("FAKE", Path::new(env!("CARGO_BIN_EXE_fake_rplidar"))),
            ("OUT", dir.path()),
            ("PY", &python),
            ("PYDIR", &repo_root().join("tests/python")),
        ],
        Duration::from_secs(120),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let log = std::fs::read_to_string(dir.path().join("driver.err")).unwrap_or_default();
    let fake_log = std::fs::read_to_string(dir.path().join("fake.err")).unwrap_or_default();
    for want in [
        "scanning=0",
        "/lidar/stop_motor answered",
        "stop_call=0",
        "stopped=0",
        "/start_motor answered",
        "start_call=0",
        "restarted=0",
        "driver=0",
        "fake=0",
    ] {
        assert!(
            stdout.contains(want),
            "expected {want}: {stdout}\n{log}\n{fake_log}"
        );
    }
    // `--require-count` fails when the count does not come: no scan while stopped.
    assert!(
        !stdout.contains("scan_while_stopped=0"),
        "a scan while the motor was stopped: {stdout}"
    );
    let reports = json_lines(&dir.path().join("stopped.jsonl"));
    for report in &reports {
        let status = &report["msg"]["status"][0];
        assert_eq!(status["level"], 0, "{status}");
        assert!(
            status["message"]
                .as_str()
                .unwrap()
                .contains("stopped on request"),
            "{status}"
        );
    }
    // The fake started scanning at start-up and again after start_motor (more, were the
    // host to stall long enough for a reset).
    let starts: usize = fake_log
        .split(" scan starts")
        .next()
        .and_then(|head| head.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no scan starts in the fake's log: {fake_log}"));
    assert!(starts >= 2, "{fake_log}");
    assert!(!log.contains("ERROR"), "{log}");
}

/// The `rplidar_driver` node against the fake RPLIDAR on a pseudo-terminal
/// (`fake_rplidar`), over DDS: /scan carries the configured frame and beam count with
/// returns wherever the fake's room has them, /diagnostics says OK while it scans, WARN
/// while the fake's window is covered (every scan `+inf`, which reads as free space) and OK
/// again once returns come back; SIGINT stops the node with status 0.
#[test]
fn ros_rplidar_driver_publishes_a_fake_devices_scans_and_warns_when_it_is_blinded() {
    if !netns_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
mkfifo "$OUT/ctl"
"$FAKE" "$OUT/rplidar" < "$OUT/ctl" > "$OUT/fake.out" 2> "$OUT/fake.err" & F=$!
exec 3> "$OUT/ctl"
wait_until 10 has_lines "$OUT/fake.out" 1
"$DRIVER" --ros-args -p port:="$(head -n 1 "$OUT/fake.out")" -p frame_id:=e2e_laser \
  -p diagnostics_period:=0.5 2> "$OUT/driver.err" & D=$!
echo_count /scan 5 20 scan --full-length
echo_count /diagnostics 3 20 seeing --full-length
echo blind >&3
wait_until 20 grep -q "no return on any beam" "$OUT/driver.err"
echo_count /scan 2 20 blind_scan --full-length
echo_count /diagnostics 2 20 blind --full-length
echo see >&3
wait_until 20 grep -q "returns again" "$OUT/driver.err"
echo_count /diagnostics 2 20 back --full-length
kill -INT $D; wait $D; echo "driver=$?"
exec 3>&-
wait $F; echo "fake=$?"
"#;
    let out = in_netns(
        script,
        &[
            ("LH", &workspace_bin("lidar-har")),
            ("DRIVER", &workspace_bin("rplidar_driver")),
            ("FAKE", Path::new(env!("CARGO_BIN_EXE_fake_rplidar"))),
            ("OUT", dir.path()),
        ],
        Duration::from_secs(120),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let log = std::fs::read_to_string(dir.path().join("driver.err")).unwrap_or_default();
    let fake_log = std::fs::read_to_string(dir.path().join("fake.err")).unwrap_or_default();
    for want in [
        "scan=0",
        "seeing=0",
        "blind_scan=0",
        "blind=0",
        "back=0",
        "driver=0",
        "fake=0",
    ] {
        assert!(
            stdout.contains(want),
            "expected {want}: {stdout}\n{log}\n{fake_log}"
        );
    }
    let read = |name: &str| json_lines(&dir.path().join(format!("{name}.jsonl")));
    let ranges = |line: &serde_json::Value| -> Vec<Option<f64>> {
        line["msg"]["ranges"]
            .as_array()
            .expect("ranges printed whole")
            .iter()
            .map(serde_json::Value::as_f64)
            .collect()
    };
    // The fake's room returns everywhere but a window at device angles 200..215 deg, ROS
    // angles (-35, -20] deg (ROS angle = 180 deg - device angle).
    let scans = read("scan");
    assert_eq!(scans.len(), 5);
    for line in &scans {
        let msg = &line["msg"];
        assert_eq!(msg["header"]["frame_id"], "e2e_laser");
        let (min, step) = (
            msg["angle_min"].as_f64().unwrap(),
            msg["angle_increment"].as_f64().unwrap(),
        );
        let beams = ranges(line);
        assert_eq!(beams.len(), 720);
        for (i, r) in beams.iter().enumerate() {
            let deg = (min + i as f64 * step).to_degrees();
            if !(-36.0..=-19.0).contains(&deg) {
                assert!(
                    r.is_some_and(|r| (0.15..=12.0).contains(&r)),
                    "beam {i} at {deg:.1} deg: {r:?}"
                );
            } else if -34.0 < deg && deg < -21.0 {
                assert_eq!(r, &None, "beam {i} at {deg:.1} deg is in the window");
            }
        }
    }
    let statuses = |name: &str| -> Vec<serde_json::Value> {
        read(name)
            .iter()
            .map(|line| line["msg"]["status"][0].clone())
            .collect()
    };
    let value = |status: &serde_json::Value, key: &str| -> String {
        status["values"]
            .as_array()
            .unwrap()
            .iter()
            .find(|kv| kv["key"] == key)
            .and_then(|kv| kv["value"].as_str())
            .unwrap_or_default()
            .to_owned()
    };
    // A period without a complete rotation (the host stalled, the suite loading both cores)
    // is reported as such whatever the phase; each phase must have its own report too.
    let stalled = "scanning, but no complete rotation";
    for (name, level, message) in [
        ("seeing", 0, "scanning at"),
        ("blind", 1, "no return on any beam"),
        ("back", 0, "scanning at"),
    ] {
        let got = statuses(name);
        let text = |status: &serde_json::Value| status["message"].as_str().unwrap().to_owned();
        assert!(
            got.iter()
                .any(|status| status["level"] == level && text(status).starts_with(message)),
            "{name}: {got:?}"
        );
        for status in &got {
            assert!(
                text(status).starts_with(message) || text(status).starts_with(stalled),
                "{name}: {status}"
            );
        }
    }
    let last_seeing = statuses("seeing").pop().unwrap();
    let valid: usize = value(&last_seeing, "valid_beams").parse().unwrap();
    assert!((680..=700).contains(&valid), "{last_seeing}");
    for status in statuses("blind") {
        assert_eq!(value(&status, "valid_beams"), "0", "{status}");
    }
    for line in read("blind_scan") {
        assert!(ranges(&line).iter().all(Option::is_none), "{line}");
    }
}
