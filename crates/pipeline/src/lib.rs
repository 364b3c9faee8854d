//! The embedded pipeline between ROS messages and the ROS-free core, shared by
//! `lidar-har run` (bags in, bags out) and the ROS nodes (topics in, topics out), so the two
//! cannot drift apart.
//!
//! Messages go in as CDR bytes with their topic ([`Pipeline::handle`]); each stage converts
//! what it needs, runs the core and returns its outputs both as core values (for the next
//! stage) and as CDR messages to publish or record ([`Outgoing`]). Stages:
//! - [`LocaliserStage`]: /scan, /odom, /map, /tf, /tf_static -> /human/pose,
//!   /human/observation, /human/markers.
//!
//! A further stage (the classifier) plugs in by consuming [`Step::localised`].

pub mod bag_run;
pub mod classifier;
pub mod convert;
pub mod files;
pub mod localiser_stage;

use lidar_har_core::localiser::LocaliserOutput;
use lidar_har_msgs::topics::{self, TopicSpec};
use lidar_har_msgs::{CdrError, RosMessage};

pub use localiser_stage::{LocaliserMessages, LocaliserStage, RoomSource};

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
    /// The localiser's result, when the message was a scan that could be used.
    pub localised: Option<LocaliserOutput>,
    /// Messages to publish, in order.
    pub outgoing: Vec<Outgoing>,
}

/// All stages, fed message by message in arrival (log-time) order.
#[derive(Debug)]
pub struct Pipeline {
    pub localiser: LocaliserStage,
}

impl Pipeline {
    pub fn new(localiser: LocaliserStage) -> Self {
        Self { localiser }
    }

    /// Whether `topic` is an input of some stage (the others need not be decoded at all).
    pub fn consumes(topic: &str) -> bool {
        [
            topics::SCAN,
            topics::ODOM,
            topics::MAP,
            topics::TF,
            topics::TF_STATIC,
        ]
        .iter()
        .any(|t| t.name == topic)
    }

    /// Feeds one message (CDR with its encapsulation header) received on `topic`.
    pub fn handle(&mut self, topic: &str, cdr: &[u8]) -> Result<Step, PipelineError> {
        let mut step = Step::default();
        let decode_error = |source| PipelineError::Decode {
            topic: topic.to_string(),
            cause: source,
        };
        match topic {
            t if t == topics::SCAN.name => {
                let scan = lidar_har_msgs::decode(cdr).map_err(decode_error)?;
                if let Some(output) = self.localiser.on_scan(&scan) {
                    self.localiser_outgoing(&output, &mut step.outgoing)?;
                    step.localised = Some(output);
                }
            }
            t if t == topics::ODOM.name => self
                .localiser
                .on_odom(&lidar_har_msgs::decode(cdr).map_err(decode_error)?),
            t if t == topics::MAP.name => self
                .localiser
                .on_map(&lidar_har_msgs::decode(cdr).map_err(decode_error)?),
            t if t == topics::TF.name => self
                .localiser
                .on_tf(&lidar_har_msgs::decode(cdr).map_err(decode_error)?),
            t if t == topics::TF_STATIC.name => self
                .localiser
                .on_tf_static(&lidar_har_msgs::decode(cdr).map_err(decode_error)?),
            _ => {}
        }
        Ok(step)
    }

    fn localiser_outgoing(
        &self,
        output: &LocaliserOutput,
        out: &mut Vec<Outgoing>,
    ) -> Result<(), PipelineError> {
        let stamp = output.stamp_ns;
        let messages = self.localiser.messages(output);
        if let Some(pose) = &messages.pose {
            out.push(Outgoing::encode(topics::HUMAN_POSE, stamp, pose)?);
        }
        if let Some(observation) = &messages.observation {
            out.push(Outgoing::encode(
                topics::HUMAN_OBSERVATION,
                stamp,
                observation,
            )?);
        }
        out.push(Outgoing::encode(
            topics::HUMAN_MARKERS,
            stamp,
            &messages.markers,
        )?);
        Ok(())
    }
}
