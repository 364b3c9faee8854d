//! RPLIDAR driver on `serialport`: the serial protocol (requests, answers and every
//! measurement format), rotation assembly with timestamps, conversion to fixed-size
//! `sensor_msgs/LaserScan`, and a fault-tolerant [`Driver`] that reconnects, resets and
//! reports diagnostics instead of failing. With the `fake` feature, [`fake`] provides a
//! fake device speaking the protocol on a pseudo-terminal for tests.
//!
//! See `docs/rplidar.md` for the supported models and modes and the fault behaviour.

pub mod config;
pub mod decode;
pub mod driver;
#[cfg(any(test, feature = "fake"))]
pub mod encode;
pub mod error;
#[cfg(all(feature = "fake", unix))]
pub mod fake;
pub mod protocol;
pub mod rotation;
pub mod scan;

pub use config::{Config, ConfigField, ScanModeChoice};
pub use decode::{DecodeStats, Sample, ScanFormat, StreamDecoder};
pub use driver::{DEFAULT_MOTOR_PWM, Driver, Event};
pub use error::{Error, Result};
pub use rotation::{Rotation, RotationAssembler, RotationSample};
pub use scan::{ScanFrame, ScanGeometry};
