//! `lidar-har simulate`: run a scene and record it as a rosbag2 directory (MCAP) with the
//! map beside it; optionally draw a top view.

use std::path::{Path, PathBuf};

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
    check_output_space(&args, &sim, free_bytes(&args.out))?;
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

/// Bytes each scan adds to the bag besides its ranges (4 bytes a beam): the /clock, /tf and
/// /odom messages with MCAP's records and index. Measured: 1 178 B a scan in a 1-beam bag
/// without a person, about 290 B more with one (its ground-truth pose and activity).
const BAG_BYTES_PER_SCAN: u64 = 1_200;
const TRUTH_BYTES_PER_SCAN: u64 = 300;
/// A recording estimated at this size or more is announced on stderr before it starts.
const NOTE_OUTPUT_BYTES: u64 = 1_000_000_000;

/// What a recording will write, known before the first scan: a duration typed with the wrong
/// exponent (`1e7` s at 1000 Hz is 10^10 scans, about 40 TB) must not start filling the disk.
struct OutputEstimate {
    scans: u64,
    beams: u64,
    bytes: u64,
}

impl OutputEstimate {
    /// The scans in the bag, plus the map: a byte a cell in `map.pgm` and again in `/map`
    /// (the room's bounds at `map_resolution`; the map's narrow border is left out).
    fn of(sim: &Simulator, map_resolution: f64) -> Self {
        let scans = sim.frame_count();
        let beams = sim.scan_geometry().beams as u64;
        let truth = if sim.scene().person.is_some() {
            TRUTH_BYTES_PER_SCAN
        } else {
            0
        };
        let (lo, hi) = sim.world().bounds();
        let cells =
            ((hi.x - lo.x) / map_resolution).ceil() * ((hi.y - lo.y) / map_resolution).ceil();
        let per_scan = beams * 4 + BAG_BYTES_PER_SCAN + truth;
        Self {
            scans,
            beams,
            bytes: scans
                .saturating_mul(per_scan)
                .saturating_add(2 * cells as u64),
        }
    }

    fn describe(&self) -> String {
        format!(
            "{} scans of {} beams, about {} to write",
            self.scans,
            self.beams,
            size(self.bytes)
        )
    }

    /// Refuses a recording that would not fit in the `free` bytes of `out`'s filesystem.
    fn check_fits(&self, free: u64, asked: &str, out: &Path) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.bytes <= free,
            "{asked}: {}, more than the {} free where {} would be written; shorten the \
             duration or lower lidar.rate_hz (an exponent typed wrong?), or record elsewhere",
            self.describe(),
            size(free),
            out.display()
        );
        Ok(())
    }
}

/// Bytes an unprivileged writer may still use on the filesystem that will hold `out`: that
/// of its nearest existing ancestor, since the recording creates `out` itself.
fn free_bytes(out: &Path) -> nix::Result<u64> {
    let existing = out
        .ancestors()
        .find(|dir| !dir.as_os_str().is_empty() && dir.exists())
        .unwrap_or(Path::new("."));
    let stat = nix::sys::statvfs::statvfs(existing)?;
    Ok((stat.blocks_available() as u64).saturating_mul(stat.fragment_size() as u64))
}

/// Decimal gigabytes, or terabytes from 1 TB, as `df -H` gives them.
fn size(bytes: u64) -> String {
    if bytes >= 1_000_000_000_000 {
        format!("{:.1} TB", bytes as f64 / 1e12)
    } else {
        format!("{:.1} GB", bytes as f64 / 1e9)
    }
}

/// Refuses a recording larger than the `free` space where it would be written, and
/// announces a large one, before anything is written.
fn check_output_space(
    args: &SimulateArgs,
    sim: &Simulator,
    free: nix::Result<u64>,
) -> anyhow::Result<()> {
    let rate_hz = sim.scene().lidar.rate_hz;
    let estimate = OutputEstimate::of(sim, args.map_resolution);
    let asked = match args.duration {
        Some(d) => format!(
            "scene {} with --duration {d} at {rate_hz} Hz",
            args.scene.display()
        ),
        None => format!(
            "scene {} (duration {} s at {rate_hz} Hz)",
            args.scene.display(),
            sim.scene().duration
        ),
    };
    match free {
        Ok(free) => {
            estimate.check_fits(free, &asked, &args.out)?;
            if estimate.bytes >= NOTE_OUTPUT_BYTES {
                errln!("{asked}: {}; {} free", estimate.describe(), size(free));
            }
        }
        Err(e) if estimate.bytes >= NOTE_OUTPUT_BYTES => errln!(
            "{asked}: {}; the free space of {} is unknown ({e})",
            estimate.describe(),
            args.out.display()
        ),
        Err(_) => {}
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

    /// The review's scene: `duration: 1e7` at 1000 Hz passes validation and asks for 10^10
    /// scans (about 40 TB); `simulate` wrote 32 GB in ten minutes before it was stopped.
    const HUGE_SCENE: &str = "duration: 1e7\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\n\
                              robot: {start: {x: 1, y: 1}}\nlidar: {rate_hz: 1000}\n";

    fn simulate_args(scene: &Path, out: &Path) -> SimulateArgs {
        SimulateArgs {
            scene: scene.to_path_buf(),
            out: out.to_path_buf(),
            seed: 0,
            duration: None,
            render: None,
            map_resolution: lidar_har_sim::map::DEFAULT_RESOLUTION,
            rosbag2_version: MetadataVersion::default(),
        }
    }

    #[test]
    fn a_recording_larger_than_the_free_space_is_refused_before_writing() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("big.yaml");
        std::fs::write(&scene, HUGE_SCENE).unwrap();
        let out = dir.path().join("bag");
        // The largest recording a scene may ask for: a host with more free space would record it.
        if free_bytes(dir.path()).unwrap() > 40_000_000_000_000 {
            return;
        }
        let message = format!("{:#}", run(simulate_args(&scene, &out)).unwrap_err());
        for expected in [
            "big.yaml (duration 10000000 s at 1000 Hz)",
            "10000000000 scans of 720 beams",
            "about 40.8 TB to write, more than the",
        ] {
            assert!(message.contains(expected), "{expected:?} in {message}");
        }
        assert!(!out.exists(), "{message}");
    }

    #[test]
    fn a_refusal_names_the_duration_option_when_it_set_the_duration() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("big.yaml");
        std::fs::write(&scene, HUGE_SCENE).unwrap();
        let mut args = simulate_args(&scene, &dir.path().join("bag"));
        args.duration = Some(2e6);
        let mut parsed = Scene::load(&scene).unwrap();
        parsed.duration = 2e6;
        let sim = Simulator::new(parsed, 0).unwrap();
        let message = format!(
            "{:#}",
            check_output_space(&args, &sim, Ok(1_000_000_000_000)).unwrap_err()
        );
        assert!(
            message.contains("with --duration 2000000 at 1000 Hz")
                && message.contains("about 8.2 TB to write, more than the 1.0 TB free"),
            "{message}"
        );
    }

    /// The estimate is the size of the bag and map written, a little above it (under 5 %),
    /// with and without a person, at one beam and at the paper's 720.
    #[test]
    fn the_output_estimate_is_near_the_size_written() {
        let dir = tempfile::tempdir().unwrap();
        let person = "person: {start: {x: 3, y: 2}, script: [{activity: standing, duration: 1}]}\n";
        for (i, (beams, extra)) in [(1, ""), (720, ""), (720, person)].into_iter().enumerate() {
            let scene = Scene::parse(
                &format!(
                    "duration: 20\nroom: {{outline: [[0,0],[5,0],[5,4],[0,4]]}}\n\
                     robot: {{start: {{x: 1, y: 1}}}}\nlidar: {{rate_hz: 100, beams: {beams}}}\n\
                     {extra}"
                ),
                "s.yaml",
            )
            .unwrap();
            let mut sim = Simulator::new(scene, 0).unwrap();
            let estimate = OutputEstimate::of(&sim, 0.05);
            let out = dir.path().join(format!("bag_{i}"));
            record(&mut sim, &out, 0.05, |_| {}).unwrap();
            let written: u64 = std::fs::read_dir(&out)
                .unwrap()
                .map(|e| e.unwrap().metadata().unwrap().len())
                .sum();
            let ratio = estimate.bytes as f64 / written as f64;
            assert!(
                (1.0..1.05).contains(&ratio),
                "{beams} {extra}: {} / {written}",
                estimate.bytes
            );
        }
    }

    #[test]
    fn the_free_space_is_that_of_the_nearest_folder_there() {
        let dir = tempfile::tempdir().unwrap();
        let free = free_bytes(dir.path()).unwrap();
        assert!(free > 0);
        let below = free_bytes(&dir.path().join("not/yet/there")).unwrap();
        // Other writers may change it between the two calls, not by gigabytes.
        assert!(below.abs_diff(free) < 1_000_000_000, "{below} {free}");
        assert!(free_bytes(Path::new("not_there_relative")).is_ok());
    }

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
