//! Property tests over random scenes: valid ranges, person points inside the body, exact
//! geometry without noise, and determinism.

use glam::{DVec2, DVec3};
use lidar_har_sim::scene::NoiseSpec;
use lidar_har_sim::shapes::{ray_capsule, ray_circle, ray_segment};
use lidar_har_sim::{BeamLabel, Frame, Scene, SceneError, Simulator};
use proptest::prelude::*;

/// A rectangular room `w` x `h` with a box and a table, the robot in one corner region and
/// the person in the middle doing two activities.
fn scene_text(
    w: f64,
    h: f64,
    first: usize,
    second: usize,
    noise: &str,
    lidar_height: f64,
    beams: u32,
) -> String {
    let step = |a: usize, dur: f64| {
        let name = lidar_har_core::activity::Activity::ALL[a].label();
        let path = if matches!(a, 0 | 4 | 7 | 8) {
            format!(", path: [[{:.2}, {:.2}]]", w * 0.5, h * 0.3)
        } else {
            String::new()
        };
        let dur = match a {
            1 => 1.0,
            2 => 2.0,
            _ => dur,
        };
        format!("    - {{activity: {name}, duration: {dur}{path}}}\n")
    };
    format!(
        "duration: 2\nroom: {{outline: [[0,0],[{w},0],[{w},{h}],[0,{h}]]}}\nfurniture:\n  - {{kind: box, center: [{bx}, {by}], size: [0.6, 0.4], yaw_deg: 20, height: 0.8}}\n  - {{kind: table, center: [{tx}, {ty}], size: [0.8, 0.6], height: 0.7}}\nrobot: {{start: {{x: 0.4, y: 0.4}}, lidar_height: {lidar_height}, motion: {{kind: bounce, runs: 5}}}}\nlidar: {{beams: {beams}, noise: {noise}}}\nperson:\n  start: {{x: {px}, y: {py}, yaw_deg: 30}}\n  script:\n{s1}{s2}",
        bx = w - 0.6,
        by = h - 0.5,
        tx = 0.7,
        ty = h - 0.6,
        px = w * 0.5,
        py = h * 0.5,
        s1 = step(first, 0.6),
        s2 = step(second, 5.0),
    )
}

/// The scene's frames, or `None` when the simulator refuses a later step of the script: the
/// generator puts the second step wherever the first ends, and a body sitting or crawling
/// off there may have no room (near a wall, by the seed's draws). Such a case is not run.
fn frames(text: &str, seed: u64) -> Option<(Simulator, Vec<Frame>)> {
    let scene = Scene::parse(text, "proptest").expect("generated scene is valid");
    let mut sim = match Simulator::new(scene, seed) {
        Ok(sim) => sim,
        Err(SceneError::Refused { key, .. }) if key.starts_with("person.script[") => {
            return None;
        }
        Err(e) => panic!("simulator starts: {e}"),
    };
    let mut out = Vec::new();
    while let Some(f) = sim.step() {
        out.push(f);
    }
    Some((sim, out))
}

/// Exact distance for one beam, brute force over every object (no broad phase).
fn brute(sim: &Simulator, frame: &Frame, i: usize) -> f64 {
    let g = sim.scan_geometry();
    let w = sim.world();
    let o = frame.laser.position();
    let d = g.direction(frame.laser.theta, i);
    let mut best = f64::INFINITY;
    for s in &w.segments {
        best = best.min(ray_segment(o, d, s.a, s.b).unwrap_or(f64::INFINITY));
    }
    for c in &w.circles {
        best = best.min(ray_circle(o, d, c.center, c.radius).unwrap_or(f64::INFINITY));
    }
    if let Some(p) = &frame.person {
        for c in &p.parts {
            best = best.min(
                ray_capsule(o.extend(w.lidar_height), d.extend(0.0), c.a, c.b, c.radius)
                    .unwrap_or(f64::INFINITY),
            );
        }
    }
    best
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn ranges_are_valid_or_infinite(w in 3.0f64..9.0, h in 3.0f64..7.0, a in 0usize..9, b in 0usize..9,
                                    dist in 0.0f64..20.0, miss in 0.0f64..50.0, wrong in 0.0f64..50.0,
                                    angle in 0.0f64..1.0, lh in 0.05f64..0.6, seed in 0u64..1000) {
        let noise = format!("{{distance_pct: {dist}, missing_pct: {miss}, wrong_pct: {wrong}, angle_deg: {angle}}}");
        let run = frames(&scene_text(w, h, a, b, &noise, lh, 360), seed);
        prop_assume!(run.is_some(), "a later step with no room for the body");
        let (sim, frames) = run.unwrap();
        let g = sim.scan_geometry();
        for f in &frames {
            prop_assert_eq!(f.ranges.len(), 360);
            for r in &f.ranges {
                prop_assert!(*r == f32::INFINITY || (*r >= g.range_min as f32 && *r <= g.range_max as f32), "range {}", r);
            }
        }
    }

    #[test]
    fn person_points_lie_on_the_body(w in 4.0f64..9.0, h in 4.0f64..7.0, a in 0usize..9, b in 0usize..9,
                                     noisy in any::<bool>(), seed in 0u64..1000) {
        let noise = if noisy { "{}" } else { "{distance_pct: 0, missing_pct: 0, wrong_pct: 0, angle_deg: 0}" };
        let run = frames(&scene_text(w, h, a, b, noise, 0.1, 720), seed);
        prop_assume!(run.is_some(), "a later step with no room for the body");
        let (sim, frames) = run.unwrap();
        let g = sim.scan_geometry();
        let n = sim.scene().lidar.noise;
        let hgt = sim.world().lidar_height;
        let mut person_beams = 0usize;
        for f in &frames {
            let person = f.person.as_ref().expect("scene has a person");
            for (i, (r, l)) in f.ranges.iter().zip(&f.labels).enumerate() {
                if *l != BeamLabel::Person {
                    continue;
                }
                person_beams += 1;
                let r = *r as f64;
                let p = f.laser.transform_point(DVec2::from_angle(g.angle_min + g.angle_increment * i as f64) * r);
                // Six sigma of the range error plus the arc of four sigma of angle error.
                let tol = 6.0 * n.distance_pct / 100.0 * r + 4.0 * n.angle_deg.to_radians() * r + 1e-4;
                let gap = person.parts.iter().map(|c| {
                    let q = DVec3::new(p.x, p.y, hgt);
                    lidar_har_sim::shapes::point_segment_dist_sq(q, c.a, c.b).sqrt() - c.radius
                }).fold(f64::INFINITY, f64::min);
                prop_assert!(gap <= tol, "person point {:?} is {} m off the body (tolerance {})", p, gap, tol);
            }
        }
        // The person stands in the open middle of the room: some beams must hit them, or the
        // checks above checked nothing.
        prop_assert!(person_beams > 0, "no beam of {} frames hit the person", frames.len());
    }

    #[test]
    fn zero_noise_gives_exact_geometry(w in 3.0f64..9.0, h in 3.0f64..7.0, a in 0usize..9, b in 0usize..9, seed in 0u64..1000) {
        let noise = "{distance_pct: 0, missing_pct: 0, wrong_pct: 0, angle_deg: 0}";
        let text = scene_text(w, h, a, b, noise, 0.1, 720);
        let scene = Scene::parse(&text, "proptest").unwrap();
        prop_assert_eq!(scene.lidar.noise, NoiseSpec { wrong_spread_deg: 30.0, ..NoiseSpec::NONE });
        let run = frames(&text, seed);
        prop_assume!(run.is_some(), "a later step with no room for the body");
        let (sim, frames) = run.unwrap();
        let g = sim.scan_geometry();
        for f in frames.iter().step_by(7) {
            for i in 0..f.ranges.len() {
                let exact = brute(&sim, f, i);
                let expect = if exact >= g.range_min && exact <= g.range_max { exact as f32 } else { f32::INFINITY };
                prop_assert_eq!(f.ranges[i], expect, "beam {}", i);
            }
        }
    }
}

/// The case the property tests drew in session 48 (seeds are random): a 3 m room, walking
/// unsteadily, then crawling off with the legs into a wall, which the simulator rightly
/// refuses. Such a case is skipped, not failed.
#[test]
fn a_later_step_without_room_for_the_body_is_skipped() {
    let noise = "{distance_pct: 0, missing_pct: 0, wrong_pct: 0, angle_deg: 0}";
    assert!(frames(&scene_text(3.0, 3.0, 7, 0, noise, 0.1, 720), 0).is_none());
}
