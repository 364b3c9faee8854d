//! The repository as colcon sees it, with the colcon plugins a ROS 2 user installs from PyPI
//! (in the checker venv): `colcon build --packages-up-to lidar_har` must build the interface
//! package `lidar_har_msgs` too. colcon-cargo ends its crawl at the Cargo workspace, so
//! `msg/`, no crate, was found only because the root Cargo.toml names it.

use std::process::Command;

use lidar_har_e2e::{repo_root, skip_or_fail};

#[test]
fn colcon_finds_the_nodes_and_the_interface_package_they_need() {
    let colcon = repo_root().join(".venv/bin/colcon");
    if !colcon.is_file() {
        skip_or_fail(
            &format!("{} missing", colcon.display()),
            "run scripts/setup.sh for the external checkers",
        );
        return;
    }
    let home = tempfile::tempdir().unwrap();
    let out = Command::new(&colcon)
        .args(["--log-base", "/dev/null", "list", "--base-paths"])
        .arg(repo_root())
        .args(["--packages-up-to", "lidar_har"])
        .env("COLCON_HOME", home.path())
        .current_dir(home.path())
        .output()
        .unwrap();
    let listed = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{listed}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let packages: Vec<(&str, &str)> = listed
        .lines()
        .filter_map(|line| {
            let mut fields = line.split('\t');
            let name = fields.next()?;
            let path = fields.next()?;
            Some((name, path))
        })
        .collect();
    for (name, dir) in [("lidar_har_msgs", "msg"), ("lidar_har", "nodes")] {
        let path = repo_root().join(dir);
        assert!(
            packages.contains(&(name, &*path.to_string_lossy())),
            "`colcon build --packages-up-to lidar_har` would not build {name} ({dir}/): {listed}"
        );
    }
}
