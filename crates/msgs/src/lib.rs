//! Serde mirrors of the ROS 2 messages lidar_har uses, their CDR codec, and their schema
//! texts in rosbag2's format. This crate is the only place that knows message layouts:
//! bags, the DDS transport and the rplidar driver all exchange CDR bytes made here.

pub mod qos;
pub mod topics;

use serde::{Serialize, de::DeserializeOwned};

/// The 4-byte CDR encapsulation header ROS 2 puts before every message (CDR, little endian).
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A ROS 2 message type: its serde mirror plus what is needed to name and describe it.
pub trait RosMessage: Serialize + DeserializeOwned {
    /// The full type name, e.g. `sensor_msgs/msg/LaserScan`.
    const TYPE_NAME: &'static str;
    /// The type's .msg text followed by every dependency, as rosbag2 stores it in MCAP
    /// schemas (`ros2msg` encoding): 80 `=` then `MSG: pkg/Type` before each dependency.
    fn schema_text() -> String;
}

/// Why bytes could not be turned into a message, or a message into bytes.
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    #[error("{type_name}: CDR payload of {len} bytes is shorter than the 4-byte encapsulation header")]
    TooShort { type_name: &'static str, len: usize },
    #[error("{type_name}: unsupported CDR encapsulation {header:02x?} (expected little- or big-endian plain CDR)")]
    Encapsulation { type_name: &'static str, header: [u8; 4] },
    #[error("{type_name}: malformed CDR payload: {source}")]
    Malformed {
        type_name: &'static str,
        #[source]
        source: cdr_encoding::Error,
    },
}

/// Serialises `msg` as ROS 2 does: encapsulation header, then little-endian CDR.
pub fn encode<M: RosMessage>(msg: &M) -> Result<Vec<u8>, CdrError> {
    let mut out = CDR_LE_HEADER.to_vec();
    cdr_encoding::to_writer::<M, byteorder::LittleEndian, _>(&mut out, msg).map_err(|source| {
        CdrError::Malformed { type_name: M::TYPE_NAME, source }
    })?;
    Ok(out)
}

/// Parses a CDR payload with its encapsulation header (either byte order).
pub fn decode<M: RosMessage>(bytes: &[u8]) -> Result<M, CdrError> {
    let type_name = M::TYPE_NAME;
    let Some((header, body)) = bytes.split_first_chunk::<4>() else {
        return Err(CdrError::TooShort { type_name, len: bytes.len() });
    };
    let decoded = match header {
        [0x00, 0x01, _, _] => cdr_encoding::from_bytes::<M, byteorder::LittleEndian>(body),
        [0x00, 0x00, _, _] => cdr_encoding::from_bytes::<M, byteorder::BigEndian>(body),
        _ => return Err(CdrError::Encapsulation { type_name, header: *header }),
    };
    decoded
        .map(|(msg, _consumed)| msg)
        .map_err(|source| CdrError::Malformed { type_name, source })
}
