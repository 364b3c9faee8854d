//! The fake RPLIDAR (`lidar_har_rplidar::fake`) on a pseudo-terminal, for the test that runs
//! the `rplidar_driver` node against it over DDS (tests/ros_nodes.rs).
//!
//! Usage: `fake_rplidar LINK`: an A1 (firmware 1.29, standard, express and dense modes)
//! turning at 20 Hz with 720 samples a turn, seeing the synthetic room
//! (`SyntheticRoom::default()`: every direction returns but a 15° window at device angles
//! 200..215°). The pty's slave is published as the symbolic link LINK (in a directory that
//! exists), which it prints on stdout once it is there. It then takes commands on stdin, one
//! a line: `blind` (every sample without a return, a covered window) and `see` (returns
//! again). It stops at the end of stdin, removes LINK and exits 0; an unknown command exits
//! 1 naming it.

use std::io::{BufRead, Write};

use lidar_har_rplidar::fake::{FakeConfig, FakeLidar, SyntheticRoom};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [link] = args.as_slice() else {
        return Err("usage: fake_rplidar LINK".into());
    };
    let fake = FakeLidar::spawn(link, FakeConfig::default(), SyntheticRoom::default())
        .map_err(|e| format!("cannot publish the fake device at {link}: {e}"))?;
    let mut stdout = std::io::stdout();
    writeln!(stdout, "{}", fake.path().display())?;
    stdout.flush()?;
    for line in std::io::stdin().lock().lines() {
        match line?.trim() {
            "blind" => fake.set_blinded(true),
            "see" => fake.set_blinded(false),
            "" => {}
            other => return Err(format!("unknown command `{other}`: use blind or see").into()),
        }
    }
    let log = fake.log();
    eprintln!(
        "fake_rplidar: served {} rotations, {} scan starts, {} resets",
        log.rotations_served,
        log.scans_started.len(),
        log.resets
    );
    Ok(())
}
