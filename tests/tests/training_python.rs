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

/// `training/train.sh --help` answers without making training/.venv (PyTorch, a ~3.2 GB
/// download), which it made first until session 57; `--setup` (what training/sweep.sh runs)
/// makes it. A copy of the script runs with a `python3` on PATH that logs its calls, makes no
/// venv, and runs the checkers' Python otherwise.
#[test]
fn train_sh_answers_help_without_making_the_venv() {
    let Some(python) = checker_python() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let training = dir.path().join("training");
    let bin = dir.path().join("bin");
    std::fs::create_dir_all(&training).unwrap();
    std::fs::create_dir_all(&bin).unwrap();
    std::fs::copy(
        repo_root().join("training/train.sh"),
        training.join("train.sh"),
    )
    .unwrap();
    std::os::unix::fs::symlink(
        repo_root().join("training/lidar_har_train"),
        training.join("lidar_har_train"),
    )
    .unwrap();
    let calls = dir.path().join("calls");
    let stub = format!(
        "#!/bin/sh\necho \"$*\" >> '{calls}'\nif [ \"$1 $2\" = '-m venv' ]; then exit 9; fi\nexec '{python}' \"$@\"\n",
        calls = calls.display(),
        python = python.get_program().to_string_lossy(),
    );
    std::fs::write(bin.join("python3"), stub).unwrap();
    std::fs::set_permissions(
        bin.join("python3"),
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let train_sh = |args: &[&str]| {
        std::fs::remove_file(&calls).ok();
        let out = Command::new("bash")
            .arg(training.join("train.sh"))
            .args(args)
            .env("PATH", &path)
            .output()
            .expect("bash runs");
        let calls = std::fs::read_to_string(&calls).unwrap_or_default();
        (out, calls)
    };
    for help in ["--help", "-h"] {
        let (out, calls) = train_sh(&["--data", "d", help]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{calls}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            stdout.starts_with("usage: train ") && stdout.contains("--shift-px"),
            "{stdout}"
        );
        assert!(!calls.contains("venv"), "{calls}");
        assert!(!training.join(".venv").exists());
    }
    let (out, calls) = train_sh(&["--setup"]);
    assert_eq!(out.status.code(), Some(9), "{calls}");
    assert_eq!(
        calls,
        format!("-m venv {}\n", training.join(".venv").display())
    );
}
