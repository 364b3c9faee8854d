//! The Python tests of training/lidar_har_train (training/lidar_har_train/tests, `unittest`):
//! with .venv, which has numpy but no PyTorch (the data reader, the sweep's bookkeeping,
//! the export's file handling), and with training/.venv as well where `training/train.sh`
//! has made it (training, export and the pose head).

use std::process::Command;

use lidar_har_e2e::{checker_python, repo_root};

/// Runs the tests with `python`; panics with their output when one fails or none ran.
fn run_unittests(mut python: Command) {
    let out = python
        .current_dir(repo_root())
        .env("PYTHONPATH", repo_root().join("training"))
        .args(["-m", "unittest", "discover", "-v"])
        .args(["-s", "training/lidar_har_train/tests", "-t", "training"])
        .output()
        .expect("python runs");
    // unittest reports on stderr.
    let report = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "{:?} failed:\n{report}",
        python.get_program()
    );
    assert!(
        report.contains(" ... ok"),
        "no test ran with {:?}:\n{report}",
        python.get_program()
    );
}

#[test]
fn training_python_tests_pass() {
    let Some(python) = checker_python() else {
        return;
    };
    run_unittests(python);
    let training = repo_root().join("training/.venv/bin/python");
    if training.is_file() {
        run_unittests(Command::new(training));
    }
}
