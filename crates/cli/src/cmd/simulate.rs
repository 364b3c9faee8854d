//! `lidar-har simulate`: run a scene and record it as a rosbag2 directory (MCAP) with the
//! map beside it; optionally draw a top view.

use std::path::PathBuf;

use anyhow::Context;
use lidar_har_bag::MetadataVersion;
use lidar_har_sim::map::OccupancyMap;
use lidar_har_sim::record::{RecordSummary, record_as};
use lidar_har_sim::render::{Trace, animation_scan_every, render_gif, render_png};
use lidar_har_sim::{Scene, Simulator};

#[derive(clap::Args)]
pub struct SimulateArgs {
    /// Scene file (YAML, see docs/simulator.md).
    #[arg(long, default_value = "config/scenes/living_room.yaml")]
    pub scene: PathBuf,
    /// Output rosbag2 directory; must not hold a bag already.
    #[arg(long)]
    pub out: PathBuf,
    /// Mixed with the scene's seed: the same scene and seed give a byte-identical bag.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Simulated seconds, overriding the scene's `duration`.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Also draw a top view of the map, paths and scan points: a picture (.png) or an
    /// animation played at 4x real time (.gif; at most 100 frames, at least 20 ms apart).
    #[arg(long, value_name = "FILE.png|FILE.gif")]
    pub render: Option<PathBuf>,
    /// Cell size of the recorded map, metres.
    #[arg(long, default_value_t = lidar_har_sim::map::DEFAULT_RESOLUTION)]
    pub map_resolution: f64,
    /// rosbag2 metadata version of the bag: 9 (read by Jazzy and later) or 8 (read by
    /// Humble, Iron and later; use it for a bag to play on a Humble or Iron robot, whose
    /// `ros2 bag info` and `play` cannot parse 9; the bag is MCAP, which needs
    /// ros-humble-rosbag2-storage-mcap there, or `lidar-har bag convert OUT OUT_DB3 --storage
    /// sqlite3`).
    #[arg(long, default_value = "9", value_parser = super::parse_metadata_version)]
    pub rosbag2_version: MetadataVersion,
}

/// What `--render` draws.
#[derive(Clone, Copy, PartialEq)]
enum RenderKind {
    Picture,
    Animation,
}

/// Playback speed of `--render FILE.gif`, and how many scans it shows at most.
const GIF_SPEED_UP: f64 = 4.0;
const GIF_FRAMES: u64 = 100;
/// Scans drawn on a `--render FILE.png`, whatever the duration.
const PNG_SCANS: u64 = 40;

pub fn run(args: SimulateArgs) -> anyhow::Result<()> {
    let render = match &args.render {
        None => None,
        Some(path) => {
            let ext = path
                .extension()
                .and_then(|e| e.to_str())
                .unwrap_or_default()
                .to_ascii_lowercase();
            Some(match ext.as_str() {
                "png" => RenderKind::Picture,
                "gif" => RenderKind::Animation,
                _ => anyhow::bail!(
                    "--render {}: give a .png (picture) or .gif (animation) file",
                    path.display()
                ),
            })
        }
    };
    if let Some(path) = &args.render {
        super::prepare_output_file(path, "--render")?;
    }
    anyhow::ensure!(
        args.map_resolution.is_finite()
            && args.map_resolution >= 0.005
            && args.map_resolution <= 1.0,
        "--map-resolution {}: must be within [0.005, 1] m",
        args.map_resolution
    );
    let mut scene = Scene::load(&args.scene)?;
    if let Some(d) = args.duration {
        scene.duration = d;
        scene
            .validate()
            .map_err(|(key, message)| anyhow::anyhow!("--duration {d}: {key}: {message}"))?;
    }
    let simulated_s = scene.duration;
    let mut sim = Simulator::new(scene, args.seed)
        .with_context(|| format!("scene {}", args.scene.display()))?;
    let geometry = sim.scan_geometry();
    let total = sim.frame_count();
    let progress = indicatif::ProgressBar::new(total);
    progress.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} scans {elapsed} (eta {eta})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let scan_every = match render {
        Some(RenderKind::Animation) => {
            animation_scan_every(total, geometry.scan_time, GIF_FRAMES, GIF_SPEED_UP)
        }
        _ => (total / PNG_SCANS).max(1),
    };
    let mut trace = render.map(|_| Trace::new(scan_every));
    let summary = record_as(
        &mut sim,
        &args.out,
        args.map_resolution,
        args.rosbag2_version,
        |frame| {
            if let Some(t) = trace.as_mut() {
                t.add(frame, &geometry);
            }
            if frame.index % 256 == 0 {
                progress.set_position(frame.index);
            }
        },
    )
    .with_context(|| format!("recording {}", args.out.display()))?;
    progress.finish_and_clear();
    outln!("{}", recorded_line(&summary, simulated_s));
    outln!(
        "map: {} and {}",
        args.out.join("map.pgm").display(),
        args.out.join("map.yaml").display()
    );
    if let (Some(path), Some(trace)) = (&args.render, &trace) {
        let map = OccupancyMap::from_world(sim.world(), args.map_resolution);
        if render == Some(RenderKind::Animation) {
            let delay_ms = scan_every as f64 * geometry.scan_time * 1000.0 / GIF_SPEED_UP;
            render_gif(path, &map, trace, delay_ms)
        } else {
            render_png(path, &map, trace)
        }
        .with_context(|| format!("--render {}", path.display()))?;
        outln!("render: {}", path.display());
    }
    Ok(())
}

/// The summary of a recording. The time is the scene's duration: the stamps span whole
/// scan periods (one scan of 0.05 s for `--duration 0.001`), which is not what was asked.
fn recorded_line(summary: &RecordSummary, simulated_s: f64) -> String {
    format!(
        "recorded {} scans ({simulated_s} s simulated), {} messages into {}",
        summary.frames,
        summary.messages,
        summary.bag_dir.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use lidar_har_sim::record::record;

    /// The line said `(0.1 s simulated)` for `--duration 0.001`: one 20 Hz scan period,
    /// rounded.
    #[test]
    fn the_recorded_line_gives_the_scenes_duration() {
        let dir = tempfile::tempdir().unwrap();
        let mut scene = Scene::parse(
            "duration: 0.001\nroom: {outline: [[0,0],[4,0],[4,3],[0,3]]}\n\
             robot: {start: {x: 1, y: 1}}\nlidar: {beams: 90}\n",
            "s.yaml",
        )
        .unwrap();
        for (duration, scans, shown) in
            [(0.001, 1, "0.001 s"), (2.0, 40, "2 s"), (0.26, 6, "0.26 s")]
        {
            scene.duration = duration;
            let out = dir.path().join(format!("bag_{duration}"));
            let mut sim = Simulator::new(scene.clone(), 0).unwrap();
            let summary = record(&mut sim, &out, 0.05, |_| {}).unwrap();
            assert_eq!(summary.frames, scans, "{duration}");
            let line = recorded_line(&summary, duration);
            assert!(
                line.starts_with(&format!("recorded {scans} scans ({shown} simulated)")),
                "{line}"
            );
        }
    }
}
