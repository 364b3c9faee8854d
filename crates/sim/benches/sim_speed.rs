//! Simulated seconds per wall-clock second on one core, for living_room.yaml, and how the
//! cost grows with beams per rotation and with the number of furniture pieces.
//! Run: `cargo bench -p lidar-har-sim --bench sim_speed [-- ROW_FILTER]`. Prints a table;
//! asserts nothing.

use std::path::PathBuf;
use std::time::Instant;

use lidar_har_sim::scene::{Furniture, NoiseSpec};
use lidar_har_sim::{Frame, Scene, Simulator};

fn living_room() -> Scene {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/living_room.yaml");
    Scene::load(&path).expect("living_room.yaml loads")
}

/// Simulates `sim_seconds` and returns (simulated s per wall s, microseconds per scan).
fn measure(scene: Scene, sim_seconds: f64) -> (f64, f64) {
    let mut scene = scene;
    scene.duration = sim_seconds;
    let mut sim = Simulator::new(scene, 1).expect("scene is valid");
    let frames = sim.frame_count();
    let mut frame = Frame::default();
    let start = Instant::now();
    while sim.step_into(&mut frame) {}
    let wall = start.elapsed().as_secs_f64();
    (sim_seconds / wall, wall * 1e6 / frames as f64)
}

/// Adds `n` small cylinders on a grid over the room's middle (free of the script's paths is
/// not needed: the person is removed for this series).
fn with_furniture(mut scene: Scene, n: usize) -> Scene {
    scene.person = None;
    scene.furniture.clear();
    let cols = (n as f64).sqrt().ceil() as usize;
    for k in 0..n {
        let (i, j) = (k % cols, k / cols);
        let x = 1.0 + 4.0 * (i as f64 + 0.5) / cols as f64;
        let y = 1.2 + 2.5 * (j as f64 + 0.5) / cols as f64;
        scene.furniture.push(Furniture::Cylinder {
            name: String::new(),
            center: [x, y],
            radius: 0.04,
            height: 1.0,
        });
    }
    scene.robot.start.x = 0.4;
    scene.robot.start.y = 0.4;
    scene
}

fn main() {
    let seconds = 300.0;
    println!(
        "sim_speed: living_room.yaml, {seconds} s simulated per row, one thread, no recording"
    );
    println!(
        "{:<44} {:>14} {:>12}",
        "case", "sim s / wall s", "us / scan"
    );
    // `cargo bench -p lidar-har-sim --bench sim_speed -- TEXT` runs only rows whose name
    // contains TEXT (for profiling one case).
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let row = |name: &str, scene: Scene| {
        if filter.as_ref().is_some_and(|f| !name.contains(f.as_str())) {
            return;
        }
        let (speed, us) = measure(scene, seconds);
        println!("{name:<44} {speed:>14.0} {us:>12.1}");
    };
    row("living_room (720 beams, 20 Hz, paper noise)", living_room());
    let mut quiet = living_room();
    quiet.lidar.noise = NoiseSpec::NONE;
    row("living_room, no noise", quiet);
    let paper = NoiseSpec::default();
    for (name, noise) in [
        (
            "noise: angle error only",
            NoiseSpec {
                angle_deg: paper.angle_deg,
                ..NoiseSpec::NONE
            },
        ),
        (
            "noise: distance error only",
            NoiseSpec {
                distance_pct: paper.distance_pct,
                ..NoiseSpec::NONE
            },
        ),
        (
            "noise: missing + wrong only",
            NoiseSpec {
                missing_pct: paper.missing_pct,
                wrong_pct: paper.wrong_pct,
                wrong_spread_deg: paper.wrong_spread_deg,
                ..NoiseSpec::NONE
            },
        ),
    ] {
        let mut s = living_room();
        s.lidar.noise = noise;
        row(name, s);
    }
    for beams in [180u32, 360, 720, 1440, 2880, 5760] {
        let mut s = living_room();
        s.lidar.beams = beams;
        row(&format!("beams = {beams}"), s);
    }
    for n in [0usize, 10, 20, 40, 80, 160] {
        row(
            &format!("furniture = {n} cylinders (no person)"),
            with_furniture(living_room(), n),
        );
    }
}
