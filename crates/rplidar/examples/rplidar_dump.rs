//! Runs the driver on a real device (or the fake one) and prints one line per scan and per
//! diagnostics report: a quick check of a device without ROS.
//!
//! ```text
//! cargo run -p lidar-har-rplidar --example rplidar_dump -- /dev/ttyUSB0 [baud] [mode] [seconds]
//! cargo run -p lidar-har-rplidar --example rplidar_dump -- --fake [mode] [seconds]
//! ```
//! `mode`: standard, express, auto (default) or a device mode name such as Sensitivity.
//! `-h` / `--help` prints this usage. Ctrl-C (SIGINT) or SIGTERM ends the run early, with the
//! device stopped as at the end of SECONDS.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use lidar_har_rplidar::fake::{FakeConfig, FakeLidar, SyntheticRoom};
use lidar_har_rplidar::{Config, Driver, Error, Event, ScanModeChoice};
use signal_hook::consts::{SIGINT, SIGTERM};

/// How long to run without a SECONDS argument.
const DEFAULT_RUN: Duration = Duration::from_secs(5);
/// Longest run: a day, so that the end time cannot overflow.
const MAX_RUN_S: f64 = 86_400.0;

/// The SECONDS argument: positive and at most a day (`Duration::from_secs_f64` panics on
/// negative or huge values).
fn parse_seconds(text: &str) -> Result<Duration, String> {
    match text.parse::<f64>() {
        Ok(s) if s > 0.0 && s <= MAX_RUN_S => Ok(Duration::from_secs_f64(s)),
        _ => Err(format!(
            "SECONDS `{text}` must be a number of seconds in (0, {MAX_RUN_S}]"
        )),
    }
}

/// The one-line usage, printed with every argument error and with the help.
const USAGE: &str =
    "usage: rplidar_dump PORT [BAUD] [MODE] [SECONDS] | rplidar_dump --fake [MODE] [SECONDS]";

/// What `-h` / `--help` prints.
const HELP: &str = "Runs the RPLIDAR driver on a serial device (PORT; BAUD default 115200) or on
a fake one (--fake), printing one line per scan and per diagnostics report.
MODE: standard, express, auto (default) or a device mode name such as Sensitivity.
SECONDS: how long to run, default 5; exits 1 when no scan came in that time.
Ctrl-C or SIGTERM ends the run early (a second one at once, without stopping the device).";

/// Where the command line points the driver, read before anything is opened.
#[derive(Debug, PartialEq)]
enum Target {
    Help,
    Fake,
    Port(String),
}

/// `-h` / `--help` anywhere asks for the usage. Any other option where PORT goes is refused:
/// taken as a port, it would only be retried, with diagnostics, for the whole run.
fn target(args: &[String]) -> Result<Target, String> {
    if args.iter().any(|a| a == "-h" || a == "--help") {
        return Ok(Target::Help);
    }
    match args.first().map(String::as_str) {
        None => Err("PORT or --fake is required".to_string()),
        Some("--fake") => Ok(Target::Fake),
        Some(option) if option.starts_with('-') => Err(format!("unknown option `{option}`")),
        Some(port) => Ok(Target::Port(port.to_string())),
    }
}

/// A bad command line: the problem and the usage on stderr, exit status 2.
fn refuse(problem: impl std::fmt::Display) -> ! {
    eprintln!("{problem}\n{USAGE}");
    std::process::exit(2);
}

/// One line on stdout; false when it cannot be written (the reader of `| head` has gone).
fn print(line: std::fmt::Arguments) -> bool {
    use std::io::Write;
    writeln!(std::io::stdout().lock(), "{line}").is_ok()
}

/// A flag set by the first SIGINT or SIGTERM (Ctrl-C, `kill`): killed by them, the program
/// would leave the device scanning and a PWM motor turning, as the driver is never dropped.
/// A second signal takes the default action (the way out of a run that does not end).
fn stop_on_signals() -> std::io::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [SIGINT, SIGTERM] {
        // Registered first, so it runs before the flag is set: only a second signal finds it.
        signal_hook::flag::register_conditional_default(signal, Arc::clone(&stop))?;
        signal_hook::flag::register(signal, Arc::clone(&stop))?;
    }
    Ok(stop)
}

/// How a run ended.
struct Outcome {
    scans: u64,
    /// The driver's permanent error (a scan mode the device lacks).
    failure: Option<Error>,
}

/// Prints the driver's scans and reports until `end`, a permanent error, the reader of stdout
/// leaving, or `stop`; it then drops the driver, which stops the device (STOP, then PWM 0 for
/// a motor it started by PWM). `next_event` returns at least once per diagnostics period, so
/// `stop` is seen promptly.
fn dump(mut driver: Driver, end: Instant, stop: &AtomicBool) -> Outcome {
    let mut scans = 0u64;
    let mut reader_gone = false;
    let mut failure = None;
    while Instant::now() < end && !reader_gone && !stop.load(Ordering::Relaxed) {
        let event = match driver.next_event() {
            Ok(event) => event,
            Err(e) => {
                failure = Some(e);
                break;
            }
        };
        match event {
            Event::Scan(scan) => {
                scans += 1;
                let valid: Vec<f32> = scan
                    .ranges
                    .iter()
                    .copied()
                    .filter(|r| r.is_finite())
                    .collect();
                let nearest = valid.iter().copied().fold(f32::INFINITY, f32::min);
                reader_gone |= !print(format_args!(
                    "scan {}.{:09}: {} beams, {} valid, nearest {:.3} m, scan_time {:.1} ms",
                    scan.header.stamp.sec,
                    scan.header.stamp.nanosec,
                    scan.ranges.len(),
                    valid.len(),
                    nearest,
                    scan.scan_time * 1e3
                ));
            }
            Event::Diagnostics(array) => {
                for s in array.status {
                    let values: Vec<String> = s
                        .values
                        .iter()
                        .map(|kv| format!("{}={}", kv.key, kv.value))
                        .collect();
                    reader_gone |= !print(format_args!(
                        "diag level {} {}: {} [{}]",
                        s.level,
                        s.name,
                        s.message,
                        values.join(", ")
                    ));
                }
            }
        }
    }
    drop(driver);
    Outcome { scans, failure }
}

fn main() {
    env_logger::init();
    let args: Vec<String> = std::env::args().skip(1).collect();
    // Arguments first, so that a bad one leaves no fake device or temporary directory behind.
    let (config, rest) = match target(&args) {
        Ok(Target::Help) => {
            print(format_args!("{USAGE}\n{HELP}"));
            return;
        }
        Ok(Target::Fake) => (None, &args[1..]),
        Ok(Target::Port(port)) => {
            let mut config = Config::new(port);
            let mut rest = &args[1..];
            if let Some(baud) = rest.first().and_then(|b| b.parse().ok()) {
                config.baud = baud;
                rest = &rest[1..];
            }
            (Some(config), rest)
        }
        Err(e) => refuse(e),
    };
    let mode = match rest.first().map(|m| m.parse::<ScanModeChoice>()) {
        None => ScanModeChoice::Auto,
        Some(Ok(m)) => m,
        Some(Err(e)) => refuse(e),
    };
    let run = match rest.get(1).map_or(Ok(DEFAULT_RUN), |s| parse_seconds(s)) {
        Ok(run) => run,
        Err(e) => refuse(e),
    };
    // Before anything is opened, so that a signal always finds the handlers.
    let stop = match stop_on_signals() {
        Ok(stop) => stop,
        Err(e) => {
            eprintln!("cannot handle SIGINT and SIGTERM: {e}");
            std::process::exit(1);
        }
    };
    let mut fake_dir = None;
    let mut fake = None;
    let mut config = match config {
        Some(config) => config,
        None => {
            let dir = std::env::temp_dir().join(format!("rplidar-dump-{}", std::process::id()));
            if let Err(e) = std::fs::create_dir_all(&dir) {
                eprintln!("cannot create {}: {e}", dir.display());
                std::process::exit(1);
            }
            let link = dir.join("rplidar");
            fake_dir = Some(dir);
            match FakeLidar::spawn(&link, FakeConfig::default(), SyntheticRoom::default()) {
                Ok(device) => fake = Some(device),
                Err(e) => {
                    eprintln!("cannot start the fake device: {e}");
                    std::process::exit(1);
                }
            }
            Config::new(link.to_string_lossy())
        }
    };
    config.scan_mode = mode;
    let started = Instant::now();
    let driver = match Driver::new(config) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let Outcome { scans, failure } = dump(driver, started + run, &stop);
    drop(fake);
    if let Some(dir) = fake_dir {
        let _ = std::fs::remove_dir(dir);
    }
    // The device lacks what the arguments ask for (a scan mode): a usage error.
    if let Some(e) = failure {
        eprintln!("{e}");
        std::process::exit(2);
    }
    // The driver retries a missing port or a silent device for ever; this check must fail.
    if scans == 0 {
        eprintln!(
            "no scan in {:.1} s: the diagnostics above say why (port, baud, scan mode)",
            started.elapsed().as_secs_f64()
        );
        std::process::exit(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn help_is_asked_for_anywhere_and_no_other_option_is_taken_for_a_port() {
        let target =
            |line: &[&str]| target(&line.iter().map(|a| a.to_string()).collect::<Vec<_>>());
        assert_eq!(target(&["--help"]), Ok(Target::Help));
        assert_eq!(target(&["-h"]), Ok(Target::Help));
        assert_eq!(target(&["--fake", "express", "--help"]), Ok(Target::Help));
        assert_eq!(target(&["--fake", "express"]), Ok(Target::Fake));
        assert_eq!(
            target(&["/dev/ttyUSB0", "115200"]),
            Ok(Target::Port("/dev/ttyUSB0".into()))
        );
        let err = target(&["--port"]).unwrap_err();
        assert!(err.contains("unknown option `--port`"), "{err}");
        assert!(target(&[]).is_err());
    }

    /// The fake's log once `done` holds, or when `limit` has passed.
    fn log_when(
        fake: &FakeLidar,
        limit: Duration,
        done: impl Fn(&lidar_har_rplidar::fake::FakeLog) -> bool,
    ) -> lidar_har_rplidar::fake::FakeLog {
        let deadline = Instant::now() + limit;
        loop {
            let log = fake.log();
            if done(&log) || Instant::now() > deadline {
                return log;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    #[test]
    fn sigint_ends_the_run_with_the_device_and_its_pwm_motor_stopped() {
        // Waits sized for a loaded CI machine; only a run that ignores the signal uses them up.
        const LIMIT: Duration = Duration::from_secs(20);
        let stop = stop_on_signals().unwrap();
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("rplidar");
        let mut info = FakeConfig::default().info;
        info.model = 0x28; // an A2 whose accessory board runs the motor only on PWM
        let fake = FakeLidar::spawn(
            &link,
            FakeConfig {
                info,
                accessory_board_motor: true,
                ..FakeConfig::default()
            },
            SyntheticRoom::default(),
        )
        .unwrap();
        let mut config = Config::new(link.to_string_lossy());
        config.request_timeout = LIMIT;
        config.data_timeout = LIMIT;
        let driver = Driver::new(config).unwrap();
        let (finished, outcome) = std::sync::mpsc::channel();
        let run_stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            let run = dump(driver, Instant::now() + Duration::from_secs(600), &run_stop);
            let _ = finished.send(run.failure.map(|e| e.to_string()));
        });
        let log = log_when(&fake, LIMIT, |l| l.rotations_served >= 3);
        assert_eq!(log.motor_pwm, Some(660), "{log:?}");
        signal_hook::low_level::raise(SIGINT).unwrap();
        let failure = outcome
            .recv_timeout(LIMIT)
            .expect("the run ends at SIGINT, not after its 600 s");
        assert_eq!(failure, None);
        let log = log_when(&fake, LIMIT, |l| l.motor_pwm == Some(0));
        assert_eq!(log.motor_pwm, Some(0), "the motor is switched off: {log:?}");
        assert_eq!(
            log.commands[log.commands.len() - 2..],
            [0x25, 0xF0],
            "STOP, then PWM 0"
        );
    }

    #[test]
    fn seconds_must_be_positive_finite_and_at_most_a_day() {
        assert_eq!(parse_seconds("2.5"), Ok(Duration::from_millis(2500)));
        for bad in ["-1", "0", "inf", "NaN", "1e300", "ten"] {
            let err = parse_seconds(bad).unwrap_err();
            assert!(err.contains(&format!("`{bad}`")), "{err}");
        }
    }
}
