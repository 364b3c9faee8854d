//! Serde mirrors of the ROS 2 messages lidar_har uses, their CDR codec, and their schema
//! texts in rosbag2's format. This crate is the only place that knows message layouts:
//! bags, the DDS transport and the rplidar driver all exchange CDR bytes made here.
//!
//! One module per ROS package, named like the package; struct and field names are those of
//! ROS 2 Humble (identical on the wire to Jazzy for every type here, see `docs/msgs.md`).

pub mod builtin_interfaces;
pub mod diagnostic_msgs;
pub mod geometry_msgs;
pub mod lidar_har_msgs;
pub mod nav_msgs;
pub mod qos;
pub mod rcl_interfaces;
pub mod rosgraph_msgs;
pub mod schema;
pub mod sensor_msgs;
pub mod std_msgs;
pub mod tf2_msgs;
pub mod topics;
pub mod visualization_msgs;

mod codec;

pub use codec::{CDR_BE_HEADER, CDR_LE_HEADER, CdrError, decode, encode};
pub use schema::MessageDefinition;

use serde::{Serialize, de::DeserializeOwned};

/// A ROS 2 message type: its serde mirror plus what is needed to name and describe it.
pub trait RosMessage: Serialize + DeserializeOwned {
    /// The full type name, e.g. `sensor_msgs/msg/LaserScan`.
    const TYPE_NAME: &'static str;
    /// The type's own .msg text and the definitions of the types its fields use.
    const DEFINITION: MessageDefinition;

    /// The type's .msg text followed by every dependency, as rosbag2 stores it in MCAP
    /// schemas (`ros2msg` encoding): 80 `=` then `MSG: pkg/Type` before each dependency.
    fn schema_text() -> String {
        Self::DEFINITION.schema_text()
    }
}

/// Implements [`RosMessage`] for a mirror: its type name, .msg text, the message types its
/// fields use (checked against the .msg text by the tests of `schema`) and its RIHS01 type
/// hash (checked against the schema text by `tests/tests/bag_python.rs`).
macro_rules! ros_message {
    ($ty:ty, $name:literal, $text:expr, [$($dep:ty),* $(,)?], $hash:literal) => {
        impl $crate::RosMessage for $ty {
            const TYPE_NAME: &'static str = $name;
            const DEFINITION: $crate::MessageDefinition = $crate::MessageDefinition {
                type_name: $name,
                text: $text,
                dependencies: &[$(&<$dep as $crate::RosMessage>::DEFINITION),*],
                type_hash: $hash,
            };
        }
    };
}
pub(crate) use ros_message;
