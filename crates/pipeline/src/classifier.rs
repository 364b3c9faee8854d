//! The classifier stage: /human/observation in; /human/activity, /human/fall_alert and a text
//! marker on /human/markers out. It works from the `HumanObservation` message alone (points,
//! position, visibility, sensor position, stamp), so the classifier node, which subscribes
//! only to /human/observation, and `lidar-har run`, which gets the localiser's observation in
//! process, run exactly the same code.
//!
//! Per observation: the person's points become the model's image, the model's two staggered
//! states step (core `StreamingClassifier`), and the probabilities feed the fall alerts (core
//! `FallDetector`). An activity is published once the model has enough history (`T/2` scans)
//! and only for scans where the person is visible: a hidden person's class is not known.
//! With a pose head (core `pose_head`), the pelvis is published on /human/pelvis where the
//! head places it better than the localiser.

use std::path::{Path, PathBuf};

use glam::DVec2;
use lidar_har_bag::BagError;
use lidar_har_core::activity::Activity;
use lidar_har_core::classifier::{
    LaneSchedule, PersonScan, Prediction, StepError, StepModel, StreamSpec, StreamSpecError,
    StreamingClassifier,
};
use lidar_har_core::fall::{
    AlertKind, FallAlert, FallAlertConfig, FallConfigError, FallDetector, FallInput,
};
use lidar_har_core::geometry::MainAxisSpan;
use lidar_har_core::metrics::{ConfusionMatrix, MetricsReport};
use lidar_har_core::pose_head::{NoPoseHead, PelvisPlacer, PersonAt, PoseHead, PoseHeadSpec};
use lidar_har_core::stats::{Spread, SpreadTally, upper_median};
use lidar_har_core::truth_match::{Around, TruthMatcher};
use lidar_har_infer::{ActivityModel, InferError, PoseHeadModel};
use lidar_har_msgs::CdrError;
use lidar_har_msgs::builtin_interfaces::{Duration, Time};
use lidar_har_msgs::geometry_msgs::{
    Point, Pose, PoseWithCovariance, PoseWithCovarianceStamped, Quaternion, Vector3,
};
use lidar_har_msgs::lidar_har_msgs::{self as har, HumanObservation};
use lidar_har_msgs::std_msgs::{ColorRGBA, Header};
use lidar_har_msgs::topics::{self, TopicSpec};
use lidar_har_msgs::visualization_msgs::{Marker, MarkerArray};
use serde::{Deserialize, Serialize};

use crate::bag_run::OutputBag;
use crate::{Outgoing, PipelineError};

/// `config/classifier.yaml`. Every key is optional; unknown keys are errors.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClassifierConfig {
    /// The ONNX step model; relative paths are taken from the working directory.
    pub model: PathBuf,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
    /// Each staggered model state (lane) restarts every this many training windows (`T`,
    /// from the model's metadata); at least 1.
    pub lane_period_windows: f64,
    /// Model states stepped side by side, restarting in turn: every prediction has between
    /// `1 - 1/lanes` of the lane period and all of it behind it, for one step per lane.
    pub lanes: usize,
    /// The pose head for /human/pelvis (docs/model_contract.md, "Pose head"); `None`: none.
    /// When it cannot be used (missing, or fitted on another activity model) the classifier
    /// runs without it and says why: a pelvis is never worth losing the fall alerts for.
    #[serde(deserialize_with = "deserialize_pose_head")]
    pub pose_head: Option<PathBuf>,
    /// While the person is hidden, /human/pelvis stays at the last seen offset from the
    /// track's prediction for this long, s (0: only on seen scans).
    pub pelvis_hold_s: f64,
    /// A person read lying or sitting on the floor gets the pelvis combined over the scans
    /// since, while each scan's own lies within this of it, m (0: every scan's own).
    pub pelvis_floor_fusion_m: f64,
    /// ... until they are read as anything else for this long, s (shorter readings get
    /// their own pelvis and leave the combination as it was).
    pub pelvis_floor_fusion_gap_s: f64,
    /// With a pose head, this many more states restart between each two lanes: more views of
    /// the same scans for the head to combine. A model step each; the activity and the
    /// alerts stay as the lanes alone give them.
    pub pose_head_lanes_between: usize,
    pub fall_alert: FallAlertConfig,
}

impl Default for ClassifierConfig {
    fn default() -> Self {
        Self {
            model: PathBuf::from("models/activity.onnx"),
            threads: 1,
            lane_period_windows: 1.2,
            lanes: 2,
            pose_head: Some(PathBuf::from("models/pose_head.onnx")),
            pelvis_hold_s: 1.0,
            pelvis_floor_fusion_m: 1.0,
            pelvis_floor_fusion_gap_s: 0.25,
            pose_head_lanes_between: 1,
            fall_alert: FallAlertConfig::default(),
        }
    }
}

/// A `pose_head` setting as a file or YAML `null` gives it, or as the classifier node's
/// `pose_head` parameter does: `none` is no head, in both, rather than a file of that name.
pub fn pose_head_setting(value: Option<PathBuf>) -> Option<PathBuf> {
    value.filter(|path| path.as_os_str() != "none")
}

fn deserialize_pose_head<'de, D>(deserializer: D) -> Result<Option<PathBuf>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    Option::<PathBuf>::deserialize(deserializer).map(pose_head_setting)
}

impl ClassifierConfig {
    /// The lanes for a model trained on windows of `window` scans, with or without a pose
    /// head to serve.
    pub fn lane_schedule(&self, window: usize, pose_head: bool) -> LaneSchedule {
        LaneSchedule {
            period: (self.lane_period_windows * window as f64).round() as usize,
            lanes: self.lanes,
            lanes_between: if pose_head {
                self.pose_head_lanes_between
            } else {
                0
            },
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ClassifierError {
    #[error("cannot read classifier configuration {}: {cause}", path.display())]
    ConfigRead {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("classifier configuration{}: {message}", path.as_ref().map(|p| format!(" {}", p.display())).unwrap_or_default())]
    Config {
        path: Option<PathBuf>,
        message: String,
    },
    #[error(transparent)]
    Model(#[from] InferError),
    #[error(transparent)]
    Stream(#[from] StreamSpecError),
    /// The configuration's `lanes` / `lane_period_windows` against the model's window: which
    /// model it was is known only here.
    #[error(
        "lanes = {lanes} and lane_period_windows = {lane_period_windows} do not fit model {} \
         (a window of {window} scans): {cause}",
        model.display()
    )]
    LanesDoNotFit {
        model: PathBuf,
        window: usize,
        lanes: usize,
        lane_period_windows: f64,
        cause: StreamSpecError,
    },
    #[error(transparent)]
    FallConfig(#[from] FallConfigError),
    #[error(transparent)]
    Step(#[from] StepError),
}

/// Parses and validates configuration text (the file, or a ROS parameter value).
pub fn parse_classifier_config(text: &str) -> Result<ClassifierConfig, ClassifierError> {
    let config: ClassifierConfig =
        serde_yaml_ng::from_str(text).map_err(|e| ClassifierError::Config {
            path: None,
            message: e.to_string(),
        })?;
    config.fall_alert.validate()?;
    if config.threads == 0 {
        return Err(ClassifierError::Config {
            path: None,
            message: "threads must be at least 1".into(),
        });
    }
    let windows = config.lane_period_windows;
    if !(windows.is_finite() && (1.0..=10.0).contains(&windows)) {
        return Err(ClassifierError::Config {
            path: None,
            message: format!("lane_period_windows = {windows} is out of range (1..=10)"),
        });
    }
    if !(2..=8).contains(&config.lanes) {
        return Err(ClassifierError::Config {
            path: None,
            message: format!("lanes = {} is out of range (2..=8)", config.lanes),
        });
    }
    if config.pose_head_lanes_between > 3 {
        return Err(ClassifierError::Config {
            path: None,
            message: format!(
                "pose_head_lanes_between = {} is out of range (0..=3)",
                config.pose_head_lanes_between
            ),
        });
    }
    for (key, value) in [
        ("pelvis_hold_s", config.pelvis_hold_s),
        ("pelvis_floor_fusion_m", config.pelvis_floor_fusion_m),
        (
            "pelvis_floor_fusion_gap_s",
            config.pelvis_floor_fusion_gap_s,
        ),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(ClassifierError::Config {
                path: None,
                message: format!("{key} = {value} must be finite and not negative"),
            });
        }
    }
    Ok(config)
}

/// `config` with one setting changed, given as `key=value` with the value in YAML: to score a
/// variant of the alert rules without writing a file for it.
pub fn with_fall_alert_setting(
    config: &FallAlertConfig,
    setting: &str,
) -> Result<FallAlertConfig, ClassifierError> {
    let refuse = |why: String| ClassifierError::Config {
        path: None,
        message: format!("fall_alert setting `{setting}`: {why}"),
    };
    let (key, value) = setting
        .split_once('=')
        .ok_or_else(|| refuse("expected KEY=VALUE".into()))?;
    let value: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(value).map_err(|e| refuse(e.to_string()))?;
    let mut settings = serde_yaml_ng::to_value(config).map_err(|e| refuse(e.to_string()))?;
    let Some(slot) = settings.get_mut(key.trim()) else {
        let known: Vec<&str> = (settings.as_mapping().into_iter())
            .flat_map(|m| m.keys().filter_map(|k| k.as_str()))
            .collect();
        return Err(refuse(format!(
            "no such setting; known: {}",
            known.join(", ")
        )));
    };
    *slot = value;
    let changed: FallAlertConfig =
        serde_yaml_ng::from_value(settings).map_err(|e| refuse(e.to_string()))?;
    changed.validate()?;
    Ok(changed)
}

/// Loads `config/classifier.yaml` (or another file of that format).
pub fn load_classifier_config(path: &Path) -> Result<ClassifierConfig, ClassifierError> {
    let text = std::fs::read_to_string(path).map_err(|source| ClassifierError::ConfigRead {
        path: path.into(),
        cause: source,
    })?;
    parse_classifier_config(&text).map_err(|e| match e {
        ClassifierError::Config { message, .. } => ClassifierError::Config {
            path: Some(path.into()),
            message,
        },
        other => ClassifierError::Config {
            path: Some(path.into()),
            message: other.to_string(),
        },
    })
}

/// What one observation produced.
#[derive(Debug, Clone, PartialEq)]
pub struct ClassifierOutput {
    pub stamp_ns: i64,
    pub frame_id: String,
    pub visible: bool,
    /// The person's position (the localiser's prediction when not visible).
    pub position: DVec2,
    pub prediction: Prediction,
    /// The pelvis from the pose head, when it placed one.
    pub pelvis: Option<Pelvis>,
    /// How far the person's points stretch along their main axis, as the fall alerts took
    /// it; `None` when not visible.
    pub body_length_m: Option<f64>,
    /// Alerts raised by this observation, their times in seconds since the stamps' zero.
    pub alerts: Vec<FallAlert>,
    /// The stamp each of `alerts` names as its `event_time` on /human/fall_alert, ns: exact,
    /// where the seconds in `alerts` are not (f64 seconds since the epoch lose nanoseconds).
    pub alert_event_ns: Vec<i64>,
}

/// The pelvis the pose head placed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pelvis {
    pub position: DVec2,
    /// Covariance of (x, y), m^2: the track's and the head's own error.
    pub covariance: [[f64; 2]; 2],
}

/// Whether the stage has a pose head, for `summary.json` and the logs.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum PoseHeadStatus {
    /// None configured.
    Off,
    Used {
        #[serde(serialize_with = "crate::bag_run::path_as_text")]
        path: PathBuf,
    },
    /// Configured but unusable; the classifier runs without it.
    NotUsed {
        #[serde(serialize_with = "crate::bag_run::path_as_text")]
        path: PathBuf,
        reason: String,
    },
}

impl std::fmt::Display for PoseHeadStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PoseHeadStatus::Off => f.write_str("off"),
            PoseHeadStatus::Used { path } => write!(f, "{}", path.display()),
            PoseHeadStatus::NotUsed { path, reason } => {
                write!(f, "{} not used: {reason}", path.display())
            }
        }
    }
}

impl ClassifierOutput {
    pub fn publishable(&self) -> bool {
        publishable(self.visible, self.prediction.ready)
    }
}

/// Whether a scan's activity is worth publishing, and is read by the fall alerts: the person
/// is visible (a hidden person's activity is unknown) and the model has its minimum history.
pub fn publishable(visible: bool, ready: bool) -> bool {
    visible && ready
}

/// What the fall alerts are fed for one scan: the position only where the activity is
/// [`publishable`]. `lidar-har alerts --readings` replays the alerts through this too.
pub fn fall_input(
    stamp_s: f64,
    visible: bool,
    ready: bool,
    position: DVec2,
    probabilities: [f32; Activity::COUNT],
    body_length_m: Option<f64>,
) -> FallInput {
    FallInput {
        stamp_s,
        position: publishable(visible, ready).then_some(position),
        probabilities,
        body_length_m,
    }
}

/// The fall alerts' clock: seconds from the first stamp of the stream (since a reset). Seconds
/// since the epoch as f64 resolve only ~240 ns, so an alert's time turned back into a stamp
/// named no scan; counted from the stream's start, times turn back into the exact stamp for
/// 2^22 s (48 days) of stream, and to within a nanosecond after that.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StreamClock {
    start_ns: Option<i64>,
}

impl StreamClock {
    /// A stamp in stream time; the first one since a reset starts the stream.
    pub fn seconds(&mut self, stamp_ns: i64) -> f64 {
        let start_ns = *self.start_ns.get_or_insert(stamp_ns);
        // One rounding (a division by the exact 1e9), so that `stamp_ns` undoes it.
        stamp_ns.saturating_sub(start_ns) as f64 / 1e9
    }

    /// The stamp of a time in stream time, ns.
    pub fn stamp_ns(&self, s: f64) -> i64 {
        self.start_ns
            .unwrap_or(0)
            .saturating_add((s * 1e9).round() as i64)
    }

    /// Seconds since the stamps' zero (the epoch, for wall-clock stamps) of a time in stream
    /// time: what the rest of the stage's outputs count in.
    pub fn stamp_s(&self, s: f64) -> f64 {
        self.stamp_ns(s) as f64 * 1e-9
    }

    /// An alert raised in stream time, its times in seconds since the stamps' zero.
    pub fn alert_in_stamp_time(&self, alert: &FallAlert) -> FallAlert {
        FallAlert {
            event_time_s: self.stamp_s(alert.event_time_s),
            raised_at_s: self.stamp_s(alert.raised_at_s),
            down_since_s: self.stamp_s(alert.down_since_s),
            ..*alert
        }
    }

    /// The next stamp starts the stream afresh.
    pub fn reset(&mut self) {
        self.start_ns = None;
    }
}

/// The time an alert's `event_time` names: the fall's start for FALL_DETECTED, since when
/// the person is down for PERSON_DOWN.
pub fn event_time_s(alert: &FallAlert) -> f64 {
    match alert.kind {
        AlertKind::FallDetected => alert.event_time_s,
        AlertKind::PersonDown => alert.down_since_s,
    }
}

/// The stage's messages for one observation.
#[derive(Debug, Clone, PartialEq)]
pub struct ClassifierMessages {
    pub activity: Option<har::Activity>,
    pub pelvis: Option<PoseWithCovarianceStamped>,
    pub alerts: Vec<har::FallAlert>,
    pub markers: MarkerArray,
}

/// Streaming classifier plus fall alerts over a step model (the ONNX one in production), and
/// the pose head `H` that reads its state, if any.
pub struct ClassifierStage<M: StepModel = ActivityModel, H = PoseHeadModel> {
    classifier: StreamingClassifier<M>,
    pelvis: Option<PelvisPlacer<H>>,
    pose_head: PoseHeadStatus,
    /// Scans on which the pose head failed (logged at powers of two).
    pose_head_errors: u64,
    /// Observations marked visible with a position that is not finite (logged at powers of
    /// two).
    non_finite_positions: u64,
    scan_rate: ScanRate,
    fall: FallDetector,
    /// The fall alerts run on it, so that their event times turn back into exact stamps.
    alert_clock: StreamClock,
    points: Vec<DVec2>,
    track_id: Option<u32>,
    alerts_raised: usize,
    /// The latest alert, shown in the text marker.
    last_alert: Option<FallAlert>,
    /// The last observation's stamp: one before it starts the stream afresh.
    last_stamp_ns: Option<i64>,
}

impl ClassifierStage<ActivityModel, PoseHeadModel> {
    /// The topics the stage reads.
    pub const INPUTS: [TopicSpec; 1] = [topics::HUMAN_OBSERVATION];
    /// The topics the stage writes.
    pub const OUTPUTS: [TopicSpec; 4] = [
        topics::HUMAN_ACTIVITY,
        topics::HUMAN_PELVIS,
        topics::FALL_ALERT,
        topics::HUMAN_MARKERS,
    ];

    /// Loads the model named by `config` (or `model`, when given) and the pose head, if the
    /// configuration names one that fits the model.
    pub fn load(config: &ClassifierConfig, model: Option<&Path>) -> Result<Self, ClassifierError> {
        let path = model.unwrap_or(&config.model);
        let model = ActivityModel::load(path, config.threads)?;
        let stream = model.info().stream;
        let (pelvis, status) = match &config.pose_head {
            None => (None, PoseHeadStatus::Off),
            // The head's states between the lanes must fit in the lane period, which only the
            // model's window sets; without room for them the activity and the alerts still run.
            Some(head_path) if let Some(reason) = no_room_for_the_head(config, stream.window) => {
                log::warn!("classifier: no /human/pelvis: {reason}");
                (
                    None,
                    PoseHeadStatus::NotUsed {
                        path: head_path.clone(),
                        reason,
                    },
                )
            }
            Some(head_path) => match PoseHeadModel::load(head_path, &model, config.threads) {
                // A head that asks for more history than any state reaches would never place
                // a pelvis, and nothing would say why.
                Ok(head)
                    if let Some(reason) =
                        history_out_of_reach(&head, config, path, stream.window) =>
                {
                    log::warn!("classifier: no /human/pelvis: {reason}");
                    (
                        None,
                        PoseHeadStatus::NotUsed {
                            path: head_path.clone(),
                            reason,
                        },
                    )
                }
                Ok(head) => (
                    Some(
                        PelvisPlacer::new(head.spec().clone(), head)
                            .holding_for(config.pelvis_hold_s)
                            .fusing_on_floor_within(
                                config.pelvis_floor_fusion_m,
                                config.pelvis_floor_fusion_gap_s,
                            ),
                    ),
                    PoseHeadStatus::Used {
                        path: head_path.clone(),
                    },
                ),
                Err(e) => {
                    log::warn!("classifier: no /human/pelvis: {e}");
                    (
                        None,
                        PoseHeadStatus::NotUsed {
                            path: head_path.clone(),
                            reason: e.to_string(),
                        },
                    )
                }
            },
        };
        let schedule = config.lane_schedule(stream.window, pelvis.is_some());
        let stage = ClassifierStage::with_schedule(model, stream, schedule, config.fall_alert)
            .map_err(|e| lanes_do_not_fit(e, config, path, stream.window))?;
        Ok(stage.with_pose_head(pelvis, status))
    }
}

/// A lane schedule refused for `model` (of `window` scans) as [`ClassifierError::LanesDoNotFit`],
/// naming the model and the settings; other errors as they are.
fn lanes_do_not_fit(
    e: ClassifierError,
    config: &ClassifierConfig,
    model: &Path,
    window: usize,
) -> ClassifierError {
    match e {
        ClassifierError::Stream(
            cause @ (StreamSpecError::LanePeriod { .. }
            | StreamSpecError::LaneCount { .. }
            | StreamSpecError::LanesBetween { .. }),
        ) => ClassifierError::LanesDoNotFit {
            model: model.to_path_buf(),
            window,
            lanes: config.lanes,
            lane_period_windows: config.lane_period_windows,
            cause,
        },
        other => other,
    }
}

/// Why `config`'s lanes leave no room for the pose head's states between them with a model of
/// `window` scans, if they do not.
fn no_room_for_the_head(config: &ClassifierConfig, window: usize) -> Option<String> {
    let schedule = config.lane_schedule(window, true);
    (schedule.states() > schedule.period).then(|| {
        format!(
            "{} lanes with pose_head_lanes_between = {} more between each two make {} states, \
             more than the lane period's {} scans (lane_period_windows x the model's window of \
             {window}): lower pose_head_lanes_between or lanes",
            schedule.lanes,
            schedule.lanes_between,
            schedule.states(),
            schedule.period
        )
    })
}

/// Why `head` would never place a pelvis under `config`'s lanes with `model` (of `window`
/// scans), if so: it reads only states with `min_history` frames behind them, and every state
/// restarts after the lane period.
fn history_out_of_reach(
    head: &PoseHeadModel,
    config: &ClassifierConfig,
    model: &Path,
    window: usize,
) -> Option<String> {
    let min_history = head.spec().min_history;
    let period = config.lane_schedule(window, true).period;
    (min_history > period).then(|| {
        format!(
            "pose head {} reads states with at least {min_history} scans behind them \
             ({}), more than the lane period's {period} scans (lane_period_windows = {} x \
             the window of {window} scans of model {}), after which every state restarts: \
             raise lane_period_windows, or use a head fitted from an earlier step",
            head.path().display(),
            PoseHeadSpec::KEY_MIN_HISTORY,
            config.lane_period_windows,
            model.display()
        )
    })
}

impl<M: StepModel> ClassifierStage<M, NoPoseHead> {
    /// Two lanes restarting every `T` scans (the model's window).
    pub fn new(
        model: M,
        stream: StreamSpec,
        fall_alert: FallAlertConfig,
    ) -> Result<Self, ClassifierError> {
        Self::with_schedule(
            model,
            stream,
            LaneSchedule::for_window(stream.window),
            fall_alert,
        )
    }

    pub fn with_schedule(
        model: M,
        stream: StreamSpec,
        schedule: LaneSchedule,
        fall_alert: FallAlertConfig,
    ) -> Result<Self, ClassifierError> {
        Ok(Self {
            classifier: StreamingClassifier::with_schedule(model, stream, schedule)?,
            pelvis: None,
            pose_head: PoseHeadStatus::Off,
            pose_head_errors: 0,
            non_finite_positions: 0,
            scan_rate: ScanRate::default(),
            fall: FallDetector::new(fall_alert)?,
            alert_clock: StreamClock::default(),
            points: Vec::new(),
            track_id: None,
            alerts_raised: 0,
            last_alert: None,
            last_stamp_ns: None,
        })
    }

    /// The same stage with a pose head (`None`: without one, for the reason `status` gives).
    pub fn with_pose_head<H>(
        self,
        pelvis: Option<PelvisPlacer<H>>,
        status: PoseHeadStatus,
    ) -> ClassifierStage<M, H> {
        ClassifierStage {
            classifier: self.classifier,
            pelvis,
            pose_head: status,
            pose_head_errors: 0,
            non_finite_positions: 0,
            scan_rate: self.scan_rate,
            fall: self.fall,
            alert_clock: self.alert_clock,
            points: self.points,
            track_id: self.track_id,
            alerts_raised: self.alerts_raised,
            last_alert: self.last_alert,
            last_stamp_ns: self.last_stamp_ns,
        }
    }
}

impl<M: StepModel, H: PoseHead<M::State>> ClassifierStage<M, H> {
    pub fn classifier(&self) -> &StreamingClassifier<M> {
        &self.classifier
    }

    pub fn pose_head(&self) -> &PoseHeadStatus {
        &self.pose_head
    }

    /// The rate the scans come at (the median period of the first ones), once measured.
    pub fn measured_scan_rate_hz(&self) -> Option<f64> {
        self.scan_rate.measured_hz
    }

    /// Forgets the stream so far (model state, posture, incidents, track) for one that
    /// starts afresh, e.g. another recording. Alert ids keep counting.
    pub fn reset(&mut self) {
        self.classifier.reset();
        if let Some(placer) = &mut self.pelvis {
            placer.reset();
        }
        self.fall.reset();
        self.alert_clock.reset();
        self.track_id = None;
        self.last_alert = None;
    }

    /// Classifies one observation and runs the fall alerts.
    pub fn on_observation(
        &mut self,
        obs: &HumanObservation,
    ) -> Result<ClassifierOutput, ClassifierError> {
        let stamp_ns = obs.header.stamp.to_nanos();
        // The model's and the pose head's clock; the alerts run on `alert_clock`'s.
        let stamp_s = stamp_ns as f64 * 1e-9;
        // Time going back (a bag played again, a simulation restarted) is another stream for
        // every part of the stage: the model and the alerts restarted on their own, but the
        // pose head's pelvis on the floor went on combining the old pass with the new one.
        if self.last_stamp_ns.is_some_and(|last| stamp_ns < last) {
            self.reset();
        }
        self.last_stamp_ns = Some(stamp_ns);
        let stream_s = self.alert_clock.seconds(stamp_ns);
        let model_hz = self.classifier.spec().scan_rate_hz;
        if let Some(hz) = self.scan_rate.observe(stamp_ns)
            && (hz / model_hz - 1.0).abs() > SCAN_RATE_TOLERANCE
        {
            log::warn!(
                "classifier: scans come at {hz:.1} Hz but the model was trained at {model_hz:.1} \
                 Hz: its windows and the alerts' scan counts span other times than intended; \
                 run the Lidar at the model's rate or train a model at this one"
            );
        }
        let position = DVec2::new(obs.position.x, obs.position.y);
        // Another publisher's observation may be broken; seen nowhere is not seen.
        let visible = obs.visible && position.is_finite();
        if obs.visible && !visible {
            self.non_finite_positions += 1;
            if self.non_finite_positions.is_power_of_two() {
                log::warn!(
                    "classifier: /human/observation at {stamp_ns} ns is marked visible at a \
                     position that is not finite ({}, {}); taken as hidden ({} such so far)",
                    obs.position.x,
                    obs.position.y,
                    self.non_finite_positions
                );
            }
        }
        // A new track may be another person, or the same one found far away: start afresh.
        if visible && self.track_id.is_some_and(|id| id != obs.track_id) {
            self.classifier.reset();
            if let Some(placer) = &mut self.pelvis {
                placer.reset();
            }
        }
        if visible {
            self.track_id = Some(obs.track_id);
        }
        self.points.clear();
        if visible {
            self.points.extend(
                obs.points
                    .iter()
                    .map(|p| DVec2::new(f64::from(p.x), f64::from(p.y))),
            );
        }
        let scan = PersonScan {
            stamp_s,
            points: &self.points,
            position: visible.then_some(position),
            sensor: DVec2::new(obs.sensor_position.x, obs.sensor_position.y),
        };
        let prediction = self.classifier.classify(&scan)?;
        let pelvis = match &mut self.pelvis {
            Some(placer) if position.is_finite() => {
                let c = obs.covariance;
                // A failing head costs this scan's pelvis, never its activity or alerts.
                let person = if visible {
                    PersonAt::Seen(position)
                } else {
                    PersonAt::Predicted(position)
                };
                match placer.place(&self.classifier, person, &prediction) {
                    Ok(placed) => placed.map(|placed| {
                        let sigma2 = placed.sigma_m.powi(2);
                        Pelvis {
                            position: placed.position,
                            covariance: [[c[0] + sigma2, c[1]], [c[2], c[3] + sigma2]],
                        }
                    }),
                    Err(e) => {
                        self.pose_head_errors += 1;
                        if self.pose_head_errors.is_power_of_two() {
                            log::warn!(
                                "classifier: pose head failed ({} times so far): {e}",
                                self.pose_head_errors
                            );
                        }
                        None
                    }
                }
            }
            _ => None,
        };
        let body_length_m = MainAxisSpan::of(&self.points).map(|span| span.length());
        let was_down = self.fall.down_since_s().is_some();
        let raised = self.fall.update(&fall_input(
            stream_s,
            visible,
            prediction.ready,
            position,
            prediction.probabilities,
            body_length_m,
        ));
        let alert_event_ns = raised
            .iter()
            .map(|a| self.alert_clock.stamp_ns(event_time_s(a)))
            .collect();
        let alerts: Vec<FallAlert> = raised
            .iter()
            .map(|a| self.alert_clock.alert_in_stamp_time(a))
            .collect();
        self.alerts_raised += alerts.len();
        // The marker shows an alert for the spell on the floor it belongs to: a later spell
        // (sitting down to play, hours on) used to show the old alert in red.
        if was_down && self.fall.down_since_s().is_none() {
            self.last_alert = None;
        }
        if let Some(last) = alerts.last() {
            self.last_alert = Some(*last);
        }
        Ok(ClassifierOutput {
            stamp_ns,
            frame_id: obs.header.frame_id.clone(),
            visible,
            position,
            prediction,
            pelvis,
            body_length_m,
            alerts,
            alert_event_ns,
        })
    }

    /// The messages for an output: the activity (when publishable), the alerts, the marker.
    pub fn messages(&self, out: &ClassifierOutput) -> ClassifierMessages {
        let header = Header {
            stamp: Time::from_nanos(out.stamp_ns),
            frame_id: out.frame_id.clone(),
        };
        let activity = out
            .publishable()
            .then(|| activity_msg(header.clone(), &out.prediction));
        let pelvis = out.pelvis.map(|pelvis| pelvis_msg(header.clone(), &pelvis));
        let alerts = out
            .alerts
            .iter()
            .zip(&out.alert_event_ns)
            .map(|(a, &event_ns)| alert_msg(header.clone(), a, Time::from_nanos(event_ns)))
            .collect();
        ClassifierMessages {
            activity,
            pelvis,
            alerts,
            markers: self.marker(out, header),
        }
    }

    /// Decodes a /human/observation message, classifies it and encodes the outputs.
    pub fn handle_cdr(
        &mut self,
        cdr: &[u8],
    ) -> Result<(ClassifierOutput, Vec<Outgoing>), ClassifierStageError> {
        let obs: HumanObservation =
            lidar_har_msgs::decode(cdr).map_err(|source| PipelineError::Decode {
                topic: topics::HUMAN_OBSERVATION.name.to_string(),
                cause: source,
            })?;
        let out = self.on_observation(&obs)?;
        let outgoing = self.outgoing(&out)?;
        Ok((out, outgoing))
    }

    /// The encoded messages of an output, in publishing order.
    pub fn outgoing(&self, out: &ClassifierOutput) -> Result<Vec<Outgoing>, PipelineError> {
        let messages = self.messages(out);
        let mut outgoing = Vec::with_capacity(3 + messages.alerts.len());
        if let Some(activity) = &messages.activity {
            outgoing.push(Outgoing::encode(
                topics::HUMAN_ACTIVITY,
                out.stamp_ns,
                activity,
            )?);
        }
        if let Some(pelvis) = &messages.pelvis {
            outgoing.push(Outgoing::encode(
                topics::HUMAN_PELVIS,
                out.stamp_ns,
                pelvis,
            )?);
        }
        for alert in &messages.alerts {
            outgoing.push(Outgoing::encode(topics::FALL_ALERT, out.stamp_ns, alert)?);
        }
        outgoing.push(Outgoing::encode(
            topics::HUMAN_MARKERS,
            out.stamp_ns,
            &messages.markers,
        )?);
        Ok(outgoing)
    }

    /// A text above the person: the activity and its confidence, or the alert in red while
    /// the person is down; plus a red sphere per alert raised by this scan.
    fn marker(&self, out: &ClassifierOutput, header: Header) -> MarkerArray {
        let down = self.fall.down_since_s();
        let (text, color) = match (self.last_alert, down) {
            (Some(alert), Some(_)) => (
                format!("{} ({:.0}%)", alert.kind.name(), alert.confidence * 100.0),
                ColorRGBA {
                    r: 1.0,
                    g: 0.1,
                    b: 0.1,
                    a: 1.0,
                },
            ),
            _ if out.publishable() => (
                format!(
                    "{} {:.0}%",
                    out.prediction.activity,
                    out.prediction.confidence * 100.0
                ),
                if out.prediction.activity.is_on_floor() {
                    ColorRGBA {
                        r: 1.0,
                        g: 0.6,
                        b: 0.0,
                        a: 1.0,
                    }
                } else {
                    ColorRGBA {
                        r: 0.2,
                        g: 0.9,
                        b: 0.2,
                        a: 1.0,
                    }
                },
            ),
            _ => (
                String::from("?"),
                ColorRGBA {
                    r: 0.7,
                    g: 0.7,
                    b: 0.7,
                    a: 1.0,
                },
            ),
        };
        let at = |z: f64| Point {
            x: out.position.x,
            y: out.position.y,
            z,
        };
        let mut markers = vec![Marker {
            header: header.clone(),
            ns: "lidar_har/activity".into(),
            id: 0,
            r#type: Marker::TEXT_VIEW_FACING,
            action: Marker::ADD,
            pose: lidar_har_msgs::geometry_msgs::Pose {
                position: at(2.0),
                ..Default::default()
            },
            scale: Vector3 {
                x: 0.0,
                y: 0.0,
                z: 0.3,
            },
            color,
            lifetime: Duration { sec: 1, nanosec: 0 },
            text,
            ..Default::default()
        }];
        for (i, alert) in out.alerts.iter().enumerate() {
            markers.push(Marker {
                header: header.clone(),
                ns: "lidar_har/fall_alert".into(),
                id: i32::try_from(self.alerts_raised - out.alerts.len() + i).unwrap_or(i32::MAX),
                r#type: Marker::SPHERE,
                action: Marker::ADD,
                pose: lidar_har_msgs::geometry_msgs::Pose {
                    position: Point {
                        x: alert.position.x,
                        y: alert.position.y,
                        z: 0.2,
                    },
                    ..Default::default()
                },
                scale: Vector3 {
                    x: 0.4,
                    y: 0.4,
                    z: 0.4,
                },
                color: ColorRGBA {
                    r: 1.0,
                    g: 0.0,
                    b: 0.0,
                    a: 0.8,
                },
                ..Default::default()
            });
        }
        MarkerArray { markers }
    }
}

/// Why a /human/observation message could not be handled.
#[derive(Debug, thiserror::Error)]
pub enum ClassifierStageError {
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    #[error(transparent)]
    Classifier(#[from] ClassifierError),
}

/// Scan periods measured before the rate is compared with the model's.
const SCAN_RATE_SAMPLES: usize = 40;
/// A rate off the model's by more than this fraction is warned about: the model's window
/// and the alerts' scan counts then span other times than they were tuned for.
const SCAN_RATE_TOLERANCE: f64 = 0.25;

/// Measures the scan rate once, from the median period of the first scans.
#[derive(Debug, Default)]
struct ScanRate {
    last_ns: Option<i64>,
    periods_s: Vec<f64>,
    measured_hz: Option<f64>,
}

impl ScanRate {
    /// Takes a scan's stamp; returns the rate on the scan that completes the measurement.
    fn observe(&mut self, stamp_ns: i64) -> Option<f64> {
        if self.measured_hz.is_some() {
            return None;
        }
        let last = self.last_ns.replace(stamp_ns);
        let period_s = (stamp_ns - last?) as f64 * 1e-9;
        // Restarts and gaps are not periods.
        if period_s > 0.0 && period_s < 1.0 {
            self.periods_s.push(period_s);
        }
        if self.periods_s.len() < SCAN_RATE_SAMPLES {
            return None;
        }
        let hz = 1.0 / upper_median(&mut self.periods_s)?;
        self.measured_hz = Some(hz);
        Some(hz)
    }
}

/// The /human/activity message of a prediction.
pub fn activity_msg(header: Header, prediction: &Prediction) -> har::Activity {
    har::Activity {
        header,
        activity: prediction.activity.index() as u8,
        label: prediction.activity.label().into(),
        confidence: prediction.confidence,
        probabilities: prediction.probabilities.to_vec(),
    }
}

/// `/human/pelvis`: heading unknown (identity orientation, rotations of unknown variance).
pub fn pelvis_msg(header: Header, pelvis: &Pelvis) -> PoseWithCovarianceStamped {
    PoseWithCovarianceStamped {
        header,
        pose: PoseWithCovariance {
            pose: Pose {
                position: Point::new(pelvis.position.x, pelvis.position.y, 0.0),
                orientation: Quaternion::from_yaw(0.0),
            },
            covariance: crate::convert::planar_covariance(pelvis.covariance),
        },
    }
}

/// The /human/fall_alert message of an alert raised on the scan of `header`, with the stamp
/// its [`event_time_s`] names (both exact: seconds since the epoch as f64 lose the
/// nanoseconds).
pub fn alert_msg(header: Header, alert: &FallAlert, event_time: Time) -> har::FallAlert {
    let (kind, description) = match alert.kind {
        AlertKind::FallDetected => (
            har::FallAlert::FALL_DETECTED,
            format!(
                "fall detected near ({:.1}, {:.1})",
                alert.position.x, alert.position.y
            ),
        ),
        AlertKind::PersonDown => (
            har::FallAlert::PERSON_DOWN,
            format!(
                "person down for {:.0} s near ({:.1}, {:.1})",
                alert.raised_at_s - alert.down_since_s,
                alert.position.x,
                alert.position.y
            ),
        ),
    };
    har::FallAlert {
        header,
        kind,
        position: Point {
            x: alert.position.x,
            y: alert.position.y,
            z: 0.0,
        },
        confidence: alert.confidence,
        event_time,
        description,
    }
}

/// The activity of a /human/activity or /ground_truth/activity message, if its index is valid.
pub fn activity_of(msg: &har::Activity) -> Option<Activity> {
    Activity::from_index(usize::from(msg.activity))
}

/// The classifier's results over a run, with the ground truth when the input had it: the
/// activity part of `summary.json` and the demo's timeline. Each prediction is scored and
/// added to its segment once the truth around it is known, so a run of any length keeps
/// only its segments and alerts.
#[derive(Debug, Clone)]
pub struct ActivityLog {
    /// Published predictions (activity, confidence) waiting for the truth at their stamp.
    matcher: TruthMatcher<Activity, (Activity, f32)>,
    scores: ActivityScores,
    predictions: usize,
    alerts: Vec<FallAlert>,
}

/// What the settled predictions add up to.
#[derive(Debug, Clone, Default)]
struct ActivityScores {
    confusion: ConfusionMatrix,
    segments: Segments,
}

impl ActivityScores {
    /// Scores a prediction against the true activity at its stamp (the latest truth not
    /// after it, if recent) and adds it to its segment.
    fn settle(
        &mut self,
        stamp_ns: i64,
        (activity, confidence): (Activity, f32),
        around: Around<'_, Activity>,
    ) {
        let truth = around
            .latest_not_after(stamp_ns)
            .filter(|&(t, _)| stamp_ns - t <= TRUTH_MAX_AGE_NS)
            .map(|(_, &a)| a);
        if let Some(truth) = truth {
            self.confusion.add(truth, activity);
        }
        self.segments.add(stamp_ns, activity, confidence, truth);
    }
}

impl Default for ActivityLog {
    fn default() -> Self {
        Self {
            matcher: TruthMatcher::new(TRUTH_MAX_AGE_NS),
            scores: ActivityScores::default(),
            predictions: 0,
            alerts: Vec::new(),
        }
    }
}

/// Runs of the same recognised activity (a gap over 1 s, or time going back, also ends a
/// run), built as the predictions are settled.
#[derive(Debug, Clone, Default)]
struct Segments {
    done: Vec<Segment>,
    /// The run under way, the true activities counted over it, and its last stamp.
    open: Option<(Segment, [usize; Activity::COUNT], i64)>,
}

impl Segments {
    fn add(&mut self, stamp_ns: i64, activity: Activity, confidence: f32, truth: Option<Activity>) {
        // Time going back (a bag played again) is another stream, as for the rest of the
        // stage: a run across it would end before it starts.
        let continues = self.open.as_ref().is_some_and(|(seg, _, last)| {
            seg.activity == activity && (0..1_000_000_000).contains(&(stamp_ns - last))
        });
        let s = stamp_ns as f64 * 1e-9;
        if !continues {
            self.close();
            let segment = Segment {
                start_s: s,
                end_s: s,
                activity,
                mean_confidence: 0.0,
                truth: None,
                scans: 0,
            };
            self.open = Some((segment, [0; Activity::COUNT], stamp_ns));
        }
        if let Some((seg, votes, last)) = &mut self.open {
            seg.end_s = s;
            seg.mean_confidence += confidence;
            seg.scans += 1;
            if let Some(truth) = truth {
                votes[truth.index()] += 1;
            }
            *last = stamp_ns;
        }
    }

    /// Ends the run under way: its mean confidence, and its most frequent true activity.
    fn close(&mut self) {
        let Some((mut seg, votes, _)) = self.open.take() else {
            return;
        };
        seg.mean_confidence /= seg.scans.max(1) as f32;
        let (best, &n) = votes
            .iter()
            .enumerate()
            .max_by_key(|(_, n)| **n)
            .unwrap_or((0, &0));
        seg.truth = (n > 0).then(|| Activity::ALL[best]);
        self.done.push(seg);
    }
}

/// One stretch of the same recognised activity.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Segment {
    pub start_s: f64,
    pub end_s: f64,
    pub activity: Activity,
    pub mean_confidence: f32,
    /// The most frequent true activity over the segment, when known.
    pub truth: Option<Activity>,
    pub scans: usize,
}

/// An alert as reported in `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlertRecord {
    pub kind: &'static str,
    /// When the alert was raised, s since the stamps' zero (the epoch, for wall-clock stamps).
    pub time_s: f64,
    /// When the fall happened / since when the person is down, s.
    pub event_time_s: f64,
    pub position: [f64; 2],
    pub confidence: f32,
}

/// The activity part of `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct ActivitySummary {
    /// Scans with a published activity.
    pub scans_classified: usize,
    /// Against /ground_truth/activity (the latest truth at or before each prediction), when
    /// the input had it.
    pub accuracy: Option<f64>,
    pub macro_f1: Option<f64>,
    pub metrics: Option<MetricsReport>,
    pub alerts: Vec<AlertRecord>,
    pub segments: Vec<Segment>,
    /// Classifier time per scan (decode, render, two model steps, alerts, encode), microseconds.
    pub classify_time_us: Option<Spread>,
    /// The rate the scans came at (after the first 40), and the model's: a log warning
    /// says when they differ by more than 25 %.
    pub scan_rate_hz: Option<f64>,
    pub model_scan_rate_hz: Option<f64>,
    /// Whether a pose head ran, and the scans it placed the pelvis on (/human/pelvis).
    pub pose_head: PoseHeadStatus,
    pub pelvis_published: usize,
}

/// Ground truth older than this is not matched to a prediction.
const TRUTH_MAX_AGE_NS: i64 = 500_000_000;

impl ActivityLog {
    pub fn add_truth(&mut self, stamp_ns: i64, msg: &har::Activity) {
        if let Some(activity) = activity_of(msg) {
            let scores = &mut self.scores;
            self.matcher.add_truth(stamp_ns, activity, |t, p, around| {
                scores.settle(t, p, around)
            });
        }
    }

    pub fn add_output(&mut self, out: &ClassifierOutput) {
        if out.publishable() {
            self.predictions += 1;
            let prediction = (out.prediction.activity, out.prediction.confidence);
            let scores = &mut self.scores;
            self.matcher
                .add_output(out.stamp_ns, prediction, |t, p, around| {
                    scores.settle(t, p, around)
                });
        }
        self.alerts.extend(out.alerts.iter().copied());
    }

    pub fn alerts(&self) -> &[FallAlert] {
        &self.alerts
    }

    /// The activity part of `summary.json`, once the run has ended.
    pub fn finish(mut self) -> ActivitySummary {
        let scores = &mut self.scores;
        self.matcher
            .finish(|t, p, around| scores.settle(t, p, around));
        self.scores.segments.close();
        let metrics = (self.scores.confusion.total() > 0).then(|| self.scores.confusion.report());
        ActivitySummary {
            scans_classified: self.predictions,
            accuracy: metrics.as_ref().map(|m| m.accuracy),
            macro_f1: metrics.as_ref().map(|m| m.macro_f1),
            metrics,
            alerts: self
                .alerts
                .iter()
                .map(|a| AlertRecord {
                    kind: a.kind.name(),
                    time_s: a.raised_at_s,
                    event_time_s: event_time_s(a),
                    position: [a.position.x, a.position.y],
                    confidence: a.confidence,
                })
                .collect(),
            segments: self.scores.segments.done,
            classify_time_us: None,
            scan_rate_hz: None,
            model_scan_rate_hz: None,
            pose_head: PoseHeadStatus::Off,
            pelvis_published: 0,
        }
    }
}

/// The classifier inside a bag run (`lidar-har run`, `lidar-har demo`): classifies every
/// /human/observation the localiser produces, records /human/activity, /human/fall_alert,
/// /human/pelvis and the text markers, and scores against /ground_truth/activity when the
/// input has it.
pub struct ClassifierRun {
    stage: ClassifierStage,
    log: ActivityLog,
    times_us: SpreadTally,
    /// The pelvis placed by the pose head since [`ClassifierRun::take_pelvis`], by scan stamp.
    pelvis: Vec<(i64, DVec2)>,
    pelvis_published: usize,
}

impl ClassifierRun {
    /// Loads the model; fails early (before any work) when it is missing or unusable.
    pub fn load(config: &ClassifierConfig) -> Result<Self, ClassifierError> {
        Ok(Self {
            stage: ClassifierStage::load(config, None)?,
            log: ActivityLog::default(),
            // Resolved to a nanosecond.
            times_us: SpreadTally::with_steps_per_unit(1e3),
            pelvis: Vec::new(),
            pelvis_published: 0,
        })
    }

    /// An input message: takes /ground_truth/activity (`Some`: whether it could be read),
    /// ignores the rest (`None`).
    pub(crate) fn on_input(&mut self, topic: &str, cdr: &[u8]) -> Option<Result<(), CdrError>> {
        if topic != topics::GROUND_TRUTH_ACTIVITY.name {
            return None;
        }
        Some(
            lidar_har_msgs::decode::<har::Activity>(cdr)
                .map(|msg| self.log.add_truth(msg.header.stamp.to_nanos(), &msg)),
        )
    }

    /// A message the localiser produced: classifies /human/observation and records the results.
    pub(crate) fn on_localiser_output(
        &mut self,
        out: &Outgoing,
        log_time_ns: i64,
        outputs: &mut OutputBag,
    ) -> Result<(), ClassifierRunError> {
        if out.topic.name != topics::HUMAN_OBSERVATION.name {
            return Ok(());
        }
        let started = std::time::Instant::now();
        let (result, outgoing) = self.stage.handle_cdr(&out.cdr)?;
        self.times_us.record(started.elapsed().as_secs_f64() * 1e6);
        self.log.add_output(&result);
        if let Some(pelvis) = result.pelvis {
            self.pelvis.push((result.stamp_ns, pelvis.position));
            self.pelvis_published += 1;
        }
        for message in &outgoing {
            outputs.write(message, log_time_ns)?;
        }
        Ok(())
    }

    /// The pelvis placed by the pose head since the last call, by scan stamp: the run scores
    /// it against the truth as it goes.
    pub fn take_pelvis(&mut self) -> Vec<(i64, DVec2)> {
        std::mem::take(&mut self.pelvis)
    }

    /// Scans the pose head placed the pelvis on (/human/pelvis).
    pub fn pelvis_published(&self) -> usize {
        self.pelvis_published
    }

    /// The activity part of `summary.json`, with the classification time per scan.
    pub fn finish(self) -> ActivitySummary {
        let mut summary = self.log.finish();
        summary.classify_time_us = self.times_us.spread();
        summary.scan_rate_hz = self.stage.measured_scan_rate_hz();
        summary.model_scan_rate_hz = Some(self.stage.classifier().spec().scan_rate_hz);
        summary.pose_head = self.stage.pose_head().clone();
        summary.pelvis_published = self.pelvis_published;
        summary
    }
}

/// Why the classifier failed inside a run.
#[derive(Debug, thiserror::Error)]
pub enum ClassifierRunError {
    #[error(transparent)]
    Stage(#[from] ClassifierStageError),
    #[error("writing the classifier's outputs: {0}")]
    Bag(BagError),
}

impl From<BagError> for ClassifierRunError {
    fn from(cause: BagError) -> Self {
        Self::Bag(cause)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lidar_har_core::pose_head::{HeadEstimate, PoseHeadSpec};
    use lidar_har_core::representation::{Framing, RepresentationKind, RepresentationSpec};
    use lidar_har_msgs::geometry_msgs::Point32;
    use ndarray::ArrayView2;

    /// A stand-in model that "recognises" a script: the class is chosen by the scan's stamp
    /// through a shared timeline, so tests can drive fall alerts through the whole stage.
    struct TimelineModel {
        timeline: Vec<(f64, Activity)>,
        now: std::rc::Rc<std::cell::Cell<f64>>,
    }

    impl StepModel for TimelineModel {
        type State = ();
        type Error = std::io::Error;
        fn initial_state(&self) {}
        fn reset_state(&self, _: &mut ()) {}
        fn step(&mut self, _: ArrayView2<'_, f32>, _: &mut ()) -> Result<[f32; 9], std::io::Error> {
            let t = self.now.get();
            let activity = self
                .timeline
                .iter()
                .rev()
                .find(|(start, _)| *start <= t)
                .map_or(Activity::Standing, |(_, a)| *a);
            let mut logits = [0.0; 9];
            logits[activity.index()] = 8.0;
            Ok(logits)
        }
    }

    impl TimelineModel {
        /// Walking, falling from 3 s, lying from 4 s; and the clock it reads.
        fn walk_fall_lie() -> (Self, std::rc::Rc<std::cell::Cell<f64>>) {
            let now = std::rc::Rc::new(std::cell::Cell::new(0.0));
            let model = TimelineModel {
                timeline: vec![
                    (0.0, Activity::Walking),
                    (3.0, Activity::FallingDown),
                    (4.0, Activity::LyingDown),
                ],
                now: now.clone(),
            };
            (model, now)
        }
    }

    fn stream() -> StreamSpec {
        StreamSpec {
            representation: RepresentationSpec::new(
                RepresentationKind::BooleanGrid,
                Framing::RoomFixed,
                16,
                0.1,
            ),
            window: 8,
            scan_rate_hz: 20.0,
        }
    }

    fn observation(t: f64, visible: bool) -> HumanObservation {
        HumanObservation {
            header: Header {
                stamp: Time::from_nanos((t * 1e9) as i64),
                frame_id: "map".into(),
            },
            track_id: 1,
            visible,
            position: Point {
                x: 2.0,
                y: 1.0,
                z: 0.0,
            },
            sensor_position: Point {
                x: 0.0,
                y: 0.0,
                z: 0.2,
            },
            points: if visible {
                vec![
                    Point32 {
                        x: 2.0,
                        y: 1.0,
                        z: 0.0,
                    },
                    // A body stretched on the floor: 1.1 m from end to end.
                    Point32 {
                        x: 3.0,
                        y: 1.5,
                        z: 0.0,
                    },
                ]
            } else {
                vec![]
            },
            ..Default::default()
        }
    }

    fn run(
        timeline: Vec<(f64, Activity)>,
        seconds: f64,
    ) -> Vec<(ClassifierOutput, ClassifierMessages)> {
        let now = std::rc::Rc::new(std::cell::Cell::new(0.0));
        let model = TimelineModel {
            timeline,
            now: now.clone(),
        };
        let config = FallAlertConfig {
            down_after_s: 5.0,
            ..Default::default()
        };
        let mut stage = ClassifierStage::new(model, stream(), config).unwrap();
        (0..(seconds * 20.0) as usize)
            .map(|k| {
                let t = k as f64 * 0.05;
                now.set(t);
                let out = stage.on_observation(&observation(t, true)).unwrap();
                let msgs = stage.messages(&out);
                (out, msgs)
            })
            .collect()
    }

    #[test]
    fn a_fall_gives_activity_messages_and_one_alert_of_each_kind() {
        let outputs = run(
            vec![
                (0.0, Activity::Walking),
                (3.0, Activity::FallingDown),
                (4.0, Activity::LyingDown),
            ],
            12.0,
        );
        let alerts: Vec<&har::FallAlert> = outputs.iter().flat_map(|(_, m)| &m.alerts).collect();
        assert_eq!(alerts.len(), 2, "{alerts:?}");
        assert_eq!(alerts[0].kind, har::FallAlert::FALL_DETECTED);
        assert_eq!(alerts[0].event_time.to_nanos(), 3_000_000_000);
        assert!(
            (alerts[0].header.stamp.to_secs_f64() - 4.2).abs() < 1e-6,
            "once lying is confirmed (confirm_scans) after the landing at 4 s: {}",
            alerts[0].header.stamp.to_secs_f64()
        );
        assert_eq!((alerts[0].position.x, alerts[0].position.y), (2.0, 1.0));
        assert_eq!(alerts[1].kind, har::FallAlert::PERSON_DOWN);
        assert_eq!(
            alerts[1].event_time.to_nanos(),
            3_000_000_000,
            "down since the fall"
        );
        assert!(
            alerts[1].description.contains("person down for 5 s"),
            "{}",
            alerts[1].description
        );

        // Activities: none before T/2 = 4 scans, then every scan, with labels and probabilities.
        let published: Vec<&har::Activity> = outputs
            .iter()
            .filter_map(|(_, m)| m.activity.as_ref())
            .collect();
        assert_eq!(published.len(), outputs.len() - 3);
        let at = |t: f64| {
            published
                .iter()
                .find(|a| (a.header.stamp.to_secs_f64() - t).abs() < 1e-6)
                .unwrap()
        };
        assert_eq!(at(1.0).label, "walking");
        assert_eq!(at(3.5).label, "falling_down");
        assert_eq!(at(6.0).activity, har::Activity::LYING_DOWN);
        assert_eq!(at(6.0).probabilities.len(), 9);
        assert!((at(6.0).probabilities.iter().sum::<f32>() - 1.0).abs() < 1e-5);

        // The marker shows the alert while the person is down.
        let (_, last) = outputs.last().unwrap();
        assert!(
            last.markers.markers[0].text.contains("PERSON_DOWN"),
            "{:?}",
            last.markers.markers[0].text
        );
        let (_, early) = &outputs[20];
        assert!(
            early.markers.markers[0].text.starts_with("walking"),
            "{}",
            early.markers.markers[0].text
        );
    }

    #[test]
    fn the_marker_shows_an_alert_only_during_its_own_spell_on_the_floor() {
        let outputs = run(
            vec![
                (0.0, Activity::Standing),
                (3.0, Activity::FallingDown),
                (3.5, Activity::LyingDown),
                (10.0, Activity::Standing),
                (20.0, Activity::SittingOnFloor),
            ],
            23.0,
        );
        let alerts = outputs.iter().flat_map(|(_, m)| &m.alerts).count();
        assert_eq!(alerts, 2, "the fall's FALL_DETECTED and PERSON_DOWN only");
        let text_at = |t: f64| &outputs[(t * 20.0).round() as usize].1.markers.markers[0].text;
        assert!(text_at(9.0).contains("PERSON_DOWN"), "{}", text_at(9.0));
        assert!(
            text_at(22.0).starts_with("sitting_on_floor"),
            "sitting down long after getting up raised nothing: {}",
            text_at(22.0)
        );
    }

    #[test]
    fn alerts_carry_their_scan_stamp_to_the_nanosecond() {
        let (model, now) = TimelineModel::walk_fall_lie();
        let mut stage = ClassifierStage::new(model, stream(), FallAlertConfig::default()).unwrap();
        let epoch_ns = 1_700_000_000_000_000_000;
        let mut alerts = 0;
        for k in 0..120 {
            now.set(k as f64 * 0.05);
            let mut obs = observation(k as f64 * 0.05, true);
            obs.header.stamp = Time::from_nanos(epoch_ns + 21_250_000_000 + k * 50_000_000);
            let out = stage.on_observation(&obs).unwrap();
            for alert in stage.messages(&out).alerts {
                assert_eq!(alert.header.stamp.to_nanos(), out.stamp_ns);
                alerts += 1;
            }
        }
        assert_eq!(alerts, 1, "FALL_DETECTED");
    }

    #[test]
    fn alert_event_times_are_the_exact_stamps_of_the_scans_they_name() {
        let (model, now) = TimelineModel::walk_fall_lie();
        let config = FallAlertConfig {
            down_after_s: 5.0,
            ..Default::default()
        };
        let mut stage = ClassifierStage::new(model, stream(), config).unwrap();
        // Wall-clock stamps with odd nanoseconds, as from a driver: through f64 seconds since
        // the epoch, event times came out up to ~380 ns off the scans they name.
        let first_ns = 1_760_000_000_123_456_789;
        let days_ns = 3 * 86_400 * 1_000_000_000;
        // A run, the bag played again from earlier on (time going back starts the stream
        // afresh), then a fall days after that stream started.
        let again_ns = first_ns - 40_000_000_333;
        for pass_ns in [first_ns, again_ns, again_ns + days_ns] {
            let stamp_ns = |k: i64| pass_ns + k * 50_000_000 + 7;
            let mut alerts = Vec::new();
            for k in 0..240 {
                now.set(k as f64 * 0.05);
                let mut obs = observation(k as f64 * 0.05, true);
                obs.header.stamp = Time::from_nanos(stamp_ns(k));
                let out = stage.on_observation(&obs).unwrap();
                alerts.extend(
                    stage
                        .messages(&out)
                        .alerts
                        .into_iter()
                        .map(|a| (a.kind, a.event_time.to_nanos())),
                );
            }
            let fall_start_ns = stamp_ns(60);
            assert_eq!(
                alerts,
                [
                    (har::FallAlert::FALL_DETECTED, fall_start_ns),
                    (har::FallAlert::PERSON_DOWN, fall_start_ns)
                ],
                "pass from {pass_ns} ns: the fall's first scan, and down since then"
            );
        }
    }

    #[test]
    fn the_stream_clock_turns_times_back_into_exact_stamps_for_weeks() {
        let start_ns = 1_760_000_000_123_456_789;
        let mut clock = StreamClock::default();
        assert_eq!(clock.seconds(start_ns), 0.0);
        let weeks_ns = (1_i64 << 22) * 1_000_000_000;
        // The last nanoseconds before 2^22 s (48 days), then offsets spread over them.
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for i in 0..300_000 {
            x = x
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let offset_ns = if i < 1000 {
                weeks_ns - 1 - i
            } else {
                (x >> 11) as i64 % weeks_ns
            };
            let stamp_ns = start_ns + offset_ns;
            let s = clock.seconds(stamp_ns);
            assert_eq!(
                clock.stamp_ns(s),
                stamp_ns,
                "{offset_ns} ns into the stream"
            );
        }
        clock.reset();
        assert_eq!(clock.seconds(start_ns - 5), 0.0, "a reset starts afresh");
        assert_eq!(clock.stamp_ns(0.05), start_ns - 5 + 50_000_000);
    }

    #[test]
    fn the_scan_rate_is_measured_from_the_first_scans() {
        let rate_of = |period_ns: i64| {
            let model = TimelineModel {
                timeline: vec![],
                now: Default::default(),
            };
            let mut stage =
                ClassifierStage::new(model, stream(), FallAlertConfig::default()).unwrap();
            for k in 0..60 {
                // A restart and a hidden stretch on the way do not count as periods.
                let k = if k < 20 { k } else { k + 100 };
                let mut obs = observation(0.0, true);
                obs.header.stamp = Time::from_nanos(k * period_ns);
                stage.on_observation(&obs).unwrap();
                if k == 10 {
                    assert_eq!(stage.measured_scan_rate_hz(), None, "not yet");
                }
            }
            stage.measured_scan_rate_hz().unwrap()
        };
        assert!((rate_of(50_000_000) - 20.0).abs() < 1e-9);
        assert!((rate_of(100_000_000) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn hidden_person_gets_no_activity_message() {
        let now = std::rc::Rc::new(std::cell::Cell::new(0.0));
        let model = TimelineModel {
            timeline: vec![(0.0, Activity::Walking)],
            now,
        };
        let mut stage = ClassifierStage::new(model, stream(), FallAlertConfig::default()).unwrap();
        for k in 0..20 {
            let out = stage
                .on_observation(&observation(k as f64 * 0.05, k < 10))
                .unwrap();
            let msgs = stage.messages(&out);
            assert_eq!(msgs.activity.is_some(), (3..10).contains(&k), "scan {k}");
            assert_eq!(msgs.markers.markers.len(), 1);
        }
    }

    #[test]
    fn a_visible_person_at_a_non_finite_position_is_taken_as_hidden() {
        let now = std::rc::Rc::new(std::cell::Cell::new(0.0));
        let model = TimelineModel {
            timeline: vec![(0.0, Activity::Walking)],
            now,
        };
        let mut stage = with_head_for_all(
            ClassifierStage::new(model, stream(), FallAlertConfig::default()).unwrap(),
            ShiftHead,
        );
        for k in 0..20 {
            let mut obs = observation(k as f64 * 0.05, true);
            if k >= 10 {
                obs.position.x = [f64::NAN, f64::INFINITY][k % 2];
            }
            let out = stage.on_observation(&obs).unwrap();
            let msgs = stage.messages(&out);
            assert_eq!(out.visible, k < 10, "scan {k}");
            assert_eq!(msgs.activity.is_some(), (3..10).contains(&k), "scan {k}");
            assert_eq!(msgs.pelvis.is_some(), k < 10, "scan {k}");
        }
        assert_eq!(stage.non_finite_positions, 10);
    }

    /// `stage` with `head` placing the pelvis for every activity from the first scan.
    fn with_head_for_all<H>(
        stage: ClassifierStage<TimelineModel, NoPoseHead>,
        head: H,
    ) -> ClassifierStage<TimelineModel, H> {
        let spec = PoseHeadSpec {
            min_history: 1,
            activities: Activity::ALL.to_vec(),
            max_sigma_m: f64::INFINITY,
        };
        let status = PoseHeadStatus::Used {
            path: "head.onnx".into(),
        };
        stage.with_pose_head(Some(PelvisPlacer::new(spec, head)), status)
    }

    /// A pose head that puts the pelvis 0.3 m along x from the localiser's position and
    /// expects an error of 0.2 m.
    struct ShiftHead;

    impl PoseHead<()> for ShiftHead {
        type Error = std::io::Error;
        fn estimate(&mut self, _: &(), _: DVec2) -> Result<HeadEstimate, std::io::Error> {
            Ok(HeadEstimate {
                offset: DVec2::new(0.3, 0.0),
                sigma_m: 0.2,
            })
        }
    }

    /// A pose head whose every run fails.
    struct BrokenHead;

    impl PoseHead<()> for BrokenHead {
        type Error = std::io::Error;
        fn estimate(&mut self, _: &(), _: DVec2) -> Result<HeadEstimate, std::io::Error> {
            Err(std::io::Error::other("no session"))
        }
    }

    #[test]
    fn a_failing_pose_head_costs_the_pelvis_not_the_activity_or_the_alerts() {
        let now = std::rc::Rc::new(std::cell::Cell::new(0.0));
        let stage = || {
            let model = TimelineModel {
                timeline: vec![(0.0, Activity::Walking), (1.0, Activity::FallingDown)],
                now: now.clone(),
            };
            ClassifierStage::new(model, stream(), FallAlertConfig::default()).unwrap()
        };
        let mut plain = stage();
        let mut broken = with_head_for_all(stage(), BrokenHead);
        for k in 0..40 {
            let t = k as f64 * 0.05;
            now.set(t);
            let obs = observation(t, true);
            let a = plain.on_observation(&obs).unwrap();
            let b = broken.on_observation(&obs).unwrap();
            assert_eq!(b.pelvis, None);
            assert_eq!(
                (a.prediction, a.alerts),
                (b.prediction, b.alerts),
                "scan {k}"
            );
        }
        assert_eq!(broken.pose_head_errors, 40);
    }

    #[test]
    fn pose_head_publishes_the_pelvis_on_seen_scans_of_its_activities() {
        publishes_the_pelvis(0.0);
    }

    #[test]
    fn pose_head_holds_the_pelvis_through_a_short_occlusion() {
        publishes_the_pelvis(0.5);
    }

    /// A sitter hidden on scan 15: a pelvis there only with a hold.
    fn publishes_the_pelvis(hold_s: f64) {
        let now = std::rc::Rc::new(std::cell::Cell::new(0.0));
        let model = TimelineModel {
            timeline: vec![(0.0, Activity::Walking), (0.5, Activity::SittingOnFloor)],
            now: now.clone(),
        };
        let spec = PoseHeadSpec {
            min_history: 4,
            activities: vec![Activity::SittingOnFloor],
            max_sigma_m: f64::INFINITY,
        };
        let status = PoseHeadStatus::Used {
            path: "head.onnx".into(),
        };
        let mut stage = ClassifierStage::new(model, stream(), FallAlertConfig::default())
            .unwrap()
            .with_pose_head(
                Some(PelvisPlacer::new(spec, ShiftHead).holding_for(hold_s)),
                status.clone(),
            );
        assert_eq!(stage.pose_head(), &status);
        for k in 0..20 {
            let t = k as f64 * 0.05;
            now.set(t);
            let mut obs = observation(t, k != 15);
            obs.covariance = [0.01, 0.002, 0.002, 0.03];
            let out = stage.on_observation(&obs).unwrap();
            let topics: Vec<&str> = stage
                .outgoing(&out)
                .unwrap()
                .iter()
                .map(|o| o.topic.name)
                .collect();
            let expected = k >= 10 && (k != 15 || hold_s > 0.0);
            assert_eq!(out.pelvis.is_some(), expected, "scan {k}");
            assert_eq!(topics.contains(&"/human/pelvis"), expected, "scan {k}");
            if let Some(pelvis) = stage.messages(&out).pelvis {
                let pose = &pelvis.pose;
                assert!((pose.pose.position.x - 2.3).abs() < 1e-12);
                assert_eq!(pose.pose.position.y, 1.0);
                assert_eq!(pelvis.header.stamp, obs.header.stamp);
                // The track's covariance plus the head's own error (0.2 m per axis).
                let c = pose.covariance;
                assert!((c[0] - 0.05).abs() < 1e-12 && (c[7] - 0.07).abs() < 1e-12);
                assert_eq!((c[1], c[6]), (0.002, 0.002));
            }
        }
    }

    #[test]
    fn time_going_back_starts_the_pelvis_on_the_floor_afresh() {
        let now = std::rc::Rc::new(std::cell::Cell::new(0.0));
        let model = TimelineModel {
            timeline: vec![(0.0, Activity::LyingDown)],
            now: now.clone(),
        };
        let spec = PoseHeadSpec {
            min_history: 1,
            activities: vec![Activity::LyingDown],
            max_sigma_m: f64::INFINITY,
        };
        let placer = PelvisPlacer::new(spec, ShiftHead).fusing_on_floor_within(1.0, 1.0);
        let status = PoseHeadStatus::Used {
            path: "head.onnx".into(),
        };
        let mut stage = ClassifierStage::new(model, stream(), FallAlertConfig::default())
            .unwrap()
            .with_pose_head(Some(placer), status);
        let mut pelvis_x = |t: f64, x: f64| {
            now.set(t);
            let mut obs = observation(t, true);
            obs.position.x = x;
            stage
                .on_observation(&obs)
                .unwrap()
                .pelvis
                .unwrap()
                .position
                .x
        };
        for k in 0..40 {
            pelvis_x(k as f64 * 0.05, 2.0);
        }
        // Played again from the start, lying 0.4 m further along: nothing of the first pass.
        assert!((pelvis_x(0.0, 2.4) - 2.7).abs() < 1e-12);
    }

    #[test]
    fn observation_bytes_in_encoded_messages_out() {
        let now = std::rc::Rc::new(std::cell::Cell::new(0.0));
        let model = TimelineModel {
            timeline: vec![(0.0, Activity::Standing)],
            now,
        };
        let mut stage = ClassifierStage::new(model, stream(), FallAlertConfig::default()).unwrap();
        let mut last = vec![];
        for k in 0..6 {
            let cdr = lidar_har_msgs::encode(&observation(k as f64 * 0.05, true)).unwrap();
            last = stage.handle_cdr(&cdr).unwrap().1;
        }
        assert_eq!(last[0].topic.name, "/human/activity");
        let activity: har::Activity = lidar_har_msgs::decode(&last[0].cdr).unwrap();
        assert_eq!(activity.label, "standing");
        assert_eq!(last.last().unwrap().topic.name, "/human/markers");
        let e = stage.handle_cdr(&[0, 1, 0, 0, 7]).unwrap_err().to_string();
        assert!(e.contains("/human/observation"), "{e}");
    }

    /// `pose_head: none` in a file had been a head file named `none` (a warning that it is
    /// missing) for `lidar-har run`, while the node's `pose_head:=none` is no head.
    #[test]
    fn pose_head_none_is_no_head_in_a_file_as_in_the_nodes_parameter() {
        let head = |text: &str| parse_classifier_config(text).unwrap().pose_head;
        assert_eq!(head("pose_head: none\n"), None);
        assert_eq!(head("pose_head: null\n"), None);
        assert_eq!(
            head("pose_head: heads/none.onnx\n"),
            Some(PathBuf::from("heads/none.onnx"))
        );
        assert_eq!(pose_head_setting(Some(PathBuf::from("none"))), None);
        let given = Some(PathBuf::from("h.onnx"));
        assert_eq!(pose_head_setting(given.clone()), given);
    }

    #[test]
    fn config_parses_with_defaults_and_rejects_unknown_keys() {
        let c = parse_classifier_config("threads: 2\nfall_alert:\n  down_after_s: 30\n").unwrap();
        assert_eq!(c.threads, 2);
        assert_eq!(c.fall_alert.down_after_s, 30.0);
        assert_eq!(
            c.fall_alert.fall_min_scans,
            FallAlertConfig::default().fall_min_scans
        );
        assert_eq!(c.model, PathBuf::from("models/activity.onnx"));
        assert_eq!(c.pose_head, Some(PathBuf::from("models/pose_head.onnx")));
        assert_eq!(
            parse_classifier_config("pose_head: null\n")
                .unwrap()
                .pose_head,
            None
        );
        let e = parse_classifier_config("fall_alert:\n  down_after: 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("down_after"), "{e}");
        let e = parse_classifier_config("fall_alert:\n  fall_probability: 2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("fall_probability"), "{e}");
        let e = parse_classifier_config("threads: 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("threads must be at least 1"), "{e}");
        for bad in ["0.9", ".nan", "11"] {
            let e = parse_classifier_config(&format!("lane_period_windows: {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("lane_period_windows"), "{e}");
        }
        for bad in ["1", "9"] {
            let e = parse_classifier_config(&format!("lanes: {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("lanes"), "{e}");
        }
        for bad in ["-1", ".inf", ".nan"] {
            let e = parse_classifier_config(&format!("pelvis_hold_s: {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("pelvis_hold_s"), "{e}");
            let e = parse_classifier_config(&format!("pelvis_floor_fusion_m: {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("pelvis_floor_fusion_m"), "{e}");
            let e = parse_classifier_config(&format!("pelvis_floor_fusion_gap_s: {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("pelvis_floor_fusion_gap_s"), "{e}");
        }
        for bad in ["-1", "4", "0.5"] {
            let e = parse_classifier_config(&format!("pose_head_lanes_between: {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("pose_head_lanes_between"), "{e}");
        }
        let c = parse_classifier_config("lane_period_windows: 1.25\nlanes: 3\n").unwrap();
        let schedule = |lanes_between| LaneSchedule {
            period: 25,
            lanes: 3,
            lanes_between,
        };
        assert_eq!(c.lane_schedule(20, false), schedule(0));
        assert_eq!(c.lane_schedule(20, true), schedule(1));
    }

    /// Whether ONNX Runtime is installed; a test needing it skips without it, unless
    /// `LIDAR_HAR_REQUIRE_CHECKERS` asks for it.
    fn onnx_runtime_installed() -> bool {
        let (runtime, _) = lidar_har_infer::runtime_library_path();
        if !runtime.is_file() {
            assert!(
                std::env::var_os("LIDAR_HAR_REQUIRE_CHECKERS").is_none(),
                "{} missing: run scripts/setup.sh",
                runtime.display()
            );
            eprintln!("SKIP: {} missing (run scripts/setup.sh)", runtime.display());
        }
        runtime.is_file()
    }

    fn infer_fixture(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../infer/tests/fixtures")
            .join(name)
    }

    /// The infer crate's fixture `name` written to `out` with its one-character metadata
    /// value of `key` changed from `from` to `to` (the ONNX bytes: key, tag, length 1, value).
    fn fixture_with_metadata(name: &str, key: &[u8], from: u8, to: u8, out: &Path) {
        let mut bytes = std::fs::read(infer_fixture(name)).unwrap();
        let entry = [key, b"\x12\x01", &[from]].concat();
        let at = bytes.windows(entry.len()).position(|w| w == entry).unwrap();
        bytes[at + entry.len() - 1] = to;
        std::fs::write(out, bytes).unwrap();
    }

    /// The reviewer's case: `lanes: 8` with a model of window 4 (lane period 5) was reported
    /// without the settings or the model. The model: the infer crate's step-model fixture
    /// with its `lidar_har.window` metadata "8" made "4".
    #[test]
    fn lanes_that_do_not_fit_the_model_name_the_settings_and_the_model() {
        if !onnx_runtime_installed() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("window4.onnx");
        fixture_with_metadata("step_model.onnx", b"lidar_har.window", b'8', b'4', &model);

        let config = parse_classifier_config("lanes: 8\npose_head: null\n").unwrap();
        let e = ClassifierStage::load(&config, Some(&model))
            .map(|_| ())
            .unwrap_err();
        assert!(matches!(e, ClassifierError::LanesDoNotFit { .. }), "{e}");
        assert_eq!(
            e.to_string(),
            format!(
                "lanes = 8 and lane_period_windows = 1.2 do not fit model {} (a window of 4 \
                 scans): 8 lanes: need at least 2 (a restarting lane has no history) and at \
                 most the lane period (5 scans)",
                model.display()
            )
        );
    }

    /// A head asking for more history than the lane period gives any state never placed a
    /// pelvis, and the run said nothing of it. The head: the infer crate's fixture, fitted on
    /// its step model (window 8), with its min_history "3" made "9".
    #[test]
    fn a_head_asking_for_more_history_than_the_lanes_give_is_not_used_and_says_why() {
        if !onnx_runtime_installed() {
            return;
        }
        let model = infer_fixture("step_model.onnx");
        let dir = tempfile::tempdir().unwrap();
        let head = dir.path().join("pose_head_9.onnx");
        let min_history = b"lidar_har.pose_head.min_history";
        fixture_with_metadata("pose_head.onnx", min_history, b'3', b'9', &head);

        // Lane period 8 scans (1.0 x the window of 8): no state ever has 9 behind it.
        let config = ClassifierConfig {
            pose_head: Some(head.clone()),
            lane_period_windows: 1.0,
            ..ClassifierConfig::default()
        };
        let stage = ClassifierStage::load(&config, Some(&model)).unwrap();
        let PoseHeadStatus::NotUsed { path, reason } = stage.pose_head() else {
            panic!("{}", stage.pose_head());
        };
        assert_eq!(path, &head);
        assert_eq!(
            reason,
            &format!(
                "pose head {} reads states with at least 9 scans behind them \
                 (lidar_har.pose_head.min_history), more than the lane period's 8 scans \
                 (lane_period_windows = 1 x the window of 8 scans of model {}), after which \
                 every state restarts: raise lane_period_windows, or use a head fitted from an \
                 earlier step",
                head.display(),
                model.display()
            )
        );
        // A period of 10 scans (1.2 x 8) reaches it.
        let config = ClassifierConfig {
            lane_period_windows: 1.2,
            ..config
        };
        let stage = ClassifierStage::load(&config, Some(&model)).unwrap();
        assert_eq!(stage.pose_head(), &PoseHeadStatus::Used { path: head });
    }

    #[test]
    fn the_message_classes_are_the_cores_in_the_same_order() {
        assert_eq!(usize::from(har::Activity::NUM_CLASSES), Activity::COUNT);
        for activity in Activity::ALL {
            let msg = activity_msg(
                Header::default(),
                &Prediction {
                    stamp_s: 0.0,
                    activity,
                    confidence: 1.0,
                    probabilities: [0.0; Activity::COUNT],
                    history: 20,
                    ready: true,
                },
            );
            assert_eq!(
                har::Activity::label_of(msg.activity),
                Some(activity.label())
            );
            assert_eq!(activity_of(&msg), Some(activity));
        }
    }

    #[test]
    fn the_committed_config_file_is_valid() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/classifier.yaml");
        let config = load_classifier_config(&path).unwrap();
        assert_eq!(
            config,
            ClassifierConfig::default(),
            "config/classifier.yaml should state the defaults"
        );
    }

    #[test]
    fn one_fall_alert_setting_changes_by_name_and_bad_ones_are_refused() {
        let defaults = FallAlertConfig::default();
        let changed = with_fall_alert_setting(&defaults, "fall_min_scans=7").unwrap();
        assert_eq!(changed.fall_min_scans, 7);
        assert_eq!(
            FallAlertConfig {
                fall_min_scans: defaults.fall_min_scans,
                ..changed
            },
            defaults,
            "nothing else changes"
        );
        let changed = with_fall_alert_setting(&changed, "fall_on_first_sight = false").unwrap();
        assert!(!changed.fall_on_first_sight);
        assert_eq!(changed.fall_min_scans, 7);
        for (setting, needle) in [
            ("fall_min_scans", "expected KEY=VALUE"),
            (
                "fall_min_scan=7",
                "no such setting; known: fall_probability",
            ),
            ("fall_min_scans=many", "fall_min_scans=many"),
            ("down_after_s=[1, 2]", "down_after_s"),
            ("down_after_s=-1", "down_after_s"),
            ("down_after_s=.nan", "down_after_s"),
        ] {
            let err = with_fall_alert_setting(&defaults, setting)
                .unwrap_err()
                .to_string();
            assert!(err.contains(needle), "{setting}: {err}");
        }
    }

    #[test]
    fn time_going_back_ends_a_segment() {
        // A bag played twice: the first pass ends standing, the second starts standing.
        let mut segments = Segments::default();
        let pass = [0, 50_000_000, 100_000_000];
        for offset_ns in [60_000_000_000, 0] {
            for t in pass {
                segments.add(offset_ns + t, Activity::Standing, 0.9, None);
            }
        }
        segments.close();
        let spans: Vec<(i64, i64, usize)> = (segments.done.iter())
            .map(|s| {
                (
                    (s.start_s * 1e3).round() as i64,
                    (s.end_s * 1e3).round() as i64,
                    s.scans,
                )
            })
            .collect();
        assert_eq!(spans, [(60_000, 60_100, 3), (0, 100, 3)]);
    }

    #[test]
    fn activity_log_scores_against_truth_and_makes_segments() {
        let outputs = run(
            vec![
                (0.0, Activity::Walking),
                (3.0, Activity::FallingDown),
                (4.0, Activity::LyingDown),
            ],
            8.0,
        );
        let mut log = ActivityLog::default();
        // Truth: walking to 3.0, falling to 4.2 (the model switches to lying 0.2 s early),
        // each sample coming just before the scan of the same stamp, as in a bag.
        let mut outputs_in_order = outputs.iter().map(|(out, _)| out).peekable();
        for k in 0..160 {
            let t = k as f64 * 0.05;
            let a = if t < 3.0 {
                Activity::Walking
            } else if t < 4.2 {
                Activity::FallingDown
            } else {
                Activity::LyingDown
            };
            let msg = har::Activity {
                activity: a.index() as u8,
                ..Default::default()
            };
            let stamp_ns = (t * 1e9) as i64;
            log.add_truth(stamp_ns, &msg);
            while let Some(out) = outputs_in_order.next_if(|out| out.stamp_ns <= stamp_ns) {
                log.add_output(out);
            }
        }
        outputs_in_order.for_each(|out| log.add_output(out));
        let summary = log.finish();
        assert_eq!(summary.scans_classified, 157);
        // 4 of 157 scans (4.0 .. 4.15) disagree.
        let accuracy = summary.accuracy.unwrap();
        assert!((accuracy - 153.0 / 157.0).abs() < 1e-9, "{accuracy}");
        assert_eq!(
            summary.alerts.len(),
            1,
            "down for 4 s only: no PERSON_DOWN yet"
        );
        assert_eq!(summary.alerts[0].kind, "FALL_DETECTED");
        assert!((summary.alerts[0].event_time_s - 3.0).abs() < 1e-6);
        let kinds: Vec<Activity> = summary.segments.iter().map(|s| s.activity).collect();
        assert_eq!(
            kinds,
            [
                Activity::Walking,
                Activity::FallingDown,
                Activity::LyingDown
            ]
        );
        assert_eq!(summary.segments[1].truth, Some(Activity::FallingDown));
        assert!((summary.segments[1].start_s - 3.0).abs() < 1e-6);
        assert!((summary.segments[1].end_s - 3.95).abs() < 1e-6);
        // Without truth: no accuracy, segments without truth.
        let mut bare = ActivityLog::default();
        for (out, _) in &outputs {
            bare.add_output(out);
        }
        let summary = bare.finish();
        assert!(summary.accuracy.is_none() && summary.metrics.is_none());
        assert!(summary.segments.iter().all(|s| s.truth.is_none()));
    }
}
