//! `lidar-har`: the lidar_har pipeline without ROS 2 — simulate, record, replay, run,
//! evaluate and inspect. Each subcommand lives in its own module under `cmd/`, thin over the
//! library crates.

use std::process::ExitCode;
use std::sync::atomic::{AtomicI32, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{Parser, Subcommand};
use lidar_har_pipeline::bag_run::StopRequest;

#[macro_use]
mod stdout;
mod cmd;

#[derive(Parser)]
#[command(name = "lidar-har", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Inspect and convert rosbag2 directories (MCAP and sqlite3).
    #[command(subcommand)]
    Bag(cmd::bag::BagCommand),
    /// Simulate a scene and record it as a rosbag2 directory.
    Simulate(cmd::simulate::SimulateArgs),
    /// Run the embedded pipeline (localiser, classifier, alerts) over a bag.
    Run(cmd::run::RunArgs),
    /// Write random furnished rooms as scene files (more rooms to train on).
    RandomScenes(cmd::random_scenes::RandomScenesArgs),
    /// Make a labelled training/test dataset from simulated episodes.
    Dataset(cmd::dataset::DatasetArgs),
    /// Evaluate a model on a dataset against the paper's tables.
    Evaluate(cmd::evaluate::EvaluateArgs),
    /// Measure the fall alerts end to end: latency after falls, false alerts without falls.
    Alerts(cmd::alerts::AlertsArgs),
    /// The embedded demo: simulate a fall in the default scene, detect it, show the result.
    Demo(cmd::demo::DemoArgs),
    /// List and echo ROS 2 topics over DDS, without ROS 2 installed.
    #[command(subcommand)]
    Topic(cmd::topic::TopicCommand),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bag(c) => stop_on_signal().and_then(|stop| cmd::bag::run(c, &stop)),
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Run(a) => stop_on_signal().and_then(|stop| cmd::run::run(a, stop)),
        Command::RandomScenes(a) => cmd::random_scenes::run(a),
        Command::Dataset(a) => stop_on_signal().and_then(|stop| cmd::dataset::run(a, &stop)),
        Command::Evaluate(a) => cmd::evaluate::run(a),
        Command::Alerts(a) => cmd::alerts::run(a),
        Command::Demo(a) => cmd::demo::run(a),
        Command::Topic(c) => cmd::topic::run(c),
    };
    if let Err(err) = &result {
        errln!("lidar-har: error: {err:#}");
    }
    match STOP_SIGNAL.load(Ordering::SeqCst) {
        0 => {}
        signal => {
            let _ = std::io::Write::flush(&mut std::io::stdout());
            end_by(signal)
        }
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(_) => ExitCode::FAILURE,
    }
}

/// The SIGINT or SIGTERM that asked the command to stop; 0 until one comes.
static STOP_SIGNAL: AtomicI32 = AtomicI32::new(0);

/// For commands that read bags given by the user (`run`, `bag`), and `dataset`: once the
/// command writes its outputs message by message or episode by episode
/// ([`StopRequest::arm`]), the first SIGINT (Ctrl-C) or SIGTERM asks it to stop at the next
/// one, so that it finishes the bag it writes (a bag left without its MCAP footer is refused
/// by other readers) and `run` its `summary.json`, or `dataset` removes its scratch arrays
/// (gigabytes for a training set) and leaves the dataset already there whole; the process
/// then ends by that signal (the shell sees 130 or 143). Before that (opening a
/// large bag, scanning one cut short, `bag info`) the signal ends the process at once. Either
/// way it deletes the bag reader's temporary copies (a storage file rosbag2 compressed whole,
/// `.zstd`, is read from a decompressed copy in $TMPDIR as large as the file uncompressed),
/// which also stops a decompression under way: a process ended by a signal runs no
/// destructors. A second signal ends the process at once (the same signal again within
/// `REPEAT_GRACE` is not a second). A signal the process started with ignored (a background
/// job of a script) stays ignored. Not for `topic echo`, which turns both signals into a
/// clean stop of its own.
fn stop_on_signal() -> anyhow::Result<StopRequest> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let handled = [SIGINT, SIGTERM].into_iter().filter(|&s| !ignored(s));
    let mut signals =
        signal_hook::iterator::Signals::new(handled).context("cannot install signal handler")?;
    let stop = StopRequest::default();
    let request = stop.clone();
    std::thread::spawn(move || {
        let mut received = signals.forever();
        if let Some(signal) = received.next() {
            // Stored first: a command that finishes meanwhile still ends by the signal.
            STOP_SIGNAL.store(signal, Ordering::SeqCst);
            if !request.is_armed() {
                end_by(signal);
            }
            let name = signal_hook::low_level::signal_name(signal).unwrap_or("a signal");
            // Asked before the copies go, so that a read they break is put down to it.
            request.request(format!("interrupted by {name}"));
            lidar_har_bag::remove_temporary_copies();
        }
        // The same signal again within a second is the same request: one sender may deliver
        // it twice (coreutils `timeout` signals the process and its process group).
        let first_at = Instant::now();
        let first = STOP_SIGNAL.load(Ordering::SeqCst);
        for signal in received {
            if signal != first || first_at.elapsed() >= REPEAT_GRACE {
                end_by(signal);
            }
        }
    });
    Ok(stop)
}

/// How long a repeat of the first signal counts as the same request.
const REPEAT_GRACE: Duration = Duration::from_secs(1);

/// Ends the process by `signal`, its default action, as if it had not been handled.
fn end_by(signal: i32) -> ! {
    lidar_har_bag::remove_temporary_copies();
    let _ = signal_hook::low_level::emulate_default_handler(signal);
    std::process::exit(128 + signal);
}

fn ignored(signal: i32) -> bool {
    use nix::libc;
    // SAFETY: an all-zero `sigaction` is a valid value, and a null new action makes
    // `sigaction` only read the current one into it.
    unsafe {
        let mut current: libc::sigaction = std::mem::zeroed();
        libc::sigaction(signal, std::ptr::null(), &mut current) == 0
            && current.sa_sigaction == libc::SIG_IGN
    }
}
