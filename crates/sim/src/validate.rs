//! Scene checks that serde cannot make. Each error names the key path of the culprit.

use glam::DVec2;

use crate::scene::{Furniture, Motion, Scene, is_locomotion, MAX_ROBOT_SPEED};
use crate::shapes::{polygon_area2, polygon_self_intersection};
use crate::world::World;

type Check = Result<(), (String, String)>;

/// How close to furniture or a wall a person may start (about half a body's depth).
pub const PERSON_START_CLEARANCE: f64 = 0.1;

fn fail(key: impl Into<String>, message: impl Into<String>) -> Check {
    Err((key.into(), message.into()))
}

fn positive(key: &str, v: f64) -> Check {
    if !v.is_finite() {
        return fail(key, format!("must be a finite number, got {v}"));
    }
    if v <= 0.0 { fail(key, format!("must be positive, got {v}")) } else { Ok(()) }
}

fn finite(key: &str, v: f64) -> Check {
    if v.is_finite() { Ok(()) } else { fail(key, format!("must be a finite number, got {v}")) }
}

fn in_range(key: &str, v: f64, lo: f64, hi: f64) -> Check {
    finite(key, v)?;
    if v < lo || v > hi { fail(key, format!("must be within [{lo}, {hi}], got {v}")) } else { Ok(()) }
}

fn points(key: &str, pts: &[[f64; 2]]) -> Check {
    for (i, p) in pts.iter().enumerate() {
        finite(&format!("{key}[{i}][0]"), p[0])?;
        finite(&format!("{key}[{i}][1]"), p[1])?;
    }
    Ok(())
}

fn polygon(key: &str, pts: &[[f64; 2]]) -> Check {
    if pts.len() < 3 {
        return fail(key, format!("a polygon needs at least 3 points, got {}", pts.len()));
    }
    points(key, pts)?;
    let poly: Vec<DVec2> = pts.iter().map(|p| DVec2::new(p[0], p[1])).collect();
    if let Some((i, j)) = polygon_self_intersection(&poly) {
        return fail(key, format!("edges {i} and {j} cross or touch: the polygon must be simple"));
    }
    if polygon_area2(&poly).abs() < 1e-9 {
        return fail(key, "the polygon has no area");
    }
    Ok(())
}

fn describe(world: &World, furniture: Option<usize>) -> String {
    match furniture {
        Some(i) if world.furniture[i].name.is_empty() => format!("furniture[{i}]"),
        Some(i) => format!("furniture[{i}] '{}'", world.furniture[i].name),
        None => "a wall".to_string(),
    }
}

pub fn validate(scene: &Scene) -> Check {
    in_range("duration", scene.duration, 1e-3, 1e7)?;
    polygon("room.outline", &scene.room.outline)?;
    for (i, f) in scene.furniture.iter().enumerate() {
        let k = format!("furniture[{i}]");
        match f {
            Furniture::Box { center, size, yaw_deg, height, .. } => {
                points(&format!("{k}.center"), &[*center])?;
                positive(&format!("{k}.size[0]"), size[0])?;
                positive(&format!("{k}.size[1]"), size[1])?;
                finite(&format!("{k}.yaw_deg"), *yaw_deg)?;
                positive(&format!("{k}.height"), *height)?;
            }
            Furniture::Cylinder { center, radius, height, .. } => {
                points(&format!("{k}.center"), &[*center])?;
                positive(&format!("{k}.radius"), *radius)?;
                positive(&format!("{k}.height"), *height)?;
            }
            Furniture::Polygon { points: pts, height, .. } => {
                polygon(&format!("{k}.points"), pts)?;
                positive(&format!("{k}.height"), *height)?;
            }
            Furniture::Table(l) | Furniture::Chair(l) => {
                points(&format!("{k}.center"), &[l.center])?;
                positive(&format!("{k}.size[0]"), l.size[0])?;
                positive(&format!("{k}.size[1]"), l.size[1])?;
                finite(&format!("{k}.yaw_deg"), l.yaw_deg)?;
                positive(&format!("{k}.height"), l.height)?;
                positive(&format!("{k}.leg_radius"), l.leg_radius)?;
                in_range(&format!("{k}.leg_inset"), l.leg_inset, 0.0, f64::MAX)?;
                for (axis, s) in l.size.iter().enumerate() {
                    if 2.0 * (l.leg_inset + l.leg_radius) > *s {
                        return fail(format!("{k}.size[{axis}]"), format!("{s} m is too small for legs of radius {} set in by {} m", l.leg_radius, l.leg_inset));
                    }
                }
            }
        }
    }

    let r = &scene.robot;
    positive("robot.radius", r.radius)?;
    in_range("robot.lidar_height", r.lidar_height, 0.01, 3.0)?;
    finite("robot.lidar_mount.x", r.lidar_mount.x)?;
    finite("robot.lidar_mount.y", r.lidar_mount.y)?;
    finite("robot.lidar_mount.yaw_deg", r.lidar_mount.yaw_deg)?;
    finite("robot.start.x", r.start.x)?;
    finite("robot.start.y", r.start.y)?;
    finite("robot.start.yaw_deg", r.start.yaw_deg)?;
    positive("robot.speed", r.speed)?;
    if r.speed > MAX_ROBOT_SPEED {
        return fail("robot.speed", format!("at most {MAX_ROBOT_SPEED} m/s (the paper's robot), got {}", r.speed));
    }
    positive("robot.turn_rate_deg", r.turn_rate_deg)?;

    let l = &scene.lidar;
    positive("lidar.rate_hz", l.rate_hz)?;
    if l.rate_hz > 1000.0 {
        return fail("lidar.rate_hz", format!("at most 1000 Hz, got {}", l.rate_hz));
    }
    if l.beams == 0 || l.beams > 100_000 {
        return fail("lidar.beams", format!("must be within [1, 100000], got {}", l.beams));
    }
    in_range("lidar.range_min", l.range_min, 0.0, 1e4)?;
    in_range("lidar.range_max", l.range_max, 0.0, 1e6)?;
    if l.range_max <= l.range_min {
        return fail("lidar.range_max", format!("must exceed range_min ({}), got {}", l.range_min, l.range_max));
    }
    let n = &l.noise;
    in_range("lidar.noise.distance_pct", n.distance_pct, 0.0, 100.0)?;
    in_range("lidar.noise.missing_pct", n.missing_pct, 0.0, 100.0)?;
    in_range("lidar.noise.wrong_pct", n.wrong_pct, 0.0, 100.0)?;
    if n.missing_pct + n.wrong_pct > 100.0 {
        return fail("lidar.noise.wrong_pct", format!("missing_pct + wrong_pct must not exceed 100, got {}", n.missing_pct + n.wrong_pct));
    }
    in_range("lidar.noise.angle_deg", n.angle_deg, 0.0, 10.0)?;
    in_range("lidar.noise.wrong_spread_deg", n.wrong_spread_deg, 0.0, 180.0)?;

    // Placement: needs the room's geometry.
    let world = World::new(scene);
    let (clear, what) = world.robot_clearance(r.start.to_pose().position());
    if clear < r.radius {
        let where_ = if clear < 0.0 { "inside" } else { "overlapping" };
        return fail("robot.start", format!("the robot (radius {} m) starts {where_} {}", r.radius, describe(&world, what)));
    }
    match &r.motion {
        Motion::Static => {}
        Motion::Waypoints { points: pts, .. } => {
            if pts.is_empty() {
                return fail("robot.motion.points", "needs at least one point");
            }
            points("robot.motion.points", pts)?;
            for (i, p) in pts.iter().enumerate() {
                let (clear, what) = world.robot_clearance(DVec2::new(p[0], p[1]));
                if clear < r.radius {
                    return fail(format!("robot.motion.points[{i}]"), format!("the robot (radius {} m) cannot stand here: it would touch {}", r.radius, describe(&world, what)));
                }
            }
        }
        Motion::Coverage { spacing, .. } => in_range("robot.motion.spacing", *spacing, 0.05, 100.0)?,
        Motion::Bounce { runs } => {
            if *runs == 0 {
                return fail("robot.motion.runs", "must be at least 1");
            }
        }
    }

    if let Some(p) = &scene.person {
        let b = &p.body;
        in_range("person.body.height", b.height, 0.5, 2.5)?;
        in_range("person.body.girth", b.girth, 0.3, 3.0)?;
        in_range("person.body.pace", b.pace, 0.3, 3.0)?;
        in_range("person.body.stride", b.stride, 0.3, 3.0)?;
        in_range("person.body.sway", b.sway, 0.0, 5.0)?;
        in_range("person.body.variation", b.variation, 0.0, 0.3)?;
        finite("person.start.x", p.start.x)?;
        finite("person.start.y", p.start.y)?;
        finite("person.start.yaw_deg", p.start.yaw_deg)?;
        let (clear, what) = world.person_clearance(p.start.to_pose().position());
        if clear < PERSON_START_CLEARANCE {
            let where_ = if clear < 0.0 { "inside" } else { "too close to" };
            return fail("person.start", format!("the person starts {where_} {}", describe(&world, what)));
        }
        if p.script.is_empty() {
            return fail("person.script", "needs at least one step");
        }
        for (i, s) in p.script.iter().enumerate() {
            let k = format!("person.script[{i}]");
            in_range(&format!("{k}.duration"), s.duration, 1e-3, 1e7)?;
            use lidar_har_core::activity::Activity as A;
            match s.activity {
                A::FallingDown => in_range(&format!("{k}.duration"), s.duration, 0.4, 5.0)?,
                A::GettingUp => in_range(&format!("{k}.duration"), s.duration, 0.8, 15.0)?,
                _ => {}
            }
            if let Some(v) = s.speed {
                in_range(&format!("{k}.speed"), v, 0.01, 8.0)?;
            }
            if is_locomotion(s.activity) {
                if s.path.is_empty() {
                    return fail(format!("{k}.path"), format!("{} needs a path of at least one point", s.activity));
                }
            } else if !s.path.is_empty() {
                return fail(format!("{k}.path"), format!("{} does not move along a path", s.activity));
            }
            if s.fall.is_some() && s.activity != A::FallingDown {
                return fail(format!("{k}.fall"), "only a falling_down step has a fall direction");
            }
            points(&format!("{k}.path"), &s.path)?;
            for (j, q) in s.path.iter().enumerate() {
                let (clear, what) = world.person_clearance(DVec2::new(q[0], q[1]));
                if clear < PERSON_START_CLEARANCE {
                    return fail(format!("{k}.path[{j}]"), format!("too close to {}", describe(&world, what)));
                }
            }
        }
    }
    Ok(())
}
