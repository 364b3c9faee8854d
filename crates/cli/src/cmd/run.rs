//! `lidar-har run`: the embedded pipeline over a recorded bag (the work is in
//! `lidar_har_pipeline::bag_run`).

use std::path::PathBuf;

use anyhow::Context;
use lidar_har_bag::MetadataVersion;
use lidar_har_pipeline::bag_run::{RunOptions, StopRequest, run_bag};
use lidar_har_pipeline::files;

#[derive(clap::Args)]
pub struct RunArgs {
    /// Input rosbag2 directory (MCAP or sqlite3) with /scan and, on a robot, /odom, /tf, /map.
    #[arg(long)]
    pub bag: PathBuf,
    /// Output directory: a rosbag2 bag of /human/pose, /human/observation, /human/markers,
    /// /human/activity, /human/fall_alert and, with a pose head, /human/pelvis, plus
    /// summary.json. Must not already hold a bag.
    #[arg(long)]
    pub out: PathBuf,
    /// map_server map (YAML naming a PGM, PNG or BMP image). Without it: the bag's /map, or else a
    /// background learned from the first scans (fixed Lidar).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Localiser parameters (YAML, see config/localiser.yaml); defaults are the paper's.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Activity model (ONNX step model, docs/model_contract.md) for /human/activity and
    /// /human/fall_alert, else the classifier configuration's `model` [default:
    /// models/activity.onnx; when that is absent and neither --model nor
    /// --classifier-config is given, the localiser runs alone, with a warning].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Classifier parameters (YAML, see config/classifier.yaml).
    #[arg(long)]
    pub classifier_config: Option<PathBuf>,
    /// Run the localiser only (no model needed).
    #[arg(long, conflicts_with_all = ["model", "classifier_config"])]
    pub no_classifier: bool,
    /// rosbag2 metadata version of the output bag: 9 (read by Jazzy and later) or 8 (read by
    /// Humble, Iron and later; use it for a Humble or Iron robot, whose `ros2 bag info` and
    /// `play` cannot parse 9; the bag is MCAP, which needs ros-humble-rosbag2-storage-mcap
    /// there, or `lidar-har bag convert OUT OUT_DB3 --storage sqlite3`). Default: 8 when the
    /// input was written before Jazzy (metadata.yaml version 8 or older: Humble writes 5, Iron
    /// 8; or, without metadata.yaml, what its storage files record), else 9.
    #[arg(long, value_parser = super::parse_metadata_version)]
    pub rosbag2_version: Option<MetadataVersion>,
}

/// Runs the pipeline; `stop` (a signal) ends the reading early, as a bag cut short does.
pub fn run(args: RunArgs, stop: StopRequest) -> anyhow::Result<()> {
    let _ = env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn"))
        .try_init();
    let config = match &args.config {
        Some(path) => files::load_localiser_config(path).context("--config")?,
        None => Default::default(),
    };
    let map = args
        .map
        .as_deref()
        .map(files::load_map)
        .transpose()
        .context("--map")?;
    let classifier = if args.no_classifier {
        None
    } else {
        let classifier =
            super::classifier_config(args.classifier_config.as_deref(), args.model.as_deref())?;
        // A model named on the command line or in a classifier configuration must exist.
        let explicit = args.model.is_some() || args.classifier_config.is_some();
        if classifier.model.is_file() {
            Some(classifier)
        } else {
            // The configuration's `model` (named there or its default) is fixed there.
            let source = match (&args.model, &args.classifier_config) {
                (None, Some(config)) => format!(
                    ", the `model` of --classifier-config {}: fix it there,",
                    config.display()
                ),
                _ => ":".into(),
            };
            anyhow::ensure!(
                !explicit,
                "no activity model at {}{source} pass an existing --model FILE, train one \
                 (training/, see docs/classifier.md), or run the localiser alone with \
                 --no-classifier",
                super::shown_path(&classifier.model)
            );
            errln!(
                "lidar-har: warning: no activity model at {}: running the localiser only (train \
                 one, see docs/classifier.md, or pass --model FILE; --no-classifier silences this)",
                super::shown_path(&classifier.model)
            );
            None
        }
    };
    let options = RunOptions {
        config,
        map,
        classifier,
        stop,
        metadata_version: args.rosbag2_version,
    };
    let summary = run_bag(&args.bag, &args.out, options)
        .with_context(|| format!("running the pipeline over {}", args.bag.display()))?;
    outln!("{}", serde_json::to_string_pretty(&summary)?);
    errln!(
        "wrote {} (bag) and {}",
        args.out.display(),
        args.out.join("summary.json").display()
    );
    if let Some(error) = &summary.read_error {
        anyhow::bail!(
            "input bag {}: reading stopped early ({error}); the outputs cover the {} scans read",
            args.bag.display(),
            summary.scans
        );
    }
    Ok(())
}
