//! Scene files: the room, its furniture, the robot, its Lidar and the person's script, as
//! YAML. Unknown keys and impossible values are rejected with the key's path named
//! (`furniture[2].size[0]: must be positive`). Distances in metres, times in seconds,
//! angles in degrees (the `_deg` keys), speeds in metres per second.

use std::path::Path;

use lidar_har_core::activity::Activity;
use lidar_har_core::geometry::Pose2;
use serde::{Deserialize, Deserializer, Serialize};

mod tagged;

/// The Lidar height used when a scene does not give one: the top of a typical cleaning
/// robot's Lidar turret (about 10 cm), where a lying person is seen whole and a standing
/// one by the shins. See docs/simulator.md for why not higher.
pub const DEFAULT_LIDAR_HEIGHT: f64 = 0.10;
/// Scene start time when a scene does not give one (seconds since the Unix epoch). Fixed so
/// that outputs never depend on the wall clock.
pub const DEFAULT_START_TIME: u64 = 1_700_000_000;
/// The paper's robot speed limit.
pub const MAX_ROBOT_SPEED: f64 = 0.2;

/// A whole scene, as read from YAML.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Free text shown in logs and renders.
    #[serde(default)]
    pub name: String,
    /// Simulated time, seconds.
    pub duration: f64,
    /// Scene seed; mixed with the command-line seed.
    #[serde(default)]
    pub seed: u64,
    /// Stamp of the first scan, whole seconds since the Unix epoch.
    #[serde(default = "default_start_time")]
    pub start_time: u64,
    pub room: Room,
    #[serde(default)]
    pub furniture: Vec<Furniture>,
    pub robot: RobotSpec,
    #[serde(default)]
    pub lidar: LidarSpec,
    #[serde(default)]
    pub person: Option<PersonSpec>,
}

fn default_start_time() -> u64 {
    DEFAULT_START_TIME
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Room {
    /// The walls as a simple polygon, metres, in the map frame.
    pub outline: Vec<[f64; 2]>,
}

/// A pose in the scene file: metres and degrees.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    pub x: f64,
    pub y: f64,
    #[serde(default)]
    pub yaw_deg: f64,
}

impl PoseSpec {
    pub fn to_pose(self) -> Pose2 {
        Pose2::new(self.x, self.y, self.yaw_deg.to_radians())
    }
}

/// A piece of furniture. Everything stands on the floor; `height` is its top. Read by
/// `FurnitureKeys`, with `kind` first (see `tagged`).
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Furniture {
    /// A solid box (sofa, bed, cupboard, fridge).
    Box {
        name: String,
        center: [f64; 2],
        size: [f64; 2],
        yaw_deg: f64,
        height: f64,
    },
    /// A solid upright cylinder (plant pot, bin, round pillar).
    Cylinder {
        name: String,
        center: [f64; 2],
        radius: f64,
        height: f64,
    },
    /// A solid prism over a simple polygon (kitchen counter, L-shaped sofa).
    Polygon {
        name: String,
        points: Vec<[f64; 2]>,
        height: f64,
    },
    /// A table: a top on four legs; only the legs reach the Lidar plane.
    Table(Legged),
    /// A chair: a seat on four legs; only the legs reach the Lidar plane.
    Chair(Legged),
}

/// How a furniture piece is read: `Furniture` in serde's externally tagged form, which
/// `tagged` feeds with `kind` read first. serde's `remote` keeps its variants and fields
/// those of `Furniture`; the defaults are here.
#[derive(Deserialize)]
#[serde(remote = "Furniture", rename_all = "snake_case", deny_unknown_fields)]
enum FurnitureKeys {
    Box {
        #[serde(default)]
        name: String,
        center: [f64; 2],
        size: [f64; 2],
        #[serde(default)]
        yaw_deg: f64,
        height: f64,
    },
    Cylinder {
        #[serde(default)]
        name: String,
        center: [f64; 2],
        radius: f64,
        height: f64,
    },
    Polygon {
        #[serde(default)]
        name: String,
        points: Vec<[f64; 2]>,
        height: f64,
    },
    Table(Legged),
    Chair(Legged),
}

impl<'de> Deserialize<'de> for Furniture {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        tagged::deserialize(deserializer, "a furniture piece: a map with `kind`")
    }
}

impl<'de> tagged::ExternallyTagged<'de> for Furniture {
    fn deserialize_external<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        FurnitureKeys::deserialize(deserializer)
    }
}

/// A top on four round legs set in from its corners.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Legged {
    #[serde(default)]
    pub name: String,
    pub center: [f64; 2],
    pub size: [f64; 2],
    #[serde(default)]
    pub yaw_deg: f64,
    /// Height of the top (table top or seat).
    pub height: f64,
    #[serde(default = "default_leg_radius")]
    pub leg_radius: f64,
    /// Distance from the top's edges to the legs' centres.
    #[serde(default = "default_leg_inset")]
    pub leg_inset: f64,
}

fn default_leg_radius() -> f64 {
    0.02
}
fn default_leg_inset() -> f64 {
    0.05
}

impl Furniture {
    pub fn name(&self) -> &str {
        match self {
            Furniture::Box { name, .. }
            | Furniture::Cylinder { name, .. }
            | Furniture::Polygon { name, .. } => name,
            Furniture::Table(l) | Furniture::Chair(l) => &l.name,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// The robot's footprint radius; it keeps this far (plus a margin) from obstacles.
    #[serde(default = "default_robot_radius")]
    pub radius: f64,
    /// Height of the Lidar's scan plane above the floor.
    #[serde(default = "default_lidar_height")]
    pub lidar_height: f64,
    /// Pose of the Lidar on the robot (base_link -> laser).
    #[serde(default)]
    pub lidar_mount: PoseSpec,
    pub start: PoseSpec,
    /// Cruise speed, at most 0.2 m/s.
    #[serde(default = "default_robot_speed")]
    pub speed: f64,
    /// Turning speed on the spot.
    #[serde(default = "default_turn_rate")]
    pub turn_rate_deg: f64,
    #[serde(default)]
    pub motion: Motion,
}

fn default_robot_radius() -> f64 {
    0.17
}
fn default_lidar_height() -> f64 {
    DEFAULT_LIDAR_HEIGHT
}
fn default_robot_speed() -> f64 {
    MAX_ROBOT_SPEED
}
fn default_turn_rate() -> f64 {
    90.0
}

/// How the robot moves. Every motion is planned around furniture on the robot's footprint.
/// Read by `MotionKeys`, with `kind` first (see `tagged`).
#[derive(Debug, Clone, Default, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Motion {
    /// The robot stays at its start pose.
    #[default]
    Static,
    /// Visit these points in order (then return to the start and repeat, if `repeat`).
    Waypoints { points: Vec<[f64; 2]>, repeat: bool },
    /// Cleaning lanes over the whole room (boustrophedon), `spacing` apart.
    Coverage {
        spacing: f64,
        /// Lanes run along x (`false`) or along y (`true`).
        along_y: bool,
    },
    /// Straight runs until an obstacle is near, then a turn to a random free heading.
    Bounce {
        /// Number of straight runs planned (the plan repeats after them).
        runs: u32,
    },
}

/// How `robot.motion` is read: `Motion` in serde's externally tagged form, as
/// `FurnitureKeys` is `Furniture`'s. `static` takes no other key.
#[derive(Deserialize)]
#[serde(remote = "Motion", rename_all = "snake_case", deny_unknown_fields)]
enum MotionKeys {
    Static,
    Waypoints {
        points: Vec<[f64; 2]>,
        #[serde(default = "default_true")]
        repeat: bool,
    },
    Coverage {
        #[serde(default = "default_lane_spacing")]
        spacing: f64,
        #[serde(default)]
        along_y: bool,
    },
    Bounce {
        #[serde(default = "default_bounce_runs")]
        runs: u32,
    },
}

impl<'de> Deserialize<'de> for Motion {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        tagged::deserialize(deserializer, "a robot motion: a map with `kind`")
    }
}

impl<'de> tagged::ExternallyTagged<'de> for Motion {
    fn deserialize_external<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        MotionKeys::deserialize(deserializer)
    }
}

fn default_true() -> bool {
    true
}
fn default_lane_spacing() -> f64 {
    0.35
}
/// The most straight runs a `bounce` motion may plan. Every run is planned (a free-space
/// search and A*) when the simulator is built and kept for the whole scene: 100 000 runs
/// take about 17 s and 75 MB in the largest room allowed (200 m a side), while 4 000 000 000
/// would hang for hours and hold about 64 GB.
pub const MAX_BOUNCE_RUNS: u32 = 100_000;

fn default_bounce_runs() -> u32 {
    64
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LidarSpec {
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// Beams per rotation, spread evenly over the full circle.
    #[serde(default = "default_beams")]
    pub beams: u32,
    #[serde(default = "default_range_min")]
    pub range_min: f64,
    #[serde(default = "default_range_max")]
    pub range_max: f64,
    /// Each beam measured at its own time over the rotation, from where the robot then is,
    /// as a spinning Lidar does: the rotation ends at the stamp with beam 0, as the RPLIDAR
    /// driver stamps it (LaserScan's `time_increment` is `-1 / (rate_hz * beams)`);
    /// false: every beam at the scan's stamp (the paper's data and every committed figure).
    #[serde(default)]
    pub sweep: bool,
    /// Measurement errors; absent means the paper's values.
    #[serde(default)]
    pub noise: NoiseSpec,
}

impl Default for LidarSpec {
    fn default() -> Self {
        Self {
            rate_hz: default_rate(),
            beams: default_beams(),
            range_min: default_range_min(),
            range_max: default_range_max(),
            sweep: false,
            noise: NoiseSpec::default(),
        }
    }
}

fn default_rate() -> f64 {
    20.0
}
fn default_beams() -> u32 {
    720
}
fn default_range_min() -> f64 {
    0.15
}
fn default_range_max() -> f64 {
    12.0
}

/// The paper's Lidar errors. Percentages of points (missing, wrong) or of the distance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// Standard deviation of the range error, in % of the true distance.
    #[serde(default = "paper_distance_pct")]
    pub distance_pct: f64,
    /// Share of beams with no return (+inf).
    #[serde(default = "paper_missing_pct")]
    pub missing_pct: f64,
    /// Share of beams that return a point seen at a wrong angle (multipath).
    #[serde(default = "paper_wrong_pct")]
    pub wrong_pct: f64,
    /// Standard deviation of the beam's direction error.
    #[serde(default = "paper_angle_deg")]
    pub angle_deg: f64,
    /// How far off a wrong (multipath) return's true direction can be, either side.
    #[serde(default = "default_wrong_spread")]
    pub wrong_spread_deg: f64,
}

impl Default for NoiseSpec {
    fn default() -> Self {
        Self {
            distance_pct: paper_distance_pct(),
            missing_pct: paper_missing_pct(),
            wrong_pct: paper_wrong_pct(),
            angle_deg: paper_angle_deg(),
            wrong_spread_deg: default_wrong_spread(),
        }
    }
}

impl NoiseSpec {
    /// No errors at all: ranges are exact geometry.
    pub const NONE: NoiseSpec = NoiseSpec {
        distance_pct: 0.0,
        missing_pct: 0.0,
        wrong_pct: 0.0,
        angle_deg: 0.0,
        wrong_spread_deg: 30.0,
    };

    pub fn is_none(&self) -> bool {
        self.distance_pct == 0.0
            && self.missing_pct == 0.0
            && self.wrong_pct == 0.0
            && self.angle_deg == 0.0
    }
}

fn paper_distance_pct() -> f64 {
    2.0
}
fn paper_missing_pct() -> f64 {
    4.0
}
fn paper_wrong_pct() -> f64 {
    2.0
}
fn paper_angle_deg() -> f64 {
    0.04
}
fn default_wrong_spread() -> f64 {
    30.0
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PersonSpec {
    #[serde(default)]
    pub body: BodySpec,
    pub start: PoseSpec,
    /// Activities in order. When the script ends, the last activity goes on (a fall ends
    /// lying down, getting up ends standing), or the script starts again if `repeat`.
    pub script: Vec<ScriptStep>,
    #[serde(default)]
    pub repeat: bool,
}

/// Body dimensions. Limb lengths follow anthropometric ratios of `height`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    #[serde(default = "default_height")]
    pub height: f64,
    /// Multiplies every limb radius (1 = average build).
    #[serde(default = "one")]
    pub girth: f64,
    /// Multiplies step frequency (1 = average pace).
    #[serde(default = "one")]
    pub pace: f64,
    /// Multiplies stride length.
    #[serde(default = "one")]
    pub stride: f64,
    /// Multiplies sideways sway.
    #[serde(default = "one")]
    pub sway: f64,
    /// Random per-episode variation of all of the above, as a fraction (0.05 = ±5 %).
    #[serde(default = "default_variation")]
    pub variation: f64,
}

impl Default for BodySpec {
    fn default() -> Self {
        Self {
            height: default_height(),
            girth: 1.0,
            pace: 1.0,
            stride: 1.0,
            sway: 1.0,
            variation: default_variation(),
        }
    }
}

fn default_height() -> f64 {
    1.75
}
fn one() -> f64 {
    1.0
}
fn default_variation() -> f64 {
    0.05
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptStep {
    pub activity: Activity,
    pub duration: f64,
    /// Where walking, running, unsteady walking and crawling go (from the current position),
    /// back and forth if the step lasts longer than the path.
    #[serde(default)]
    pub path: Vec<[f64; 2]>,
    /// Overrides the activity's usual speed.
    #[serde(default)]
    pub speed: Option<f64>,
    /// For falls: which way, relative to the person's heading. Absent: chosen at random.
    #[serde(default)]
    pub fall: Option<FallDirection>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FallDirection {
    Forward,
    Backward,
    Left,
    Right,
}

/// A scene that cannot be used, with where in the file the problem is.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("cannot read scene {path}: {cause}")]
    Io { path: String, cause: std::io::Error },
    #[error("{origin}: {key}: {message}")]
    Invalid {
        origin: String,
        key: String,
        message: String,
    },
    /// A scene the simulator refuses after it was read (its values changed since, or it
    /// cannot be planned): the caller holds the scene and names it, so only the key is given.
    #[error("{key}: {message}")]
    Refused { key: String, message: String },
}

/// Activities that move the person along a path.
pub fn is_locomotion(a: Activity) -> bool {
    matches!(
        a,
        Activity::Walking | Activity::Running | Activity::WalkingUnsteadily | Activity::Crawling
    )
}

impl Scene {
    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            cause: source,
        })?;
        Scene::parse(&text, &path.display().to_string())
    }

    /// Parses and validates scene YAML; `origin` names the input in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Scene, SceneError> {
        let deserializer = serde_yaml_ng::Deserializer::from_str(text);
        let scene: Scene = serde_path_to_error::deserialize(deserializer).map_err(|err| {
            let key = match err.path().to_string() {
                key if key == "." => "(top level)".to_string(),
                // Broken YAML: the path is unknown; the message says where (line, column).
                key if key.contains('?') => "YAML syntax".to_string(),
                key => key,
            };
            let message = err.into_inner().to_string();
            // serde_yaml_ng puts the key, or the map holding it, in front of some messages:
            // once is enough.
            let message = match message.split_once(": ") {
                Some((head, rest))
                    if key == head
                        || key.starts_with(&format!("{head}."))
                        || key.starts_with(&format!("{head}[")) =>
                {
                    rest.to_string()
                }
                _ => message,
            };
            SceneError::Invalid {
                origin: origin.to_string(),
                key,
                message,
            }
        })?;
        scene
            .validate()
            .map_err(|(key, message)| SceneError::Invalid {
                origin: origin.to_string(),
                key,
                message,
            })?;
        Ok(scene)
    }

    /// How many scans the scene's duration holds: one at each whole period from 0, short of
    /// the end.
    pub fn frame_count(&self) -> u64 {
        (self.duration * self.lidar.rate_hz - 1e-9).ceil().max(0.0) as u64
    }

    /// Checks values serde cannot: signs, ranges, and what lies inside what.
    /// Errors are `(key path, message)`.
    pub fn validate(&self) -> Result<(), (String, String)> {
        crate::validate::validate(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot(motion: &str) -> Result<Scene, SceneError> {
        let text = format!(
            "duration: 1\nroom: {{outline: [[0,0],[5,0],[5,4],[0,4]]}}\nrobot: {{start: {{x: 1, \
             y: 1}}{motion}}}\n"
        );
        Scene::parse(&text, "s.yaml")
    }

    #[test]
    fn a_static_motion_refuses_unknown_keys() {
        let e = robot(", motion: {kind: static, runs: 5}")
            .expect_err("a key static does not have")
            .to_string();
        assert!(
            e.starts_with("s.yaml: robot.motion.runs: unknown field `runs`"),
            "{e}"
        );
        for motion in ["", ", motion: {kind: static}"] {
            let scene = robot(motion).expect("a static robot");
            assert!(matches!(scene.robot.motion, Motion::Static), "{motion}");
        }
    }

    fn furniture(piece: &str) -> Result<Scene, SceneError> {
        let text = format!(
            "duration: 1\nroom: {{outline: [[0,0],[5,0],[5,4],[0,4]]}}\nfurniture:\n  - {piece}\n\
             robot: {{start: {{x: 0.5, y: 0.5}}}}\n"
        );
        Scene::parse(&text, "s.yaml")
    }

    /// serde read these enums into a buffer first: a wrong type anywhere in a piece was
    /// named `furniture[0]`, at the line and column of the piece's `{`.
    #[test]
    fn a_wrong_type_in_a_tagged_map_names_its_key_and_position() {
        let cases = [
            (
                "{kind: box, name: sofa, center: [2.5, 2], size: [1, \"0.8m\"], height: 0.8}",
                "furniture[0].size[1]: invalid type: string \"0.8m\", expected f64 at line 4 \
                 column 57",
            ),
            (
                "{kind: table, center: [2, 2], size: [1, 0.8], height: tall}",
                "furniture[0].height: invalid type: string \"tall\", expected f64 at line 4 \
                 column 59",
            ),
            // Keys before `kind` are read the same way as those after it.
            (
                "{name: sofa, center: [2.5, 2], kind: box, size: [1, 0.8], height: [1]}",
                "furniture[0].height: invalid type: sequence, expected f64 at line 4 column 71",
            ),
        ];
        for (piece, expected) in cases {
            let e = furniture(piece).expect_err(piece).to_string();
            assert_eq!(e, format!("s.yaml: {expected}"), "{piece}");
        }
        let e = robot(", motion: {kind: coverage, spacing: \"35cm\"}")
            .expect_err("a spacing that is not a number")
            .to_string();
        assert_eq!(
            e,
            "s.yaml: robot.motion.spacing: invalid type: string \"35cm\", expected f64 at line \
             3 column 64"
        );
    }

    #[test]
    fn a_tagged_map_names_a_bad_kind_and_missing_or_unknown_keys() {
        let cases = [
            (
                "{kind: sofa, center: [2, 2], size: [1, 1], height: 1}",
                "furniture[0].kind: unknown variant `sofa`, expected one of `box`, `cylinder`, \
                 `polygon`, `table`, `chair`",
            ),
            (
                "{center: [2, 2], size: [1, 1], height: 1}",
                "furniture[0]: missing field `kind`",
            ),
            (
                "{kind: box, center: [2, 2], height: 1}",
                "furniture[0]: missing field `size`",
            ),
            (
                "{kind: cylinder, center: [2, 2], size: [1, 1], height: 1}",
                "furniture[0].size: unknown field `size`, expected one of",
            ),
            (
                "{size: [1, 1], kind: cylinder, center: [2, 2], height: 1}",
                "furniture[0]: unknown field `size`, expected one of",
            ),
            (
                "{kind: chair, center: [2, 2], size: [1, 1], height: 1, radius: 1}",
                "furniture[0].radius: unknown field `radius`, expected one of",
            ),
            (
                "7",
                "furniture[0]: invalid type: integer `7`, expected a furniture piece",
            ),
            // A key held until `kind` is known is named after the piece.
            (
                "{name: [1], kind: box, center: [2, 2], size: [1, 1], height: 1}",
                "furniture[0]: name: invalid type: sequence, expected a string",
            ),
            (
                "{points: [[1, 1], [2, \"x\"]], kind: polygon, height: 1}",
                "furniture[0]: points[1][1]: invalid type: string \"x\", expected f64",
            ),
        ];
        for (piece, expected) in cases {
            let e = furniture(piece).expect_err(piece).to_string();
            assert!(
                e.starts_with(&format!("s.yaml: {expected}")),
                "{piece}: {e}"
            );
        }
        let e = robot(", motion: {kind: orbit}")
            .expect_err("no such motion")
            .to_string();
        assert!(
            e.starts_with("s.yaml: robot.motion.kind: unknown variant `orbit`"),
            "{e}"
        );
    }

    #[test]
    fn a_tagged_map_reads_its_defaults_in_any_key_order() {
        let scene =
            furniture("{name: stool, center: [2, 2], kind: chair, size: [0.4, 0.4], height: 0.5}")
                .expect("a chair");
        let Furniture::Chair(chair) = &scene.furniture[0] else {
            panic!("{:?}", scene.furniture[0]);
        };
        assert_eq!(chair.name, "stool");
        assert_eq!((chair.leg_radius, chair.leg_inset), (0.02, 0.05));
        let scene = robot(", motion: {along_y: true, kind: coverage}").expect("coverage");
        assert!(
            matches!(
                scene.robot.motion,
                Motion::Coverage {
                    spacing: 0.35,
                    along_y: true
                }
            ),
            "{:?}",
            scene.robot.motion
        );
        // Written back, a scene reads the same.
        let text = serde_yaml_ng::to_string(&scene).unwrap();
        let again = Scene::parse(&text, "again.yaml").unwrap();
        assert_eq!(serde_yaml_ng::to_string(&again).unwrap(), text);
    }
}
