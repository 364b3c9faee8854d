//! The lidar_har simulator: a room with furniture, a cleaning robot driving a 2D Lidar
//! through it, and a person performing the nine activities.
//!
//! - [`scene`]: the YAML scene format and its validation.
//! - [`Simulator`]: streams [`Frame`]s (scan, robot pose and twist, person pose, activity,
//!   per-beam hit labels) in memory, deterministically from a seed.
//! - [`map`]: the room as an occupancy grid and map_server files.
//! - [`generate`]: random furnished rooms, for training on more rooms than were drawn.
//! - [`scripts`]: the random activity scripts episodes are drawn from (everyday, with falls,
//!   fall and stay down) and the simulator for one episode.
//!
//! See docs/simulator.md for the schema, the body model and the noise model.

pub mod body;
pub mod generate;
pub mod lidar;
pub mod map;
pub mod person;
pub mod record;
pub mod render;
pub mod robot;
pub mod scene;
pub mod scripts;
pub mod shapes;
pub mod simulator;
mod validate;
pub mod world;

pub use lidar::ScanGeometry;
pub use scene::{Scene, SceneError};
pub use simulator::{Frame, PersonFrame, Simulator};
pub use world::BeamLabel;
