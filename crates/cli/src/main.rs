//! `lidar-har`: the lidar_har pipeline without ROS 2 — simulate, record, replay, run,
//! evaluate and inspect. Each subcommand lives in its own module under `cmd/`, thin over the
//! library crates.

use std::process::ExitCode;

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
        Command::Bag(c) => cmd::bag::run(c),
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Run(a) => cmd::run::run(a),
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
