//! Runs the pipeline over a recorded bag, in log-time order, without ROS or threads: the
//! engine of `lidar-har run`. The outputs go into a new rosbag2 directory, with
//! `summary.json` beside them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec2;
use lidar_har_bag::{BagError, BagReader, BagWriter, TopicHandle, WriterOptions};
use lidar_har_core::localiser::{ConfigError, FrameConfig, LocaliserConfig};
use lidar_har_core::map::OccupancyMap;
use lidar_har_core::stats::Spread;
use lidar_har_msgs::geometry_msgs::PoseStamped;
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_msgs::topics::{self, TopicSpec};
use serde::Serialize;

use crate::classifier::{
    ActivitySummary, ClassifierConfig, ClassifierError, ClassifierRun, ClassifierRunError,
    ClassifierStage,
};
use crate::localiser_stage::{MountSource, carries_odometry};
use crate::{LocaliserStage, Outgoing, RoomSource};

/// What to run with.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub config: LocaliserConfig,
    /// A map given on the command line; without one the bag's /map is used, or, when the bag
    /// has none, a background learned from its first scans.
    pub map: Option<OccupancyMap>,
    /// Classifier parameters, model included; `None` runs the localiser only.
    pub classifier: Option<ClassifierConfig>,
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("input bag {}: {cause}", path.display())]
    Input { path: PathBuf, cause: BagError },
    #[error("output bag {}: {cause}", path.display())]
    Output { path: PathBuf, cause: BagError },
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Classifier(#[from] ClassifierError),
    #[error(transparent)]
    ClassifierRun(#[from] ClassifierRunError),
    #[error("input bag {}: no {} topic to localise from (topics: {topics})", path.display(), topics::SCAN.name)]
    NoScans { path: PathBuf, topics: String },
    #[error("cannot write {}: {cause}", path.display())]
    Summary {
        path: PathBuf,
        cause: std::io::Error,
    },
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    pub input: PathBuf,
    /// `map` (a given map or /map) or `learned_background`.
    pub room: &'static str,
    /// `odometry` (a moving robot) or `stationary`.
    pub motion: &'static str,
    /// Where the Lidar's mount on the base came from at the end of the run.
    pub mount: MountSource,
    /// Scans in the bag.
    pub scans: u64,
    /// Scans that gave an output (not skipped, not used for learning).
    pub scans_localised: u64,
    /// Scans used to learn the background.
    pub scans_learning: u64,
    /// Fraction of all scans in which the person was seen.
    pub visible_ratio: f64,
    /// Fraction of all scans with a person track (seen or predicted).
    pub tracked_ratio: f64,
    /// Tracks confirmed over the run: people, or persistent objects not in the map.
    pub tracks_confirmed: u64,
    /// Distance from the estimate to `/ground_truth/human_pose`, when the bag has it.
    pub position_error_m: Option<Spread>,
    /// The same with /human/pelvis in place of /human/pose on the scans the pose head placed
    /// the pelvis on, when it did on any.
    pub pelvis_error_m: Option<Spread>,
    /// Localiser time per scan (core only), microseconds.
    pub scan_time_us: Option<Spread>,
    /// Whole pipeline time per scan (decode, localise, encode outputs), microseconds.
    pub pipeline_time_us: Option<Spread>,
    /// Input problems by kind (the log shows them rate-limited).
    pub warnings: std::collections::BTreeMap<&'static str, u64>,
    /// Messages that could not be decoded, or that carry a negative log time (sqlite3 bags can
    /// hold one; a rosbag2 output cannot), and were skipped.
    pub decode_errors: u64,
    /// Why reading the input stopped before its end (a file cut short, corrupt data); the
    /// outputs cover the messages read before it. `None` when the whole bag was read.
    pub read_error: Option<String>,
    /// The classifier's results (activities, accuracy, alerts), when it ran.
    pub activity: Option<ActivitySummary>,
}

/// The output bag, with a topic for each stage output added to it.
pub(crate) struct OutputBag {
    writer: BagWriter,
    topics: Vec<(&'static str, TopicHandle)>,
}

impl OutputBag {
    fn create(dir: &Path) -> Result<Self, BagError> {
        Ok(Self {
            writer: BagWriter::create(dir, WriterOptions::default())?,
            topics: Vec::new(),
        })
    }

    /// Adds the topics a stage writes; those another stage added already (/human/markers)
    /// are shared.
    pub(crate) fn add_topics(&mut self, specs: &[TopicSpec]) -> Result<(), BagError> {
        for spec in specs {
            if self.topics.iter().all(|(name, _)| *name != spec.name) {
                let handle = self.writer.add_contract_topic(spec)?;
                self.topics.push((spec.name, handle));
            }
        }
        Ok(())
    }

    /// Records a stage's message at `log_time_ns`.
    ///
    /// # Errors
    /// A message for a topic that was not added, or a failed write.
    pub(crate) fn write(&mut self, message: &Outgoing, log_time_ns: i64) -> Result<(), BagError> {
        let Some(&(_, handle)) = self
            .topics
            .iter()
            .find(|(name, _)| *name == message.topic.name)
        else {
            return Err(BagError::Write {
                path: self.writer.dir().to_path_buf(),
                message: format!("{} is not an output topic of this run", message.topic.name),
            });
        };
        self.writer.write(handle, log_time_ns, &message.cdr)
    }

    fn finish(mut self) -> Result<(), BagError> {
        self.writer.finish().map(drop)
    }
}

/// Runs the localiser over the bag at `input`, writing the outputs as a rosbag2 directory
/// `out_dir` (created; it must not hold a bag) and `out_dir/summary.json`.
pub fn run_bag(input: &Path, out_dir: &Path, options: RunOptions) -> Result<RunSummary, RunError> {
    let input_error = |source| RunError::Input {
        path: input.to_path_buf(),
        cause: source,
    };
    let output_error = |source| RunError::Output {
        path: out_dir.to_path_buf(),
        cause: source,
    };
    let reader = BagReader::open(input).map_err(input_error)?;
    // A file cut short may not list its topics; reading it says what is wrong instead.
    if reader.topic(topics::SCAN.name).is_none() && !reader.metadata().truncated {
        let names: Vec<&str> = reader.topics().iter().map(|t| t.name.as_str()).collect();
        return Err(RunError::NoScans {
            path: input.to_path_buf(),
            topics: if names.is_empty() {
                "none".into()
            } else {
                names.join(", ")
            },
        });
    }
    let has_odometry = reader.topic(topics::ODOM.name).is_some()
        || tf_carries_odometry(&reader, &options.config.frames);
    let room = match options.map {
        Some(map) => RoomSource::Map(map),
        None if reader.topic(topics::MAP.name).is_some() => RoomSource::MapTopic,
        None => RoomSource::LearnedBackground,
    };
    let learned = matches!(room, RoomSource::LearnedBackground);
    if learned && has_odometry {
        log::warn!(
            "{}: no map, so the background is learned; it assumes the Lidar does not move",
            input.display()
        );
    }
    let moving = has_odometry && !learned;
    let mut localiser = LocaliserStage::new(options.config, room, moving)?;
    let mut classifier = options
        .classifier
        .as_ref()
        .map(ClassifierRun::load)
        .transpose()?;
    let mut outputs = OutputBag::create(out_dir).map_err(output_error)?;
    outputs
        .add_topics(&LocaliserStage::OUTPUTS)
        .map_err(output_error)?;
    if classifier.is_some() {
        outputs
            .add_topics(&ClassifierStage::OUTPUTS)
            .map_err(output_error)?;
    }

    let mut scans = 0u64;
    let mut scans_localised = 0u64;
    let mut visible = 0u64;
    let mut tracked = 0u64;
    let mut decode_errors = 0u64;
    let mut scan_times = Vec::new();
    let mut pipeline_times = Vec::new();
    let mut estimates: Vec<(i64, DVec2)> = Vec::new();
    let mut ground_truth: Vec<(i64, DVec2)> = Vec::new();

    let mut read_error = None;
    for message in reader.messages().map_err(input_error)? {
        let message = match message {
            Ok(message) => message,
            Err(e) => {
                // Keep what was read: finish the outputs and the summary, then report it.
                read_error = Some(e.to_string());
                break;
            }
        };
        let topic = &*message.topic;
        if message.log_time_ns < 0 {
            // Its outputs could not be written: skipped, rather than ending the whole run.
            decode_errors += 1;
            log::warn!(
                "{topic} skipped: negative log time {} ns",
                message.log_time_ns
            );
            continue;
        }
        if classifier
            .as_mut()
            .is_some_and(|c| c.on_input(topic, &message.data))
        {
            continue;
        }
        if topic == topics::GROUND_TRUTH_POSE.name {
            match lidar_har_msgs::decode::<PoseStamped>(&message.data) {
                Ok(gt) => ground_truth.push((
                    gt.header.stamp.to_nanos(),
                    DVec2::new(gt.pose.position.x, gt.pose.position.y),
                )),
                Err(e) => {
                    decode_errors += 1;
                    log::warn!("{topic} at {} ns skipped: {e}", message.log_time_ns);
                }
            }
            continue;
        }
        if !LocaliserStage::consumes(topic) {
            continue;
        }
        let is_scan = topic == topics::SCAN.name;
        scans += u64::from(is_scan);
        let started = Instant::now();
        let step = match localiser.handle(topic, &message.data) {
            Ok(step) => step,
            Err(e) => {
                decode_errors += 1;
                log::warn!("skipped at {} ns: {e}", message.log_time_ns);
                continue;
            }
        };
        if is_scan {
            pipeline_times.push(started.elapsed().as_secs_f64() * 1e6);
            if let Some(t) = localiser.last_scan_time() {
                scan_times.push(t.as_secs_f64() * 1e6);
            }
        }
        if let Some(output) = &step.localised {
            scans_localised += 1;
            if let Some(person) = &output.person {
                tracked += 1;
                visible += u64::from(person.visible);
                estimates.push((output.stamp_ns, person.position));
            }
        }
        for out in &step.outgoing {
            if let Some(c) = classifier.as_mut() {
                c.on_localiser_output(out, message.log_time_ns, &mut outputs)?;
            }
            outputs
                .write(out, message.log_time_ns)
                .map_err(output_error)?;
        }
    }
    outputs.finish().map_err(output_error)?;

    let ratio = |n: u64| {
        if scans == 0 {
            0.0
        } else {
            n as f64 / scans as f64
        }
    };
    let summary = RunSummary {
        input: input.to_path_buf(),
        room: if learned { "learned_background" } else { "map" },
        motion: if moving { "odometry" } else { "stationary" },
        scans,
        scans_localised,
        mount: localiser.mount_source(),
        scans_learning: localiser.scans_learning(),
        visible_ratio: ratio(visible),
        tracked_ratio: ratio(tracked),
        tracks_confirmed: localiser.localiser().confirmed_tracks(),
        pelvis_error_m: classifier
            .as_ref()
            .filter(|c| !c.pelvis().is_empty())
            .and_then(|c| {
                let placed = with_pelvis(&estimates, c.pelvis());
                Spread::of(position_errors(&placed, ground_truth.clone()))
            }),
        position_error_m: Spread::of(position_errors(&estimates, ground_truth)),
        scan_time_us: Spread::of(scan_times),
        pipeline_time_us: Spread::of(pipeline_times),
        warnings: localiser.warning_counts().clone(),
        decode_errors,
        read_error,
        activity: classifier.map(ClassifierRun::finish),
    };
    let path = out_dir.join("summary.json");
    let json = serde_json::to_string_pretty(&summary).expect("the summary is plain data");
    std::fs::write(&path, json + "\n").map_err(|cause| RunError::Summary { path, cause })?;
    Ok(summary)
}

/// /tf messages looked at for `odom -> base_link` before deciding the bag has no odometry.
const TF_MESSAGES_TO_PROBE: usize = 100;

/// Whether the bag's /tf carries the odometry transform (a base that publishes no /odom).
fn tf_carries_odometry(reader: &BagReader, frames: &FrameConfig) -> bool {
    let Ok(messages) = reader.messages_on(&[topics::TF.name]) else {
        return false;
    };
    messages
        .take(TF_MESSAGES_TO_PROBE)
        .map_while(Result::ok)
        .any(|m| {
            lidar_har_msgs::decode::<TFMessage>(&m.data)
                .is_ok_and(|tf| carries_odometry(&tf, frames))
        })
}

/// `estimates` with the pelvis in place of the position on the scans (same stamp) that have one.
fn with_pelvis(estimates: &[(i64, DVec2)], pelvis: &[(i64, DVec2)]) -> Vec<(i64, DVec2)> {
    let placed: std::collections::HashMap<i64, DVec2> = pelvis.iter().copied().collect();
    estimates
        .iter()
        .map(|&(stamp, position)| (stamp, placed.get(&stamp).copied().unwrap_or(position)))
        .collect()
}

/// Ground truth samples farther apart than this are not interpolated between.
const MAX_TRUTH_GAP_NS: i64 = 200_000_000;
/// An estimate this close in time to a lone ground truth sample is compared with it.
const MAX_TRUTH_OFFSET_NS: i64 = 30_000_000;

/// The distance of each estimate from the ground truth at its stamp (interpolated), for the
/// estimates that have ground truth around them.
pub fn position_errors(estimates: &[(i64, DVec2)], mut truth: Vec<(i64, DVec2)>) -> Vec<f64> {
    truth.sort_by_key(|&(t, _)| t);
    estimates
        .iter()
        .filter_map(|&(stamp, estimate)| {
            let i = truth.partition_point(|&(t, _)| t < stamp);
            let after = truth.get(i);
            let before = i.checked_sub(1).and_then(|j| truth.get(j));
            let at = match (before, after) {
                (_, Some(&(t, p))) if t == stamp => p,
                (Some(&(ta, pa)), Some(&(tb, pb))) if tb - ta <= MAX_TRUTH_GAP_NS => {
                    pa.lerp(pb, (stamp - ta) as f64 / (tb - ta) as f64)
                }
                (Some(&(t, p)), _) | (_, Some(&(t, p)))
                    if (stamp - t).abs() <= MAX_TRUTH_OFFSET_NS =>
                {
                    p
                }
                _ => return None,
            };
            Some(estimate.distance(at))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ground_truth_is_interpolated_at_the_estimate_stamp() {
        let truth = vec![(100_000_000, DVec2::new(1.0, 0.0)), (0, DVec2::ZERO)];
        let errors = position_errors(
            &[
                (50_000_000, DVec2::new(0.5, 0.0)),
                (100_000_000, DVec2::new(1.0, 1.0)),
                (900_000_000, DVec2::ZERO),
            ],
            truth,
        );
        assert_eq!(errors.len(), 2);
        assert!(errors[0].abs() < 1e-12);
        assert!((errors[1] - 1.0).abs() < 1e-12);
    }
}
