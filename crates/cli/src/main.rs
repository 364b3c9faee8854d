//! `lidar-har`: the lidar_har pipeline without ROS 2 — simulate, record, replay, run,
//! evaluate and inspect. Each subcommand lives in its own module under `cmd/`, thin over the
//! library crates.

use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};

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
        Command::Bag(c) => remove_bag_copies_on_signal().and_then(|()| cmd::bag::run(c)),
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Run(a) => remove_bag_copies_on_signal().and_then(|()| cmd::run::run(a)),
        Command::RandomScenes(a) => cmd::random_scenes::run(a),
        Command::Dataset(a) => cmd::dataset::run(a),
        Command::Evaluate(a) => cmd::evaluate::run(a),
        Command::Alerts(a) => cmd::alerts::run(a),
        Command::Demo(a) => cmd::demo::run(a),
        Command::Topic(c) => cmd::topic::run(c),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            errln!("lidar-har: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

/// For commands that read bags given by the user: a storage file rosbag2 compressed whole
/// (`.zstd`) is read from a decompressed copy in $TMPDIR, as large as the file uncompressed,
/// which only the reader's destructor deletes, and a process ended by SIGINT (Ctrl-C) or
/// SIGTERM runs none. A thread waits for either, deletes the copies, and ends the process by
/// that same signal, as it ended before (the shell sees 130 or 143). A signal the process
/// started with ignored (a background job of a script) stays ignored. Not for `topic echo`,
/// which turns both signals into a clean stop of its own.
fn remove_bag_copies_on_signal() -> anyhow::Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let handled = [SIGINT, SIGTERM].into_iter().filter(|&s| !ignored(s));
    let mut signals =
        signal_hook::iterator::Signals::new(handled).context("cannot install signal handler")?;
    std::thread::spawn(move || {
        if let Some(signal) = signals.forever().next() {
            lidar_har_bag::remove_temporary_copies();
            let _ = signal_hook::low_level::emulate_default_handler(signal);
            std::process::exit(128 + signal);
        }
    });
    Ok(())
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
