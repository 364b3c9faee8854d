//! rosbag2 bags without ROS 2: read MCAP and sqlite3 storage (metadata.yaml versions 1 to 9 or
//! none, zstd/lz4 chunks, rosbag2's zstd file and message compression, bare storage files) and
//! write MCAP (or sqlite3) bags that `ros2 bag play`, `rosbags` and Foxglove accept (version 9
//! for Jazzy and later, or version 8, which Humble and Iron read too).
//!
//! The API is byte-level: messages are CDR bytes made by `lidar-har-msgs`; a bag stores them
//! with their type name and `ros2msg` schema text. Reading streams in constant memory; writing
//! flushes at the first write after each flush interval, so a recorder killed while messages
//! keep coming loses about one interval at most.

mod compression;
mod error;
mod mcap_records;
mod mcap_storage;
pub mod metadata;
pub mod qos;
mod reader;
mod source;
mod sqlite_storage;
mod writer;

pub use error::{BagError, Result};
pub use qos::OfferedQos;
pub use reader::{
    BagInfo, BagMessage, BagReader, MessageFilter, Messages, RecordedVersion, TopicInfo,
};
pub use source::{PROCESS_ENDING, remove_temporary_copies};
pub use writer::{
    BagSummary, BagWriter, Compression, MetadataVersion, StorageId, TopicHandle, WriterOptions,
    validate_topic_name,
};
