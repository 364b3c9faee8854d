//! `lidar-har dataset` end to end on short episodes: the split is by episode, the held-out
//! scene is only in `test_unseen`, class counts and the `.npy` arrays (images, labels,
//! positions) agree with the index.

use std::path::Path;

use lidar_har_e2e::{checker_python, lidar_har, repo_root, runtime_available};
use serde_json::Value;

/// The shape in a `.npy` header, and the byte count after the header.
fn npy_shape(path: &Path) -> (Vec<usize>, usize, String) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(
        &bytes[..6],
        b"\x93NUMPY",
        "{} is not a .npy file",
        path.display()
    );
    let (header_len, start) = if bytes[6] == 1 {
        (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10)
    } else {
        (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        )
    };
    let header = String::from_utf8_lossy(&bytes[start..start + header_len]).to_string();
    let inner = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .expect("shape in header");
    let shape = inner
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().expect("dim"))
        .collect();
    (shape, bytes.len() - start - header_len, header)
}

/// Runs `lidar-har dataset` on a tiny configuration; `overrides` are `--flag value` pairs
/// that replace the defaults (clap refuses a flag given twice).
fn make_dataset(out: &Path, overrides: &[&str]) -> std::process::Output {
    let mut options: Vec<[&str; 2]> = vec![
        ["--scenes", "config/scenes/[ko]*.yaml"],
        ["--held-out", "office"],
        ["--episodes", "4"],
        ["--episode-seconds", "6"],
        ["--window", "8"],
        ["--stride", "4"],
        ["--size", "16"],
        ["--test-fraction", "0.25"],
        ["--seed", "3"],
    ];
    for pair in overrides.chunks(2) {
        let [flag, value] = pair else {
            panic!("overrides come in --flag value pairs: {overrides:?}")
        };
        match options.iter_mut().find(|[f, _]| f == flag) {
            Some(option) => option[1] = value,
            None => options.push([flag, value]),
        }
    }
    lidar_har()
        .current_dir(repo_root())
        .arg("dataset")
        .args(options.iter().flatten())
        .arg("--out")
        .arg(out)
        .output()
        .expect("lidar-har runs")
}

/// Prints, per split, how many scans training's reader (training/lidar_har_train/data.py)
/// counts as seen by the localiser.
const TRAINING_READER: &str = r#"
import json, sys
from pathlib import Path
from lidar_har_train.data import load_index, load_split
data = Path(sys.argv[1])
index = load_index(data)
splits = {name: load_split(data, index, name) for name in index["splits"]}
print(json.dumps({name: int(s.seen.sum()) for name, s in splits.items() if s is not None}))
"#;

#[test]
fn dataset_splits_by_episode_and_arrays_match_the_index() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = make_dataset(dir.path(), &[]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "dataset failed: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("falling_down"),
        "class counts are printed:\n{stdout}"
    );

    let index: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("index.json")).expect("index"),
    )
    .expect("index.json is JSON");
    let classes = index["classes"].as_array().expect("classes");
    assert_eq!(classes.len(), 9);
    assert_eq!(classes[1], "falling_down");

    // Every episode is in exactly one split; the held-out scene only in test_unseen.
    let episodes = index["episodes"].as_array().expect("episodes");
    assert_eq!(
        episodes.len(),
        4 + 1,
        "4 episodes + 1 for the held-out scene"
    );
    let split_of = |id: u64| {
        episodes
            .iter()
            .find(|e| e["id"] == id)
            .map(|e| e["split"].as_str().unwrap_or("").to_string())
    };
    for e in episodes {
        let held_out = e["scene"] == "office";
        assert_eq!(held_out, e["split"] == "test_unseen", "episode {e}");
    }
    assert_eq!(episodes.iter().filter(|e| e["split"] == "test").count(), 1);
    let windows = index["windows"].as_array().expect("windows");
    assert!(!windows.is_empty());
    for w in windows {
        let episode_split = split_of(w["episode"].as_u64().expect("episode id"))
            .expect("window's episode is listed");
        assert_eq!(
            w["split"].as_str(),
            Some(episode_split.as_str()),
            "a window is in its episode's split: {w}"
        );
    }

    // Arrays: shapes, rows and class counts agree with the index.
    let mut seen_scans = serde_json::Map::new();
    for (name, split) in index["splits"].as_object().expect("splits") {
        let n = split["windows"].as_u64().expect("windows") as usize;
        let listed: Vec<&Value> = windows
            .iter()
            .filter(|w| w["split"] == name.as_str())
            .collect();
        assert_eq!(listed.len(), n, "{name}: windows listed");
        let counts: Vec<u64> = split["class_counts"]
            .as_array()
            .expect("counts")
            .iter()
            .map(|v| v.as_u64().unwrap_or(0))
            .collect();
        assert_eq!(
            counts.iter().sum::<u64>() as usize,
            n,
            "{name}: class counts add up"
        );
        if n == 0 {
            continue;
        }
        let (shape, data, header) =
            npy_shape(&dir.path().join(split["images"].as_str().expect("images")));
        assert_eq!(shape, vec![n, 8, 16, 16], "{name} images");
        assert!(header.contains("'|u1'"), "uint8 images: {header}");
        assert_eq!(data, n * 8 * 16 * 16);
        let (shape, data, _) =
            npy_shape(&dir.path().join(split["labels"].as_str().expect("labels")));
        assert_eq!(shape, vec![n, 8], "{name} labels");
        let labels_bytes =
            std::fs::read(dir.path().join(split["labels"].as_str().unwrap_or(""))).expect("labels");
        let labels = &labels_bytes[labels_bytes.len() - data..];
        assert!(
            labels.iter().all(|&l| l < 9),
            "{name}: class indices in 0..8"
        );
        // Positions: the pelvis and the localiser from the image centre, which in this
        // person-centred dataset is the localiser's position; NaN where it saw nobody.
        let positions_file = dir
            .path()
            .join(split["positions"].as_str().expect("positions"));
        let (shape, data, header) = npy_shape(&positions_file);
        assert_eq!(shape, vec![n, 8, 4], "{name} positions");
        assert!(header.contains("'<f4'"), "float32 positions: {header}");
        let bytes = std::fs::read(&positions_file).expect("positions");
        let values: Vec<f32> = bytes[bytes.len() - data..]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let mut seen = 0;
        for scan in values.chunks_exact(4) {
            if scan.iter().all(|v| v.is_nan()) {
                continue;
            }
            seen += 1;
            assert_eq!(&scan[2..], &[0.0, 0.0], "{name}: localiser at the centre");
            assert!(
                scan[0].hypot(scan[1]) < 1.5,
                "{name}: the pelvis near the person the localiser saw: {scan:?}"
            );
        }
        assert!(seen > 0, "{name}: some scans saw the person");
        seen_scans.insert(name.clone(), seen.into());
        for (row, w) in listed.iter().enumerate() {
            assert_eq!(w["row"].as_u64(), Some(row as u64));
            let last = labels[row * 8 + 7] as usize;
            assert_eq!(
                w["label"], classes[last],
                "{name} row {row}: index label = last scan's label"
            );
        }
    }
    // The localiser found the person in most scans of the seen scenes.
    let visible: u64 = episodes
        .iter()
        .map(|e| e["person_visible_scans"].as_u64().unwrap_or(0))
        .sum();
    let scans: u64 = episodes
        .iter()
        .map(|e| e["scans"].as_u64().unwrap_or(0))
        .sum();
    assert!(
        visible * 2 > scans,
        "person visible in {visible} of {scans} scans"
    );

    // Training reads the same windows and the same sightings.
    if let Some(mut python) = checker_python() {
        let out = python
            .env("PYTHONPATH", repo_root().join("training"))
            .args(["-c", TRAINING_READER, &dir.path().to_string_lossy()])
            .output()
            .expect("python runs");
        assert!(
            out.status.success(),
            "training's reader failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let read: Value = serde_json::from_slice(&out.stdout).expect("JSON from the reader");
        assert_eq!(read, Value::Object(seen_scans), "seen scans per split");
    }

    // Same seed, same dataset (bit for bit).
    let again = tempfile::tempdir().expect("tempdir");
    assert!(make_dataset(again.path(), &[]).status.success());
    for file in ["train_images.npy", "test_labels.npy"] {
        let a = std::fs::read(dir.path().join(file)).expect("a");
        let b = std::fs::read(again.path().join(file)).expect("b");
        assert!(a == b, "{file} differs between two runs with one seed");
    }
    // The index too, but for the command line it records (its --out differs).
    let index_without_command = |dir: &Path| {
        let mut index: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("index.json")).unwrap())
                .unwrap();
        let command = index["generator"]
            .as_object_mut()
            .and_then(|generator| generator.remove("command"));
        assert!(command.is_some(), "index.json records its command: {index}");
        index
    };
    assert_eq!(
        index_without_command(dir.path()),
        index_without_command(again.path()),
        "index.json differs between two runs with one seed (beyond generator.command)"
    );
}

#[test]
fn dataset_rejects_bad_arguments_with_a_clear_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (extra, needle) in [
        (&["--size", "18"][..], "multiple of 4"),
        (&["--held-out", "nowhere"][..], "nowhere"),
        (&["--window", "1"][..], "--window"),
        // 4 episodes x 0.1 rounds to none: an empty test split used to pass silently.
        (&["--test-fraction", "0.1"][..], "test split would be empty"),
        // 1 episode x 0.6 rounds to all: an empty train split used to pass silently.
        (
            &["--episodes", "1", "--test-fraction", "0.6"][..],
            "--test-fraction 0.6 of --episodes 1 rounds to every episode: the train split would be empty",
        ),
        // Its plans used to be allocated before any check: an abort, not an error.
        (
            &["--episodes", "1000000000000"][..],
            "--episodes 1000000000000",
        ),
    ] {
        let out = make_dataset(dir.path(), extra);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{extra:?} accepted");
        assert!(
            stderr.contains(needle),
            "{extra:?}: error should mention '{needle}': {stderr}"
        );
    }
    let out = lidar_har()
        .current_dir(repo_root())
        .args([
            "dataset",
            "--scenes",
            "config/scenes/no_such_*.yaml",
            "--out",
        ])
        .arg(dir.path())
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("matches no file"));
}

#[test]
fn a_run_that_gives_no_window_leaves_the_dataset_already_there_whole() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = make_dataset(dir.path(), &[]);
    assert!(out.status.success());
    let before: Vec<(String, Vec<u8>)> = ["index.json", "train_images.npy", "test_labels.npy"]
        .iter()
        .map(|f| (f.to_string(), std::fs::read(dir.path().join(f)).expect(f)))
        .collect();
    // Episodes of 6 s at 20 Hz have 120 scans: none holds a 400-scan window (refused before
    // any episode runs).
    let out = make_dataset(dir.path(), &["--window", "400", "--stride", "10"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("--window 400 is longer than an episode")
            && stderr.contains("gives 120 scans")
            && stderr.contains("nothing was written"),
        "{stderr}"
    );
    for (file, bytes) in before {
        assert!(
            std::fs::read(dir.path().join(&file)).expect("still there") == bytes,
            "{file} changed"
        );
    }
    // Nor are the failed run's rows left beside it.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .expect("read_dir")
        .filter_map(|entry| entry.ok()?.file_name().into_string().ok())
        .filter(|name| name.ends_with(".rows") || name.ends_with(".partial"))
        .collect();
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}

/// SIGTERM (or Ctrl-C) between episodes stops `dataset` with its scratch rows removed: they
/// stayed in `--out` (gigabytes for a training set) when the signal ended it at once.
#[test]
fn a_signal_stops_a_dataset_run_without_leaving_its_scratch_rows() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().expect("tempdir");
    let mut child = lidar_har()
        .current_dir(repo_root())
        .args([
            "dataset",
            "--scenes",
            "config/scenes/kitchen.yaml",
            "--episodes",
            "400",
        ])
        .args([
            "--episode-seconds",
            "6",
            "--window",
            "8",
            "--size",
            "16",
            "--threads",
            "1",
        ])
        .arg("--out")
        .arg(dir.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("lidar-har runs");
    let rows = |dir: &Path| -> Vec<(String, u64)> {
        std::fs::read_dir(dir)
            .expect("read_dir")
            .filter_map(|entry| {
                let entry = entry.ok()?;
                let name = entry.file_name().into_string().ok()?;
                let len = entry.metadata().ok()?.len();
                name.ends_with(".rows").then_some((name, len))
            })
            .collect()
    };
    // Rows written: an episode is in, so the run takes signals between episodes.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while !rows(dir.path()).iter().any(|(_, len)| *len > 0) {
        assert!(
            std::time::Instant::now() < deadline,
            "no episode written in 120 s"
        );
        assert!(child.try_wait().expect("try_wait").is_none(), "ended early");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let kill = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(kill.success());
    let out = child.wait_with_output().expect("wait");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.signal(), Some(15), "ended by SIGTERM: {stderr}");
    assert!(
        stderr.contains("interrupted by SIGTERM; nothing was written"),
        "{stderr}"
    );
    assert!(
        rows(dir.path()).is_empty(),
        "left behind: {:?}",
        rows(dir.path())
    );
    assert!(!dir.path().join("index.json").exists());
}

/// `lidar-har random-scenes` with `--seed` and `--count`, into `out`.
fn random_scenes(out: &Path, seed: &str, count: &str) -> std::process::Output {
    lidar_har()
        .current_dir(repo_root())
        .args(["random-scenes", "--seed", seed, "--count", count, "--out"])
        .arg(out)
        .output()
        .expect("lidar-har runs")
}

#[test]
fn random_rooms_are_trained_on_beside_the_drawn_scenes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rooms = dir.path().join("rooms");
    let out = random_scenes(&rooms, "5", "2");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let first = std::fs::read(rooms.join("random_5.yaml")).expect("random_5.yaml");
    assert!(rooms.join("random_6.yaml").exists());
    // Same seed, same file.
    let again = dir.path().join("again");
    assert!(random_scenes(&again, "5", "1").status.success());
    assert_eq!(std::fs::read(again.join("random_5.yaml")).unwrap(), first);
    // A second run into the folder is refused and leaves the rooms there as they are (a
    // user's edits; the dataset would have taken both runs' rooms).
    let edited = [first.as_slice(), b"# edited\n"].concat();
    std::fs::write(rooms.join("random_5.yaml"), &edited).unwrap();
    let out = random_scenes(&rooms, "7", "1");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("already holds 2 random rooms (random_5.yaml, random_6.yaml)"),
        "{stderr}"
    );
    assert!(!rooms.join("random_7.yaml").exists());
    assert_eq!(std::fs::read(rooms.join("random_5.yaml")).unwrap(), edited);

    let data = dir.path().join("data");
    let out = lidar_har()
        .current_dir(repo_root())
        .args(["dataset", "--scenes", "config/scenes/[ko]*.yaml"])
        .arg(rooms.join("*.yaml"))
        .args([
            "--held-out",
            "office",
            "--episodes",
            "8",
            "--episode-seconds",
            "6",
        ])
        .args([
            "--window", "8", "--stride", "4", "--size", "16", "--seed", "3",
        ])
        .arg("--out")
        .arg(&data)
        .output()
        .expect("lidar-har runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let index: Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("index.json")).unwrap()).unwrap();
    let episodes = index["episodes"].as_array().expect("episodes");
    let in_room = |name: &str| {
        episodes
            .iter()
            .filter(|e| e["scene"] == name)
            .map(|e| e["split"].as_str().unwrap().to_string())
            .collect::<Vec<_>>()
    };
    // Kitchen and two random rooms share the 8 episodes; the office stays unseen.
    for room in ["kitchen", "random_5", "random_6"] {
        let splits = in_room(room);
        assert!(!splits.is_empty(), "no episode in {room}");
        assert!(
            splits.iter().all(|s| s != "test_unseen"),
            "{room}: {splits:?}"
        );
    }
    assert!(in_room("office").iter().all(|s| s == "test_unseen"));
}

#[test]
fn random_scenes_rejects_a_count_of_zero() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = random_scenes(dir.path(), "1", "0");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--count 0"));
}

/// A dataset of short episodes in the committed model's image (room-fixed, 32 px at 8 cm)
/// and window (20 scans), with a test split (kitchen) and a `test_unseen` one (office).
fn dataset_for_the_committed_model(out: &Path) {
    let made = make_dataset(
        out,
        &[
            "--window",
            "20",
            "--size",
            "32",
            "--resolution",
            "0.08",
            "--framing",
            "room_fixed",
        ],
    );
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
}

/// `lidar-har evaluate --model model --data data --out out`.
fn evaluate(model: &Path, data: &Path, out: &Path) -> std::process::Output {
    lidar_har()
        .current_dir(repo_root())
        .arg("evaluate")
        .arg("--model")
        .arg(model)
        .arg("--data")
        .arg(data)
        .arg("--out")
        .arg(out)
        .output()
        .expect("lidar-har runs")
}

#[test]
fn evaluate_refuses_a_dataset_whose_test_episodes_the_model_trained_on() {
    if !runtime_available() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    dataset_for_the_committed_model(&data);
    let index: Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("index.json")).unwrap()).unwrap();
    assert_eq!(index["generator"]["test_fraction"], 0.25, "recorded");
    // The committed model, said to be trained on a dataset of the same seed and scenes, of 8
    // episodes: episodes 0-3 are this dataset's, split otherwise.
    let model = dir.path().join("model.onnx");
    std::fs::copy(repo_root().join("models/activity.onnx"), &model).unwrap();
    let training_report = |generator: &Value| {
        let report = serde_json::json!({ "dataset_generator": generator });
        std::fs::write(dir.path().join("model.training.json"), report.to_string()).unwrap();
    };
    let mut larger = index["generator"].clone();
    larger["episodes"] = 8.into();
    training_report(&larger);
    let out = evaluate(&model, &data, &dir.path().join("eval"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("test episodes are episodes")
            && stderr.contains("`--seed 3 --episodes 8 --test-fraction 0.25`")
            && stderr.contains("`--seed 3 --episodes 4 --test-fraction 0.25`")
            && stderr.contains("another --seed"),
        "{stderr}"
    );
    assert!(!dir.path().join("eval").exists());
    // The same report with a diverged epoch's loss as Python's json wrote it until session
    // 57 (a bare NaN, no JSON): evaluated, but not in silence.
    let report = dir.path().join("model.training.json");
    let text = serde_json::json!({ "dataset_generator": larger, "history": [{ "loss": 0.5 }] })
        .to_string()
        .replace("0.5", "NaN");
    std::fs::write(&report, text).unwrap();
    let out = evaluate(&model, &data, &dir.path().join("eval"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "lidar-har: warning: {}: the training report is not JSON: expected value",
            report.display()
        )) && stderr.contains("trained on the test episodes of"),
        "{stderr}"
    );
    // Trained on this very dataset: its test episodes were not trained on.
    training_report(&index["generator"]);
    let out = evaluate(&model, &data, &dir.path().join("eval"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn evaluate_removes_the_confusion_picture_of_a_split_it_no_longer_scores() {
    if !runtime_available() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    dataset_for_the_committed_model(&data);
    let model = repo_root().join("models/activity.onnx");
    let eval = dir.path().join("eval");
    let scored = |out: std::process::Output| {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    scored(evaluate(&model, &data, &eval));
    assert!(eval.join("confusion_test_unseen.png").is_file());
    // The same dataset without its unseen room, evaluated into the same folder.
    let index_path = data.join("index.json");
    let mut index: Value =
        serde_json::from_str(&std::fs::read_to_string(&index_path).unwrap()).unwrap();
    index["splits"]
        .as_object_mut()
        .unwrap()
        .remove("test_unseen");
    std::fs::write(&index_path, index.to_string()).unwrap();
    scored(evaluate(&model, &data, &eval));
    assert!(eval.join("confusion_test.png").is_file());
    assert!(
        !eval.join("confusion_test_unseen.png").exists(),
        "an earlier run's picture stays beside this one's report"
    );
}

/// `lidar-har alerts` with the committed model and `args`.
fn alerts(args: &[&str]) -> std::process::Output {
    lidar_har()
        .current_dir(repo_root())
        .args(["alerts", "--model", "models/activity.onnx"])
        .args(args)
        .output()
        .expect("lidar-har runs")
}

/// `--out` naming the readings file (given or being saved) is refused before anything is
/// written: the report replaced readings that stand for hours of simulation.
#[test]
fn alerts_refuse_an_out_that_is_the_readings_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let readings = dir.path().join("r.zst");
    std::fs::write(&readings, b"saved readings").expect("write");
    let same = dir.path().join(".").join("r.zst");
    for (flag, path) in [("--readings", &readings), ("--save-readings", &same)] {
        // Not `alerts`: a replay takes the model its readings name, and no --model.
        let out = lidar_har()
            .current_dir(repo_root())
            .args(["alerts", flag, path.to_str().unwrap(), "--out"])
            .arg(&readings)
            .output()
            .expect("lidar-har runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{flag}: {stderr}");
        assert!(
            stderr.contains(&format!("is the file {flag} names")),
            "{flag}: {stderr}"
        );
        assert_eq!(
            std::fs::read(&readings).unwrap(),
            b"saved readings",
            "{flag}"
        );
    }
}

#[test]
fn alerts_that_could_run_no_episode_leave_no_readings_to_replay() {
    if !runtime_available() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    // A closet: no room for a fall, so no script with falls fits.
    let closet = dir.path().join("closet.yaml");
    std::fs::write(
        &closet,
        "name: closet\nduration: 30\nseed: 6\n\
         room:\n  outline: [[0, 0], [1.2, 0], [1.2, 1.0], [0, 1.0]]\n\
         robot:\n  start: {x: 0.3, y: 0.3, yaw_deg: 90}\n  motion: {kind: static}\n\
         lidar: {range_max: 8.0}\n\
         person:\n  start: {x: 0.8, y: 0.6, yaw_deg: 180}\n  script:\n    - {activity: standing, duration: 5}\n",
    )
    .unwrap();
    let readings = dir.path().join("readings.zst");
    let out = alerts(&[
        "--scenes",
        closet.to_str().unwrap(),
        "--fall-episodes",
        "1",
        "--no-fall-hours",
        "0",
        "--save-readings",
        readings.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("could be run"),
        "{stderr}"
    );
    assert!(
        !readings.exists(),
        "the failed run's readings would replay as a clean result"
    );
}

#[test]
fn alerts_episodes_staying_down_run_on_and_must_have_a_spell_due() {
    if !runtime_available() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let stay_down = |seconds: &str, report: &Path| {
        alerts(&[
            "--scenes",
            "config/scenes/kitchen.yaml",
            "--fall-episodes",
            "0",
            "--no-fall-hours",
            "0",
            "--stay-down-episodes",
            "1",
            "--seed",
            "27",
            "--episode-seconds",
            seconds,
            "--out",
            report.to_str().unwrap(),
        ])
    };
    // The fall comes 5 s or more in: down_after_s (15 s) later is past a 10 s episode.
    let out = stay_down("10", &dir.path().join("short.json"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("--episode-seconds 10") && stderr.contains("down_after_s (15 s)"),
        "{stderr}"
    );
    // In 30 s the spell falls due 0.3 s before the end; its PERSON_DOWN comes after the end,
    // while the episode runs on (without the run-on it counted as missed).
    let report = dir.path().join("long.json");
    let out = stay_down("30", &report);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let spells = r["person_down_due"].as_array().unwrap();
    assert_eq!(spells.len(), 1, "{r}");
    let spell = |key: &str| {
        spells[0][key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key}: {r}"))
    };
    let due_s = spell("start_s") + 15.0;
    assert!((29.0..30.0).contains(&due_s), "{r}");
    assert!(due_s + spell("delay_s") > 30.0, "{r}");
    assert!((30.5..=33.0).contains(&spell("end_s")), "{r}");
}

/// Runs training/lidar_har_train/sweep.py's `main` with `--only` and the names given, on
/// training/sweep.toml (no PyTorch needed: it stops before training).
const SWEEP_ONLY: &str = r#"
import sys
from lidar_har_train import sweep
sys.exit(sweep.main(["--config", "training/sweep.toml", "--out", sys.argv[1],
                     "--lidar-har", "/nonexistent/lidar-har", "--only", *sys.argv[2:]]))
"#;

#[test]
fn the_sweep_refuses_configurations_it_does_not_have() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (names, needle) in [
        (
            &["room_fixed", "room_fixd"][..],
            "--only: no configuration named room_fixd (known: reference, room_fixed,",
        ),
        (
            &[][..],
            "--only: give at least one configuration (known: reference,",
        ),
    ] {
        let Some(mut python) = checker_python() else {
            return;
        };
        let out = python
            .env("PYTHONPATH", repo_root().join("training"))
            .args(["-c", SWEEP_ONLY])
            .arg(dir.path())
            .args(names)
            .output()
            .expect("python runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{names:?}: {stderr}");
        assert!(stderr.contains(needle), "{names:?}: {stderr}");
    }
}
