//! `lidar-har alerts`: how the fall alerts behave over simulated episodes, end to end (the
//! simulator, the real localiser, the activity model, the fall-alert logic): how soon after a
//! fall's end an alert comes, and how many alerts come in hours of activity without a fall.
//!
//! Episodes use the dataset's random activity scripts: with falls (a fall, lying 2-6 s,
//! sometimes sitting, getting up) for the latency, without them for the false alerts, and
//! ending with a fall after which the person stays down for PERSON_DOWN where it is due.
//! Episodes with falls run on past their end until a fall that began on their last scan has
//! ended and its alert has fallen due; falls that begin in that time are not counted.
//! Episodes staying down run on for PERSON_DOWN's scoring window, so that a spell due on
//! their last scan can be answered; spells that fall due in that time are not counted, but
//! a PERSON_DOWN raised in one is not counted as false either: it was due.
//! The report also scores the streaming classification itself, scan by scan over every
//! episode: unlike `lidar-har evaluate`'s windows from a zero state, this is what the robot
//! publishes, so models trained on different window lengths compare on equal terms.
//! The alerts' inputs can be saved and replayed with other alert settings ([`readings`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use lidar_har_core::activity::Activity;
use lidar_har_core::fall::{AlertKind, FallAlert, FallAlertConfig, FallDetector};
use lidar_har_core::metrics::{ConfusionMatrix, MetricsReport};
use lidar_har_core::pose_head::NoPoseHead;
use lidar_har_core::stats::Spread;
use lidar_har_infer::ActivityModel;
use lidar_har_pipeline::classifier::{
    ClassifierConfig, ClassifierStage, StreamClock, with_fall_alert_setting,
};
use lidar_har_pipeline::convert::observation_msg;
use lidar_har_sim::scripts::{self, ScriptKind};
use serde::Serialize;

use super::dataset::{
    EpisodeStream, core_scan, episode_localiser, episode_seed, load_scenes, with_episode_seconds,
};
use readings::{EpisodeLog, Frame, Header, Reading, ReadingsReader, ReadingsWriter};

mod readings;

#[derive(clap::Args)]
pub struct AlertsArgs {
    /// The activity model (ONNX step model) [default: the classifier configuration's
    /// `model`, models/activity.onnx].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Classifier parameters (YAML, see config/classifier.yaml): `model`, the lanes
    /// (`lanes`, `lane_period_windows`) and the `fall_alert` block are used, the rest
    /// (threads, the pose head) is not; defaults when absent.
    #[arg(long)]
    pub classifier_config: Option<PathBuf>,
    /// One `fall_alert` setting changed from the configuration, e.g. `fall_min_scans=6`
    /// (the value in YAML): to score variants, with `--readings`, without a file for each.
    /// Repeatable; applied in order.
    #[arg(long, value_name = "KEY=VALUE")]
    pub fall_alert: Vec<String>,
    /// Scene files, as globs or paths; episodes go round-robin over them.
    #[arg(long, num_args = 1.., default_value = "config/scenes/*.yaml")]
    pub scenes: Vec<String>,
    /// Episodes whose scripts contain falls.
    #[arg(long, default_value_t = 40)]
    pub fall_episodes: usize,
    /// Simulated hours of activity without any fall (at most 1000).
    #[arg(long, default_value_t = 1.0)]
    pub no_fall_hours: f64,
    /// Episodes that end with a fall after which the person stays on the floor, so that
    /// PERSON_DOWN falls due (`down_after_s` after the fall): run after the others, so the
    /// others' seeds do not move. They run on 3 s past their end, for a spell due near it to
    /// be answered; a run where none of them has a spell due before its end fails (lengthen
    /// `--episode-seconds`).
    #[arg(long, default_value_t = 0)]
    pub stay_down_episodes: usize,
    /// Length of one episode, seconds. Episodes with falls run on for the longest fall and
    /// `--latency-target-s` more, so that a fall near the end can be answered in time; falls
    /// that begin then are not counted. Episodes staying down run on 3 s.
    #[arg(long, default_value_t = 60.0)]
    pub episode_seconds: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// An alert later than this after a fall's end does not count as detecting it.
    #[arg(long, default_value_t = 1.0)]
    pub latency_target_s: f64,
    /// Write the report as JSON here too.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print every scan of this episode (by number, as in the report) to stderr: the true
    /// activity, the model's top class and its probability, p(falling_down), whether the
    /// person was seen, the length of their points, where they were (map frame), and the
    /// alerts raised (`tracked=false` where nobody was tracked). Repeatable.
    #[arg(long, value_name = "EPISODE")]
    pub trace_episode: Vec<usize>,
    /// Also write what the classifier stage gave the fall alerts on every scan of every
    /// episode (zstd-compressed JSON lines), to score other `fall_alert` settings on the same
    /// episodes with `--readings`.
    #[arg(long, value_name = "FILE")]
    pub save_readings: Option<PathBuf>,
    /// Score the alerts over readings saved by `--save-readings` instead of simulating and
    /// running the model: seconds instead of minutes, and the same report a full run with
    /// `--classifier-config`'s `fall_alert` settings gives. Episodes, seed, latency target,
    /// model and lanes are the recording's: the configuration's `model` is not used (nor can
    /// `--model` or `--latency-target-s` be given), and its lanes must be the recording's. A file cut short (a recording stopped
    /// half-way) is scored over its complete episodes, the report marked `cut_short`, and
    /// the command fails; a file without a complete episode is refused.
    #[arg(long, value_name = "FILE", conflicts_with_all = [
        "model", "scenes", "fall_episodes", "no_fall_hours", "stay_down_episodes",
        "episode_seconds", "seed", "latency_target_s", "save_readings",
    ])]
    pub readings: Option<PathBuf>,
}

/// One fall of the ground truth and the alert that answered it, if any.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FallOutcome {
    pub episode: usize,
    pub start_s: f64,
    pub end_s: f64,
    /// The first alert raised from the fall's start until the next fall (or the episode's
    /// end), minus the fall's end; `None` when there was none.
    pub latency_s: Option<f64>,
    pub alert: Option<&'static str>,
    /// Share of the fall's scans in which the localiser saw the person: a fall behind
    /// furniture can only be found after the fact (PERSON_DOWN).
    pub seen_share: f64,
    /// Why a fall without its own alert may have none by design: it began at the episode's
    /// first scan (nobody was seen upright before it), or inside an incident already alerted
    /// (since an earlier fall's alert the person was never upright for `rearm_upright_s` nor
    /// getting up for `rearm_getting_up_s`, so the hysteresis keeps one incident to one
    /// alert), or it ended less than the latency target before the last scan (an alert in
    /// time may have come after it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unalerted_because: Option<&'static str>,
}

#[derive(Debug, Serialize)]
pub struct AlertsReport {
    pub model: String,
    pub scenes: Vec<String>,
    pub seed: u64,
    /// Episodes run (a scene too small for a random script is skipped).
    pub fall_episodes: usize,
    pub falls: usize,
    pub falls_alerted: usize,
    pub falls_alerted_within_target: usize,
    pub latency_target_s: f64,
    pub latency_s: Option<Spread>,
    /// The falls not alerted within the latency target, by why not.
    pub falls_not_in_time: Shortfall,
    /// Alerts in the fall (and stay-down) episodes that answered no fall.
    pub unmatched_alerts_in_fall_episodes: usize,
    /// `PERSON_DOWN` alerts in those episodes raised in no spell where it was due (the fall's
    /// own alert answers the fall; these are false, unless the person tried to get up and
    /// never stood: the ground truth ends a spell at any getting up). A spell that fell due
    /// only in the run-on past the episode's end is not counted in `person_down_due`, but
    /// the PERSON_DOWN that answers it is not counted here either.
    pub person_down_not_due_in_fall_episodes: usize,
    /// `FALL_DETECTED` alerts after the first in the same fall's window (until the next fall):
    /// one fall alerted twice, which the hysteresis should prevent.
    pub repeated_fall_alerts: usize,
    pub no_fall_hours: f64,
    pub false_alerts: usize,
    pub false_fall_detected: usize,
    pub false_person_down: usize,
    /// PERSON_DOWN alerts in the episodes without falls that answered a spell in which they
    /// were due (someone sitting or lying on the floor for `down_after_s` on purpose): the
    /// alert doing what it is specified to do, so not counted as false. They appear in
    /// `person_down_due`.
    pub everyday_person_down_due: usize,
    pub false_alerts_per_hour: f64,
    /// Over every episode: spells in which the ground truth has the person on the floor
    /// (falling included) for at least `down_after_s` without getting up: PERSON_DOWN is due.
    pub person_down_due: Vec<DownSpell>,
    /// Of those, the spells with a PERSON_DOWN raised in them (or within a second of their end).
    pub person_down_due_alerted: usize,
    /// Of those, the spells whose PERSON_DOWN came within `person_down_window_s` of falling
    /// due: the "within 3 s of due" the figures quote (README, docs/classifier.md).
    pub person_down_due_in_time: usize,
    pub person_down_window_s: f64,
    /// `PERSON_DOWN` alerts after the first in the same spell: one spell alerted twice,
    /// which the hysteresis should prevent. Spells that fell due only in the run-on past an
    /// episode's end count here too.
    pub repeated_person_down: usize,
    /// How long after it fell due those came, seconds.
    pub person_down_delay_s: Option<Spread>,
    /// Episodes ending with a fall and the person staying down (`--stay-down-episodes`), and
    /// how many of them got a FALL_DETECTED for that fall.
    pub stay_down_episodes: usize,
    pub stay_down_fall_detected: usize,
    /// False alerts by what the person was really doing when each was raised (the
    /// misreadings to fix), most frequent first.
    pub false_alerts_by_activity: Vec<(&'static str, usize)>,
    pub outcomes: Vec<FallOutcome>,
    pub false_alert_details: Vec<FalseAlert>,
    /// The streaming classification over every episode, one sample per scan the classifier
    /// publishes (person seen, model history ready), against the true activity at that scan.
    pub scans: MetricsReport,
    /// Replayed readings (`--readings`) that end half-way: the report covers only the
    /// complete episodes before the cut. Absent when the file was whole.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cut_short: Option<CutShort>,
}

/// Where replayed readings end early, and how many complete episodes came before.
#[derive(Debug, Serialize)]
pub struct CutShort {
    /// The reader's error, naming the file and the line.
    pub error: String,
    pub episodes_scored: usize,
}

/// The reasons of [`FallOutcome::unalerted_because`].
const AT_EPISODE_START: &str = "at the episode's start";
const INSIDE_ALERTED_INCIDENT: &str = "inside an alerted incident";
const AT_EPISODE_END: &str = "at the episode's end";

/// The falls not alerted within the latency target, by why not: where the misses are.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Shortfall {
    /// Alerted, but after the target (a late `FALL_DETECTED`, or only `PERSON_DOWN`).
    pub late: usize,
    /// Without an alert of their own by design ([`FallOutcome::unalerted_because`]).
    pub at_episode_start: usize,
    pub inside_alerted_incident: usize,
    pub at_episode_end: usize,
    /// Without an alert, the person seen in under half of the fall's scans: behind
    /// furniture, for `PERSON_DOWN` to find.
    pub hidden: usize,
    /// Without an alert, in view for at least half of them: misread by the classifier or
    /// missed by the alert rules.
    pub in_view: usize,
}

impl Shortfall {
    fn of(outcomes: &[FallOutcome], latency_target_s: f64) -> Self {
        let mut shortfall = Self::default();
        for outcome in outcomes {
            let count = match (outcome.latency_s, outcome.unalerted_because) {
                (Some(latency), _) if latency <= latency_target_s => continue,
                (Some(_), _) => &mut shortfall.late,
                (None, Some(AT_EPISODE_START)) => &mut shortfall.at_episode_start,
                (None, Some(INSIDE_ALERTED_INCIDENT)) => &mut shortfall.inside_alerted_incident,
                (None, Some(_)) => &mut shortfall.at_episode_end,
                (None, None) if outcome.seen_share < 0.5 => &mut shortfall.hidden,
                (None, None) => &mut shortfall.in_view,
            };
            *count += 1;
        }
        shortfall
    }
}

/// An alert in an episode without falls, with the truth around it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FalseAlert {
    pub episode: usize,
    pub scene: String,
    pub kind: AlertKind,
    pub raised_at_s: f64,
    /// The true activity when the alert was raised, and one second before.
    pub activity: &'static str,
    pub activity_1s_before: &'static str,
    /// How long the ground truth had the person off their feet (on the floor or getting up)
    /// without a break when the alert was raised, seconds.
    pub truth_down_s: f64,
}

/// A spell of the ground truth with the person on the floor for at least `down_after_s`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct DownSpell {
    pub episode: usize,
    pub scene: String,
    pub start_s: f64,
    pub end_s: f64,
    /// The first PERSON_DOWN raised in it (or within a second of its end), minus the moment
    /// it fell due (`start_s` + `down_after_s`); `None` when there was none.
    pub delay_s: Option<f64>,
    /// Share of its scans in which the localiser saw the person.
    pub seen_share: f64,
}

/// What one episode gave: the truth's falls (start, end) that began before its end, the
/// alerts raised, the true activity at every scan and whether the localiser saw the person
/// there. An episode that runs on past its end (see [`fall_run_on_s`]) keeps the scans of
/// that time in `truth` and `seen`, for a fall's end and the alerts that answer it, but not
/// in `scans`.
struct Episode {
    falls: Vec<(f64, f64)>,
    alerts: Vec<FallAlert>,
    truth: Vec<(f64, Activity)>,
    /// Aligned with `truth`.
    seen: Vec<bool>,
    /// The episode's end in episode time: half a scan after its last scan.
    end_s: f64,
    /// (truth, prediction) at each scan the classifier published.
    scans: ConfusionMatrix,
}

impl Episode {
    /// The episode `log` recorded, with `alerts` (in episode time) raised over it.
    fn of(log: &EpisodeLog, mut alerts: Vec<FallAlert>) -> Self {
        let start_s = log.start_s();
        let mut truth = Vec::new();
        let mut seen = Vec::new();
        let mut scans = ConfusionMatrix::new();
        for frame in &log.frames {
            let Some(activity) = frame.truth else {
                continue;
            };
            let stamp_s = frame.stamp_s(start_s);
            truth.push((stamp_s, activity));
            seen.push(frame.seen());
            if let Some(reading) = frame
                .reading
                .filter(|r| stamp_s < log.end_s && r.publishable())
            {
                scans.add(activity, Activity::most_likely(&reading.probabilities).0);
            }
        }
        // Falls that begin after the end are not counted, nor are the alerts from their start on.
        let mut falls = fall_intervals(&truth);
        if let Some(&(after_end, _)) = falls.iter().find(|&&(start, _)| start >= log.end_s) {
            falls.retain(|&(start, _)| start < after_end);
            alerts.retain(|a| a.raised_at_s < after_end);
        }
        Self {
            falls,
            alerts,
            truth,
            seen,
            end_s: log.end_s,
            scans,
        }
    }
}

/// The longest run without falls, hours: about 5 hours of computing on one core.
const MAX_NO_FALL_HOURS: f64 = 1000.0;

pub fn run(args: AlertsArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.episode_seconds.is_finite() && args.episode_seconds >= 5.0,
        "--episode-seconds {}: must be at least 5",
        args.episode_seconds
    );
    anyhow::ensure!(
        (0.0..=MAX_NO_FALL_HOURS).contains(&args.no_fall_hours),
        "--no-fall-hours {}: must be a number of hours from 0 to {MAX_NO_FALL_HOURS}",
        args.no_fall_hours
    );
    anyhow::ensure!(
        args.latency_target_s.is_finite() && args.latency_target_s >= 0.0,
        "--latency-target-s {}: must be a finite number of seconds >= 0",
        args.latency_target_s
    );
    if let Some(out) = &args.out {
        super::prepare_output_file(out, "--out")?;
    }
    if let Some(path) = &args.save_readings {
        super::prepare_output_file(path, "--save-readings")?;
    }
    // The report written over the readings would lose hours of simulation.
    if let Some(out) = &args.out {
        for (readings, flag) in [
            (&args.readings, "--readings"),
            (&args.save_readings, "--save-readings"),
        ] {
            if let Some(readings) = readings.as_deref().filter(|r| super::same_file(out, r)) {
                bail!(
                    "--out {}: is the file {flag} names ({}); the report would replace the \
                     readings",
                    out.display(),
                    readings.display()
                );
            }
        }
    }
    let mut config =
        super::classifier_config(args.classifier_config.as_deref(), args.model.as_deref())?;
    for setting in &args.fall_alert {
        config.fall_alert =
            with_fall_alert_setting(&config.fall_alert, setting).context("--fall-alert")?;
    }
    let report = match &args.readings {
        Some(path) => replay(&args, &config, path)?,
        None => simulate(&args, &config)?,
    };
    print_report(&report);
    if let Some(path) = &args.out {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
        outln!("report: {}", path.display());
    }
    // The report of a cut recording is printed and written, but must not pass for a whole one.
    if let Some(cut) = &report.cut_short {
        anyhow::bail!(
            "{}: the report covers only the {} complete episodes before it",
            cut.error,
            cut.episodes_scored
        );
    }
    Ok(())
}

/// Simulates the episodes, runs the localiser and the classifier stage over them, and scores
/// the alerts the stage raised.
fn simulate(args: &AlertsArgs, config: &ClassifierConfig) -> anyhow::Result<AlertsReport> {
    let fall_run_on_s = match args.fall_episodes {
        0 => 0.0,
        _ => fall_run_on_s(args.latency_target_s),
    };
    let stay_down_run_on_s = match args.stay_down_episodes {
        0 => 0.0,
        _ => PERSON_DOWN_WINDOW_S,
    };
    let scenes = with_episode_seconds(
        load_scenes(&args.scenes)?,
        args.episode_seconds,
        fall_run_on_s.max(stay_down_run_on_s),
    )?;
    let model_source = model_source(args, &config.model);
    let model = ActivityModel::load(&config.model, 1).context(model_source.clone())?;
    let stream = model.info().stream;
    // The pose head is left out: it reads the model's state but changes no activity or alert.
    let schedule = config.lane_schedule(stream.window, false);
    let mut classifier = ClassifierStage::with_schedule(model, stream, schedule, config.fall_alert)
        .context(model_source.clone())?;
    let scene_hz = scenes[0].1.lidar.rate_hz;
    if (scene_hz / stream.scan_rate_hz - 1.0).abs() > 1e-6 {
        anyhow::bail!(
            "{model_source} was trained at {} Hz but the scenes scan at {scene_hz} Hz",
            stream.scan_rate_hz
        );
    }
    let no_fall_episodes = (args.no_fall_hours * 3600.0 / args.episode_seconds).ceil() as usize;

    let total = args
        .fall_episodes
        .checked_add(no_fall_episodes)
        .and_then(|n| n.checked_add(args.stay_down_episodes))
        .context("--fall-episodes, --no-fall-hours and --stay-down-episodes: too many episodes")?;
    anyhow::ensure!(
        total > 0,
        "nothing to measure: --fall-episodes, --no-fall-hours and --stay-down-episodes are all 0"
    );
    if let Some(&beyond) = args.trace_episode.iter().find(|&&id| id >= total) {
        anyhow::bail!("--trace-episode {beyond}: there are only episodes 0..{total}");
    }
    let scene_names: Vec<String> = scenes.iter().map(|(_, s)| s.name.clone()).collect();
    let mut readings = match &args.save_readings {
        Some(path) => Some(ReadingsWriter::create(
            path,
            &Header::new(
                config.model.display().to_string(),
                scene_names.clone(),
                args.seed,
                args.episode_seconds,
                args.latency_target_s,
                stream.window,
                schedule,
            ),
        )?),
        None => None,
    };
    let progress = ProgressBar::new(total as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} episodes {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    if !args.trace_episode.is_empty() {
        // The trace lines own stderr.
        progress.set_draw_target(ProgressDrawTarget::hidden());
    }
    let mut tally = Tally::new(config.fall_alert, args.latency_target_s);
    for id in 0..total {
        let kind = if id < args.fall_episodes {
            ScriptKind::WithFalls
        } else if id < args.fall_episodes + no_fall_episodes {
            ScriptKind::Everyday
        } else {
            ScriptKind::FallAndStayDown
        };
        let (_, scene) = &scenes[id % scenes.len()];
        let seed = episode_seed(args.seed, id, EpisodeStream::Alerts);
        let trace = args.trace_episode.contains(&id);
        let run_on_s = match kind {
            ScriptKind::WithFalls => fall_run_on_s,
            ScriptKind::FallAndStayDown => stay_down_run_on_s,
            ScriptKind::Everyday => 0.0,
        };
        let (log, alerts) =
            match run_episode(id, scene, seed, kind, run_on_s, &mut classifier, trace) {
                Ok(episode) => episode,
                Err(e) => {
                    progress.suspend(|| {
                        errln!(
                            "alerts: skipping episode {id} (scene '{}', seed {seed}): {e:#}",
                            scene.name
                        )
                    });
                    progress.inc(1);
                    continue;
                }
            };
        if let Some(readings) = &mut readings {
            readings.write(&log)?;
        }
        tally.add(&log, alerts);
        progress.inc(1);
    }
    progress.finish_and_clear();
    // A report of nothing would read as a clean bill: no falls missed, no false alerts; and
    // so would a replay of its readings, which are removed.
    let unrun = [
        ("with falls", args.fall_episodes, tally.fall_episodes_run),
        (
            "without falls",
            no_fall_episodes,
            tally.no_fall_episodes_run,
        ),
        (
            "staying down",
            args.stay_down_episodes,
            tally.stay_down_episodes_run,
        ),
    ]
    .into_iter()
    .find(|&(_, asked, ran)| asked > 0 && ran == 0);
    if let Some((kind, asked, _)) = unrun {
        if let Some(readings) = readings {
            readings.discard()?;
        }
        anyhow::bail!(
            "none of the {asked} episodes {kind} could be run (each skipped above): the scenes \
             leave no room for their scripts"
        );
    }
    if let Some(readings) = readings {
        readings.finish()?;
    }
    tally.report(
        config.model.display().to_string(),
        scene_names,
        args.seed,
        args.episode_seconds,
        None,
    )
}

/// Scores the alerts `config`'s `fall_alert` settings raise over saved readings: the fall
/// alerts fed exactly what the classifier stage fed them when the readings were recorded.
fn replay(
    args: &AlertsArgs,
    config: &ClassifierConfig,
    path: &Path,
) -> anyhow::Result<AlertsReport> {
    let readings = ReadingsReader::open(path)?;
    let header = readings.header().clone();
    let schedule = config.lane_schedule(header.window, false);
    if (schedule.period, schedule.lanes) != (header.lane_period_scans, header.lanes) {
        anyhow::bail!(
            "--readings {}: recorded with {} lanes restarting every {} scans, but the \
             classifier configuration gives {} every {}: only the fall_alert settings can \
             change on replay (record again for other lanes)",
            path.display(),
            header.lanes,
            header.lane_period_scans,
            schedule.lanes,
            schedule.period
        );
    }
    let mut detector = FallDetector::new(config.fall_alert)
        .with_context(|| format!("--readings {}: fall_alert", path.display()))?;
    let mut tally = Tally::new(config.fall_alert, header.latency_target_s);
    let mut traced = Vec::new();
    let mut scored = 0;
    let mut cut_short = None;
    for log in readings {
        // A recording stopped half-way (a signal, a full disk) still holds complete episodes:
        // they are scored, and the report says where the file ends.
        let log = match log {
            Ok(log) => log,
            Err(e) => {
                cut_short = Some(format!("{e:#}"));
                break;
            }
        };
        let trace = args.trace_episode.contains(&log.id);
        if trace {
            traced.push(log.id);
        }
        detector.reset();
        // The stage's clock: reset with it for each episode, started by its first reading.
        let mut clock = StreamClock::default();
        let start_s = log.start_s();
        let mut alerts = Vec::new();
        for frame in &log.frames {
            let raised: Vec<FallAlert> = match frame.reading {
                Some(reading) => {
                    let stream_s = clock.seconds(frame.stamp_ns as i64);
                    let raised = detector.update(&reading.fall_input(stream_s));
                    raised
                        .iter()
                        .map(|a| clock.alert_in_stamp_time(a))
                        .collect()
                }
                None => Vec::new(),
            };
            if trace {
                trace_scan(frame, start_s, &raised);
            }
            alerts.extend(raised.iter().map(|a| in_episode_time(a, start_s)));
        }
        tally.add(&log, alerts);
        scored += 1;
    }
    if scored == 0 {
        // A header alone (a recording that failed or was stopped before its first episode)
        // would score as a clean result: no falls missed, no false alerts.
        let why = cut_short.map_or(String::new(), |cut| format!(" ({cut})"));
        anyhow::bail!(
            "--readings {}: no episode in it{why}: nothing to score",
            path.display()
        );
    }
    if let Some(missing) = args.trace_episode.iter().find(|id| !traced.contains(id)) {
        anyhow::bail!("--trace-episode {missing}: no such episode in the readings");
    }
    let mut report = tally.report(
        header.model,
        header.scenes,
        header.seed,
        header.episode_seconds,
        Some(path),
    )?;
    report.cut_short = cut_short.map(|error| CutShort {
        error,
        episodes_scored: scored,
    });
    Ok(report)
}

/// What the episodes scored so far add up to.
struct Tally {
    fall_alert: FallAlertConfig,
    latency_target_s: f64,
    outcomes: Vec<FallOutcome>,
    unmatched: usize,
    repeated: usize,
    person_down_due: Vec<DownSpell>,
    repeated_person_down: usize,
    person_down_not_due_in_fall_episodes: usize,
    false_alerts: Vec<FalseAlert>,
    everyday_person_down_due: usize,
    scans: ConfusionMatrix,
    fall_episodes_run: usize,
    no_fall_episodes_run: usize,
    stay_down_episodes_run: usize,
    /// Episodes staying down in which no spell fell due before the end: they measure nothing.
    stay_down_without_spell: usize,
    stay_down_fall_detected: usize,
}

impl Tally {
    fn new(fall_alert: FallAlertConfig, latency_target_s: f64) -> Self {
        Self {
            fall_alert,
            latency_target_s,
            outcomes: Vec::new(),
            unmatched: 0,
            repeated: 0,
            person_down_due: Vec::new(),
            repeated_person_down: 0,
            person_down_not_due_in_fall_episodes: 0,
            false_alerts: Vec::new(),
            everyday_person_down_due: 0,
            scans: ConfusionMatrix::new(),
            fall_episodes_run: 0,
            no_fall_episodes_run: 0,
            stay_down_episodes_run: 0,
            stay_down_without_spell: 0,
            stay_down_fall_detected: 0,
        }
    }

    /// Scores one episode and the alerts (in episode time) raised over it.
    fn add(&mut self, log: &EpisodeLog, alerts: Vec<FallAlert>) {
        let id = log.id;
        let episode = Episode::of(log, alerts);
        self.scans.merge(&episode.scans);
        let down_after_s = self.fall_alert.down_after_s;
        // The spells scored: due by the episode's end.
        let spells = down_spells(&episode.truth, episode.end_s, down_after_s);
        let answers: Vec<Option<&FallAlert>> = spells
            .iter()
            .map(|&spell| person_down_answering(&episode.alerts, spell))
            .collect();
        // Whether an alert is due is judged over the whole truth, run-on included: a
        // PERSON_DOWN in a spell that fell due only after the end is right, not false, though
        // that spell is not scored. The scored spells are among these, with the same bounds.
        let due_spells = down_spells(&episode.truth, f64::INFINITY, down_after_s);
        let due_answers: Vec<&FallAlert> = due_spells
            .iter()
            .filter_map(|&spell| person_down_answering(&episode.alerts, spell))
            .collect();
        let answers_a_spell =
            |alert: &FallAlert| due_answers.iter().any(|a| std::ptr::eq(*a, alert));
        if log.kind != ScriptKind::Everyday {
            self.person_down_not_due_in_fall_episodes += episode
                .alerts
                .iter()
                .filter(|a| a.kind == AlertKind::PersonDown && !answers_a_spell(a))
                .count();
        }
        match log.kind {
            ScriptKind::WithFalls => {
                self.fall_episodes_run += 1;
                let (mut matched, rest) = match_alerts(
                    id,
                    &episode.falls,
                    &episode.alerts,
                    &episode.truth,
                    &episode.seen,
                );
                explain_unalerted(
                    &mut matched,
                    &episode.truth,
                    &self.fall_alert,
                    self.latency_target_s,
                );
                self.outcomes.extend(matched);
                self.unmatched += rest;
                self.repeated += repeated_fall_alerts(&episode.falls, &episode.alerts);
            }
            ScriptKind::Everyday => {
                self.no_fall_episodes_run += 1;
                let (due, not_due): (Vec<&FallAlert>, Vec<&FallAlert>) =
                    episode.alerts.iter().partition(|a| answers_a_spell(a));
                self.everyday_person_down_due += due.len();
                self.false_alerts
                    .extend(not_due.into_iter().map(|a| FalseAlert {
                        episode: id,
                        scene: log.scene.clone(),
                        kind: a.kind,
                        raised_at_s: a.raised_at_s,
                        activity: activity_at(&episode.truth, a.raised_at_s).label(),
                        activity_1s_before:
                            activity_at(&episode.truth, a.raised_at_s - 1.0).label(),
                        truth_down_s: down_for(&episode.truth, a.raised_at_s),
                    }));
            }
            ScriptKind::FallAndStayDown => {
                self.stay_down_episodes_run += 1;
                self.stay_down_without_spell += usize::from(spells.is_empty());
                let fall_start = episode.falls.first().map_or(f64::INFINITY, |&(s, _)| s);
                self.unmatched += episode
                    .alerts
                    .iter()
                    .filter(|a| a.raised_at_s < fall_start)
                    .count();
                self.repeated += repeated_fall_alerts(&episode.falls, &episode.alerts);
                self.stay_down_fall_detected += usize::from(
                    episode
                        .alerts
                        .iter()
                        .any(|a| a.kind == AlertKind::FallDetected && a.raised_at_s >= fall_start),
                );
            }
        }
        self.repeated_person_down += repeated_person_down_alerts(&due_spells, &episode.alerts);
        for (&(start, end), alert) in spells.iter().zip(answers) {
            self.person_down_due.push(DownSpell {
                episode: id,
                scene: log.scene.clone(),
                start_s: start,
                end_s: end,
                delay_s: alert.map(|a| a.raised_at_s - start - self.fall_alert.down_after_s),
                seen_share: seen_share(&episode.truth, &episode.seen, start, end),
            });
        }
    }

    /// The report; an error where the episodes staying down measured nothing (an empty
    /// `person_down_due` would read as no PERSON_DOWN missed). `readings`: the file replayed
    /// (`--readings`), `None` for a simulated run.
    fn report(
        self,
        model: String,
        scenes: Vec<String>,
        seed: u64,
        episode_seconds: f64,
        readings: Option<&Path>,
    ) -> anyhow::Result<AlertsReport> {
        let (ran, without) = (self.stay_down_episodes_run, self.stay_down_without_spell);
        let down_after_s = self.fall_alert.down_after_s;
        if ran > 0 && without == ran {
            let never_due = format!(
                "none of the {ran} episodes staying down had the person down for down_after_s \
                 ({down_after_s} s) before its end (--episode-seconds {episode_seconds}): \
                 PERSON_DOWN never fell due there"
            );
            anyhow::bail!(match readings {
                None => format!(
                    "{never_due}; give a longer --episode-seconds (their fall comes 5 s to \
                     about 40 % into an episode) or a lower down_after_s"
                ),
                Some(path) => format!(
                    "--readings {}: {never_due}; record again with a longer --episode-seconds \
                     (their fall comes 5 s to about 40 % into an episode), or replay with a \
                     lower down_after_s (--fall-alert down_after_s=SECONDS)",
                    path.display()
                ),
            });
        }
        if without > 0 {
            errln!(
                "alerts: {without} of the {ran} episodes staying down had the person down for \
                 down_after_s ({down_after_s} s) only after their end (--episode-seconds \
                 {episode_seconds}): no spell of theirs is counted"
            );
        }
        let latencies: Vec<f64> = self.outcomes.iter().filter_map(|o| o.latency_s).collect();
        let false_alerts = self.false_alerts;
        let count = |kind: AlertKind| false_alerts.iter().filter(|a| a.kind == kind).count();
        let mut by_activity: Vec<(&'static str, usize)> = Activity::ALL
            .iter()
            .map(|a| {
                let n = false_alerts
                    .iter()
                    .filter(|f| f.activity == a.label())
                    .count();
                (a.label(), n)
            })
            .filter(|&(_, n)| n > 0)
            .collect();
        by_activity.sort_by_key(|&(_, n)| std::cmp::Reverse(n));
        let delays: Vec<f64> = self
            .person_down_due
            .iter()
            .filter_map(|d| d.delay_s)
            .collect();
        let no_fall_hours = self.no_fall_episodes_run as f64 * episode_seconds / 3600.0;
        Ok(AlertsReport {
            model,
            scenes,
            seed,
            fall_episodes: self.fall_episodes_run,
            falls: self.outcomes.len(),
            falls_alerted: latencies.len(),
            falls_alerted_within_target: latencies
                .iter()
                .filter(|&&l| l <= self.latency_target_s)
                .count(),
            latency_target_s: self.latency_target_s,
            latency_s: Spread::of(latencies),
            falls_not_in_time: Shortfall::of(&self.outcomes, self.latency_target_s),
            unmatched_alerts_in_fall_episodes: self.unmatched,
            person_down_not_due_in_fall_episodes: self.person_down_not_due_in_fall_episodes,
            repeated_fall_alerts: self.repeated,
            no_fall_hours,
            false_alerts: false_alerts.len(),
            false_fall_detected: count(AlertKind::FallDetected),
            false_person_down: count(AlertKind::PersonDown),
            everyday_person_down_due: self.everyday_person_down_due,
            false_alerts_per_hour: if no_fall_hours > 0.0 {
                false_alerts.len() as f64 / no_fall_hours
            } else {
                0.0
            },
            person_down_due_alerted: delays.len(),
            person_down_due_in_time: delays
                .iter()
                .filter(|&&d| d <= PERSON_DOWN_WINDOW_S)
                .count(),
            person_down_window_s: PERSON_DOWN_WINDOW_S,
            repeated_person_down: self.repeated_person_down,
            person_down_delay_s: Spread::of(delays),
            person_down_due: self.person_down_due,
            stay_down_episodes: self.stay_down_episodes_run,
            stay_down_fall_detected: self.stay_down_fall_detected,
            false_alerts_by_activity: by_activity,
            outcomes: self.outcomes,
            false_alert_details: false_alerts,
            scans: self.scans.report(),
            cut_short: None,
        })
    }
}

/// The model and where it was named, for messages: `--model`, or the classifier
/// configuration's `model`.
fn model_source(args: &AlertsArgs, model: &Path) -> String {
    match (&args.model, &args.classifier_config) {
        (None, Some(config)) => format!(
            "model {} (named by --classifier-config {})",
            model.display(),
            config.display()
        ),
        _ => format!("--model {}", model.display()),
    }
}

/// How long an episode with falls runs on past its end: a fall that begins on its last scan
/// may end `FALL_SECONDS` later, and its alert is due within the latency target after that.
/// Falls that begin in that time are not counted.
fn fall_run_on_s(latency_target_s: f64) -> f64 {
    scripts::FALL_SECONDS.end + latency_target_s
}

/// How long after PERSON_DOWN fell due it is counted in time (`person_down_due_in_time`, the
/// figures' "within 3 s of due" in README and docs/classifier.md), and so how long an episode
/// staying down runs on past its end: a spell due on its last scan can then be answered. Before, such episodes
/// stopped at their end, and a spell due just before it counted as missed.
const PERSON_DOWN_WINDOW_S: f64 = 3.0;

/// An alert's times in episode time (from `start_s` on the stream's clock), as the ground
/// truth's are.
fn in_episode_time(alert: &FallAlert, start_s: f64) -> FallAlert {
    FallAlert {
        event_time_s: alert.event_time_s - start_s,
        raised_at_s: alert.raised_at_s - start_s,
        down_since_s: alert.down_since_s - start_s,
        ..*alert
    }
}

/// Simulates one episode (and `run_on_s` past its end) and runs the localiser over it, then
/// the classifier stage the classifier node runs (the model and the fall alerts) on the
/// observations the localiser node would publish: nothing while no person is tracked, an
/// empty view while one is predicted out of sight. Returns what the stage gave the alerts
/// on every scan, and the alerts (in episode time).
fn run_episode(
    id: usize,
    scene: &lidar_har_sim::Scene,
    seed: u64,
    kind: ScriptKind,
    run_on_s: f64,
    stage: &mut ClassifierStage<ActivityModel, NoPoseHead>,
    trace: bool,
) -> anyhow::Result<(EpisodeLog, Vec<FallAlert>)> {
    let mut sim = scripts::episode(scene, seed, false, kind)?;
    let end_s = (sim.frame_count() as f64 - 0.5) / scene.lidar.rate_hz;
    sim.run_on(run_on_s);
    let mut localiser = episode_localiser(&sim, false)?;
    stage.reset();
    let geometry = sim.scan_geometry();
    let start_ns = sim.start_ns();
    let start_s = start_ns as f64 * 1e-9;
    let mut frames = Vec::new();
    let mut alerts = Vec::new();
    while let Some(frame) = sim.step() {
        let stamp_ns = frame.stamp_ns as i64;
        localiser.add_odometry(stamp_ns, frame.robot);
        let result = localiser.process_scan(&core_scan(&geometry, stamp_ns, frame.ranges));
        let tracked = result
            .output
            .as_ref()
            .and_then(|o| o.person.as_ref().map(|p| (o, p)));
        let (reading, raised) = match tracked {
            Some((output, person)) => {
                let out = stage.on_observation(&observation_msg(output, person, "map"))?;
                (Some(Reading::of(&out)), out.alerts)
            }
            None => (None, Vec::new()),
        };
        let logged = Frame {
            stamp_ns: frame.stamp_ns,
            truth: frame.person.map(|p| p.activity),
            reading,
        };
        if trace {
            trace_scan(&logged, start_s, &raised);
        }
        alerts.extend(raised.iter().map(|a| in_episode_time(a, start_s)));
        frames.push(logged);
    }
    let log = EpisodeLog {
        id,
        kind,
        scene: scene.name.clone(),
        start_ns,
        end_s,
        frames,
    };
    Ok((log, alerts))
}

/// One scan of a traced episode on stderr, with the alerts raised at it.
fn trace_scan(frame: &Frame, start_s: f64, alerts: &[FallAlert]) {
    let stamp_s = frame.stamp_s(start_s);
    let truth = frame.truth.map_or("-", Activity::label);
    let Some(reading) = frame.reading else {
        errln!("trace t={stamp_s:.2} truth={truth} tracked=false");
        return;
    };
    let (activity, confidence) = Activity::most_likely(&reading.probabilities);
    errln!(
        "trace t={stamp_s:.2} truth={truth} model={} p={confidence:.2} p_fall={:.2} seen={} \
         length={} at={} alerts=[{}]",
        activity.label(),
        reading.probabilities[Activity::FallingDown.index()],
        reading.visible,
        reading
            .body_length_m
            .map_or("-".into(), |l| format!("{l:.2}")),
        if reading.visible {
            let at = reading.position();
            format!("{:.2},{:.2}", at.x, at.y)
        } else {
            "-".into()
        },
        alerts
            .iter()
            .map(|a| a.kind.name())
            .collect::<Vec<_>>()
            .join(" "),
    );
}

/// Share of the scans in `[start, end)` where the person was seen (1 when there are none).
fn seen_share(truth: &[(f64, Activity)], seen_at: &[bool], start: f64, end: f64) -> f64 {
    let (mut seen, mut all) = (0, 0);
    for (&(t, _), &s) in truth.iter().zip(seen_at) {
        if (start..end).contains(&t) {
            all += 1;
            seen += usize::from(s);
        }
    }
    if all == 0 {
        1.0
    } else {
        seen as f64 / all as f64
    }
}

/// The true activity at `t` (the last scan at or before it; the first scan before that).
fn activity_at(truth: &[(f64, Activity)], t: f64) -> Activity {
    let i = truth.partition_point(|&(s, _)| s <= t);
    truth
        .get(i.saturating_sub(1))
        .map_or(Activity::Standing, |&(_, a)| a)
}

/// How long the truth had the person off their feet (not upright) without a break up to `t`
/// (0 when upright at `t`).
fn down_for(truth: &[(f64, Activity)], t: f64) -> f64 {
    let upto = truth.partition_point(|&(s, _)| s <= t);
    let down_since = truth[..upto]
        .iter()
        .rev()
        .take_while(|&&(_, a)| !a.is_upright())
        .last();
    down_since.map_or(0.0, |&(s, _)| t - s)
}

/// The (start, end) of every spell in which the truth has the person falling or on the floor
/// (getting up ends it: PERSON_DOWN is for not getting up) for at least `min_s` by the last
/// scan before `end_s`, the episode's end. A spell still on then runs on to where the truth,
/// run-on included, ends it: an alert for it may come after the episode's end.
fn down_spells(truth: &[(f64, Activity)], end_s: f64, min_s: f64) -> Vec<(f64, f64)> {
    let last_scan = truth[..truth.partition_point(|&(t, _)| t < end_s)]
        .last()
        .map_or(f64::NEG_INFINITY, |&(t, _)| t);
    let mut spells = runs_where(truth, |a| a.is_on_floor() || a == Activity::FallingDown);
    spells.retain(|&(s, e)| e.min(last_scan) - s >= min_s);
    spells
}

/// Whether `alert` is a PERSON_DOWN raised in a down spell (or within a second of its end).
fn person_down_in(alert: &FallAlert, (start, end): (f64, f64)) -> bool {
    alert.kind == AlertKind::PersonDown
        && alert.raised_at_s >= start
        && alert.raised_at_s <= end + 1.0
}

/// The first PERSON_DOWN raised in a down spell: the alert that answered it.
fn person_down_answering(alerts: &[FallAlert], spell: (f64, f64)) -> Option<&FallAlert> {
    alerts.iter().find(|a| person_down_in(a, spell))
}

/// `PersonDown` alerts after the first in each spell.
fn repeated_person_down_alerts(spells: &[(f64, f64)], alerts: &[FallAlert]) -> usize {
    spells
        .iter()
        .map(|&spell| {
            let in_spell = alerts.iter().filter(|a| person_down_in(a, spell)).count();
            in_spell.saturating_sub(1)
        })
        .sum()
}

/// The (start, end) of every run of `falling_down` in the truth.
fn fall_intervals(truth: &[(f64, Activity)]) -> Vec<(f64, f64)> {
    runs_where(truth, |a| a == Activity::FallingDown)
}

/// The (start, end) of every run of scans whose activity passes `test`; the end is the first
/// scan after the run, or the last scan.
fn runs_where(truth: &[(f64, Activity)], test: impl Fn(Activity) -> bool) -> Vec<(f64, f64)> {
    let mut runs = Vec::new();
    let mut start = None;
    for &(t, activity) in truth {
        match (test(activity), start) {
            (true, None) => start = Some(t),
            (false, Some(s)) => {
                runs.push((s, t));
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(s), Some(&(t, _))) = (start, truth.last()) {
        runs.push((s, t));
    }
    runs
}

/// Pairs each fall with the first alert raised from its start until the next fall's start;
/// returns the outcomes and how many alerts came before any fall. Later alerts in a fall's
/// window (a PERSON_DOWN after its FALL_DETECTED) are not false. `truth` and `seen` (aligned)
/// give each fall's share of scans with the person seen.
fn match_alerts(
    episode: usize,
    falls: &[(f64, f64)],
    alerts: &[FallAlert],
    truth: &[(f64, Activity)],
    seen: &[bool],
) -> (Vec<FallOutcome>, usize) {
    // The fall whose window [start, next start) holds the alert; `None` before the first.
    let window = |a: &FallAlert| falls.iter().rposition(|&(start, _)| a.raised_at_s >= start);
    let outcomes = falls
        .iter()
        .enumerate()
        .map(|(k, &(start, end))| {
            let first = alerts.iter().find(|a| window(a) == Some(k));
            FallOutcome {
                episode,
                start_s: start,
                end_s: end,
                latency_s: first.map(|a| a.raised_at_s - end),
                alert: first.map(|a| a.kind.name()),
                seen_share: seen_share(truth, seen, start, end),
                unalerted_because: None,
            }
        })
        .collect();
    let unmatched = alerts.iter().filter(|a| window(a).is_none()).count();
    (outcomes, unmatched)
}

/// `FALL_DETECTED` alerts beyond the first in each fall's window [start, next start).
fn repeated_fall_alerts(falls: &[(f64, f64)], alerts: &[FallAlert]) -> usize {
    let ends = falls.iter().skip(1).map(|&(start, _)| start);
    falls
        .iter()
        .zip(ends.chain([f64::INFINITY]))
        .map(|(&(start, _), next)| {
            let in_window = alerts.iter().filter(|a| {
                a.kind == AlertKind::FallDetected && a.raised_at_s >= start && a.raised_at_s < next
            });
            in_window.count().saturating_sub(1)
        })
        .sum()
}

/// Marks the falls of one episode that had no alert of their own for a reason the alert
/// logic intends (see [`FallOutcome::unalerted_because`]).
fn explain_unalerted(
    outcomes: &mut [FallOutcome],
    truth: &[(f64, Activity)],
    fall_alert: &FallAlertConfig,
    latency_target_s: f64,
) {
    let first_scan = truth.first().map(|&(t, _)| t);
    let last_scan = truth.last().map_or(f64::NEG_INFINITY, |&(t, _)| t);
    let mut alerted_at: Option<f64> = None;
    for outcome in outcomes.iter_mut() {
        if let Some(latency) = outcome.latency_s {
            alerted_at = Some(outcome.end_s + latency);
            continue;
        }
        if first_scan == Some(outcome.start_s) {
            outcome.unalerted_because = Some(AT_EPISODE_START);
        } else if let Some(at) = alerted_at
            && !rearmed_between(truth, at, outcome.start_s, fall_alert)
        {
            outcome.unalerted_because = Some(INSIDE_ALERTED_INCIDENT);
        } else if last_scan - outcome.end_s < latency_target_s {
            outcome.unalerted_because = Some(AT_EPISODE_END);
        }
    }
}

/// Whether the truth between `from` and `to` re-arms `FALL_DETECTED`: the person upright
/// for `rearm_upright_s` without a break, or getting up for `rearm_getting_up_s` (when on).
fn rearmed_between(
    truth: &[(f64, Activity)],
    from: f64,
    to: f64,
    fall_alert: &FallAlertConfig,
) -> bool {
    let getting_up_s = fall_alert.rearm_getting_up_s;
    held_for(
        truth,
        from,
        to,
        fall_alert.rearm_upright_s,
        Activity::is_upright,
    ) || (getting_up_s > 0.0
        && held_for(truth, from, to, getting_up_s, |a| a == Activity::GettingUp))
}

/// Whether the truth shows `holds` true for `span_s` without a break between `from` and `to`.
fn held_for(
    truth: &[(f64, Activity)],
    from: f64,
    to: f64,
    span_s: f64,
    holds: impl Fn(Activity) -> bool,
) -> bool {
    let mut since = None;
    for &(t, a) in truth.iter().filter(|&&(t, _)| t >= from && t < to) {
        match (holds(a), since) {
            (true, None) => since = Some(t),
            (true, Some(s)) if t - s >= span_s => return true,
            (false, _) => since = None,
            _ => {}
        }
    }
    false
}

fn print_report(r: &AlertsReport) {
    let recall = |a: Activity| recall_text(&r.scans.per_class[a.index()]);
    outln!(
        "streaming classification: {} scans published, {:.1} % right, macro F1 {:.1} %; \
         recall falling_down {}, running {}",
        r.scans.samples,
        100.0 * r.scans.accuracy,
        100.0 * r.scans.macro_f1,
        recall(Activity::FallingDown),
        recall(Activity::Running),
    );
    outln!(
        "falls: {} in {} episodes; alerted {} ({:.1} %), within {:.1} s of the fall's end {} ({:.1} %)",
        r.falls,
        r.fall_episodes,
        r.falls_alerted,
        percent(r.falls_alerted, r.falls),
        r.latency_target_s,
        r.falls_alerted_within_target,
        percent(r.falls_alerted_within_target, r.falls),
    );
    if let Some(l) = &r.latency_s {
        outln!(
            "latency after the fall's end: median {:.2} s, p95 {:.2} s, max {:.2} s",
            l.median,
            l.p95,
            l.max
        );
    }
    let s = &r.falls_not_in_time;
    outln!(
        "falls not alerted within {:.1} s: alerted later {}; without an alert at the episode's \
         start {}, inside an alerted incident {}, at the episode's end {}, hidden for most of \
         the fall {}, in view {}",
        r.latency_target_s,
        s.late,
        s.at_episode_start,
        s.inside_alerted_incident,
        s.at_episode_end,
        s.hidden,
        s.in_view,
    );
    outln!(
        "alerts in fall episodes before any fall: {}; PERSON_DOWN there in no spell where it was due: {}; falls alerted twice (FALL_DETECTED): {}",
        r.unmatched_alerts_in_fall_episodes,
        r.person_down_not_due_in_fall_episodes,
        r.repeated_fall_alerts
    );
    outln!(
        "without falls: {:.2} h simulated, {} false alerts ({} FALL_DETECTED, {} PERSON_DOWN), {:.2} per hour",
        r.no_fall_hours,
        r.false_alerts,
        r.false_fall_detected,
        r.false_person_down,
        r.false_alerts_per_hour
    );
    outln!(
        "PERSON_DOWN there for someone truly on the floor for down_after_s (due, not counted as false): {}",
        r.everyday_person_down_due
    );
    outln!(
        "episodes ending with a fall and staying down: {}, FALL_DETECTED in {}",
        r.stay_down_episodes,
        r.stay_down_fall_detected
    );
    outln!("{}", person_down_due_line(r));
    if !r.false_alerts_by_activity.is_empty() {
        let list: Vec<String> = r
            .false_alerts_by_activity
            .iter()
            .map(|(a, n)| format!("{a} {n}"))
            .collect();
        outln!(
            "false alerts raised while the person was: {}",
            list.join(", ")
        );
    }
}

/// The spells where PERSON_DOWN was due and how they were answered: all raised, then those
/// within the window of falling due (the count the README quotes), then the delays.
fn person_down_due_line(r: &AlertsReport) -> String {
    let delay = r.person_down_delay_s.as_ref().map_or(String::new(), |d| {
        format!(
            ", raised after it fell due: median {:.2} s, max {:.2} s",
            d.median, d.max
        )
    });
    format!(
        "person truly on the floor for down_after_s (all episodes): {} spells, PERSON_DOWN in {}, \
         within {} s of due in {}{delay}; spells alerted more than once: {}",
        r.person_down_due.len(),
        r.person_down_due_alerted,
        r.person_down_window_s,
        r.person_down_due_in_time,
        r.repeated_person_down
    )
}

/// A class's recall in percent, or "-" when no scan truly was of it: 0 % would read as a
/// class the model always missed.
fn recall_text(class: &lidar_har_core::metrics::ClassMetrics) -> String {
    if class.support == 0 {
        "-".to_string()
    } else {
        format!("{:.1} %", 100.0 * class.recall)
    }
}

fn percent(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    fn alert(kind: AlertKind, raised_at_s: f64) -> FallAlert {
        FallAlert {
            kind,
            event_time_s: raised_at_s,
            raised_at_s,
            down_since_s: raised_at_s,
            position: DVec2::ZERO,
            confidence: 0.9,
        }
    }

    #[test]
    fn a_class_no_scan_truly_was_has_no_recall_to_print() {
        let class = |support, recall| lidar_har_core::metrics::ClassMetrics {
            activity: Activity::FallingDown,
            precision: 0.0,
            recall,
            f1: 0.0,
            support,
            predicted: 0,
        };
        assert_eq!(recall_text(&class(0, 0.0)), "-");
        assert_eq!(recall_text(&class(8, 0.0)), "0.0 %");
        assert_eq!(recall_text(&class(8, 0.875)), "87.5 %");
    }

    #[test]
    fn activity_at_takes_the_last_scan_at_or_before() {
        use Activity::*;
        let truth = [(0.0, Standing), (1.0, Walking), (2.0, SittingOnFloor)];
        assert_eq!(activity_at(&truth, 1.5), Walking);
        assert_eq!(activity_at(&truth, 2.0), SittingOnFloor);
        assert_eq!(activity_at(&truth, -3.0), Standing);
        assert_eq!(activity_at(&truth, 9.0), SittingOnFloor);
        assert_eq!(activity_at(&[], 1.0), Standing);
    }

    #[test]
    fn time_down_counts_back_to_the_last_upright_scan() {
        use Activity::*;
        let truth = [
            (0.0, Walking),
            (1.0, SittingOnFloor),
            (2.0, Crawling),
            (3.0, GettingUp),
            (4.0, Standing),
        ];
        assert_eq!(down_for(&truth, 3.5), 2.5);
        assert_eq!(down_for(&truth, 1.0), 0.0);
        assert_eq!(down_for(&truth, 4.0), 0.0);
        assert_eq!(down_for(&truth, 0.5), 0.0);
        assert_eq!(down_for(&[], 1.0), 0.0);
        assert_eq!(down_for(&[(0.0, LyingDown)], 7.0), 7.0);
    }

    #[test]
    fn falls_are_the_runs_of_falling_down() {
        use Activity::*;
        let truth: Vec<(f64, Activity)> = [
            Walking,
            FallingDown,
            FallingDown,
            LyingDown,
            GettingUp,
            FallingDown,
        ]
        .into_iter()
        .enumerate()
        .map(|(i, a)| (i as f64, a))
        .collect();
        assert_eq!(fall_intervals(&truth), vec![(1.0, 3.0), (5.0, 5.0)]);
        assert!(fall_intervals(&[]).is_empty());
    }

    #[test]
    fn down_spells_are_the_long_stretches_off_the_feet() {
        use Activity::*;
        let truth: Vec<(f64, Activity)> = [
            Walking,
            FallingDown,
            LyingDown,
            LyingDown,
            GettingUp,
            SittingOnFloor,
            Standing,
            Crawling,
            Crawling,
            LyingDown,
        ]
        .into_iter()
        .enumerate()
        .map(|(i, a)| (i as f64, a))
        .collect();
        // Falling and lying until getting up (1-4 s) is 3 s; sitting (5-6 s) only 1; crawling
        // and lying to the end (7-9 s) 2.
        assert_eq!(down_spells(&truth, 9.5, 2.0), vec![(1.0, 4.0), (7.0, 9.0)]);
        assert_eq!(down_spells(&truth, 9.5, 2.5), vec![(1.0, 4.0)]);
        assert!(down_spells(&[], 0.0, 0.0).is_empty());
    }

    #[test]
    fn a_spell_on_at_the_end_runs_on_and_counts_only_if_due_by_then() {
        use Activity::*;
        // The episode ends at 8.5 s (its last scan at 8 s), then runs on to 11 s.
        let truth: Vec<(f64, Activity)> = [
            Walking,
            FallingDown,
            LyingDown,
            LyingDown,
            LyingDown,
            LyingDown,
            LyingDown,
            LyingDown,
            LyingDown,
            LyingDown,
            GettingUp,
            FallingDown,
        ]
        .into_iter()
        .enumerate()
        .map(|(i, a)| (i as f64, a))
        .collect();
        // Down 1-8 s by the end (7 s): due at 5 s, the spell runs on to getting up at 10 s.
        assert_eq!(down_spells(&truth, 8.5, 5.0), vec![(1.0, 10.0)]);
        // Due only at 9 s, in the run-on: not counted; nor is the fall that begins at 11 s.
        assert!(down_spells(&truth, 8.5, 8.0).is_empty());
        assert_eq!(
            down_spells(&truth, 11.5, 0.0),
            vec![(1.0, 10.0), (11.0, 11.0)]
        );
    }

    #[test]
    fn each_fall_takes_the_first_alert_after_its_start() {
        let falls = [(10.0, 11.0), (30.0, 31.0), (50.0, 51.0)];
        let alerts = [
            alert(AlertKind::FallDetected, 5.0), // before any fall: unmatched
            alert(AlertKind::FallDetected, 11.4),
            alert(AlertKind::PersonDown, 26.0), // same fall, later: not false
            alert(AlertKind::PersonDown, 45.0), // the second fall, late
        ];
        let (outcomes, unmatched) = match_alerts(3, &falls, &alerts, &[], &[]);
        assert_eq!(unmatched, 1);
        assert_eq!(repeated_fall_alerts(&falls, &alerts), 0);
        let latencies: Vec<Option<f64>> = outcomes.iter().map(|o| o.latency_s).collect();
        assert!((latencies[0].unwrap() - 0.4).abs() < 1e-9);
        assert!((latencies[1].unwrap() - 14.0).abs() < 1e-9);
        assert_eq!(latencies[2], None);
        assert_eq!(outcomes[1].alert, Some("PERSON_DOWN"));
        assert!(outcomes.iter().all(|o| o.episode == 3));
    }

    #[test]
    fn falls_not_alerted_in_time_are_counted_by_why_not() {
        let outcome = |latency_s, unalerted_because, seen_share| FallOutcome {
            episode: 0,
            start_s: 10.0,
            end_s: 11.0,
            latency_s,
            alert: latency_s.map(|_| "FALL_DETECTED"),
            seen_share,
            unalerted_because,
        };
        let outcomes = [
            outcome(Some(0.4), None, 1.0),
            outcome(Some(1.0), None, 1.0),
            outcome(Some(1.6), None, 1.0),
            outcome(None, Some("at the episode's start"), 1.0),
            outcome(None, Some("inside an alerted incident"), 1.0),
            outcome(None, Some("at the episode's end"), 1.0),
            outcome(None, None, 0.2),
            outcome(None, None, 0.5),
            outcome(None, None, 0.9),
        ];
        let expected = Shortfall {
            late: 1,
            at_episode_start: 1,
            inside_alerted_incident: 1,
            at_episode_end: 1,
            hidden: 1,
            in_view: 2,
        };
        assert_eq!(Shortfall::of(&outcomes, 1.0), expected);
    }

    #[test]
    fn a_second_fall_detected_for_the_same_fall_is_counted() {
        let falls = [(10.0, 11.0), (30.0, 31.0)];
        let alerts = [
            alert(AlertKind::FallDetected, 11.2),
            alert(AlertKind::PersonDown, 25.0),
            alert(AlertKind::FallDetected, 27.0), // the first fall again
            alert(AlertKind::FallDetected, 31.3),
            alert(AlertKind::FallDetected, 40.0), // the second fall again
        ];
        assert_eq!(repeated_fall_alerts(&falls, &alerts), 2);
        assert_eq!(repeated_fall_alerts(&[], &alerts), 0);
    }

    #[test]
    fn a_second_person_down_in_the_same_spell_is_counted() {
        let spells = [(10.0, 40.0), (50.0, 80.0)];
        let alerts = [
            alert(AlertKind::FallDetected, 11.0),
            alert(AlertKind::PersonDown, 25.0),
            alert(AlertKind::PersonDown, 38.0), // the first spell again
            alert(AlertKind::PersonDown, 41.0), // within a second of its end: again
            alert(AlertKind::PersonDown, 66.0),
        ];
        assert_eq!(repeated_person_down_alerts(&spells, &alerts), 2);
        assert_eq!(repeated_person_down_alerts(&spells, &alerts[..2]), 0);
        assert_eq!(repeated_person_down_alerts(&[], &alerts), 0);
    }

    #[test]
    fn unalerted_falls_are_explained_only_when_the_logic_meant_no_alert() {
        use Activity::*;
        // 0-1 s fall (at the start), lying, 4-5 s fall (alerted at 5.2), lying, 2 s getting
        // up, 9-10 s fall with no upright between (same incident, unless getting up re-arms
        // the alert), then 3.5 s standing, 14-15 s fall (a new incident, missed), standing,
        // 19.5-20 s fall 0.5 s before the end.
        let mut truth = Vec::new();
        let mut push = |from: f64, to: f64, a: Activity| {
            let mut t = from;
            while t < to - 1e-9 {
                truth.push((t, a));
                t += 0.05;
            }
        };
        push(0.0, 1.0, FallingDown);
        push(1.0, 4.0, LyingDown);
        push(4.0, 5.0, FallingDown);
        push(5.0, 7.0, LyingDown);
        push(7.0, 9.0, GettingUp);
        push(9.0, 10.0, FallingDown);
        push(10.0, 10.5, GettingUp);
        push(10.5, 14.0, Standing);
        push(14.0, 15.0, FallingDown);
        push(15.0, 16.0, LyingDown);
        push(16.0, 19.5, Standing);
        push(19.5, 20.0, FallingDown);
        push(20.0, 20.5, LyingDown);
        let falls = fall_intervals(&truth);
        assert_eq!(falls.len(), 5);
        let seen = vec![true; truth.len()];
        let (outcomes, _) = match_alerts(
            0,
            &falls,
            &[alert(AlertKind::FallDetected, 5.2)],
            &truth,
            &seen,
        );
        let reasons = |rearm_getting_up_s| {
            let config = FallAlertConfig {
                rearm_upright_s: 3.0,
                rearm_getting_up_s,
                ..FallAlertConfig::default()
            };
            let mut outcomes = outcomes.clone();
            explain_unalerted(&mut outcomes, &truth, &config, 1.0);
            outcomes
                .iter()
                .map(|o| o.unalerted_because)
                .collect::<Vec<_>>()
        };
        assert_eq!(
            reasons(0.0),
            [
                Some("at the episode's start"),
                None,
                Some("inside an alerted incident"),
                None,
                Some("at the episode's end"),
            ]
        );
        // Getting up for 2 s before the 9 s fall re-arms the alert: that fall needed one.
        assert_eq!(
            reasons(1.5),
            [
                Some("at the episode's start"),
                None,
                None,
                None,
                Some("at the episode's end"),
            ]
        );
    }

    /// An episode at 20 Hz: `script` gives each stretch's true activity and seconds, every
    /// scan read surely as the truth; `seconds` is where the episode ends (the rest runs on).
    fn logged(id: usize, kind: ScriptKind, script: &[(Activity, f64)], seconds: f64) -> EpisodeLog {
        let start_ns = 1_700_000_000_000_000_000;
        let mut frames = Vec::new();
        for &(activity, span_s) in script {
            for _ in 0..(span_s * 20.0).round() as usize {
                let mut probabilities = [0.0; Activity::COUNT];
                probabilities[activity.index()] = 1.0;
                frames.push(Frame {
                    stamp_ns: start_ns + frames.len() as u64 * 50_000_000,
                    truth: Some(activity),
                    reading: Some(Reading {
                        visible: true,
                        ready: true,
                        position: [1.0, 1.0],
                        probabilities,
                        body_length_m: Some(0.5),
                    }),
                });
            }
        }
        EpisodeLog {
            id,
            kind,
            scene: "kitchen".into(),
            start_ns,
            end_s: seconds - 0.025,
            frames,
        }
    }

    /// `lidar-har alerts` with `line`'s options.
    fn alerts_args(line: &[&str]) -> AlertsArgs {
        #[derive(clap::Parser)]
        struct Command {
            #[command(flatten)]
            args: AlertsArgs,
        }
        let line = ["alerts"].iter().chain(line);
        <Command as clap::Parser>::try_parse_from(line)
            .unwrap()
            .args
    }

    /// A readings file of `episodes`, as `--save-readings` writes it with the default
    /// classifier configuration; returns the file's length after each episode.
    fn write_readings(path: &Path, episodes: &[EpisodeLog]) -> Vec<u64> {
        let schedule = ClassifierConfig::default().lane_schedule(20, false);
        let header = Header::new(
            "m.onnx".into(),
            vec!["kitchen".into()],
            1,
            10.0,
            1.0,
            20,
            schedule,
        );
        let mut writer = ReadingsWriter::create(path, &header).unwrap();
        let mut lengths = Vec::new();
        for episode in episodes {
            writer.write(episode).unwrap();
            lengths.push(std::fs::metadata(path).unwrap().len());
        }
        writer.finish().unwrap();
        lengths
    }

    #[test]
    fn replayed_readings_cut_short_are_scored_up_to_the_cut_and_fail() {
        let dir = tempfile::tempdir().unwrap();
        let whole = dir.path().join("whole.zst");
        let standing = [(Activity::Standing, 10.0)];
        let episodes: Vec<EpisodeLog> = (0..3)
            .map(|id| logged(id, ScriptKind::Everyday, &standing, 10.0))
            .collect();
        let lengths = write_readings(&whole, &episodes);
        let report = dir.path().join("whole.json");
        run(alerts_args(&[
            "--readings",
            &whole.display().to_string(),
            "--out",
            &report.display().to_string(),
        ]))
        .unwrap();
        let text = std::fs::read_to_string(&report).unwrap();
        assert!(!text.contains("cut_short"), "{text}");

        // Stopped while the third episode was being written: two complete ones, then half a line.
        let cut = dir.path().join("cut.zst");
        let bytes = std::fs::read(&whole).unwrap();
        let at = (lengths[1] + lengths[2]) / 2;
        std::fs::write(&cut, &bytes[..at as usize]).unwrap();
        let report = dir.path().join("cut.json");
        let error = run(alerts_args(&[
            "--readings",
            &cut.display().to_string(),
            "--out",
            &report.display().to_string(),
        ]))
        .unwrap_err();
        let error = format!("{error:#}");
        assert!(
            error.contains("cut.zst: line 4: cut short")
                && error.contains("only the 2 complete episodes"),
            "{error}"
        );
        let written: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        assert_eq!(written["cut_short"]["episodes_scored"], 2, "{written}");
        assert!(
            written["cut_short"]["error"]
                .as_str()
                .unwrap()
                .contains("line 4"),
            "{written}"
        );
        assert!((written["no_fall_hours"].as_f64().unwrap() - 20.0 / 3600.0).abs() < 1e-9);
    }

    #[test]
    fn readings_without_an_episode_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let header_only = dir.path().join("header.zst");
        write_readings(&header_only, &[]);
        let error = run(alerts_args(&[
            "--readings",
            &header_only.display().to_string(),
        ]))
        .unwrap_err()
        .to_string();
        assert!(error.contains("header.zst: no episode in it"), "{error}");
    }

    #[test]
    fn episodes_staying_down_without_a_spell_due_fail_the_report() {
        use Activity::*;
        let config = FallAlertConfig::default();
        assert_eq!(config.down_after_s, 15.0);
        let report = |stay_down: &[(Activity, f64)]| {
            let mut tally = Tally::new(config, 1.0);
            tally.add(
                &logged(0, ScriptKind::FallAndStayDown, stay_down, 20.0),
                Vec::new(),
            );
            tally
                .report(String::new(), Vec::new(), 1, 20.0, None)
                .map(|r| r.person_down_due.len())
        };
        // Down from 10 s: due at 25 s, after the end at 20 s (the run-on not counted).
        let late = [(Walking, 10.0), (FallingDown, 1.0), (LyingDown, 12.0)];
        let error = report(&late).unwrap_err().to_string();
        assert!(
            error.contains("--episode-seconds 20") && error.contains("down_after_s (15 s)"),
            "{error}"
        );
        // Down from 3 s: due at 18 s; answered in the run-on or not, it is measured.
        let early = [(Walking, 3.0), (FallingDown, 1.0), (LyingDown, 19.0)];
        assert_eq!(report(&early).unwrap(), 1);
    }

    #[test]
    fn person_down_for_a_spell_due_only_in_the_run_on_is_not_false() {
        use Activity::*;
        let config = FallAlertConfig::default();
        let mut tally = Tally::new(config, 1.0);
        // Down from 3 s: due at 18 s, before the end at 20 s: scored.
        let early = [(Walking, 3.0), (FallingDown, 1.0), (LyingDown, 19.0)];
        tally.add(
            &logged(0, ScriptKind::FallAndStayDown, &early, 20.0),
            vec![alert(AlertKind::PersonDown, 18.5)],
        );
        // Down from 6 s: due at 21 s, in the 3 s run-on; the PERSON_DOWN at 21.5 s is right
        // (the person has been down 15 s), and a second one in that spell is a repeat.
        let late = [(Walking, 6.0), (FallingDown, 1.0), (LyingDown, 16.0)];
        tally.add(
            &logged(1, ScriptKind::FallAndStayDown, &late, 20.0),
            vec![
                alert(AlertKind::PersonDown, 21.5),
                alert(AlertKind::PersonDown, 22.5),
            ],
        );
        // Down from 8 s: due at 23 s, after the run-on's last scan: a PERSON_DOWN at 22 s
        // was not due.
        let early_alert = [(Walking, 8.0), (FallingDown, 1.0), (LyingDown, 14.0)];
        tally.add(
            &logged(2, ScriptKind::FallAndStayDown, &early_alert, 20.0),
            vec![alert(AlertKind::PersonDown, 22.0)],
        );
        let report = tally
            .report(String::new(), Vec::new(), 1, 20.0, None)
            .unwrap();
        // Only the spell due by the end is scored.
        assert_eq!(report.person_down_due.len(), 1);
        assert_eq!(report.person_down_due_alerted, 1);
        // The repeat at 22.5 s counts as one, as in a scored spell, and the early one at 22 s
        // was not due; the PERSON_DOWN at 21.5 s, 15 s after the fall, was.
        assert_eq!(
            report.person_down_not_due_in_fall_episodes, 2,
            "the PERSON_DOWN at 21.5 s, 15 s after the fall, was due"
        );
        assert_eq!(report.repeated_person_down, 1);
    }

    #[test]
    fn person_down_within_the_window_of_due_is_counted_and_printed_apart_from_late_ones() {
        use Activity::*;
        let mut tally = Tally::new(FallAlertConfig::default(), 1.0);
        // Down from 3 s: due at 18 s. Answered 0.5 s and 3 s after (in time), 4 s after
        // (late), and never.
        let stay_down = [(Walking, 3.0), (FallingDown, 1.0), (LyingDown, 26.0)];
        for (id, raised_at_s) in [Some(18.5), Some(21.0), Some(22.0), None]
            .into_iter()
            .enumerate()
        {
            let alerts = raised_at_s.map_or(Vec::new(), |t| vec![alert(AlertKind::PersonDown, t)]);
            tally.add(
                &logged(id, ScriptKind::FallAndStayDown, &stay_down, 30.0),
                alerts,
            );
        }
        let report = tally
            .report(String::new(), Vec::new(), 1, 30.0, None)
            .unwrap();
        assert_eq!(report.person_down_due.len(), 4);
        assert_eq!(report.person_down_due_alerted, 3);
        assert_eq!(report.person_down_due_in_time, 2);
        let line = person_down_due_line(&report);
        assert!(
            line.contains("4 spells, PERSON_DOWN in 3, within 3 s of due in 2, raised after"),
            "{line}"
        );
        let json = serde_json::to_value(&report).unwrap();
        assert_eq!(json["person_down_due_in_time"], 2, "{json}");
        assert_eq!(json["person_down_window_s"], 3.0, "{json}");
    }

    #[test]
    fn replayed_readings_without_a_spell_due_name_the_file_and_ask_for_a_new_recording() {
        use Activity::*;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("short.zst");
        // Down from 5 s in a 10 s episode: due at 20 s, after the run-on.
        let late = [(Walking, 5.0), (FallingDown, 1.0), (LyingDown, 7.0)];
        write_readings(
            &path,
            &[logged(0, ScriptKind::FallAndStayDown, &late, 10.0)],
        );
        let error = run(alerts_args(&["--readings", &path.display().to_string()]))
            .unwrap_err()
            .to_string();
        assert!(
            error.contains(&format!("--readings {}:", path.display()))
                && error.contains("record again with a longer --episode-seconds")
                && error.contains("--fall-alert down_after_s=")
                && !error.contains("give a longer --episode-seconds"),
            "{error}"
        );
        // down_after_s 4 s on replay: due at 9 s, before the end; the report is given.
        run(alerts_args(&[
            "--readings",
            &path.display().to_string(),
            "--fall-alert",
            "down_after_s=4",
        ]))
        .unwrap();
    }

    #[test]
    fn seen_share_counts_the_scans_inside_the_fall() {
        let truth: Vec<(f64, Activity)> = (0..10)
            .map(|k| (k as f64 * 0.1, Activity::FallingDown))
            .collect();
        let seen = [
            true, true, false, false, false, true, true, true, false, false,
        ];
        assert_eq!(seen_share(&truth, &seen, 0.15, 0.45), 0.0);
        assert_eq!(seen_share(&truth, &seen, 0.0, 0.4), 0.5);
        assert_eq!(
            seen_share(&truth, &seen, 5.0, 6.0),
            1.0,
            "no scans: nothing hidden"
        );
    }
}
