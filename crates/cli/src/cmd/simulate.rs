//! `lidar-har simulate`: run a scene and record it as a rosbag2 directory (MCAP) with the
//! map beside it; optionally draw a top view.

use std::path::PathBuf;

use anyhow::Context;
use lidar_har_sim::map::OccupancyMap;
use lidar_har_sim::record::record;
use lidar_har_sim::render::{Trace, render_png};
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
    /// Also draw a top view (PNG) of the map, paths and scan points.
    #[arg(long, value_name = "FILE.png")]
    pub render: Option<PathBuf>,
    /// Cell size of the recorded map, metres.
    #[arg(long, default_value_t = lidar_har_sim::map::DEFAULT_RESOLUTION)]
    pub map_resolution: f64,
}

pub fn run(args: SimulateArgs) -> anyhow::Result<()> {
    if let Some(path) = &args.render {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or_default()
            .to_ascii_lowercase();
        anyhow::ensure!(
            ext == "png",
            "--render {}: only .png pictures are supported",
            path.display()
        );
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
    let mut sim = Simulator::new(scene, args.seed)
        .with_context(|| format!("scene {}", args.scene.display()))?;
    let geometry = sim.scan_geometry();
    let total = sim.frame_count();
    let progress = indicatif::ProgressBar::new(total);
    progress.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} scans {elapsed} (eta {eta})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    // About 40 scans drawn in a render, whatever the duration.
    let mut trace = args
        .render
        .as_ref()
        .map(|_| Trace::new((total / 40).max(1)));
    let summary = record(&mut sim, &args.out, args.map_resolution, |frame| {
        if let Some(t) = trace.as_mut() {
            t.add(frame, &geometry);
        }
        if frame.index % 256 == 0 {
            progress.set_position(frame.index);
        }
    })
    .with_context(|| format!("recording {}", args.out.display()))?;
    progress.finish_and_clear();
    println!(
        "recorded {} scans ({:.1} s simulated), {} messages into {}",
        summary.frames,
        (summary.last_stamp_ns - summary.first_stamp_ns) as f64 * 1e-9 + geometry.scan_time,
        summary.messages,
        summary.bag_dir.display()
    );
    println!(
        "map: {} and {}",
        args.out.join("map.pgm").display(),
        args.out.join("map.yaml").display()
    );
    if let (Some(path), Some(trace)) = (&args.render, &trace) {
        let map = OccupancyMap::from_world(sim.world(), args.map_resolution);
        render_png(path, &map, trace)?;
        println!("render: {}", path.display());
    }
    Ok(())
}
