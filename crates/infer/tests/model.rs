//! The step model on real ONNX Runtime, with the fixtures made by `make_test_models.py`:
//! parity with an independent NumPy implementation, contract checks at load, and the
//! numerical extremes of streaming.

use std::path::{Path, PathBuf};

use glam::DVec2;
use lidar_har_core::classifier::{PersonScan, StreamingClassifier};
use lidar_har_core::pose_head::PoseHead;
use lidar_har_infer::{ActivityModel, InferError, PoseHeadModel, runtime_library_path};
use ndarray::Array2;
use sha2::{Digest, Sha256};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The runtime library is installed by scripts/setup.sh; without it these tests skip, unless
/// LIDAR_HAR_REQUIRE_CHECKERS is set (as in CI), where its absence fails.
fn runtime_available() -> bool {
    let (path, _) = runtime_library_path();
    if path.is_file() {
        return true;
    }
    if std::env::var_os("LIDAR_HAR_REQUIRE_CHECKERS").is_some() {
        panic!("{} missing: run scripts/setup.sh", path.display());
    }
    eprintln!("SKIP: {} missing (run scripts/setup.sh)", path.display());
    false
}

fn load(name: &str) -> Result<ActivityModel, InferError> {
    ActivityModel::load(fixture(name), 1)
}

fn expected() -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(fixture("step_model_expected.json")).unwrap())
        .unwrap()
}

/// The expected frames as images.
fn expected_frames(expected: &serde_json::Value) -> Vec<Array2<f32>> {
    expected["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|frame| {
            let data: Vec<f32> = frame
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap() as f32)
                .collect();
            Array2::from_shape_vec((16, 16), data).unwrap()
        })
        .collect()
}

#[test]
fn loads_the_step_model_and_reads_its_metadata() {
    if !runtime_available() {
        return;
    }
    let model = load("step_model.onnx").unwrap();
    let info = model.info();
    assert_eq!((info.hidden, info.state_side, info.threads), (4, 8, 1));
    assert_eq!(info.stream.window, 8);
    assert_eq!(info.stream.scan_rate_hz, 20.0);
    assert_eq!(info.stream.representation.size, 16);
    assert_eq!(info.stream.representation.resolution_m, 0.1);
    assert_eq!(info.stream.representation.kind.name(), "boolean_grid");
    assert_eq!(info.stream.representation.framing.name(), "person_centred");
}

#[test]
fn steps_match_an_independent_numpy_implementation() {
    if !runtime_available() {
        return;
    }
    let expected = expected();
    let mut model = load("step_model.onnx").unwrap();
    let mut state = lidar_har_core::classifier::StepModel::initial_state(&model);
    let logits = expected["logits"].as_array().unwrap();
    let mut worst = 0.0f64;
    for (image, want) in expected_frames(&expected).iter().zip(logits) {
        let got = model.step(image.view(), &mut state).unwrap();
        for (g, w) in got.iter().zip(want.as_array().unwrap()) {
            worst = worst.max((*g as f64 - w.as_f64().unwrap()).abs());
        }
    }
    assert!(worst < 1e-5, "max abs difference to NumPy {worst}");
    let h_sum: f64 = state.h().iter().map(|&v| v as f64).sum();
    assert!((h_sum - expected["h_final_sum"].as_f64().unwrap()).abs() < 1e-4);
}

#[test]
fn contract_violations_are_refused_at_load_naming_file_and_problem() {
    if !runtime_available() {
        return;
    }
    let cases = [
        ("wrong_input_name.onnx", "no input named 'frame'"),
        (
            "float64_frame.onnx",
            "input 'frame' is Tensor<f64>(1, 1, 16, 16), expected a float32 tensor",
        ),
        ("wrong_class_count.onnx", "output 'logits' has shape [1, 8]"),
        ("missing_window.onnx", "lidar_har.window"),
        ("size_mismatch.onnx", "lidar_har.size = 32"),
    ];
    for (file, needle) in cases {
        let e = load(file).unwrap_err().to_string();
        assert!(e.contains(file) && e.contains(needle), "{file}: {e}");
    }
}

#[test]
fn missing_garbage_and_truncated_files_give_clear_errors() {
    if !runtime_available() {
        return;
    }
    let e = load("no_such_model.onnx").unwrap_err();
    assert!(matches!(e, InferError::ModelMissing { .. }), "{e}");
    assert!(e.to_string().contains("no_such_model.onnx"));
    // A relative path says where it was looked for, and where the committed models are.
    let e = ActivityModel::load("no_such_model.onnx", 1).unwrap_err();
    let text = e.to_string();
    let working_directory = std::env::current_dir().unwrap();
    assert!(
        text.contains("no_such_model.onnx")
            && text.contains(&format!("relative to {}", working_directory.display()))
            && text.contains("share/lidar_har/models/"),
        "{text}"
    );
    let e = ActivityModel::load(std::env::temp_dir(), 1).unwrap_err();
    assert!(
        e.to_string().contains("a directory, not an ONNX file"),
        "{e}"
    );

    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.onnx");
    std::fs::write(&garbage, b"this is not a protobuf at all \xff\xfe").unwrap();
    let e = ActivityModel::load(&garbage, 1).unwrap_err();
    assert!(matches!(e, InferError::ModelLoad { .. }), "{e}");
    assert!(e.to_string().contains("garbage.onnx"));

    let bytes = std::fs::read(fixture("step_model.onnx")).unwrap();
    let truncated = dir.path().join("truncated.onnx");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let e = ActivityModel::load(&truncated, 1).unwrap_err();
    assert!(e.to_string().contains("truncated.onnx"), "{e}");
}

#[test]
fn a_frame_of_the_wrong_size_is_an_error() {
    if !runtime_available() {
        return;
    }
    let mut model = load("step_model.onnx").unwrap();
    let mut state = lidar_har_core::classifier::StepModel::initial_state(&model);
    let e = model
        .step(Array2::zeros((8, 16)).view(), &mut state)
        .unwrap_err();
    assert!(e.to_string().contains("16x16"), "{e}");
}

#[test]
fn a_frame_with_a_non_finite_pixel_is_refused_and_leaves_the_state_as_it_was() {
    if !runtime_available() {
        return;
    }
    let frames = expected_frames(&expected());
    let mut model = load("step_model.onnx").unwrap();
    let mut state = lidar_har_core::classifier::StepModel::initial_state(&model);
    model.step(frames[0].view(), &mut state).unwrap();
    let before = state.clone();
    for value in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut bad = frames[1].clone();
        bad[[3, 5]] = value;
        let e = model.step(bad.view(), &mut state).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("frame pixel (3, 5)") && text.contains(&value.to_string()),
            "{text}"
        );
        // A transposed view takes the copying path: same check, same place.
        let transposed = bad.t().to_owned();
        let e = model.step(transposed.t(), &mut state).unwrap_err();
        assert!(e.to_string().contains("(3, 5)"), "{e}");
        // The NaN used to reach the state and make every later output NaN.
        assert_eq!(state, before);
    }
    let logits = model.step(frames[1].view(), &mut state).unwrap();
    assert!(logits.iter().all(|v| v.is_finite()), "{logits:?}");
}

#[test]
fn a_model_that_outputs_nan_is_refused_naming_file_and_output_and_leaves_the_state() {
    if !runtime_available() {
        return;
    }
    let frames = expected_frames(&expected());
    let mut model = load("nan_model.onnx").unwrap();
    let mut state = lidar_har_core::classifier::StepModel::initial_state(&model);
    let before = state.clone();
    for frame in &frames {
        let e = model.step(frame.view(), &mut state).unwrap_err();
        assert!(matches!(e, InferError::OutputNotFinite { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains("nan_model.onnx") && text.contains("NaN in output 'logits'"),
            "{text}"
        );
        // The NaN used to be copied into the state, and the logits read as crawling.
        assert_eq!(state, before);
    }
    // Streamed, every scan is an error naming the model: nothing is published.
    let spec = model.info().stream;
    let mut classifier = StreamingClassifier::new(model, spec).unwrap();
    let points = [DVec2::new(0.05, 0.05)];
    for k in 0..20 {
        let e = classifier
            .classify(&person(k as f64 * 0.05, k % 2 == 0, &points))
            .unwrap_err();
        assert!(e.to_string().contains("nan_model.onnx"), "{e}");
    }
}

#[test]
fn a_state_of_another_model_is_refused_naming_tensor_and_shapes() {
    if !runtime_available() {
        return;
    }
    let frame = Array2::zeros((16, 16));
    let other = load("three_channel_model.onnx").unwrap();
    let mut foreign = lidar_har_core::classifier::StepModel::initial_state(&other);
    let before = foreign.clone();
    let mut model = load("step_model.onnx").unwrap();
    let mut head = PoseHeadModel::load(fixture("pose_head.onnx"), &model, 1).unwrap();
    let errors = [
        model.step(frame.view(), &mut foreign).unwrap_err(),
        head.estimate(&foreign, DVec2::ZERO).unwrap_err(),
    ];
    for (e, file) in errors.iter().zip(["step_model.onnx", "pose_head.onnx"]) {
        assert!(matches!(e, InferError::StateMismatch { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains("state 'h' has 192 values")
                && text.contains(file)
                && text.contains("[1, 4, 8, 8] (256 values)")
                && text.contains("made for another model"),
            "{text}"
        );
    }
    assert_eq!(foreign, before);
}

#[test]
fn zero_threads_are_refused_at_load_as_a_wrong_setting_not_a_broken_model() {
    if !runtime_available() {
        return;
    }
    // Used to be turned into 1 silently; then refused as "could not load model", blaming a
    // model file that is fine.
    let model = load("step_model.onnx").unwrap();
    let errors = [
        (
            ActivityModel::load(fixture("step_model.onnx"), 0).unwrap_err(),
            "step_model.onnx",
        ),
        (
            PoseHeadModel::load(fixture("pose_head.onnx"), &model, 0).unwrap_err(),
            "pose_head.onnx",
        ),
    ];
    for (e, file) in errors {
        assert!(matches!(e, InferError::ZeroThreads { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains(file)
                && text.contains("threads must be at least 1, got 0")
                && !text.contains("could not load model"),
            "{text}"
        );
    }
}

fn person(t: f64, visible: bool, points: &[DVec2]) -> PersonScan<'_> {
    PersonScan {
        stamp_s: t,
        points,
        position: visible.then_some(DVec2::ZERO),
        sensor: DVec2::new(-2.0, 0.0),
    }
}

fn assert_distribution(p: &[f32; 9]) {
    assert!(p.iter().all(|v| v.is_finite() && *v >= 0.0), "{p:?}");
    assert!((p.iter().sum::<f32>() - 1.0).abs() < 1e-5, "{p:?}");
}

#[test]
fn person_hidden_in_every_frame_gives_valid_probabilities() {
    if !runtime_available() {
        return;
    }
    let model = load("step_model.onnx").unwrap();
    let spec = model.info().stream;
    let mut classifier = StreamingClassifier::new(model, spec).unwrap();
    for k in 0..40 {
        let p = classifier
            .classify(&person(k as f64 * 0.05, false, &[]))
            .unwrap();
        assert_distribution(&p.probabilities);
        assert!(classifier.last_image().iter().all(|v| *v == 0.0));
    }
}

#[test]
fn saturated_logits_still_give_a_distribution() {
    if !runtime_available() {
        return;
    }
    let model = load("saturating_model.onnx").unwrap();
    let spec = model.info().stream;
    let mut classifier = StreamingClassifier::new(model, spec).unwrap();
    let points = [
        DVec2::new(0.05, 0.05),
        DVec2::new(0.15, -0.25),
        DVec2::new(-0.3, 0.1),
    ];
    let mut saturated = false;
    for k in 0..20 {
        let p = classifier
            .classify(&person(k as f64 * 0.05, true, &points))
            .unwrap();
        assert_distribution(&p.probabilities);
        saturated |= p.confidence == 1.0;
    }
    assert!(saturated, "the fixture should push softmax into saturation");
}

#[test]
fn first_window_and_long_gap_start_from_zero_state() {
    if !runtime_available() {
        return;
    }
    let points = [DVec2::new(0.05, 0.05), DVec2::new(0.25, 0.05)];
    let fresh = |t: f64| {
        let model = load("step_model.onnx").unwrap();
        let spec = model.info().stream;
        let mut c = StreamingClassifier::new(model, spec).unwrap();
        c.classify(&person(t, true, &points)).unwrap()
    };
    let first = fresh(0.0);
    assert_eq!(first.history, 1);
    assert!(!first.ready);
    assert_distribution(&first.probabilities);

    let model = load("step_model.onnx").unwrap();
    let spec = model.info().stream;
    let mut c = StreamingClassifier::new(model, spec).unwrap();
    let moving = [DVec2::new(-0.4, 0.3)];
    for k in 0..13 {
        c.classify(&person(k as f64 * 0.05, true, &moving)).unwrap();
    }
    let before_gap = c.classify(&person(0.65, true, &points)).unwrap();
    assert!(before_gap.history >= 4);
    // 8 scans at 20 Hz = 0.4 s; a 10 s gap resets both states: the prediction equals a fresh one.
    let after_gap = c.classify(&person(10.65, true, &points)).unwrap();
    assert_eq!(after_gap.history, 1);
    assert_eq!(after_gap.probabilities, first.probabilities);
    assert_ne!(
        before_gap.probabilities, first.probabilities,
        "history changes the output"
    );
}

#[test]
fn pose_head_reads_the_state_and_matches_numpy() {
    if !runtime_available() {
        return;
    }
    let expected = expected();
    let mut model = load("step_model.onnx").unwrap();
    let mut head = PoseHeadModel::load(fixture("pose_head.onnx"), &model, 1).unwrap();
    assert_eq!(head.spec().min_history, 3);
    assert_eq!(head.spec().max_sigma_m, f64::INFINITY);
    assert_eq!(head.spec().activities.len(), 9);
    let mut state = lidar_har_core::classifier::StepModel::initial_state(&model);
    for image in expected_frames(&expected) {
        model.step(image.view(), &mut state).unwrap();
    }
    let want = &expected["pose_head"];
    let located = want["located"].as_array().unwrap();
    let located = DVec2::new(located[0].as_f64().unwrap(), located[1].as_f64().unwrap());
    let got = head.estimate(&state, located).unwrap();
    let offset = want["offset"].as_array().unwrap();
    let want_offset = DVec2::new(offset[0].as_f64().unwrap(), offset[1].as_f64().unwrap());
    assert!(
        got.offset.distance(want_offset) < 1e-5,
        "{got:?} against NumPy {want_offset}"
    );
    let want_sigma = want["sigma"].as_f64().unwrap();
    assert!(
        (got.sigma_m - want_sigma).abs() < 1e-6,
        "{got:?} against NumPy sigma {want_sigma}"
    );
}

#[test]
fn pose_head_for_another_model_or_state_or_missing_is_refused_naming_files() {
    if !runtime_available() {
        return;
    }
    let model = load("step_model.onnx").unwrap();
    let e = PoseHeadModel::load(fixture("pose_head_other_model.onnx"), &model, 1).unwrap_err();
    assert!(matches!(e, InferError::PoseHeadMismatch { .. }), "{e}");
    let text = e.to_string();
    assert!(
        text.contains("pose_head_other_model.onnx") && text.contains("step_model.onnx"),
        "{text}"
    );

    let e = PoseHeadModel::load(fixture("pose_head_wrong_state.onnx"), &model, 1).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("pose_head_wrong_state.onnx")
            && text.contains("input 'h' has shape [1, 3, 8, 8]"),
        "{text}"
    );

    // A head of the contract before its expected error was an output.
    let e = PoseHeadModel::load(fixture("pose_head_without_sigma.onnx"), &model, 1).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("pose_head_without_sigma.onnx") && text.contains("'sigma'"),
        "{text}"
    );

    let e = PoseHeadModel::load(fixture("no_such_head.onnx"), &model, 1).unwrap_err();
    assert!(matches!(e, InferError::ModelMissing { .. }), "{e}");

    // An activity model is not a pose head.
    let e = PoseHeadModel::load(fixture("step_model.onnx"), &model, 1).unwrap_err();
    assert!(e.to_string().contains("lidar_har.pose_head"), "{e}");
}

#[test]
fn pose_head_fitted_on_the_model_is_taken_with_its_hash_in_upper_case() {
    if !runtime_available() {
        return;
    }
    let model = load("step_model.onnx").unwrap();
    let sha = format!(
        "{:x}",
        Sha256::digest(std::fs::read(fixture("step_model.onnx")).unwrap())
    );
    let mut head = std::fs::read(fixture("pose_head.onnx")).unwrap();
    let at = head
        .windows(sha.len())
        .position(|w| w == sha.as_bytes())
        .expect("the head's metadata names the model's hash");
    head[at..at + sha.len()].make_ascii_uppercase();
    let dir = tempfile::tempdir().unwrap();
    let upper = dir.path().join("pose_head_upper_case.onnx");
    std::fs::write(&upper, &head).unwrap();
    // Used to be refused as fitted on another model, naming the same hash twice.
    let head = PoseHeadModel::load(&upper, &model, 1).unwrap();
    assert_eq!(head.spec().min_history, 3);
}
