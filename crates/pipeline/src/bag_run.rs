//! Runs the pipeline over a recorded bag, in log-time order, without ROS or threads: the
//! engine of `lidar-har run`. The outputs go into a new rosbag2 directory, with
//! `summary.json` beside them.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use glam::DVec2;
use lidar_har_bag::{
    BagError, BagMessage, BagReader, BagWriter, MetadataVersion, TopicHandle, WriterOptions,
};
use lidar_har_core::localiser::{ConfigError, FrameConfig, LocaliserConfig};
use lidar_har_core::map::OccupancyMap;
use lidar_har_core::stats::{Spread, SpreadTally};
use lidar_har_core::truth_match::{Around, TruthMatcher};
use lidar_har_msgs::geometry_msgs::PoseStamped;
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_msgs::topics::{self, TopicSpec};
use serde::Serialize;

use crate::classifier::{
    ActivitySummary, ClassifierConfig, ClassifierError, ClassifierRun, ClassifierRunError,
    ClassifierStage,
};
use crate::localiser_stage::{MountSource, carries_transform};
use crate::{LocaliserStage, Outgoing, PipelineError, RoomSource, Step};

/// What to run with.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub config: LocaliserConfig,
    /// A map given on the command line; without one the bag's /map is used, or, when the bag
    /// has none, a background learned from its first scans.
    pub map: Option<OccupancyMap>,
    /// Classifier parameters, model included; `None` runs the localiser only.
    pub classifier: Option<ClassifierConfig>,
    /// Asks the run to stop reading its input (a signal): it then finishes as at a bag cut
    /// short, with the outputs and `summary.json` of what was read.
    pub stop: StopRequest,
    /// The output bag's metadata version; `None` takes one the input's readers parse
    /// ([`MetadataVersion::like_source`]), so that a Humble recording gives a bag Humble reads.
    pub metadata_version: Option<MetadataVersion>,
}

/// A request, made from another thread (a signal handler's), that a run stop reading its
/// input at the next message and finish its outputs; it says why, for `read_error`.
#[derive(Debug, Clone, Default)]
pub struct StopRequest(Arc<StopState>);

#[derive(Debug, Default)]
struct StopState {
    armed: AtomicBool,
    reason: OnceLock<String>,
}

impl StopRequest {
    /// Asks the run to stop, saying why; a later request keeps the first reason.
    pub fn request(&self, reason: impl Into<String>) {
        let _ = self.0.reason.set(reason.into());
    }

    /// Why the run was asked to stop, if it was.
    pub fn reason(&self) -> Option<&str> {
        self.0.reason.get().map(String::as_str)
    }

    /// Says that the run is about to write outputs and then read its input message by
    /// message, where it looks at the request. Before that (opening a large bag, scanning one
    /// cut short) a requester had better end the process at once.
    pub fn arm(&self) {
        self.0.armed.store(true, Ordering::SeqCst);
    }

    /// Whether [`StopRequest::arm`] was called.
    pub fn is_armed(&self) -> bool {
        self.0.armed.load(Ordering::SeqCst)
    }
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
    #[error("input bag {}: no {} messages to localise from (topics and their message counts: {topics})", path.display(), topics::SCAN.name)]
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
    #[serde(serialize_with = "path_as_text")]
    pub input: PathBuf,
    /// `map_file` (a map given with the run), `map_topic` (the bag's /map) or
    /// `learned_background`.
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
    /// Why reading the input stopped before its end (a file cut short, corrupt data, a
    /// signal); the outputs cover the messages read before it. `None` when the whole bag
    /// was read.
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
    fn create(dir: &Path, metadata_version: MetadataVersion) -> Result<Self, BagError> {
        let options = WriterOptions {
            metadata_version,
            ..WriterOptions::default()
        };
        Ok(Self {
            writer: BagWriter::create(dir, options)?,
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
    let reader = open_input(input)?;
    let transforms = BagTransforms::find(&reader, &options.config.frames);
    let (room, moving, odometry_unused) = choose_room(&reader, input, options.map, transforms);
    let room_name = room.name();
    // From here a stop is honoured at the first message, outputs finished, even one that
    // comes while they are being made.
    options.stop.arm();
    let metadata_version = options
        .metadata_version
        .unwrap_or_else(|| MetadataVersion::like_source(reader.recorded_version().as_ref()));
    let mut stages = Stages::start(
        out_dir,
        metadata_version,
        options.config,
        room,
        moving,
        transforms,
        options.classifier.as_ref(),
    )?;
    let tally = replay(&reader, input, out_dir, &mut stages, &options.stop)?;
    let Stages {
        localiser,
        classifier,
        outputs,
    } = stages;
    outputs.finish().map_err(output_error(out_dir))?;
    let mut summary = summarise(input, room_name, moving, tally, &localiser, classifier);
    if odometry_unused {
        summary.warnings.insert(ODOMETRY_WITHOUT_MAP, summary.scans);
    }
    write_summary(out_dir, &summary)?;
    Ok(summary)
}

fn input_error(input: &Path) -> impl FnOnce(BagError) -> RunError + '_ {
    move |cause| RunError::Input {
        path: input.to_path_buf(),
        cause,
    }
}

fn output_error(out_dir: &Path) -> impl FnOnce(BagError) -> RunError + '_ {
    move |cause| RunError::Output {
        path: out_dir.to_path_buf(),
        cause,
    }
}

/// Opens the input bag; one without scans (no /scan, or one declared with no message, as
/// `ros2 bag record -a` leaves it when the Lidar is silent) is refused before any output is
/// made.
fn open_input(input: &Path) -> Result<BagReader, RunError> {
    let reader = BagReader::open(input).map_err(input_error(input))?;
    // A file cut short counts only what comes before the cut; reading it up to there says
    // what is wrong instead.
    if !has_messages(&reader, topics::SCAN.name) && !reader.metadata().truncated {
        let counts: Vec<String> = reader
            .topics()
            .iter()
            .map(|t| format!("{} ({})", t.name, t.message_count))
            .collect();
        return Err(RunError::NoScans {
            path: input.to_path_buf(),
            topics: if counts.is_empty() {
                "none".into()
            } else {
                counts.join(", ")
            },
        });
    }
    Ok(reader)
}

/// `summary.json`'s warning, counting every scan, when the bag has odometry but no map: a
/// clip cut after the recording's only /map (`bag convert --start-offset`), or a robot
/// recorded without its map. The run then learns a background, which assumes the Lidar does
/// not move; it used to say so only in the log.
const ODOMETRY_WITHOUT_MAP: &str = "odometry_without_map";

/// Where the room comes from, whether the Lidar moves in it (only with odometry and a map,
/// since a learned background is in the Lidar's own frame), and whether odometry is there
/// but unused for want of a map.
fn choose_room(
    reader: &BagReader,
    input: &Path,
    map: Option<OccupancyMap>,
    transforms: BagTransforms,
) -> (RoomSource, bool, bool) {
    let has_odometry = has_messages(reader, topics::ODOM.name) || transforms.tf_odometry;
    let room = match map {
        Some(map) => RoomSource::Map(map),
        None if has_messages(reader, topics::MAP.name) => RoomSource::MapTopic,
        None => RoomSource::LearnedBackground,
    };
    let learned = matches!(room, RoomSource::LearnedBackground);
    if learned && has_odometry {
        log::warn!(
            "{}: odometry but no map, so the background is learned; it assumes the Lidar does \
             not move: give the robot's map with --map",
            input.display()
        );
    }
    (room, has_odometry && !learned, learned && has_odometry)
}

/// Whether the bag holds messages on `topic`: `ros2 bag record -a` also declares topics it
/// discovered but got nothing on.
fn has_messages(reader: &BagReader, topic: &str) -> bool {
    reader.topic(topic).is_some_and(|t| t.message_count > 0)
}

/// The stages a run feeds, and the bag their outputs go into.
struct Stages {
    localiser: LocaliserStage,
    classifier: Option<ClassifierRun>,
    outputs: OutputBag,
}

impl Stages {
    /// Loads the stages before creating the output bag, so that a bad configuration or
    /// model leaves no output behind.
    fn start(
        out_dir: &Path,
        metadata_version: MetadataVersion,
        config: LocaliserConfig,
        room: RoomSource,
        moving: bool,
        transforms: BagTransforms,
        classifier: Option<&ClassifierConfig>,
    ) -> Result<Self, RunError> {
        let mut localiser = LocaliserStage::new(config, room, moving)?;
        // As tf2 would: the bag says ahead which transforms will come.
        if transforms.tf_odometry {
            localiser.take_odometry_from_tf();
        }
        localiser.set_wait_for_map_to_odom(transforms.map_to_odom);
        let classifier = classifier.map(ClassifierRun::load).transpose()?;
        let mut outputs =
            OutputBag::create(out_dir, metadata_version).map_err(output_error(out_dir))?;
        outputs
            .add_topics(&LocaliserStage::OUTPUTS)
            .map_err(output_error(out_dir))?;
        if classifier.is_some() {
            outputs
                .add_topics(&ClassifierStage::OUTPUTS)
                .map_err(output_error(out_dir))?;
        }
        Ok(Self {
            localiser,
            classifier,
            outputs,
        })
    }

    /// Hands one message to whatever takes it (classifier, ground truth, localiser); other
    /// topics are ignored.
    fn feed(
        &mut self,
        message: &BagMessage,
        out_dir: &Path,
        tally: &mut Tally,
    ) -> Result<(), RunError> {
        let topic = &*message.topic;
        if message.log_time_ns < 0 {
            // Its outputs could not be written: skipped, rather than ending the whole run.
            tally.skip(format_args!(
                "{topic} skipped: negative log time {} ns",
                message.log_time_ns
            ));
            return Ok(());
        }
        // Scans whose wait for odometry ran out before this message go first, whatever it is,
        // as on a node's clock.
        let expired = self.localiser.release_expired(message.log_time_ns);
        self.record(expired, message.log_time_ns, out_dir, tally)?;
        if let Some(taken) = self
            .classifier
            .as_mut()
            .and_then(|c| c.on_input(topic, &message.data))
        {
            if let Err(e) = taken {
                tally.skip(format_args!(
                    "{topic} at {} ns skipped: {e}",
                    message.log_time_ns
                ));
            }
            return Ok(());
        }
        if topic == topics::GROUND_TRUTH_POSE.name {
            tally.add_ground_truth(message);
            return Ok(());
        }
        if !LocaliserStage::consumes(topic) {
            return Ok(());
        }
        self.localise(message, out_dir, tally)
    }

    /// Feeds one of the localiser's inputs to it.
    fn localise(
        &mut self,
        message: &BagMessage,
        out_dir: &Path,
        tally: &mut Tally,
    ) -> Result<(), RunError> {
        let topic = &*message.topic;
        tally.scans += u64::from(topic == topics::SCAN.name);
        let step = self
            .localiser
            .handle(topic, &message.data, message.log_time_ns);
        self.record(step, message.log_time_ns, out_dir, tally)
    }

    /// Tallies the scans the localiser went through and writes what it publishes at
    /// `log_time_ns`, each message after the classifier has seen it (its own outputs go
    /// first); a message it could not use is counted as skipped.
    fn record(
        &mut self,
        step: Result<Step, PipelineError>,
        log_time_ns: i64,
        out_dir: &Path,
        tally: &mut Tally,
    ) -> Result<(), RunError> {
        let step = match step {
            Ok(step) => step,
            Err(e) => {
                tally.skip(format_args!("skipped at {log_time_ns} ns: {e}"));
                return Ok(());
            }
        };
        let mut estimates = Vec::new();
        for scan in &step.scans {
            tally
                .pipeline_times
                .record(scan.pipeline_time.as_secs_f64() * 1e6);
            if let Some(time) = scan.localise_time {
                tally.scan_times.record(time.as_secs_f64() * 1e6);
            }
            if let Some(output) = &scan.output {
                tally.scans_localised += 1;
                if let Some(person) = &output.person {
                    tally.tracked += 1;
                    tally.visible += u64::from(person.visible);
                    estimates.push((output.stamp_ns, person.position));
                }
            }
        }
        for out in &step.outgoing {
            if let Some(c) = self.classifier.as_mut() {
                c.on_localiser_output(out, log_time_ns, &mut self.outputs)?;
            }
            self.outputs
                .write(out, log_time_ns)
                .map_err(output_error(out_dir))?;
        }
        // The pose head placed the pelvis while the classifier took this step's observations.
        let pelvis = self
            .classifier
            .as_mut()
            .map(ClassifierRun::take_pelvis)
            .unwrap_or_default();
        for (stamp_ns, position) in estimates {
            let pelvis = pelvis
                .iter()
                .find(|&&(t, _)| t == stamp_ns)
                .map(|&(_, p)| p);
            tally.errors.add_estimate(stamp_ns, position, pelvis);
        }
        Ok(())
    }
}

/// Feeds the bag's messages to the stages in log-time order, up to its end, the first
/// message that cannot be read, or a request to stop.
fn replay(
    reader: &BagReader,
    input: &Path,
    out_dir: &Path,
    stages: &mut Stages,
    stop: &StopRequest,
) -> Result<Tally, RunError> {
    let mut tally = Tally::default();
    let mut last_log_time_ns = 0;
    for message in reader.messages().map_err(input_error(input))? {
        // Before the message: what stops the run (a signal) may also have made it unreadable.
        if let Some(reason) = stop.reason() {
            tally.read_error = Some(reason.to_string());
            break;
        }
        match message {
            Ok(message) => {
                stages.feed(&message, out_dir, &mut tally)?;
                last_log_time_ns = last_log_time_ns.max(message.log_time_ns);
            }
            Err(e) => {
                // Keep what was read: finish the outputs and the summary, then report it.
                tally.read_error = Some(e.to_string());
                break;
            }
        }
    }
    // Scans still waiting for odometry are localised with what there is, not lost.
    let left = stages.localiser.finish();
    stages.record(left, last_log_time_ns, out_dir, &mut tally)?;
    Ok(tally)
}

/// What a run counts and collects over the messages for its summary.
struct Tally {
    scans: u64,
    scans_localised: u64,
    visible: u64,
    tracked: u64,
    decode_errors: u64,
    scan_times: SpreadTally,
    pipeline_times: SpreadTally,
    errors: PositionErrors,
    read_error: Option<String>,
}

impl Default for Tally {
    fn default() -> Self {
        Self {
            scans: 0,
            scans_localised: 0,
            visible: 0,
            tracked: 0,
            decode_errors: 0,
            scan_times: SpreadTally::with_steps_per_unit(STEPS_PER_US),
            pipeline_times: SpreadTally::with_steps_per_unit(STEPS_PER_US),
            errors: PositionErrors::default(),
            read_error: None,
        }
    }
}

/// Times per scan are resolved to a nanosecond.
const STEPS_PER_US: f64 = 1e3;
/// Position errors are resolved to a micrometre.
const STEPS_PER_M: f64 = 1e6;

/// Messages skipped that are logged one by one; the rest are only counted.
const SKIPS_LOGGED: u64 = 10;

impl Tally {
    /// Counts a message that could not be used, and logs the first few: a bag broken
    /// throughout would otherwise bury the log.
    fn skip(&mut self, why: std::fmt::Arguments) {
        self.decode_errors += 1;
        if self.decode_errors <= SKIPS_LOGGED {
            log::warn!("{why}");
        }
        if self.decode_errors == SKIPS_LOGGED {
            log::warn!(
                "further messages skipped are not logged; summary.json counts them (decode_errors)"
            );
        }
    }

    /// Keeps a /ground_truth/human_pose sample for the position error.
    fn add_ground_truth(&mut self, message: &BagMessage) {
        let gt = match lidar_har_msgs::decode::<PoseStamped>(&message.data) {
            Ok(gt) => gt,
            Err(e) => {
                let at = message.log_time_ns;
                return self.skip(format_args!("{} at {at} ns skipped: {e}", message.topic));
            }
        };
        let frame = gt.header.frame_id.trim_start_matches('/');
        let first = self
            .errors
            .truth_frame
            .get_or_insert_with(|| frame.to_string());
        if first != frame {
            let first = first.clone();
            return self.skip(format_args!(
                "{} at {} ns skipped: in frame `{frame}`, the earlier samples in `{first}`",
                message.topic, message.log_time_ns
            ));
        }
        let position = DVec2::new(gt.pose.position.x, gt.pose.position.y);
        self.errors.add_truth(gt.header.stamp.to_nanos(), position);
    }
}

/// The distance from the estimates (and from the pelvis, where the pose head placed it) to
/// /ground_truth/human_pose at their stamps, gathered as the run goes.
struct PositionErrors {
    matcher: TruthMatcher<DVec2, Estimate>,
    spreads: ErrorSpreads,
    /// The frame of the first ground-truth sample; samples in another are skipped.
    truth_frame: Option<String>,
    truth_samples: u64,
}

/// A published position, and the pelvis on the same scan when the pose head placed it.
struct Estimate {
    position: DVec2,
    pelvis: Option<DVec2>,
}

struct ErrorSpreads {
    position: SpreadTally,
    /// Each estimate with the pelvis in place of the position where it was placed.
    pelvis: SpreadTally,
}

impl ErrorSpreads {
    /// Counts an estimate's distance from the truth at its stamp, when there is truth
    /// around it.
    fn score(&mut self, stamp_ns: i64, estimate: Estimate, around: Around<'_, DVec2>) {
        if let Some(truth) = truth_at(stamp_ns, around) {
            let pelvis = estimate.pelvis.unwrap_or(estimate.position);
            self.position.record(estimate.position.distance(truth));
            self.pelvis.record(pelvis.distance(truth));
        }
    }
}

impl Default for PositionErrors {
    fn default() -> Self {
        Self {
            matcher: TruthMatcher::new(MAX_TRUTH_GAP_NS),
            spreads: ErrorSpreads {
                position: SpreadTally::with_steps_per_unit(STEPS_PER_M),
                pelvis: SpreadTally::with_steps_per_unit(STEPS_PER_M),
            },
            truth_frame: None,
            truth_samples: 0,
        }
    }
}

impl PositionErrors {
    fn add_truth(&mut self, stamp_ns: i64, position: DVec2) {
        self.truth_samples += 1;
        let spreads = &mut self.spreads;
        self.matcher.add_truth(stamp_ns, position, |t, e, around| {
            spreads.score(t, e, around)
        });
    }

    fn add_estimate(&mut self, stamp_ns: i64, position: DVec2, pelvis: Option<DVec2>) {
        let spreads = &mut self.spreads;
        self.matcher
            .add_output(stamp_ns, Estimate { position, pelvis }, |t, e, around| {
                spreads.score(t, e, around)
            });
    }

    /// The spreads of the position error and of the pelvis's (when `pelvis_placed`), if the
    /// truth is in the frame of the estimates (`frame`): a learned background puts them in the
    /// Lidar's frame, which a map-frame truth cannot be compared to.
    fn finish(mut self, frame: &str, pelvis_placed: bool) -> (Option<Spread>, Option<Spread>) {
        let spreads = &mut self.spreads;
        self.matcher
            .finish(|t, e, around| spreads.score(t, e, around));
        let truth_frame = self.truth_frame.as_deref();
        if truth_frame.is_some_and(|truth_frame| truth_frame != frame) {
            log::warn!(
                "position error not computed: /ground_truth/human_pose is in frame `{}`, \
                 the estimates in `{frame}`",
                truth_frame.unwrap_or_default()
            );
            return (None, None);
        }
        let pelvis = pelvis_placed
            .then(|| self.spreads.pelvis.spread())
            .flatten();
        (self.spreads.position.spread(), pelvis)
    }
}

/// `summary.json`: what the run tallied, and what the stages counted themselves.
fn summarise(
    input: &Path,
    room: &'static str,
    moving: bool,
    tally: Tally,
    localiser: &LocaliserStage,
    classifier: Option<ClassifierRun>,
) -> RunSummary {
    let frame = localiser.output_frame();
    let pelvis_placed = classifier
        .as_ref()
        .is_some_and(|c| c.pelvis_published() > 0);
    let truth_samples = tally.errors.truth_samples;
    let in_frame = tally
        .errors
        .truth_frame
        .as_deref()
        .is_none_or(|f| f == frame);
    let (position_error_m, pelvis_error_m) = tally.errors.finish(frame, pelvis_placed);
    let mut warnings = localiser.warning_counts().clone();
    if !in_frame {
        warnings.insert("ground_truth_in_another_frame", truth_samples);
    }
    let ratio = |n: u64| {
        if tally.scans == 0 {
            0.0
        } else {
            n as f64 / tally.scans as f64
        }
    };
    RunSummary {
        input: input.to_path_buf(),
        room,
        motion: if moving { "odometry" } else { "stationary" },
        scans: tally.scans,
        scans_localised: tally.scans_localised,
        mount: localiser.mount_source(),
        scans_learning: localiser.scans_learning(),
        visible_ratio: ratio(tally.visible),
        tracked_ratio: ratio(tally.tracked),
        tracks_confirmed: localiser.localiser().confirmed_tracks(),
        pelvis_error_m,
        position_error_m,
        scan_time_us: tally.scan_times.spread(),
        pipeline_time_us: tally.pipeline_times.spread(),
        warnings,
        decode_errors: tally.decode_errors,
        read_error: tally.read_error,
        activity: classifier.map(ClassifierRun::finish),
    }
}

fn write_summary(out_dir: &Path, summary: &RunSummary) -> Result<(), RunError> {
    let path = out_dir.join("summary.json");
    let written = serde_json::to_string_pretty(summary)
        .map_err(std::io::Error::other)
        .and_then(|json| std::fs::write(&path, json + "\n"));
    written.map_err(|cause| RunError::Summary { path, cause })
}

/// A path in `summary.json`, as text: serde refuses a path that is not UTF-8, which would
/// lose the summary of a finished run (the bytes that are not UTF-8 become U+FFFD).
pub(crate) fn path_as_text<S: serde::Serializer>(
    path: &Path,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(&path.to_string_lossy())
}

/// How much of the bag's /tf (log time from its first message) is searched for
/// `odom -> base_link` before the bag is taken to have no odometry: a base driver may start
/// after the other transform publishers, and /tf is busy, but a fixed Lidar's long bag
/// need not be read to its end twice.
const TF_ODOMETRY_SEARCH_NS: i64 = 60_000_000_000;

/// What the bag's transforms carry, found before the run: the stage, which sees them only
/// as they come, is told what a tf2 buffer filled from the whole bag would know.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct BagTransforms {
    /// /tf carries the odometry transform (`odom -> base_link`) within its first
    /// [`TF_ODOMETRY_SEARCH_NS`]: it is the odometry, /odom is ignored (REP 105), and a base
    /// that publishes no /odom moves.
    tf_odometry: bool,
    /// /tf or /tf_static carries `map -> odom` somewhere: a moving robot's scans before it
    /// are skipped rather than placed as if `map` were `odom`.
    map_to_odom: bool,
}

impl BagTransforms {
    /// Reads /tf and /tf_static up to what decides both: the odometry's search window, and
    /// for a robot that moves, the first `map -> odom` (a fixed Lidar's long bag is not read
    /// to its end twice).
    fn find(reader: &BagReader, frames: &FrameConfig) -> Self {
        let mut found = Self::default();
        let present: Vec<&str> = [topics::TF.name, topics::TF_STATIC.name]
            .into_iter()
            .filter(|name| reader.topic(name).is_some())
            .collect();
        if present.is_empty() {
            return found;
        }
        let Ok(messages) = reader.messages_on(&present) else {
            return found;
        };
        let odom_topic = has_messages(reader, topics::ODOM.name);
        let mut first_tf_ns = None;
        let mut odometry_search_over = false;
        for m in messages.map_while(Result::ok) {
            let on_tf = *m.topic == *topics::TF.name;
            if on_tf {
                let first_ns = *first_tf_ns.get_or_insert(m.log_time_ns);
                odometry_search_over |=
                    m.log_time_ns.saturating_sub(first_ns) > TF_ODOMETRY_SEARCH_NS;
            }
            let moving = odom_topic || found.tf_odometry;
            if odometry_search_over && (found.map_to_odom || !moving) {
                break;
            }
            let Ok(tf) = lidar_har_msgs::decode::<TFMessage>(&m.data) else {
                continue;
            };
            found.tf_odometry |= on_tf
                && !odometry_search_over
                && carries_transform(&tf, &frames.odom, &frames.base);
            found.map_to_odom |= carries_transform(&tf, &frames.map, &frames.odom);
            if found.tf_odometry && found.map_to_odom {
                break;
            }
        }
        found
    }
}

/// Ground truth samples farther apart than this are not interpolated between.
const MAX_TRUTH_GAP_NS: i64 = 200_000_000;
/// An estimate this close in time to a lone ground truth sample is compared with it.
const MAX_TRUTH_OFFSET_NS: i64 = 30_000_000;

/// The ground truth at `stamp_ns` from the samples around it: interpolated between two
/// close enough, or a lone one close in time; `None` without either.
fn truth_at(stamp_ns: i64, around: Around<'_, DVec2>) -> Option<DVec2> {
    match (around.before, around.from) {
        (_, Some((t, &p))) if t == stamp_ns => Some(p),
        (Some((ta, &pa)), Some((tb, &pb))) if tb - ta <= MAX_TRUTH_GAP_NS => {
            Some(pa.lerp(pb, (stamp_ns - ta) as f64 / (tb - ta) as f64))
        }
        (Some((t, &p)), _) | (_, Some((t, &p))) if (stamp_ns - t).abs() <= MAX_TRUTH_OFFSET_NS => {
            Some(p)
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lidar_har_bag::WriterOptions;
    use lidar_har_msgs::builtin_interfaces::Time;
    use lidar_har_msgs::geometry_msgs::{Pose, Quaternion, Transform, TransformStamped, Vector3};
    use lidar_har_msgs::nav_msgs::{OccupancyGrid, Odometry};
    use lidar_har_msgs::sensor_msgs::LaserScan;
    use lidar_har_msgs::std_msgs::Header;

    /// Where the robot's transforms put `map -> odom`, and how its /odom disagrees with /tf.
    #[derive(Default)]
    struct Robot {
        /// `map -> odom` (x, y).
        map_to_odom: (f64, f64),
        /// On /tf_static; else on /tf from scan [`Self::map_to_odom_from_scan`] on.
        on_tf_static: bool,
        map_to_odom_from_scan: i64,
        /// /odom's x against /tf's `odom -> base_link` at 0 (raw wheel odometry, drifted).
        odom_drift_m: f64,
        /// Of the bag's metadata.yaml: 8 stands for a Humble or Iron robot's recording.
        metadata_version: MetadataVersion,
        /// /map declared but never written: a clip cut after it, or a robot without one.
        no_map_message: bool,
    }

    const SCANS: i64 = 40;
    const SCAN_PERIOD_NS: i64 = 50_000_000;

    /// A bag of a robot standing at its odom origin in an empty 10 m room (/map), seeing a
    /// person 1.5 m ahead and 1 m to the left of its Lidar, with the ground truth where its
    /// transforms put them; its /tf carries `odom -> base_link`, its /odom the same but for
    /// `odom_drift_m`.
    fn robot_bag(dir: &Path, robot: &Robot) {
        let options = WriterOptions {
            metadata_version: robot.metadata_version,
            ..WriterOptions::default()
        };
        let mut bag = BagWriter::create(dir, options).unwrap();
        let [map_t, tf_static_t, tf_t, odom_t, scan_t, truth_t] = [
            topics::MAP,
            topics::TF_STATIC,
            topics::TF,
            topics::ODOM,
            topics::SCAN,
            topics::GROUND_TRUTH_POSE,
        ]
        .map(|spec| bag.add_contract_topic(&spec).unwrap());
        let transform =
            |parent: &str, child: &str, (x, y): (f64, f64), stamp_ns: i64| TransformStamped {
                header: Header::new(Time::from_nanos(stamp_ns), parent),
                child_frame_id: child.into(),
                transform: Transform {
                    translation: Vector3::new(x, y, 0.0),
                    rotation: Quaternion::IDENTITY,
                },
            };
        let mut grid = OccupancyGrid::default();
        grid.header.frame_id = "map".into();
        grid.info.resolution = 0.1;
        (grid.info.width, grid.info.height) = (100, 100);
        grid.info.origin = Pose::from_xy_yaw(-5.0, -5.0, 0.0);
        grid.data = vec![0; 10_000];
        if !robot.no_map_message {
            bag.write_message(map_t, 0, &grid).unwrap();
        }
        let mut statics = vec![transform("base_link", "laser", (0.0, 0.0), 0)];
        if robot.on_tf_static {
            statics.push(transform("map", "odom", robot.map_to_odom, 0));
        }
        let msg = TFMessage {
            transforms: statics,
        };
        bag.write_message(tf_static_t, 0, &msg).unwrap();
        use crate::localiser_stage::tests::{TURN_OF_720 as increment, ranges_to_a_person_at};
        let person = DVec2::new(1.5, 1.0);
        let ranges = ranges_to_a_person_at(person);
        for k in 0..SCANS {
            let t = 1_000_000_000 + k * SCAN_PERIOD_NS;
            let stamp = Time::from_nanos(t);
            let mut transforms = vec![transform("odom", "base_link", (0.0, 0.0), t)];
            if !robot.on_tf_static && k >= robot.map_to_odom_from_scan {
                transforms.push(transform("map", "odom", robot.map_to_odom, t));
            }
            bag.write_message(tf_t, t, &TFMessage { transforms })
                .unwrap();
            let mut odom = Odometry {
                header: Header::new(stamp, "odom"),
                child_frame_id: "base_link".into(),
                ..Odometry::default()
            };
            odom.pose.pose.position.x = robot.odom_drift_m;
            bag.write_message(odom_t, t, &odom).unwrap();
            let scan = LaserScan {
                header: Header::new(stamp, "laser"),
                angle_min: (-359.5 * increment) as f32,
                angle_max: (359.5 * increment) as f32,
                angle_increment: increment as f32,
                range_min: 0.1,
                range_max: 10.0,
                ranges: ranges.clone(),
                ..LaserScan::default()
            };
            bag.write_message(scan_t, t, &scan).unwrap();
            let (x, y) = robot.map_to_odom;
            let truth = PoseStamped {
                header: Header::new(stamp, "map"),
                pose: Pose::from_xy_yaw(person.x + x, person.y + y, 0.0),
            };
            bag.write_message(truth_t, t, &truth).unwrap();
        }
        bag.finish().unwrap();
    }

    /// `lidar-har run --no-classifier` over `robot`'s bag.
    fn run_robot(robot: &Robot) -> RunSummary {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in");
        robot_bag(&input, robot);
        run_bag(&input, &dir.path().join("out"), RunOptions::default()).unwrap()
    }

    /// A bag at a path that is not UTF-8 (a name a Linux file system takes) still gets its
    /// summary, the path written lossily.
    #[test]
    fn a_bag_at_a_path_that_is_not_utf8_gets_its_summary() {
        use std::os::unix::ffi::OsStrExt;
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join(std::ffi::OsStr::from_bytes(b"rec\xff"));
        robot_bag(&input, &Robot::default());
        let out = dir.path().join("out");
        run_bag(&input, &out, RunOptions::default()).expect("the run finishes");
        let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
        let summary: serde_json::Value = serde_json::from_str(&json).unwrap();
        let written = summary["input"].as_str().expect("the input path as text");
        assert!(written.ends_with("rec\u{fffd}"), "{written}");
    }

    fn median_error(summary: &RunSummary) -> f64 {
        summary
            .position_error_m
            .as_ref()
            .unwrap_or_else(|| panic!("no position error: {summary:?}"))
            .median
    }

    /// `room` says which map was used: a map given with the run replaces the bag's /map,
    /// and both had read `map`.
    #[test]
    fn the_summary_says_whether_the_map_was_given_or_the_bags() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in");
        robot_bag(&input, &Robot::default());
        let run = |map, out| {
            let options = RunOptions {
                map,
                ..RunOptions::default()
            };
            run_bag(&input, &dir.path().join(out), options).unwrap()
        };
        assert_eq!(run(None, "topic").room, "map_topic");
        let given = Some(crate::localiser_stage::tests::empty_room());
        assert_eq!(run(given, "file").room, "map_file");
    }

    /// A bag with odometry and no map message (a clip cut after the recording's only /map)
    /// learns a background as if the Lidar did not move; summary.json says so, counting every
    /// scan: it used to say only `learned_background`, and 9.7 % of a clip's activities were
    /// right against 92 % with `--map`.
    #[test]
    fn odometry_without_a_map_is_a_warning_of_the_summary() {
        let without = run_robot(&Robot {
            no_map_message: true,
            ..Robot::default()
        });
        assert_eq!(without.room, "learned_background");
        assert_eq!(without.motion, "stationary");
        assert_eq!(
            without.warnings.get(ODOMETRY_WITHOUT_MAP),
            Some(&(SCANS as u64))
        );
        let with = run_robot(&Robot::default());
        assert_eq!(with.warnings.get(ODOMETRY_WITHOUT_MAP), None);
    }

    /// `run` over an Iron/Humble-era (version 8) bag wrote version 9, which Humble's
    /// `ros2 bag info` and `play` cannot parse; asked for a version, it writes that one.
    /// Without metadata.yaml (a killed recorder) the version the storage file records counts:
    /// it had written 9.
    #[test]
    fn the_output_bag_is_of_the_inputs_version_unless_another_is_asked_for() {
        let dir = tempfile::tempdir().unwrap();
        let written_from =
            |input: MetadataVersion, asked: Option<MetadataVersion>, metadata_yaml: bool| {
                let name = format!("{}_{asked:?}_{metadata_yaml}", input.number());
                let (input_dir, out_dir) = (dir.path().join(&name), dir.path().join(name + "_out"));
                let robot = Robot {
                    metadata_version: input,
                    ..Robot::default()
                };
                robot_bag(&input_dir, &robot);
                if !metadata_yaml {
                    std::fs::remove_file(input_dir.join("metadata.yaml")).unwrap();
                }
                let options = RunOptions {
                    metadata_version: asked,
                    ..RunOptions::default()
                };
                run_bag(&input_dir, &out_dir, options).unwrap();
                BagReader::open(&out_dir)
                    .unwrap()
                    .metadata()
                    .metadata_version
            };
        let written = |input, asked| written_from(input, asked, true);
        use MetadataVersion::{V8, V9};
        assert_eq!(written(V8, None), Some(8));
        assert_eq!(written(V9, None), Some(9));
        assert_eq!(written(V8, Some(V9)), Some(9));
        assert_eq!(written(V9, Some(V8)), Some(8));
        assert_eq!(written_from(V8, None, false), Some(8));
        assert_eq!(written_from(V9, None, false), Some(9));
    }

    /// REP 105: /tf's `odom -> base_link` (an EKF's fused pose) is the odometry, not raw
    /// /odom beside it. /odom had won: wheel drift moved the person with it.
    #[test]
    fn a_bag_whose_tf_carries_odometry_ignores_a_disagreeing_odom_topic() {
        let summary = run_robot(&Robot {
            odom_drift_m: 1.0,
            ..Robot::default()
        });
        assert!(median_error(&summary) < 0.25, "{summary:?}");
        assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    }

    /// A known start pose as static_transform_publisher gives it had been ignored for a
    /// moving robot: the person 2.2 m off.
    #[test]
    fn a_bag_with_map_to_odom_on_tf_static_is_corrected_by_it() {
        let summary = run_robot(&Robot {
            map_to_odom: (2.0, 1.0),
            on_tf_static: true,
            ..Robot::default()
        });
        assert!(median_error(&summary) < 0.25, "{summary:?}");
        assert_eq!(summary.scans_localised, SCANS as u64);
        assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    }

    /// A bag that carries `map -> odom` has its scans before the first one skipped and
    /// counted, not placed as if `map` were `odom`.
    #[test]
    fn a_bag_with_a_late_map_to_odom_skips_the_scans_before_it() {
        let summary = run_robot(&Robot {
            map_to_odom: (2.0, 1.0),
            map_to_odom_from_scan: 10,
            ..Robot::default()
        });
        assert_eq!(summary.warnings.get("waiting_for_map_to_odom"), Some(&10));
        assert_eq!(summary.scans_localised, (SCANS - 10) as u64);
        assert!(summary.position_error_m.unwrap().max < 0.25);
        // The core's time per scan counts only the scans the core saw.
        let core_times = summary.scan_time_us.expect("scans were localised");
        assert_eq!(core_times.count, (SCANS - 10) as usize, "{core_times:?}");
    }

    /// `map -> odom` is looked for over the whole bag for a robot that moves; a fixed Lidar's
    /// /tf is not read past the odometry's search window.
    #[test]
    fn map_to_odom_is_found_anywhere_in_a_moving_robots_bag() {
        let find = |odom: bool| {
            let dir = tempfile::tempdir().unwrap();
            let mut bag = BagWriter::create(dir.path(), WriterOptions::default()).unwrap();
            let tf_t = bag.add_contract_topic(&topics::TF).unwrap();
            if odom {
                let odom_t = bag.add_contract_topic(&topics::ODOM).unwrap();
                bag.write_message(odom_t, 0, &Odometry::default()).unwrap();
            }
            for (t, parent, child) in [(0, "map", "other"), (70_000_000_000, "map", "odom")] {
                let mut transform = TransformStamped::default();
                transform.header.frame_id = parent.into();
                transform.child_frame_id = child.into();
                let msg = TFMessage {
                    transforms: vec![transform],
                };
                bag.write_message(tf_t, t, &msg).unwrap();
            }
            bag.finish().unwrap();
            let reader = BagReader::open(dir.path()).unwrap();
            BagTransforms::find(&reader, &FrameConfig::default())
        };
        let moving = BagTransforms {
            tf_odometry: false,
            map_to_odom: true,
        };
        assert_eq!(find(true), moving);
        assert_eq!(find(false), BagTransforms::default());
    }

    #[test]
    fn ground_truth_is_interpolated_at_the_estimate_stamp() {
        let mut errors = PositionErrors {
            truth_frame: Some("map".into()),
            ..Default::default()
        };
        errors.add_truth(100_000_000, DVec2::new(1.0, 0.0));
        errors.add_truth(0, DVec2::ZERO);
        errors.add_estimate(50_000_000, DVec2::new(0.5, 0.0), None);
        errors.add_estimate(
            100_000_000,
            DVec2::new(1.0, 1.0),
            Some(DVec2::new(1.0, 0.5)),
        );
        errors.add_estimate(900_000_000, DVec2::ZERO, None);
        let (position, pelvis) = errors.finish("map", true);
        let (position, pelvis) = (position.unwrap(), pelvis.unwrap());
        assert_eq!((position.count, pelvis.count), (2, 2));
        assert_eq!((position.median, position.max), (0.0, 1.0));
        assert_eq!((pelvis.median, pelvis.max), (0.0, 0.5));
    }

    #[test]
    fn no_position_error_against_truth_in_another_frame() {
        let mut errors = PositionErrors {
            truth_frame: Some("laser".into()),
            ..Default::default()
        };
        errors.add_truth(0, DVec2::ZERO);
        errors.add_estimate(0, DVec2::ONE, None);
        assert_eq!(errors.finish("map", false), (None, None));
    }
}
