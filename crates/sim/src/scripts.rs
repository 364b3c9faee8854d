//! The random activity scripts episodes are drawn from, and the simulator for one episode.
//!
//! An episode is a scene, a seed and a seeded random script for the scene's person, of one
//! [`ScriptKind`]: everyday activities; everyday activities with falls (each followed by
//! getting up); or everyday activities, then a fall after which the person stays down.
//! [`episode`] draws the script (and, for a fixed Lidar, the Lidar's spot) and returns the
//! simulator that runs it. Every block of a script is checked against the body the simulator
//! gives the person, and what does not fit is drawn again. The dataset and the fall-alert
//! measurements of the `lidar-har` CLI are made of such episodes (docs/training.md).

use glam::DVec2;
use lidar_har_core::activity::Activity;
use rand::seq::{IndexedRandom, SliceRandom};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::person::Person;
use crate::scene::{FallDirection, Motion as RobotMotionSpec, PersonSpec, PoseSpec, ScriptStep};
use crate::world::World;
use crate::{Scene, SceneError, Simulator};

/// Random scripts drawn for an episode before [`episode`] gives up.
const ATTEMPTS: usize = 30;

/// Why [`episode`] made no simulator.
#[derive(Debug, thiserror::Error)]
pub enum EpisodeError {
    /// `fixed_lidar`, and no spot in the room is free enough for the Lidar.
    #[error("no free spot for a fixed Lidar in scene '{scene}'")]
    NoLidarSpot {
        /// The scene's name.
        scene: String,
    },
    /// No random script was accepted by the simulator in `attempts` draws.
    #[error("no valid random activity script in {attempts} attempts ({})", refusal(.last_refusal))]
    NoScript {
        /// Scripts drawn.
        attempts: usize,
        /// Why the simulator refused the last script drawn (part of the message, not a
        /// source); `None` when no script could be drawn at all.
        last_refusal: Option<SceneError>,
    },
}

/// The parenthesised end of [`EpisodeError::NoScript`]'s message.
fn refusal(last: &Option<SceneError>) -> String {
    match last {
        Some(e) => format!("the last one was refused: {e}"),
        None => "no free reachable spots for the person's steps were found".to_string(),
    }
}

/// Which random activity script an episode's person follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScriptKind {
    /// Everyday activities, time on the floor included, and no falls.
    Everyday,
    /// Everyday activities and falls, each fall followed by getting up.
    WithFalls,
    /// Everyday activities, then a fall after which the person stays on the floor (lying,
    /// sitting up) to the end: what PERSON_DOWN is for.
    FallAndStayDown,
}

/// A simulator for one episode: `scene` with a random activity script of `kind`, the robot
/// static at a random free spot when `fixed_lidar`.
pub fn episode(
    scene: &Scene,
    seed: u64,
    fixed_lidar: bool,
    kind: ScriptKind,
) -> Result<Simulator, EpisodeError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_da7a);
    let mut scene = scene.clone();
    let world = World::new(&scene);
    if fixed_lidar {
        let spot =
            random_free_point(&world, &mut rng, 0.5).ok_or_else(|| EpisodeError::NoLidarSpot {
                scene: scene.name.clone(),
            })?;
        scene.robot.start = PoseSpec {
            x: spot.x,
            y: spot.y,
            yaw_deg: rng.random_range(-180.0..180.0),
        };
        scene.robot.motion = RobotMotionSpec::Static;
    }
    let person_seed = Simulator::person_seed(&scene, seed);
    let mut last_refusal = None;
    for _ in 0..ATTEMPTS {
        let Some(person) = random_person(&scene, &world, &mut rng, person_seed, kind) else {
            continue;
        };
        let mut candidate = scene.clone();
        candidate.person = Some(person);
        match Simulator::new(candidate, seed) {
            Ok(sim) => return Ok(sim),
            Err(e) => last_refusal = Some(e),
        }
    }
    Err(EpisodeError::NoScript {
        attempts: ATTEMPTS,
        last_refusal,
    })
}

/// A random point in the room at least `clearance` from walls and furniture.
fn random_free_point(world: &World, rng: &mut ChaCha8Rng, clearance: f64) -> Option<DVec2> {
    let (lo, hi) = world.bounds();
    (0..500).find_map(|_| {
        let p = DVec2::new(rng.random_range(lo.x..hi.x), rng.random_range(lo.y..hi.y));
        (world.person_clearance(p).0 >= clearance && world.wall_clearance(p) >= clearance)
            .then_some(p)
    })
}

/// A reachable random point: free, and the straight walk to it stays clear.
fn random_reachable_point(
    world: &World,
    rng: &mut ChaCha8Rng,
    from: DVec2,
    max_dist: f64,
) -> Option<DVec2> {
    (0..200).find_map(|_| {
        let p = random_free_point(world, rng, 0.45)?;
        let d = p - from;
        if d.length() < 0.5 || d.length() > max_dist {
            return None;
        }
        let steps = (d.length() / 0.1).ceil() as usize;
        let clear = (1..steps).all(|k| {
            world
                .person_clearance(from + d * (k as f64 / steps as f64))
                .0
                >= 0.3
        });
        clear.then_some(p)
    })
}

/// A locomotion step of about `seconds` that ends at its last path point.
fn locomotion_step(
    world: &World,
    rng: &mut ChaCha8Rng,
    activity: Activity,
    from: DVec2,
    speed: std::ops::Range<f64>,
    seconds: std::ops::Range<f64>,
) -> Option<(ScriptStep, DVec2)> {
    let speed = rng.random_range(speed);
    let seconds = rng.random_range(seconds);
    let mut path = Vec::new();
    let (mut here, mut length) = (from, 0.0);
    while length < speed * seconds {
        let max = if activity == Activity::Crawling {
            1.5
        } else {
            6.0
        };
        let next = random_reachable_point(world, rng, here, max)?;
        length += (next - here).length();
        path.push([next.x, next.y]);
        here = next;
        if path.len() > 12 {
            break;
        }
    }
    let step = ScriptStep {
        activity,
        duration: (length / speed).max(0.5),
        path,
        speed: Some(speed),
        fall: None,
    };
    Some((step, here))
}

fn still_step(activity: Activity, duration: f64) -> ScriptStep {
    ScriptStep {
        activity,
        duration,
        path: Vec::new(),
        speed: None,
        fall: None,
    }
}

/// How long a scripted fall lasts, seconds.
pub const FALL_SECONDS: std::ops::Range<f64> = 0.7..1.4;

const FALL_DIRECTIONS: [FallDirection; 4] = [
    FallDirection::Forward,
    FallDirection::Backward,
    FallDirection::Left,
    FallDirection::Right,
];

/// The scene's person with a random start and a random script that covers the nine
/// activities in plausible orders (falls end on the floor, the floor ends by getting up).
/// The rarer, shorter activities (falls, getting up, crawling, running) come often.
/// A random script of activity blocks filling the scene's duration; without falls
/// (`ScriptKind::Everyday`) the fall blocks (fall, lying, getting up) are drawn again; for
/// `FallAndStayDown` everyday blocks fill the first 5-40 % and a fall ends the script.
fn random_person(
    scene: &Scene,
    world: &World,
    rng: &mut ChaCha8Rng,
    person_seed: u64,
    kind: ScriptKind,
) -> Option<PersonSpec> {
    let falls = kind == ScriptKind::WithFalls;
    let everyday_until = match kind {
        ScriptKind::FallAndStayDown => rng.random_range(5.0..(0.4 * scene.duration).max(6.0)),
        _ => scene.duration + 2.0,
    };
    let base = scene.person.clone()?;
    let start = random_free_point(world, rng, 0.6)?;
    let mut script: Vec<ScriptStep> = Vec::new();
    let mut here = start;
    let mut total = 0.0;
    let mut spec = PersonSpec {
        start: PoseSpec {
            x: start.x,
            y: start.y,
            yaw_deg: rng.random_range(-180.0..180.0),
        },
        script: Vec::new(),
        repeat: false,
        ..base
    };
    let mut draws = 0;
    while total < everyday_until {
        draws += 1;
        if draws > 200 {
            return None;
        }
        let mut block: Vec<ScriptStep> = Vec::new();
        let mut end_here = None;
        let kind = rng.random_range(0..10);
        if !falls && (5..=7).contains(&kind) {
            continue;
        }
        match kind {
            0 => block.push(still_step(Activity::Standing, rng.random_range(1.5..4.0))),
            1..=4 => {
                let (activity, speed, seconds) = match kind {
                    1 | 2 => (Activity::Walking, 0.7..1.2, 3.0..7.0),
                    3 => (Activity::Running, 1.8..2.8, 2.0..4.0),
                    _ => (Activity::WalkingUnsteadily, 0.35..0.6, 3.0..6.0),
                };
                // No path from here (a small room, a corner): draw another block, so that
                // the room still gets its falls and its time on the floor.
                let Some((s, p)) = locomotion_step(world, rng, activity, here, speed, seconds)
                else {
                    continue;
                };
                block.push(s);
                end_here = Some(p);
            }
            5..=7 => {
                let mut fall = still_step(Activity::FallingDown, rng.random_range(FALL_SECONDS));
                fall.fall = FALL_DIRECTIONS.choose(rng).copied();
                block.push(fall);
                block.push(still_step(Activity::LyingDown, rng.random_range(2.0..6.0)));
                if rng.random_bool(0.3) {
                    block.push(still_step(
                        Activity::SittingOnFloor,
                        rng.random_range(2.0..4.0),
                    ));
                }
                block.push(still_step(Activity::GettingUp, rng.random_range(1.2..2.5)));
            }
            _ => {
                block.push(still_step(
                    Activity::SittingOnFloor,
                    rng.random_range(2.0..5.0),
                ));
                if rng.random_bool(0.6) {
                    // Crawling from where the person sits: the position comes from the plan.
                    let mut trial = spec.clone();
                    trial.script = script.iter().chain(block.iter()).cloned().collect();
                    if let Some((s, _)) =
                        position_after(&trial, world, person_seed).and_then(|at| {
                            locomotion_step(world, rng, Activity::Crawling, at, 0.2..0.4, 2.5..5.0)
                        })
                    {
                        block.push(s);
                    }
                }
                block.push(still_step(Activity::GettingUp, rng.random_range(1.2..2.5)));
            }
        }
        let mut trial = spec.clone();
        trial.script = script.iter().chain(block.iter()).cloned().collect();
        if Person::new(&trial, world, person_seed).is_err() {
            continue; // this block does not fit here (a path through furniture): draw another
        }
        let end = match end_here {
            Some(p) => p,
            None => position_after(&trial, world, person_seed)?,
        };
        if world.person_clearance(end).0 < 0.2 {
            continue; // got up against furniture: no room for what comes next
        }
        total += block.iter().map(|s| s.duration).sum::<f64>();
        script.extend(block);
        here = end;
    }
    if kind == ScriptKind::FallAndStayDown {
        script.extend(fall_and_stay_down(
            &spec,
            &script,
            world,
            rng,
            person_seed,
            scene.duration + 2.0 - total,
        )?);
    }
    spec.script = script;
    Some(spec)
}

/// A fall after `script` (in a direction that fits), then lying, and lying or sitting up on
/// the floor for the rest of `remaining_s`.
fn fall_and_stay_down(
    spec: &PersonSpec,
    script: &[ScriptStep],
    world: &World,
    rng: &mut ChaCha8Rng,
    person_seed: u64,
    remaining_s: f64,
) -> Option<Vec<ScriptStep>> {
    let mut directions = FALL_DIRECTIONS;
    directions.shuffle(rng);
    let mut fall = still_step(Activity::FallingDown, rng.random_range(FALL_SECONDS));
    let lying = rng.random_range(3.0..8.0);
    let rest = remaining_s - fall.duration - lying;
    let last = if rng.random_bool(0.5) {
        Activity::SittingOnFloor
    } else {
        Activity::LyingDown
    };
    directions.into_iter().find_map(|direction| {
        fall.fall = Some(direction);
        let mut block = vec![fall.clone(), still_step(Activity::LyingDown, lying)];
        if rest > 0.0 {
            block.push(still_step(last, rest));
        }
        let mut trial = spec.clone();
        trial.script = script.iter().chain(block.iter()).cloned().collect();
        Person::new(&trial, world, person_seed).ok().map(|_| block)
    })
}

/// Where the person stands at the end of `spec`'s script.
fn position_after(spec: &PersonSpec, world: &World, seed: u64) -> Option<DVec2> {
    let mut person = Person::new(spec, world, seed).ok()?;
    let end: f64 = spec.script.iter().map(|s| s.duration).sum();
    Some(person.state_at(end).position)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped_scene(name: &str) -> Scene {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/scenes");
        Scene::load(&std::path::Path::new(dir).join(format!("{name}.yaml"))).expect("shipped scene")
    }

    #[test]
    fn episode_errors_say_what_failed() {
        let no_spot = EpisodeError::NoLidarSpot {
            scene: "cupboard".to_string(),
        };
        assert_eq!(
            no_spot.to_string(),
            "no free spot for a fixed Lidar in scene 'cupboard'"
        );
        let no_script = EpisodeError::NoScript {
            attempts: ATTEMPTS,
            last_refusal: None,
        };
        assert_eq!(
            no_script.to_string(),
            "no valid random activity script in 30 attempts (no free reachable spots for the \
             person's steps were found)"
        );
        let refusal = SceneError::Invalid {
            origin: "bathroom".to_string(),
            key: "person.script[3]".to_string(),
            message: "no path".to_string(),
        };
        let refused = EpisodeError::NoScript {
            attempts: ATTEMPTS,
            last_refusal: Some(refusal),
        };
        assert_eq!(
            refused.to_string(),
            "no valid random activity script in 30 attempts (the last one was refused: \
             bathroom: person.script[3]: no path)"
        );
    }

    #[test]
    fn a_random_script_is_checked_against_the_body_that_performs_it() {
        // The bathroom is small: whether a fall or a walk fits depends on the body's size and
        // sway, so a script checked against another body is often refused by the simulator.
        let scene = shipped_scene("bathroom");
        let world = World::new(&scene);
        let mut refused = Vec::new();
        for seed in 0..12 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let person_seed = Simulator::person_seed(&scene, seed);
            let kind = ScriptKind::WithFalls;
            if let Some(person) = random_person(&scene, &world, &mut rng, person_seed, kind) {
                let mut candidate = scene.clone();
                candidate.person = Some(person);
                if let Err(e) = Simulator::new(candidate, seed) {
                    refused.push(format!("seed {seed}: {e}"));
                }
            }
        }
        assert!(refused.is_empty(), "scripts refused: {refused:#?}");
    }

    #[test]
    fn a_stay_down_script_ends_with_a_fall_and_the_floor_to_the_end() {
        for name in ["bathroom", "living_room"] {
            let scene = shipped_scene(name);
            let world = World::new(&scene);
            let mut drawn = 0;
            for seed in 0..6 {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                let person_seed = Simulator::person_seed(&scene, seed);
                let kind = ScriptKind::FallAndStayDown;
                let Some(person) = random_person(&scene, &world, &mut rng, person_seed, kind)
                else {
                    continue; // drawn again by `episode`
                };
                drawn += 1;
                let script = &person.script;
                let fall = script
                    .iter()
                    .rposition(|s| s.activity == Activity::FallingDown)
                    .expect("a fall");
                let after: Vec<Activity> = script[fall + 1..].iter().map(|s| s.activity).collect();
                assert!(
                    !after.is_empty() && after.iter().all(|a| a.is_on_floor()),
                    "{name} seed {seed}: after the fall {after:?}"
                );
                let total: f64 = script.iter().map(|s| s.duration).sum();
                assert!(total >= scene.duration, "{name} seed {seed}: {total} s");
                let falls = script
                    .iter()
                    .filter(|s| s.activity == Activity::FallingDown);
                assert_eq!(falls.count(), 1, "{name} seed {seed}: one fall only");
            }
            assert!(drawn > 0, "{name}: no script of 6 drawn");
            assert!(episode(&scene, 7, false, ScriptKind::FallAndStayDown).is_ok());
        }
    }

    #[test]
    fn a_small_room_gets_a_script_for_every_episode() {
        // The bathroom (2.5 x 2.2 m, a bathtub along one wall) has no room for most walks and
        // for falls in most directions: what does not fit is drawn again.
        let scene = shipped_scene("bathroom");
        let failed: Vec<String> = (0..12)
            .filter_map(|seed| {
                episode(&scene, seed, false, ScriptKind::WithFalls)
                    .err()
                    .map(|e| format!("seed {seed}: {e}"))
            })
            .collect();
        assert!(failed.is_empty(), "{failed:#?}");
    }
}
