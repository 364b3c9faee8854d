//! The localiser fed with ROS messages: resolves frames from /tf and /tf_static, converts
//! each message, holds scans that came before their odometry ([`crate::odometry_wait`]),
//! logs the core's warnings (rate-limited) and builds the output messages.

use std::collections::{BTreeMap, HashMap};
use std::time::{Duration, Instant};

use lidar_har_core::geometry::Pose2;
use lidar_har_core::localiser::{
    ConfigError, FrameConfig, Localiser, LocaliserConfig, LocaliserOutput, Motion, Reference,
    Warning,
};
use lidar_har_core::map::{MAP_SERVER_OCCUPIED_THRESH, OccupancyMap};
use lidar_har_core::scan::MAX_SWEEP_S;
use lidar_har_msgs::geometry_msgs::PoseWithCovarianceStamped;
use lidar_har_msgs::lidar_har_msgs::HumanObservation;
use lidar_har_msgs::nav_msgs::{OccupancyGrid, Odometry};
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_msgs::topics::{self, TopicSpec};
use lidar_har_msgs::visualization_msgs::MarkerArray;
use serde::Serialize;

use crate::convert::SpatialTransform;
use crate::odometry_wait::OdometryWait;
use crate::{Outgoing, PipelineError, ProcessedScan, Step, convert};

/// How the room is told apart from the person.
#[derive(Debug, Clone)]
pub enum RoomSource {
    /// A map given by the user (a map_server file): /map messages are ignored.
    Map(OccupancyMap),
    /// The map will come on /map; scans before it are skipped.
    MapTopic,
    /// No map exists: learn the background from the first scans of a stationary Lidar.
    LearnedBackground,
}

impl RoomSource {
    /// As `summary.json`'s `room` says it: which map was used matters, since a given map
    /// replaces the bag's.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Map(_) => "map_file",
            Self::MapTopic => "map_topic",
            Self::LearnedBackground => "learned_background",
        }
    }
}

/// A decoded input message of the stage (one of [`LocaliserStage::INPUTS`]).
#[derive(Debug, Clone)]
pub enum LocaliserInput {
    Scan(LaserScan),
    /// Boxed: its covariances make it five times the size of the others.
    Odometry(Box<Odometry>),
    Map(OccupancyGrid),
    Tf(TFMessage),
    TfStatic(TFMessage),
}

/// A scan decoded on arrival, waiting for the odometry at its stamp.
#[derive(Debug)]
struct ArrivedScan {
    msg: LaserScan,
    decode_time: Duration,
}

/// The three messages the localiser publishes for one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct LocaliserMessages {
    /// `/human/pose`, when a person is tracked.
    pub pose: Option<PoseWithCovarianceStamped>,
    /// `/human/observation`, when a person is tracked.
    pub observation: Option<HumanObservation>,
    /// `/human/markers`, every scan (it clears the person when they are lost).
    pub markers: MarkerArray,
}

/// Scan time between two log lines of the same warning kind.
const WARNING_LOG_INTERVAL_NS: i64 = 5_000_000_000;

/// Counts warnings by kind and logs the first of each kind, then at most one per interval
/// of scan time with the number left unlogged.
#[derive(Debug, Default)]
pub struct WarningLog {
    counts: BTreeMap<&'static str, u64>,
    last_logged: HashMap<&'static str, (i64, u64)>,
}

impl WarningLog {
    pub fn record(&mut self, warning: &Warning, stamp_ns: i64) {
        let kind = warning.kind();
        let count = self.tally(kind);
        let due = match self.last_logged.get(kind) {
            None => true,
            Some(&(at, _)) => stamp_ns.abs_diff(at) >= WARNING_LOG_INTERVAL_NS as u64,
        };
        if due {
            let unlogged = self
                .last_logged
                .get(kind)
                .map_or(0, |&(_, logged_count)| count - logged_count - 1);
            if unlogged > 0 {
                log::warn!("localiser: {warning} ({unlogged} more like it since the last report)");
            } else {
                log::warn!("localiser: {warning}");
            }
            self.last_logged.insert(kind, (stamp_ns, count));
        }
    }

    /// Counts one more warning of `kind` (the stage's own kinds are logged where they arise),
    /// and says how many there have been.
    pub fn tally(&mut self, kind: &'static str) -> u64 {
        self.add(kind, 1)
    }

    /// Counts `n` more warnings of `kind` (known only once they are over), and says how many
    /// there have been.
    pub fn add(&mut self, kind: &'static str, n: u64) -> u64 {
        let count = self.counts.entry(kind).or_default();
        *count += n;
        *count
    }

    /// Warnings so far, by kind.
    pub fn counts(&self) -> &BTreeMap<&'static str, u64> {
        &self.counts
    }
}

/// The localiser with message inputs and outputs.
#[derive(Debug)]
pub struct LocaliserStage {
    localiser: Localiser,
    frames: FrameConfig,
    learned_background: bool,
    /// A Lidar that does not move, in a map: its transforms place its base there.
    fixed_in_map: bool,
    /// Whether transforms have placed the fixed Lidar's base in the map (until they do, it
    /// is at the map origin).
    base_placed: bool,
    /// A map file was given, so /map is not used (and that is logged once).
    map_given: bool,
    map_topic_ignored: bool,
    /// Which of /odom and /tf's `odom -> base_link` the odometry comes from.
    odometry_source: OdometrySource,
    /// Whether /odom's frames were found not to be the configured ones (warned about once).
    odom_frames_warned: bool,
    /// Scans of a moving robot are skipped until the first `map -> odom` comes, as tf2 would
    /// refuse to place them, instead of being placed as if `map` were `odom`.
    wait_for_map_to_odom: bool,
    /// Whether a `map -> odom` has been taken, from /tf or /tf_static.
    map_to_odom_received: bool,
    /// Scans of a moving robot localised before the first `map -> odom`, as if `map` were
    /// `odom`: a robot that never publishes one means it, but one whose first comes late
    /// (AMCL waiting for its initial pose) has had those scans misplaced.
    scans_before_map_to_odom: u64,
    /// The `map -> odom` /tf_static resolves, as last applied: applied again only when it
    /// changes, so that a static publisher's latched message coming again (a late joiner's)
    /// does not undo a newer correction from /tf.
    static_map_to_odom: Option<Pose2>,
    /// The scan's frame (from its header), where the mount ends.
    laser_frame: Option<String>,
    /// child frame -> (parent frame, transform from parent), the latest from /tf_static, and
    /// for a Lidar fixed in a map from /tf too: its transforms do not change, whatever
    /// carries them. Kept in space: a chain is composed whole before it is laid into the plane.
    static_tf: HashMap<String, (String, SpatialTransform)>,
    warnings: WarningLog,
    occupied_thresh: f64,
    last_stamp_ns: i64,
    /// Scans that came before the odometry at their stamp, oldest first.
    waiting: OdometryWait<ArrivedScan>,
    scans_learning: u64,
    /// Receive time of the first scan, from which a background's learning is timed.
    first_scan_received_ns: Option<i64>,
    /// Whether learning that takes too long has been warned about.
    learning_overdue_warned: bool,
    mount: MountSource,
    /// The mount in use, in space: a fixed Lidar placed in the map by its transforms has its
    /// base there less this.
    mount_transform: SpatialTransform,
    /// The Lidar points down in its root frame (mounted upside down): its scans are mirrored.
    scans_mirrored: bool,
    /// Whether a Lidar tilted out of the plane of the scans has been warned about.
    tilt_warned: bool,
    /// The localiser configuration's mount, for a scan frame /tf_static does not reach.
    configured_mount: Pose2,
    /// Scans localised with the configured mount while /tf_static had transforms but no
    /// chain to the scan's frame (counted until that is warned about).
    scans_without_tf_mount: u32,
}

/// Where the odometry comes from. REP 105 makes `odom -> base_link` on /tf the robot's
/// odometry, the one AMCL or SLAM computes `map -> odom` against: with robot_localization its
/// fused pose is there while the base still publishes raw wheel odometry on /odom.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OdometrySource {
    /// Nothing yet.
    Undecided,
    /// /odom, while /tf has brought no `odom -> base_link`.
    OdomTopic,
    /// /tf's `odom -> base_link`: /odom is ignored once it is seen.
    Tf,
}

/// Where the Lidar's mount on the base comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MountSource {
    /// /tf_static links the scan's frame to the base.
    TfStatic,
    /// The localiser configuration's `mount` (no /tf_static chain to the scan's frame yet).
    Configuration,
    /// Not used: a learned background works in the Lidar's own frame.
    None,
}

/// Scans localised with the configured mount, or at the map origin, before a missing
/// transform is warned about (2 s at 20 Hz: /tf_static is latched, so it normally comes
/// before the first scans).
const SCANS_BEFORE_TF_WARNING: u32 = 40;

/// Summary warning key: scans of a fixed Lidar placed at the map origin, since no transform
/// placed its base in the map.
const LIDAR_AT_MAP_ORIGIN: &str = "lidar_at_map_origin";

/// Summary warning key: scans of a moving robot skipped because no `map -> odom` had come
/// yet, with `wait_for_map_to_odom`.
const WAITING_FOR_MAP_TO_ODOM: &str = "waiting_for_map_to_odom";

/// Summary warning key: scans of a moving robot localised as if `map` were `odom` before a
/// `map -> odom` came late (counted when it comes).
const LOCALISED_BEFORE_MAP_TO_ODOM: &str = "localised_before_map_to_odom";

/// Summary warning key: /map messages refused as unusable (their grid does not fit its size).
const MAP_REFUSED: &str = "map_refused";

/// Summary warning key: /odom gives the pose of other frames than the configured base in the
/// configured odom frame (warned about once; used all the same).
const ODOM_FRAMES_UNEXPECTED: &str = "odom_frames_unexpected";

/// Summary warning key: the input ended before the background was learned.
const BACKGROUND_NOT_LEARNED: &str = "background_not_learned";

/// Summary warning key: the mount (or for a fixed Lidar its transforms in the map) tilts the
/// Lidar more than [`MAX_MOUNT_TILT_RAD`] out of the plane of the scans (warned about once).
const MOUNT_TILTED: &str = "mount_tilted";

/// A mount tilted up to this from level (or from upside down) is taken as level: 2 degrees
/// shorten a range by 0.06 %, and lower the scan plane by 3.5 cm at 1 m.
const MAX_MOUNT_TILT_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;

/// Longest chain of static transforms between two frames (the base and the laser, the map
/// and the base).
const MAX_TF_CHAIN: usize = 16;

impl LocaliserStage {
    /// `moving`: whether odometry gives the robot's pose (otherwise the Lidar is fixed, and
    /// `base_link` is where the transforms place it in the map, or at its origin). A learned
    /// background implies a fixed Lidar.
    pub fn new(
        config: LocaliserConfig,
        room: RoomSource,
        moving: bool,
    ) -> Result<Self, ConfigError> {
        let frames = config.frames.clone();
        let configured_mount = config.mount;
        let learned_background = matches!(room, RoomSource::LearnedBackground);
        let map_given = matches!(room, RoomSource::Map(_));
        // A fixed Lidar needs no odometry: its scans never wait.
        let max_wait_s = if moving && !learned_background {
            config.odometry.max_wait_s
        } else {
            0.0
        };
        let localiser = match room {
            RoomSource::LearnedBackground => Localiser::with_learned_background(config)?,
            RoomSource::Map(map) => Localiser::new(config, Reference::Map(map), motion(moving))?,
            RoomSource::MapTopic => Localiser::new(config, Reference::AwaitingMap, motion(moving))?,
        };
        Ok(Self {
            localiser,
            frames,
            learned_background,
            fixed_in_map: !moving && !learned_background,
            base_placed: false,
            map_given,
            map_topic_ignored: false,
            odometry_source: OdometrySource::Undecided,
            odom_frames_warned: false,
            wait_for_map_to_odom: false,
            map_to_odom_received: false,
            scans_before_map_to_odom: 0,
            static_map_to_odom: None,
            laser_frame: None,
            static_tf: HashMap::new(),
            warnings: WarningLog::default(),
            occupied_thresh: MAP_SERVER_OCCUPIED_THRESH,
            last_stamp_ns: 0,
            waiting: OdometryWait::new(max_wait_s),
            scans_learning: 0,
            first_scan_received_ns: None,
            learning_overdue_warned: false,
            mount: if learned_background {
                MountSource::None
            } else {
                MountSource::Configuration
            },
            mount_transform: SpatialTransform::from_pose2(configured_mount),
            scans_mirrored: false,
            tilt_warned: false,
            configured_mount,
            scans_without_tf_mount: 0,
        })
    }

    pub fn localiser(&self) -> &Localiser {
        &self.localiser
    }

    /// Whether a moving robot's scans wait for the first `map -> odom` (skipped until it
    /// comes) rather than being placed as if `map` were `odom`, the default for robots that
    /// publish none: for a host that knows one will come.
    pub fn set_wait_for_map_to_odom(&mut self, wait: bool) {
        self.wait_for_map_to_odom = wait;
    }

    /// The input's /tf carries `odom -> base_link`, as a host that can look ahead (a bag)
    /// knows: /odom is ignored from the start, not only once the transform comes.
    pub fn take_odometry_from_tf(&mut self) {
        self.choose_tf_odometry();
    }

    /// Odometry moves the robot in a map: `map -> odom` and the odometry place its scans.
    fn moving(&self) -> bool {
        !self.fixed_in_map && !self.learned_background
    }

    /// Where the Lidar's mount comes from.
    pub fn mount_source(&self) -> MountSource {
        self.mount
    }

    /// Scans used to learn the background so far.
    pub fn scans_learning(&self) -> u64 {
        self.scans_learning
    }

    pub fn warning_counts(&self) -> &BTreeMap<&'static str, u64> {
        self.warnings.counts()
    }

    /// The frame of the outputs: the map, or the Lidar's own frame with a learned background.
    pub fn output_frame(&self) -> &str {
        match (&self.laser_frame, self.learned_background) {
            (Some(laser), true) => laser,
            _ => &self.frames.map,
        }
    }

    fn warn(&mut self, warning: Option<Warning>) {
        if let Some(w) = warning {
            self.warnings.record(&w, self.last_stamp_ns);
        }
    }

    /// The topics the stage reads.
    pub const INPUTS: [TopicSpec; 5] = [
        topics::SCAN,
        topics::ODOM,
        topics::MAP,
        topics::TF,
        topics::TF_STATIC,
    ];
    /// The topics the stage writes.
    pub const OUTPUTS: [TopicSpec; 3] = [
        topics::HUMAN_POSE,
        topics::HUMAN_OBSERVATION,
        topics::HUMAN_MARKERS,
    ];

    /// Whether `topic` is one of [`Self::INPUTS`] (the others need not be decoded at all).
    pub fn consumes(topic: &str) -> bool {
        Self::INPUTS.iter().any(|t| t.name == topic)
    }

    /// Feeds one message (CDR with its encapsulation header) received on `topic` at
    /// `received_ns` (the host's receive time: a bag's log time, a node's clock); messages on
    /// other topics than [`Self::INPUTS`] are ignored. A scan stamped after the newest
    /// odometry waits for it up to `odometry.max_wait_s` ([`crate::odometry_wait`]), so the
    /// step may hold no scan, or several that waited.
    pub fn handle(
        &mut self,
        topic: &str,
        cdr: &[u8],
        received_ns: i64,
    ) -> Result<Step, PipelineError> {
        let decode_error = |source| PipelineError::Decode {
            topic: topic.to_string(),
            cause: source,
        };
        let started = Instant::now();
        let input = match topic {
            t if t == topics::SCAN.name => {
                LocaliserInput::Scan(lidar_har_msgs::decode(cdr).map_err(decode_error)?)
            }
            t if t == topics::ODOM.name => LocaliserInput::Odometry(Box::new(
                lidar_har_msgs::decode(cdr).map_err(decode_error)?,
            )),
            t if t == topics::MAP.name => {
                LocaliserInput::Map(lidar_har_msgs::decode(cdr).map_err(decode_error)?)
            }
            t if t == topics::TF.name => {
                LocaliserInput::Tf(lidar_har_msgs::decode(cdr).map_err(decode_error)?)
            }
            t if t == topics::TF_STATIC.name => {
                LocaliserInput::TfStatic(lidar_har_msgs::decode(cdr).map_err(decode_error)?)
            }
            _ => return Ok(Step::default()),
        };
        self.accept(input, received_ns, started.elapsed())
    }

    /// Feeds one decoded message received at `received_ns`, as [`Self::handle`] does.
    pub fn receive(
        &mut self,
        input: LocaliserInput,
        received_ns: i64,
    ) -> Result<Step, PipelineError> {
        self.accept(input, received_ns, Duration::ZERO)
    }

    /// Localises the scans whose wait for odometry is over at `now_ns` (receive time): for a
    /// host that has no message to hand over for a while.
    pub fn release_expired(&mut self, now_ns: i64) -> Result<Step, PipelineError> {
        let mut step = Step::default();
        while let Some(scan) = self.waiting.pop_expired(now_ns) {
            self.localise_into(&mut step, scan)?;
        }
        Ok(step)
    }

    /// When the oldest waiting scan stops waiting (receive time), if one waits: a host with
    /// no message by then calls [`Self::release_expired`].
    pub fn wait_deadline_ns(&self) -> Option<i64> {
        self.waiting.deadline_ns()
    }

    /// Localises every scan still waiting for odometry, with what there is: the input has
    /// ended (a bag's end, a node's shutdown).
    pub fn finish(&mut self) -> Result<Step, PipelineError> {
        let mut step = Step::default();
        while let Some(scan) = self.waiting.pop_any() {
            self.localise_into(&mut step, scan)?;
        }
        if self.learning() {
            self.warnings.tally(BACKGROUND_NOT_LEARNED);
            log::warn!(
                "localiser: the background was never learned ({} scans learned from, short of \
                 background.learn_duration_s = {} s of scans): nothing was localised",
                self.scans_learning,
                self.localiser.config().background.learn_duration_s
            );
        }
        Ok(step)
    }

    /// Whether a learned background is still being learned: no scan is localised until it is.
    fn learning(&self) -> bool {
        matches!(self.localiser.reference(), Reference::Background(b) if !b.is_ready())
    }

    /// Warns once when the background is still not learned twice its learning time after the
    /// first scan came (the Lidar sends broken scans, or none with a return; its stamps keep
    /// going back): nothing is localised until it is, and nothing else would say so while the
    /// input lasts.
    fn check_learning_time(&mut self, received_ns: i64) {
        let first_ns = *self.first_scan_received_ns.get_or_insert(received_ns);
        if self.learning_overdue_warned || !self.learning() {
            return;
        }
        let learn_s = self.localiser.config().background.learn_duration_s;
        let waited_s = received_ns.saturating_sub(first_ns) as f64 * 1e-9;
        if waited_s > 2.0 * learn_s {
            self.learning_overdue_warned = true;
            log::warn!(
                "localiser: the background is still not learned {waited_s:.1} s after the first \
                 scan ({} scans learned from; background.learn_duration_s = {learn_s} s): \
                 nothing is localised until it is",
                self.scans_learning
            );
        }
    }

    /// Scans whose wait ran out before this message came go first, as a host waiting on
    /// its clock had let them go; then the message, then the scans it lets go.
    fn accept(
        &mut self,
        input: LocaliserInput,
        received_ns: i64,
        decode_time: Duration,
    ) -> Result<Step, PipelineError> {
        let mut step = self.release_expired(received_ns)?;
        match input {
            LocaliserInput::Scan(msg) => {
                self.check_learning_time(received_ns);
                let needed_ns = msg
                    .header
                    .stamp
                    .to_nanos()
                    .saturating_add(self.last_beam_after_stamp_ns(&msg));
                let scan = ArrivedScan { msg, decode_time };
                self.waiting.push(needed_ns, received_ns, scan);
            }
            LocaliserInput::Odometry(msg) => self.on_odom(&msg),
            LocaliserInput::Map(msg) => self.on_map(&msg),
            LocaliserInput::Tf(msg) => self.on_tf(&msg),
            LocaliserInput::TfStatic(msg) => self.on_tf_static(&msg),
        }
        while let Some(scan) = self
            .waiting
            .pop_ready(self.localiser.latest_odometry_ns(), received_ns)
        {
            self.localise_into(&mut step, scan)?;
        }
        Ok(step)
    }

    /// How long after its stamp the scan's last beam was measured, when de-skewing places it
    /// from the pose at that time: a Lidar that measures beam 0 first (`time_increment` > 0)
    /// needs odometry up to the end of its sweep, not only up to the stamp.
    fn last_beam_after_stamp_ns(&self, msg: &LaserScan) -> i64 {
        if !self.localiser.config().odometry.deskew {
            return 0;
        }
        let sweep_s = f64::from(msg.time_increment) * msg.ranges.len().saturating_sub(1) as f64;
        if sweep_s.is_finite() && sweep_s > 0.0 && sweep_s <= MAX_SWEEP_S {
            (sweep_s * 1e9) as i64
        } else {
            0
        }
    }

    /// Localises one scan and adds it, with its output messages, to `step`.
    fn localise_into(&mut self, step: &mut Step, scan: ArrivedScan) -> Result<(), PipelineError> {
        let started = Instant::now();
        let (output, localise_time) = self.localise(&scan.msg);
        if let Some(output) = &output {
            step.outgoing.extend(self.outgoing(output)?);
        }
        step.scans.push(ProcessedScan {
            output,
            localise_time,
            pipeline_time: scan.decode_time + started.elapsed(),
        });
        Ok(())
    }

    /// One output's messages, encoded for their topics.
    fn outgoing(&self, output: &LocaliserOutput) -> Result<Vec<Outgoing>, PipelineError> {
        let stamp = output.stamp_ns;
        let messages = self.messages(output);
        let mut out = Vec::with_capacity(Self::OUTPUTS.len());
        if let Some(pose) = &messages.pose {
            out.push(Outgoing::encode(topics::HUMAN_POSE, stamp, pose)?);
        }
        if let Some(observation) = &messages.observation {
            out.push(Outgoing::encode(
                topics::HUMAN_OBSERVATION,
                stamp,
                observation,
            )?);
        }
        out.push(Outgoing::encode(
            topics::HUMAN_MARKERS,
            stamp,
            &messages.markers,
        )?);
        Ok(out)
    }

    /// Localises the person in one scan (`None` when the scan was skipped or learned from),
    /// and the time the core took (`None` when the core did not see it).
    fn localise(&mut self, msg: &LaserScan) -> (Option<LocaliserOutput>, Option<Duration>) {
        let frame = msg.header.frame_id.trim_start_matches('/');
        if self.laser_frame.as_deref() != Some(frame) {
            self.laser_frame = Some(frame.to_string());
            self.update_placement();
        }
        let mut scan = convert::scan_from_msg(msg);
        if self.scans_mirrored {
            scan = convert::mirrored_scan(scan);
        }
        self.last_stamp_ns = scan.stamp_ns;
        if self.moving() && !self.map_to_odom_received && self.wait_for_map_to_odom {
            if self.warnings.tally(WAITING_FOR_MAP_TO_ODOM) == 1 {
                log::warn!(
                    "localiser: no `{} -> {}` yet on /tf or /tf_static: scans are skipped until \
                     the first one comes (wait_for_map_to_odom)",
                    self.frames.map,
                    self.frames.odom
                );
            }
            return (None, None);
        }
        let learning = self.learning();
        let started = Instant::now();
        let result = self.localiser.process_scan(&scan);
        let localise_time = started.elapsed();
        self.scans_learning += u64::from(result.learning);
        if learning && !self.learning() {
            log::info!(
                "localiser: background learned from {} scans (background.learn_duration_s = {} s)",
                self.scans_learning,
                self.localiser.config().background.learn_duration_s
            );
        }
        if self.moving() && !self.map_to_odom_received && result.output.is_some() {
            self.scans_before_map_to_odom += 1;
        }
        if self.fixed_in_map && !self.base_placed && result.output.is_some() {
            let scans = self.warnings.tally(LIDAR_AT_MAP_ORIGIN);
            if scans == u64::from(SCANS_BEFORE_TF_WARNING) {
                log::warn!(
                    "localiser: no transform places `{}` in `{}` (`{} -> {} -> {}`, or \
                     `{} -> {frame}`, on /tf_static or /tf): the fixed Lidar is assumed at the \
                     map origin (publish them, e.g. with static_transform_publisher)",
                    self.frames.base,
                    self.frames.map,
                    self.frames.map,
                    self.frames.odom,
                    self.frames.base,
                    self.frames.map
                );
            }
        }
        // A configured mount is a choice unless /tf_static speaks, but of other frames.
        if self.mount == MountSource::Configuration
            && !self.static_tf.is_empty()
            && result.output.is_some()
        {
            self.scans_without_tf_mount += 1;
            if self.scans_without_tf_mount == SCANS_BEFORE_TF_WARNING {
                log::warn!(
                    "no /tf_static chain from the scan's frame `{frame}` to `{}`: the Lidar \
                     mount of the localiser configuration is used (publish the transform, or \
                     set the scan's frame_id to the one your robot description uses)",
                    self.frames.base
                );
            }
        }
        for w in &result.warnings {
            self.warnings.record(w, scan.stamp_ns);
        }
        (result.output, Some(localise_time))
    }

    /// Odometry: the pose of the base in the odom frame, unless /tf gives it.
    fn on_odom(&mut self, msg: &Odometry) {
        if !self.moving() {
            return;
        }
        match self.odometry_source {
            OdometrySource::Tf => return,
            OdometrySource::Undecided => {
                self.odometry_source = OdometrySource::OdomTopic;
                log::info!(
                    "localiser: odometry from /odom (no `{} -> {}` on /tf so far)",
                    self.frames.odom,
                    self.frames.base
                );
            }
            OdometrySource::OdomTopic => {}
        }
        self.check_odom_frames(msg);
        let stamp_ns = msg.header.stamp.to_nanos();
        self.last_stamp_ns = stamp_ns;
        let w = self
            .localiser
            .add_odometry(stamp_ns, convert::pose2_from_pose(&msg.pose.pose));
        self.warn(w);
    }

    /// Warns once when /odom is not the pose of the configured base in the configured odom
    /// frame: it is still used (a driver naming its frames otherwise, `base_footprint`, is
    /// common), but `map -> odom` and the mount may then not be about the same frames.
    fn check_odom_frames(&mut self, msg: &Odometry) {
        let parent = msg.header.frame_id.trim_start_matches('/');
        let child = msg.child_frame_id.trim_start_matches('/');
        if self.odom_frames_warned || (parent == self.frames.odom && child == self.frames.base) {
            return;
        }
        self.odom_frames_warned = true;
        self.warnings.tally(ODOM_FRAMES_UNEXPECTED);
        log::warn!(
            "localiser: /odom is the pose of `{child}` in `{parent}`, not of `{}` in `{}` as \
             configured (frames.base, frames.odom): it is used as that all the same",
            self.frames.base,
            self.frames.odom
        );
    }

    /// From now on the odometry is /tf's `odom -> base_link`. Samples /odom gave are
    /// forgotten: the two need not agree, and the buffer must not mix them.
    fn choose_tf_odometry(&mut self) {
        let previous = std::mem::replace(&mut self.odometry_source, OdometrySource::Tf);
        if previous == OdometrySource::OdomTopic {
            self.localiser.restart_odometry();
            log::warn!(
                "localiser: `{} -> {}` came on /tf: it is the odometry from now on, and /odom, \
                 used until now, is ignored (REP 105: the transform is the robot's odometry, \
                 e.g. a filter's fused pose beside raw wheel odometry)",
                self.frames.odom,
                self.frames.base
            );
        } else if previous == OdometrySource::Undecided {
            log::info!(
                "localiser: odometry from `{} -> {}` on /tf; /odom is ignored",
                self.frames.odom,
                self.frames.base
            );
        }
    }

    /// Takes a `map -> odom` correction; the first one says how many scans were placed
    /// without it, or skipped waiting for it.
    fn take_map_to_odom(&mut self, pose: Pose2) {
        let w = self.localiser.set_map_to_odom(pose);
        if w.is_none() && !std::mem::replace(&mut self.map_to_odom_received, true) {
            let scans = self.scans_before_map_to_odom;
            if scans > 0 {
                self.warnings.add(LOCALISED_BEFORE_MAP_TO_ODOM, scans);
                log::warn!(
                    "localiser: the first `{} -> {}` came after {scans} scans had been placed as \
                     if `{}` were `{}` (set wait_for_map_to_odom to skip them)",
                    self.frames.map,
                    self.frames.odom,
                    self.frames.map,
                    self.frames.odom
                );
            }
            if let Some(skipped) = self.warnings.counts().get(WAITING_FOR_MAP_TO_ODOM) {
                log::info!(
                    "localiser: the first `{} -> {}` came; {skipped} scans were skipped waiting \
                     for it",
                    self.frames.map,
                    self.frames.odom
                );
            }
        }
        self.warn(w);
    }

    /// A new map replaces the previous one (not a map file the user gave, nor the learned
    /// background, which needs none).
    fn on_map(&mut self, msg: &OccupancyGrid) {
        if self.learned_background {
            return;
        }
        if self.map_given {
            if !std::mem::replace(&mut self.map_topic_ignored, true) {
                log::warn!("localiser: /map ignored: the map file given is used instead");
            }
            return;
        }
        match convert::map_from_grid(msg, self.occupied_thresh) {
            Ok(map) => self.localiser.set_map(map),
            Err(e) => {
                self.warnings.tally(MAP_REFUSED);
                log::warn!("localiser: /map ignored: {e}");
            }
        }
    }

    /// Dynamic transforms: the `map -> odom` correction, and `odom -> base_link`, which once
    /// seen is the odometry (not /odom). A fixed Lidar's do not change: they place it as
    /// static ones do.
    fn on_tf(&mut self, msg: &TFMessage) {
        if self.fixed_in_map {
            return self.on_tf_static(msg);
        }
        for t in &msg.transforms {
            let parent = t.header.frame_id.trim_start_matches('/');
            let child = t.child_frame_id.trim_start_matches('/');
            let pose = convert::pose2_from_transform(&t.transform);
            if parent == self.frames.map && child == self.frames.odom {
                self.take_map_to_odom(pose);
            } else if parent == self.frames.odom && child == self.frames.base && self.moving() {
                if self.odometry_source != OdometrySource::Tf {
                    self.choose_tf_odometry();
                }
                let stamp_ns = t.header.stamp.to_nanos();
                self.last_stamp_ns = stamp_ns;
                let w = self.localiser.add_odometry(stamp_ns, pose);
                self.warn(w);
            }
        }
    }

    /// Static transforms: the mount of the Lidar on the base, possibly through a chain,
    /// where a fixed Lidar's base is in the map, and a moving robot's `map -> odom` (tf2
    /// takes it from /tf_static as from /tf: static_transform_publisher for a known start
    /// pose).
    fn on_tf_static(&mut self, msg: &TFMessage) {
        for t in &msg.transforms {
            let parent = t.header.frame_id.trim_start_matches('/').to_string();
            let child = t.child_frame_id.trim_start_matches('/').to_string();
            self.static_tf
                .insert(child, (parent, SpatialTransform::from_msg(&t.transform)));
        }
        if self.moving()
            && let Some(map_to_odom) = self.static_pose(&self.frames.odom, &self.frames.map)
        {
            let pose = map_to_odom.in_scan_plane().pose;
            if self.static_map_to_odom.replace(pose) != Some(pose) {
                self.take_map_to_odom(pose);
            }
        }
        self.update_placement();
    }

    /// Recomputes the mount, then lays the Lidar into the plane of the scans (once the scans
    /// name their frame; a learned background works in it).
    fn update_placement(&mut self) {
        if self.learned_background {
            return;
        }
        let Some(laser) = self.laser_frame.clone() else {
            return;
        };
        self.update_mount(&laser);
        self.place_lidar(&laser);
    }

    /// Recomputes `base -> laser` from the static transforms, when they connect the two and
    /// the localiser accepts it.
    fn update_mount(&mut self, laser: &str) {
        if let Some(mount) = self.static_pose(laser, &self.frames.base) {
            let w = self.localiser.set_mount(mount.in_scan_plane().pose);
            if w.is_none() {
                self.mount = MountSource::TfStatic;
                self.mount_transform = mount;
            }
            self.warn(w);
        } else if self.mount == MountSource::TfStatic {
            // The scans now come from another frame: the old chain's mount is not theirs.
            log::warn!(
                "localiser: the scans' frame is now `{laser}`, which /tf_static does not \
                 connect to `{}`: the mount of the localiser configuration is used",
                self.frames.base
            );
            let w = self.localiser.set_mount(self.configured_mount);
            if w.is_none() {
                self.mount = MountSource::Configuration;
                self.mount_transform = SpatialTransform::from_pose2(self.configured_mount);
            }
            self.warn(w);
        }
    }

    /// Lays the Lidar into the plane of the scans from its whole transform in its root frame,
    /// as tf2 resolves it: for a fixed Lidar its transforms place, `map -> ... -> laser`;
    /// otherwise the mount (a moving base is level, an unplaced fixed one at the map origin).
    /// That transform alone decides whether the scans are mirrored (the Lidar's z axis points
    /// down) and whether the Lidar is tilted (warned about once); a fixed Lidar's base is
    /// placed so that the planar mount in use puts the Lidar where that transform lays it.
    fn place_lidar(&mut self, laser: &str) {
        let mut root = self.frames.base.clone();
        let mut lidar = self.mount_transform;
        if let Some(in_map) = self.lidar_in_map(laser) {
            let mount = self.mount_transform.in_scan_plane().pose;
            let base = in_map.in_scan_plane().pose.compose(&mount.inverse());
            let w = self.localiser.set_fixed_base(base);
            if w.is_none() {
                self.base_placed = true;
                root = self.frames.map.clone();
                lidar = in_map;
            }
            self.warn(w);
        }
        let planar = lidar.in_scan_plane();
        if planar.mirrored && !self.scans_mirrored {
            log::info!(
                "localiser: the Lidar is upside down in `{root}` (its z axis points down): its \
                 scans are mirrored"
            );
        }
        self.scans_mirrored = planar.mirrored;
        if planar.tilt_rad > MAX_MOUNT_TILT_RAD && !self.tilt_warned {
            self.tilt_warned = true;
            self.warnings.tally(MOUNT_TILTED);
            log::warn!(
                "localiser: `{root} -> {laser}` tilts the Lidar {:.1} degrees out of the plane of \
                 the scans (more than {:.0}): its points are placed as if it were level",
                planar.tilt_rad.to_degrees(),
                MAX_MOUNT_TILT_RAD.to_degrees()
            );
        }
    }

    /// A fixed Lidar's transform in the map, from the latest transforms, as tf2 would look
    /// them up: its base's (`map -> odom -> base_link`, or `map -> base_link`) and the mount
    /// in use, or when none reaches the base, a chain to the scan's frame (a plain
    /// `map -> laser`).
    fn lidar_in_map(&self, laser: &str) -> Option<SpatialTransform> {
        if !self.fixed_in_map {
            return None;
        }
        match self.static_pose(&self.frames.base, &self.frames.map) {
            Some(base) => Some(base.compose(&self.mount_transform)),
            None => self.static_pose(laser, &self.frames.map),
        }
    }

    /// The transform from `ancestor` to `frame` through the static transforms, when they
    /// link them.
    fn static_pose(&self, frame: &str, ancestor: &str) -> Option<SpatialTransform> {
        let mut frame = frame;
        let mut pose = SpatialTransform::IDENTITY;
        for _ in 0..MAX_TF_CHAIN {
            if frame == ancestor {
                return Some(pose);
            }
            let (parent, to_parent) = self.static_tf.get(frame)?;
            pose = to_parent.compose(&pose);
            frame = parent;
        }
        None
    }

    /// The messages to publish for one output.
    pub fn messages(&self, output: &LocaliserOutput) -> LocaliserMessages {
        let frame = self.output_frame();
        LocaliserMessages {
            pose: output
                .person
                .as_ref()
                .map(|p| convert::pose_msg(output, p, frame)),
            observation: output
                .person
                .as_ref()
                .map(|p| convert::observation_msg(output, p, frame)),
            markers: convert::markers_msg(output, frame),
        }
    }
}

/// Whether a /tf or /tf_static message carries the transform `parent -> child`.
pub fn carries_transform(msg: &TFMessage, parent: &str, child: &str) -> bool {
    msg.transforms.iter().any(|t| {
        t.header.frame_id.trim_start_matches('/') == parent
            && t.child_frame_id.trim_start_matches('/') == child
    })
}

fn motion(moving: bool) -> Motion {
    if moving {
        Motion::Odometry
    } else {
        Motion::Stationary(Pose2::IDENTITY)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::convert::tests::quaternion;
    use lidar_har_msgs::builtin_interfaces::Time;
    use lidar_har_msgs::geometry_msgs::{Quaternion, Transform, TransformStamped, Vector3};
    use lidar_har_msgs::std_msgs::Header;

    fn tf(parent: &str, child: &str, x: f64, yaw: f64) -> TransformStamped {
        TransformStamped {
            header: Header::new(Time::default(), parent),
            child_frame_id: child.into(),
            transform: Transform {
                translation: Vector3::new(x, 0.0, 0.3),
                rotation: Quaternion::from_yaw(yaw),
            },
        }
    }

    fn scan(stamp_ns: i64) -> LaserScan {
        LaserScan {
            header: Header::new(Time::from_nanos(stamp_ns), "laser"),
            angle_min: 0.0,
            angle_max: 0.0,
            angle_increment: 0.01,
            range_min: 0.1,
            range_max: 10.0,
            ranges: vec![],
            ..LaserScan::default()
        }
    }

    /// A scan with a return on each of its four beams, 2 m off.
    fn returning_scan(stamp_ns: i64) -> LaserScan {
        LaserScan {
            ranges: vec![2.0; 4],
            ..scan(stamp_ns)
        }
    }

    /// Feeds `msg` (received at 0) and gives the output of the one scan that goes through.
    fn scan_output(stage: &mut LocaliserStage, msg: LaserScan) -> Option<LocaliserOutput> {
        let mut step = stage.receive(LocaliserInput::Scan(msg), 0).unwrap();
        assert_eq!(step.scans.len(), 1, "the scan did not go through at once");
        step.scans.remove(0).output
    }

    fn odometry(stamp_ns: i64, x: f64) -> LocaliserInput {
        let mut odom = Odometry {
            header: Header::new(Time::from_nanos(stamp_ns), "odom"),
            child_frame_id: "base_link".into(),
            ..Odometry::default()
        };
        odom.pose.pose.position.x = x;
        LocaliserInput::Odometry(Box::new(odom))
    }

    /// `tf(parent, child, x, 0.0)` stamped `stamp_ns`, on /tf.
    fn tf_at(parent: &str, child: &str, x: f64, stamp_ns: i64) -> LocaliserInput {
        let mut t = tf(parent, child, x, 0.0);
        t.header.stamp = Time::from_nanos(stamp_ns);
        LocaliserInput::Tf(TFMessage {
            transforms: vec![t],
        })
    }

    /// The Lidar pose of a moving robot's scan stamped `stamp_ns`, given odometry at x = 0
    /// there (`None`: skipped).
    fn placed_with_odometry(stage: &mut LocaliserStage, stamp_ns: i64) -> Option<Pose2> {
        stage.receive(odometry(stamp_ns, 0.0), stamp_ns).unwrap();
        scan_output(stage, scan(stamp_ns)).map(|out| out.laser_pose)
    }

    /// A 10 m square map without an obstacle, centred on the origin.
    pub(crate) fn empty_room() -> OccupancyMap {
        let geometry = lidar_har_core::map::MapGeometry {
            resolution: 0.1,
            origin: Pose2::new(-5.0, -5.0, 0.0),
            width: 100,
            height: 100,
        };
        OccupancyMap::new(geometry, vec![false; 10_000]).unwrap()
    }

    #[test]
    fn mount_is_resolved_through_a_static_chain_and_map_to_odom_applied() {
        let mut stage = LocaliserStage::new(
            LocaliserConfig::default(),
            RoomSource::Map(empty_room()),
            true,
        )
        .unwrap();
        assert_eq!(stage.mount_source(), MountSource::Configuration);
        stage.on_tf_static(&TFMessage {
            transforms: vec![
                tf("base_link", "laser_mount", 0.2, 0.0),
                tf("/laser_mount", "laser", 0.1, 0.5),
            ],
        });
        stage.on_tf(&TFMessage {
            transforms: vec![tf("map", "odom", 1.0, 0.0), tf("odom", "other", 9.0, 0.0)],
        });
        let mut odom = Odometry::default();
        odom.pose.pose.position.y = 2.0;
        stage.on_odom(&odom);
        let out = scan_output(&mut stage, scan(0)).expect("localised");
        assert!(
            (out.laser_pose.x - 1.3).abs() < 1e-12,
            "{:?}",
            out.laser_pose
        );
        assert!((out.laser_pose.y - 2.0).abs() < 1e-12);
        assert!((out.laser_pose.theta - 0.5).abs() < 1e-12);
        assert_eq!(stage.output_frame(), "map");
        assert_eq!(stage.mount_source(), MountSource::TfStatic);
    }

    /// A stage in an empty room, its localiser configured with the Lidar at `mount`.
    fn stage_with_mount(mount: Pose2) -> LocaliserStage {
        let config = LocaliserConfig {
            mount,
            ..LocaliserConfig::default()
        };
        LocaliserStage::new(config, RoomSource::Map(empty_room()), false).unwrap()
    }

    #[test]
    fn a_scan_frame_without_a_static_chain_keeps_the_configured_mount() {
        let mount = Pose2::new(0.15, 0.0, 0.0);
        let mut stage = stage_with_mount(mount);
        // The robot description calls the Lidar `rplidar_link`; the driver says `laser`.
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("base_link", "rplidar_link", 0.2, 0.0)],
        });
        for k in 0..=SCANS_BEFORE_TF_WARNING {
            let out = scan_output(&mut stage, scan(i64::from(k))).expect("localised");
            assert_eq!(out.laser_pose, mount);
        }
        assert_eq!(stage.mount_source(), MountSource::Configuration);
    }

    #[test]
    fn scans_from_a_frame_the_static_chain_does_not_reach_get_the_configured_mount_again() {
        let mount = Pose2::new(0.15, 0.0, 0.0);
        let mut stage = stage_with_mount(mount);
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("base_link", "laser", 0.2, 0.0)],
        });
        let out = scan_output(&mut stage, scan(0)).expect("localised");
        assert!(
            (out.laser_pose.x - 0.2).abs() < 1e-12,
            "{:?}",
            out.laser_pose
        );
        assert_eq!(stage.mount_source(), MountSource::TfStatic);
        let mut other = scan(1);
        other.header.frame_id = "other_laser".into();
        let out = scan_output(&mut stage, other).expect("localised");
        assert_eq!(out.laser_pose, mount);
        assert_eq!(stage.mount_source(), MountSource::Configuration);
        let out = scan_output(&mut stage, scan(2)).expect("localised");
        assert!(
            (out.laser_pose.x - 0.2).abs() < 1e-12,
            "{:?}",
            out.laser_pose
        );
        assert_eq!(stage.mount_source(), MountSource::TfStatic);
    }

    /// `tf(parent, child, x, 0.0)` turned by `rotation`.
    fn rotated_tf(parent: &str, child: &str, x: f64, rotation: glam::DQuat) -> TransformStamped {
        let mut t = tf(parent, child, x, 0.0);
        t.transform.rotation = quaternion(rotation);
        t
    }

    /// The beam spacing of [`ranges_to_a_person_at`].
    pub(crate) const TURN_OF_720: f64 = std::f64::consts::TAU / 720.0;

    /// A full turn of 720 beams from the laser, beam `i` at angle `(i - 359.5)` increments
    /// (symmetric about 0: beam i and beam 719 - i point at opposite angles), seeing only a
    /// person of radius 0.2 m at `person`.
    pub(crate) fn ranges_to_a_person_at(person: glam::DVec2) -> Vec<f32> {
        (0..720)
            .map(|i| {
                let d = glam::DVec2::from_angle((i as f64 - 359.5) * TURN_OF_720);
                let along = person.dot(d);
                let off = (person - along * d).length();
                if along > 0.0 && off < 0.2 {
                    (along - (0.04 - off * off).sqrt()) as f32
                } else {
                    f32::INFINITY
                }
            })
            .collect()
    }

    /// The person positions a Lidar fixed in an empty room gives over 20 scans of a person
    /// standing 1.8 m off, the Lidar placed by the static `transforms`, each scan's beams in
    /// reverse order when `reversed`.
    fn person_positions(
        transforms: Vec<TransformStamped>,
        reversed: bool,
    ) -> Vec<Option<glam::DVec2>> {
        let mut stage = fixed_stage();
        stage.on_tf_static(&TFMessage { transforms });
        let mut ranges = ranges_to_a_person_at(glam::DVec2::new(1.5, 1.0));
        if reversed {
            ranges.reverse();
        }
        (0..20)
            .map(|k| {
                let mut msg = scan(k * 50 * MS);
                msg.angle_min = (-359.5 * TURN_OF_720) as f32;
                msg.angle_increment = TURN_OF_720 as f32;
                msg.ranges = ranges.clone();
                let out = scan_output(&mut stage, msg).expect("localised");
                out.person.map(|p| p.position)
            })
            .collect()
    }

    /// Some robots mount the Lidar upside down (`base_link -> laser` rolled by pi): its scans
    /// turn the other way, which tf2 resolves. The heading alone had mirrored the room: the
    /// person seen on a third of the scans, 1.8 m off.
    #[test]
    fn an_upside_down_mount_places_its_mirrored_scans_as_the_upright_one() {
        let yaw = glam::DQuat::from_rotation_z(0.5);
        let upright = person_positions(vec![rotated_tf("base_link", "laser", 0.2, yaw)], false);
        let flipped = yaw * glam::DQuat::from_rotation_x(std::f64::consts::PI);
        let mount = rotated_tf("base_link", "laser", 0.2, flipped);
        assert_same_positions(&upright, &person_positions(vec![mount], true));
    }

    /// Both runs saw the person, on the same scans, at the same places.
    fn assert_same_positions(a: &[Option<glam::DVec2>], b: &[Option<glam::DVec2>]) {
        assert!(a.iter().any(Option::is_some), "{a:?}");
        assert_eq!(a.len(), b.len());
        for (p, q) in a.iter().zip(b) {
            match (p, q) {
                (Some(p), Some(q)) => assert!(p.distance(*q) < 1e-5, "{p} against {q}"),
                (None, None) => {}
                _ => panic!("{a:?} against {b:?}"),
            }
        }
    }

    /// A fixed Lidar's whole transform in the map decides, not the mount alone: upside down
    /// by a plain `map -> laser`, or by its base rolled over in the map under an upright
    /// mount, it is mirrored as tf2 resolves it. Only `base_link -> laser` had decided: the
    /// person seen 1.8 m off, on a third of the scans.
    #[test]
    fn an_upside_down_fixed_lidar_placed_by_its_transforms_is_mirrored_too() {
        let yaw = glam::DQuat::from_rotation_z(0.5);
        let flip = glam::DQuat::from_rotation_x(std::f64::consts::PI);
        let upright = person_positions(vec![rotated_tf("map", "laser", 0.2, yaw)], false);
        let by_map = person_positions(vec![rotated_tf("map", "laser", 0.2, yaw * flip)], true);
        assert_same_positions(&upright, &by_map);
        // The base rolled over in the map (0.2 along its x, which keeps its heading), the
        // mount upright at its origin.
        let by_base = person_positions(
            vec![
                rotated_tf("map", "base_link", 0.2, yaw * flip),
                rotated_tf("base_link", "laser", 0.0, glam::DQuat::IDENTITY),
            ],
            true,
        );
        assert_same_positions(&upright, &by_base);
    }

    /// An upright Lidar placed by `map -> laser` is where that puts it, as one placed at the
    /// same pose through its base: its scans are not mirrored.
    #[test]
    fn an_upright_fixed_lidar_placed_by_map_to_laser_is_not_mirrored() {
        let yaw = glam::DQuat::from_rotation_z(0.5);
        let by_map = person_positions(vec![rotated_tf("map", "laser", 0.2, yaw)], false);
        let by_mount = person_positions(vec![rotated_tf("base_link", "laser", 0.2, yaw)], false);
        assert_same_positions(&by_map, &by_mount);
        // The person, 1.5 m ahead and 1 m to the left of the Lidar, is found there (within
        // their 0.2 m radius: the points are on their near side).
        let person =
            glam::DVec2::new(0.2, 0.0) + glam::DVec2::from_angle(0.5).rotate((1.5, 1.0).into());
        let last = by_map.iter().flatten().last().expect("found");
        assert!(last.distance(person) < 0.2, "{last} against {person}");
    }

    #[test]
    fn a_tilted_mount_is_warned_about_once() {
        let mut stage = fixed_stage();
        let mount = |pitch: f64| TFMessage {
            transforms: vec![TransformStamped {
                header: Header::new(Time::default(), "base_link"),
                child_frame_id: "laser".into(),
                transform: Transform {
                    translation: Vector3::new(0.2, 0.0, 0.3),
                    rotation: quaternion(glam::DQuat::from_rotation_y(pitch)),
                },
            }],
        };
        stage.on_tf_static(&mount(0.01));
        scan_output(&mut stage, scan(0)).expect("localised");
        assert_eq!(stage.warning_counts().get(MOUNT_TILTED), None);
        stage.on_tf_static(&mount(0.2));
        stage.on_tf_static(&mount(0.3));
        scan_output(&mut stage, scan(MS)).expect("localised");
        assert_eq!(stage.warning_counts().get(MOUNT_TILTED), Some(&1));
        assert_eq!(stage.mount_source(), MountSource::TfStatic);
    }

    /// A fixed Lidar tilted by its transforms in the map is warned about as a tilted mount
    /// is, once; one the map's transforms level again is not.
    #[test]
    fn a_fixed_lidar_tilted_in_the_map_is_warned_about_once() {
        let pitch = glam::DQuat::from_rotation_y;
        let mut stage = fixed_stage();
        stage.on_tf_static(&TFMessage {
            transforms: vec![
                rotated_tf("map", "base_link", 1.0, pitch(-0.2)),
                rotated_tf("base_link", "laser", 0.2, pitch(0.2)),
            ],
        });
        scan_output(&mut stage, scan(0)).expect("localised");
        assert_eq!(stage.warning_counts().get(MOUNT_TILTED), None);
        let mut stage = fixed_stage();
        for k in 0..2 {
            stage.on_tf_static(&TFMessage {
                transforms: vec![rotated_tf("map", "laser", 1.0, pitch(0.2 + 0.1 * k as f64))],
            });
            scan_output(&mut stage, scan(k)).expect("localised");
        }
        assert_eq!(stage.warning_counts().get(MOUNT_TILTED), Some(&1));
    }

    /// A mount the localiser refuses (not finite) is not the one in use: `mount` had said
    /// `tf_static` all the same.
    #[test]
    fn a_mount_refused_as_not_finite_is_not_reported_as_in_use() {
        let mount = Pose2::new(0.15, 0.0, 0.0);
        let mut stage = stage_with_mount(mount);
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("base_link", "laser", f64::NAN, 0.0)],
        });
        let out = scan_output(&mut stage, scan(0)).expect("localised");
        assert_eq!(out.laser_pose, mount);
        assert_eq!(stage.mount_source(), MountSource::Configuration);
        assert_eq!(stage.warning_counts().get("non_finite"), Some(&1));
        // A finite one then is used.
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("base_link", "laser", 0.2, 0.0)],
        });
        let out = scan_output(&mut stage, scan(MS)).expect("localised");
        assert!(
            (out.laser_pose.x - 0.2).abs() < 1e-12,
            "{:?}",
            out.laser_pose
        );
        assert_eq!(stage.mount_source(), MountSource::TfStatic);
    }

    /// A stage for a Lidar fixed in an empty room.
    fn fixed_stage() -> LocaliserStage {
        LocaliserStage::new(
            LocaliserConfig::default(),
            RoomSource::Map(empty_room()),
            false,
        )
        .unwrap()
    }

    fn assert_near(pose: Pose2, expected: Pose2) {
        let d = pose.position().distance(expected.position());
        let turn = lidar_har_core::geometry::normalize_angle(pose.theta - expected.theta);
        assert!(d < 1e-9 && turn.abs() < 1e-9, "{pose:?}, not {expected:?}");
    }

    /// A fixed sensor's transforms as static_transform_publisher gives them: `map -> odom`
    /// and `odom -> base_link` on /tf_static. They had been ignored, and the Lidar put at the
    /// map origin: 1.9 m position error on a real layout.
    #[test]
    fn a_fixed_lidar_in_a_map_is_placed_by_its_transforms() {
        let mut stage = fixed_stage();
        stage.on_tf_static(&TFMessage {
            transforms: vec![
                tf("base_link", "laser", 0.2, 0.0),
                tf("map", "odom", 1.0, 0.5),
                tf("odom", "base_link", 2.0, 3.0),
            ],
        });
        let base = Pose2::new(1.0, 0.0, 0.5).compose(&Pose2::new(2.0, 0.0, 3.0));
        let out = scan_output(&mut stage, scan(0)).expect("localised");
        assert_near(out.laser_pose, base.compose(&Pose2::new(0.2, 0.0, 0.0)));
        // The latest transform counts, whatever carries it (a fixed Lidar's /tf is static).
        stage.on_tf(&TFMessage {
            transforms: vec![tf("map", "odom", -1.0, 0.0)],
        });
        let out = scan_output(&mut stage, scan(1)).expect("localised");
        let base = Pose2::new(-1.0, 0.0, 0.0).compose(&Pose2::new(2.0, 0.0, 3.0));
        assert_near(out.laser_pose, base.compose(&Pose2::new(0.2, 0.0, 0.0)));
        assert_eq!(stage.mount_source(), MountSource::TfStatic);
        assert!(
            stage.warning_counts().is_empty(),
            "{:?}",
            stage.warning_counts()
        );
    }

    #[test]
    fn a_fixed_lidar_without_transforms_is_at_the_map_origin_with_a_warning() {
        let mut stage = fixed_stage();
        for k in 0..3 {
            let out = scan_output(&mut stage, scan(k)).expect("localised");
            assert_eq!(out.laser_pose, Pose2::IDENTITY);
        }
        assert_eq!(stage.warning_counts().get(LIDAR_AT_MAP_ORIGIN), Some(&3));
        // A mount alone does not place the base.
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("base_link", "laser", 0.2, 0.0)],
        });
        scan_output(&mut stage, scan(3)).expect("localised");
        assert_eq!(stage.warning_counts().get(LIDAR_AT_MAP_ORIGIN), Some(&4));
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("map", "base_link", 1.0, 0.0)],
        });
        let out = scan_output(&mut stage, scan(4)).expect("localised");
        assert_near(out.laser_pose, Pose2::new(1.2, 0.0, 0.0));
        assert_eq!(stage.warning_counts().get(LIDAR_AT_MAP_ORIGIN), Some(&4));
    }

    /// A plain `static_transform_publisher map laser`: no chain reaches `base_link`, but tf2
    /// would place the scans from it. It had left the Lidar at the map origin.
    #[test]
    fn a_fixed_lidar_placed_by_a_transform_to_its_own_frame_is_there() {
        let mount = Pose2::new(0.15, -0.05, 0.2);
        let mut stage = stage_with_mount(mount);
        // Before the first scan names the laser frame.
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("map", "laser", 1.0, 0.5)],
        });
        let out = scan_output(&mut stage, scan(0)).expect("localised");
        assert_near(out.laser_pose, Pose2::new(1.0, 0.0, 0.5));
        // After it, through a chain, and from /tf as well.
        stage.on_tf(&TFMessage {
            transforms: vec![tf("map", "room", -2.0, 1.0), tf("room", "laser", 0.5, -0.5)],
        });
        let out = scan_output(&mut stage, scan(1)).expect("localised");
        let laser = Pose2::new(-2.0, 0.0, 1.0).compose(&Pose2::new(0.5, 0.0, -0.5));
        assert_near(out.laser_pose, laser);
        assert_eq!(stage.mount_source(), MountSource::Configuration);
        assert!(
            stage.warning_counts().is_empty(),
            "{:?}",
            stage.warning_counts()
        );
    }

    #[test]
    fn a_learned_background_says_when_it_was_never_learned() {
        let config = |learn_duration_s| {
            let mut config = LocaliserConfig::default();
            config.background.learn_duration_s = learn_duration_s;
            config
        };
        let learned = |learn_duration_s| {
            let mut stage = LocaliserStage::new(
                config(learn_duration_s),
                RoomSource::LearnedBackground,
                false,
            )
            .unwrap();
            // 4 s of scans, every 0.5 s.
            for k in 0..=8 {
                stage
                    .receive(
                        LocaliserInput::Scan(returning_scan(k * 500 * MS)),
                        k * 500 * MS,
                    )
                    .unwrap();
            }
            stage.finish().unwrap();
            stage
        };
        let stage = learned(3.0);
        assert_eq!(stage.scans_learning(), 6);
        assert!(!stage.learning_overdue_warned);
        assert!(
            stage.warning_counts().is_empty(),
            "{:?}",
            stage.warning_counts()
        );
        let stage = learned(10.0);
        assert_eq!(stage.scans_learning(), 9);
        assert_eq!(stage.warning_counts().get(BACKGROUND_NOT_LEARNED), Some(&1));
        assert!(!stage.learning_overdue_warned, "4 s is not twice 10 s");
        // Scans whose stamp never moves on never complete it: that is said while the input
        // lasts, once twice the learning time has passed since the first scan came.
        let mut stage =
            LocaliserStage::new(config(1.5), RoomSource::LearnedBackground, false).unwrap();
        for k in 0..=7 {
            assert!(!stage.learning_overdue_warned, "at {k}");
            stage
                .receive(LocaliserInput::Scan(returning_scan(0)), k * 500 * MS)
                .unwrap();
        }
        assert!(stage.learning_overdue_warned);
        // Nor do scans without a return, however long they come: a background is learned
        // only from scans that see something of the room.
        let mut stage =
            LocaliserStage::new(config(1.5), RoomSource::LearnedBackground, false).unwrap();
        for k in 0..=7 {
            stage
                .receive(LocaliserInput::Scan(scan(k * 500 * MS)), k * 500 * MS)
                .unwrap();
        }
        assert!(stage.learning_overdue_warned);
        assert_eq!(stage.scans_learning(), 8);
    }

    #[test]
    fn warnings_are_counted_by_kind() {
        let mut stage =
            LocaliserStage::new(LocaliserConfig::default(), RoomSource::MapTopic, false).unwrap();
        for k in 0..5 {
            assert!(scan_output(&mut stage, scan(k)).is_none());
        }
        assert_eq!(stage.warning_counts().get("no_map"), Some(&5));
    }

    #[test]
    fn learned_background_reports_in_the_laser_frame() {
        let mut stage = LocaliserStage::new(
            LocaliserConfig::default(),
            RoomSource::LearnedBackground,
            false,
        )
        .unwrap();
        assert!(scan_output(&mut stage, scan(0)).is_none(), "learning");
        assert_eq!(stage.output_frame(), "laser");
    }

    const MS: i64 = 1_000_000;

    fn moving_stage() -> LocaliserStage {
        LocaliserStage::new(
            LocaliserConfig::default(),
            RoomSource::Map(empty_room()),
            true,
        )
        .unwrap()
    }

    /// The x of each scan's Lidar pose in `step`, in order (`None`: skipped).
    fn placed_x(step: &Step) -> Vec<Option<f64>> {
        step.scans
            .iter()
            .map(|s| s.output.as_ref().map(|o| o.laser_pose.x))
            .collect()
    }

    #[test]
    fn scans_before_their_odometry_wait_for_it_and_keep_their_order() {
        let mut stage = moving_stage();
        // Odometry 150 ms late: each sample comes 150 ms after its stamp.
        let step = stage.receive(odometry(0, 0.0), 150 * MS).unwrap();
        assert!(step.scans.is_empty());
        for k in 1..=3 {
            let step = stage.receive(LocaliserInput::Scan(scan(k * 100 * MS)), k * 100 * MS);
            assert!(step.unwrap().scans.is_empty(), "scan {k} waits");
        }
        assert_eq!(stage.wait_deadline_ns(), Some(600 * MS));
        let step = stage.receive(odometry(200 * MS, 0.2), 350 * MS).unwrap();
        assert_eq!(placed_x(&step), [Some(0.1), Some(0.2)]);
        assert_eq!(step.outgoing.len(), 2, "markers of both scans");
        let step = stage.receive(odometry(300 * MS, 0.3), 450 * MS).unwrap();
        assert_eq!(placed_x(&step), [Some(0.3)]);
        assert_eq!(stage.wait_deadline_ns(), None);
        assert!(
            stage.warning_counts().is_empty(),
            "{:?}",
            stage.warning_counts()
        );
    }

    #[test]
    fn a_scan_measured_from_beam_zero_waits_for_odometry_to_the_end_of_its_sweep() {
        let mut stage = moving_stage();
        // 11 beams 20 ms apart, beam 0 first: the last beam is measured 200 ms after the stamp.
        let mut swept = scan(100 * MS);
        swept.ranges = vec![f32::INFINITY; 11];
        swept.time_increment = 0.02;
        stage.receive(odometry(0, 0.0), 0).unwrap();
        let step = stage
            .receive(LocaliserInput::Scan(swept), 110 * MS)
            .unwrap();
        assert!(step.scans.is_empty());
        let step = stage.receive(odometry(200 * MS, 0.2), 210 * MS).unwrap();
        assert!(step.scans.is_empty(), "odometry at the stamp only");
        let step = stage.receive(odometry(300 * MS, 0.3), 310 * MS).unwrap();
        assert_eq!(placed_x(&step), [Some(0.1)]);
        assert!(
            stage.warning_counts().is_empty(),
            "{:?}",
            stage.warning_counts()
        );
    }

    #[test]
    fn a_scan_whose_wait_runs_out_is_placed_with_what_there_is() {
        let mut stage = moving_stage();
        stage.receive(odometry(0, 0.0), 0).unwrap();
        stage.receive(odometry(100 * MS, 0.1), 100 * MS).unwrap();
        let step = stage.receive(LocaliserInput::Scan(scan(150 * MS)), 150 * MS);
        assert!(step.unwrap().scans.is_empty());
        let step = stage.receive(LocaliserInput::Scan(scan(400 * MS)), 400 * MS);
        assert!(step.unwrap().scans.is_empty());
        assert!(stage.release_expired(649 * MS).unwrap().scans.is_empty());
        // Extrapolated 50 ms, within `max_extrapolation_s`.
        let step = stage.release_expired(650 * MS).unwrap();
        let [Some(x)] = placed_x(&step)[..] else {
            panic!("{:?}", placed_x(&step));
        };
        assert!((x - 0.15).abs() < 1e-9, "{x}");
        // A message after the next deadline lets that scan go before it is taken in: the
        // odometry it brings comes too late for it, as on a node's clock.
        let step = stage.receive(odometry(400 * MS, 0.4), 901 * MS).unwrap();
        assert_eq!(placed_x(&step), [None]);
        assert_eq!(stage.warning_counts().get("odometry_stale"), Some(&1));
    }

    #[test]
    fn scans_waiting_when_the_input_ends_are_localised() {
        let mut stage = moving_stage();
        stage.receive(odometry(0, 0.0), 0).unwrap();
        stage
            .receive(LocaliserInput::Scan(scan(50 * MS)), 50 * MS)
            .unwrap();
        assert_eq!(placed_x(&stage.finish().unwrap()), [Some(0.0)]);
        assert_eq!(stage.wait_deadline_ns(), None);
    }

    /// static_transform_publisher's `map -> odom` (a known start pose, no AMCL) had been kept
    /// for the mount's chains only: a moving robot's scans were placed as if `map` were
    /// `odom`, the person 1-2 m off.
    #[test]
    fn a_static_map_to_odom_corrects_a_moving_robots_odometry() {
        let mut stage = moving_stage();
        let map_to_odom = tf("map", "odom", 1.0, 0.5);
        stage.on_tf_static(&TFMessage {
            transforms: vec![map_to_odom.clone()],
        });
        let mount = LocaliserConfig::default().mount;
        let start = Pose2::new(1.0, 0.0, 0.5);
        let out = placed_with_odometry(&mut stage, 0).expect("localised");
        assert_near(out, start.compose(&mount));
        // /tf corrects it as before; the static one coming again (a late joiner's latched
        // message) does not undo that.
        stage.receive(tf_at("map", "odom", -1.0, MS), MS).unwrap();
        stage.on_tf_static(&TFMessage {
            transforms: vec![map_to_odom, tf("base_link", "laser", 0.0, 0.0)],
        });
        let out = placed_with_odometry(&mut stage, MS).expect("localised");
        assert_near(out, Pose2::new(-1.0, 0.0, 0.0));
        assert!(
            stage.warning_counts().is_empty(),
            "{:?}",
            stage.warning_counts()
        );
    }

    /// A `map -> odom` reached through a chain of static frames counts too, as tf2 resolves it.
    #[test]
    fn a_static_chain_from_map_to_odom_corrects_a_moving_robots_odometry() {
        let mut stage = moving_stage();
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("world", "odom", 0.5, 0.0)],
        });
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("map", "world", 1.0, 0.0)],
        });
        let out = placed_with_odometry(&mut stage, 0).expect("localised");
        assert_near(
            out,
            Pose2::new(1.5, 0.0, 0.0).compose(&LocaliserConfig::default().mount),
        );
    }

    /// AMCL publishes `map -> odom` only once it has an initial pose; with
    /// `wait_for_map_to_odom` the scans before it are skipped, as tf2 would refuse to place
    /// them, and counted.
    #[test]
    fn scans_before_the_first_map_to_odom_are_skipped_when_waiting_for_it() {
        let mut stage = moving_stage();
        stage.set_wait_for_map_to_odom(true);
        for k in 0..3 {
            assert_eq!(placed_with_odometry(&mut stage, k * MS), None, "scan {k}");
        }
        assert_eq!(
            stage.warning_counts().get(WAITING_FOR_MAP_TO_ODOM),
            Some(&3)
        );
        stage
            .receive(tf_at("map", "odom", 2.0, 3 * MS), 3 * MS)
            .unwrap();
        let out = placed_with_odometry(&mut stage, 3 * MS).expect("localised");
        assert!((out.x - 2.0).abs() < 1e-12, "{out:?}");
        assert_eq!(
            stage.warning_counts().get(WAITING_FOR_MAP_TO_ODOM),
            Some(&3)
        );
        assert_eq!(
            stage.warning_counts().get(LOCALISED_BEFORE_MAP_TO_ODOM),
            None
        );
        // From /tf_static as well.
        let mut stage = moving_stage();
        stage.set_wait_for_map_to_odom(true);
        assert_eq!(placed_with_odometry(&mut stage, 0), None);
        stage.on_tf_static(&TFMessage {
            transforms: vec![tf("map", "odom", 2.0, 0.0)],
        });
        assert!(placed_with_odometry(&mut stage, MS).is_some());
        assert_eq!(
            stage.warning_counts().get(WAITING_FOR_MAP_TO_ODOM),
            Some(&1)
        );
    }

    /// Not waiting, the scans before a late first `map -> odom` are placed as if `map` were
    /// `odom` (right for a robot that never publishes one), but once one comes that is said,
    /// with how many scans: they had been misplaced without a word.
    #[test]
    fn scans_placed_before_a_late_first_map_to_odom_are_counted_when_it_comes() {
        let mut stage = moving_stage();
        for k in 0..3 {
            let out = placed_with_odometry(&mut stage, k * MS).expect("localised");
            assert!(out.x.abs() < 1e-12, "{out:?}");
        }
        assert!(
            stage.warning_counts().is_empty(),
            "{:?}",
            stage.warning_counts()
        );
        stage
            .receive(tf_at("map", "odom", 2.0, 3 * MS), 3 * MS)
            .unwrap();
        assert_eq!(
            stage.warning_counts().get(LOCALISED_BEFORE_MAP_TO_ODOM),
            Some(&3)
        );
        placed_with_odometry(&mut stage, 3 * MS).expect("localised");
        stage
            .receive(tf_at("map", "odom", 2.5, 4 * MS), 4 * MS)
            .unwrap();
        assert_eq!(
            stage.warning_counts().get(LOCALISED_BEFORE_MAP_TO_ODOM),
            Some(&3)
        );
        // One there from the start says nothing.
        let mut stage = moving_stage();
        stage.receive(tf_at("map", "odom", 2.0, 0), 0).unwrap();
        placed_with_odometry(&mut stage, 0).expect("localised");
        assert!(
            stage.warning_counts().is_empty(),
            "{:?}",
            stage.warning_counts()
        );
    }

    /// REP 105: `odom -> base_link` on /tf is the odometry (robot_localization's fused pose)
    /// while the base may publish raw wheel odometry on /odom. /odom had won: 0.4 m of wheel
    /// drift put the person 2.2 m off. Whichever comes first, /tf wins once seen, and the
    /// samples /odom gave before are forgotten, not mixed with its.
    #[test]
    fn odom_to_base_link_on_tf_wins_over_a_disagreeing_odom_topic() {
        for odom_first in [true, false] {
            let mut stage = moving_stage();
            for k in 0..3 {
                let (odom, tf) = (
                    odometry(k * MS, 0.4),
                    tf_at("odom", "base_link", 0.0, k * MS),
                );
                let (first, second) = if odom_first { (odom, tf) } else { (tf, odom) };
                stage.receive(first, k * MS).unwrap();
                stage.receive(second, k * MS).unwrap();
            }
            let out = scan_output(&mut stage, scan(2 * MS)).expect("localised");
            assert!(out.laser_pose.x.abs() < 1e-12, "{:?}", out.laser_pose);
            assert!(
                stage.warning_counts().is_empty(),
                "{:?}",
                stage.warning_counts()
            );
        }
        // A host that knows /tf will carry it ignores /odom from the start.
        let mut stage = moving_stage();
        stage.take_odometry_from_tf();
        stage.receive(odometry(0, 0.4), 0).unwrap();
        assert_eq!(stage.localiser().latest_odometry_ns(), None);
    }

    /// A base that publishes no `odom -> base_link` keeps /odom as its odometry, whatever
    /// else /tf carries; /odom naming other frames than the configured ones is warned about
    /// once, and still used.
    #[test]
    fn the_odom_topic_is_the_odometry_when_tf_has_none() {
        let mut stage = moving_stage();
        stage.receive(tf_at("map", "odom", 1.0, 0), 0).unwrap();
        stage.receive(tf_at("odom", "other", 9.0, 0), 0).unwrap();
        let mut footprint = odometry(0, 0.4);
        if let LocaliserInput::Odometry(odom) = &mut footprint {
            odom.child_frame_id = "base_footprint".into();
        }
        stage.receive(footprint, 0).unwrap();
        stage.receive(odometry(MS, 0.4), MS).unwrap();
        let out = scan_output(&mut stage, scan(MS)).expect("localised");
        assert!(
            (out.laser_pose.x - 1.4).abs() < 1e-12,
            "{:?}",
            out.laser_pose
        );
        assert_eq!(stage.warning_counts().get(ODOM_FRAMES_UNEXPECTED), Some(&1));
    }

    /// A /map whose grid does not fit its size is refused; that had been only logged, and
    /// summary.json said `no_map` as if none had come.
    #[test]
    fn a_refused_map_is_counted() {
        let mut stage =
            LocaliserStage::new(LocaliserConfig::default(), RoomSource::MapTopic, true).unwrap();
        let mut grid = OccupancyGrid::default();
        grid.info.resolution = 0.1;
        grid.info.width = 10;
        grid.info.height = 10;
        grid.data = vec![0; 95];
        stage.receive(LocaliserInput::Map(grid), 0).unwrap();
        assert_eq!(stage.warning_counts().get(MAP_REFUSED), Some(&1));
    }

    #[test]
    fn a_fixed_lidar_never_waits_for_odometry() {
        let mut stage = LocaliserStage::new(
            LocaliserConfig::default(),
            RoomSource::Map(empty_room()),
            false,
        )
        .unwrap();
        assert!(scan_output(&mut stage, scan(0)).is_some());
    }
}
