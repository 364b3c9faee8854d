//! The real driver against the fake RPLIDAR on a pseudo-terminal: scans decoded to the
//! served ranges, scan-mode selection, and recovery from every injected fault.

use std::os::fd::OwnedFd;
use std::path::Path;
use std::time::{Duration, Instant};

use lidar_har_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_rplidar::fake::{
    FakeConfig, FakeLidar, FakeLog, FakeScanMode, SyntheticRoom, driver_config,
};
use lidar_har_rplidar::protocol::HealthStatus;
use lidar_har_rplidar::{
    Config, DEFAULT_MOTOR_PWM, Driver, Error, Event, ScanFormat, ScanGeometry, ScanModeChoice,
};
use nix::fcntl::OFlag;
use nix::sys::stat::Mode;
use nix::sys::termios::{ControlFlags, SetArg, tcgetattr, tcsetattr};

const SAMPLES: usize = 720;

fn config(path: &Path, mode: ScanModeChoice) -> Config {
    Config {
        scan_mode: mode,
        ..driver_config(path)
    }
}

/// What the scan of the synthetic room must contain, beam by beam.
fn expected_ranges(geometry: &ScanGeometry) -> Vec<f32> {
    let room = SyntheticRoom::default();
    (0..geometry.beams)
        .map(|b| {
            let k =
                (geometry.device_angle_of(b) / (360.0 / SAMPLES as f32)).round() as usize % SAMPLES;
            let r = room.range_at(k as f32 * 360.0 / SAMPLES as f32);
            if r >= geometry.range_min_m && r <= geometry.range_max_m {
                r
            } else {
                f32::INFINITY
            }
        })
        .collect()
}

fn mismatches(scan: &LaserScan, expected: &[f32], tolerance_m: f32) -> usize {
    assert_eq!(
        scan.ranges.len(),
        expected.len(),
        "the beam count never changes"
    );
    scan.ranges
        .iter()
        .zip(expected)
        .filter(|(got, want)| {
            if want.is_infinite() {
                !got.is_infinite()
            } else {
                (*got - *want).abs() > tolerance_m
            }
        })
        .count()
}

/// The data timeout of tests about hangs: short enough to keep them quick, still twenty times
/// the tolerated stall and far above the delays of a busy scheduler.
const HANG_DATA_TIMEOUT: Duration = Duration::from_secs(2);

/// A start that waited for one full request timeout of [`driver_config`] (20 s, which no
/// start comes near, even on a machine that stalls a thread for seconds) takes longer.
const QUICK_START: Duration = Duration::from_secs(15);

/// How long a test waits for what it expects before failing: only a broken driver takes it.
const LIMIT: Duration = Duration::from_secs(30);

fn spawn(dir: &Path, fake: FakeConfig) -> FakeLidar {
    FakeLidar::spawn(dir.join("rplidar"), fake, SyntheticRoom::default())
        .expect("fake device starts")
}

/// Runs the driver until `done` says so, returning every scan and diagnostic seen.
fn run_until(
    driver: &mut Driver,
    limit: Duration,
    mut done: impl FnMut(&[LaserScan], &[DiagnosticStatus]) -> bool,
) -> (Vec<LaserScan>, Vec<DiagnosticStatus>) {
    let deadline = Instant::now() + limit;
    let mut scans = Vec::new();
    let mut diags = Vec::new();
    while !done(&scans, &diags) {
        assert!(
            Instant::now() < deadline,
            "gave up after {limit:?}: {} scans; diagnostics: {:#?}",
            scans.len(),
            diags
                .iter()
                .map(|d: &DiagnosticStatus| (d.level, d.message.clone()))
                .collect::<Vec<_>>()
        );
        match driver.next_event() {
            Ok(Event::Scan(scan)) => scans.push(scan),
            Ok(Event::Diagnostics(DiagnosticArray { status, .. })) => diags.extend(status),
            Err(e) => panic!("the driver stopped: {e}"),
        }
    }
    (scans, diags)
}

/// Runs the driver until it stops with a permanent error, returning the error and the
/// diagnostics before it.
fn run_until_stopped(driver: &mut Driver, limit: Duration) -> (Error, Vec<DiagnosticStatus>) {
    let deadline = Instant::now() + limit;
    let mut diags = Vec::new();
    loop {
        assert!(
            Instant::now() < deadline,
            "still running after {limit:?}: {:#?}",
            diags
                .iter()
                .map(|d: &DiagnosticStatus| (d.level, d.message.clone()))
                .collect::<Vec<_>>()
        );
        match driver.next_event() {
            Ok(Event::Scan(_)) => panic!("a scan from a driver that should stop"),
            Ok(Event::Diagnostics(DiagnosticArray { status, .. })) => diags.extend(status),
            Err(e) => return (e, diags),
        }
    }
}

fn scans(n: usize) -> impl FnMut(&[LaserScan], &[DiagnosticStatus]) -> bool {
    move |s, _| s.len() >= n
}

fn value<'a>(d: &'a DiagnosticStatus, key: &str) -> Option<&'a str> {
    d.values
        .iter()
        .find(|kv| kv.key == key)
        .map(|kv| kv.value.as_str())
}

fn check_exact(mode: ScanModeChoice, format: ScanFormat, tolerance_m: f32) {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    let mut cfg = config(fake.path(), mode);
    cfg.motor_pwm = Some(600);
    let expected = expected_ranges(&cfg.geometry);
    let mut driver = Driver::new(cfg.clone()).unwrap();
    let started = Instant::now();
    let (first, diags) = run_until(&mut driver, LIMIT, |_, d| !d.is_empty());
    // Requests return as soon as their answer is complete: no full timeout is waited.
    assert!(
        started.elapsed() < QUICK_START,
        "start took {:?}",
        started.elapsed()
    );
    // Three seconds of rotations: the mean period below is then immune to a busy scheduler.
    let (more, _) = run_until(&mut driver, LIMIT, scans(60));
    let scans: Vec<LaserScan> = first.into_iter().chain(more).collect();
    let status = driver.status();
    assert_eq!(status.format, Some(format));
    for scan in &scans {
        assert_eq!(
            mismatches(scan, &expected, tolerance_m),
            0,
            "{format:?} scan differs from the served ranges; decoder {:?}",
            status.decode
        );
        assert_eq!(scan.header.frame_id, "laser");
        // A single period may be short when a busy machine gets a backlog of rotations in
        // several reads (they crowd together), or long when it did not read for a while: the
        // mean below checks the rate. It is never 0.
        assert!(
            scan.scan_time > 0.0 && scan.scan_time.is_finite(),
            "scan_time {}",
            scan.scan_time
        );
        assert!(scan.time_increment <= 0.0);
        assert!((scan.time_increment * 720.0 + scan.scan_time).abs() < 1e-6);
    }
    // 20 Hz served: consecutive measured periods add up to the real time, so over 60 of them
    // the mean is near 50 ms even when the reads of the first and last are 1.2 s late; a
    // period measured wrong by half or double still fails.
    let mean = scans.iter().map(|s| s.scan_time).sum::<f32>() / scans.len() as f32;
    assert!((0.03..0.07).contains(&mean), "mean scan_time {mean}");
    // Stamps increase in the driver's monotonic time; the wall clock is read once per read of
    // the port, so crowded stamps from different reads may differ by the jitter of those
    // readings, never by a rotation.
    let stamps: Vec<i64> = scans.iter().map(|s| s.header.stamp.to_nanos()).collect();
    assert!(
        stamps.windows(2).all(|w| w[1] > w[0] - 1_000_000) && stamps[stamps.len() - 1] > stamps[0],
        "stamps increase: {stamps:?}"
    );
    let window = scans[1].ranges.iter().filter(|r| r.is_infinite()).count();
    assert!(
        window >= 25,
        "the window sector has no return: {window} inf beams"
    );
    // Device facts and the configured baud are reported.
    let connected = diags
        .iter()
        .find(|d| d.message.starts_with("scanning:"))
        .expect("a connect report");
    assert_eq!(connected.level, DiagnosticStatus::OK);
    assert_eq!(value(connected, "model"), Some("A1 (0x18)"));
    assert_eq!(value(connected, "firmware"), Some("1.29"));
    assert_eq!(value(connected, "baud"), Some("115200"));
    assert_eq!(connected.hardware_id, "46414B452D52504C494441522D303031");
    assert_eq!(status.health.map(|h| h.status), Some(HealthStatus::Good));
    if let Some(baud) = status.baud_readback {
        assert_eq!(baud, cfg.baud, "a pty reads back the configured rate");
    }
    assert_eq!(
        fake.log().motor_pwm,
        Some(600),
        "motor PWM sent through the accessory board request"
    );
    // The fake announces 720 x 20 Hz = 14.4 kHz, and delivers it.
    let nominal = status
        .nominal_sample_rate_hz
        .expect("the device announces its rate");
    assert!((nominal - 14_400.0).abs() < 100.0, "nominal rate {nominal}");
    let n = status.samples_per_rotation.unwrap();
    assert!((700..=740).contains(&n), "samples per rotation {n}");
}

#[test]
fn standard_scan_decodes_to_the_served_ranges() {
    check_exact(ScanModeChoice::Standard, ScanFormat::Standard, 0.0006);
}

#[test]
fn express_scan_decodes_to_the_served_ranges() {
    check_exact(ScanModeChoice::Express, ScanFormat::Express, 0.0006);
}

#[test]
fn named_dense_mode_decodes_to_the_served_ranges() {
    check_exact(
        ScanModeChoice::Named("denseboost".into()),
        ScanFormat::Dense,
        0.0006,
    );
}

#[test]
fn auto_uses_the_typical_mode_or_legacy_express() {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(
        dir.path(),
        FakeConfig {
            typical_mode: 2,
            ..FakeConfig::default()
        },
    );
    let mut driver = Driver::new(config(fake.path(), ScanModeChoice::Auto)).unwrap();
    run_until(&mut driver, LIMIT, scans(1));
    assert_eq!(driver.status().scan_mode.as_deref(), Some("DenseBoost"));
    drop(driver);
    drop(fake);

    // Firmware without scan modes: the configuration probe times out quickly and the
    // legacy express scan is used.
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(
        dir.path(),
        FakeConfig {
            scan_modes: Vec::new(),
            ..FakeConfig::default()
        },
    );
    let mut driver = Driver::new(config(fake.path(), ScanModeChoice::Auto)).unwrap();
    let started = Instant::now();
    run_until(&mut driver, LIMIT, scans(1));
    assert_eq!(driver.status().format, Some(ScanFormat::Express));
    assert!(
        started.elapsed() < QUICK_START,
        "the probe waited {:?}, as long as a request",
        started.elapsed()
    );
}

#[test]
fn s_series_firmware_1_02_lists_its_modes_and_auto_picks_the_typical_one() {
    // An S3 reports firmware 1.02: the driver must ask for its modes, not trust the number.
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::s_series());
    let cfg = config(fake.path(), ScanModeChoice::Auto);
    let expected = expected_ranges(&cfg.geometry);
    let mut driver = Driver::new(cfg).unwrap();
    let (scans, diags) = run_until(&mut driver, LIMIT, scans(3));
    let status = driver.status();
    assert_eq!(status.scan_mode.as_deref(), Some("DenseBoost"));
    assert_eq!(status.format, Some(ScanFormat::Dense));
    for scan in &scans {
        assert_eq!(
            mismatches(scan, &expected, 0.0006),
            0,
            "dense scan of the S3"
        );
    }
    let connected = diags
        .iter()
        .find(|d| d.message.starts_with("scanning:"))
        .expect("a connect report");
    assert!(
        connected.message.contains("S-series") && connected.message.contains("1.02"),
        "{}",
        connected.message
    );
    let log = fake.log();
    assert!(log.commands.contains(&0x84), "scan modes asked");
    assert!(
        !log.commands.contains(&0x20),
        "no standard scan: {:?}",
        log.commands
    );
}

#[test]
fn s_series_named_and_standard_modes_work() {
    for (mode, format) in [
        (
            ScanModeChoice::Named("DenseBoost".into()),
            ScanFormat::Dense,
        ),
        (ScanModeChoice::Standard, ScanFormat::Standard),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let fake = spawn(dir.path(), FakeConfig::s_series());
        let mut driver = Driver::new(config(fake.path(), mode.clone())).unwrap();
        run_until(&mut driver, LIMIT, scans(1));
        assert_eq!(driver.status().format, Some(format), "{mode:?}");
    }
}

#[test]
fn old_a1_firmware_without_scan_modes_uses_standard_scans_as_before() {
    // A1 firmware 1.15: before express scans (1.17) and scan modes (1.24). Its number proves
    // it lists no modes, so it is not asked.
    let dir = tempfile::tempdir().unwrap();
    let mut info = FakeConfig::default().info;
    info.firmware_minor = 15;
    let fake = spawn(
        dir.path(),
        FakeConfig {
            info,
            scan_modes: Vec::new(),
            ..FakeConfig::default()
        },
    );
    for mode in [ScanModeChoice::Auto, ScanModeChoice::Express] {
        let mut driver = Driver::new(config(fake.path(), mode.clone())).unwrap();
        let (_, diags) = run_until(&mut driver, LIMIT, scans(2));
        assert_eq!(
            driver.status().format,
            Some(ScanFormat::Standard),
            "{mode:?}"
        );
        let warned = diags
            .iter()
            .any(|d| d.message.contains("has no express scan"));
        assert_eq!(warned, mode == ScanModeChoice::Express, "{mode:?}");
    }
    let log = fake.log();
    assert!(!log.commands.contains(&0x84), "{:?}", log.commands);
    assert!(!log.commands.contains(&0x82), "{:?}", log.commands);
}

/// Checks a permanent scan-mode error: returned (naming `scan_mode`) after an ERROR report,
/// again at the next call, with no scan started and the motor not started.
fn check_stops_on(fake: FakeConfig, mode: ScanModeChoice, reason: &str) {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), fake);
    let mut driver = Driver::new(config(fake.path(), mode.clone())).unwrap();
    let (error, diags) = run_until_stopped(&mut driver, LIMIT);
    let text = error.to_string();
    assert!(
        matches!(
            error,
            Error::Unsupported {
                parameter: "scan_mode",
                ..
            }
        ),
        "{mode:?}: {text}"
    );
    assert!(text.contains(reason), "{mode:?}: {text}");
    let report = diags.last().expect("the error is reported first");
    assert_eq!(report.level, DiagnosticStatus::ERROR);
    assert!(
        report.message.contains("not retrying"),
        "{}",
        report.message
    );
    assert!(!driver.status().scanning);
    let started = Instant::now();
    assert!(driver.next_event().is_err(), "{mode:?}: stays stopped");
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "without retrying"
    );
    let log = fake.log();
    assert!(
        log.scans_started.is_empty(),
        "{mode:?}: {:?}",
        log.scans_started
    );
    assert_eq!(log.motor_pwm, None);
}

#[test]
fn a_scan_mode_the_device_lacks_stops_the_driver_naming_scan_mode() {
    check_stops_on(
        FakeConfig::default(),
        ScanModeChoice::Named("Boost".into()),
        "Standard (id 0), Express (id 1), DenseBoost (id 2)",
    );
    // An S3 has no express capsules.
    check_stops_on(
        FakeConfig::s_series(),
        ScanModeChoice::Express,
        "no express-capsule mode",
    );
    // Old A1 firmware has no scan modes at all.
    let mut info = FakeConfig::default().info;
    info.firmware_minor = 15;
    check_stops_on(
        FakeConfig {
            info,
            scan_modes: Vec::new(),
            ..FakeConfig::default()
        },
        ScanModeChoice::Named("Boost".into()),
        "has no scan modes",
    );
    // A typical mode in a format the driver does not decode (ultra dense).
    let mut s3 = FakeConfig::s_series();
    s3.scan_modes.push(FakeScanMode::new("DenseUltra", 0x86));
    s3.typical_mode = 2;
    check_stops_on(
        s3,
        ScanModeChoice::Auto,
        "does not decode; set a mode it decodes: Standard, DenseBoost",
    );
}

#[test]
fn a_named_mode_without_an_answer_to_the_mode_list_is_retried() {
    // Firmware 1.29 should list modes: no answer may be a glitch, so it is not permanent.
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(
        dir.path(),
        FakeConfig {
            scan_modes: Vec::new(),
            ..FakeConfig::default()
        },
    );
    let mut driver =
        Driver::new(config(fake.path(), ScanModeChoice::Named("Boost".into()))).unwrap();
    let (_, diags) = run_until(&mut driver, LIMIT, |_, d| {
        d.iter()
            .filter(|s| s.message.starts_with("cannot start"))
            .count()
            >= 2
    });
    let retry = diags
        .iter()
        .find(|d| d.message.starts_with("cannot start"))
        .unwrap();
    assert!(
        retry.message.contains("list of scan modes"),
        "{}",
        retry.message
    );
    assert!(retry.message.contains("retrying in"), "{}", retry.message);
}

fn garbage_resync(mode: ScanModeChoice) {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    let cfg = config(fake.path(), mode);
    let expected = expected_ranges(&cfg.geometry);
    let mut driver = Driver::new(cfg).unwrap();
    run_until(&mut driver, LIMIT, scans(2));
    // Faults while scanning: garbage that looks like sync bytes, odd lengths, dropped bytes.
    // A busy machine may leave many rotations in the pty between the fake and the driver, so
    // each round lasts until the decoder has met its fault, plus the two scans it can touch.
    let disturbances = |d: &Driver| {
        let s = d.status().decode;
        s.skipped_bytes + s.rejected_packets + s.gaps
    };
    let mut lost = Vec::new();
    for round in 0..4 {
        let before = disturbances(&driver);
        match round {
            0 => fake.inject_garbage(&[0xA5, 0x5A, 0x13, 0x37, 0xFF]),
            1 => fake.drop_bytes(7),
            2 => fake.inject_garbage(&[0x00; 1]),
            _ => fake.inject_garbage(&(0..=255).collect::<Vec<u8>>()),
        }
        let mut faulty = Vec::new();
        let deadline = Instant::now() + LIMIT;
        while disturbances(&driver) == before {
            assert!(
                Instant::now() < deadline,
                "fault {round} never reached the decoder"
            );
            let (s, _) = run_until(&mut driver, LIMIT, scans(1));
            faulty.extend(s);
        }
        let (s, _) = run_until(&mut driver, LIMIT, scans(2));
        faulty.extend(s);
        lost.push(
            faulty
                .iter()
                .map(|s| mismatches(s, &expected, 0.0006))
                .sum::<usize>(),
        );
    }
    eprintln!("beams wrong after each of 4 faults: {lost:?}");
    // A fault costs at most the packet it hit and, when the corrupted packet still passes its
    // check (a shifted capsule whose XOR is unchanged), the next one: two capsules of at most
    // 40 samples.
    assert!(
        lost.iter().all(|&l| l <= 2 * 40),
        "beams wrong after each of 4 faults: {lost:?}"
    );
    let (clean, _) = run_until(&mut driver, LIMIT, scans(2));
    for scan in &clean {
        assert_eq!(
            mismatches(scan, &expected, 0.0006),
            0,
            "decoding recovered fully"
        );
    }
    let status = driver.status();
    assert!(status.decode.skipped_bytes + status.decode.rejected_packets > 0);
    assert_eq!(status.resets, 0, "garbage alone must not trigger a reset");
    assert_eq!(status.connects, 1);
}

#[test]
fn standard_scan_resyncs_after_garbage_with_bounded_loss() {
    garbage_resync(ScanModeChoice::Standard);
}

#[test]
fn express_scan_resyncs_after_garbage_with_bounded_loss() {
    garbage_resync(ScanModeChoice::Express);
}

#[test]
fn a_byte_lost_mid_turn_neither_splits_the_scan_nor_publishes_false_ranges() {
    // A byte lost at the start of the node at 290° (the quality byte): the windows after it
    // pass the check bits and used to take an angle more than half a turn back for a wrap,
    // publishing the turn as two scans of 580 and 139 samples.
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(
        dir.path(),
        FakeConfig {
            fault_angle_deg: 290.0,
            ..FakeConfig::default()
        },
    );
    let cfg = config(fake.path(), ScanModeChoice::Standard);
    let expected = expected_ranges(&cfg.geometry);
    let valid = expected.iter().filter(|r| r.is_finite()).count();
    let mut driver = Driver::new(cfg).unwrap();
    run_until(&mut driver, LIMIT, scans(2));
    let mut faulty = Vec::new();
    for round in 0..4 {
        let before = driver.status().decode;
        fake.drop_bytes(1);
        let deadline = Instant::now() + LIMIT;
        while driver.status().decode == before {
            assert!(
                Instant::now() < deadline,
                "fault {round} never reached the decoder"
            );
            faulty.extend(run_until(&mut driver, LIMIT, scans(1)).0);
        }
        faulty.extend(run_until(&mut driver, LIMIT, scans(2)).0);
    }
    let beams: Vec<usize> = faulty
        .iter()
        .map(|s| s.ranges.iter().filter(|r| r.is_finite()).count())
        .collect();
    let wrong: Vec<usize> = faulty
        .iter()
        .map(|s| mismatches(s, &expected, 0.0006))
        .collect();
    eprintln!("valid beams per scan: {beams:?}; wrong beams: {wrong:?}");
    // The node hit and its neighbour at most: one beam each.
    assert!(
        beams.iter().all(|&b| b + 2 >= valid),
        "partial scans (of {valid}): {beams:?}"
    );
    assert!(
        wrong.iter().all(|&w| w <= 2),
        "wrong beams per scan: {wrong:?}"
    );
    assert_eq!(driver.status().resets, 0);
}

#[test]
fn unplug_and_replug_reconnects_with_backoff() {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    let mut driver = Driver::new(config(fake.path(), ScanModeChoice::Express)).unwrap();
    run_until(&mut driver, LIMIT, scans(2));
    fake.unplug();
    let (_, diags) = run_until(&mut driver, LIMIT, |_, d| {
        d.iter()
            .filter(|s| s.message.starts_with("cannot start"))
            .count()
            >= 3
    });
    let lost = diags
        .iter()
        .find(|d| d.message.starts_with("lost the device"))
        .expect("the loss is reported");
    assert_eq!(lost.level, DiagnosticStatus::ERROR);
    let retry = diags
        .iter()
        .find(|d| d.message.starts_with("cannot start"))
        .unwrap();
    assert!(retry.message.contains("retrying in"), "{}", retry.message);
    assert!(!driver.status().scanning);
    fake.replug();
    let (scans_after, diags) = run_until(&mut driver, LIMIT, scans(3));
    assert!(
        diags
            .iter()
            .any(|d| d.level == DiagnosticStatus::OK && d.message.starts_with("scanning:"))
    );
    assert!(scans_after.iter().all(|s| s.ranges.len() == 720));
    let status = driver.status();
    assert_eq!((status.connects, status.disconnects), (2, 1));
    assert_eq!(fake.log().plugs, 2);
}

#[test]
fn hung_device_is_reset_and_scans_again() {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    let mut cfg = config(fake.path(), ScanModeChoice::Standard);
    cfg.data_timeout = HANG_DATA_TIMEOUT;
    let mut driver = Driver::new(cfg).unwrap();
    run_until(&mut driver, LIMIT, scans(2));
    // A short stall (a tenth of the data timeout) is tolerated without a reset.
    fake.stall(Duration::from_millis(100));
    run_until(&mut driver, LIMIT, scans(3));
    assert_eq!(driver.status().resets, 0);
    fake.hang();
    let (_, diags) = run_until(&mut driver, LIMIT, |s, d| {
        d.iter().any(|x| x.message.starts_with("scanning again")) && !s.is_empty()
    });
    let warn = diags
        .iter()
        .find(|d| d.message.starts_with("no valid data"))
        .expect("silence is reported");
    assert_eq!(warn.level, DiagnosticStatus::WARN);
    assert_eq!(fake.log().resets, 1);
    assert_eq!(driver.status().resets, 1);
    assert_eq!(driver.status().connects, 1, "recovered on the same port");
}

#[test]
fn health_error_at_start_is_reset() {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    fake.set_health(HealthStatus::Error, 0x8001, true);
    let mut driver = Driver::new(config(fake.path(), ScanModeChoice::Express)).unwrap();
    let (_, diags) = run_until(&mut driver, LIMIT, scans(2));
    let error = diags
        .iter()
        .find(|d| d.message.contains("health error"))
        .expect("the health error is reported");
    assert_eq!(error.level, DiagnosticStatus::ERROR);
    assert!(error.message.contains("0x8001"));
    assert_eq!(fake.log().resets, 1);
}

#[test]
fn persistent_health_error_keeps_retrying_until_it_clears() {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    fake.set_health(HealthStatus::Error, 0x0042, false);
    let mut driver = Driver::new(config(fake.path(), ScanModeChoice::Standard)).unwrap();
    let (_, diags) = run_until(&mut driver, LIMIT, |_, d| {
        d.iter()
            .filter(|s| s.message.contains("persists after a reset"))
            .count()
            >= 2
    });
    assert!(
        diags
            .iter()
            .all(|d| d.level != DiagnosticStatus::OK || !d.message.starts_with("scanning:"))
    );
    fake.set_health(HealthStatus::Warning, 0x0007, false);
    let (_, diags) = run_until(&mut driver, LIMIT, scans(2));
    let warn = diags
        .iter()
        .find(|d| d.message.contains("Warning"))
        .expect("a warning health is reported");
    assert_eq!(warn.level, DiagnosticStatus::WARN);
}

#[test]
fn missing_port_is_reported_not_fatal() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no-such-device");
    let mut driver = Driver::new(config(&path, ScanModeChoice::Auto)).unwrap();
    let (_, diags) = run_until(&mut driver, LIMIT, |_, d| d.len() >= 3);
    assert!(diags.iter().all(|d| d.level == DiagnosticStatus::ERROR));
    assert!(
        diags[0].message.contains("no-such-device"),
        "{}",
        diags[0].message
    );
}

#[test]
fn a_port_that_never_answers_times_out_quickly_with_a_hint() {
    // A pty with nobody behind it: like a device at the wrong baud rate.
    use serialport::SerialPort;
    let (_master, slave) = serialport::TTYPort::pair().unwrap();
    let path = slave.name().unwrap();
    drop(slave);
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("silent");
    std::os::unix::fs::symlink(&path, &link).unwrap();
    let mut cfg = config(&link, ScanModeChoice::Auto);
    let timeout = Duration::from_secs(1);
    cfg.request_timeout = timeout;
    let mut driver = Driver::new(cfg).unwrap();
    let started = Instant::now();
    let (_, diags) = run_until(&mut driver, LIMIT, |_, d| !d.is_empty());
    // One request timeout, not a wait per request or per retry.
    let elapsed = started.elapsed();
    assert!(elapsed < 4 * timeout, "{elapsed:?}");
    assert!(
        diags[0].message.contains("device info"),
        "{}",
        diags[0].message
    );
    assert!(
        diags[0].message.contains("wrong baud rate"),
        "{}",
        diags[0].message
    );
}

#[test]
fn stopped_motor_is_reset_and_scans_again() {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    let mut cfg = config(fake.path(), ScanModeChoice::Express);
    cfg.data_timeout = HANG_DATA_TIMEOUT;
    let mut driver = Driver::new(cfg).unwrap();
    run_until(&mut driver, LIMIT, scans(2));
    fake.stop_motor();
    let (_, diags) = run_until(&mut driver, LIMIT, |s, d| {
        d.iter().any(|x| x.message.starts_with("scanning again")) && !s.is_empty()
    });
    let warn = diags
        .iter()
        .find(|d| d.message.contains("no complete rotation"))
        .expect("a stuck motor is reported");
    assert_eq!(warn.level, DiagnosticStatus::WARN);
    assert!(diags.iter().any(|d| {
        d.level == DiagnosticStatus::WARN && d.message.contains("no complete rotation for")
    }));
    assert_eq!(fake.log().resets, 1);
}

#[test]
fn stamps_follow_the_callers_clock_and_drop_stops_the_device() {
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    // A simulation clock that starts at 1000 s.
    const EPOCH_NS: i64 = 1_000_000_000_000;
    let t0 = Instant::now();
    let clock = Box::new(move || EPOCH_NS + t0.elapsed().as_nanos() as i64);
    let mut driver =
        Driver::with_clock(config(fake.path(), ScanModeChoice::Standard), clock).unwrap();
    let (scans, _) = run_until(&mut driver, LIMIT, scans(4));
    let elapsed_ns = t0.elapsed().as_nanos() as i64;
    for pair in scans.windows(2) {
        let (a, b) = (
            pair[0].header.stamp.to_nanos(),
            pair[1].header.stamp.to_nanos(),
        );
        assert!(a > EPOCH_NS && b <= EPOCH_NS + elapsed_ns, "{a} {b}");
        // A stamp is its rotation's start plus (beams - 1)/beams of its period, and a
        // rotation starts where the one before ends: consecutive stamps are that far apart
        // however much the periods jitter.
        let beams = pair[1].ranges.len() as f32;
        let (t0, t1) = (pair[0].scan_time, pair[1].scan_time);
        let gap = (b - a) as f32 * 1e-9;
        let expected = t1 * (beams - 1.0) / beams + t0 / beams;
        assert!(
            (gap - expected).abs() < 0.02,
            "gap {gap} vs {expected} from scan_time {t0} and {t1}"
        );
    }
    drop(driver);
    let log = fake.log_when(LIMIT, |l| l.commands.last() == Some(&0x25));
    assert_eq!(log.commands.last(), Some(&0x25), "STOP sent on drop");
}

/// HUPCL set on a tty (the Linux default for a ttyUSB), before the driver opens it.
fn set_hupcl(tty: &OwnedFd) {
    let mut termios = tcgetattr(tty).expect("the fake's slave is a tty");
    termios.control_flags.insert(ControlFlags::HUPCL);
    tcsetattr(tty, SetArg::TCSANOW, &termios).expect("HUPCL can be set on a pty");
}

fn hupcl(tty: &OwnedFd) -> bool {
    let termios = tcgetattr(tty).expect("the fake's slave is a tty");
    termios.control_flags.contains(ControlFlags::HUPCL)
}

#[test]
fn the_driver_clears_hupcl_so_closing_the_port_leaves_dtr_as_set() {
    // With HUPCL the kernel lowers DTR when the driver closes the port, and DTR low runs an
    // A1's motor that the driver's stop turned off. A pty slave starts without HUPCL: the
    // test sets it, as a ttyUSB has it, through its own handle of the fake's slave (opened
    // before the driver, whose exclusive open would refuse it afterwards).
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    let tty = nix::fcntl::open(fake.path(), OFlag::O_RDWR | OFlag::O_NOCTTY, Mode::empty())
        .expect("the fake's slave opens");
    set_hupcl(&tty);
    assert!(hupcl(&tty), "HUPCL is set before the driver opens the port");
    // 256000 is no `Bnnn` constant: the rate set with termios2 survives clearing the flag.
    let cfg = Config {
        baud: 256_000,
        ..config(fake.path(), ScanModeChoice::Standard)
    };
    let mut driver = Driver::new(cfg).unwrap();
    run_until(&mut driver, LIMIT, scans(1));
    assert!(
        !hupcl(&tty),
        "the driver clears HUPCL on the port it opened"
    );
    if let Some(baud) = driver.status().baud_readback {
        assert_eq!(baud, 256_000, "the configured rate is kept");
    }
}

#[test]
fn accessory_board_motor_gets_the_default_pwm_and_pwm_0_on_drop() {
    let dir = tempfile::tempdir().unwrap();
    let mut info = FakeConfig::default().info;
    info.model = 0x28; // A2
    let fake = spawn(
        dir.path(),
        FakeConfig {
            info,
            accessory_board_motor: true,
            ..FakeConfig::default()
        },
    );
    let mut driver = Driver::new(config(fake.path(), ScanModeChoice::Express)).unwrap();
    let (_, diags) = run_until(&mut driver, LIMIT, |s, d| s.len() >= 2 && !d.is_empty());
    // No motor_pwm configured: the SDK's default duty cycle starts the motor.
    assert_eq!(fake.log().motor_pwm, Some(DEFAULT_MOTOR_PWM));
    assert_eq!(driver.status().motor_pwm, Some(DEFAULT_MOTOR_PWM));
    let connected = diags
        .iter()
        .find(|d| d.message.starts_with("scanning:"))
        .expect("a connect report");
    assert_eq!(value(connected, "motor_pwm"), Some("660"));
    drop(driver);
    let log = fake.log_when(LIMIT, |l| l.motor_pwm == Some(0));
    assert_eq!(log.motor_pwm, Some(0), "the motor is switched off on drop");
    assert_eq!(
        log.commands[log.commands.len() - 2..],
        [0x25, 0xF0],
        "STOP, then PWM 0"
    );
}

#[test]
fn a_scan_that_does_not_start_leaves_the_motor_off() {
    // An A2 whose board drives the motor and whose typical mode (ultra capsules) never
    // answers EXPRESS_SCAN: the motor, started by PWM before the request, must not keep
    // turning while the driver waits to retry, nor after it is dropped.
    let dir = tempfile::tempdir().unwrap();
    let mut info = FakeConfig::default().info;
    info.model = 0x28;
    let fake = spawn(
        dir.path(),
        FakeConfig {
            info,
            accessory_board_motor: true,
            scan_modes: vec![
                FakeScanMode::new("Standard", 0x81),
                FakeScanMode::new("Sensitivity", 0x84),
            ],
            typical_mode: 1,
            ..FakeConfig::default()
        },
    );
    let mut cfg = config(fake.path(), ScanModeChoice::Auto);
    cfg.request_timeout = Duration::from_secs(2);
    cfg.reconnect_min = Duration::from_secs(60);
    cfg.reconnect_max = Duration::from_secs(60);
    let mut driver = Driver::new(cfg).unwrap();
    let (_, diags) = run_until(&mut driver, LIMIT, |_, d| {
        d.iter().any(|s| s.message.starts_with("cannot start"))
    });
    let failed = diags
        .iter()
        .find(|d| d.message.starts_with("cannot start"))
        .unwrap();
    assert!(failed.message.contains("scan start"), "{}", failed.message);
    let stopped = |l: &FakeLog| {
        let scan = l.commands.iter().rposition(|&c| c == 0x82);
        l.motor_pwm == Some(0) && scan.is_some_and(|i| l.commands[i..].contains(&0x25))
    };
    let log = fake.log_when(LIMIT, stopped);
    assert!(
        stopped(&log),
        "STOP and PWM 0 after the failed start: {log:?}"
    );
    drop(driver);
    let log = fake.log();
    assert_eq!(log.motor_pwm, Some(0), "{log:?}");
    assert_eq!(
        log.commands.last(),
        Some(&0xF0),
        "nothing restarted it: {log:?}"
    );
}

#[test]
fn motor_without_accessory_board_control_gets_no_pwm() {
    // An A2 whose board does not drive the motor (DTR does), and an A1, which is not asked.
    for (model, asked) in [(0x28, true), (0x18, false)] {
        let dir = tempfile::tempdir().unwrap();
        let mut info = FakeConfig::default().info;
        info.model = model;
        let fake = spawn(
            dir.path(),
            FakeConfig {
                info,
                ..FakeConfig::default()
            },
        );
        let mut driver = Driver::new(config(fake.path(), ScanModeChoice::Express)).unwrap();
        run_until(&mut driver, LIMIT, scans(1));
        assert_eq!(driver.status().motor_pwm, None, "model 0x{model:02X}");
        drop(driver);
        // A PWM command would come after the STOP.
        let log = fake.log_when(LIMIT, |l| l.commands.last() == Some(&0x25));
        assert_eq!(log.motor_pwm, None, "model 0x{model:02X}");
        assert_eq!(
            log.commands.contains(&0xFF),
            asked,
            "GET_ACC_BOARD_FLAG asked of A2/A3 only (model 0x{model:02X})"
        );
        assert_eq!(log.commands.last(), Some(&0x25), "STOP last");
    }
}

#[test]
fn a_motor_parameter_of_the_other_family_is_warned_about_and_not_sent() {
    // motor_pwm on an S-series (time of flight) and motor_rpm on an A2: neither is sent,
    // and the user learns why the scan rate did not change.
    let s_series = FakeConfig::s_series();
    let mut a2 = FakeConfig::default();
    a2.info.model = 0x28;
    for (fake_config, pwm, rpm, names) in [
        (s_series, Some(600), None, "motor_pwm = 600 ignored"),
        (a2, None, Some(900), "motor_rpm = 900 ignored"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let fake = spawn(dir.path(), fake_config);
        let mut cfg = config(fake.path(), ScanModeChoice::Auto);
        cfg.motor_pwm = pwm;
        cfg.motor_rpm = rpm;
        let mut driver = Driver::new(cfg).unwrap();
        let (_, diags) = run_until(&mut driver, LIMIT, scans(2));
        let warnings: Vec<_> = diags.iter().filter(|d| d.message.contains(names)).collect();
        assert_eq!(warnings.len(), 1, "{names}: {diags:#?}");
        assert_eq!(warnings[0].level, DiagnosticStatus::WARN);
        drop(driver);
        let log = fake.log_when(LIMIT, |l| l.commands.last() == Some(&0x25));
        assert_eq!(log.motor_rpm, None, "{names}");
        if pwm.is_some() {
            assert_eq!(log.motor_pwm, None, "{names}");
        }
    }
}

/// The last routine report ("scanning ..." or the warning of no return) among `diags`.
fn last_routine<'a>(diags: &'a [DiagnosticStatus], starts: &str) -> Option<&'a DiagnosticStatus> {
    diags.iter().rev().find(|d| d.message.starts_with(starts))
}

#[test]
fn a_blinded_sensor_warns_until_returns_come_back() {
    // A covered window: the device turns and streams, every sample without a return. Its
    // all-`+inf` scans read as free space downstream, and the diagnostics used to stay OK.
    const SEEING: &str = "scanning at";
    const BLIND: &str = "no return on any beam";
    let dir = tempfile::tempdir().unwrap();
    let fake = spawn(dir.path(), FakeConfig::default());
    let cfg = config(fake.path(), ScanModeChoice::Express);
    let room_beams = expected_ranges(&cfg.geometry)
        .iter()
        .filter(|r| r.is_finite())
        .count();
    let mut driver = Driver::new(cfg).unwrap();
    let (_, seeing) = run_until(&mut driver, LIMIT, |_, d| {
        last_routine(d, SEEING).is_some_and(|d| value(d, "valid_beams").is_some())
    });
    assert!(
        seeing.iter().all(|d| d.level == DiagnosticStatus::OK),
        "{seeing:#?}"
    );
    let report = last_routine(&seeing, SEEING).unwrap();
    let valid: usize = value(report, "valid_beams").unwrap().parse().unwrap();
    // All but the room's window (30 of 720 beams); angle quantisation may move one beam.
    assert!(valid.abs_diff(room_beams) <= 2, "{valid} of {room_beams}");
    let percent: f64 = value(report, "valid_beams_percent")
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        (percent - 100.0 * valid as f64 / 720.0).abs() < 0.1,
        "{percent}"
    );
    assert_eq!(value(report, "rotations_without_return"), Some("0"));

    fake.set_blinded(true);
    let (blind_scans, blind) =
        run_until(&mut driver, LIMIT, |_, d| last_routine(d, BLIND).is_some());
    let warning = last_routine(&blind, BLIND).unwrap();
    assert_eq!(warning.level, DiagnosticStatus::WARN);
    assert!(
        warning
            .message
            .contains("covered, blinded, or facing open space beyond range_max (12 m)"),
        "{}",
        warning.message
    );
    assert_eq!(value(warning, "valid_beams"), Some("0"));
    assert_eq!(value(warning, "valid_beams_percent"), Some("0.0"));
    let rotations: u64 = value(warning, "rotations_without_return")
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        warning
            .message
            .contains(&format!("for {rotations} rotations"))
            && rotations >= 1,
        "{}",
        warning.message
    );
    let last = blind_scans.last().expect("scans go on while blinded");
    assert!(last.ranges.iter().all(|r| r.is_infinite()));
    // Samples keep coming: nothing to reset.
    assert_eq!(driver.status().resets, 0);

    fake.set_blinded(false);
    let (_, back) = run_until(&mut driver, LIMIT, |_, d| last_routine(d, SEEING).is_some());
    let report = last_routine(&back, SEEING).unwrap();
    assert_eq!(report.level, DiagnosticStatus::OK);
    let valid: usize = value(report, "valid_beams").unwrap().parse().unwrap();
    assert!(valid.abs_diff(room_beams) <= 2, "{valid} of {room_beams}");
    assert_eq!(value(report, "rotations_without_return"), Some("0"));
}
