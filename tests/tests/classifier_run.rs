//! `lidar-har run` and `lidar-har demo` with the classifier, end to end through the binary:
//! simulate, localise, classify on real ONNX Runtime, record, summarise.

use std::path::{Path, PathBuf};
use std::process::Output;

use lidar_har_bag::BagReader;
use lidar_har_e2e::{copy_bag, lidar_har as lidar_har_command, repo_root, runtime_available};
use lidar_har_msgs::geometry_msgs::PoseWithCovarianceStamped;
use lidar_har_msgs::lidar_har_msgs::Activity;

fn lidar_har(args: &[&str]) -> Output {
    lidar_har_command()
        .args(args)
        .current_dir(repo_root())
        .output()
        .expect("lidar-har runs")
}

/// Runs `lidar-har` and fails the test with its stderr unless it succeeds.
fn lidar_har_ok(args: &[&str]) -> Output {
    let out = lidar_har(args);
    assert!(
        out.status.success(),
        "lidar-har {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Simulates `seconds` of the living room into the bag directory `out`.
fn simulate_living_room(seconds: &str, out: &Path) {
    lidar_har_ok(&[
        "simulate",
        "--scene",
        "config/scenes/living_room.yaml",
        "--duration",
        seconds,
        "--out",
        path(out),
    ]);
}

fn path(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}

/// `lidar-har dataset` into `out` with the committed model's image settings (its metadata
/// must match the dataset's) and `args`.
fn dataset_for_the_committed_model(out: &Path, args: &[&str]) {
    let mut all = vec!["dataset"];
    all.extend_from_slice(args);
    all.extend_from_slice(&[
        "--window",
        "20",
        "--size",
        "32",
        "--resolution",
        "0.08",
        "--framing",
        "room_fixed",
        "--out",
        path(out),
    ]);
    lidar_har_ok(&all);
}

/// `lidar-har evaluate` of the committed model on the dataset `data`, into `out`.
fn evaluate_committed_model(data: &Path, out: &Path) -> Output {
    lidar_har(&[
        "evaluate",
        "--model",
        "models/activity.onnx",
        "--data",
        path(data),
        "--out",
        path(out),
    ])
}

/// The small real step model the infer crate is tested with (untrained: checks plumbing).
fn test_model() -> PathBuf {
    repo_root().join("crates/infer/tests/fixtures/step_model.onnx")
}

#[test]
fn run_without_the_model_says_how_to_proceed() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no_model.onnx");
    let out = lidar_har(&[
        "run",
        "--bag",
        path(tmp.path()),
        "--out",
        path(&tmp.path().join("out")),
        "--model",
        path(&missing),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(path(&missing)) && err.contains("--no-classifier"),
        "{err}"
    );

    // A model named by a classifier configuration is blamed on it, not on --model.
    let config = tmp.path().join("classifier.yaml");
    std::fs::write(&config, format!("model: {}\n", path(&missing))).unwrap();
    let out = lidar_har(&[
        "run",
        "--bag",
        path(tmp.path()),
        "--out",
        path(&tmp.path().join("out")),
        "--classifier-config",
        path(&config),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(path(&missing))
            && err.contains(&format!("`model` of --classifier-config {}", path(&config))),
        "{err}"
    );
}

#[test]
fn demo_without_a_model_refuses_rather_than_faking() {
    let tmp = tempfile::tempdir().unwrap();
    let demo_out = tmp.path().join("demo");
    let out = lidar_har(&[
        "demo",
        "--out",
        path(&demo_out),
        "--model",
        path(&tmp.path().join("none.onnx")),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("none.onnx") && err.contains("does not fake results"),
        "{err}"
    );
    assert!(!demo_out.exists(), "nothing is written without a model");

    // The model a classifier configuration names counts as much as --model.
    let config = tmp.path().join("classifier.yaml");
    let other = tmp.path().join("other.onnx");
    std::fs::write(&config, format!("model: {}\n", path(&other))).unwrap();
    let out = lidar_har(&[
        "demo",
        "--out",
        path(&demo_out),
        "--classifier-config",
        path(&config),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("other.onnx"), "{err}");
    assert!(!demo_out.exists(), "nothing is written without a model");
}

#[test]
fn demo_run_again_replaces_its_own_output_but_nothing_else() {
    if !runtime_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let demo_out = tmp.path().join("demo_out");
    let outputs = [
        "sim/metadata.yaml",
        "run/summary.json",
        "scene.png",
        "timeline.png",
    ];
    lidar_har_ok(&["demo", "--out", path(&demo_out)]);
    // Marks the first run's summary, to see it replaced.
    std::fs::write(demo_out.join("run/summary.json"), "first").unwrap();
    let again = lidar_har_ok(&["demo", "--out", path(&demo_out)]);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(err.contains("replacing the earlier demo output"), "{err}");
    assert_ne!(
        std::fs::read_to_string(demo_out.join("run/summary.json")).unwrap(),
        "first"
    );
    for output in outputs {
        assert!(demo_out.join(output).is_file(), "{output}");
    }

    // Something the demo did not write: refused by name, and nothing deleted.
    let notes = demo_out.join("notes.txt");
    std::fs::write(&notes, "mine").unwrap();
    let out = lidar_har(&["demo", "--out", path(&demo_out)]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("notes.txt") && err.contains("choose another or delete it"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "mine");
    for output in outputs {
        assert!(demo_out.join(output).is_file(), "{output} deleted");
    }
}

#[test]
fn run_with_a_model_records_activities_and_scores_them() {
    if !runtime_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    let run = tmp.path().join("run");
    simulate_living_room("4", &sim);
    let model = test_model();
    lidar_har_ok(&[
        "run",
        "--bag",
        path(&sim),
        "--out",
        path(&run),
        "--model",
        path(&model),
    ]);

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap();
    let activity = &summary["activity"];
    let classified = activity["scans_classified"].as_u64().unwrap();
    assert!(classified > 20, "{activity:#}");
    // The simulator writes /ground_truth/activity, so the run is scored (the untrained test
    // model's accuracy itself means nothing).
    let accuracy = activity["accuracy"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&accuracy));
    assert_eq!(
        activity["metrics"]["confusion"].as_array().unwrap().len(),
        9
    );
    assert!(activity["alerts"].is_array());
    assert!(activity["classify_time_us"]["median"].as_f64().unwrap() > 0.0);

    let bag = BagReader::open(&run).unwrap();
    assert_eq!(
        bag.topic("/human/activity").unwrap().type_name,
        "lidar_har_msgs/msg/Activity"
    );
    assert_eq!(
        bag.topic("/human/fall_alert").unwrap().type_name,
        "lidar_har_msgs/msg/FallAlert"
    );
    let mut count = 0;
    for message in bag.messages_on(&["/human/activity"]).unwrap() {
        let msg: Activity = lidar_har_msgs::decode(&message.unwrap().data).unwrap();
        assert_eq!(msg.probabilities.len(), 9);
        assert!((msg.probabilities.iter().sum::<f32>() - 1.0).abs() < 1e-4);
        assert_eq!(Activity::label_of(msg.activity), Some(msg.label.as_str()));
        count += 1;
    }
    assert_eq!(count, classified);

    // Ground truth that cannot be read is counted as skipped, and nothing is scored.
    let garbled = tmp.path().join("garbled");
    copy_bag(&sim, &garbled, &[], |topic, mut data| {
        if topic == "/ground_truth/activity" {
            data.truncate(10);
        }
        data
    });
    let rerun = tmp.path().join("rerun");
    lidar_har_ok(&[
        "run",
        "--bag",
        path(&garbled),
        "--out",
        path(&rerun),
        "--model",
        path(&model),
    ]);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rerun.join("summary.json")).unwrap())
            .unwrap();
    let truths = BagReader::open(&sim)
        .unwrap()
        .topic("/ground_truth/activity")
        .unwrap()
        .message_count;
    assert_eq!(
        summary["decode_errors"].as_u64(),
        Some(truths),
        "{summary:#}"
    );
    assert!(summary["activity"]["accuracy"].is_null(), "{summary:#}");
}

#[test]
fn run_with_a_pose_head_records_the_pelvis_and_scores_it() {
    if !runtime_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    simulate_living_room("3", &sim);
    let fixtures = repo_root().join("crates/infer/tests/fixtures");
    let run_with_head = |head: &str, name: &str, settings: &str| -> serde_json::Value {
        let config = tmp.path().join(format!("{name}.yaml"));
        std::fs::write(
            &config,
            format!(
                "model: {}\npose_head: {}\n{settings}",
                path(&test_model()),
                path(&fixtures.join(head))
            ),
        )
        .unwrap();
        let run = tmp.path().join(name);
        lidar_har_ok(&[
            "run",
            "--bag",
            path(&sim),
            "--out",
            path(&run),
            "--classifier-config",
            path(&config),
        ]);
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap()
    };

    // The fixture head reads the test model's state and places a pelvis on every seen scan
    // with 3 scans of history.
    let summary = run_with_head("pose_head.onnx", "with_head", "");
    let activity = &summary["activity"];
    assert_eq!(activity["pose_head"]["status"], "used", "{activity:#}");
    let published = activity["pelvis_published"].as_u64().unwrap();
    assert!(published > 20, "{activity:#}");
    assert!(
        summary["pelvis_error_m"]["median"]
            .as_f64()
            .unwrap()
            .is_finite()
    );
    let bag = BagReader::open(tmp.path().join("with_head")).unwrap();
    assert_eq!(
        bag.topic("/human/pelvis").unwrap().type_name,
        "geometry_msgs/msg/PoseWithCovarianceStamped"
    );
    let decode = |message: Result<_, _>| -> PoseWithCovarianceStamped {
        let message: lidar_har_bag::BagMessage = message.unwrap();
        lidar_har_msgs::decode(&message.data).unwrap()
    };
    let track_covariance: std::collections::HashMap<_, _> = bag
        .messages_on(&["/human/pose"])
        .unwrap()
        .map(|m| {
            let msg = decode(m);
            (msg.header.stamp, msg.pose.covariance)
        })
        .collect();
    // The track's covariance plus the head's expected error, which follows the state.
    let mut head_variances = Vec::new();
    for message in bag.messages_on(&["/human/pelvis"]).unwrap() {
        let msg = decode(message);
        assert_eq!(msg.header.frame_id, "map");
        let p = msg.pose.pose.position;
        assert!(p.x.is_finite() && p.y.is_finite());
        let track = track_covariance[&msg.header.stamp];
        let (x, y) = (
            msg.pose.covariance[0] - track[0],
            msg.pose.covariance[7] - track[7],
        );
        assert!(x > 0.0 && (x - y).abs() < 1e-12, "{x} {y}");
        head_variances.push(x);
    }
    assert_eq!(head_variances.len() as u64, published);
    head_variances.sort_by(f64::total_cmp);
    assert!(
        head_variances[0] < head_variances[head_variances.len() - 1],
        "the same expected error on every scan: {head_variances:?}"
    );

    // A head fitted on another model is left out, and the run says why.
    let summary = run_with_head("pose_head_other_model.onnx", "other_head", "");
    let activity = &summary["activity"];
    assert_eq!(activity["pose_head"]["status"], "not_used", "{activity:#}");
    let reason = activity["pose_head"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("fitted on another activity model"),
        "{reason}"
    );
    assert_eq!(activity["pelvis_published"], 0);
    assert!(summary["pelvis_error_m"].is_null());
    assert!(activity["scans_classified"].as_u64().unwrap() > 20);

    // Lanes that leave no room for the head's states between them (4 x (1 + 3) = 16 states
    // in a period of 10 scans, the test model's window of 8 x 1.2) lose the head, not the
    // activity and the alerts: the run used to fail.
    let settings = "lanes: 4\npose_head_lanes_between: 3\n";
    let summary = run_with_head("pose_head.onnx", "crowded_lanes", settings);
    let activity = &summary["activity"];
    assert_eq!(activity["pose_head"]["status"], "not_used", "{activity:#}");
    let reason = activity["pose_head"]["reason"].as_str().unwrap();
    assert!(reason.contains("pose_head_lanes_between = 3"), "{reason}");
    assert!(activity["scans_classified"].as_u64().unwrap() > 20);
}

#[test]
fn alerts_measures_latency_and_false_alerts_end_to_end() {
    if !runtime_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // Its folder is made up front (it used to fail only after the whole run).
    let report = tmp.path().join("reports/alerts.json");
    let out = lidar_har(&[
        "alerts",
        "--model",
        path(&repo_root().join("models/activity.onnx")),
        "--scenes",
        "config/scenes/living_room.yaml",
        "--fall-episodes",
        "1",
        "--no-fall-hours",
        "0.01",
        "--episode-seconds",
        "20",
        "--out",
        path(&report),
        "--trace-episode",
        "0",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    // The trace: one line per scan of the fall episode (20 s at 20 Hz, and the 2.4 s it runs
    // on for a fall at its end: the longest fall and the latency target), none of the others.
    let stderr = String::from_utf8_lossy(&out.stderr);
    let traced = stderr.lines().filter(|l| l.starts_with("trace t=")).count();
    assert!((443..=453).contains(&traced), "{traced} trace lines");
    assert!(
        stderr.lines().any(|l| l.contains("truth=falling_down")),
        "{stderr}"
    );
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("falls:") && stdout.contains("without falls:"),
        "{stdout}"
    );
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let falls = r["falls"].as_u64().unwrap();
    assert!(falls >= 1, "a fall episode's script has a fall: {r}");
    let outcomes = r["outcomes"].as_array().unwrap();
    assert_eq!(outcomes.len() as u64, falls);
    // Falls that begin while the episode runs on are not counted.
    assert!(
        outcomes
            .iter()
            .all(|o| o["start_s"].as_f64().unwrap() < 20.0),
        "{r}"
    );
    let alerted = r["falls_alerted"].as_u64().expect("falls_alerted");
    let within_target = r["falls_alerted_within_target"]
        .as_u64()
        .expect("falls_alerted_within_target");
    assert!(within_target <= alerted && alerted <= falls, "{r}");
    assert!((r["no_fall_hours"].as_f64().unwrap() - 20.0 * 2.0 / 3600.0).abs() < 1e-9);
    let false_alerts = r["false_alerts"].as_u64().unwrap();
    assert_eq!(
        false_alerts,
        r["false_fall_detected"].as_u64().unwrap() + r["false_person_down"].as_u64().unwrap()
    );
    // Streaming classification: one sample per published scan of the three 20 s episodes
    // (1,200 scans; the first half-window of each and unseen scans publish nothing).
    let scans = &r["scans"];
    let samples = scans["samples"].as_u64().unwrap();
    assert!((300..1200).contains(&samples), "{scans}");
    let confused: u64 = scans["confusion"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|row| row.as_array().unwrap())
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert_eq!(confused, samples);
    let accuracy = scans["accuracy"].as_f64().unwrap();
    assert!(
        accuracy > 0.3,
        "the committed model reads most scans right: {accuracy}"
    );
    assert!(stdout.contains("streaming classification:"), "{stdout}");
}

#[test]
fn alerts_replayed_from_saved_readings_match_a_full_run() {
    if !runtime_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let model = repo_root().join("models/activity.onnx");
    let committed = std::fs::read_to_string(repo_root().join("config/classifier.yaml")).unwrap();
    let changed = |text: &str, from: &str, to: &str| {
        assert_eq!(
            text.matches(from).count(),
            1,
            "{from} in config/classifier.yaml"
        );
        text.replace(from, to)
    };
    // Other fall_alert settings: PERSON_DOWN a second after going down, falls on shorter runs.
    let other = tmp.path().join("other.yaml");
    let other_text = changed(&committed, "down_after_s: 15.0", "down_after_s: 1.0");
    let other_text = changed(&other_text, "fall_min_scans: 5", "fall_min_scans: 3");
    std::fs::write(&other, other_text).unwrap();
    let full_run = |config: &Path, report: &Path, readings: Option<&Path>| {
        let mut args = vec![
            "alerts",
            "--model",
            path(&model),
            "--classifier-config",
            path(config),
            "--scenes",
            "config/scenes/kitchen.yaml",
            "--fall-episodes",
            "1",
            "--no-fall-hours",
            "0",
            "--stay-down-episodes",
            "1",
            // Long enough for the stay-down episode's spell to fall due (15 s on the floor).
            "--episode-seconds",
            "30",
            "--seed",
            "4",
            "--out",
            path(report),
        ];
        if let Some(readings) = readings {
            args.extend_from_slice(&["--save-readings", path(readings)]);
        }
        lidar_har_ok(&args);
        std::fs::read_to_string(report).unwrap()
    };
    let replay = |config: &Path, report: &Path, readings: &Path| {
        lidar_har_ok(&[
            "alerts",
            "--readings",
            path(readings),
            "--classifier-config",
            path(config),
            "--out",
            path(report),
        ]);
        std::fs::read_to_string(report).unwrap()
    };
    let readings = tmp.path().join("readings.zst");
    let committed_config = repo_root().join("config/classifier.yaml");
    let recorded = full_run(
        &committed_config,
        &tmp.path().join("a.json"),
        Some(&readings),
    );
    let other_run = full_run(&other, &tmp.path().join("b.json"), None);
    assert_ne!(recorded, other_run, "the settings change the alerts");
    assert_eq!(
        replay(&committed_config, &tmp.path().join("c.json"), &readings),
        recorded
    );
    assert_eq!(
        replay(&other, &tmp.path().join("d.json"), &readings),
        other_run
    );
    // The same settings changed on the command line instead of in a file.
    let by_option = tmp.path().join("e.json");
    lidar_har_ok(&[
        "alerts",
        "--readings",
        path(&readings),
        "--fall-alert",
        "down_after_s=1.0",
        "--fall-alert",
        "fall_min_scans=3",
        "--out",
        path(&by_option),
    ]);
    assert_eq!(std::fs::read_to_string(&by_option).unwrap(), other_run);

    // What a replay cannot change, and files that are not readings, are refused by name.
    let lanes = tmp.path().join("lanes.yaml");
    std::fs::write(&lanes, changed(&committed, "\nlanes: 2", "\nlanes: 3")).unwrap();
    let not_readings = tmp.path().join("a.json");
    let cases: &[(&[&str], &str)] = &[
        (
            &["--classifier-config", path(&lanes)],
            "only the fall_alert settings can change on replay",
        ),
        (&["--seed", "5"], "cannot be used with"),
        (
            &["--fall-alert", "fall_min_scan=3"],
            "--fall-alert: classifier configuration: fall_alert setting `fall_min_scan=3`: no such setting",
        ),
        (&["--save-readings", "x.zst"], "cannot be used with"),
    ];
    for (extra, needle) in cases {
        let mut args = vec!["alerts", "--readings", path(&readings)];
        args.extend_from_slice(extra);
        let out = lidar_har(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{extra:?}");
        assert!(err.contains(needle), "{extra:?}: {err}");
    }
    let out = lidar_har(&["alerts", "--readings", path(&not_readings)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains(path(&not_readings)) && err.contains("not a readings file"),
        "{err}"
    );
}

#[test]
fn alerts_refuses_what_it_cannot_measure_before_simulating() {
    if !runtime_available() {
        return;
    }
    let model = repo_root().join("models/activity.onnx");
    let cases: &[(&[&str], &str)] = &[
        (&["--latency-target-s", "NaN"], "--latency-target-s NaN"),
        (&["--latency-target-s=-1"], "--latency-target-s -1"),
        (
            &["--fall-episodes", "0", "--no-fall-hours", "0"],
            "nothing to measure",
        ),
        (&["--no-fall-hours", "1e9"], "--no-fall-hours 1000000000"),
        (
            &[
                "--fall-episodes",
                "1",
                "--no-fall-hours",
                "0",
                "--trace-episode",
                "3",
            ],
            "--trace-episode 3: there are only episodes 0..1",
        ),
    ];
    for (extra, needle) in cases {
        let mut args = vec!["alerts", "--model", path(&model)];
        args.extend_from_slice(extra);
        let out = lidar_har(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{extra:?}");
        assert!(err.contains(needle), "{extra:?}: {err}");
    }
    // A room too small for any random script: every episode is skipped, and a report of
    // nothing (no falls missed, no false alert) is refused rather than written.
    let tmp = tempfile::tempdir().unwrap();
    let closet = tmp.path().join("closet.yaml");
    std::fs::write(
        &closet,
        "duration: 30\nroom: {outline: [[0, 0], [1.2, 0], [1.2, 1.2], [0, 1.2]]}\n\
         robot: {start: {x: 0.2, y: 0.2}}\nperson: {start: {x: 0.7, y: 0.7}, script: \
         [{activity: standing, duration: 30}]}\n",
    )
    .unwrap();
    let report = tmp.path().join("report.json");
    let out = lidar_har(&[
        "alerts",
        "--model",
        path(&model),
        "--scenes",
        path(&closet),
        "--fall-episodes",
        "2",
        "--no-fall-hours",
        "0",
        "--out",
        path(&report),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("none of the 2 episodes with falls could be run"),
        "{err}"
    );
    assert!(!report.exists());
}

#[test]
fn alerts_without_a_model_names_it() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("none.onnx");
    let out = lidar_har(&["alerts", "--model", path(&missing)]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(path(&missing)), "{err}");

    // The model a classifier configuration names counts, as for `run` and `demo`: it used
    // to be ignored for models/activity.onnx. (Short, should it run at all.)
    let config = tmp.path().join("classifier.yaml");
    std::fs::write(&config, format!("model: {}\n", path(&missing))).unwrap();
    let out = lidar_har(&[
        "alerts",
        "--classifier-config",
        path(&config),
        "--fall-episodes",
        "1",
        "--no-fall-hours",
        "0",
        "--episode-seconds",
        "5",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(path(&missing)) && err.contains("--classifier-config"),
        "{err}"
    );
}

#[test]
fn evaluate_refuses_a_dataset_without_test_windows_before_writing_anything() {
    if !runtime_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    dataset_for_the_committed_model(
        &data,
        &[
            "--scenes",
            "config/scenes/kitchen.yaml",
            "--episodes",
            "1",
            "--test-fraction",
            "0",
            "--episode-seconds",
            "6",
        ],
    );
    let eval = tmp.path().join("eval");
    let out = evaluate_committed_model(&data, &eval);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("no test windows"),
        "{err}"
    );
    assert!(
        !eval.exists(),
        "a confusion matrix was written before the error"
    );
}

#[test]
fn evaluate_scores_a_fixed_lidar_dataset_per_lidar_spot() {
    if !runtime_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    dataset_for_the_committed_model(
        &data,
        &[
            "--scenes",
            "config/scenes/[kl]*.yaml",
            "--episodes",
            "3",
            "--test-fraction",
            "0.67",
            "--episode-seconds",
            "8",
            "--stride",
            "5",
            "--seed",
            "5",
            "--fixed-lidar",
        ],
    );
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("index.json")).unwrap()).unwrap();
    for e in index["episodes"].as_array().unwrap() {
        let at = e["fixed_lidar_at"]
            .as_array()
            .expect("a fixed Lidar's spot per episode");
        assert!(
            at.iter().all(|v| v.as_f64().is_some_and(f64::is_finite)),
            "{e}"
        );
    }

    // The localiser's sightings, not the images, say when the person was in view: blank the
    // last image of a window seen throughout, as a person seen outside the image leaves it.
    let positions: ndarray::Array3<f32> =
        ndarray_npy::read_npy(data.join("test_positions.npy")).unwrap();
    let seen: Vec<Vec<bool>> = positions
        .outer_iter()
        .map(|window| window.outer_iter().map(|p| p[2].is_finite()).collect())
        .collect();
    let images_path = data.join("test_images.npy");
    let mut images: ndarray::Array4<u8> = ndarray_npy::read_npy(&images_path).unwrap();
    let blanked = seen
        .iter()
        .position(|window| window.iter().all(|&s| s))
        .expect("a window in full view");
    images.slice_mut(ndarray::s![blanked, -1, .., ..]).fill(0);
    ndarray_npy::write_npy(&images_path, &images).unwrap();

    let eval = tmp.path().join("eval");
    let out = evaluate_committed_model(&data, &eval);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(eval.join("metrics.json")).unwrap()).unwrap();
    let confusion_total = |scores: &serde_json::Value| -> u64 {
        scores["confusion"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|row| row.as_array().unwrap())
            .map(|v| v.as_u64().unwrap())
            .sum()
    };
    let windows = metrics["windows"].as_u64().unwrap();
    assert_eq!(
        confusion_total(&metrics),
        windows,
        "every test window is in the confusion matrix"
    );
    let within = &metrics["within_one_activity"];
    let within_windows = within["windows"].as_u64().unwrap();
    assert!(
        within_windows > 0 && within_windows < windows,
        "some, not all, windows lie within one activity: {within_windows} of {windows}"
    );
    assert_eq!(confusion_total(within), within_windows);
    // The person is hidden from some fixed spots for part of an episode, never from most.
    let in_view = &metrics["in_full_view"];
    let in_view_windows = in_view["windows"].as_u64().unwrap();
    let seen_throughout = seen.iter().filter(|w| w.iter().all(|&s| s)).count() as u64;
    assert_eq!(in_view_windows, seen_throughout);
    assert!(
        in_view_windows > 0 && in_view_windows <= windows,
        "{in_view_windows} of {windows} windows in full view"
    );
    assert_eq!(confusion_total(in_view), in_view_windows);
    let published = &metrics["seen_at_last_scan"];
    let published_windows = published["windows"].as_u64().unwrap();
    let seen_at_last_scan = seen.iter().filter(|w| w[w.len() - 1]).count() as u64;
    assert_eq!(published_windows, seen_at_last_scan);
    assert!(published_windows >= in_view_windows && published_windows <= windows);
    assert_eq!(confusion_total(published), published_windows);
    let both = &metrics["within_one_activity_in_full_view"];
    let both_windows = both["windows"].as_u64().unwrap();
    assert!(both_windows <= within_windows.min(in_view_windows));
    assert_eq!(confusion_total(both), both_windows);
    let spread = &metrics["per_episode"];
    let (best, worst) = (&spread["best"], &spread["worst"]);
    let (best_accuracy, worst_accuracy) = (
        best["accuracy"].as_f64().expect("best accuracy"),
        worst["accuracy"].as_f64().expect("worst accuracy"),
    );
    assert!(
        (0.0..=1.0).contains(&worst_accuracy) && best_accuracy >= worst_accuracy,
        "{spread}"
    );
    assert!(best["fixed_lidar_at"].is_array(), "{spread}");
    let report = std::fs::read_to_string(eval.join("report.md")).unwrap();
    assert!(
        report.contains("Fixed Lidar") && report.contains("82.9"),
        "{report}"
    );
    assert!(eval.join("confusion_test.png").is_file());

    // A file in the way of --out is refused before the scoring.
    let out = evaluate_committed_model(&data, &eval.join("report.md"));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("is a file"), "{err}");

    // A broken second split: an error naming its file, and no outputs from the good one.
    let index_path = data.join("index.json");
    let mut index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&index_path).unwrap()).unwrap();
    let mut unseen = index["splits"]["test"].clone();
    unseen["labels"] = "test_unseen_labels.npy".into();
    index["splits"]["test_unseen"] = unseen;
    std::fs::write(&index_path, index.to_string()).unwrap();
    std::fs::write(data.join("test_unseen_labels.npy"), b"cut short").unwrap();
    let broken_eval = tmp.path().join("eval_broken");
    let out = evaluate_committed_model(&data, &broken_eval);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("test_unseen_labels.npy"),
        "{err}"
    );
    assert!(
        !broken_eval.exists(),
        "outputs were written before the error"
    );
    index["splits"]
        .as_object_mut()
        .unwrap()
        .remove("test_unseen");

    // The same images said to be scanned at 10 Hz: the model's 20-scan window would span 2 s.
    index["spec"]["scan_rate_hz"] = 10.0.into();
    std::fs::write(&index_path, index.to_string()).unwrap();
    let out = evaluate_committed_model(&data, &tmp.path().join("eval10"));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("20 Hz") && err.contains("10 Hz"), "{err}");
}
