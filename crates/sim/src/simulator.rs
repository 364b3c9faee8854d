//! The streaming simulator: one [`Frame`] per Lidar rotation, in memory, with ground truth.

use lidar_har_core::activity::Activity;
use lidar_har_core::geometry::Pose2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::body::{Capsule, PARTS};
use crate::lidar::{Lidar, ScanGeometry};
use crate::person::Person;
use crate::robot::{RobotMotion, Twist2};
use crate::scene::{Scene, SceneError};
use crate::world::{BeamLabel, World};

/// The person at a frame's instant.
#[derive(Debug, Clone, Copy)]
pub struct PersonFrame {
    /// Pelvis position on the floor and facing direction, map frame.
    pub pose: Pose2,
    pub activity: Activity,
    /// The body's capsules (map frame, metres).
    pub parts: [Capsule; PARTS],
}

/// One simulated scan with everything known about its instant.
#[derive(Debug, Clone, Default)]
pub struct Frame {
    /// Scan number from 0.
    pub index: u64,
    /// Nanoseconds since the Unix epoch: the scene's start time plus `index` rotations.
    pub stamp_ns: u64,
    /// Measured ranges, metres; `+inf` where there is no valid return.
    pub ranges: Vec<f32>,
    /// What each beam hit (or which error replaced it).
    pub labels: Vec<BeamLabel>,
    /// base_link in the map frame (the odometry; map -> odom is the identity here).
    pub robot: Pose2,
    pub robot_twist: Twist2,
    /// The Lidar in the map frame.
    pub laser: Pose2,
    pub person: Option<PersonFrame>,
}

/// SplitMix64: turns related seeds into unrelated ones.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn base_seed(scene: &Scene, seed: u64) -> u64 {
    mix(mix(scene.seed) ^ seed)
}

/// Simulates a scene scan by scan.
#[derive(Debug, Clone)]
pub struct Simulator {
    scene: Scene,
    world: World,
    robot: RobotMotion,
    person: Option<Person>,
    lidar: Lidar,
    noise_rng: Option<ChaCha8Rng>,
    mount: Pose2,
    index: u64,
    frames: u64,
    start_ns: u64,
}

impl Simulator {
    /// Prepares a validated scene. `seed` is mixed with the scene's own seed: the same pair
    /// gives the same frames, bit for bit. Separate random streams drive the robot, the
    /// person and the noise, so turning noise off leaves the motion unchanged.
    pub fn new(scene: Scene, seed: u64) -> Result<Self, SceneError> {
        scene
            .validate()
            .map_err(|(key, message)| SceneError::Refused { key, message })?;
        let base = base_seed(&scene, seed);
        let world = World::new(&scene);
        let robot = RobotMotion::new(&scene.robot, &world, mix(base ^ 1))?;
        let person = scene
            .person
            .as_ref()
            .map(|p| Person::new(p, &world, Self::person_seed(&scene, seed)))
            .transpose()?;
        let lidar = Lidar::new(&scene.lidar);
        let noise_rng =
            (!scene.lidar.noise.is_none()).then(|| ChaCha8Rng::seed_from_u64(mix(base ^ 3)));
        let frames = scene.frame_count();
        let start_ns = scene.start_time.saturating_mul(1_000_000_000);
        Ok(Self {
            mount: scene.robot.lidar_mount.to_pose(),
            scene,
            world,
            robot,
            person,
            lidar,
            noise_rng,
            index: 0,
            frames,
            start_ns,
        })
    }

    /// The seed `new(scene, seed)` gives the scene's person (their size, sway, steps): a
    /// script written for an episode is checked against the body that will perform it.
    pub fn person_seed(scene: &Scene, seed: u64) -> u64 {
        mix(base_seed(scene, seed) ^ 2)
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    pub fn robot_motion(&self) -> &RobotMotion {
        &self.robot
    }

    pub fn scan_geometry(&self) -> ScanGeometry {
        self.lidar.geometry
    }

    /// base_link -> laser.
    pub fn lidar_mount(&self) -> Pose2 {
        self.mount
    }

    /// Number of frames in the scene's duration.
    pub fn frame_count(&self) -> u64 {
        self.frames
    }

    /// Runs on for `seconds` past the scene's duration, the frames before unchanged: the
    /// script's last activity goes on after its end, and the robot keeps moving.
    pub fn run_on(&mut self, seconds: f64) {
        self.frames += (seconds.max(0.0) * self.scene.lidar.rate_hz).ceil() as u64;
    }

    /// Makes `index` the next frame (clamped to the end). Skipping ahead costs no scans;
    /// the person's script is planned up to that time on the next step. The range noise
    /// draws on from where the run is, so its frames are not noised as a full run's are.
    pub fn seek(&mut self, index: u64) {
        self.index = index.min(self.frames);
    }

    /// Stamp of the first frame, nanoseconds since the Unix epoch.
    pub fn start_ns(&self) -> u64 {
        self.start_ns
    }

    /// Nanoseconds from the start to scan `index`, from integers (no accumulated rounding).
    pub fn offset_ns(&self, index: u64) -> u64 {
        let period = 1e9 / self.scene.lidar.rate_hz;
        if period.fract() == 0.0 {
            index.saturating_mul(period as u64)
        } else {
            // Rate in micro-hertz, so the division stays in integers.
            let rate_uhz = ((self.scene.lidar.rate_hz * 1e6).round() as u128).max(1);
            (index as u128 * 1_000_000_000_000_000 / rate_uhz) as u64
        }
    }

    /// Exact distances of the last frame's beams before noise.
    pub fn exact_ranges(&self) -> &[f64] {
        self.lidar.exact_ranges()
    }

    /// The next frame, or `None` after the scene's duration.
    pub fn step(&mut self) -> Option<Frame> {
        let mut frame = Frame::default();
        self.step_into(&mut frame).then_some(frame)
    }

    /// Like [`Simulator::step`], reusing `frame`'s buffers. Returns `false` at the end.
    pub fn step_into(&mut self, frame: &mut Frame) -> bool {
        if self.index >= self.frames {
            return false;
        }
        let offset = self.offset_ns(self.index);
        let t = offset as f64 * 1e-9;
        let (robot, twist) = self.robot.at(t);
        let laser = robot.compose(&self.mount);
        let person = self.person.as_mut().map(|p| {
            let s = p.state_at(t);
            PersonFrame {
                pose: Pose2::new(s.position.x, s.position.y, s.yaw),
                activity: s.activity,
                parts: s.parts,
            }
        });
        let (robot_motion, mount) = (&self.robot, self.mount);
        let (person_model, frame_parts) = (&mut self.person, person.as_ref().map(|p| p.parts));
        // A Lidar that sweeps measured its earlier beams from where the robot was then, of the
        // body as it was then; before the start, both stand where they start.
        let at = |s: f64| {
            let then = (t + s).max(0.0);
            let laser = robot_motion.at(then).0.compose(&mount);
            let parts = if s == 0.0 {
                frame_parts
            } else {
                person_model.as_mut().map(|p| p.state_at(then).parts)
            };
            (laser, parts)
        };
        self.lidar.scan_moving(
            &self.world,
            at,
            self.noise_rng.as_mut(),
            &mut frame.ranges,
            &mut frame.labels,
        );
        frame.index = self.index;
        frame.stamp_ns = self.start_ns + offset;
        frame.robot = robot;
        frame.robot_twist = twist;
        frame.laser = laser;
        frame.person = person;
        self.index += 1;
        true
    }
}

impl Iterator for Simulator {
    type Item = Frame;
    fn next(&mut self) -> Option<Frame> {
        self.step()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hall(hours: f64) -> Scene {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/hall.yaml");
        let mut s = Scene::load(&path).unwrap();
        s.duration = hours * 3600.0;
        s
    }

    #[test]
    fn running_on_adds_frames_after_the_same_ones() {
        let scene = hall(3.0 / 3600.0);
        let frames = |run_on_s: f64| {
            let mut sim = Simulator::new(scene.clone(), 5).unwrap();
            sim.run_on(run_on_s);
            let count = sim.frame_count();
            let frames: Vec<Frame> = sim.collect();
            assert_eq!(frames.len() as u64, count);
            frames
        };
        let (short, long) = (frames(0.0), frames(1.5));
        assert_eq!((short.len(), long.len()), (60, 90));
        for (a, b) in long.iter().zip(&short) {
            assert_eq!(
                (a.stamp_ns, &a.ranges, a.robot),
                (b.stamp_ns, &b.ranges, b.robot)
            );
        }
        let last = &long[89];
        assert_eq!(last.stamp_ns, 1_700_000_000_000_000_000 + 89 * 50_000_000);
        assert!(last.person.is_some_and(|p| p.pose.is_finite()));
    }

    #[test]
    fn hours_of_simulation_do_not_drift() {
        let mut sim = Simulator::new(hall(5.0), 3).unwrap();
        assert_eq!(sim.frame_count(), 5 * 3600 * 20);
        let last = sim.frame_count() - 1;
        sim.seek(last);
        let f = sim.step().unwrap();
        // Stamps come from the index: exact to the nanosecond after five hours.
        assert_eq!(f.stamp_ns, 1_700_000_000_000_000_000 + last * 50_000_000);
        assert!(sim.step().is_none());
        // The robot's pose is its periodic plan's: the same as one period earlier.
        let period = sim.robot_motion().period();
        let t = last as f64 / 20.0;
        let (now, _) = sim.robot_motion().at(t);
        let (before, _) = sim.robot_motion().at(t - (t / period).floor() * period);
        assert!(
            (now.position() - before.position()).length() < 1e-6,
            "{now:?} vs {before:?}"
        );
        assert_eq!(f.robot, now);
        // The person is still inside the hall, on the floor, and finite.
        let p = f.person.unwrap();
        assert!(
            p.pose.is_finite() && (0.0..12.0).contains(&p.pose.x) && (0.0..9.0).contains(&p.pose.y),
            "{:?}",
            p.pose
        );
        assert!(
            p.parts
                .iter()
                .all(|c| c.a.is_finite() && c.b.is_finite() && c.a.z.min(c.b.z) - c.radius > -1e-9)
        );
        assert!(
            f.ranges
                .iter()
                .all(|r| r.is_infinite() || (0.15..=16.0).contains(r))
        );
    }

    #[test]
    fn rate_that_does_not_divide_a_second_keeps_integer_stamps() {
        let mut s = hall(1.0);
        s.lidar.rate_hz = 7.0;
        let sim = Simulator::new(s, 0).unwrap();
        assert_eq!(sim.offset_ns(7), 1_000_000_000);
        assert_eq!(sim.offset_ns(7 * 3600), 3_600_000_000_000);
        assert_eq!(sim.offset_ns(1), 142_857_142);
    }

    #[test]
    fn a_scene_without_person_or_noise_does_no_work_for_them() {
        let mut s = hall(0.01);
        s.person = None;
        s.lidar.noise = crate::scene::NoiseSpec::NONE;
        let mut sim = Simulator::new(s, 0).unwrap();
        assert!(sim.person.is_none() && sim.noise_rng.is_none());
        let f = sim.step().unwrap();
        assert!(f.person.is_none());
        assert!(!f.labels.contains(&BeamLabel::Missing) && !f.labels.contains(&BeamLabel::Person));
    }
}
