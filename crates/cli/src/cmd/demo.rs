//! `lidar-har demo`: the product in one command. Simulates a scene with a fall, runs the
//! whole pipeline (localiser, classifier, fall alerts) over the recording, prints a timeline
//! of recognised activities (with the ground truth) and the alerts, and writes the bags and
//! two pictures. It needs a trained model: without one it stops and says so, it never fakes
//! results.

use std::path::{Path, PathBuf};

use anyhow::Context;
use lidar_har_core::activity::Activity;
use lidar_har_pipeline::bag_run::{RunOptions, RunSummary, run_bag};
use lidar_har_pipeline::classifier::{ActivitySummary, AlertRecord, ClassifierRun, Segment};
use lidar_har_sim::map::OccupancyMap;
use lidar_har_sim::record::record;
use lidar_har_sim::render::{ACTIVITY_COLOURS, Trace, font, render_png};
use lidar_har_sim::{Scene, Simulator};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

#[derive(clap::Args)]
pub struct DemoArgs {
    /// Scene to simulate (YAML, see docs/simulator.md); the default one contains a fall.
    #[arg(long, default_value = "config/scenes/living_room.yaml")]
    pub scene: PathBuf,
    /// Output directory (made if missing): sim/ (the simulated bag), run/ (the pipeline's
    /// bag and summary.json), scene.png, timeline.png, .lidar_har_demo. An earlier demo's
    /// output there is replaced; a folder holding anything else is refused.
    #[arg(long, default_value = "demo_out")]
    pub out: PathBuf,
    /// Mixed with the scene's seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The activity model (ONNX step model, see docs/model_contract.md) [default: the
    /// classifier configuration's `model`, models/activity.onnx].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Classifier parameters (YAML, see config/classifier.yaml); defaults when absent.
    #[arg(long)]
    pub classifier_config: Option<PathBuf>,
}

/// What the demo writes into `--out`: two folders and two pictures, and a mark that says
/// the folder is a demo's.
const SIM_DIR: &str = "sim";
const RUN_DIR: &str = "run";
const SCENE_PNG: &str = "scene.png";
const TIMELINE_PNG: &str = "timeline.png";
const DEMO_MARK: &str = ".lidar_har_demo";
/// What the demo writes inside its folders: the simulator's bag and map in sim/,
/// `lidar-har run`'s bag and summary in run/ (a bag's storage file is named after its folder).
const SIM_FILES: [&str; 4] = ["metadata.yaml", "sim_0.mcap", "map.pgm", "map.yaml"];
const RUN_FILES: [&str; 3] = ["metadata.yaml", "run_0.mcap", "summary.json"];

/// The entries of `out` an earlier demo left, for a new run to replace: only in a folder the
/// demo marked as its own, and only its folders, holding only its files, and its pictures
/// (by name and kind). Otherwise an error naming what is in the way, so that nothing but a
/// demo's output is ever deleted. Nothing when `out` does not exist or is empty.
fn earlier_demo_output(out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let listing = || format!("--out {}: cannot list it", out.display());
    let entries = match std::fs::read_dir(out) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        listed => listed.with_context(listing)?,
    };
    let mut earlier = Vec::new();
    for entry in entries {
        let entry = entry.with_context(listing)?;
        // Not followed: a link, even to a folder of the right name, is not the demo's.
        let kind = entry.file_type().with_context(listing)?;
        let name = entry.file_name();
        let demos = if kind.is_dir() {
            name == SIM_DIR || name == RUN_DIR
        } else {
            kind.is_file() && (name == SCENE_PNG || name == TIMELINE_PNG || name == DEMO_MARK)
        };
        anyhow::ensure!(demos, not_the_demos(out, Path::new(&name)));
        if name == SIM_DIR {
            ensure_only_demo_files(out, SIM_DIR, &SIM_FILES)?;
        } else if name == RUN_DIR {
            ensure_only_demo_files(out, RUN_DIR, &RUN_FILES)?;
        }
        earlier.push(entry.path());
    }
    anyhow::ensure!(
        earlier.is_empty() || out.join(DEMO_MARK).is_file(),
        "--out {} already exists and was not written by the demo (no {DEMO_MARK} in it): \
         choose another or delete it",
        out.display()
    );
    earlier.sort();
    Ok(earlier)
}

/// Checks that the demo's folder `folder` of `out` holds nothing but plain files named as
/// in `files`: it is deleted whole when replaced.
fn ensure_only_demo_files(out: &Path, folder: &str, files: &[&str]) -> anyhow::Result<()> {
    let listing = || format!("--out {}: cannot list {folder}", out.display());
    for entry in std::fs::read_dir(out.join(folder)).with_context(listing)? {
        let entry = entry.with_context(listing)?;
        let name = entry.file_name();
        let demos = entry.file_type().with_context(listing)?.is_file()
            && files.iter().any(|file| name == *file);
        anyhow::ensure!(demos, not_the_demos(out, &Path::new(folder).join(&name)));
    }
    Ok(())
}

/// The refusal of an `out` that holds `entry` (relative to it), not the demo's.
fn not_the_demos(out: &Path, entry: &Path) -> String {
    format!(
        "--out {} already exists and holds {}, which is not an earlier demo's output: \
         choose another or delete it",
        out.display(),
        entry.display()
    )
}

pub fn run(args: DemoArgs) -> anyhow::Result<()> {
    let _ = env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn"))
        .try_init();
    let config =
        super::classifier_config(args.classifier_config.as_deref(), args.model.as_deref())?;
    anyhow::ensure!(
        config.model.is_file(),
        "no activity model at {}: the demo needs a trained model and does not fake results. \
         Train one (training/, see docs/classifier.md) or pass --model FILE",
        super::shown_path(&config.model)
    );
    // Load once now, so a broken model or a missing ONNX Runtime stops us before simulating.
    drop(
        ClassifierRun::load(&config)
            .with_context(|| format!("loading {}", config.model.display()))?,
    );
    // The scene too, so that a bad one leaves an earlier demo's output in place.
    let scene = Scene::load(&args.scene)?;
    let mut sim = Simulator::new(scene, args.seed)
        .with_context(|| format!("scene {}", args.scene.display()))?;
    anyhow::ensure!(
        !args.out.exists() || args.out.is_dir(),
        "--out {} is a file: give a folder (made if missing)",
        args.out.display()
    );
    let earlier = earlier_demo_output(&args.out)?;
    if !earlier.is_empty() {
        errln!(
            "replacing the earlier demo output in {}",
            args.out.display()
        );
    }
    for path in earlier {
        if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        }
        .with_context(|| format!("removing the earlier demo output {}", path.display()))?;
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let mark = args.out.join(DEMO_MARK);
    std::fs::write(
        &mark,
        "Written by `lidar-har demo`: run again, it replaces sim/, run/, scene.png and \
         timeline.png here.\n",
    )
    .with_context(|| format!("writing {}", mark.display()))?;

    // 1. Simulate.
    let geometry = sim.scan_geometry();
    let start_s = sim.start_ns() as f64 * 1e-9;
    let mut trace = Trace::new((sim.frame_count() / 40).max(1));
    let mut truth: Vec<(f64, Activity)> = Vec::new();
    let sim_dir = args.out.join(SIM_DIR);
    errln!(
        "simulating {} ({} scans) ...",
        args.scene.display(),
        sim.frame_count()
    );
    record(
        &mut sim,
        &sim_dir,
        lidar_har_sim::map::DEFAULT_RESOLUTION,
        |frame| {
            trace.add(frame, &geometry);
            if let Some(p) = &frame.person {
                truth.push((frame.stamp_ns as f64 * 1e-9 - start_s, p.activity));
            }
        },
    )
    .with_context(|| format!("recording {}", sim_dir.display()))?;

    // 2. Run the pipeline over the recording, as `lidar-har run` does.
    errln!("running the pipeline ...");
    let run_dir = args.out.join(RUN_DIR);
    let summary = run_bag(
        &sim_dir,
        &run_dir,
        RunOptions {
            classifier: Some(config),
            ..RunOptions::default()
        },
    )
    .with_context(|| format!("running the pipeline over {}", sim_dir.display()))?;
    let activity = summary
        .activity
        .as_ref()
        .context("the run produced no activity results")?;

    // 3. Report.
    out!("{}", timeline_text(activity, start_s));
    out!("{}", position_text(&summary));
    let map = OccupancyMap::from_world(sim.world(), lidar_har_sim::map::DEFAULT_RESOLUTION);
    let scene_png = args.out.join(SCENE_PNG);
    render_png(&scene_png, &map, &trace)?;
    mark_alerts(&scene_png, &map, activity)
        .with_context(|| format!("marking alerts on {}", scene_png.display()))?;
    let timeline_png = args.out.join(TIMELINE_PNG);
    draw_timeline(
        &timeline_png,
        &activity.segments,
        &activity.alerts,
        &truth,
        start_s,
    )
    .with_context(|| format!("drawing {}", timeline_png.display()))?;
    outln!();
    outln!("simulated bag:  {}", sim_dir.display());
    outln!("pipeline bag:   {} (summary.json in it)", run_dir.display());
    outln!(
        "pictures:       {} (top view, alerts ringed in red), {}",
        scene_png.display(),
        timeline_png.display()
    );
    Ok(())
}

/// The printed timeline: activity segments (time from the start of the recording), then alerts.
fn timeline_text(activity: &ActivitySummary, start_s: f64) -> String {
    let mut s = String::from("\nActivities (recognised; ground truth where it differs)\n");
    for seg in &activity.segments {
        let truth = match seg.truth {
            Some(t) if t == seg.activity => String::from("  ok"),
            Some(t) => format!("  truth: {t}"),
            None => String::new(),
        };
        s += &format!(
            "  {:6.2} - {:6.2} s  {:<20} {:>4.0} %{}\n",
            seg.start_s - start_s,
            seg.end_s - start_s,
            seg.activity.label(),
            seg.mean_confidence * 100.0,
            truth
        );
    }
    s += "\nAlerts\n";
    if activity.alerts.is_empty() {
        s += "  none\n";
    }
    for a in &activity.alerts {
        s += &format!(
            "  {:6.2} s  {:<14} at ({:.2}, {:.2}) m, confidence {:.0} %, since {:.2} s\n",
            a.time_s - start_s,
            a.kind,
            a.position[0],
            a.position[1],
            a.confidence * 100.0,
            a.event_time_s - start_s
        );
    }
    if let (Some(acc), Some(f1)) = (activity.accuracy, activity.macro_f1) {
        s += &format!(
            "\nAccuracy {:.1} %, macro F1 {:.1} % over {} classified scans (against the simulator's ground truth)\n",
            acc * 100.0,
            f1 * 100.0,
            activity.scans_classified
        );
    }
    s
}

/// Where the pipeline placed the person against the simulator's pelvis: /human/pose, and with
/// /human/pelvis where the pose head placed it.
fn position_text(summary: &RunSummary) -> String {
    let Some(pose) = &summary.position_error_m else {
        return String::new();
    };
    let mut s = format!(
        "Position against the simulator's pelvis: /human/pose median {:.2} m, p95 {:.2} m",
        pose.median, pose.p95
    );
    match &summary.pelvis_error_m {
        Some(pelvis) => {
            s += &format!(
                "; with /human/pelvis where placed median {:.2} m, p95 {:.2} m\n",
                pelvis.median, pelvis.p95
            )
        }
        None => s += "\n",
    }
    s
}

/// Rings each alert's position in red on the simulator's top view. The pixel mapping follows
/// the picture's own size: the map spans the full width, and the legend strip lies below.
fn mark_alerts(png: &Path, map: &OccupancyMap, activity: &ActivitySummary) -> anyhow::Result<()> {
    if activity.alerts.is_empty() {
        return Ok(());
    }
    let mut img = image::open(png)?.to_rgb8();
    let w_m = map.width as f64 * map.resolution;
    let h_m = map.height as f64 * map.resolution;
    let scale = img.width() as f64 / w_m;
    let map_h = (h_m * scale).ceil();
    for a in &activity.alerts {
        let cx = (a.position[0] - map.origin.x) * scale;
        let cy = map_h - (a.position[1] - map.origin.y) * scale;
        let radius = 0.35 * scale;
        for k in 0..720 {
            let angle = k as f64 * std::f64::consts::TAU / 720.0;
            for r in [radius, radius + 1.0, radius + 2.0] {
                let (x, y) = (cx + r * angle.cos(), cy + r * angle.sin());
                if x >= 0.0 && y >= 0.0 && (x as u32) < img.width() && (y as u32) < img.height() {
                    img.put_pixel(x as u32, y as u32, image::Rgb([255, 0, 0]));
                }
            }
        }
    }
    img.save(png)?;
    Ok(())
}

/// The timeline picture's layout: a key line, a band for the alerts' names, one row per class
/// (its name in the column on the left), and the time axis below.
const TIMELINE_WIDTH: u32 = 1400;
const TIMELINE_ROW: i32 = 30;
/// The column of class names, left of the rows.
const TIMELINE_NAMES: i32 = 160;
const TIMELINE_RIGHT: i32 = 30;
const TIMELINE_KEY: i32 = 24;
const TIMELINE_ALERTS: i32 = 36;
const TIMELINE_ROWS_TOP: i32 = TIMELINE_KEY + TIMELINE_ALERTS;
const TIMELINE_ROWS_BOTTOM: i32 = TIMELINE_ROWS_TOP + TIMELINE_ROW * Activity::COUNT as i32;
const TIMELINE_AXIS: i32 = 44;
const TIMELINE_FONT: f64 = 13.0;
const TIMELINE_KEY_TEXT: &str = "bars: recognised (pipeline)    black line: ground truth \
     (simulator)    red line: alert raised    thin dark red line: when its event began";

/// Seconds to pixels across the rows of a timeline `end_s` seconds long.
struct TimeAxis {
    end_s: f64,
}

impl TimeAxis {
    fn x(&self, t: f64) -> i32 {
        let span = f64::from(TIMELINE_WIDTH) - f64::from(TIMELINE_NAMES + TIMELINE_RIGHT);
        TIMELINE_NAMES + (t / self.end_s * span).round() as i32
    }

    /// Seconds between labelled ticks: the first of 1, 2, 5, 10 .. s that gives at most 15.
    fn label_step_s(&self) -> f64 {
        [
            1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1200.0, 1800.0,
        ]
        .into_iter()
        .find(|step| self.end_s / step <= 15.0)
        .unwrap_or(3600.0 * (self.end_s / 3600.0 / 15.0).ceil())
    }
}

fn timeline_row_y(a: Activity) -> i32 {
    TIMELINE_ROWS_TOP + a.index() as i32 * TIMELINE_ROW
}

/// A time chart: one row per class in class order from the top (crawling ..
/// walking_unsteadily), named on the left; recognised segments as bars in the activity
/// colours of docs/simulator.md, the ground truth as a black line through its row, alerts as
/// red vertical lines named above the rows (a thin dark-red line where the event began); a
/// key line on top and the time in seconds from the start of the recording below.
fn draw_timeline(
    path: &Path,
    segments: &[Segment],
    alerts: &[AlertRecord],
    truth: &[(f64, Activity)],
    start_s: f64,
) -> anyhow::Result<()> {
    let end_s = truth
        .last()
        .map(|t| t.0)
        .unwrap_or(0.0)
        .max(segments.last().map(|s| s.end_s - start_s).unwrap_or(0.0))
        .max(1.0);
    let axis = TimeAxis { end_s };
    let x = |t: f64| axis.x(t);
    let height = (TIMELINE_ROWS_BOTTOM + TIMELINE_AXIS) as u32;
    let root = BitMapBackend::new(path, (TIMELINE_WIDTH, height)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let font = || font(TIMELINE_FONT).map_err(plot_error);
    let left = font()?
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    root.draw(&Text::new(TIMELINE_KEY_TEXT, (10, TIMELINE_KEY / 2), &left))
        .map_err(plot_error)?;
    let step = axis.label_step_s();
    let ticks = |every: f64| (0..=(end_s / every + 1e-9) as i64).map(move |k| k as f64 * every);
    let name = font()?
        .color(&BLACK)
        .pos(Pos::new(HPos::Right, VPos::Center));
    for a in Activity::ALL {
        let y = timeline_row_y(a);
        root.draw(&Text::new(
            a.label(),
            (TIMELINE_NAMES - 8, y + TIMELINE_ROW / 2 - 1),
            &name,
        ))
        .map_err(plot_error)?;
        root.draw(&Rectangle::new(
            [(x(0.0), y), (x(end_s), y + TIMELINE_ROW - 2)],
            RGBColor(240, 240, 240).filled(),
        ))
        .map_err(plot_error)?;
        // Faint ticks five to a label, darker at each label.
        for (every, c) in [
            (step / 5.0, RGBColor(220, 220, 220)),
            (step, RGBColor(170, 170, 170)),
        ] {
            for t in ticks(every) {
                root.draw(&PathElement::new(
                    vec![(x(t), y), (x(t), y + TIMELINE_ROW - 2)],
                    c,
                ))
                .map_err(plot_error)?;
            }
        }
    }
    let below = font()?.color(&BLACK).pos(Pos::new(HPos::Center, VPos::Top));
    for t in ticks(step) {
        root.draw(&PathElement::new(
            vec![
                (x(t), TIMELINE_ROWS_BOTTOM),
                (x(t), TIMELINE_ROWS_BOTTOM + 5),
            ],
            BLACK,
        ))
        .map_err(plot_error)?;
        root.draw(&Text::new(
            format!("{t}"),
            (x(t), TIMELINE_ROWS_BOTTOM + 8),
            &below,
        ))
        .map_err(plot_error)?;
    }
    root.draw(&Text::new(
        "time since the start of the recording (s)",
        (x(end_s / 2.0), TIMELINE_ROWS_BOTTOM + 26),
        &below,
    ))
    .map_err(plot_error)?;
    for seg in segments {
        let y = timeline_row_y(seg.activity);
        let (x0, x1) = (
            x(seg.start_s - start_s),
            x(seg.end_s - start_s + 0.05).max(x(seg.start_s - start_s) + 1),
        );
        root.draw(&Rectangle::new(
            [(x0, y + 3), (x1, y + TIMELINE_ROW - 5)],
            ACTIVITY_COLOURS[seg.activity.index()].filled(),
        ))
        .map_err(plot_error)?;
    }
    for pair in truth.windows(2) {
        let (t, a) = pair[0];
        let y = timeline_row_y(a) + TIMELINE_ROW / 2 - 1;
        root.draw(&PathElement::new(
            vec![(x(t), y), (x(pair[1].0), y)],
            BLACK.stroke_width(2),
        ))
        .map_err(plot_error)?;
    }
    let alert_name = font()?.color(&RED).pos(Pos::new(HPos::Left, VPos::Center));
    for (k, alert) in alerts.iter().enumerate() {
        let xe = x(alert.event_time_s - start_s);
        root.draw(&PathElement::new(
            vec![(xe, TIMELINE_KEY + 4), (xe, TIMELINE_ROWS_BOTTOM)],
            RGBColor(120, 0, 0).stroke_width(1),
        ))
        .map_err(plot_error)?;
        let xa = x(alert.time_s - start_s);
        root.draw(&PathElement::new(
            vec![(xa, TIMELINE_KEY + 4), (xa, TIMELINE_ROWS_BOTTOM)],
            RED.stroke_width(3),
        ))
        .map_err(plot_error)?;
        // Alternate lines of the band, so that two close alerts' names do not overlap.
        let y = TIMELINE_KEY + 10 + (k % 2) as i32 * 16;
        root.draw(&Text::new(alert.kind, (xa + 5, y), &alert_name))
            .map_err(plot_error)?;
    }
    root.present().map_err(plot_error)?;
    Ok(())
}

/// plotters' errors carry the backend's error type; keep only the message.
fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("{e}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether each pixel of a box is dark (text, outlines), row by row.
    fn dark_pixels(img: &image::RgbImage, (x0, y0): (i32, i32), (w, h): (i32, i32)) -> Vec<bool> {
        (y0..y0 + h)
            .flat_map(|y| (x0..x0 + w).map(move |x| img.get_pixel(x as u32, y as u32).0))
            .map(|p| p.iter().all(|v| *v < 128))
            .collect()
    }

    fn count(pixels: &[bool]) -> usize {
        pixels.iter().filter(|p| **p).count()
    }

    /// The timeline had no text: which row was which class, what the bars and lines were,
    /// when things happened and which alert a red line was could be read only in the docs.
    #[test]
    fn the_timeline_names_its_rows_alerts_and_times() {
        use Activity::*;
        let segment = |start_s, end_s, activity| Segment {
            start_s,
            end_s,
            activity,
            mean_confidence: 0.9,
            truth: Some(activity),
            scans: 10,
        };
        let segments = [
            segment(100.0, 110.0, Walking),
            segment(110.0, 112.0, FallingDown),
            segment(112.0, 130.0, LyingDown),
        ];
        let alert = |kind, time_s, event_time_s| AlertRecord {
            kind,
            time_s,
            event_time_s,
            position: [1.0, 2.0],
            confidence: 0.9,
        };
        let alerts = [
            alert("FALL_DETECTED", 113.0, 111.0),
            alert("PERSON_DOWN", 125.0, 112.0),
        ];
        let truth: Vec<(f64, Activity)> = (0..=600)
            .map(|k| f64::from(k) * 0.05)
            .map(|t| {
                (
                    t,
                    [Walking, FallingDown, LyingDown][(t >= 10.0) as usize + (t >= 12.0) as usize],
                )
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join(TIMELINE_PNG);
        draw_timeline(&png, &segments, &alerts, &truth, 100.0).unwrap();
        let img = image::open(&png).unwrap().to_rgb8();
        assert_eq!(
            img.dimensions(),
            (
                TIMELINE_WIDTH,
                (TIMELINE_ROWS_BOTTOM + TIMELINE_AXIS) as u32
            )
        );

        let key = dark_pixels(&img, (0, 0), (TIMELINE_WIDTH as i32, TIMELINE_KEY));
        assert!(count(&key) > 500, "the key line: {}", count(&key));
        let mut names = Vec::new();
        for a in Activity::ALL {
            let name = dark_pixels(
                &img,
                (0, timeline_row_y(a)),
                (TIMELINE_NAMES - 4, TIMELINE_ROW),
            );
            assert!(
                count(&name) > 20,
                "{}: {} text pixels",
                a.label(),
                count(&name)
            );
            assert!(!names.contains(&name), "{} named as another row", a.label());
            names.push(name);
        }

        // 30 s: a label every 2 s, under its tick and not between.
        let axis = TimeAxis { end_s: 30.0 };
        assert_eq!(axis.label_step_s(), 2.0);
        let under = |t: f64, half: i32| {
            count(&dark_pixels(
                &img,
                (axis.x(t) - half, TIMELINE_ROWS_BOTTOM + 7),
                (2 * half, 16),
            ))
        };
        for t in [0.0, 10.0, 20.0, 30.0] {
            assert!(under(t, 10) > 10, "no time under {t} s");
        }
        assert_eq!(under(11.0, 4), 0, "a label between the ticks");
        assert_eq!(TimeAxis { end_s: 600.0 }.label_step_s(), 60.0);

        // Each alert's name is written in red beside its line.
        for a in &alerts {
            let xa = axis.x(a.time_s - 100.0);
            let red = (xa + 4..xa + 90)
                .flat_map(|x| (TIMELINE_KEY..TIMELINE_ROWS_TOP).map(move |y| (x, y)))
                .map(|(x, y)| img.get_pixel(x as u32, y as u32).0)
                .filter(|p| p[0] > 150 && p[1] < 120 && p[2] < 120)
                .count();
            assert!(red > 30, "{}: {red} red text pixels", a.kind);
        }
    }

    #[test]
    fn only_an_earlier_demos_own_output_is_to_be_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("demo_out");
        assert!(
            earlier_demo_output(&out).unwrap().is_empty(),
            "no folder yet"
        );
        std::fs::create_dir(&out).unwrap();
        assert!(earlier_demo_output(&out).unwrap().is_empty());
        for folder in [SIM_DIR, RUN_DIR] {
            std::fs::create_dir(out.join(folder)).unwrap();
            std::fs::write(out.join(folder).join("metadata.yaml"), "").unwrap();
        }
        for picture in [SCENE_PNG, TIMELINE_PNG] {
            std::fs::write(out.join(picture), "").unwrap();
        }
        // Someone's own bag named run/ and picture named scene.png are not the demo's.
        let error = earlier_demo_output(&out).unwrap_err().to_string();
        assert!(
            error.contains("not written by the demo") && error.contains(DEMO_MARK),
            "{error}"
        );
        std::fs::write(out.join(DEMO_MARK), "").unwrap();
        let names: Vec<PathBuf> = [DEMO_MARK, RUN_DIR, SCENE_PNG, SIM_DIR, TIMELINE_PNG]
            .iter()
            .map(|name| out.join(name))
            .collect();
        assert_eq!(earlier_demo_output(&out).unwrap(), names);

        // Anything else, or one of the demo's names of the wrong kind, is refused by name.
        std::fs::write(out.join("notes.txt"), "mine").unwrap();
        let error = earlier_demo_output(&out).unwrap_err().to_string();
        assert!(
            error.contains("notes.txt") && error.contains("choose another or delete it"),
            "{error}"
        );
        std::fs::remove_file(out.join("notes.txt")).unwrap();
        // Inside the demo's folders too: they are deleted whole.
        for (folder, file) in [(SIM_DIR, "my_recording.mcap"), (RUN_DIR, "notes.txt")] {
            let path = out.join(folder).join(file);
            std::fs::write(&path, "mine").unwrap();
            let error = earlier_demo_output(&out).unwrap_err().to_string();
            let named = Path::new(folder).join(file).display().to_string();
            assert!(error.contains(&named), "{error}");
            std::fs::remove_file(&path).unwrap();
        }
        std::fs::create_dir(out.join(RUN_DIR).join(RUN_FILES[1])).unwrap();
        let error = earlier_demo_output(&out).unwrap_err().to_string();
        assert!(error.contains(RUN_FILES[1]), "{error}");
        std::fs::remove_dir(out.join(RUN_DIR).join(RUN_FILES[1])).unwrap();
        for file in SIM_FILES {
            std::fs::write(out.join(SIM_DIR).join(file), "").unwrap();
        }
        for file in RUN_FILES {
            std::fs::write(out.join(RUN_DIR).join(file), "").unwrap();
        }
        assert_eq!(
            earlier_demo_output(&out).unwrap(),
            names,
            "every file of a demo's"
        );
        std::fs::remove_file(out.join(SCENE_PNG)).unwrap();
        std::fs::create_dir(out.join(SCENE_PNG)).unwrap();
        let error = earlier_demo_output(&out).unwrap_err().to_string();
        assert!(error.contains(SCENE_PNG), "{error}");
    }
}
