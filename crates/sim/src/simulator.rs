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
            .map_err(|(key, message)| SceneError::Invalid { origin: "scene".to_string(), key, message })?;
        let base = mix(mix(scene.seed) ^ seed);
        let world = World::new(&scene);
        let robot = RobotMotion::new(&scene.robot, &world, mix(base ^ 1))?;
        let person = scene.person.as_ref().map(|p| Person::new(p, &world, mix(base ^ 2))).transpose()?;
        let lidar = Lidar::new(&scene.lidar);
        let noise_rng = (!scene.lidar.noise.is_none()).then(|| ChaCha8Rng::seed_from_u64(mix(base ^ 3)));
        let frames = (scene.duration * scene.lidar.rate_hz - 1e-9).ceil().max(0.0) as u64;
        let start_ns = scene.start_time.saturating_mul(1_000_000_000);
        Ok(Self { mount: scene.robot.lidar_mount.to_pose(), scene, world, robot, person, lidar, noise_rng, index: 0, frames, start_ns })
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
            PersonFrame { pose: Pose2::new(s.position.x, s.position.y, s.yaw), activity: s.activity, parts: s.parts }
        });
        self.lidar.scan(
            &self.world,
            laser,
            person.as_ref().map(|p| &p.parts[..]),
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
