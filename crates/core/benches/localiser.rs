//! Time per scan of the localiser (map mode, moving robot with odometry), and how it grows
//! with the number of beams and the size of the map; plus the one-off distance-field time at
//! map load; the same with each beam placed from its own pose (de-skew); and without a map,
//! against a learned background, with a fixed beam count and with one that changes every
//! rotation (a driver without angle compensation). Prints a table; run with `cargo bench -p
//! lidar-har-core --bench localiser`.
//!
//! Scans are ray-cast in a square room with walls, four furniture blocks and a walking
//! person (a 0.2 m cylinder), seen from a robot driving at 0.2 m/s; with 2 % of the beams
//! replaced by random ranges to feed the clustering some clutter. Then the clustering alone on
//! the worst case: every return a stray one (a garbled scan, a wrong pose). Last, the search a
//! hidden person's scan adds (`shadow`): a prediction in open view moved to the nearest shadow.

use std::f64::consts::TAU;
use std::hint::black_box;
use std::time::{Duration, Instant};

use glam::DVec2;
use lidar_har_core::cluster::{ClusterConfig, Clusterer};
use lidar_har_core::geometry::Pose2;
use lidar_har_core::localiser::{Localiser, LocaliserConfig, Motion, Reference};
use lidar_har_core::map::{MapGeometry, OccupancyMap};
use lidar_har_core::scan::Scan;
use lidar_har_core::visibility::{ScanView, ShadowConfig};

const RESOLUTION: f64 = 0.05;
const SCANS: usize = 2000;

/// Axis-aligned boxes (min, max) standing for furniture, in a room centred on the origin.
fn furniture(half: f64) -> Vec<(DVec2, DVec2)> {
    let s = half / 5.0;
    vec![
        (DVec2::new(-4.0, -4.0) * s, DVec2::new(-3.0, -2.0) * s),
        (DVec2::new(2.0, 2.5) * s, DVec2::new(4.0, 3.5) * s),
        (DVec2::new(3.0, -4.5) * s, DVec2::new(4.5, -3.0) * s),
        (DVec2::new(-1.0, 3.5) * s, DVec2::new(0.5, 4.5) * s),
    ]
}

/// The room's occupancy grid (walls and furniture), as a node has it after reading the PGM.
fn room_grid(side_m: f64) -> (MapGeometry, Vec<bool>) {
    let n = (side_m / RESOLUTION).round() as usize;
    let half = side_m / 2.0;
    let boxes = furniture(half);
    let occupied = (0..n * n)
        .map(|i| {
            let (c, r) = (i % n, i / n);
            let p = DVec2::new(
                -half + (c as f64 + 0.5) * RESOLUTION,
                -half + (r as f64 + 0.5) * RESOLUTION,
            );
            c == 0
                || r == 0
                || c == n - 1
                || r == n - 1
                || boxes
                    .iter()
                    .any(|(lo, hi)| p.cmpge(*lo).all() && p.cmple(*hi).all())
        })
        .collect();
    let geometry = MapGeometry {
        resolution: RESOLUTION,
        origin: Pose2::new(-half, -half, 0.0),
        width: n,
        height: n,
    };
    (geometry, occupied)
}

fn room_map(side_m: f64) -> OccupancyMap {
    let (geometry, occupied) = room_grid(side_m);
    OccupancyMap::new(geometry, occupied).expect("valid map")
}

/// Distance along `dir` from `o` to the box, if hit.
fn hit_box(o: DVec2, dir: DVec2, lo: DVec2, hi: DVec2) -> Option<f64> {
    let inv = dir.recip();
    let (t1, t2) = ((lo - o) * inv, (hi - o) * inv);
    let (tmin, tmax) = (t1.min(t2).max_element(), t1.max(t2).min_element());
    (tmax >= tmin.max(0.0)).then_some(tmin.max(0.0))
}

fn cast(
    stamp_ns: i64,
    laser: Pose2,
    person: DVec2,
    beams: usize,
    half: f64,
    rng: &mut u64,
) -> Scan {
    let inc = std::f64::consts::TAU / beams as f64;
    let wall = half - RESOLUTION;
    let boxes = furniture(half);
    let ranges = (0..beams)
        .map(|i| {
            *rng ^= *rng << 13;
            *rng ^= *rng >> 7;
            *rng ^= *rng << 17;
            if (*rng).is_multiple_of(50) {
                return (*rng % 800) as f32 / 100.0;
            }
            let d = DVec2::from_angle(laser.theta - std::f64::consts::PI + i as f64 * inc);
            let o = laser.position();
            let tx = if d.x > 0.0 {
                (wall - o.x) / d.x
            } else {
                (-wall - o.x) / d.x
            };
            let ty = if d.y > 0.0 {
                (wall - o.y) / d.y
            } else {
                (-wall - o.y) / d.y
            };
            let mut r = tx.min(ty);
            for (lo, hi) in &boxes {
                if let Some(t) = hit_box(o, d, *lo, *hi) {
                    r = r.min(t);
                }
            }
            let oc = o - person;
            let b = oc.dot(d);
            let disc = b * b - (oc.length_squared() - 0.04);
            if disc >= 0.0 && -b - disc.sqrt() > 0.0 {
                r = r.min(-b - disc.sqrt());
            }
            r as f32
        })
        .collect();
    Scan {
        stamp_ns,
        angle_min: -std::f32::consts::PI,
        angle_increment: inc as f32,
        time_increment: 0.0,
        range_min: 0.05,
        range_max: 25.0,
        ranges,
    }
}

struct Row {
    beams: usize,
    side_m: f64,
    map_load: Duration,
    median_us: f64,
    p99_us: f64,
    tracked: usize,
    deskewed: bool,
}

/// `deskewed`: the scans state their beams' times (a 20 Hz rotation), so each beam is placed
/// from its own pose.
fn measure(beams: usize, side_m: f64, deskewed: bool) -> Row {
    // Only the map's own work at load (the distance field): building the grid is the bench's.
    let (geometry, occupied) = room_grid(side_m);
    let started = Instant::now();
    let map = OccupancyMap::new(geometry, occupied).expect("valid map");
    let map_load = started.elapsed();
    let half = side_m / 2.0;
    let mut loc = Localiser::new(
        LocaliserConfig::default(),
        Reference::Map(map),
        Motion::Odometry,
    )
    .expect("config");
    let robot = |t: f64| {
        Pose2::new(
            -1.0 + 0.2 * (t * 0.1).sin(),
            -1.0 + 0.2 * (t * 0.1).cos(),
            0.05 * t,
        )
    };
    let person = |t: f64| DVec2::new(1.5 * (0.3 * t).cos(), 1.5 * (0.3 * t).sin());
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    // Scans are made before timing, so only the localiser is measured.
    let scans: Vec<Scan> = (0..SCANS)
        .map(|k| {
            cast(
                k as i64 * 50_000_000,
                robot(k as f64 * 0.05),
                person(k as f64 * 0.05),
                beams,
                half,
                &mut rng,
            )
        })
        .map(|scan| Scan {
            time_increment: if deskewed { 0.05 / beams as f32 } else { 0.0 },
            ..scan
        })
        .collect();
    let mut odometry_k = 0i64;
    let mut times = Vec::with_capacity(SCANS);
    let mut tracked = 0;
    for scan in &scans {
        // Odometry at 50 Hz up to just after the scan, as it arrives on a robot.
        while odometry_k * 20_000_000 <= scan.stamp_ns + 20_000_000 {
            loc.add_odometry(odometry_k * 20_000_000, robot(odometry_k as f64 * 0.02));
            odometry_k += 1;
        }
        let started = Instant::now();
        let result = black_box(loc.process_scan(black_box(scan)));
        times.push(started.elapsed().as_secs_f64() * 1e6);
        tracked += usize::from(
            result
                .output
                .and_then(|o| o.person)
                .is_some_and(|p| p.visible),
        );
    }
    times.sort_by(f64::total_cmp);
    Row {
        beams,
        side_m,
        map_load,
        median_us: times[times.len() / 2],
        p99_us: times[times.len() * 99 / 100],
        tracked,
        deskewed,
    }
}

fn main() {
    println!(
        "localiser time per scan ({SCANS} scans each, map at {RESOLUTION} m/cell, one thread)"
    );
    println!(
        "{:>6} {:>9} {:>8} {:>12} {:>12} {:>10} {:>10}",
        "beams", "map (m)", "de-skew", "map load ms", "median us", "p99 us", "seen"
    );
    let mut rows = Vec::new();
    for beams in [360, 720, 1440, 2880] {
        rows.push(measure(beams, 10.0, false));
    }
    for side in [20.0, 40.0] {
        rows.push(measure(720, side, false));
    }
    for beams in [720, 2880] {
        rows.push(measure(beams, 10.0, true));
    }
    for r in rows {
        println!(
            "{:>6} {:>9} {:>8} {:>12.2} {:>12.1} {:>10.1} {:>9.0}%",
            r.beams,
            format!("{0}x{0}", r.side_m),
            if r.deskewed { "yes" } else { "no" },
            r.map_load.as_secs_f64() * 1e3,
            r.median_us,
            r.p99_us,
            100.0 * r.tracked as f64 / SCANS as f64
        );
    }
    println!("\nlearned background (fixed Lidar, 10 m x 10 m room, {SCANS} scans after learning)");
    println!(
        "{:>6} {:>14} {:>12} {:>10} {:>10}",
        "beams", "beam count", "median us", "p99 us", "seen"
    );
    for varying in [false, true] {
        let (median_us, p99_us, seen) = measure_background(720, varying);
        println!(
            "{:>6} {:>14} {:>12.1} {:>10.1} {:>9.0}%",
            720,
            if varying { "720 +- 3" } else { "fixed" },
            median_us,
            p99_us,
            100.0 * seen
        );
    }
    println!("\nclustering alone, every point a stray return in a 20 m x 20 m square");
    println!("{:>8} {:>12}", "points", "ms");
    for n in [720, 2880, 20_000, 100_000] {
        println!("{n:>8} {:>12.2}", scattered_clustering_ms(n));
    }
    let (searches, median_us, max_us) = shadow_search_us();
    println!(
        "\nshadow search for a hidden person predicted in open view (720 beams, 10 m x 10 m, \
         {searches} predictions 1-4 m away): median {median_us:.1} us, max {max_us:.1} us"
    );
}

/// Time per scan against a learned background (median and p99 in microseconds, and the
/// fraction of scans with the person seen): a fixed Lidar in the 10 m room, the person
/// walking; with `varying`, each rotation has up to 3 beams more or fewer over the same turn.
fn measure_background(beams: usize, varying: bool) -> (f64, f64, f64) {
    let mut loc = Localiser::with_learned_background(LocaliserConfig::default()).expect("config");
    let laser = Pose2::new(-1.0, -1.0, 0.3);
    let person = |t: f64| DVec2::new(1.5 * (0.3 * t).cos(), 1.5 * (0.3 * t).sin());
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let count = |k: usize| if varying { beams + k % 7 - 3 } else { beams };
    // 3 s of learning with nobody in the room (the person far outside it), then the scans.
    let mut k = 0;
    loop {
        let scan = cast(
            k as i64 * 50_000_000,
            laser,
            DVec2::splat(1e3),
            count(k),
            5.0,
            &mut rng,
        );
        k += 1;
        if !loc.process_scan(&scan).learning {
            break;
        }
    }
    let scans: Vec<Scan> = (k..k + SCANS)
        .map(|k| {
            let t = k as f64 * 0.05;
            cast(
                k as i64 * 50_000_000,
                laser,
                person(t),
                count(k),
                5.0,
                &mut rng,
            )
        })
        .collect();
    let mut times = Vec::with_capacity(SCANS);
    let mut seen = 0;
    for scan in &scans {
        let started = Instant::now();
        let result = black_box(loc.process_scan(black_box(scan)));
        times.push(started.elapsed().as_secs_f64() * 1e6);
        seen += usize::from(
            result
                .output
                .and_then(|o| o.person)
                .is_some_and(|p| p.visible),
        );
    }
    times.sort_by(f64::total_cmp);
    (
        times[times.len() / 2],
        times[times.len() * 99 / 100],
        seen as f64 / SCANS as f64,
    )
}

/// Times `ScanView::nearest_hidden` for predictions on a grid around the robot that the scan
/// sees through (the only ones it searches from): count, median and max in microseconds.
fn shadow_search_us() -> (usize, f64, f64) {
    let map = room_map(10.0);
    let laser = Pose2::new(-1.0, -1.0, 0.3);
    let mut rng = 1u64;
    let scan = cast(0, laser, DVec2::new(1.0, -3.5), 720, 5.0, &mut rng);
    let view = ScanView::new(&scan, laser);
    let config = ShadowConfig::default();
    let mut times = Vec::new();
    for i in 0..64 {
        for distance in [1.0, 2.0, 3.0, 4.0] {
            let p = laser.position() + DVec2::from_angle(i as f64 / 64.0 * TAU) * distance;
            if !view.sees_through(p, &config) {
                continue;
            }
            let started = Instant::now();
            for _ in 0..20 {
                black_box(view.nearest_hidden(black_box(p), &map, &config));
            }
            times.push(started.elapsed().as_secs_f64() * 1e6 / 20.0);
        }
    }
    times.sort_by(f64::total_cmp);
    (times.len(), times[times.len() / 2], times[times.len() - 1])
}

/// One clustering pass over `n` points scattered at random (a fixed sequence), in ms.
fn scattered_clustering_ms(n: usize) -> f64 {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let points: Vec<DVec2> = (0..n)
        .map(|_| DVec2::new(20.0 * uniform(), 20.0 * uniform()))
        .collect();
    let mut clusterer = Clusterer::default();
    let (mut clusters, mut fragments) = (Vec::new(), Vec::new());
    let started = Instant::now();
    clusterer.cluster(
        black_box(&points),
        &ClusterConfig::default(),
        black_box(&mut clusters),
        black_box(&mut fragments),
    );
    started.elapsed().as_secs_f64() * 1e3
}
