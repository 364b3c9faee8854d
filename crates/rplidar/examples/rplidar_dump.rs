//! Runs the driver on a real device (or the fake one) and prints one line per scan and per
//! diagnostics report: a quick check of a device without ROS.
//!
//! ```text
//! cargo run -p lidar-har-rplidar --example rplidar_dump -- /dev/ttyUSB0 [baud] [mode] [seconds]
//! cargo run -p lidar-har-rplidar --example rplidar_dump -- --fake [mode] [seconds]
//! ```
//! `mode`: standard, express, auto (default) or a device mode name such as Sensitivity.

use std::time::{Duration, Instant};

use lidar_har_rplidar::fake::{FakeConfig, FakeLidar, SyntheticRoom};
use lidar_har_rplidar::{Config, Driver, Event, ScanModeChoice};

fn main() {
    env_logger::init();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage =
        "usage: rplidar_dump PORT [BAUD] [MODE] [SECONDS] | rplidar_dump --fake [MODE] [SECONDS]";
    let Some(first) = args.first() else {
        eprintln!("{usage}");
        std::process::exit(2);
    };
    let mut fake_dir = None;
    let mut fake = None;
    let (mut config, rest) = if first == "--fake" {
        let dir = std::env::temp_dir().join(format!("rplidar-dump-{}", std::process::id()));
        if let Err(e) = std::fs::create_dir_all(&dir) {
            eprintln!("cannot create {}: {e}", dir.display());
            std::process::exit(1);
        }
        let link = dir.join("rplidar");
        fake_dir = Some(dir);
        let device = match FakeLidar::spawn(&link, FakeConfig::default(), SyntheticRoom::default())
        {
            Ok(device) => device,
            Err(e) => {
                eprintln!("cannot start the fake device: {e}");
                std::process::exit(1);
            }
        };
        fake = Some(device);
        (Config::new(link.to_string_lossy()), &args[1..])
    } else {
        let mut config = Config::new(first.clone());
        let mut rest = &args[1..];
        if let Some(baud) = rest.first().and_then(|b| b.parse().ok()) {
            config.baud = baud;
            rest = &rest[1..];
        }
        (config, rest)
    };
    if let Some(mode) = rest.first() {
        match mode.parse::<ScanModeChoice>() {
            Ok(m) => config.scan_mode = m,
            Err(e) => {
                eprintln!("{e}\n{usage}");
                std::process::exit(2);
            }
        }
    }
    let seconds: f64 = rest.get(1).and_then(|s| s.parse().ok()).unwrap_or(5.0);
    let mut driver = match Driver::new(config) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while Instant::now() < end {
        match driver.next_event() {
            Event::Scan(scan) => {
                let valid: Vec<f32> = scan
                    .ranges
                    .iter()
                    .copied()
                    .filter(|r| r.is_finite())
                    .collect();
                let nearest = valid.iter().copied().fold(f32::INFINITY, f32::min);
                println!(
                    "scan {}.{:09}: {} beams, {} valid, nearest {:.3} m, scan_time {:.1} ms",
                    scan.header.stamp.sec,
                    scan.header.stamp.nanosec,
                    scan.ranges.len(),
                    valid.len(),
                    nearest,
                    scan.scan_time * 1e3
                );
            }
            Event::Diagnostics(array) => {
                for s in array.status {
                    let values: Vec<String> = s
                        .values
                        .iter()
                        .map(|kv| format!("{}={}", kv.key, kv.value))
                        .collect();
                    println!(
                        "diag level {} {}: {} [{}]",
                        s.level,
                        s.name,
                        s.message,
                        values.join(", ")
                    );
                }
            }
        }
    }
    drop(driver);
    drop(fake);
    if let Some(dir) = fake_dir {
        let _ = std::fs::remove_dir(dir);
    }
}
