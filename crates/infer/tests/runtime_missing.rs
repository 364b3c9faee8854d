//! Without the ONNX Runtime library, loading a model fails with an error naming the path that
//! was tried and the fix. (Its own test binary: the library path is read once per process.)

use lidar_har_infer::{ActivityModel, InferError};

#[test]
fn missing_runtime_library_names_the_path_and_the_fix() {
    let missing = std::env::temp_dir().join("lidar_har_no_such_dir/libonnxruntime.so");
    // SAFETY: the only test in this binary, set before any thread reads the environment.
    unsafe { std::env::set_var("ORT_DYLIB_PATH", &missing) };
    let e = ActivityModel::load("models/activity.onnx", 1).unwrap_err();
    assert!(matches!(e, InferError::RuntimeMissing { .. }), "{e}");
    let text = e.to_string();
    assert!(text.contains(&missing.display().to_string()), "{text}");
    assert!(
        text.contains("scripts/setup.sh") && text.contains("ORT_DYLIB_PATH"),
        "{text}"
    );
}
