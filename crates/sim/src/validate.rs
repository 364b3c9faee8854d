//! Scene checks that serde cannot make. Each error names the key path of the culprit.

use glam::DVec2;

use lidar_har_core::activity::Activity;

use crate::scene::{
    BodySpec, Furniture, Legged, LidarSpec, MAX_BOUNCE_RUNS, MAX_ROBOT_SPEED, Motion, NoiseSpec,
    PersonSpec, RobotSpec, Room, Scene, ScriptStep, is_locomotion,
};
use crate::shapes::{polygon_area2, polygon_self_intersection};
use crate::world::World;

type Check = Result<(), (String, String)>;

/// How close to furniture or a wall a person may start (about half a body's depth).
pub const PERSON_START_CLEARANCE: f64 = 0.1;

/// How close to furniture or a wall a person whose script starts sitting on the floor may
/// start: a seated body of 1.75 m reaches about 0.6 m ahead (the feet) and behind (the
/// hands). Random scripts start at least this far from everything, so none is refused.
/// Sitting down later in a script is checked by the planner, along the seated body.
pub const SEATED_START_CLEARANCE: f64 = 0.6;

fn fail(key: impl Into<String>, message: impl Into<String>) -> Check {
    Err((key.into(), message.into()))
}

fn positive(key: &str, v: f64) -> Check {
    if !v.is_finite() {
        return fail(key, format!("must be a finite number, got {v}"));
    }
    if v <= 0.0 {
        fail(key, format!("must be positive, got {v}"))
    } else {
        Ok(())
    }
}

fn finite(key: &str, v: f64) -> Check {
    if v.is_finite() {
        Ok(())
    } else {
        fail(key, format!("must be a finite number, got {v}"))
    }
}

fn in_range(key: &str, v: f64, lo: f64, hi: f64) -> Check {
    finite(key, v)?;
    if v < lo || v > hi {
        fail(key, format!("must be within [{lo}, {hi}], got {v}"))
    } else {
        Ok(())
    }
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
        return fail(
            key,
            format!("a polygon needs at least 3 points, got {}", pts.len()),
        );
    }
    points(key, pts)?;
    // GIS formats close a ring by repeating its first point; here the closing edge is
    // implied, and the repeat would read as a zero-length edge touching the first.
    let last = pts.len() - 1;
    if pts[last] == pts[0] {
        return fail(
            format!("{key}[{last}]"),
            "repeats the first point: list each corner once, the last edge back to the \
             first point is implied",
        );
    }
    let poly: Vec<DVec2> = pts.iter().map(|p| DVec2::new(p[0], p[1])).collect();
    if let Some((i, j)) = polygon_self_intersection(&poly) {
        return fail(
            key,
            format!("edges {i} and {j} cross or touch: the polygon must be simple"),
        );
    }
    if polygon_area2(&poly).abs() < 1e-9 {
        return fail(key, "the polygon has no area");
    }
    Ok(())
}

/// Names what a check hit: furniture `i` (with its name when it has one) or a wall.
pub(crate) fn describe(world: &World, furniture: Option<usize>) -> String {
    match furniture {
        Some(i) if world.furniture[i].name.is_empty() => format!("furniture[{i}]"),
        Some(i) => format!("furniture[{i}] '{}'", world.furniture[i].name),
        None => "a wall".to_string(),
    }
}

/// Where a point lies when it is `clear` from what `world.*_clearance` named `what`, and
/// less than a check asks: `outside the room`, `inside <furniture>`, or `{near} <it>`.
pub(crate) fn place(world: &World, clear: f64, what: Option<usize>, near: &str) -> String {
    match (clear < 0.0, what) {
        (true, None) => "outside the room".to_string(),
        (true, Some(_)) => format!("inside {}", describe(world, what)),
        (false, _) => format!("{near} {}", describe(world, what)),
    }
}

/// The largest room side: coordinates are metres, and a plan typed in millimetres would
/// otherwise ask for a map of gigabytes.
pub const MAX_ROOM_SIDE_M: f64 = 200.0;

/// The last second a ROS stamp holds (`builtin_interfaces/Time.sec` is a signed 32-bit int).
const LAST_ROS_SECOND: u64 = i32::MAX as u64;

/// Checks run in this order; the first failure is reported. Placement comes last because it
/// needs the room built from the values checked before it.
pub fn validate(scene: &Scene) -> Check {
    check_times(scene)?;
    let (room_lo, room_hi) = check_room(&scene.room)?;
    for (i, f) in scene.furniture.iter().enumerate() {
        check_furniture(&format!("furniture[{i}]"), f)?;
        check_furniture_reach(&format!("furniture[{i}]"), f, room_lo, room_hi)?;
    }
    check_robot(&scene.robot)?;
    check_lidar(&scene.lidar)?;
    let world = World::new(scene);
    check_furniture_in_room(&world)?;
    check_robot_start(&world, &scene.robot)?;
    check_robot_motion(&world, &scene.robot)?;
    if let Some(p) = &scene.person {
        check_person(&world, p)?;
    }
    Ok(())
}

fn check_times(scene: &Scene) -> Check {
    in_range("duration", scene.duration, 1e-3, 1e7)?;
    // ROS reads a stamp of 0 as unset: a simulated clock at 0 has not started (rclcpp waits
    // for a /clock after it), and tf2 answers a lookup at time 0 with the latest transform.
    if scene.start_time == 0 {
        return fail(
            "start_time",
            "0 would stamp the first scan, /map and /tf_static at time 0, which ROS reads as \
             unset (a simulated clock at 0 has not started); use 1 or later",
        );
    }
    if scene.start_time as f64 + scene.duration > LAST_ROS_SECOND as f64 {
        return fail(
            "start_time",
            format!(
                "{} s plus the {} s simulated passes {LAST_ROS_SECOND} (2038-01-19), the last \
                 second a ROS stamp holds",
                scene.start_time, scene.duration
            ),
        );
    }
    Ok(())
}

/// The room's outline; its bounds when it passes.
fn check_room(room: &Room) -> Result<(DVec2, DVec2), (String, String)> {
    polygon("room.outline", &room.outline)?;
    let (lo, hi) = room
        .outline
        .iter()
        .fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(DVec2::from(*p)), hi.max(DVec2::from(*p)))
        });
    let span = hi - lo;
    if span.max_element() > MAX_ROOM_SIDE_M {
        return Err((
            "room.outline".to_string(),
            format!(
                "spans {:.1} m x {:.1} m; at most {MAX_ROOM_SIDE_M} m a side (coordinates are \
                 metres)",
                span.x, span.y
            ),
        ));
    }
    Ok((lo, hi))
}

/// A piece may reach at most [`MAX_ROOM_SIDE_M`] beyond the room's bounds, like the room's
/// own size a limit on typing errors: sizes and coordinates were unbounded, and a box
/// 1e150 m wide was accepted and, at such coordinates, invisible to the Lidar. The key names
/// the point beyond the limit, or else the size (or radius) that takes the piece there.
fn check_furniture_reach(k: &str, f: &Furniture, room_lo: DVec2, room_hi: DVec2) -> Check {
    // Millimetres, or powers of ten for what no room holds.
    let m = |v: f64| {
        if v.abs() < 1e6 {
            format!("{}", (v * 1000.0).round() / 1000.0)
        } else {
            format!("{v:e}")
        }
    };
    let margin = DVec2::splat(MAX_ROOM_SIDE_M);
    let (lo, hi) = (room_lo - margin, room_hi + margin);
    let within = |p: DVec2| p.cmpge(lo).all() && p.cmple(hi).all();
    let piece = if f.name().is_empty() {
        "the piece".to_string()
    } else {
        format!("'{}'", f.name())
    };
    let limit = format!(
        "more than {MAX_ROOM_SIDE_M} m beyond the room, which spans x {} .. {} m, y {} .. {} m \
         (coordinates are metres)",
        m(room_lo.x),
        m(room_hi.x),
        m(room_lo.y),
        m(room_hi.y)
    );
    let (anchors, size_key): (Vec<(String, [f64; 2])>, String) = match f {
        Furniture::Box { center, .. } => {
            (vec![(format!("{k}.center"), *center)], format!("{k}.size"))
        }
        Furniture::Table(l) | Furniture::Chair(l) => {
            (vec![(format!("{k}.center"), l.center)], format!("{k}.size"))
        }
        Furniture::Cylinder { center, .. } => (
            vec![(format!("{k}.center"), *center)],
            format!("{k}.radius"),
        ),
        Furniture::Polygon { points, .. } => (
            points
                .iter()
                .enumerate()
                .map(|(j, p)| (format!("{k}.points[{j}]"), *p))
                .collect(),
            format!("{k}.points"),
        ),
    };
    for (key, p) in anchors {
        if !within(DVec2::from(p)) {
            return fail(
                key,
                format!("{piece} lies at ({}, {}), {limit}", m(p[0]), m(p[1])),
            );
        }
    }
    let (reach_lo, reach_hi) = crate::world::FurnitureShapes::new(f)
        .person_blocks
        .iter()
        .map(|s| s.bounds())
        .fold(
            (DVec2::INFINITY, DVec2::NEG_INFINITY),
            |(lo, hi), (l, h)| (lo.min(l), hi.max(h)),
        );
    if !(within(reach_lo) && within(reach_hi)) {
        return fail(
            size_key,
            format!(
                "{piece} reaches x {} .. {} m, y {} .. {} m, {limit}",
                m(reach_lo.x),
                m(reach_hi.x),
                m(reach_lo.y),
                m(reach_hi.y)
            ),
        );
    }
    Ok(())
}

/// `k` is the piece's key path, `furniture[i]`.
fn check_furniture(k: &str, f: &Furniture) -> Check {
    match f {
        Furniture::Box {
            center,
            size,
            yaw_deg,
            height,
            ..
        } => {
            points(&format!("{k}.center"), &[*center])?;
            positive(&format!("{k}.size[0]"), size[0])?;
            positive(&format!("{k}.size[1]"), size[1])?;
            finite(&format!("{k}.yaw_deg"), *yaw_deg)?;
            positive(&format!("{k}.height"), *height)
        }
        Furniture::Cylinder {
            center,
            radius,
            height,
            ..
        } => {
            points(&format!("{k}.center"), &[*center])?;
            positive(&format!("{k}.radius"), *radius)?;
            positive(&format!("{k}.height"), *height)
        }
        Furniture::Polygon {
            points: pts,
            height,
            ..
        } => {
            polygon(&format!("{k}.points"), pts)?;
            positive(&format!("{k}.height"), *height)
        }
        Furniture::Table(l) | Furniture::Chair(l) => check_legged(k, l),
    }
}

fn check_legged(k: &str, l: &Legged) -> Check {
    points(&format!("{k}.center"), &[l.center])?;
    positive(&format!("{k}.size[0]"), l.size[0])?;
    positive(&format!("{k}.size[1]"), l.size[1])?;
    finite(&format!("{k}.yaw_deg"), l.yaw_deg)?;
    positive(&format!("{k}.height"), l.height)?;
    positive(&format!("{k}.leg_radius"), l.leg_radius)?;
    in_range(&format!("{k}.leg_inset"), l.leg_inset, 0.0, f64::MAX)?;
    for (axis, s) in l.size.iter().enumerate() {
        if 2.0 * (l.leg_inset + l.leg_radius) > *s {
            return fail(
                format!("{k}.size[{axis}]"),
                format!(
                    "{s} m is too small for legs of radius {} set in by {} m",
                    l.leg_radius, l.leg_inset
                ),
            );
        }
    }
    Ok(())
}

/// A piece that does not even touch the floor is a typing error (a sign or a decimal point
/// off): it would be planned around and drawn on the map while nothing in the room can meet
/// it. A piece that only touches a wall from outside is left alone: that needs no tolerance,
/// so no piece reaching into the room by a rounding error is ever refused.
fn check_furniture_in_room(world: &World) -> Check {
    for (i, f) in world.furniture.iter().enumerate() {
        if !f.person_blocks.iter().any(|s| world.meets_floor(s)) {
            return fail(
                format!("furniture[{i}]"),
                format!(
                    "{} lies wholly outside the room",
                    if f.name.is_empty() {
                        "the piece".to_string()
                    } else {
                        format!("'{}'", f.name)
                    }
                ),
            );
        }
    }
    Ok(())
}

/// How far inside the robot's rim the Lidar must sit, metres.
const LIDAR_RIM_MARGIN: f64 = 0.02;

/// The robot's own values; where it starts and drives needs the room ([`check_robot_start`]).
fn check_robot(r: &RobotSpec) -> Check {
    positive("robot.radius", r.radius)?;
    in_range("robot.lidar_height", r.lidar_height, 0.01, 3.0)?;
    finite("robot.lidar_mount.x", r.lidar_mount.x)?;
    finite("robot.lidar_mount.y", r.lidar_mount.y)?;
    finite("robot.lidar_mount.yaw_deg", r.lidar_mount.yaw_deg)?;
    // The Lidar sits on the robot, inside its footprint. The start check and the planner keep
    // that disc clear of walls and furniture, so the scans are then always cast from the
    // floor of the room; a Lidar mounted further out could scan from inside a cupboard or
    // from beyond a wall. The planner lets the disc graze an obstacle by up to a centimetre
    // (`robot::ENTRY_TOLERANCE`), hence the margin.
    let offset = r.lidar_mount.x.hypot(r.lidar_mount.y);
    let reach = (r.radius - LIDAR_RIM_MARGIN).max(0.0);
    if offset > reach {
        return fail(
            "robot.lidar_mount",
            format!(
                "({}, {}) is {offset:.3} m from the robot's centre; the Lidar must sit on the \
                 robot, {LIDAR_RIM_MARGIN} m inside its radius ({} m)",
                r.lidar_mount.x, r.lidar_mount.y, r.radius
            ),
        );
    }
    finite("robot.start.x", r.start.x)?;
    finite("robot.start.y", r.start.y)?;
    finite("robot.start.yaw_deg", r.start.yaw_deg)?;
    positive("robot.speed", r.speed)?;
    if r.speed > MAX_ROBOT_SPEED {
        return fail(
            "robot.speed",
            format!(
                "at most {MAX_ROBOT_SPEED} m/s (the paper's robot), got {}",
                r.speed
            ),
        );
    }
    positive("robot.turn_rate_deg", r.turn_rate_deg)
}

/// The slowest Lidar: a rotation of 10 s. Slower rates turn every scan into a long smear of
/// the robot's and the person's motion, and a typo such as `1e-9` gave `scan_time` 1e9 s.
pub const MIN_LIDAR_RATE_HZ: f64 = 0.1;

/// The smallest `range_min`, metres: real Lidars' are centimetres, and a tiny value such as
/// `1e-300` rounds to 0 in the LaserScan's f32, where 0 reads as "every range is valid".
pub const MIN_RANGE_MIN_M: f64 = 1e-3;

fn check_lidar(l: &LidarSpec) -> Check {
    positive("lidar.rate_hz", l.rate_hz)?;
    if l.rate_hz < MIN_LIDAR_RATE_HZ {
        return fail(
            "lidar.rate_hz",
            format!("at least {MIN_LIDAR_RATE_HZ} Hz, got {:?}", l.rate_hz),
        );
    }
    if l.rate_hz > 1000.0 {
        return fail(
            "lidar.rate_hz",
            format!("at most 1000 Hz, got {}", l.rate_hz),
        );
    }
    if l.beams == 0 || l.beams > 100_000 {
        return fail(
            "lidar.beams",
            format!("must be within [1, 100000], got {}", l.beams),
        );
    }
    in_range("lidar.range_min", l.range_min, 0.0, 1e4)?;
    // A Lidar inside furniture or the person measures 0 on every beam; range_min is what
    // turns that into no return, so 0 would record scans of zeros.
    if l.range_min == 0.0 {
        return fail(
            "lidar.range_min",
            "must be positive: a Lidar inside furniture or the person measures 0, which \
             must read as no return",
        );
    }
    if l.range_min < MIN_RANGE_MIN_M {
        return fail(
            "lidar.range_min",
            format!("at least {MIN_RANGE_MIN_M} m, got {:?}", l.range_min),
        );
    }
    in_range("lidar.range_max", l.range_max, 0.0, 1e6)?;
    if l.range_max <= l.range_min {
        return fail(
            "lidar.range_max",
            format!(
                "must exceed range_min ({}), got {}",
                l.range_min, l.range_max
            ),
        );
    }
    check_noise(&l.noise)
}

fn check_noise(n: &NoiseSpec) -> Check {
    in_range("lidar.noise.distance_pct", n.distance_pct, 0.0, 100.0)?;
    in_range("lidar.noise.missing_pct", n.missing_pct, 0.0, 100.0)?;
    in_range("lidar.noise.wrong_pct", n.wrong_pct, 0.0, 100.0)?;
    if n.missing_pct + n.wrong_pct > 100.0 {
        return fail(
            "lidar.noise.wrong_pct",
            format!(
                "missing_pct + wrong_pct must not exceed 100, got {}",
                n.missing_pct + n.wrong_pct
            ),
        );
    }
    in_range("lidar.noise.angle_deg", n.angle_deg, 0.0, 10.0)?;
    in_range(
        "lidar.noise.wrong_spread_deg",
        n.wrong_spread_deg,
        0.0,
        180.0,
    )
}

/// Where the robot starts, against the room and furniture.
fn check_robot_start(world: &World, r: &RobotSpec) -> Check {
    let (clear, what) = world.robot_clearance(r.start.to_pose().position());
    if clear < r.radius {
        return fail(
            "robot.start",
            format!(
                "the robot (radius {} m) starts {}",
                r.radius,
                place(world, clear, what, "overlapping")
            ),
        );
    }
    Ok(())
}

/// The motion's values; waypoints must leave the robot room to stand.
fn check_robot_motion(world: &World, r: &RobotSpec) -> Check {
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
                    return fail(
                        format!("robot.motion.points[{i}]"),
                        format!(
                            "the robot (radius {} m) cannot stand here: {}",
                            r.radius,
                            place(world, clear, what, "it would touch")
                        ),
                    );
                }
            }
        }
        Motion::Coverage { spacing, .. } => {
            in_range("robot.motion.spacing", *spacing, 0.05, 100.0)?
        }
        Motion::Bounce { runs } => {
            if *runs == 0 || *runs > MAX_BOUNCE_RUNS {
                return fail(
                    "robot.motion.runs",
                    format!(
                        "must be within [1, {MAX_BOUNCE_RUNS}] (every run is planned when the \
                         simulation starts), got {runs}"
                    ),
                );
            }
        }
    }
    Ok(())
}

fn check_person(world: &World, p: &PersonSpec) -> Check {
    check_body(&p.body)?;
    finite("person.start.x", p.start.x)?;
    finite("person.start.y", p.start.y)?;
    finite("person.start.yaw_deg", p.start.yaw_deg)?;
    let (clear, what) = world.person_clearance(p.start.to_pose().position());
    if clear < PERSON_START_CLEARANCE {
        return fail(
            "person.start",
            format!(
                "the person starts {}",
                place(world, clear, what, "too close to")
            ),
        );
    }
    if p.script.is_empty() {
        return fail("person.script", "needs at least one step");
    }
    if p.script[0].activity == Activity::SittingOnFloor && clear < SEATED_START_CLEARANCE {
        return fail(
            "person.script[0]",
            format!(
                "sitting on the floor from the start needs {SEATED_START_CLEARANCE} m around \
                 person.start; it is {clear:.2} m from {}",
                describe(world, what)
            ),
        );
    }
    for (i, s) in p.script.iter().enumerate() {
        check_script_step(world, &format!("person.script[{i}]"), s)?;
    }
    Ok(())
}

fn check_body(b: &BodySpec) -> Check {
    in_range("person.body.height", b.height, 0.5, 2.5)?;
    in_range("person.body.girth", b.girth, 0.3, 3.0)?;
    in_range("person.body.pace", b.pace, 0.3, 3.0)?;
    in_range("person.body.stride", b.stride, 0.3, 3.0)?;
    in_range("person.body.sway", b.sway, 0.0, 5.0)?;
    in_range("person.body.variation", b.variation, 0.0, 0.3)
}

/// `k` is the step's key path, `person.script[i]`.
fn check_script_step(world: &World, k: &str, s: &ScriptStep) -> Check {
    in_range(&format!("{k}.duration"), s.duration, 1e-3, 1e7)?;
    match s.activity {
        Activity::FallingDown => in_range(&format!("{k}.duration"), s.duration, 0.4, 5.0)?,
        Activity::GettingUp => in_range(&format!("{k}.duration"), s.duration, 0.8, 15.0)?,
        _ => {}
    }
    if let Some(v) = s.speed {
        in_range(&format!("{k}.speed"), v, 0.01, 8.0)?;
    }
    if is_locomotion(s.activity) {
        if s.path.is_empty() {
            return fail(
                format!("{k}.path"),
                format!("{} needs a path of at least one point", s.activity),
            );
        }
    } else if !s.path.is_empty() {
        return fail(
            format!("{k}.path"),
            format!("{} does not move along a path", s.activity),
        );
    }
    if s.speed.is_some() && !is_locomotion(s.activity) {
        return fail(
            format!("{k}.speed"),
            format!(
                "{} does not move along a path, so it has no speed",
                s.activity
            ),
        );
    }
    if s.fall.is_some() && s.activity != Activity::FallingDown {
        return fail(
            format!("{k}.fall"),
            "only a falling_down step has a fall direction",
        );
    }
    points(&format!("{k}.path"), &s.path)?;
    for (j, q) in s.path.iter().enumerate() {
        let (clear, what) = world.person_clearance(DVec2::new(q[0], q[1]));
        if clear < PERSON_START_CLEARANCE {
            return fail(
                format!("{k}.path[{j}]"),
                place(world, clear, what, "too close to"),
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::scene::Scene;

    const BASE: &str = "duration: 5\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nfurniture:\n  - {kind: box, name: sofa, center: [2.5, 2], size: [1, 1], height: 0.8}\n  - {kind: table, center: [1, 3], size: [1, 0.6], height: 0.7}\n";

    fn error(text: &str) -> String {
        Scene::parse(text, "bad.yaml")
            .expect_err("the scene must be rejected")
            .to_string()
    }

    fn with(robot: &str, rest: &str) -> String {
        format!("{BASE}robot: {robot}\n{rest}")
    }

    #[test]
    fn yaml_that_does_not_parse_is_named_once_and_where() {
        let cases = [
            ("duration: [1,\n", "bad.yaml: duration: invalid type"),
            (
                "room:\n  outline: [[0,0],[4,0]]\n  foo: 1\n",
                "bad.yaml: room.foo: unknown field `foo`",
            ),
            (
                "room: {outline: [[0,0],[4,0]]\nduration: 3\n",
                "bad.yaml: YAML syntax: did not find expected ',' or '}' at line 2",
            ),
        ];
        for (text, want) in cases {
            let got = error(text);
            assert!(got.starts_with(want), "{text:?}: {got}");
        }
    }

    #[test]
    fn each_bad_value_names_its_key() {
        let ok_robot = "{start: {x: 0.5, y: 0.5}}";
        let cases = [
            (
                with(ok_robot, "lidar: {rate_hz: 0}"),
                "bad.yaml: lidar.rate_hz: must be positive",
            ),
            (
                with(ok_robot, "lidar: {noise: {missing_pct: 120}}"),
                "lidar.noise.missing_pct: must be within [0, 100]",
            ),
            (
                with(ok_robot, "lidar: {noise: {missing_pct: 60, wrong_pct: 50}}"),
                "lidar.noise.wrong_pct: missing_pct + wrong_pct",
            ),
            (
                with(ok_robot, "lidar: {range_min: 2, range_max: 1}"),
                "lidar.range_max: must exceed range_min",
            ),
            (with(ok_robot, "lidar: {beams: 0}"), "lidar.beams"),
            (
                with("{start: {x: 2.5, y: 2}}", ""),
                "robot.start: the robot (radius 0.17 m) starts inside furniture[0] 'sofa'",
            ),
            (
                with("{start: {x: 1.85, y: 2}}", ""),
                "robot.start: the robot (radius 0.17 m) starts overlapping furniture[0] 'sofa'",
            ),
            (
                with("{start: {x: 7, y: 2}}", ""),
                "robot.start: the robot (radius 0.17 m) starts outside the room",
            ),
            (
                with("{start: {x: 0.5, y: 0.5}, speed: 0.5}", ""),
                "robot.speed: at most 0.2",
            ),
            (
                with(
                    "{start: {x: 0.5, y: 0.5}, motion: {kind: waypoints, points: [[0.5, 0.5], [2.5, 2.2]]}}",
                    "",
                ),
                "robot.motion.points[1]",
            ),
            (
                with(
                    ok_robot,
                    "person: {start: {x: 1, y: 3}, script: [{activity: standing, duration: 1}]}",
                ),
                "person.start: the person starts inside furniture[1]",
            ),
            (
                with(ok_robot, "person: {start: {x: 4, y: 1}, script: []}"),
                "person.script: needs at least one step",
            ),
            (
                with(
                    ok_robot,
                    "person: {start: {x: 4, y: 1}, script: [{activity: walking, duration: 3}]}",
                ),
                "person.script[0].path: walking needs a path",
            ),
            (
                with(
                    ok_robot,
                    "person: {start: {x: 4, y: 1}, script: [{activity: standing, duration: -3}]}",
                ),
                "person.script[0].duration",
            ),
            (
                with(
                    ok_robot,
                    "person: {start: {x: 4, y: 1}, script: [{activity: falling_down, duration: 9}]}",
                ),
                "person.script[0].duration: must be within [0.4, 5]",
            ),
            (
                with(
                    ok_robot,
                    "person: {start: {x: 4, y: 1}, body: {height: 4}, script: [{activity: standing, duration: 1}]}",
                ),
                "person.body.height",
            ),
            (
                format!("{BASE}robot: {ok_robot}\nfurniture: []\n"),
                "duplicate",
            ),
        ];
        for (text, expect) in cases {
            let e = error(&text);
            assert!(e.contains(expect), "expected `{expect}` in `{e}`");
        }
    }

    #[test]
    fn points_outside_the_room_or_inside_furniture_say_so() {
        let ok_robot = "{start: {x: 0.5, y: 0.5}}";
        let walk = |x: f64, y: f64| {
            with(
                ok_robot,
                &format!(
                    "person: {{start: {{x: 4, y: 1}}, script: [{{activity: walking, duration: 5, path: [[{x}, {y}]]}}]}}"
                ),
            )
        };
        let drive = |x: f64, y: f64| {
            with(
                &format!(
                    "{{start: {{x: 0.5, y: 0.5}}, motion: {{kind: waypoints, points: [[{x}, {y}]]}}}}"
                ),
                "",
            )
        };
        let cases = [
            (
                walk(-20.0, 2.0),
                "person.script[0].path[0]: outside the room",
            ),
            (
                walk(2.5, 2.0),
                "person.script[0].path[0]: inside furniture[0] 'sofa'",
            ),
            (
                walk(1.95, 2.0),
                "person.script[0].path[0]: too close to furniture[0] 'sofa'",
            ),
            (
                drive(50.0, 3.0),
                "robot.motion.points[0]: the robot (radius 0.17 m) cannot stand here: outside \
                 the room",
            ),
            (
                drive(2.5, 2.0),
                "robot.motion.points[0]: the robot (radius 0.17 m) cannot stand here: inside \
                 furniture[0] 'sofa'",
            ),
            (
                drive(1.9, 2.0),
                "robot.motion.points[0]: the robot (radius 0.17 m) cannot stand here: it would \
                 touch furniture[0] 'sofa'",
            ),
        ];
        for (text, expect) in cases {
            assert_eq!(error(&text), format!("bad.yaml: {expect}"));
        }
    }

    #[test]
    fn an_outline_that_repeats_its_first_point_says_so() {
        let e = error(
            "duration: 1\nroom: {outline: [[0,0],[5,0],[5,4],[0,4],[0,0]]}\nrobot: {start: {x: 0.5, y: 0.5}}\n",
        );
        assert_eq!(
            e,
            "bad.yaml: room.outline[4]: repeats the first point: list each corner once, the \
             last edge back to the first point is implied"
        );
    }

    /// A room far from the origin was refused as having no area.
    #[test]
    fn a_room_far_from_the_origin_has_its_area() {
        for outline in [
            "[[1e9,1e9],[1000000005,1e9],[1000000005,1000000004],[1e9,1000000004]]",
            "[[1e9,1e9],[1e9,1000000004],[1000000005,1000000004],[1000000005,1e9]]",
        ] {
            accepted(&format!(
                "duration: 1\nroom: {{outline: {outline}}}\n\
                 robot: {{start: {{x: 1000000001, y: 1000000001}}}}\n"
            ));
        }
        let e = error(
            "duration: 1\nroom: {outline: [[1e9,1e9],[1000000005,1e9],[1000000010,1e9]]}\n\
             robot: {start: {x: 1000000001, y: 1e9}}\n",
        );
        assert_eq!(e, "bad.yaml: room.outline: the polygon has no area");
    }

    #[test]
    fn lidar_values_too_small_for_a_laser_scan_are_refused() {
        let ok_robot = "{start: {x: 0.5, y: 0.5}}";
        assert_eq!(
            error(&with(ok_robot, "lidar: {range_min: 1e-300}")),
            "bad.yaml: lidar.range_min: at least 0.001 m, got 1e-300"
        );
        assert_eq!(
            error(&with(ok_robot, "lidar: {rate_hz: 0.05}")),
            "bad.yaml: lidar.rate_hz: at least 0.1 Hz, got 0.05"
        );
        assert_eq!(
            error(&with(ok_robot, "lidar: {rate_hz: 1e-9}")),
            "bad.yaml: lidar.rate_hz: at least 0.1 Hz, got 1e-9"
        );
        accepted(&with(ok_robot, "lidar: {rate_hz: 0.1, range_min: 0.001}"));
    }

    fn accepted(text: &str) {
        if let Err(e) = Scene::parse(text, "good.yaml") {
            panic!("must be accepted: {e}\n{text}");
        }
    }

    #[test]
    fn bounce_runs_are_capped() {
        let robot = |runs: &str| {
            with(
                &format!("{{start: {{x: 0.5, y: 0.5}}, motion: {{kind: bounce, runs: {runs}}}}}"),
                "",
            )
        };
        let e = error(&robot("4000000000"));
        assert!(
            e.starts_with("bad.yaml: robot.motion.runs: must be within [1, 100000]")
                && e.ends_with("got 4000000000"),
            "{e}"
        );
        assert!(error(&robot("0")).contains("robot.motion.runs"));
        accepted(&robot("100000"));
    }

    #[test]
    fn the_lidar_must_sit_on_the_robot() {
        let e = error(&with(
            "{start: {x: 1, y: 1}, lidar_mount: {x: 10, y: 0}}",
            "",
        ));
        assert!(
            e.starts_with("bad.yaml: robot.lidar_mount: (10, 0) is 10.000 m from the robot's")
                && e.contains("0.02 m inside its radius (0.17 m)"),
            "{e}"
        );
        let e = error(&with(
            "{start: {x: 1, y: 1}, radius: 0.1, lidar_mount: {x: 0.08, y: -0.08}}",
            "",
        ));
        assert!(
            e.contains("robot.lidar_mount: (0.08, -0.08) is 0.113 m"),
            "{e}"
        );
        // On the rim: the disc may graze a wall, and the Lidar would be past it.
        let e = error(&with(
            "{start: {x: 1, y: 1}, lidar_mount: {x: 0.17, y: 0}}",
            "",
        ));
        assert!(e.contains("robot.lidar_mount: (0.17, 0) is 0.170 m"), "{e}");
        accepted(&with(
            "{start: {x: 1, y: 1}, lidar_mount: {x: 0.15, y: 0}}",
            "",
        ));
        accepted(&with(
            "{start: {x: 1, y: 1}, lidar_mount: {x: 0.1, y: 0, yaw_deg: 90}}",
            "",
        ));
        accepted(&with(
            "{start: {x: 1, y: 1}, lidar_mount: {x: 0, y: -0.15}}",
            "",
        ));
    }

    #[test]
    fn furniture_wholly_outside_the_room_is_refused() {
        let room = |piece: &str| {
            format!(
                "duration: 5\nroom: {{outline: [[0,0],[5,0],[5,4],[0,4]]}}\nfurniture:\n  - \
                 {{kind: box, center: [4, 3], size: [1, 1], height: 1}}\n  - {piece}\nrobot: \
                 {{start: {{x: 1, y: 1}}}}\n"
            )
        };
        let cases = [
            (
                "{kind: box, name: sofa, center: [12, 2], size: [2, 1], height: 0.8}",
                "bad.yaml: furniture[1]: 'sofa' lies wholly outside the room",
            ),
            (
                "{kind: cylinder, center: [-3, -3], radius: 0.3, height: 1}",
                "bad.yaml: furniture[1]: the piece lies wholly outside the room",
            ),
            (
                "{kind: polygon, points: [[6, 0], [7, 0], [6, 1]], height: 1}",
                "bad.yaml: furniture[1]: the piece lies wholly outside",
            ),
            (
                "{kind: table, center: [2.5, -1], size: [1, 1.9], height: 0.7}",
                "bad.yaml: furniture[1]: the piece lies wholly outside",
            ),
        ];
        for (piece, want) in cases {
            let e = error(&room(piece));
            assert!(e.starts_with(want), "{piece}: {e}");
        }
        for piece in [
            // Partly outside, across a wall, along the walls, touching one from outside.
            "{kind: box, center: [5, 2], size: [1, 1], height: 1}",
            "{kind: box, center: [2.5, 2], size: [0.3, 9], height: 1}",
            "{kind: box, center: [2.5, 3.7], size: [5, 0.6], height: 1}",
            "{kind: cylinder, center: [2.5, -0.3], radius: 0.3, height: 1}",
            "{kind: chair, center: [-0.25, 2], size: [0.5, 0.5], height: 0.45}",
        ] {
            accepted(&room(piece));
        }
    }

    #[test]
    fn a_script_that_starts_sitting_on_the_floor_needs_room_to_sit() {
        let sitting = |x: f64| {
            format!(
                "duration: 5\nroom: {{outline: [[0,0],[5,0],[5,4],[0,4]]}}\nrobot: {{start: {{x: 4.5, y: 3.5}}}}\nperson: {{start: {{x: {x}, y: 2}}, script: [{{activity: sitting_on_floor, duration: 5}}]}}\n"
            )
        };
        assert_eq!(
            error(&sitting(0.3)),
            "bad.yaml: person.script[0]: sitting on the floor from the start needs 0.6 m around \
             person.start; it is 0.30 m from a wall"
        );
        accepted(&sitting(0.6));
    }

    #[test]
    fn range_min_must_be_positive() {
        let e = error(&with("{start: {x: 1, y: 1}}", "lidar: {range_min: 0}"));
        assert!(
            e.starts_with("bad.yaml: lidar.range_min: must be positive: a Lidar inside"),
            "{e}"
        );
        accepted(&with("{start: {x: 1, y: 1}}", "lidar: {range_min: 0.01}"));
    }

    #[test]
    fn only_steps_that_move_have_a_speed() {
        let step = |s: &str| {
            with(
                "{start: {x: 0.5, y: 0.5}}",
                &format!("person: {{start: {{x: 4, y: 1}}, script: [{s}]}}"),
            )
        };
        for (s, want) in [
            (
                "{activity: standing, duration: 1, speed: 2}",
                "bad.yaml: person.script[0].speed: standing does not move along a path, so it \
                 has no speed",
            ),
            (
                "{activity: falling_down, duration: 1, speed: 1}",
                "bad.yaml: person.script[0].speed: falling_down does not move",
            ),
        ] {
            let e = error(&step(s));
            assert!(e.starts_with(want), "{s}: {e}");
        }
        accepted(&step(
            "{activity: walking, duration: 2, path: [[4, 3]], speed: 2}",
        ));
    }

    #[test]
    fn negative_size_and_unknown_keys_name_their_path() {
        let neg = "duration: 5\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nfurniture:\n  - {kind: cylinder, center: [4, 3], radius: 0.2, height: 1}\n  - {kind: box, center: [2, 2], size: [1, 1], height: 1}\n  - {kind: box, center: [2, 2], size: [-1, 1], height: 1}\nrobot: {start: {x: 0.5, y: 0.5}}\n";
        assert!(
            error(neg).contains("furniture[2].size[0]: must be positive, got -1"),
            "{}",
            error(neg)
        );
        let unknown = "duration: 5\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nfurniture:\n  - {kind: box, center: [2, 2], size: [1, 1], height: 1, colour: red}\nrobot: {start: {x: 0.5, y: 0.5}}\n";
        let e = error(unknown);
        assert!(
            e.contains("furniture[0]") && e.contains("unknown field `colour`"),
            "{e}"
        );
        let nested = "duration: 5\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nrobot: {start: {x: 0.5, y: 0.5}, lidar_hieght: 0.2}\n";
        let e = error(nested);
        assert!(
            e.contains("robot") && e.contains("unknown field `lidar_hieght`"),
            "{e}"
        );
        let kind = "duration: 5\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nfurniture: [{kind: sofa, center: [1, 1]}]\nrobot: {start: {x: 0.5, y: 0.5}}\n";
        assert!(
            error(kind).contains("furniture[0]") && error(kind).contains("sofa"),
            "{}",
            error(kind)
        );
        let activity = "duration: 5\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nrobot: {start: {x: 0.5, y: 0.5}}\nperson: {start: {x: 3, y: 3}, script: [{activity: dancing, duration: 1}]}\n";
        let e = error(activity);
        assert!(
            e.contains("person.script[0].activity") && e.contains("dancing"),
            "{e}"
        );
        let nan = "duration: .nan\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nrobot: {start: {x: 0.5, y: 0.5}}\n";
        assert!(
            error(nan).contains("duration: must be a finite number"),
            "{}",
            error(nan)
        );
        let bow = "duration: 5\nroom: {outline: [[0,0],[5,4],[5,0],[0,4]]}\nrobot: {start: {x: 0.5, y: 0.5}}\n";
        assert!(error(bow).contains("room.outline: edges"), "{}", error(bow));
        let millimetres = "duration: 5\nroom: {outline: [[0,0],[6000,0],[6000,4500],[0,4500]]}\nrobot: {start: {x: 500, y: 500}}\n";
        assert!(
            error(millimetres).contains("room.outline: spans 6000.0 m x 4500.0 m"),
            "{}",
            error(millimetres)
        );
        let late = "duration: 5\nstart_time: 2200000000\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nrobot: {start: {x: 0.5, y: 0.5}}\n";
        assert!(
            error(late).contains("start_time: 2200000000 s"),
            "{}",
            error(late)
        );
        let zero = "duration: 5\nstart_time: 0\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nrobot: {start: {x: 0.5, y: 0.5}}\n";
        assert!(
            error(zero).contains("start_time: 0 would stamp"),
            "{}",
            error(zero)
        );
        assert!(error("").contains("bad.yaml"), "{}", error(""));
        assert!(error("duration: [1").contains("bad.yaml"));
    }

    /// Furniture sizes and coordinates were unbounded: a box 1e150 m wide was accepted, and
    /// the Lidar saw straight through it.
    #[test]
    fn furniture_reaching_far_beyond_the_room_is_refused() {
        let scene = |piece: &str| {
            format!(
                "duration: 5\nroom: {{outline: [[0,0],[6,0],[6,4],[0,4]]}}\nfurniture: [{piece}]\nrobot: {{start: {{x: 3, y: 1.5}}}}\n"
            )
        };
        let room = "more than 200 m beyond the room, which spans x 0 .. 6 m, y 0 .. 4 m \
                    (coordinates are metres)";
        for (piece, want) in [
            (
                "{kind: box, name: wall unit, center: [3, 3.4], size: [1e150, 0.8], height: 0.8}",
                format!(
                    "furniture[0].size: 'wall unit' reaches x -5e149 .. 5e149 m, y 3 .. 3.8 m, \
                     {room}"
                ),
            ),
            (
                "{kind: table, center: [3, 3.4], size: [0.8, 1e4], yaw_deg: 90, height: 0.8}",
                format!(
                    "furniture[0].size: the piece reaches x -4997 .. 5003 m, y 3 .. 3.8 m, \
                     {room}"
                ),
            ),
            (
                "{kind: cylinder, center: [3, 3.4], radius: 300, height: 1}",
                format!(
                    "furniture[0].radius: the piece reaches x -297 .. 303 m, y -296.6 .. 303.4 m, {room}"
                ),
            ),
            (
                "{kind: box, center: [3, 1e200], size: [1, 1], height: 0.8}",
                format!("furniture[0].center: the piece lies at (3, 1e200), {room}"),
            ),
            (
                "{kind: polygon, points: [[5, 3], [6, 3], [5, -300]], height: 1}",
                format!("furniture[0].points[2]: the piece lies at (5, -300), {room}"),
            ),
        ] {
            let got = error(&scene(piece));
            assert!(got.ends_with(&want), "{piece}:\n{got}\nwant: {want}");
        }
        // Up to 200 m beyond the room is a piece like any other.
        Scene::parse(
            &scene("{kind: box, center: [105.5, 3.6], size: [200, 0.4], height: 0.8}"),
            "t",
        )
        .unwrap();
    }
}
