//! Helpers shared by the end-to-end tests: where the repository, the shared data, the
//! project's binaries and the external Python checkers are.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// `../shared/data/real` beside the repository, if present. Tests that need it print why
/// they skip when it is absent, so a clone without `../shared` still passes.
pub fn shared_real_data() -> Option<PathBuf> {
    let dir = repo_root().join("../shared/data/real");
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "SKIP: {} not found (the shared real recordings are not beside this clone)",
            dir.display()
        );
        None
    }
}

/// A binary of this workspace, built by `cargo build --workspace --bins` (scripts/test.sh does).
pub fn workspace_bin(name: &str) -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join("target"));
    let profile = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    };
    let path = target.join(profile).join(name);
    assert!(
        path.is_file(),
        "{} is not built: run `cargo build --workspace --bins` first (scripts/test.sh does)",
        path.display()
    );
    path
}

/// The Python of `.venv` with the external checkers (rosbags, mcap, cyclonedds).
///
/// Returns `None` (with a message) when it is missing, unless `LIDAR_HAR_REQUIRE_CHECKERS`
/// is set, as scripts/test.sh and CI do: there a missing checker is a failure, not a skip.
pub fn checker_python() -> Option<Command> {
    let python = repo_root().join(".venv/bin/python");
    if python.is_file() {
        let mut cmd = Command::new(python);
        cmd.current_dir(repo_root());
        return Some(cmd);
    }
    if std::env::var_os("LIDAR_HAR_REQUIRE_CHECKERS").is_some() {
        panic!("{} missing: run scripts/setup.sh", python.display());
    }
    eprintln!(
        "SKIP: {} missing (run scripts/setup.sh for the external checkers)",
        python.display()
    );
    None
}
