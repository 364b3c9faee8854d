//! The embedded pipeline between ROS messages and the ROS-free core, shared by
//! `lidar-har run` (bags in, bags out) and the ROS nodes (topics in, topics out), so the two
//! cannot drift apart.
//!
//! Each stage takes messages as CDR bytes with their topic, converts what it needs, runs the
//! core and returns its outputs both as core values and as CDR messages to publish or record
//! ([`Outgoing`]). Each lists the topics it reads and writes (`INPUTS`, `OUTPUTS`):
//! - [`LocaliserStage`]: /scan, /odom, /map, /tf, /tf_static -> /human/pose,
//!   /human/observation, /human/markers;
//! - [`classifier::ClassifierStage`]: /human/observation -> /human/activity, /human/pelvis,
//!   /human/fall_alert, /human/markers.

pub mod bag_run;
pub mod classifier;
pub mod convert;
pub mod files;
pub mod localiser_stage;
pub mod odometry_wait;

use std::time::Duration;

use lidar_har_core::localiser::LocaliserOutput;
use lidar_har_msgs::topics::TopicSpec;
use lidar_har_msgs::{CdrError, RosMessage};

pub use localiser_stage::{LocaliserInput, LocaliserMessages, LocaliserStage, RoomSource};

/// A message for a topic of the contract, ready to publish or record.
#[derive(Debug, Clone)]
pub struct Outgoing {
    pub topic: TopicSpec,
    /// The stamp of the scan it answers.
    pub stamp_ns: i64,
    pub cdr: Vec<u8>,
}

impl Outgoing {
    fn encode<M: RosMessage>(
        topic: TopicSpec,
        stamp_ns: i64,
        msg: &M,
    ) -> Result<Self, PipelineError> {
        debug_assert_eq!(topic.type_name, M::TYPE_NAME);
        Ok(Self {
            topic,
            stamp_ns,
            cdr: lidar_har_msgs::encode(msg)?,
        })
    }
}

/// Why an incoming message could not be used.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("message on {topic} cannot be decoded: {cause}")]
    Decode { topic: String, cause: CdrError },
    #[error("an output message cannot be encoded: {0}")]
    Encode(CdrError),
}

impl From<CdrError> for PipelineError {
    fn from(cause: CdrError) -> Self {
        Self::Encode(cause)
    }
}

/// What one incoming message produced.
#[derive(Debug, Default)]
pub struct Step {
    /// The scans localised, in the order they came: the message itself when it is a scan
    /// with its odometry, and scans that waited for odometry (`odometry.max_wait_s`) which
    /// this message's odometry, or its receive time, let go.
    pub scans: Vec<ProcessedScan>,
    /// Messages to publish, in order.
    pub outgoing: Vec<Outgoing>,
}

/// One scan through the localiser.
#[derive(Debug)]
pub struct ProcessedScan {
    /// The localiser's result; `None` when the scan was skipped or learned from.
    pub output: Option<LocaliserOutput>,
    /// The core's time (conversion and logging excluded); `None` when the core did not see
    /// the scan (skipped while waiting for the first `map -> odom`).
    pub localise_time: Option<Duration>,
    /// Decoding, localising and encoding the outputs (not the wait for odometry).
    pub pipeline_time: Duration,
}
