//! Localiser accuracy over the simulator's scene set (docs/localiser.md, "Accuracy").
//!
//! Every scene in `--scenes` is simulated in memory with several robot motions (its own, and
//! parked / bounce / coverage where those differ) and `--seeds` seeds each; the real
//! localiser (map subtraction, clustering, tracker) runs on each scan with the odometry and
//! mount the robot would publish, and is scored against the simulator's ground truth with
//! `lidar_har_core::localiser_accuracy` (definitions there). Prints per scene, per activity
//! and overall: position error (median, p95), continuity, visible and in-sight ratios, and
//! the radial bias of the person's points (what `centroid_offset_m` corrects). With
//! `--classifier-config`, the classifier stage runs on the localiser's observations too, and
//! the pelvis the pipeline publishes (/human/pelvis where the pose head placed it, else
//! /human/pose) is scored against the pelvis as well.
//!
//! ```sh
//! cargo run --release -p lidar-har-pipeline --example localiser_accuracy -- --seeds 3 \
//!     [--classifier-config config/classifier.yaml]
//! ```

use std::collections::BTreeMap;
use std::error::Error;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use glam::{DAffine2, DVec2};
use lidar_har_core::activity::Activity;
use lidar_har_core::localiser::{Localiser, LocaliserConfig, LocaliserOutput, Motion, Reference};
use lidar_har_core::localiser_accuracy::{
    AccuracyCriteria, AccuracyReport, AccuracyTally, PointOwners, ReportedPerson, ScanOutcome,
};
use lidar_har_core::scan::Scan;
use lidar_har_core::stats::{Spread, nearest_rank};
use lidar_har_core::sweep::BeamPoses;
use lidar_har_pipeline::classifier::{ClassifierConfig, ClassifierStage, load_classifier_config};
use lidar_har_pipeline::convert::observation_msg;
use lidar_har_pipeline::files::load_localiser_config;
use lidar_har_sim::body::Capsule;
use lidar_har_sim::map::{DEFAULT_RESOLUTION, OccupancyMap as SimMap};
use lidar_har_sim::scene::Motion as RobotMotion;
use lidar_har_sim::{BeamLabel, Scene, Simulator};

/// Issue 4's p95 target for the position error, metres.
const P95_TARGET_M: f64 = 0.30;

#[derive(Parser, Debug)]
#[command(about = "Localiser accuracy over the simulator's scenes")]
struct Args {
    /// Directory of scene files (every *.yaml in it).
    #[arg(long, default_value = "config/scenes")]
    scenes: PathBuf,
    /// Seeds per scene and robot motion.
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Localiser parameters (YAML); default: the built-in defaults (= config/localiser.yaml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Overrides `centroid_offset_m` (for calibration sweeps).
    #[arg(long)]
    centroid_offset: Option<f64>,
    /// Beams on the body for a scan to count as "in sight".
    #[arg(long, default_value_t = AccuracyCriteria::default().min_person_beams)]
    min_person_beams: usize,
    /// Largest distance from the truth at which the track is "on the person" (m).
    #[arg(long, default_value_t = AccuracyCriteria::default().on_person_m)]
    on_person_m: f64,
    /// Simulate Lidars that sweep (`lidar.sweep` in every scene): each beam measured from
    /// where the robot is at its own time, so that `odometry.deskew` (in `--config`) counts.
    #[arg(long)]
    sweep: bool,
    /// Overrides every scene's `lidar.rate_hz` (the RPLIDAR A1 spins at 5-10 Hz, the
    /// scenes' Lidar at 20 Hz: a slower rotation is smeared more by the robot's turns).
    #[arg(long)]
    rate_hz: Option<f64>,
    /// Also print one line per run (scene, motion, seed).
    #[arg(long)]
    per_run: bool,
    /// Print every scan of the runs of this scene (by name) to stderr, for diagnosis.
    #[arg(long)]
    trace: Option<String>,
    /// Write one JSON line per scan in which the person is seen (the run, truths, Lidar
    /// position, report, the person's points, the published pelvis with
    /// --classifier-config) here, for offline study of position estimators.
    #[arg(long)]
    dump_points: Option<PathBuf>,
    /// Also run the classifier stage with this configuration (its model and pose head) and
    /// score the published pelvis: /human/pelvis where placed, else /human/pose.
    #[arg(long)]
    classifier_config: Option<PathBuf>,
    /// Write the per-scene, per-activity and overall figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// Tallies against the two truths, the radial offsets of the person's visible points (truth
/// minus centroid along the line of sight from the Lidar: positive when the truth lies
/// beyond the points) and why in-sight scans were off the person.
#[derive(Default, Clone)]
struct Group {
    /// Against the published ground truth (/ground_truth/human_pose: the pelvis on the floor).
    tally: AccuracyTally,
    /// Against the centre of the body's cut by the scan plane.
    centre_tally: AccuracyTally,
    /// The published pelvis (with `--classifier-config`) against the pelvis.
    published_tally: AccuracyTally,
    /// The same split by whether the localiser saw the person or predicted them through an
    /// occlusion: the two call for different fixes (the pose head, the tracker).
    published_seen_tally: AccuracyTally,
    published_predicted_tally: AccuracyTally,
    /// Each predicted scan with a published pelvis: how long the person had been hidden, its
    /// error, the error on the last scan they were seen (where the prediction starts), and
    /// how far they had truly moved since.
    predicted: Vec<PredictedScan>,
    radial_m: Vec<f64>,
    /// In-sight scans with no person reported.
    missed: u64,
    /// In-sight scans with the person reported farther than `FAR_M` from the body centre.
    far: u64,
    /// Scans with a pelvis placed, and of them those whose error lies within the 1- and
    /// 2-sigma ellipses of its published covariance.
    pelvis_calibration: [u64; 3],
}

#[derive(Clone, Copy)]
struct PredictedScan {
    unseen_s: f64,
    error_m: f64,
    last_seen_error_m: f64,
    moved_m: f64,
}

/// A reported person this far from the body centre is on something else.
const FAR_M: f64 = 1.5;

impl Group {
    fn merge(&mut self, other: &Group) {
        self.tally.merge(&other.tally);
        self.centre_tally.merge(&other.centre_tally);
        self.published_tally.merge(&other.published_tally);
        self.published_seen_tally.merge(&other.published_seen_tally);
        self.published_predicted_tally
            .merge(&other.published_predicted_tally);
        self.predicted.extend_from_slice(&other.predicted);
        self.radial_m.extend_from_slice(&other.radial_m);
        self.missed += other.missed;
        self.far += other.far;
        for (sum, add) in self
            .pelvis_calibration
            .iter_mut()
            .zip(other.pelvis_calibration)
        {
            *sum += add;
        }
    }

    fn radial_median(&self) -> Option<f64> {
        let mut v = self.radial_m.clone();
        v.sort_by(f64::total_cmp);
        nearest_rank(&v, 0.5)
    }
}

#[derive(serde::Serialize)]
struct Row {
    name: String,
    /// Against /ground_truth/human_pose (the pelvis).
    pelvis: AccuracyReport,
    /// Against the centre of the body's cut by the scan plane.
    body_centre: AccuracyReport,
    /// The published pelvis (with `--classifier-config`) against the pelvis.
    pelvis_published: Option<AccuracyReport>,
    radial_bias_median_m: Option<f64>,
    in_sight_missed: u64,
    in_sight_far: u64,
}

fn main() -> std::process::ExitCode {
    match measure(Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("localiser_accuracy: error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn measure(args: Args) -> Result<(), Box<dyn Error>> {
    if args.seeds == 0 {
        return Err("--seeds 0: nothing to measure (give at least 1)".into());
    }
    let mut config = match &args.config {
        Some(path) => load_localiser_config(path)?,
        None => LocaliserConfig::default(),
    };
    if let Some(offset) = args.centroid_offset {
        config.centroid_offset_m = offset;
    }
    config.validate()?;
    let criteria = AccuracyCriteria {
        min_person_beams: args.min_person_beams,
        on_person_m: args.on_person_m,
    };
    let classifier = args
        .classifier_config
        .as_deref()
        .map(load_classifier_config)
        .transpose()?;

    let mut paths: Vec<PathBuf> = std::fs::read_dir(&args.scenes)
        .map_err(|e| format!("scenes directory {}: {e}", args.scenes.display()))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .collect();
    paths.sort();
    if paths.is_empty() {
        return Err(format!("no *.yaml scenes in {}", args.scenes.display()).into());
    }
    let scenes = paths
        .iter()
        .map(|path| Ok((path, Scene::load(path)?)))
        .collect::<Result<Vec<_>, Box<dyn Error>>>()?;
    if let Some(name) = &args.trace
        && !scenes.iter().any(|(_, scene)| &scene.name == name)
    {
        let names: Vec<&str> = scenes.iter().map(|(_, s)| s.name.as_str()).collect();
        return Err(format!(
            "--trace {name}: no such scene (there are {})",
            names.join(", ")
        )
        .into());
    }

    let mut dump = match &args.dump_points {
        Some(path) => {
            // `out/` (the docs' folder) is not in a fresh checkout.
            if let Some(folder) = path.parent().filter(|f| !f.as_os_str().is_empty()) {
                std::fs::create_dir_all(folder)
                    .map_err(|e| format!("{}: {e}", folder.display()))?;
            }
            Some(BufWriter::new(
                File::create(path).map_err(|e| format!("{}: {e}", path.display()))?,
            ))
        }
        None => None,
    };
    let started = Instant::now();
    let mut by_scene: BTreeMap<String, Group> = BTreeMap::new();
    let mut by_activity: BTreeMap<usize, Group> = BTreeMap::new();
    let mut by_motion: BTreeMap<&'static str, Group> = BTreeMap::new();
    let mut runs = 0;
    let mut skipped = 0;
    for (path, scene) in &scenes {
        for (index, (motion_name, motion)) in motions(&scene.robot.motion).into_iter().enumerate() {
            let mut variant = scene.clone();
            variant.robot.motion = motion;
            variant.lidar.sweep |= args.sweep;
            variant.lidar.rate_hz = args.rate_hz.unwrap_or(variant.lidar.rate_hz);
            for seed in 0..args.seeds {
                let sim = match Simulator::new(variant.clone(), seed) {
                    Ok(sim) => sim,
                    Err(e) => {
                        let failure = format!("{} with {motion_name} robot: {e}", path.display());
                        // The scene's own motion (first) must run; one borrowed from another
                        // scene may not fit this room (a coverage path through a narrow gap).
                        if index == 0 {
                            return Err(failure.into());
                        }
                        eprintln!("skipped: {failure}");
                        skipped += 1;
                        continue;
                    }
                };
                let mut run_activity: BTreeMap<usize, Group> = BTreeMap::new();
                let run_name = format!("{} {motion_name} {seed}", scene.name);
                let trace = args.trace.as_deref() == Some(scene.name.as_str());
                run_scene(
                    sim,
                    &config,
                    classifier.as_ref(),
                    &criteria,
                    trace,
                    dump.as_mut().map(|out| (out, run_name.clone())),
                    &mut run_activity,
                )?;
                runs += 1;
                let mut run = Group::default();
                for (activity, group) in &run_activity {
                    run.merge(group);
                    by_activity.entry(*activity).or_default().merge(group);
                }
                if args.per_run {
                    print_row(&run_name, &run);
                }
                by_scene.entry(scene.name.clone()).or_default().merge(&run);
                by_motion.entry(motion_name).or_default().merge(&run);
            }
        }
    }
    if let Some(out) = dump.as_mut() {
        out.flush()?;
    }
    let mut overall = Group::default();
    for group in by_scene.values() {
        overall.merge(group);
    }

    println!(
        "{runs} runs ({} scenes x robot motions x {} seeds; {skipped} skipped) in {:.1} s; in \
         sight: >= {} beams on the body; on the person: within {} m; centroid_offset_m = {}",
        paths.len(),
        args.seeds,
        started.elapsed().as_secs_f64(),
        criteria.min_person_beams,
        criteria.on_person_m,
        config.centroid_offset_m
    );
    println!(
        "columns: scans; % in sight; % seen | error (m) median, p95, % continuity against \
         /ground_truth/human_pose (the pelvis) | the same against the centre of the body's cut \
         by the scan plane | % identity continuity (a seen track on the person's own returns, \
         by the simulator's beam labels; a predicted one within {} m of the body centre) | \
         radial bias (m) | % of in-sight scans with no person reported, \
         with the person reported > {FAR_M} m away | error (m) median, p95 of the published \
         pelvis (/human/pelvis, else /human/pose; with --classifier-config)",
        criteria.on_person_m
    );
    print_header("scene");
    for (name, group) in &by_scene {
        print_row(name, group);
    }
    print_row("overall", &overall);
    print_header("robot motion");
    for (name, group) in &by_motion {
        print_row(name, group);
    }
    print_header("activity");
    for (index, group) in &by_activity {
        print_row(activity_name(*index), group);
    }
    let [placed, within_1, within_2] = overall.pelvis_calibration;
    if placed > 0 {
        let share = |n: u64| 100.0 * n as f64 / placed as f64;
        println!(
            "\n/human/pelvis placed on {placed} scans; its error within the 1 / 2-sigma ellipse of \
             its covariance on {:.1} / {:.1} % of them (39.3 / 86.5 % if calibrated)",
            share(within_1),
            share(within_2)
        );
    }
    if classifier.is_some() {
        let part = |tally: &AccuracyTally| {
            let r = tally.report();
            let m = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.3}"));
            format!(
                "median {} m, p95 {} m over {} scans",
                m(r.error_median_m),
                m(r.error_p95_m),
                r.scans
            )
        };
        println!(
            "published pelvis where the person was seen: {}; predicted through an occlusion: {}",
            part(&overall.published_seen_tally),
            part(&overall.published_predicted_tally)
        );
        let scored = overall.published_tally.scored();
        if scored > 0 {
            let share = |tally: &AccuracyTally| {
                100.0 * tally.errors_above(P95_TARGET_M) as f64 / scored as f64
            };
            println!(
                "published pelvis more than {P95_TARGET_M} m off (the p95 target allows 5 % of \
                 scans): {:.1} % of all scans where seen, {:.1} % where predicted; by activity \
                 (seen + predicted):",
                share(&overall.published_seen_tally),
                share(&overall.published_predicted_tally)
            );
            for (index, group) in &by_activity {
                println!(
                    "  {:20} {:4.1} + {:4.1} %",
                    activity_name(*index),
                    share(&group.published_seen_tally),
                    share(&group.published_predicted_tally)
                );
            }
        }
        print_predicted(&overall.predicted);
    }

    if let Some(path) = &args.json {
        let rows = |groups: Vec<(String, &Group)>| -> Vec<Row> {
            groups
                .into_iter()
                .map(|(name, g)| Row {
                    name,
                    pelvis: g.tally.report(),
                    body_centre: g.centre_tally.report(),
                    pelvis_published: classifier.is_some().then(|| g.published_tally.report()),
                    radial_bias_median_m: g.radial_median(),
                    in_sight_missed: g.missed,
                    in_sight_far: g.far,
                })
                .collect()
        };
        let json = serde_json::json!({
            "seeds": args.seeds,
            "runs": runs,
            "criteria": criteria,
            "centroid_offset_m": config.centroid_offset_m,
            "overall": rows(vec![("overall".into(), &overall)]),
            "scenes": rows(by_scene.iter().map(|(n, g)| (n.clone(), g)).collect()),
            "motions": rows(by_motion.iter().map(|(n, g)| (n.to_string(), g)).collect()),
            "activities": rows(by_activity.iter().map(|(i, g)| (activity_name(*i).to_string(), g)).collect()),
            "pelvis_calibration": {
                "placed": placed, "within_1_sigma": within_1, "within_2_sigma": within_2,
            },
        });
        std::fs::write(path, serde_json::to_string_pretty(&json)?)
            .map_err(|e| format!("{}: {e}", path.display()))?;
    }
    Ok(())
}

/// The predicted scans by how long the person had been hidden: the error then, on the last
/// scan they were seen, and how far they had truly moved (median / p95, m).
fn print_predicted(scans: &[PredictedScan]) {
    println!("predicted scans by time hidden: error | error when last seen | truly moved since");
    for (from, to) in [(0.0, 0.25), (0.25, 0.5), (0.5, 1.0), (1.0, f64::INFINITY)] {
        let bin: Vec<&PredictedScan> = scans
            .iter()
            .filter(|p| (from..to).contains(&p.unseen_s))
            .collect();
        let spread = |value: fn(&PredictedScan) -> f64| {
            Spread::of(bin.iter().map(|&p| value(p)).collect())
                .map_or("-".into(), |s| format!("{:.2} / {:.2}", s.median, s.p95))
        };
        println!(
            "  {from:.2}-{to:.2} s, {:5} scans: {} | {} | {}",
            bin.len(),
            spread(|p| p.error_m),
            spread(|p| p.last_seen_error_m),
            spread(|p| p.moved_m)
        );
    }
}

/// The scene's own robot motion, then parked, bounce and coverage where they differ from it.
fn motions(own: &RobotMotion) -> Vec<(&'static str, RobotMotion)> {
    let kind = |m: &RobotMotion| match m {
        RobotMotion::Static => "parked",
        RobotMotion::Waypoints { .. } => "waypoints",
        RobotMotion::Coverage { .. } => "coverage",
        RobotMotion::Bounce { .. } => "bounce",
    };
    let mut list = vec![(kind(own), own.clone())];
    for m in [
        RobotMotion::Static,
        RobotMotion::Bounce { runs: 64 },
        RobotMotion::Coverage {
            spacing: 0.35,
            along_y: false,
        },
    ] {
        if kind(&m) != kind(own) {
            list.push((kind(&m), m));
        }
    }
    list
}

/// Runs the localiser over one simulation, adding each scan to its activity's group.
fn run_scene(
    mut sim: Simulator,
    config: &LocaliserConfig,
    classifier: Option<&ClassifierConfig>,
    criteria: &AccuracyCriteria,
    trace: bool,
    mut dump: Option<(&mut BufWriter<File>, String)>,
    by_activity: &mut BTreeMap<usize, Group>,
) -> Result<(), Box<dyn Error>> {
    let map = SimMap::from_world(sim.world(), DEFAULT_RESOLUTION).to_localiser_map()?;
    let config = LocaliserConfig {
        mount: sim.lidar_mount(),
        ..config.clone()
    };
    let mut localiser = Localiser::new(config, Reference::Map(map), Motion::Odometry)?;
    let mut stage = classifier
        .map(|c| ClassifierStage::load(c, None))
        .transpose()?;
    let geometry = sim.scan_geometry();
    let plane_height = sim.scene().robot.lidar_height;
    // The truth and the published error on the last scan the person was seen.
    let mut last_seen: Option<(DVec2, f64)> = None;
    while let Some(frame) = sim.step() {
        let stamp = frame.stamp_ns as i64;
        localiser.add_odometry(stamp, frame.robot);
        let person_beams = frame
            .labels
            .iter()
            .filter(|&&l| l == BeamLabel::Person)
            .count();
        let scan = Scan {
            stamp_ns: stamp,
            angle_min: geometry.angle_min as f32,
            angle_increment: geometry.angle_increment as f32,
            time_increment: geometry.time_increment as f32,
            range_min: geometry.range_min as f32,
            range_max: geometry.range_max as f32,
            ranges: frame.ranges,
        };
        let result = localiser.process_scan(&scan);
        let estimate = result.output.as_ref().and_then(|o| o.person.as_ref());
        let truth = frame.person.map(|p| p.pose.position());
        let activity = frame.person.map_or(0, |p| p.activity.index());
        let centre = frame
            .person
            .and_then(|p| plane_centre(&p.parts, plane_height))
            .or(truth);
        if trace && let (Some(output), Some(person)) = (&result.output, frame.person) {
            let reported = output.person.as_ref();
            let fmt = |p: DVec2| format!("({:.2}, {:.2})", p.x, p.y);
            let clusters: Vec<String> = localiser
                .clusters()
                .iter()
                .map(|c| format!("{}:{}:{:.2}", fmt(c.centroid), c.points.len(), c.extent_m))
                .collect();
            eprintln!(
                "{} t={:.2} truth={} centre={} laser={} {} beams={person_beams} clusters=[{}] \
                 reported={}",
                sim.scene().name,
                frame.index as f64 / sim.scene().lidar.rate_hz,
                fmt(person.pose.position()),
                centre.map_or("-".into(), fmt),
                fmt(frame.laser.position()),
                person.activity,
                clusters.join(" "),
                reported.map_or("none".into(), |e| format!(
                    "id={} pos={} vis={} vel={} pts={} err={:.2}",
                    e.track_id,
                    fmt(e.position),
                    e.visible,
                    fmt(e.velocity),
                    e.points.len(),
                    centre.map_or(f64::NAN, |c| c.distance(e.position))
                )),
            );
        }
        let pelvis = match (&mut stage, &result.output, estimate) {
            (Some(stage), Some(output), Some(person)) => {
                stage
                    .on_observation(&observation_msg(output, person, "map"))?
                    .pelvis
            }
            _ => None,
        };
        let group = by_activity.entry(activity).or_default();
        if let (Some(pelvis), Some(truth)) = (pelvis, truth) {
            let d2 = mahalanobis_squared(truth - pelvis.position, pelvis.covariance);
            group.pelvis_calibration[0] += 1;
            group.pelvis_calibration[1] += u64::from(d2 <= 1.0);
            group.pelvis_calibration[2] += u64::from(d2 <= 4.0);
        }
        let pelvis = pelvis.map(|p| p.position);
        if let (Some((out, run)), Some(e), Some(person), Some(c)) =
            (dump.as_mut(), estimate, frame.person, centre)
            && e.visible
        {
            let points: Vec<[f64; 2]> = e.points.iter().map(|p| [p.x, p.y]).collect();
            let line = serde_json::json!({
                "run": run, "stamp_ns": stamp,
                "scene": sim.scene().name, "activity": person.activity.to_string(),
                "pelvis": [person.pose.x, person.pose.y, person.pose.theta],
                "centre": [c.x, c.y], "laser": [frame.laser.x, frame.laser.y],
                "reported": [e.position.x, e.position.y], "velocity": [e.velocity.x, e.velocity.y],
                "person_beams": person_beams, "points": points,
                "published": pelvis.map(|p| [p.x, p.y]),
            });
            writeln!(out, "{line}")?;
        }
        let reported = estimate.map(|e| ReportedPerson {
            position: e.position,
            visible: e.visible,
            points: result
                .output
                .as_ref()
                .map(|o| point_owners(&scan, &frame.labels, o, &e.points)),
        });
        group.tally.add(
            &ScanOutcome {
                truth,
                person_beams,
                reported,
            },
            criteria,
        );
        group.centre_tally.add(
            &ScanOutcome {
                truth: centre,
                person_beams,
                reported,
            },
            criteria,
        );
        if stage.is_some() {
            let published = reported.map(|r| ReportedPerson {
                position: pelvis.unwrap_or(r.position),
                ..r
            });
            let outcome = ScanOutcome {
                truth,
                person_beams,
                reported: published,
            };
            group.published_tally.add(&outcome, criteria);
            match published {
                Some(p) if p.visible => group.published_seen_tally.add(&outcome, criteria),
                Some(_) => group.published_predicted_tally.add(&outcome, criteria),
                None => {}
            }
            if let (Some(p), Some(truth), Some(e)) = (published, truth, estimate) {
                let error_m = p.position.distance(truth);
                if p.visible {
                    last_seen = Some((truth, error_m));
                } else if let Some((seen_at, last_seen_error_m)) = last_seen {
                    group.predicted.push(PredictedScan {
                        unseen_s: e.unseen_s,
                        error_m,
                        last_seen_error_m,
                        moved_m: seen_at.distance(truth),
                    });
                }
            }
        }
        if let Some(centre) = centre
            && person_beams >= criteria.min_person_beams
        {
            match reported {
                None => group.missed += 1,
                Some(r) if r.position.distance(centre) > FAR_M => group.far += 1,
                Some(_) => {}
            }
        }
        if let (Some(e), Some(truth)) = (estimate, truth)
            && e.visible
            && !e.points.is_empty()
        {
            let centroid = e.points.iter().copied().sum::<DVec2>() / e.points.len() as f64;
            let sight = (centroid - frame.laser.position()).normalize_or_zero();
            if centroid.distance(truth) <= criteria.on_person_m {
                group.radial_m.push((truth - centroid).dot(sight));
            }
        }
    }
    Ok(())
}

/// `e` Σ⁻¹ `e` for a 2 x 2 covariance Σ: at most k² within its k-sigma ellipse (39 % of a
/// Gaussian's draws at k = 1, 86 % at k = 2).
fn mahalanobis_squared(e: DVec2, c: [[f64; 2]; 2]) -> f64 {
    let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
    (e.x * e.x * c[1][1] - e.x * e.y * (c[0][1] + c[1][0]) + e.y * e.y * c[0][0]) / det
}

/// How many of `taken` (map-frame points the localiser took for the person) are returns the
/// simulator labelled as the person's: the same beams moved by the same poses give the same
/// points, to rounding.
fn point_owners(
    scan: &Scan,
    labels: &[BeamLabel],
    output: &LocaliserOutput,
    taken: &[DVec2],
) -> PointOwners {
    let beams = scan.ranges.len();
    let beam_poses: Vec<DAffine2> =
        BeamPoses::sweep(output.laser_pose, output.last_beam_pose, beams).collect();
    let person: Vec<DVec2> = scan
        .points()
        .filter(|p| labels.get(p.beam) == Some(&BeamLabel::Person))
        .map(|p| beam_poses[p.beam].transform_point2(p.point))
        .collect();
    const SAME_POINT_M2: f64 = 1e-6;
    let from_person = taken
        .iter()
        .filter(|t| {
            person
                .iter()
                .any(|p| p.distance_squared(**t) < SAME_POINT_M2)
        })
        .count();
    PointOwners {
        from_person,
        total: taken.len(),
    }
}

/// Centre of the body's cut by the plane `z = height`: capsule axes sampled every ~2 cm,
/// each sample inside the plane's reach weighted by the half-width of its cut there.
fn plane_centre(parts: &[Capsule], height: f64) -> Option<DVec2> {
    let (mut sum, mut weight) = (DVec2::ZERO, 0.0);
    for part in parts {
        let samples = ((part.a.distance(part.b) / 0.02).ceil() as usize).max(1);
        for k in 0..=samples {
            let p = part.a.lerp(part.b, k as f64 / samples as f64);
            let dz = p.z - height;
            if dz.abs() < part.radius {
                let w = (part.radius * part.radius - dz * dz).sqrt();
                sum += w * p.truncate();
                weight += w;
            }
        }
    }
    (weight > 0.0).then(|| sum / weight)
}

fn activity_name(index: usize) -> &'static str {
    Activity::from_index(index).map_or("?", Activity::label)
}

fn print_header(what: &str) {
    println!(
        "\n{what:<20} {:>6} {:>6} {:>6} | {:>6} {:>6} {:>6} | {:>6} {:>6} {:>6} | {:>6} | {:>6} {:>5} {:>5} | {:>6} {:>6}",
        "scans",
        "insght",
        "seen",
        "median",
        "p95",
        "contin",
        "median",
        "p95",
        "contin",
        "ident",
        "radial",
        "miss",
        "far",
        "pubmed",
        "pubp95"
    );
}

fn print_row(name: &str, group: &Group) {
    let (r, c, p) = (
        group.tally.report(),
        group.centre_tally.report(),
        group.published_tally.report(),
    );
    let pct = |v: Option<f64>| v.map_or("-".into(), |v| format!("{:.1}", 100.0 * v));
    let m = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.3}"));
    let share = |n: u64| pct((r.in_sight_scans > 0).then(|| n as f64 / r.in_sight_scans as f64));
    println!(
        "{name:<20} {:>6} {:>6} {:>6} | {:>6} {:>6} {:>6} | {:>6} {:>6} {:>6} | {:>6} | {:>6} {:>5} {:>5} | {:>6} {:>6}",
        r.scans,
        pct(r.in_sight_ratio),
        pct(r.visible_ratio),
        m(r.error_median_m),
        m(r.error_p95_m),
        pct(r.continuity),
        m(c.error_median_m),
        m(c.error_p95_m),
        pct(c.continuity),
        pct(c.identity_continuity),
        m(group.radial_median()),
        share(group.missed),
        share(group.far),
        m(p.error_median_m),
        m(p.error_p95_m),
    );
}
