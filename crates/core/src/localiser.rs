//! Finds and tracks the person in each scan (the paper's localisation step, made robust).
//!
//! Per scan: the Lidar's pose in the map at the scan's stamp (`map -> odom` correction, the
//! odometry interpolated at the stamp, the `base_link -> laser` mount) and, for a Lidar
//! that sweeps, at its last beam; each return moved into the map frame from the pose at its
//! own time ([`crate::sweep`]); returns within `obstacle_margin_m` of a mapped obstacle
//! (or, without a map, not in front of the learned background) dropped as room; the rest
//! clustered; the clusters (and, with a map, the groups too small to be clusters but clear
//! of the room) handed to the tracker, which picks the person; a hidden person's prediction
//! kept out of what the scan sees through ([`crate::visibility`]) and out of mapped
//! obstacles, and reported as slowing down ([`PersonEstimate::slowed`]).
//!
//! Nothing here logs: every problem with the input comes back as a [`Warning`] for the host
//! to count and report (rate-limited), and what cannot be used is skipped. No `NaN` from the
//! input reaches an output.

use std::collections::VecDeque;

use glam::DVec2;
use serde::{Deserialize, Serialize};

use crate::background::{BackgroundConfig, BackgroundStatus, LearnedBackground};
use crate::cluster::{Cluster, ClusterConfig, Clusterer};
use crate::geometry::{Pose2, normalize_angle};
use crate::map::OccupancyMap;
use crate::scan::{BeamDirections, MAX_SWEEP_S, Scan, ScanError};
use crate::sweep::BeamPoses;
use crate::tracker::{PersonEstimate, Tracker, TrackerConfig, seconds_between};
use crate::visibility::{ScanView, ShadowConfig};

/// Every parameter of the localiser, with the paper's values as defaults
/// (`config/localiser.yaml` holds the same values, documented).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LocaliserConfig {
    /// Returns closer than this to a mapped obstacle belong to the room (m; paper: 0.2).
    pub obstacle_margin_m: f64,
    /// The margin widens with range, because range noise grows with it: a return at range
    /// `r` is room within `sqrt(obstacle_margin_m^2 + (range_margin_fraction * r)^2)` of an
    /// obstacle. 0.05 is 2.5 standard deviations of the paper's 2 % range noise: at 10 m
    /// it keeps far walls' noisy returns (sigma 0.2 m) from becoming clutter.
    pub range_margin_fraction: f64,
    /// Inside the tracked person's gate the margin is this instead of `obstacle_margin_m`
    /// (still widened with range), so a person lying or sitting against a wall or furniture
    /// keeps their points; range noise rarely pushes a wall's returns this far (m).
    pub near_person_margin_m: f64,
    /// Returns in cells of unknown state (behind the walls, where range noise puts some wall
    /// returns) belong to the room too; off the map always does.
    pub unknown_is_room: bool,
    /// The Lidar sees only the near side of a person, so the centroid of their points lies
    /// closer to it than their centre; clusters are moved this far away from the Lidar (m).
    /// 0.06 is the median radial bias measured over the simulator's scenes (the
    /// `localiser_accuracy` example: 0.062 overall, 0.063 standing, 0.079 walking: about
    /// pi/4 of a shin's radius plus the far leg hidden behind the near one).
    pub centroid_offset_m: f64,
    /// A group of returns too small to be a cluster can be a piece of a still person
    /// (`tracker.still_pieces_min_points`) only when one of its points is this far from mapped
    /// obstacles (m): stray returns of walls and furniture lie just past the margin.
    pub piece_clearance_m: f64,
    pub cluster: ClusterConfig,
    pub tracker: TrackerConfig,
    pub shadow: ShadowConfig,
    pub background: BackgroundConfig,
    pub odometry: OdometryConfig,
    /// Lidar pose on the robot (`base_link -> laser`) until /tf_static gives one. Each of
    /// its `x`, `y` and `theta` may be left out of a file, like any other key.
    #[serde(deserialize_with = "deserialize_mount")]
    pub mount: Pose2,
    pub frames: FrameConfig,
}

impl Default for LocaliserConfig {
    fn default() -> Self {
        Self {
            obstacle_margin_m: 0.2,
            range_margin_fraction: 0.05,
            near_person_margin_m: 0.08,
            unknown_is_room: true,
            centroid_offset_m: 0.06,
            cluster: ClusterConfig::default(),
            piece_clearance_m: 0.5,
            tracker: TrackerConfig::default(),
            shadow: ShadowConfig::default(),
            background: BackgroundConfig::default(),
            odometry: OdometryConfig::default(),
            mount: Pose2::IDENTITY,
            frames: FrameConfig::default(),
        }
    }
}

/// Reads `mount` with each field optional, taking the default mount's where left out:
/// `Pose2` on its own requires all three, so `mount: {x: 0.1}` used to be refused.
fn deserialize_mount<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<Pose2, D::Error> {
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields, default)]
    struct MountFields {
        x: f64,
        y: f64,
        theta: f64,
    }
    impl Default for MountFields {
        fn default() -> Self {
            let Pose2 { x, y, theta } = LocaliserConfig::default().mount;
            Self { x, y, theta }
        }
    }
    let MountFields { x, y, theta } = MountFields::deserialize(deserializer)?;
    Ok(Pose2::new(x, y, theta))
}

/// Why a configuration cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("localiser configuration: `{key}` = {value} {why}")]
pub struct ConfigError {
    pub key: &'static str,
    pub value: String,
    pub why: &'static str,
}

impl LocaliserConfig {
    /// Checks values that serde cannot: signs, ranges, finiteness.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let non_negative = [
            ("obstacle_margin_m", self.obstacle_margin_m),
            ("range_margin_fraction", self.range_margin_fraction),
            ("near_person_margin_m", self.near_person_margin_m),
            ("piece_clearance_m", self.piece_clearance_m),
            ("tracker.gate_growth_mps", self.tracker.gate_growth_mps),
            ("tracker.part_merge_m", self.tracker.part_merge_m),
            ("tracker.midpoint_length_m", self.tracker.midpoint_length_m),
            ("tracker.still_window_s", self.tracker.still_window_s),
            (
                "tracker.long_body_offset_m",
                self.tracker.long_body_offset_m,
            ),
            (
                "tracker.part_merge_still_m",
                self.tracker.part_merge_still_m,
            ),
            ("tracker.still_speed_mps", self.tracker.still_speed_mps),
            (
                "tracker.hidden_speed_decay_s",
                self.tracker.hidden_speed_decay_s,
            ),
            ("shadow.pass_margin_m", self.shadow.pass_margin_m),
            ("shadow.min_clearance_m", self.shadow.min_clearance_m),
            (
                "background.learn_duration_s",
                self.background.learn_duration_s,
            ),
            ("background.margin_m", self.background.margin_m),
            ("background.raise_after_s", self.background.raise_after_s),
            (
                "odometry.max_extrapolation_s",
                self.odometry.max_extrapolation_s,
            ),
            ("odometry.max_wait_s", self.odometry.max_wait_s),
        ];
        let positive = [
            // 0 would split every pair of returns: nobody found, and nothing said.
            ("cluster.tolerance_m", self.cluster.tolerance_m),
            ("cluster.max_extent_m", self.cluster.max_extent_m),
            ("tracker.gate_m", self.tracker.gate_m),
            ("tracker.max_gate_m", self.tracker.max_gate_m),
            ("tracker.accel_std_mps2", self.tracker.accel_std_mps2),
            ("tracker.measurement_std_m", self.tracker.measurement_std_m),
            (
                "tracker.initial_velocity_std_mps",
                self.tracker.initial_velocity_std_mps,
            ),
            ("tracker.max_speed_mps", self.tracker.max_speed_mps),
            // 0 would drop every track between two scans: nobody tracked, and nothing said.
            ("tracker.max_coast_s", self.tracker.max_coast_s),
            ("shadow.body_radius_m", self.shadow.body_radius_m),
            ("shadow.search_m", self.shadow.search_m),
            (
                "odometry.max_interpolation_gap_s",
                self.odometry.max_interpolation_gap_s,
            ),
            ("odometry.max_speed_mps", self.odometry.max_speed_mps),
            (
                "odometry.max_turn_rate_radps",
                self.odometry.max_turn_rate_radps,
            ),
            ("odometry.buffer_s", self.odometry.buffer_s),
        ];
        for (key, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ConfigError {
                    key,
                    value: value.to_string(),
                    why: "must be finite and >= 0",
                });
            }
        }
        for (key, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(ConfigError {
                    key,
                    value: value.to_string(),
                    why: "must be finite and > 0",
                });
            }
        }
        // Values used squared (variances, squared distances) must square to a finite number
        // too: a finite and positive `tracker.initial_velocity_std_mps` of 1e200 passed the
        // checks above, squared to inf, turned every track's filter into NaN, and nobody was
        // tracked, silently. The margins are squared into f32.
        let squared_f64 = [
            ("tracker.accel_std_mps2", self.tracker.accel_std_mps2),
            ("tracker.measurement_std_m", self.tracker.measurement_std_m),
            (
                "tracker.initial_velocity_std_mps",
                self.tracker.initial_velocity_std_mps,
            ),
            ("cluster.tolerance_m", self.cluster.tolerance_m),
        ];
        let squared_f32 = [
            ("obstacle_margin_m", self.obstacle_margin_m),
            ("range_margin_fraction", self.range_margin_fraction),
            ("near_person_margin_m", self.near_person_margin_m),
        ];
        let squares = squared_f64
            .into_iter()
            .map(|(key, value)| (key, value, value.powi(2).is_finite()))
            .chain(
                squared_f32
                    .into_iter()
                    .map(|(key, value)| (key, value, (value.powi(2) as f32).is_finite())),
            );
        for (key, value, finite) in squares {
            if !finite {
                // In exponent form: 1e200 in full is 201 digits.
                return Err(ConfigError {
                    key,
                    value: format!("{value:e}"),
                    why: "is too large: its square, used as a variance or squared distance, \
                          is not finite",
                });
            }
        }
        if !self.centroid_offset_m.is_finite() {
            return Err(ConfigError {
                key: "centroid_offset_m",
                value: self.centroid_offset_m.to_string(),
                why: "must be finite",
            });
        }
        if !(0.0..=1.0).contains(&self.background.min_return_fraction) {
            return Err(ConfigError {
                key: "background.min_return_fraction",
                value: self.background.min_return_fraction.to_string(),
                why: "must be in [0, 1]",
            });
        }
        if !self.mount.is_finite() {
            return Err(ConfigError {
                key: "mount",
                value: format!("{:?}", self.mount),
                why: "must be finite",
            });
        }
        Ok(())
    }
}

/// How odometry is trusted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryConfig {
    /// Odometry samples farther apart than this are a gap: scans inside it are skipped (s).
    pub max_interpolation_gap_s: f64,
    /// A scan may be this much newer (or older) than the newest (oldest) sample (s).
    pub max_extrapolation_s: f64,
    /// A scan newer than the newest sample waits up to this long, in receive time, for a
    /// sample at or after its stamp (odometry delivered late, as a tf2 message filter
    /// waits for its transform); then it is placed with what there is (s; 0: no wait).
    /// The host does the waiting (`lidar_har_pipeline::odometry_wait`), not the core.
    pub max_wait_s: f64,
    /// Motion between samples faster than this is a jump (a reset or a glitch), not driving.
    pub max_speed_mps: f64,
    pub max_turn_rate_radps: f64,
    /// Samples older than this behind the newest are forgotten (s).
    pub buffer_s: f64,
    /// Each beam placed from the pose at its own time (`stamp + i * time_increment`), so a
    /// turning robot's walls stay on the map ([`crate::sweep`]). Scans with
    /// `time_increment` 0 are placed from one pose either way.
    pub deskew: bool,
}

impl Default for OdometryConfig {
    fn default() -> Self {
        // The paper's robot drives at up to 0.2 m/s; 2 m/s leaves room for any cleaning robot.
        Self {
            max_interpolation_gap_s: 0.5,
            max_extrapolation_s: 0.1,
            // A few scans' delay: odometry delivered a few hundred ms late is waited for.
            max_wait_s: 0.5,
            max_speed_mps: 2.0,
            max_turn_rate_radps: 6.0,
            buffer_s: 5.0,
            deskew: true,
        }
    }
}

/// Frame names (REP-105) the host uses to pick transforms out of /tf and /tf_static.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrameConfig {
    pub map: String,
    pub odom: String,
    pub base: String,
}

impl Default for FrameConfig {
    fn default() -> Self {
        Self {
            map: "map".into(),
            odom: "odom".into(),
            base: "base_link".into(),
        }
    }
}

/// Something wrong with the input; the host counts and reports these (rate-limited).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Warning {
    #[error("scan skipped: {0}")]
    InvalidScan(ScanError),
    #[error("scan skipped: stamp {stamp_ns} ns is not after the previous scan's {previous_ns} ns")]
    ScanNotAfterPrevious { stamp_ns: i64, previous_ns: i64 },
    #[error("time jumped back by {back_s:.3} s: tracks and odometry were reset")]
    TimeReset { back_s: f64 },
    #[error("{count} NaN ranges ignored")]
    NanRanges { count: usize },
    #[error("scan skipped: no map received yet")]
    NoMap,
    #[error("scan skipped: no odometry at its stamp")]
    NoOdometry,
    #[error("scan skipped: odometry has a {gap_s:.3} s gap around its stamp")]
    OdometryGap { gap_s: f64 },
    #[error("scan skipped: the newest odometry is {age_s:.3} s older than the scan")]
    OdometryStale { age_s: f64 },
    #[error(
        "scan skipped: odometry jumps around its stamp ({speed_mps:.2} m/s, {turn_rate_radps:.2} rad/s)"
    )]
    OdometryJump {
        speed_mps: f64,
        turn_rate_radps: f64,
    },
    #[error("odometry out of order: {stamp_ns} ns arrived after {latest_ns} ns")]
    OdometryOutOfOrder { stamp_ns: i64, latest_ns: i64 },
    #[error("odometry sample ignored: it is older than the buffer")]
    OdometryTooOld,
    #[error(
        "odometry sample ignored: stamped {ahead_s:.3} s ahead of the odometry before and after it"
    )]
    OdometryAhead { ahead_s: f64 },
    #[error("odometry went back {back_s:.3} s and stayed there: its samples before were dropped")]
    OdometryRestarted { back_s: f64 },
    #[error("ignored a non-finite {what}")]
    NonFinite { what: &'static str },
    #[error("scan not de-skewed (every beam placed from the pose at its stamp): {0}")]
    NotDeskewed(DeskewProblem),
    #[error(
        "scans come {period_s:.3} s apart, more than tracker.max_coast_s = {max_coast_s} s: \
         every track is lost between two scans, so nobody is tracked"
    )]
    ScanPeriodOverCoast { period_s: f64, max_coast_s: f64 },
}

/// Why a scan's beams could not each be placed from their own pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DeskewProblem {
    #[error(
        "time_increment {0} s is not finite or spreads the beams over more than {MAX_SWEEP_S} s"
    )]
    TimeIncrement(f32),
    #[error("no usable odometry at its last beam, {offset_s:.3} s from its stamp")]
    NoOdometryAtLastBeam { offset_s: f64 },
    #[error(
        "the Lidar turned {turn_rad:.2} rad over it, more than {MAX_SWEEP_TURN_RAD:.2}: \
         which way round is not certain"
    )]
    TurnedTooFar { turn_rad: f64 },
}

/// The most a Lidar may turn over one scan for the turn to be interpolated: odometry at
/// the first and the last beam does not say which way round a larger turn went (a robot
/// turning at 3 rad/s turns 0.6 rad over the 0.2 s of a 5 Hz rotation).
pub const MAX_SWEEP_TURN_RAD: f64 = std::f64::consts::FRAC_PI_2;

impl Warning {
    /// A short stable name per kind, for counters and rate limiting.
    pub fn kind(&self) -> &'static str {
        match self {
            Warning::InvalidScan(_) => "invalid_scan",
            Warning::ScanNotAfterPrevious { .. } => "scan_not_after_previous",
            Warning::TimeReset { .. } => "time_reset",
            Warning::NanRanges { .. } => "nan_ranges",
            Warning::NoMap => "no_map",
            Warning::NoOdometry => "no_odometry",
            Warning::OdometryGap { .. } => "odometry_gap",
            Warning::OdometryStale { .. } => "odometry_stale",
            Warning::OdometryJump { .. } => "odometry_jump",
            Warning::OdometryOutOfOrder { .. } => "odometry_out_of_order",
            Warning::OdometryTooOld => "odometry_too_old",
            Warning::OdometryAhead { .. } => "odometry_ahead",
            Warning::OdometryRestarted { .. } => "odometry_restarted",
            Warning::NonFinite { .. } => "non_finite",
            Warning::NotDeskewed(_) => "not_deskewed",
            Warning::ScanPeriodOverCoast { .. } => "scan_period_over_max_coast",
        }
    }
}

/// What the room is subtracted with.
#[derive(Debug, Clone)]
pub enum Reference {
    /// The room's occupancy map (from /map, a map_server file or the simulator).
    Map(OccupancyMap),
    /// A background learned from the first scans of a stationary Lidar.
    Background(LearnedBackground),
    /// A map is expected but has not arrived: scans are skipped.
    AwaitingMap,
}

/// Where the robot's pose comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// A moving robot: odometry (and the `map -> odom` correction) at each scan's stamp.
    Odometry,
    /// A Lidar that does not move: `base_link` sits at this pose in the map (until
    /// [`Localiser::set_fixed_base`] says where its transforms place it).
    Stationary(Pose2),
}

/// The localiser's result for one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct LocaliserOutput {
    pub stamp_ns: i64,
    /// The Lidar's pose in the map frame at the scan's stamp (beam 0).
    pub laser_pose: Pose2,
    /// Its pose at the scan's last beam: `laser_pose` unless the scan was de-skewed. The
    /// beams between were placed from poses in between ([`BeamPoses::sweep`]).
    pub last_beam_pose: Pose2,
    /// Returns that were not the room.
    pub foreground_points: usize,
    /// Clusters that could be a person.
    pub clusters: usize,
    /// The tracked person, if any (possibly predicted through an occlusion).
    pub person: Option<PersonEstimate>,
}

/// What processing one scan gave: an output unless it was skipped or used for learning.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScanResult {
    pub output: Option<LocaliserOutput>,
    /// The scan went into the learned background (no output yet, and nothing wrong).
    pub learning: bool,
    pub warnings: Vec<Warning>,
}

/// Time-stamped odometry poses (`odom -> base_link`) for interpolation at scan stamps.
#[derive(Debug, Clone, Default)]
struct OdometryBuffer {
    samples: VecDeque<(i64, Pose2)>,
    /// A sample stamped more than `buffer_s` from the newest, either way, held out of the
    /// buffer until the next sample tells what it was. Taken at its word, one stray stamp
    /// (an hour ahead) would have forgotten the whole buffer and had every correct sample
    /// after it refused as too old, so that no scan was placed again; one far behind, as
    /// the first sample, the same. The next sample near it (or a scan near it, far from the
    /// buffer) says the odometry's time really moved there (a restart, a pause longer than
    /// the buffer); a sample that fits the buffer says it was a stray, and it is dropped.
    held: Option<(i64, Pose2)>,
}

impl OdometryBuffer {
    fn insert(&mut self, stamp_ns: i64, pose: Pose2, config: &OdometryConfig) -> Option<Warning> {
        if !pose.is_finite() {
            return Some(Warning::NonFinite {
                what: "odometry pose",
            });
        }
        let Some(&(latest_ns, _)) = self.samples.back() else {
            self.samples.push_back((stamp_ns, pose));
            return None;
        };
        let buffer_ns = (config.buffer_s * 1e9) as i64;
        if stamp_ns.abs_diff(latest_ns) > buffer_ns.unsigned_abs() {
            return self.hold(stamp_ns, pose, latest_ns, buffer_ns);
        }
        // This one fits: the one held was a stray. (Should this one also be out of order, the
        // stray is what is said.)
        let stray = self
            .held
            .take()
            .map(|(held_ns, _)| stray(held_ns, latest_ns));
        stray.or(self.add(stamp_ns, pose, buffer_ns))
    }

    /// Holds a sample more than `buffer_ns` from the newest, `latest_ns`, unless the one
    /// held before is near it: then the odometry's time has moved there, and both go in.
    fn hold(
        &mut self,
        stamp_ns: i64,
        pose: Pose2,
        latest_ns: i64,
        buffer_ns: i64,
    ) -> Option<Warning> {
        match self.held {
            Some((held_ns, _)) if held_ns.abs_diff(stamp_ns) <= buffer_ns.unsigned_abs() => {
                let restarted = self.take_held(buffer_ns);
                restarted.or(self.add(stamp_ns, pose, buffer_ns))
            }
            earlier => {
                self.held = Some((stamp_ns, pose));
                // Two strays that do not agree: the earlier one is dropped.
                earlier.map(|(held_ns, _)| stray(held_ns, latest_ns))
            }
        }
    }

    /// A scan stamped `stamp_ns`, more than `buffer_s` from the newest sample and near the
    /// held one, says as a second sample would that the odometry's time has moved there: the
    /// held sample is taken, and the first scan after a pause longer than the buffer is
    /// placed from it rather than skipped while the next sample is awaited.
    fn meet_scan(&mut self, stamp_ns: i64, config: &OdometryConfig) -> Option<Warning> {
        let (held_ns, _) = self.held?;
        let &(latest_ns, _) = self.samples.back()?;
        let buffer_ns = (config.buffer_s * 1e9) as i64;
        let near = |a: i64, b: i64| a.abs_diff(b) <= buffer_ns.unsigned_abs();
        if near(stamp_ns, latest_ns) || !near(stamp_ns, held_ns) {
            return None;
        }
        self.take_held(buffer_ns)
    }

    /// Time went back to a scan stamped `stamp_ns` (a bag looping, a simulation restarted):
    /// forgets the old timeline's samples, but not what already came for the new one, before
    /// its first scan (in a bag the odometry of a stamp comes before the scan). Samples
    /// no more than `TIME_RESET_S` ahead of the scan are the new timeline's, the buffer having
    /// moved there already; otherwise the sample held for being far from them is its first,
    /// where near the scan. Clearing both lost the new timeline's first scan to
    /// `no_odometry`. A jump back within the buffer mixes the two timelines' samples, which
    /// stamps cannot tell apart: all are forgotten.
    fn restart_at(&mut self, stamp_ns: i64, config: &OdometryConfig) {
        let reset_ns = (TIME_RESET_S * 1e9) as i64;
        let on_new_timeline = self
            .samples
            .back()
            .is_none_or(|&(latest_ns, _)| latest_ns <= stamp_ns.saturating_add(reset_ns));
        if on_new_timeline {
            return;
        }
        self.samples.clear();
        let buffer_ns = (config.buffer_s * 1e9) as i64;
        if let Some((held_ns, pose)) = self.held.take()
            && held_ns.abs_diff(stamp_ns) <= buffer_ns.unsigned_abs()
        {
            self.samples.push_back((held_ns, pose));
        }
    }

    /// Puts the held sample in: ahead of the newest, the samples before are forgotten as it
    /// goes in (a pause longer than the buffer, as always); behind, they are dropped first.
    fn take_held(&mut self, buffer_ns: i64) -> Option<Warning> {
        let (held_ns, held_pose) = self.held.take()?;
        let restarted = self
            .samples
            .back()
            .filter(|&&(latest_ns, _)| held_ns < latest_ns)
            .map(|&(latest_ns, _)| Warning::OdometryRestarted {
                back_s: latest_ns.abs_diff(held_ns) as f64 * 1e-9,
            });
        if restarted.is_some() {
            self.samples.clear();
        }
        self.add(held_ns, held_pose, buffer_ns);
        restarted
    }

    /// Puts a sample no more than `buffer_ns` behind the newest in order, forgetting those
    /// more than `buffer_ns` behind it.
    fn add(&mut self, stamp_ns: i64, pose: Pose2, buffer_ns: i64) -> Option<Warning> {
        let Some(&(latest_ns, _)) = self.samples.back() else {
            self.samples.push_back((stamp_ns, pose));
            return None;
        };
        if stamp_ns > latest_ns {
            self.samples.push_back((stamp_ns, pose));
            while self
                .samples
                .front()
                .is_some_and(|&(t, _)| t < stamp_ns.saturating_sub(buffer_ns))
            {
                self.samples.pop_front();
            }
            return None;
        }
        match self.samples.binary_search_by_key(&stamp_ns, |&(t, _)| t) {
            Ok(i) => self.samples[i].1 = pose,
            Err(i) => self.samples.insert(i, (stamp_ns, pose)),
        }
        (stamp_ns < latest_ns).then_some(Warning::OdometryOutOfOrder {
            stamp_ns,
            latest_ns,
        })
    }

    /// The pose at `stamp_ns`: interpolated between the samples around it, or extrapolated a
    /// little past either end.
    fn pose_at(&self, stamp_ns: i64, config: &OdometryConfig) -> Result<Pose2, Warning> {
        let (Some(&first), Some(&last)) = (self.samples.front(), self.samples.back()) else {
            return Err(Warning::NoOdometry);
        };
        let max_extrapolation_ns = (config.max_extrapolation_s * 1e9) as i64;
        let (a, b) = if stamp_ns < first.0 {
            if first.0.abs_diff(stamp_ns) > max_extrapolation_ns.unsigned_abs() {
                return Err(Warning::NoOdometry);
            }
            return Ok(first.1);
        } else if stamp_ns >= last.0 {
            let age_ns = stamp_ns.abs_diff(last.0);
            if age_ns > max_extrapolation_ns.unsigned_abs() {
                return Err(Warning::OdometryStale {
                    age_s: age_ns as f64 * 1e-9,
                });
            }
            match self.samples.len() {
                1 => return Ok(last.1),
                n => {
                    let before = self.samples[n - 2];
                    // The first sample after a pause stands alone, as a single one does.
                    if seconds_between(before.0, last.0) > config.max_interpolation_gap_s {
                        return Ok(last.1);
                    }
                    (before, last)
                }
            }
        } else {
            let i = self.samples.partition_point(|&(t, _)| t <= stamp_ns);
            (self.samples[i - 1], self.samples[i])
        };
        let gap_s = seconds_between(a.0, b.0);
        if gap_s > config.max_interpolation_gap_s {
            return Err(Warning::OdometryGap { gap_s });
        }
        let speed_mps = a.1.position().distance(b.1.position()) / gap_s;
        let turn_rate_radps = crate::geometry::normalize_angle(b.1.theta - a.1.theta).abs() / gap_s;
        if speed_mps > config.max_speed_mps || turn_rate_radps > config.max_turn_rate_radps {
            return Err(Warning::OdometryJump {
                speed_mps,
                turn_rate_radps,
            });
        }
        let t = seconds_between(a.0, stamp_ns) / gap_s;
        Ok(a.1.lerp(&b.1, t))
    }
}

/// What is said of a sample at `stray_ns` dropped as a stray stamp, `latest_ns` being the
/// newest sample kept.
fn stray(stray_ns: i64, latest_ns: i64) -> Warning {
    if stray_ns > latest_ns {
        Warning::OdometryAhead {
            ahead_s: stray_ns.abs_diff(latest_ns) as f64 * 1e-9,
        }
    } else {
        Warning::OdometryTooOld
    }
}

/// Time going back by more than this is a restart (a replayed bag looping, a simulator
/// reset), not jitter: the tracks and odometry are reset instead of skipping every scan.
const TIME_RESET_S: f64 = 1.0;

/// The localiser: feed it odometry, transforms, a map and scans in arrival order.
#[derive(Debug)]
pub struct Localiser {
    config: LocaliserConfig,
    reference: Reference,
    motion: Motion,
    odometry: OdometryBuffer,
    map_to_odom: Pose2,
    mount: Pose2,
    tracker: Tracker,
    last_scan_ns: Option<i64>,
    /// The stamp of the latest scan that passed the checks of its stamp, localised or not:
    /// the Lidar's period is measured between arrivals, since scans skipped for want of a
    /// pose say nothing of its rate.
    last_arrival_ns: Option<i64>,
    /// Whether the scan before came more than `tracker.max_coast_s` after the one before it.
    slow_scan: bool,
    directions: BeamDirections,
    clusterer: Clusterer,
    foreground: Vec<DVec2>,
    clusters: Vec<Cluster>,
    fragments: Vec<Cluster>,
}

impl Localiser {
    pub fn new(
        config: LocaliserConfig,
        reference: Reference,
        motion: Motion,
    ) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Self {
            reference,
            motion,
            odometry: OdometryBuffer::default(),
            map_to_odom: Pose2::IDENTITY,
            mount: config.mount,
            tracker: Tracker::new(config.tracker.clone()),
            last_scan_ns: None,
            last_arrival_ns: None,
            slow_scan: false,
            directions: BeamDirections::default(),
            clusterer: Clusterer::default(),
            foreground: Vec::new(),
            clusters: Vec::new(),
            fragments: Vec::new(),
            config,
        })
    }

    /// A localiser that learns its background from the first scans of a stationary Lidar.
    pub fn with_learned_background(config: LocaliserConfig) -> Result<Self, ConfigError> {
        let background = LearnedBackground::new(config.background.clone());
        Self::new(
            config,
            Reference::Background(background),
            Motion::Stationary(Pose2::IDENTITY),
        )
    }

    pub fn config(&self) -> &LocaliserConfig {
        &self.config
    }

    pub fn reference(&self) -> &Reference {
        &self.reference
    }

    /// The clusters of the latest localised scan (map frame, centroid offset applied), for
    /// diagnosis.
    pub fn clusters(&self) -> &[Cluster] {
        &self.clusters
    }

    /// Tracks ever confirmed: the people (and persistent unmapped objects) seen so far.
    pub fn confirmed_tracks(&self) -> u64 {
        self.tracker.confirmed_total()
    }

    /// Replaces the map (a new /map message); a learned background is kept unless replaced.
    pub fn set_map(&mut self, map: OccupancyMap) {
        self.reference = Reference::Map(map);
    }

    /// An odometry sample: the pose of `base_link` in `odom` at `stamp_ns`.
    pub fn add_odometry(&mut self, stamp_ns: i64, pose: Pose2) -> Option<Warning> {
        self.odometry.insert(stamp_ns, pose, &self.config.odometry)
    }

    /// Forgets every odometry sample: the host takes its odometry from another source from
    /// now on, and two sources (raw wheel odometry, a filter's fused pose) need not agree,
    /// so interpolating between their samples would place scans where neither puts the base.
    pub fn restart_odometry(&mut self) {
        self.odometry = OdometryBuffer::default();
    }

    /// The stamp of the newest odometry sample in use, if any: a scan stamped after it would
    /// be placed by extrapolation.
    pub fn latest_odometry_ns(&self) -> Option<i64> {
        self.odometry.samples.back().map(|&(stamp_ns, _)| stamp_ns)
    }

    /// The latest `map -> odom` correction (from AMCL or SLAM on /tf, or a known start pose
    /// on /tf_static).
    pub fn set_map_to_odom(&mut self, pose: Pose2) -> Option<Warning> {
        if !pose.is_finite() {
            return Some(Warning::NonFinite {
                what: "map -> odom transform",
            });
        }
        self.map_to_odom = pose;
        None
    }

    /// Where a fixed Lidar's base sits in the map: its transforms (`map -> odom -> base_link`),
    /// which the host resolves, place a sensor that has no odometry. A moving robot's base
    /// is placed by its odometry, and this does nothing.
    pub fn set_fixed_base(&mut self, pose: Pose2) -> Option<Warning> {
        if !pose.is_finite() {
            return Some(Warning::NonFinite {
                what: "map -> base_link transform",
            });
        }
        if let Motion::Stationary(base) = &mut self.motion {
            *base = pose;
        }
        None
    }

    /// The Lidar's mount on the robot (`base_link -> laser`, from /tf_static).
    pub fn set_mount(&mut self, pose: Pose2) -> Option<Warning> {
        if !pose.is_finite() {
            return Some(Warning::NonFinite {
                what: "base_link -> laser transform",
            });
        }
        self.mount = pose;
        None
    }

    /// Localises the person in `scan`.
    pub fn process_scan(&mut self, scan: &Scan) -> ScanResult {
        let mut result = ScanResult::default();
        if let Err(e) = scan.validate() {
            result.warnings.push(Warning::InvalidScan(e));
            return result;
        }
        if let Some(previous_ns) = self.last_scan_ns
            && scan.stamp_ns <= previous_ns
        {
            let back_s = previous_ns.abs_diff(scan.stamp_ns) as f64 * 1e-9;
            if back_s <= TIME_RESET_S {
                result.warnings.push(Warning::ScanNotAfterPrevious {
                    stamp_ns: scan.stamp_ns,
                    previous_ns,
                });
                return result;
            }
            result.warnings.push(Warning::TimeReset { back_s });
            self.tracker.reset();
            self.odometry
                .restart_at(scan.stamp_ns, &self.config.odometry);
            // The new timeline starts here even when this scan cannot be localised (its
            // odometry has not arrived yet): the next scan is not another restart.
            self.last_scan_ns = Some(scan.stamp_ns);
        }
        result
            .warnings
            .extend(self.check_scan_period(scan.stamp_ns));
        let nan = scan.ranges.iter().filter(|r| r.is_nan()).count();
        if nan > 0 {
            result.warnings.push(Warning::NanRanges { count: nan });
        }

        if self.motion == Motion::Odometry
            && let Some(w) = self
                .odometry
                .meet_scan(scan.stamp_ns, &self.config.odometry)
        {
            result.warnings.push(w);
        }
        let laser_pose = match self.laser_pose_at(scan.stamp_ns) {
            Ok(pose) => pose,
            Err(w) => {
                result.warnings.push(w);
                return result;
            }
        };
        let last_beam_pose = self.last_beam_pose(scan, laser_pose, &mut result.warnings);
        let beam_poses = BeamPoses::sweep(laser_pose, last_beam_pose, scan.ranges.len());

        if let Reference::Background(background) = &mut self.reference
            && background.observe(scan) == BackgroundStatus::Learning
        {
            self.last_scan_ns = Some(scan.stamp_ns);
            result.learning = true;
            return result;
        }
        self.foreground.clear();
        let directions = self.directions.for_scan(scan);
        match &mut self.reference {
            Reference::AwaitingMap => {
                result.warnings.push(Warning::NoMap);
                return result;
            }
            Reference::Map(map) => {
                let margin2 = self.config.obstacle_margin_m.powi(2) as f32;
                let fraction2 = self.config.range_margin_fraction.powi(2) as f32;
                let near2 = self.config.near_person_margin_m.powi(2) as f32;
                let person_zone = self.tracker.person_prediction(scan.stamp_ns);
                let unknown_is_room = self.config.unknown_is_room;
                for ((&r, &dir), to_map) in scan.ranges.iter().zip(directions).zip(beam_poses) {
                    if !scan.is_return(r) {
                        continue;
                    }
                    let p = to_map.transform_point2(dir * f64::from(r));
                    // Off the map is outside the room: never the person.
                    let clearance = if unknown_is_room {
                        map.free_clearance(p)
                    } else {
                        map.distance_to_obstacle(p)
                    };
                    let Some(clearance) = clearance else { continue };
                    let (d2, noise2) = (clearance * clearance, fraction2 * r * r);
                    let near_person = || {
                        person_zone.is_some_and(|(c, gate)| p.distance_squared(c) <= gate * gate)
                    };
                    if d2 >= margin2 + noise2 || (d2 >= near2 + noise2 && near_person()) {
                        self.foreground.push(p);
                    }
                }
            }
            Reference::Background(background) => {
                // Each beam's threshold by its angle, not its index: the beam count may
                // change from one rotation to the next.
                let thresholds = background.thresholds(scan);
                let beams = scan.ranges.iter().zip(thresholds);
                for ((&r, &threshold), (&dir, to_map)) in
                    beams.zip(directions.iter().zip(beam_poses))
                {
                    if scan.is_return(r) && r < threshold {
                        self.foreground
                            .push(to_map.transform_point2(dir * f64::from(r)));
                    }
                }
            }
        }
        self.last_scan_ns = Some(scan.stamp_ns);

        self.clusterer.cluster(
            &self.foreground,
            &self.config.cluster,
            &mut self.clusters,
            &mut self.fragments,
        );
        // Groups too small to be clusters may be pieces of a still person, but stray returns
        // of walls and furniture lie just past the margin: only groups reaching clear of the
        // mapped room count. Without a map nothing says where the room is, so none do.
        match &self.reference {
            Reference::Map(map) => {
                let clear = self.config.piece_clearance_m;
                self.fragments.retain(|piece| {
                    piece.points.iter().any(|&p| {
                        map.distance_to_obstacle(p)
                            .is_some_and(|c| f64::from(c) >= clear)
                    })
                });
            }
            _ => self.fragments.clear(),
        }
        let offset = self.config.centroid_offset_m;
        if offset != 0.0 {
            let sensor = laser_pose.position();
            for cluster in self.clusters.iter_mut().chain(&mut self.fragments) {
                cluster.centroid += (cluster.centroid - sensor).normalize_or_zero() * offset;
            }
        }
        let mut person = self
            .tracker
            .update(scan.stamp_ns, &self.clusters, &self.fragments);
        if let Some(person) = person.as_mut().filter(|p| !p.visible) {
            let shadow = &self.config.shadow;
            let view = shadow
                .enabled
                .then(|| ScanView::sweeping(scan, laser_pose, last_beam_pose));
            if let (Reference::Map(map), Some(view)) = (&self.reference, &view) {
                let room_for_a_body = |p: DVec2| {
                    map.free_clearance(p)
                        .is_some_and(|c| f64::from(c) >= shadow.min_clearance_m)
                };
                if let Some(hidden) = view.nearest_hidden(person.position, map, shadow)
                    && let Some(velocity) = self.tracker.place_hidden_person(hidden)
                {
                    (person.position, person.velocity) = (hidden, velocity);
                } else if let Some(halted) = self.tracker.halt_hidden_person(room_for_a_body) {
                    (person.position, person.velocity) = (halted, DVec2::ZERO);
                }
            }
            let decay_s = self.config.tracker.hidden_speed_decay_s;
            report_slowed(person, decay_s, view.as_ref(), shadow);
        }
        result.output = Some(LocaliserOutput {
            stamp_ns: scan.stamp_ns,
            laser_pose,
            last_beam_pose,
            foreground_points: self.foreground.len(),
            clusters: self.clusters.len(),
            person,
        });
        result
    }

    /// Warns when scans keep coming farther apart than `tracker.max_coast_s`: the tracker
    /// loses every track across such a gap, so none lives from one scan to the next (a
    /// 5.5 Hz Lidar and a `max_coast_s` under its 0.18 s period tracked nobody, silently).
    /// One such gap alone (a Lidar stopped while docked) is not warned about: losing the
    /// tracks across it is meant. Measured between scans that arrived, not only those
    /// localised: two odometry outages in a row had blamed the Lidar's rate.
    fn check_scan_period(&mut self, stamp_ns: i64) -> Option<Warning> {
        let max_coast_s = self.config.tracker.max_coast_s;
        let period_s = self
            .last_arrival_ns
            .replace(stamp_ns)
            .map_or(0.0, |previous| seconds_between(previous, stamp_ns));
        let slow = period_s > max_coast_s;
        let slow_before = std::mem::replace(&mut self.slow_scan, slow);
        (slow && slow_before).then_some(Warning::ScanPeriodOverCoast {
            period_s,
            max_coast_s,
        })
    }

    /// The Lidar's pose in the map at `stamp_ns`.
    fn laser_pose_at(&self, stamp_ns: i64) -> Result<Pose2, Warning> {
        let base_in_map = match self.motion {
            Motion::Stationary(pose) => pose,
            Motion::Odometry => {
                let odom = self.odometry.pose_at(stamp_ns, &self.config.odometry)?;
                self.map_to_odom.compose(&odom)
            }
        };
        Ok(base_in_map.compose(&self.mount))
    }

    /// Where the last beam of `scan` was measured from, given beam 0's `laser_pose`: the
    /// same pose unless the scan is de-skewed. A scan that cannot be de-skewed is placed
    /// from `laser_pose` alone, with a warning.
    fn last_beam_pose(&self, scan: &Scan, laser_pose: Pose2, warnings: &mut Vec<Warning>) -> Pose2 {
        let moving = matches!(self.motion, Motion::Odometry);
        if !(moving && self.config.odometry.deskew) || scan.time_increment == 0.0 {
            return laser_pose;
        }
        let Some(sweep_ns) = scan.sweep_ns() else {
            warnings.push(Warning::NotDeskewed(DeskewProblem::TimeIncrement(
                scan.time_increment,
            )));
            return laser_pose;
        };
        let problem = match self.laser_pose_at(scan.stamp_ns.saturating_add(sweep_ns)) {
            Err(_) => DeskewProblem::NoOdometryAtLastBeam {
                offset_s: sweep_ns as f64 * 1e-9,
            },
            Ok(last) => {
                let turn_rad = normalize_angle(last.theta - laser_pose.theta);
                if turn_rad.abs() <= MAX_SWEEP_TURN_RAD {
                    return last;
                }
                DeskewProblem::TurnedTooFar { turn_rad }
            }
        };
        warnings.push(Warning::NotDeskewed(problem));
        laser_pose
    }
}

/// Reports a hidden person where they are if their speed decayed since they vanished
/// ([`PersonEstimate::slowed`]; a person just seen stays where they are), unless `view`
/// sees through that place: then they did not stop there, and the track's straight line
/// stands.
fn report_slowed(
    person: &mut PersonEstimate,
    decay_s: f64,
    view: Option<&ScanView>,
    shadow: &ShadowConfig,
) {
    let (position, velocity) = person.slowed(decay_s);
    if view.is_none_or(|view| !view.sees_through(position, shadow)) {
        (person.position, person.velocity) = (position, velocity);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::MapGeometry;

    const PERIOD_NS: i64 = 50_000_000;

    /// A 10 m x 10 m room at 5 cm with walls on its border, origin at (-5, -5).
    fn room() -> OccupancyMap {
        let n = 200;
        let occupied = (0..n * n)
            .map(|i| i % n == 0 || i % n == n - 1 || i / n == 0 || i / n == n - 1)
            .collect();
        let geometry = MapGeometry {
            resolution: 0.05,
            origin: Pose2::new(-5.0, -5.0, 0.0),
            width: n,
            height: n,
        };
        OccupancyMap::new(geometry, occupied).unwrap()
    }

    /// Ray-casts a 720-beam scan from `laser` in the room with a round person of radius 0.2 m.
    fn cast(stamp_ns: i64, laser: Pose2, person: Option<DVec2>) -> Scan {
        cast_with_radius(stamp_ns, laser, person, 0.2)
    }

    /// [`cast`] with a person of any radius.
    fn cast_with_radius(stamp_ns: i64, laser: Pose2, person: Option<DVec2>, radius: f64) -> Scan {
        cast_sweeping(stamp_ns, |_| laser, 0.0, person, radius)
    }

    /// [`cast_with_radius`] from a Lidar that moves while it turns: beam `i` is measured
    /// from `laser_at(i * time_increment)`, seconds after the stamp.
    fn cast_sweeping(
        stamp_ns: i64,
        laser_at: impl Fn(f64) -> Pose2,
        time_increment: f64,
        person: Option<DVec2>,
        radius: f64,
    ) -> Scan {
        let n = 720;
        let inc = std::f64::consts::TAU / n as f64;
        let ranges = (0..n)
            .map(|i| {
                let laser = laser_at(i as f64 * time_increment);
                let a = laser.theta + -std::f64::consts::PI + i as f64 * inc;
                let d = DVec2::from_angle(a);
                let o = laser.position();
                // Walls at +-4.95 (inner face of the border cells).
                let tx = if d.x > 0.0 {
                    (4.95 - o.x) / d.x
                } else {
                    (-4.95 - o.x) / d.x
                };
                let ty = if d.y > 0.0 {
                    (4.95 - o.y) / d.y
                } else {
                    (-4.95 - o.y) / d.y
                };
                let mut r = tx.min(ty);
                if let Some(t) = person.and_then(|c| ray_to_disc(o, d, c, radius)) {
                    r = r.min(t);
                }
                r as f32
            })
            .collect();
        full_turn_scan(stamp_ns, ranges, time_increment)
    }

    /// A scan of `ranges` over one full turn from -pi, beams `time_increment` seconds apart.
    fn full_turn_scan(stamp_ns: i64, ranges: Vec<f32>, time_increment: f64) -> Scan {
        Scan {
            stamp_ns,
            angle_min: -std::f32::consts::PI,
            angle_increment: (std::f64::consts::TAU / ranges.len() as f64) as f32,
            time_increment: time_increment as f32,
            range_min: 0.05,
            range_max: 12.0,
            ranges,
        }
    }

    fn map_localiser(motion: Motion) -> Localiser {
        Localiser::new(LocaliserConfig::default(), Reference::Map(room()), motion).unwrap()
    }

    #[test]
    fn a_person_walking_past_a_moving_robot_is_tracked_in_the_map_frame() {
        let mut loc = map_localiser(Motion::Odometry);
        let mount = Pose2::new(0.1, 0.0, 0.0);
        loc.set_mount(mount);
        let robot = |t: f64| Pose2::new(-2.0 + 0.2 * t, -1.0, 0.3 * t);
        let person = |t: f64| DVec2::new(2.0 - 0.8 * t, 1.0 + 0.2 * t);
        // Odometry at 50 Hz, scans at 20 Hz, both from t = 0.
        for k in 0..=250 {
            let t = k as f64 * 0.02;
            assert!(loc.add_odometry((t * 1e9) as i64, robot(t)).is_none());
        }
        let mut errors = Vec::new();
        for k in 0..100 {
            let stamp = k * PERIOD_NS;
            let t = stamp as f64 * 1e-9;
            let scan = cast(stamp, robot(t).compose(&mount), Some(person(t)));
            let result = loc.process_scan(&scan);
            assert!(result.warnings.is_empty(), "{:?}", result.warnings);
            let out = result.output.expect("localised");
            assert!(
                (out.laser_pose.position() - robot(t).compose(&mount).position()).length() < 1e-9
            );
            if k >= 3 {
                let est = out.person.expect("person tracked");
                assert!(est.visible);
                errors.push(est.position.distance(person(t)));
            }
        }
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        // The visible arc's centroid sits ~0.16 m in front of the centre of a 0.2 m cylinder.
        assert!(median < 0.2, "median error {median}");
    }

    #[test]
    fn the_centroid_offset_moves_the_estimate_to_the_body_centre() {
        let person = DVec2::new(2.0, 0.5);
        let error_with = |offset: f64| {
            let config = LocaliserConfig {
                centroid_offset_m: offset,
                ..LocaliserConfig::default()
            };
            let mut loc = Localiser::new(
                config,
                Reference::Map(room()),
                Motion::Stationary(Pose2::IDENTITY),
            )
            .unwrap();
            let mut est = None;
            for k in 0..10 {
                est = loc
                    .process_scan(&cast(k * PERIOD_NS, Pose2::IDENTITY, Some(person)))
                    .output
                    .unwrap()
                    .person;
            }
            est.expect("tracked").position.distance(person)
        };
        // The near arc of a 0.2 m cylinder has its centroid about pi/4 x 0.2 m in front.
        assert!(error_with(0.0) > 0.12, "{}", error_with(0.0));
        assert!(error_with(0.157) < 0.03, "{}", error_with(0.157));
    }

    #[test]
    fn a_tracked_person_who_lies_down_against_a_wall_keeps_their_points() {
        // A thin body (radius 8 cm, a torso seen edge-on) moves up to the wall at y = 4.95:
        // its points end 0.11-0.19 m from the wall, inside the 0.2 m margin.
        let laser = Pose2::new(1.0, 4.0, 0.0);
        let seen_at_the_wall = |near_person_margin_m: f64| {
            let config = LocaliserConfig {
                near_person_margin_m,
                ..LocaliserConfig::default()
            };
            let mut loc =
                Localiser::new(config, Reference::Map(room()), Motion::Stationary(laser)).unwrap();
            let mut seen = 0;
            for k in 0..40 {
                let y = (4.3 + 0.03 * k as f64).min(4.95 - 0.08 - 0.03);
                let scan = cast_with_radius(k * PERIOD_NS, laser, Some(DVec2::new(1.0, y)), 0.08);
                let out = loc.process_scan(&scan).output.unwrap();
                if k >= 30 && out.person.is_some_and(|p| p.visible) {
                    seen += 1;
                }
            }
            seen
        };
        assert_eq!(seen_at_the_wall(0.08), 10);
        assert_eq!(seen_at_the_wall(0.2), 0, "the plain margin hides them");
    }

    /// [`room`] with a box at x 1-2, y `-half_width`..`half_width` (a multiple of 0.05 m).
    fn room_with_box(half_width: f64) -> OccupancyMap {
        let n = 200;
        let rows = (100 - (half_width / 0.05).round() as usize)
            ..(100 + (half_width / 0.05).round() as usize);
        let occupied = (0..n * n)
            .map(|i| {
                let (col, row) = (i % n, i / n);
                let wall = col == 0 || col == n - 1 || row == 0 || row == n - 1;
                wall || ((120..140).contains(&col) && rows.contains(&row))
            })
            .collect();
        OccupancyMap::new(*room().geometry(), occupied).unwrap()
    }

    /// The localiser's settings with the shadow step on or off and the given decay of a
    /// hidden person's speed.
    fn hidden_config(shadow_enabled: bool, hidden_speed_decay_s: f64) -> LocaliserConfig {
        LocaliserConfig {
            shadow: ShadowConfig {
                enabled: shadow_enabled,
                ..ShadowConfig::default()
            },
            tracker: TrackerConfig {
                hidden_speed_decay_s,
                ..TrackerConfig::default()
            },
            ..LocaliserConfig::default()
        }
    }

    /// A round person (radius 0.2 m) at `person(t)` in `map`, seen by a Lidar at `laser`
    /// for `scans` scans at 20 Hz: every scan with the person hidden, where they truly were
    /// then, and the localiser's estimate.
    fn hidden_walk(
        map: &OccupancyMap,
        laser: Pose2,
        config: LocaliserConfig,
        scans: i64,
        person: impl Fn(f64) -> DVec2,
    ) -> Vec<(Scan, DVec2, PersonEstimate)> {
        let reference = Reference::Map(map.clone());
        let mut loc = Localiser::new(config, reference, Motion::Stationary(laser)).unwrap();
        let mut hidden = Vec::new();
        for k in 0..scans {
            let truth = person(k as f64 * 0.05);
            let mut scan = crate::visibility::tests::cast(
                map,
                laser,
                -std::f32::consts::PI,
                Some((truth, 0.2)),
            );
            scan.stamp_ns = k * PERIOD_NS;
            let out = loc.process_scan(&scan).output.unwrap();
            if let Some(estimate) = out.person.filter(|p| !p.visible) {
                assert!(estimate.position.is_finite() && estimate.velocity.is_finite());
                hidden.push((scan, truth, estimate));
            }
        }
        assert!(hidden.len() >= 20, "hidden on {} scans", hidden.len());
        hidden
    }

    #[test]
    fn a_hidden_person_is_kept_out_of_what_the_scan_sees_through() {
        // A box at x 1-2, y -0.2-0.2: from the Lidar at (-3, 0) its shadow covers |y| < 0.3
        // at x = 3. The person walks down x = 3 at 1.5 m/s into the shadow and stops in it at
        // y = 0; the straight-line prediction walks out of it.
        let map = room_with_box(0.2);
        let laser = Pose2::new(-3.0, 0.0, 0.0);
        let shadow = ShadowConfig::default();
        let run = |enabled: bool| {
            let walk = hidden_walk(&map, laser, hidden_config(enabled, 0.0), 80, |t| {
                DVec2::new(3.0, (3.0 - 1.5 * t).max(0.0))
            });
            let seen_through = walk
                .iter()
                .filter(|(scan, _, e)| ScanView::new(scan, laser).sees_through(e.position, &shadow))
                .count();
            let (_, truth, last) = walk.last().unwrap();
            (seen_through, last.position.distance(*truth))
        };
        let (seen_through, kept_error) = run(true);
        assert_eq!(seen_through, 0);
        let (seen_through, straight_error) = run(false);
        assert!(seen_through > 0, "the prediction never left the shadow");
        assert!(
            kept_error < 0.5 && kept_error < straight_error,
            "{kept_error} vs {straight_error}"
        );
    }

    #[test]
    fn a_walker_who_stops_out_of_sight_is_reported_nearer_where_they_stopped() {
        // A box at x 1-2, y -1-1 hides |y| < 1.5 at x = 3 from the Lidar at (-3, 0). The
        // person walks down x = 3 at 1.5 m/s, vanishes at y = 1.5 and stops at y = 0.9.
        let map = room_with_box(1.0);
        let laser = Pose2::new(-3.0, 0.0, 0.0);
        let mean_error = |hidden_speed_decay_s: f64| {
            let config = hidden_config(true, hidden_speed_decay_s);
            let walk = hidden_walk(&map, laser, config, 60, |t| {
                DVec2::new(3.0, (3.0 - 1.5 * t).max(0.9))
            });
            let total: f64 = walk
                .iter()
                .map(|(_, truth, e)| e.position.distance(*truth))
                .sum();
            total / walk.len() as f64
        };
        let (slowed, straight) = (mean_error(1.0), mean_error(0.0));
        assert!(slowed < 0.7 * straight, "{slowed} vs {straight}");
    }

    #[test]
    fn a_hidden_walker_is_not_reported_through_the_wall() {
        // The box of y -1-1 hides y < (x + 3) / 4 from the Lidar at (-3, 0). The person walks
        // along y = 1.4 at 1.5 m/s, out of sight from x = 3.4, and stops at x = 4.6 by the
        // wall (inner face 4.95); the straight line goes through it.
        let map = room_with_box(1.0);
        let laser = Pose2::new(-3.0, 0.0, 0.0);
        let run = |enabled: bool| {
            let walk = hidden_walk(&map, laser, hidden_config(enabled, 0.0), 100, |t| {
                DVec2::new((1.5 * t).min(4.6), 1.4)
            });
            let in_the_wall = walk
                .iter()
                .filter(|(_, _, e)| map.free_clearance(e.position).is_none())
                .count();
            let worst = walk
                .iter()
                .map(|(_, truth, e)| e.position.distance(*truth))
                .fold(0.0, f64::max);
            (in_the_wall, worst)
        };
        let (in_the_wall, worst) = run(true);
        assert_eq!(in_the_wall, 0);
        assert!(worst < 0.5, "{worst}");
        let (in_the_wall, worst) = run(false);
        assert!(in_the_wall > 0 && worst > 1.0, "{in_the_wall} {worst}");
    }

    #[test]
    fn a_hidden_person_is_not_slowed_onto_floor_the_scan_sees_through() {
        // The box of y -0.2-0.2 hides |y| < 0.3 at x = 3 from the Lidar at (-3, 0). A person
        // predicted at (3, 0), hidden for 1 s, walking at 1.5 m/s down y: slowed, they would be
        // at (3, 0.55), which the scan sees through.
        let map = room_with_box(0.2);
        let laser = Pose2::new(-3.0, 0.0, 0.0);
        let scan = crate::visibility::tests::cast(&map, laser, -std::f32::consts::PI, None);
        let view = ScanView::new(&scan, laser);
        let shadow = ShadowConfig::default();
        let hidden = PersonEstimate {
            track_id: 1,
            position: DVec2::new(3.0, 0.0),
            velocity: DVec2::new(0.0, -1.5),
            covariance: [[0.1, 0.0], [0.0, 0.1]],
            visible: false,
            points: Vec::new(),
            unseen_s: 1.0,
        };
        let mut kept = hidden.clone();
        report_slowed(&mut kept, 1.0, Some(&view), &shadow);
        assert_eq!(kept, hidden);
        // Without the scan's word, slowed; seen, never.
        let mut slowed = hidden.clone();
        report_slowed(&mut slowed, 1.0, None, &shadow);
        assert!((slowed.position - DVec2::new(3.0, 0.552)).length() < 1e-3);
        let mut seen = PersonEstimate {
            visible: true,
            unseen_s: 0.0,
            ..hidden.clone()
        };
        report_slowed(&mut seen, 1.0, None, &shadow);
        assert_eq!(seen.position, hidden.position);
    }

    #[test]
    fn a_still_person_broken_into_pieces_is_seen_where_the_pieces_are_clear_of_the_room() {
        // A person sitting 3 m away, seen whole for 3 s, then only in pieces: two beams in
        // every sixteen across them (0.4 m apart, each too small to be a cluster).
        let laser = Pose2::IDENTITY;
        let person = DVec2::new(3.0, 0.0);
        let empty = cast(0, laser, None);
        let seen_in_pieces = |config: LocaliserConfig| {
            let mut loc =
                Localiser::new(config, Reference::Map(room()), Motion::Stationary(laser)).unwrap();
            for k in 0..60 {
                loc.process_scan(&cast_with_radius(k * PERIOD_NS, laser, Some(person), 0.5));
            }
            let mut scan = cast_with_radius(60 * PERIOD_NS, laser, Some(person), 0.5);
            let mut on_body = 0;
            for (range, wall) in scan.ranges.iter_mut().zip(&empty.ranges) {
                if *range < *wall {
                    if on_body % 16 >= 2 {
                        *range = *wall;
                    }
                    on_body += 1;
                }
            }
            let out = loc.process_scan(&scan).output.unwrap();
            assert_eq!(out.clusters, 0);
            out.person.expect("tracked")
        };
        let est = seen_in_pieces(LocaliserConfig::default());
        assert!(est.visible);
        assert!(est.position.distance(person) < 0.5, "{:?}", est.position);
        // Pieces no farther from the room than its walls' stray returns are not a person.
        let near_the_room = LocaliserConfig {
            piece_clearance_m: 3.5,
            ..LocaliserConfig::default()
        };
        assert!(!seen_in_pieces(near_the_room).visible);
    }

    #[test]
    fn points_near_walls_are_room_and_an_empty_room_has_nobody() {
        let mut loc = map_localiser(Motion::Stationary(Pose2::IDENTITY));
        for k in 0..10 {
            let out = loc
                .process_scan(&cast(k * PERIOD_NS, Pose2::IDENTITY, None))
                .output
                .unwrap();
            assert_eq!(out.foreground_points, 0);
            assert!(out.person.is_none());
        }
    }

    #[test]
    fn nan_and_inf_ranges_are_skipped_and_reported() {
        let mut loc = map_localiser(Motion::Stationary(Pose2::IDENTITY));
        let mut scan = cast(0, Pose2::IDENTITY, Some(DVec2::new(1.0, 0.0)));
        for (i, r) in scan.ranges.iter_mut().enumerate() {
            match i % 3 {
                0 => *r = f32::NAN,
                1 => *r = f32::INFINITY,
                _ => {}
            }
        }
        let result = loc.process_scan(&scan);
        assert_eq!(result.warnings, vec![Warning::NanRanges { count: 240 }]);
        let out = result.output.unwrap();
        assert!(out.foreground_points > 0);
    }

    #[test]
    fn empty_and_broken_scans_never_panic() {
        let mut loc = map_localiser(Motion::Stationary(Pose2::IDENTITY));
        let mut scan = cast(0, Pose2::IDENTITY, None);
        scan.ranges.clear();
        let out = loc.process_scan(&scan).output.unwrap();
        assert_eq!(out.foreground_points, 0);
        // A tiny increment once made the shadow search walk billions of beams per scan.
        for increment in [f32::NAN, 1e-10] {
            let mut broken = cast(PERIOD_NS, Pose2::IDENTITY, None);
            broken.angle_increment = increment;
            let result = loc.process_scan(&broken);
            assert!(result.output.is_none());
            assert!(matches!(
                result.warnings[..],
                [Warning::InvalidScan(ScanError::AngleIncrement(_))]
            ));
        }
        // A huge one put the beams at pseudo-random bearings, which could seed false tracks.
        for increment in [1e30, f32::MAX, -f32::MAX, 7.0] {
            let mut broken = cast(PERIOD_NS, Pose2::IDENTITY, None);
            broken.angle_increment = increment;
            let result = loc.process_scan(&broken);
            assert!(result.output.is_none());
            assert!(matches!(
                result.warnings[..],
                [Warning::InvalidScan(ScanError::AngleSpan {
                    beams: 720,
                    ..
                })]
            ));
        }
    }

    #[test]
    fn backwards_stamps_are_skipped_and_a_restart_resets() {
        let mut loc = map_localiser(Motion::Stationary(Pose2::IDENTITY));
        let person = Some(DVec2::new(1.0, 1.0));
        for k in 30..40 {
            assert!(
                loc.process_scan(&cast(k * PERIOD_NS, Pose2::IDENTITY, person))
                    .output
                    .is_some()
            );
        }
        let result = loc.process_scan(&cast(35 * PERIOD_NS, Pose2::IDENTITY, person));
        assert!(result.output.is_none());
        assert!(matches!(
            result.warnings[..],
            [Warning::ScanNotAfterPrevious { .. }]
        ));
        let same = loc.process_scan(&cast(39 * PERIOD_NS, Pose2::IDENTITY, person));
        assert!(same.output.is_none(), "a repeated stamp is skipped");
        // Back to time zero: a restart, not jitter.
        let result = loc.process_scan(&cast(0, Pose2::IDENTITY, person));
        assert!(matches!(result.warnings[..], [Warning::TimeReset { .. }]));
        let out = result.output.unwrap();
        assert!(out.person.is_none(), "tracks were reset");
    }

    #[test]
    fn the_first_scan_after_a_restart_keeps_the_odometry_that_came_for_it() {
        // Passes of 8 s (longer than the 5 s buffer), each stamp's odometry before its scan,
        // as in a bag: the second pass's first sample is held (far from the first pass's),
        // or, at twice the scan rate, has already restarted the buffer with the next one.
        for samples_per_scan in [1, 2] {
            let mut loc = map_localiser(Motion::Odometry);
            let person = Some(DVec2::new(1.0, 1.0));
            let mut play = || {
                let mut localised = 0;
                let mut no_odometry = 0;
                for k in 0..160 {
                    for i in 0..samples_per_scan {
                        let stamp_ns = k * PERIOD_NS + i * PERIOD_NS / 2;
                        loc.add_odometry(stamp_ns, Pose2::IDENTITY);
                    }
                    let result = loc.process_scan(&cast(k * PERIOD_NS, Pose2::IDENTITY, person));
                    localised += usize::from(result.output.is_some());
                    no_odometry += (result.warnings.iter())
                        .filter(|w| matches!(w, Warning::NoOdometry))
                        .count();
                }
                (localised, no_odometry)
            };
            assert_eq!(play(), (160, 0), "{samples_per_scan} per scan, first pass");
            assert_eq!(play(), (160, 0), "{samples_per_scan} per scan, second pass");
        }
    }

    #[test]
    fn a_looping_bag_with_odometry_localises_again_after_the_restart() {
        let mut loc = map_localiser(Motion::Odometry);
        let person = Some(DVec2::new(1.0, 1.0));
        let play = |loc: &mut Localiser| {
            let mut localised = 0;
            for k in 0..40 {
                // Odometry at twice the scan rate, each sample before the scan it brackets.
                loc.add_odometry(k * PERIOD_NS, Pose2::IDENTITY);
                loc.add_odometry(k * PERIOD_NS + PERIOD_NS / 2, Pose2::IDENTITY);
                let scan = cast(k * PERIOD_NS + PERIOD_NS / 4, Pose2::IDENTITY, person);
                localised += usize::from(loc.process_scan(&scan).output.is_some());
            }
            localised
        };
        assert_eq!(play(&mut loc), 40);
        // A loop shorter than the odometry buffer: the restart clears the odometry (the new
        // loop's first samples cannot be told from the old loop's), so the loop's first scan
        // cannot be placed; every later one must be.
        assert_eq!(play(&mut loc), 39);
    }

    /// A robot turning on the spot at 90 degrees per second with a 10 Hz Lidar (the rotation
    /// spans 0.157 rad: 0.5-0.9 m at the walls), a person standing at (1, -1). Beam 0 is
    /// measured first (`time_increment` > 0) or last (< 0, the RPLIDAR). Per scan: the
    /// number of clusters and the person's error when seen.
    fn turn_on_the_spot(deskew: bool, beam_zero_first: bool) -> Vec<(usize, Option<f64>)> {
        const SCAN_NS: i64 = 100_000_000;
        let robot = |t: f64| Pose2::new(-2.0, 1.0, std::f64::consts::FRAC_PI_2 * t);
        let person = DVec2::new(1.0, -1.0);
        let sign = if beam_zero_first { 1.0 } else { -1.0 };
        let time_increment = sign * 0.1 / 720.0;
        let mut config = LocaliserConfig::default();
        config.odometry.deskew = deskew;
        let mut loc = Localiser::new(config, Reference::Map(room()), Motion::Odometry).unwrap();
        // Odometry at 100 Hz from before the first rotation to after the last.
        for k in -20..=420 {
            loc.add_odometry(k * 10_000_000, robot(k as f64 * 0.01));
        }
        (1..40)
            .map(|k| {
                let stamp_ns = k * SCAN_NS;
                let t = stamp_ns as f64 * 1e-9;
                let scan = cast_sweeping(
                    stamp_ns,
                    |s| robot(t + s),
                    time_increment,
                    Some(person),
                    0.2,
                );
                let result = loc.process_scan(&scan);
                assert!(result.warnings.is_empty(), "{:?}", result.warnings);
                let output = result.output.unwrap();
                let seen = output.person.filter(|p| p.visible);
                (output.clusters, seen.map(|p| p.position.distance(person)))
            })
            .collect()
    }

    #[test]
    fn a_robot_turning_on_the_spot_keeps_its_walls_on_the_map() {
        for beam_zero_first in [true, false] {
            let scans = turn_on_the_spot(true, beam_zero_first);
            for (k, &(clusters, error)) in scans.iter().enumerate() {
                // Nothing but the person stands out. They may fall into the seam between the
                // first and the last beam, which the turn opens: no Lidar sees them then.
                assert!(clusters <= 1, "scan {k}: {clusters} clusters");
                assert!(error.is_none_or(|e| e < 0.15), "scan {k}: {error:?}");
            }
            // The track is confirmed after a few scans.
            let seen = scans[3..].iter().filter(|(_, e)| e.is_some()).count();
            assert!(seen * 10 >= (scans.len() - 3) * 9, "seen in {seen}");
            // Placed from beam 0's pose alone, the walls leave the map and the person is
            // placed up to half a metre off.
            let skewed = turn_on_the_spot(false, beam_zero_first);
            let spurious: usize = skewed
                .iter()
                .map(|(clusters, _)| clusters.saturating_sub(1))
                .sum();
            let worst = skewed.iter().filter_map(|(_, e)| *e).fold(0.0, f64::max);
            assert!(spurious >= 20 && worst > 0.3, "{skewed:?}");
        }
    }

    #[test]
    fn a_scan_that_cannot_be_deskewed_is_placed_from_its_stamp() {
        let mut loc = map_localiser(Motion::Odometry);
        loc.add_odometry(0, Pose2::IDENTITY);
        loc.add_odometry(10_000_000, Pose2::IDENTITY);
        let person = Some(DVec2::new(1.0, 0.0));
        let mut scan = cast_sweeping(20_000_000, |_| Pose2::IDENTITY, 0.1 / 720.0, person, 0.2);
        // The last beam is 0.11 s past the newest odometry: too far to extrapolate.
        let result = loc.process_scan(&scan);
        assert!(result.output.is_some());
        assert!(
            matches!(
                result.warnings[..],
                [Warning::NotDeskewed(
                    DeskewProblem::NoOdometryAtLastBeam { .. }
                )]
            ),
            "{:?}",
            result.warnings
        );
        for garbled in [f32::NAN, f32::NEG_INFINITY, 0.01] {
            scan.stamp_ns += 1_000_000;
            scan.time_increment = garbled;
            let result = loc.process_scan(&scan);
            assert!(result.output.is_some());
            assert!(
                matches!(
                    result.warnings[..],
                    [Warning::NotDeskewed(DeskewProblem::TimeIncrement(t))]
                        if t.to_bits() == garbled.to_bits()
                ),
                "{garbled}: {:?}",
                result.warnings
            );
            assert_eq!(result.warnings[0].kind(), "not_deskewed");
        }
        // Turning at 5.5 rad/s through a 0.3 s rotation: 1.65 rad, too far to tell which way.
        let mut loc = map_localiser(Motion::Odometry);
        for k in 0..=50 {
            loc.add_odometry(k * 10_000_000, Pose2::new(0.0, 0.0, 0.055 * k as f64));
        }
        let scan = cast_sweeping(100_000_000, |_| Pose2::IDENTITY, 0.3 / 720.0, person, 0.2);
        let result = loc.process_scan(&scan);
        assert!(result.output.is_some());
        assert!(
            matches!(
                result.warnings[..],
                [Warning::NotDeskewed(DeskewProblem::TurnedTooFar { turn_rad })]
                    if (turn_rad - 1.65).abs() < 0.01
            ),
            "{:?}",
            result.warnings
        );
    }

    #[test]
    fn a_scan_just_after_odometry_resumes_from_a_pause_is_placed_from_the_new_sample() {
        let mut loc = map_localiser(Motion::Odometry);
        let scan_at = |ns: i64| cast(ns, Pose2::IDENTITY, None);
        loc.add_odometry(10_000_000_000, Pose2::IDENTITY);
        loc.add_odometry(12_000_000_000, Pose2::IDENTITY);
        assert!(
            matches!(
                loc.process_scan(&scan_at(11_000_000_000)).warnings[..],
                [Warning::OdometryGap { .. }]
            ),
            "inside the pause it is a gap"
        );
        let result = loc.process_scan(&scan_at(12_010_000_000));
        assert_eq!(
            result.warnings,
            [],
            "no gap: the scan is 10 ms past a sample"
        );
    }

    #[test]
    fn odometry_gaps_staleness_and_jumps_skip_scans() {
        let mut loc = map_localiser(Motion::Odometry);
        let scan_at = |ns: i64| cast(ns, Pose2::IDENTITY, None);
        let warning =
            |loc: &mut Localiser, ns: i64| loc.process_scan(&scan_at(ns)).warnings.first().cloned();
        assert_eq!(warning(&mut loc, 0), Some(Warning::NoOdometry));
        loc.add_odometry(0, Pose2::IDENTITY);
        loc.add_odometry(20_000_000, Pose2::IDENTITY);
        assert_eq!(warning(&mut loc, 10_000_000), None);
        assert!(matches!(
            warning(&mut loc, 500_000_000),
            Some(Warning::OdometryStale { .. })
        ));
        loc.add_odometry(1_000_000_000, Pose2::IDENTITY);
        assert!(matches!(
            warning(&mut loc, 600_000_000),
            Some(Warning::OdometryGap { .. })
        ));
        loc.add_odometry(1_020_000_000, Pose2::new(3.0, 0.0, 0.0));
        assert!(matches!(
            warning(&mut loc, 1_010_000_000),
            Some(Warning::OdometryJump { .. })
        ));
        loc.add_odometry(1_040_000_000, Pose2::new(3.0, 0.0, 0.0));
        assert_eq!(
            warning(&mut loc, 1_030_000_000),
            None,
            "after the jump, driving resumes"
        );
        assert!(matches!(
            loc.add_odometry(1_030_000_000, Pose2::new(3.0, 0.0, 0.0)),
            Some(Warning::OdometryOutOfOrder { .. })
        ));
        // A sample older than the buffer is said to be too old once the next one shows it a
        // stray (it might have been the first of a restarted odometry).
        assert_eq!(loc.add_odometry(-10_000_000_000, Pose2::IDENTITY), None);
        assert_eq!(
            loc.add_odometry(1_050_000_000, Pose2::new(3.0, 0.0, 0.0)),
            Some(Warning::OdometryTooOld)
        );
        assert!(matches!(
            loc.add_odometry(2_000_000_000, Pose2::new(f64::NAN, 0.0, 0.0)),
            Some(Warning::NonFinite { .. })
        ));
        assert!(matches!(
            loc.set_map_to_odom(Pose2::new(0.0, f64::INFINITY, 0.0)),
            Some(Warning::NonFinite { .. })
        ));
    }

    /// A robot standing still with odometry at 50 Hz and a scan every 50 ms, sample `k` and
    /// the scan after it at `clock(k)`; `odometry(k, stamp)` gives the stamp sample `k`
    /// carries and the warning it must bring. Returns how many of the 40 scans were placed.
    fn localised_with_odometry(
        clock: impl Fn(i64) -> i64,
        odometry: impl Fn(i64, i64) -> (i64, Option<Warning>),
    ) -> usize {
        let mut loc = map_localiser(Motion::Odometry);
        let mut localised = 0;
        for k in 0..200 {
            let (stamp_ns, expected) = odometry(k, clock(k));
            let warning = loc.add_odometry(stamp_ns, Pose2::IDENTITY);
            assert_eq!(warning, expected, "sample {k} at {stamp_ns} ns");
            if k % 5 == 2 {
                let result = loc.process_scan(&cast(clock(k), Pose2::IDENTITY, None));
                localised += usize::from(result.output.is_some());
            }
        }
        localised
    }

    #[test]
    fn one_odometry_stamp_far_ahead_does_not_stop_localisation() {
        const HOUR_NS: i64 = 3_600_000_000_000;
        let clock = |k: i64| k * 20_000_000;
        // Sample 50 (1 s) stamped an hour ahead: said to be a stray when the next one comes,
        // and every scan is placed (it had emptied the buffer, and every correct sample
        // after it was refused as too old: 10 scans placed).
        let localised = localised_with_odometry(clock, |k, t| match k {
            50 => (HOUR_NS, None),
            51 => (
                t,
                Some(Warning::OdometryAhead {
                    ahead_s: (HOUR_NS - clock(49)) as f64 * 1e-9,
                }),
            ),
            _ => (t, None),
        });
        assert_eq!(localised, 40);
        // The same stray stamp as the very first sample: the next two agree with each other,
        // and the odometry restarts from them.
        let localised = localised_with_odometry(clock, |k, t| match k {
            0 => (HOUR_NS, None),
            2 => (
                t,
                Some(Warning::OdometryRestarted {
                    back_s: (HOUR_NS - clock(1)) as f64 * 1e-9,
                }),
            ),
            _ => (t, None),
        });
        assert_eq!(localised, 40);
    }

    #[test]
    fn odometry_resuming_after_a_pause_longer_than_its_buffer_is_taken() {
        // Robot and Lidar off for 7 s (longer than the 5 s buffer) after sample 51: sample 52
        // is held, and the scan right after it, near it, says as the next sample would that
        // time has moved on: the scan is placed from it, with nothing said.
        let clock = |k: i64| k * 20_000_000 + if k >= 52 { 7_000_000_000 } else { 0 };
        assert_eq!(localised_with_odometry(clock, |_, t| (t, None)), 40);
    }

    #[test]
    fn odometry_is_interpolated_at_the_scan_stamp() {
        let mut buffer = OdometryBuffer::default();
        let config = OdometryConfig::default();
        buffer.insert(0, Pose2::new(0.0, 0.0, 0.0), &config);
        buffer.insert(100_000_000, Pose2::new(0.1, 0.0, 0.2), &config);
        let p = buffer.pose_at(25_000_000, &config).unwrap();
        assert!((p.x - 0.025).abs() < 1e-12 && (p.theta - 0.05).abs() < 1e-12);
        let p = buffer.pose_at(150_000_000, &config).unwrap();
        assert!((p.x - 0.15).abs() < 1e-12, "extrapolated: {p:?}");
    }

    #[test]
    fn map_to_odom_correction_moves_the_laser() {
        let mut loc = map_localiser(Motion::Odometry);
        loc.add_odometry(0, Pose2::new(1.0, 0.0, 0.0));
        loc.set_map_to_odom(Pose2::new(0.0, 0.5, 0.0));
        let out = loc
            .process_scan(&cast(0, Pose2::new(1.0, 0.5, 0.0), None))
            .output
            .unwrap();
        assert!((out.laser_pose.position() - DVec2::new(1.0, 0.5)).length() < 1e-12);
    }

    #[test]
    fn without_a_map_scans_are_skipped() {
        let mut loc = Localiser::new(
            LocaliserConfig::default(),
            Reference::AwaitingMap,
            Motion::Stationary(Pose2::IDENTITY),
        )
        .unwrap();
        assert_eq!(
            loc.process_scan(&cast(0, Pose2::IDENTITY, None)).warnings,
            vec![Warning::NoMap]
        );
        loc.set_map(room());
        assert!(
            loc.process_scan(&cast(PERIOD_NS, Pose2::IDENTITY, None))
                .output
                .is_some()
        );
    }

    #[test]
    fn learned_background_finds_a_person_who_walks_in() {
        let mut loc = Localiser::with_learned_background(LocaliserConfig::default()).unwrap();
        for k in 0..60 {
            assert!(
                loc.process_scan(&cast(k * PERIOD_NS, Pose2::IDENTITY, None))
                    .learning
            );
        }
        let mut last = None;
        for k in 60..80 {
            let r = loc.process_scan(&cast(
                k * PERIOD_NS,
                Pose2::IDENTITY,
                Some(DVec2::new(2.0, -1.0)),
            ));
            last = r.output.unwrap().person;
        }
        let est = last.expect("found");
        assert!(est.position.distance(DVec2::new(2.0, -1.0)) < 0.25);
    }

    /// How far along the unit direction `d` from `o` the ray enters the disc at `c`, if ahead.
    fn ray_to_disc(o: DVec2, d: DVec2, c: DVec2, radius: f64) -> Option<f64> {
        let oc = o - c;
        let b = oc.dot(d);
        let disc = b * b - (oc.length_squared() - radius * radius);
        let t = -b - disc.sqrt();
        (disc >= 0.0 && t > 0.0).then_some(t)
    }

    /// A fixed Lidar at the origin of an empty 4 m x 3 m room with two chair legs and a
    /// cabinet, scanned with `n` beams over one full turn (`angle_increment` 2pi / n).
    fn empty_room_scan(stamp_ns: i64, n: usize) -> Scan {
        let inc = std::f64::consts::TAU / n as f64;
        let ranges = (0..n)
            .map(|i| {
                let d = DVec2::from_angle(-std::f64::consts::PI + i as f64 * inc);
                let tx = if d.x > 0.0 { 2.5 / d.x } else { -1.5 / d.x };
                let ty = if d.y > 0.0 { 1.8 / d.y } else { -1.2 / d.y };
                let mut r = tx.min(ty);
                let furniture = [
                    (DVec2::new(1.0, 0.8), 0.03),
                    (DVec2::new(1.4, 0.8), 0.03),
                    (DVec2::new(-0.8, -0.6), 0.25),
                ];
                for (c, radius) in furniture {
                    if let Some(t) = ray_to_disc(DVec2::ZERO, d, c, radius) {
                        r = r.min(t);
                    }
                }
                r as f32
            })
            .collect();
        full_turn_scan(stamp_ns, ranges, 0.0)
    }

    #[test]
    fn a_learned_background_holds_when_the_beam_count_varies() {
        // sllidar_ros2 with angle_compensate false publishes a few beams more or fewer each
        // rotation. Kept by beam index, the background had shifted by up to half a degree
        // per beam at the end of the turn: foreground, and phantom persons, in an empty room.
        let mut loc = Localiser::with_learned_background(LocaliserConfig::default()).unwrap();
        let mut k = 0;
        while loc
            .process_scan(&empty_room_scan(k * 100_000_000, 1080))
            .learning
        {
            k += 1;
        }
        let mut seen = Vec::new();
        for n in [
            1082, 1079, 1083, 1081, 1084, 1078, 1082, 1083, 1080, 1084, 1083,
        ] {
            k += 1;
            let out = loc
                .process_scan(&empty_room_scan(k * 100_000_000, n))
                .output
                .unwrap();
            seen.push((n, out.foreground_points, out.person.is_some()));
        }
        assert!(
            seen.iter().all(|&(_, fg, person)| fg == 0 && !person),
            "(beams, foreground, person): {seen:?}"
        );
    }

    #[test]
    fn extreme_stamps_are_warned_about_or_skipped_without_overflow() {
        // Stamps 292+ years apart: `a - b` overflowed (a panic in debug, a wrapped
        // difference taken at its word in release: the scan placed from odometry 1.7e18 ns
        // away, with no warning).
        let scan = |stamp_ns| empty_room_scan(stamp_ns, 720);
        let mut loc = Localiser::new(
            LocaliserConfig::default(),
            Reference::AwaitingMap,
            Motion::Odometry,
        )
        .unwrap();
        loc.add_odometry(1_700_000_000_000_000_000, Pose2::IDENTITY);
        let r = loc.process_scan(&scan(i64::MIN));
        assert_eq!(r.warnings, [Warning::NoOdometry]);
        // Odometry far behind the scan: stale, by the right age.
        let r = loc.process_scan(&scan(i64::MAX));
        let Some(Warning::OdometryStale { age_s }) = r.warnings.last() else {
            panic!("{:?}", r.warnings)
        };
        assert!(
            (age_s - (i64::MAX as f64 - 1.7e18) * 1e-9).abs() < 1.0,
            "{age_s}"
        );
        // Odometry stamps as far apart: one far behind is held, then dropped as a stray...
        let odometry = |loc: &mut Localiser, stamp_ns| loc.add_odometry(stamp_ns, Pose2::IDENTITY);
        assert_eq!(odometry(&mut loc, i64::MIN), None);
        let w = odometry(&mut loc, 1_700_000_000_000_000_001);
        assert_eq!(w, Some(Warning::OdometryTooOld));
        // ... or, the next sample near it, taken as a restart ...
        assert_eq!(odometry(&mut loc, i64::MIN), None);
        let w = odometry(&mut loc, i64::MIN + 1);
        assert!(
            matches!(w, Some(Warning::OdometryRestarted { back_s }) if back_s > 1e10),
            "{w:?}"
        );
        // ... and one far ahead of those is a stray too.
        assert_eq!(odometry(&mut loc, i64::MAX), None);
        let w = odometry(&mut loc, i64::MIN + 2);
        assert!(
            matches!(w, Some(Warning::OdometryAhead { ahead_s }) if ahead_s > 1.8e10),
            "{w:?}"
        );
        // Time going back from the far future to the far past: a reset, then the scans go on.
        let mut loc = Localiser::with_learned_background(LocaliserConfig::default()).unwrap();
        loc.process_scan(&scan(1_700_000_000_000_000_000));
        let r = loc.process_scan(&scan(i64::MIN));
        assert!(matches!(r.warnings[..], [Warning::TimeReset { back_s }] if back_s > 1e9));
        // And forwards across the whole range.
        let mut loc = Localiser::with_learned_background(LocaliserConfig::default()).unwrap();
        loc.process_scan(&scan(-1_700_000_000_000_000_000));
        let r = loc.process_scan(&scan(i64::MAX));
        assert!(r.learning && r.warnings.is_empty(), "{r:?}");
    }

    #[test]
    fn a_range_of_zero_is_no_return_even_with_range_min_zero() {
        // Drivers that publish range_min 0 encode "no return" as 0: a cluster on the Lidar.
        let mut loc = map_localiser(Motion::Stationary(Pose2::IDENTITY));
        let mut scan = cast(0, Pose2::IDENTITY, None);
        scan.range_min = 0.0;
        scan.ranges[100..120].fill(0.0);
        let out = loc.process_scan(&scan).output.unwrap();
        assert_eq!((out.foreground_points, out.clusters), (0, 0));
    }

    #[test]
    fn a_std_whose_square_is_not_finite_is_refused() {
        let mut c = LocaliserConfig::default();
        c.tracker.initial_velocity_std_mps = 1e200;
        let err = c.validate().unwrap_err();
        assert_eq!(err.key, "tracker.initial_velocity_std_mps");
        let message = err.to_string();
        assert!(message.contains("1e200"), "{message}");
        // Accepted, it made every track's filter NaN: nobody tracked, and nothing said.
        type Set = fn(&mut LocaliserConfig, f64);
        let set: [(&str, Set); 7] = [
            ("tracker.accel_std_mps2", |c, v| {
                c.tracker.accel_std_mps2 = v
            }),
            ("tracker.measurement_std_m", |c, v| {
                c.tracker.measurement_std_m = v
            }),
            ("tracker.initial_velocity_std_mps", |c, v| {
                c.tracker.initial_velocity_std_mps = v
            }),
            ("cluster.tolerance_m", |c, v| c.cluster.tolerance_m = v),
            ("obstacle_margin_m", |c, v| c.obstacle_margin_m = v),
            ("range_margin_fraction", |c, v| c.range_margin_fraction = v),
            ("near_person_margin_m", |c, v| c.near_person_margin_m = v),
        ];
        for (key, set) in set {
            let mut c = LocaliserConfig::default();
            set(&mut c, 1e200);
            assert_eq!(c.validate().map_err(|e| e.key), Err(key));
            // Large but squaring into range (f32 for the margins): accepted.
            set(&mut c, 1e15);
            assert_eq!(c.validate(), Ok(()), "{key}");
        }
        // The f32 margins: 1e20 squares to inf in f32.
        let c = LocaliserConfig {
            obstacle_margin_m: 1e20,
            ..LocaliserConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "obstacle_margin_m");
    }

    #[test]
    fn invalid_configs_name_the_key() {
        let mut c = LocaliserConfig::default();
        c.tracker.gate_m = -1.0;
        assert_eq!(c.validate().unwrap_err().key, "tracker.gate_m");
        let mut c = LocaliserConfig::default();
        c.cluster.tolerance_m = 0.0;
        assert_eq!(c.validate().unwrap_err().key, "cluster.tolerance_m");
        let c = LocaliserConfig {
            obstacle_margin_m: f64::NAN,
            ..LocaliserConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "obstacle_margin_m");
        let mut c = LocaliserConfig::default();
        c.tracker.max_coast_s = 0.0;
        assert_eq!(c.validate().unwrap_err().key, "tracker.max_coast_s");
    }

    #[test]
    fn a_fixed_lidar_is_placed_where_its_transforms_put_it() {
        let mut loc = map_localiser(Motion::Stationary(Pose2::IDENTITY));
        let base = Pose2::new(1.0, -0.5, 0.3);
        assert_eq!(loc.set_fixed_base(base), None);
        let placed = |out: LocaliserOutput| {
            out.laser_pose.position().distance(base.position()) < 1e-12
                && (out.laser_pose.theta - base.theta).abs() < 1e-12
        };
        let out = loc.process_scan(&cast(0, base, None)).output.unwrap();
        assert_eq!(
            out.foreground_points, 0,
            "the walls are where the map has them"
        );
        assert!(placed(out));
        assert!(matches!(
            loc.set_fixed_base(Pose2::new(f64::NAN, 0.0, 0.0)),
            Some(Warning::NonFinite { .. })
        ));
        let out = loc.process_scan(&cast(PERIOD_NS, base, None)).output;
        assert!(placed(out.unwrap()), "a NaN pose is ignored");
    }

    #[test]
    fn scans_that_keep_coming_farther_apart_than_max_coast_are_warned_about() {
        let warned = |stamps_ms: &[i64]| {
            let mut loc = map_localiser(Motion::Stationary(Pose2::IDENTITY));
            let kinds: Vec<Vec<&str>> = stamps_ms
                .iter()
                .map(|&ms| {
                    let result = loc.process_scan(&cast(ms * 1_000_000, Pose2::IDENTITY, None));
                    result.warnings.iter().map(Warning::kind).collect()
                })
                .collect();
            kinds.iter().filter(|k| !k.is_empty()).count()
        };
        // Twice in a row more than the default 2 s apart: a Lidar this slow tracks nobody.
        assert_eq!(warned(&[0, 2100, 4200, 6300]), 2);
        // One gap (a Lidar stopped while docked) loses the tracks as meant: no warning.
        assert_eq!(warned(&[0, 50, 100, 5000, 5050, 5100]), 0);
        let mut loc = map_localiser(Motion::Stationary(Pose2::IDENTITY));
        for k in 0..3 {
            let warnings = loc
                .process_scan(&cast(k * 2_500_000_000, Pose2::IDENTITY, None))
                .warnings;
            if k == 2 {
                assert_eq!(
                    warnings,
                    [Warning::ScanPeriodOverCoast {
                        period_s: 2.5,
                        max_coast_s: 2.0
                    }]
                );
            }
        }
    }

    /// Scans skipped for want of odometry still arrived at the Lidar's rate: two outages
    /// longer than `tracker.max_coast_s` in a row had been blamed on the Lidar.
    #[test]
    fn the_scan_period_is_measured_between_scans_that_arrived() {
        // Scans at `stamps_ms`, odometry only for those in `odometry_ms`: how many warnings
        // about the scan period.
        let warned = |stamps_ms: &[i64], odometry_ms: &[i64]| {
            let mut config = LocaliserConfig::default();
            // No scan is placed from odometry older than its stamp.
            config.odometry.max_extrapolation_s = 0.0;
            let mut loc = Localiser::new(config, Reference::Map(room()), Motion::Odometry).unwrap();
            let mut count = 0;
            for &ms in stamps_ms {
                let stamp_ns = ms * 1_000_000;
                if odometry_ms.contains(&ms) {
                    for ago_ns in [10_000_000, 0] {
                        assert_eq!(loc.add_odometry(stamp_ns - ago_ns, Pose2::IDENTITY), None);
                    }
                }
                let result = loc.process_scan(&cast(stamp_ns, Pose2::IDENTITY, None));
                // Only the scans with odometry are localised.
                assert_eq!(
                    result.output.is_some(),
                    odometry_ms.contains(&ms),
                    "{ms} ms"
                );
                count += result
                    .warnings
                    .iter()
                    .filter(|w| matches!(w, Warning::ScanPeriodOverCoast { .. }))
                    .count();
            }
            count
        };
        // A 20 Hz Lidar through two outages of 2.5 s: its scans never came 2 s apart.
        let every_50_ms: Vec<i64> = (0..=100).map(|k| k * 50).collect();
        assert_eq!(warned(&every_50_ms, &[0, 2500, 5000]), 0);
        // A Lidar 2.5 s apart is slow, whether or not its scans between were localised.
        assert_eq!(warned(&[0, 2500, 5000, 7500], &[0, 5000, 7500]), 2);
    }
}
