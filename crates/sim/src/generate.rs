//! Random furnished rooms, so that a model can be trained on more rooms than anyone drew by
//! hand (the seven scenes of `config/scenes/` are few, and accuracy in a room never seen in
//! training lags the rooms trained on).
//!
//! A room is a rectangle or an L, 2.5-7 m a side; furniture of every kind the scene format
//! has (beds, sofas and cupboards against the walls, tables with chairs, islands, plant pots,
//! pillars) is placed at random where it overlaps nothing, as long as the floor a person can
//! walk on stays one connected area of at least half the room. The robot starts at a free
//! spot and drives one of the scene format's motions. The person is a random body standing
//! at a free spot: `lidar-har dataset` and `lidar-har alerts` write their own scripts.
//! Every scene is checked as a scene file is ([`Scene::validate`]) and by building its
//! simulator (the robot's path is planned), so what this returns runs.

use glam::DVec2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::scene::{
    BodySpec, Furniture, Legged, LidarSpec, Motion, PersonSpec, PoseSpec, RobotSpec, Room, Scene,
    ScriptStep,
};
use crate::shapes::Shape;
use crate::world::World;
use crate::{SceneError, Simulator};
use lidar_har_core::activity::Activity;

/// Rooms that fail the checks are drawn again, at most this many times.
const ATTEMPTS: usize = 50;
/// Grid step of the floor checks (m).
const CELL_M: f64 = 0.1;
/// A person needs this much room around their centre to pass between pieces (m).
const PASSAGE_M: f64 = 0.3;
/// Share of the room's floor that must stay walkable.
const MIN_WALKABLE: f64 = 0.5;
/// Share of the walkable floor that must be one connected area (no closed-off pockets).
const MIN_CONNECTED: f64 = 0.95;

/// A random furnished room with a robot and a person, named `random_<seed>`; the same seed
/// gives the same scene.
pub fn random_scene(seed: u64) -> Result<Scene, SceneError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0000_700b_5eed);
    let mut last_error = None;
    for _ in 0..ATTEMPTS {
        let Some(scene) = draw_scene(&mut rng, seed) else {
            continue;
        };
        match Simulator::new(scene.clone(), seed) {
            Ok(_) => return Ok(scene),
            Err(e) => last_error = Some(e),
        }
    }
    Err(SceneError::Invalid {
        origin: format!("random scene {seed}"),
        key: "(generator)".to_string(),
        message: match last_error {
            Some(e) => format!("no valid room in {ATTEMPTS} draws; the last was refused: {e}"),
            None => format!("no valid room in {ATTEMPTS} draws"),
        },
    })
}

fn draw_scene(rng: &mut ChaCha8Rng, seed: u64) -> Option<Scene> {
    let outline = draw_outline(rng);
    let mut scene = Scene {
        name: format!("random_{seed}"),
        duration: 60.0,
        seed,
        start_time: crate::scene::DEFAULT_START_TIME,
        room: Room {
            outline: outline.iter().map(|p| [p.x, p.y]).collect(),
        },
        furniture: Vec::new(),
        robot: RobotSpec {
            radius: 0.17,
            lidar_height: crate::scene::DEFAULT_LIDAR_HEIGHT,
            lidar_mount: PoseSpec::default(),
            start: PoseSpec::default(),
            speed: crate::scene::MAX_ROBOT_SPEED,
            turn_rate_deg: 90.0,
            motion: Motion::Static,
        },
        lidar: LidarSpec::default(),
        person: None,
    };
    let area = polygon_area(&outline);
    let wanted = ((area / 3.0).round() as usize).clamp(2, 12);
    let mut tries = 0;
    while scene.furniture.len() < wanted && tries < 40 * wanted {
        tries += 1;
        let pieces = draw_pieces(rng, &outline, scene.furniture.len());
        if pieces.is_empty() || !fits(&scene, &pieces) {
            continue;
        }
        let before = scene.furniture.len();
        scene.furniture.extend(pieces);
        if !floor_is_open(&scene) {
            scene.furniture.truncate(before);
        }
    }
    let world = World::new(&scene);
    let robot_start = free_spot(rng, &outline, 0.35, |p| world.robot_clearance(p).0)?;
    scene.robot.start = PoseSpec {
        x: robot_start.x,
        y: robot_start.y,
        yaw_deg: rng.random_range(-180.0..180.0),
    };
    scene.robot.motion = match rng.random_range(0..10) {
        0 => Motion::Static,
        1..=4 => Motion::Bounce { runs: 40 },
        5..=7 => Motion::Coverage {
            spacing: rng.random_range(0.3..0.5),
            along_y: rng.random_bool(0.5),
        },
        _ => Motion::Waypoints {
            points: (0..rng.random_range(3..6))
                .filter_map(|_| free_spot(rng, &outline, 0.35, |p| world.robot_clearance(p).0))
                .map(|p| [p.x, p.y])
                .collect(),
            repeat: true,
        },
    };
    let person_start = free_spot(rng, &outline, 0.6, |p| world.person_clearance(p).0)?;
    scene.person = Some(PersonSpec {
        body: BodySpec {
            height: rng.random_range(1.5..1.95),
            girth: rng.random_range(0.85..1.2),
            ..BodySpec::default()
        },
        start: PoseSpec {
            x: person_start.x,
            y: person_start.y,
            yaw_deg: rng.random_range(-180.0..180.0),
        },
        script: vec![ScriptStep {
            activity: Activity::Standing,
            duration: 5.0,
            path: Vec::new(),
            speed: None,
            fall: None,
        }],
        repeat: false,
    });
    tidy(&mut scene);
    // Rounding moves pieces by millimetres: check the floor again on what is written (the
    // scene checks run when `random_scene` builds its simulator).
    floor_is_open(&scene).then_some(scene)
}

/// Centimetres and tenths of a degree: the file stays readable, and every piece keeps the
/// clearances it was placed with (5 cm to other pieces, 1 cm to walls) within a few mm.
fn tidy(scene: &mut Scene) {
    let cm = |v: &mut f64| *v = (*v * 100.0).round() / 100.0;
    let deg = |v: &mut f64| *v = (*v * 10.0).round() / 10.0;
    let pose = |p: &mut PoseSpec| {
        cm(&mut p.x);
        cm(&mut p.y);
        deg(&mut p.yaw_deg);
    };
    scene.room.outline.iter_mut().flatten().for_each(cm);
    for f in &mut scene.furniture {
        match f {
            Furniture::Box {
                center,
                size,
                yaw_deg,
                height,
                ..
            } => {
                center.iter_mut().chain(size.iter_mut()).for_each(cm);
                deg(yaw_deg);
                cm(height);
            }
            Furniture::Cylinder {
                center,
                radius,
                height,
                ..
            } => {
                center.iter_mut().for_each(cm);
                cm(radius);
                cm(height);
            }
            Furniture::Polygon { points, height, .. } => {
                points.iter_mut().flatten().for_each(cm);
                cm(height);
            }
            Furniture::Table(l) | Furniture::Chair(l) => {
                l.center.iter_mut().chain(l.size.iter_mut()).for_each(cm);
                deg(&mut l.yaw_deg);
                cm(&mut l.height);
                cm(&mut l.leg_radius);
            }
        }
    }
    pose(&mut scene.robot.start);
    match &mut scene.robot.motion {
        Motion::Waypoints { points, .. } => points.iter_mut().flatten().for_each(cm),
        Motion::Coverage { spacing, .. } => cm(spacing),
        Motion::Static | Motion::Bounce { .. } => {}
    }
    if let Some(person) = &mut scene.person {
        pose(&mut person.start);
        cm(&mut person.body.height);
        cm(&mut person.body.girth);
    }
}

/// A rectangle, or an L (a rectangle with one corner cut out), counter-clockwise from the
/// origin.
fn draw_outline(rng: &mut ChaCha8Rng) -> Vec<DVec2> {
    let w = rng.random_range(2.5..7.0);
    let d = rng.random_range(2.5..6.0);
    if w >= 4.0 && d >= 4.0 && rng.random_bool(0.3) {
        let nw = rng.random_range(1.2..w - 2.5);
        let nd = rng.random_range(1.2..d - 2.5);
        [
            (0.0, 0.0),
            (w, 0.0),
            (w, d - nd),
            (w - nw, d - nd),
            (w - nw, d),
            (0.0, d),
        ]
        .map(|(x, y)| DVec2::new(x, y))
        .to_vec()
    } else {
        [(0.0, 0.0), (w, 0.0), (w, d), (0.0, d)]
            .map(|(x, y)| DVec2::new(x, y))
            .to_vec()
    }
}

/// One piece, or a table with its chairs, at a random place (not yet checked).
fn draw_pieces(rng: &mut ChaCha8Rng, outline: &[DVec2], count: usize) -> Vec<Furniture> {
    let name = |what: &str| format!("{what} {}", count + 1);
    match rng.random_range(0..10) {
        // Against a wall: bed, sofa, cupboard, counter, shelf.
        0..=4 => {
            let (what, long, deep, height) = match rng.random_range(0..5) {
                0 => (
                    "bed",
                    rng.random_range(1.9..2.1),
                    rng.random_range(0.9..1.8),
                    0.5,
                ),
                1 => (
                    "sofa",
                    rng.random_range(1.4..2.4),
                    rng.random_range(0.8..1.0),
                    0.8,
                ),
                2 => (
                    "cupboard",
                    rng.random_range(0.6..2.0),
                    rng.random_range(0.4..0.65),
                    1.9,
                ),
                3 => ("counter", rng.random_range(1.0..2.6), 0.6, 0.9),
                _ => (
                    "shelf",
                    rng.random_range(0.6..1.4),
                    rng.random_range(0.25..0.4),
                    1.6,
                ),
            };
            let Some((center, yaw_deg)) = against_a_wall(rng, outline, long, deep) else {
                return Vec::new();
            };
            vec![Furniture::Box {
                name: name(what),
                center,
                size: [long, deep],
                yaw_deg,
                height,
            }]
        }
        // Free-standing solids: an armchair, an island, a chest.
        5..=6 => {
            let center = inside(rng, outline);
            let size = [rng.random_range(0.5..1.6), rng.random_range(0.5..1.0)];
            vec![Furniture::Box {
                name: name(if size[0] < 1.0 { "armchair" } else { "island" }),
                center,
                size,
                yaw_deg: yaw(rng),
                height: rng.random_range(0.4..0.95),
            }]
        }
        // A table and up to four chairs round it.
        7..=8 => {
            let center = inside(rng, outline);
            let size = [rng.random_range(0.7..1.6), rng.random_range(0.6..1.0)];
            let table_yaw = yaw(rng);
            let mut pieces = vec![Furniture::Table(Legged {
                name: name("table"),
                center,
                size,
                yaw_deg: table_yaw,
                height: rng.random_range(0.7..0.78),
                leg_radius: rng.random_range(0.02..0.04),
                leg_inset: 0.05,
            })];
            let (s, c) = table_yaw.to_radians().sin_cos();
            let sides = [
                (0.0, -(size[1] / 2.0 + 0.3)),
                (0.0, size[1] / 2.0 + 0.3),
                (-(size[0] / 2.0 + 0.3), 0.0),
                (size[0] / 2.0 + 0.3, 0.0),
            ];
            for (x, y) in sides {
                if rng.random_bool(0.6) {
                    pieces.push(Furniture::Chair(Legged {
                        name: name("chair"),
                        center: [center[0] + c * x - s * y, center[1] + s * x + c * y],
                        size: [0.42, 0.42],
                        yaw_deg: table_yaw,
                        height: 0.45,
                        leg_radius: 0.02,
                        leg_inset: 0.04,
                    }));
                }
            }
            pieces
        }
        // A plant pot or bin, or a pillar.
        _ if rng.random_bool(0.7) => vec![Furniture::Cylinder {
            name: name("pot"),
            center: inside(rng, outline),
            radius: rng.random_range(0.12..0.3),
            height: rng.random_range(0.3..1.2),
        }],
        _ => vec![Furniture::Cylinder {
            name: name("pillar"),
            center: inside(rng, outline),
            radius: rng.random_range(0.1..0.25),
            height: 2.5,
        }],
    }
}

fn yaw(rng: &mut ChaCha8Rng) -> f64 {
    if rng.random_bool(0.7) {
        [0.0, 90.0][rng.random_range(0..2)]
    } else {
        rng.random_range(-90.0..90.0)
    }
}

/// A random point of the room's bounding box (the checks reject what lies outside).
fn inside(rng: &mut ChaCha8Rng, outline: &[DVec2]) -> [f64; 2] {
    let (lo, hi) = Shape::Polygon(outline.to_vec()).bounds();
    [rng.random_range(lo.x..hi.x), rng.random_range(lo.y..hi.y)]
}

/// The centre and yaw of a `long` x `deep` box whose back touches a random wall (1 cm gap),
/// at a random place along it.
fn against_a_wall(
    rng: &mut ChaCha8Rng,
    outline: &[DVec2],
    long: f64,
    deep: f64,
) -> Option<([f64; 2], f64)> {
    let i = rng.random_range(0..outline.len());
    let (a, b) = (outline[i], outline[(i + 1) % outline.len()]);
    let wall = b - a;
    if wall.length() < long + 0.02 {
        return None;
    }
    let along = wall.normalize();
    // Counter-clockwise outline: the room lies to the left of each wall.
    let into_room = along.perp();
    let t = rng.random_range(long / 2.0 + 0.01..wall.length() - long / 2.0 - 0.01);
    let c = a + along * t + into_room * (deep / 2.0 + 0.01);
    Some(([c.x, c.y], along.y.atan2(along.x).to_degrees()))
}

/// Whether `pieces` lie inside the room and clear of the furniture already placed (5 cm).
fn fits(scene: &Scene, pieces: &[Furniture]) -> bool {
    let world = World::new(scene);
    pieces.iter().all(|f| {
        let shapes = crate::world::FurnitureShapes::new(f);
        let (lo, hi) = shapes.person_blocks.iter().map(|s| s.bounds()).fold(
            (DVec2::INFINITY, DVec2::NEG_INFINITY),
            |(lo, hi), (l, h)| (lo.min(l), hi.max(h)),
        );
        grid(lo, hi)
            .filter(|p| {
                shapes
                    .person_blocks
                    .iter()
                    .any(|s| s.signed_distance(*p) <= 0.0)
            })
            .all(|p| {
                // Negative outside the room.
                world.wall_clearance(p) > 0.0
                    && world
                        .furniture
                        .iter()
                        .flat_map(|other| &other.person_blocks)
                        .all(|other| other.signed_distance(p) > 0.05)
            })
            && [lo, hi, DVec2::new(lo.x, hi.y), DVec2::new(hi.x, lo.y)]
                .iter()
                .all(|p| world.wall_clearance(*p) > -0.05)
    })
}

/// Whether a person can still walk on half the floor, all of it one connected area.
fn floor_is_open(scene: &Scene) -> bool {
    let world = World::new(scene);
    let (lo, hi) = world.bounds();
    let (nx, ny) = (
        ((hi.x - lo.x) / CELL_M).ceil() as usize,
        ((hi.y - lo.y) / CELL_M).ceil() as usize,
    );
    let cell =
        |i: usize, j: usize| lo + DVec2::new((i as f64 + 0.5) * CELL_M, (j as f64 + 0.5) * CELL_M);
    let mut inside_cells = 0usize;
    let mut walkable = vec![false; nx * ny];
    for j in 0..ny {
        for i in 0..nx {
            let p = cell(i, j);
            if world.wall_clearance(p) > 0.0 {
                inside_cells += 1;
                walkable[j * nx + i] = world.person_clearance(p).0 >= PASSAGE_M;
            }
        }
    }
    let free = walkable.iter().filter(|&&w| w).count();
    if (free as f64) < MIN_WALKABLE * inside_cells as f64 {
        return false;
    }
    // The largest 4-connected walkable area.
    let mut seen = vec![false; nx * ny];
    let mut largest = 0;
    for start in 0..nx * ny {
        if !walkable[start] || seen[start] {
            continue;
        }
        let (mut size, mut stack) = (0, vec![start]);
        seen[start] = true;
        while let Some(k) = stack.pop() {
            size += 1;
            let (i, j) = (k % nx, k / nx);
            let neighbours = [
                (i > 0).then(|| k - 1),
                (i + 1 < nx).then(|| k + 1),
                (j > 0).then(|| k - nx),
                (j + 1 < ny).then(|| k + nx),
            ];
            for n in neighbours.into_iter().flatten() {
                if walkable[n] && !seen[n] {
                    seen[n] = true;
                    stack.push(n);
                }
            }
        }
        largest = largest.max(size);
    }
    largest as f64 >= MIN_CONNECTED * free as f64
}

/// A random spot with at least `clearance` by `clearance_at`, or `None` after 500 draws.
fn free_spot(
    rng: &mut ChaCha8Rng,
    outline: &[DVec2],
    clearance: f64,
    clearance_at: impl Fn(DVec2) -> f64,
) -> Option<DVec2> {
    (0..500).find_map(|_| {
        let p = DVec2::from(inside(rng, outline));
        (clearance_at(p) >= clearance).then_some(p)
    })
}

/// Points every `CELL_M / 2` over a box, edges included.
fn grid(lo: DVec2, hi: DVec2) -> impl Iterator<Item = DVec2> {
    let step = CELL_M / 2.0;
    let (nx, ny) = (
        ((hi.x - lo.x) / step).ceil() as usize + 1,
        ((hi.y - lo.y) / step).ceil() as usize + 1,
    );
    (0..ny).flat_map(move |j| {
        (0..nx).map(move |i| {
            DVec2::new(
                (lo.x + i as f64 * step).min(hi.x),
                (lo.y + j as f64 * step).min(hi.y),
            )
        })
    })
}

fn polygon_area(points: &[DVec2]) -> f64 {
    0.5 * crate::shapes::polygon_area2(points).abs()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_gives_the_same_room() {
        let a = random_scene(7).unwrap();
        let b = random_scene(7).unwrap();
        assert_eq!(
            serde_yaml_ng::to_string(&a).unwrap(),
            serde_yaml_ng::to_string(&b).unwrap()
        );
        assert_ne!(
            serde_yaml_ng::to_string(&a).unwrap(),
            serde_yaml_ng::to_string(&random_scene(8).unwrap()).unwrap()
        );
    }

    #[test]
    fn random_rooms_are_valid_furnished_and_open() {
        // 12 seeds: a room takes up to seconds to generate in a debug build, and 40 seeds
        // (which all passed alike) took most of this crate's test time.
        const SEEDS: u64 = 12;
        let mut furnished = 0;
        for seed in 0..SEEDS {
            let scene = random_scene(seed).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
            // What it writes reads back as a scene file, and simulates.
            let text = serde_yaml_ng::to_string(&scene).unwrap();
            let back = Scene::parse(&text, "generated").unwrap_or_else(|e| panic!("{e}\n{text}"));
            Simulator::new(back, seed).expect("simulates");
            assert!(floor_is_open(&scene), "seed {seed}");
            furnished += usize::from(scene.furniture.len() >= 2);
            let world = World::new(&scene);
            let start = scene.robot.start;
            assert!(world.robot_clearance(DVec2::new(start.x, start.y)).0 >= 0.35);
        }
        assert!(
            furnished >= 10,
            "{furnished} of {SEEDS} rooms have two pieces or more"
        );
    }

    #[test]
    fn a_closed_off_pocket_is_refused() {
        // A 6 x 3 m room split in two by a wall-to-wall cupboard.
        let mut scene = random_scene(1).unwrap();
        scene.room.outline = vec![[0.0, 0.0], [6.0, 0.0], [6.0, 3.0], [0.0, 3.0]];
        scene.furniture = vec![Furniture::Box {
            name: "divider".into(),
            center: [3.0, 1.5],
            size: [0.4, 3.0],
            yaw_deg: 0.0,
            height: 2.0,
        }];
        assert!(!floor_is_open(&scene));
        if let Furniture::Box { size, .. } = &mut scene.furniture[0] {
            size[1] = 1.5;
        }
        assert!(floor_is_open(&scene));
    }

    #[test]
    fn overlapping_pieces_do_not_fit() {
        let mut scene = random_scene(1).unwrap();
        scene.room.outline = vec![[0.0, 0.0], [5.0, 0.0], [5.0, 4.0], [0.0, 4.0]];
        let sofa = |x: f64| Furniture::Box {
            name: "sofa".into(),
            center: [x, 2.0],
            size: [1.0, 1.0],
            yaw_deg: 0.0,
            height: 0.8,
        };
        scene.furniture = vec![sofa(2.0)];
        assert!(!fits(&scene, &[sofa(2.5)]));
        assert!(fits(&scene, &[sofa(3.5)]));
        // Through a wall.
        assert!(!fits(&scene, &[sofa(4.8)]));
    }
}
