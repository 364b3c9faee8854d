//! Our schema texts and bytes read by implementations nobody on the team wrote: for every
//! type, `rosbags` (a type store built only from our schema text) and `mcap-ros2-support`
//! (its dynamic decoder) parse the schema we write into MCAP files and decode our CDR to the
//! fixed value. Needs `.venv` (scripts/setup.sh); skips without it unless
//! `LIDAR_HAR_REQUIRE_CHECKERS` is set (CI), where it fails instead.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::sample;
use lidar_har_msgs::{RosMessage, encode};

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn checker_python() -> Option<PathBuf> {
    let python = repo_root().join(".venv/bin/python");
    if python.is_file() {
        return Some(python);
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

fn write_case<M: RosMessage>(dir: &Path) -> &'static str {
    let stem = M::TYPE_NAME.replace("/msg/", "__");
    std::fs::write(dir.join(format!("{stem}.msg")), M::schema_text()).expect("write schema");
    std::fs::write(
        dir.join(format!("{stem}.cdr")),
        encode(&sample::<M>()).expect("encodes"),
    )
    .expect("write cdr");
    M::TYPE_NAME
}

macro_rules! write_case_of {
    ($ty:ty) => {
        write_case::<$ty>(&DIR.with(|d| d.clone()))
    };
}

thread_local! {
    static DIR: PathBuf = std::env::temp_dir().join(format!("lidar_har_msgs_schemas_{}", std::process::id()));
}

#[test]
fn rosbags_and_mcap_ros2_parse_our_schemas_and_decode_our_bytes() {
    let Some(python) = checker_python() else {
        return;
    };
    let dir = DIR.with(|d| d.clone());
    std::fs::create_dir_all(&dir).expect("temp dir");
    let written = for_every_type!(write_case_of);
    let output = Command::new(python)
        .arg(repo_root().join("scripts/make_golden_cdr.py"))
        .arg("--check-schemas")
        .arg(&dir)
        .output()
        .expect("run the checker");
    let _ = std::fs::remove_dir_all(&dir);
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains(&format!("checked {} schemas", written.len())),
        "{stdout}"
    );
}

#[test]
fn committed_golden_files_are_what_the_script_writes_today() {
    let Some(python) = checker_python() else {
        return;
    };
    let output = Command::new(python)
        .arg(repo_root().join("scripts/make_golden_cdr.py"))
        .arg("--check")
        .output()
        .expect("run the script");
    assert!(
        output.status.success(),
        "golden files are stale: rerun .venv/bin/python scripts/make_golden_cdr.py\n{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}
