//! The CDR codec: the encapsulation header ROS 2 puts before every payload, then plain CDR
//! (alignment counted from after the header), via `cdr-encoding`.

use std::fmt;

use serde::de::{self, Deserialize, Deserializer, Visitor};

use crate::RosMessage;

/// The 4-byte CDR encapsulation header ROS 2 puts before every message (CDR, little endian).
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// The encapsulation header of big-endian plain CDR (accepted when decoding).
pub const CDR_BE_HEADER: [u8; 4] = [0x00, 0x00, 0x00, 0x00];

/// Trailing bytes accepted after a message: writers may pad a payload to a multiple of 4,
/// and `rosbags` accepts exactly this much too.
const MAX_TRAILING_PADDING: usize = 3;

/// Why bytes could not be turned into a message, or a message into bytes.
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    #[error(
        "{type_name}: CDR payload of {len} bytes is shorter than the 4-byte encapsulation header"
    )]
    TooShort { type_name: &'static str, len: usize },
    #[error(
        "{type_name}: unsupported CDR encapsulation {header:02x?} (expected plain CDR, 00 01 little or 00 00 big endian)"
    )]
    Encapsulation {
        type_name: &'static str,
        header: [u8; 4],
    },
    #[error("{type_name}: malformed CDR payload: {cause}")]
    Malformed {
        type_name: &'static str,
        cause: cdr_encoding::Error,
    },
    #[error(
        "{type_name}: {trailing} bytes left after the message ({len}-byte payload); wrong message type or corrupt length"
    )]
    TrailingBytes {
        type_name: &'static str,
        trailing: usize,
        len: usize,
    },
}

/// Serialises `msg` as ROS 2 does: encapsulation header, then little-endian CDR.
pub fn encode<M: RosMessage>(msg: &M) -> Result<Vec<u8>, CdrError> {
    let mut out = CDR_LE_HEADER.to_vec();
    cdr_encoding::to_writer::<M, byteorder::LittleEndian, _>(&mut out, msg).map_err(|cause| {
        CdrError::Malformed {
            type_name: M::TYPE_NAME,
            cause,
        }
    })?;
    Ok(out)
}

/// Parses a CDR payload with its encapsulation header (either byte order).
///
/// Rejects payloads with more than 3 bytes after the message (padding), so a payload of
/// another type is not silently half-read. A sequence or string length larger than the
/// bytes left fails with "unexpected end of input" before much is allocated: the decoder
/// grows vectors element by element, never from the declared length (see the tests).
pub fn decode<M: RosMessage>(bytes: &[u8]) -> Result<M, CdrError> {
    let type_name = M::TYPE_NAME;
    let Some((header, body)) = bytes.split_first_chunk::<4>() else {
        return Err(CdrError::TooShort {
            type_name,
            len: bytes.len(),
        });
    };
    let decoded = match header {
        [0x00, 0x01, _, _] => cdr_encoding::from_bytes::<M, byteorder::LittleEndian>(body),
        [0x00, 0x00, _, _] => cdr_encoding::from_bytes::<M, byteorder::BigEndian>(body),
        _ => {
            return Err(CdrError::Encapsulation {
                type_name,
                header: *header,
            });
        }
    };
    let (msg, consumed) = decoded.map_err(|cause| CdrError::Malformed { type_name, cause })?;
    let trailing = body.len().saturating_sub(consumed);
    if trailing > MAX_TRAILING_PADDING {
        return Err(CdrError::TrailingBytes {
            type_name,
            trailing,
            len: bytes.len(),
        });
    }
    Ok(msg)
}

/// Reads a CDR string strictly; every `String` field of the mirrors decodes through it
/// (`#[serde(deserialize_with)]`). `cdr-encoding` itself only logs a missing NUL terminator
/// and drops the last byte, so a corrupt string would lose text without an error.
pub(crate) fn terminated_string<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<String, D::Error> {
    // Text formats (the JSON of the golden values) have no terminator to check.
    if deserializer.is_human_readable() {
        return String::deserialize(deserializer);
    }
    // On the wire a string is laid out as bytes are: 4-aligned u32 length, then the bytes
    // (here with the NUL counted in the length).
    deserializer.deserialize_bytes(TerminatedString)
}

struct TerminatedString;

impl Visitor<'_> for TerminatedString {
    type Value = String;

    fn expecting(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        formatter.write_str("a NUL-terminated CDR string")
    }

    fn visit_bytes<E: de::Error>(self, bytes: &[u8]) -> Result<String, E> {
        // Length 0 is the empty string to Fast-CDR (ROS 2's own reader), though ROS writes 1.
        if bytes.is_empty() {
            return Ok(String::new());
        }
        let Some((0, text)) = bytes.split_last() else {
            return Err(E::custom(format!(
                "string of length {} without its NUL terminator",
                bytes.len()
            )));
        };
        // A peer's bytes that are not UTF-8 (a driver's Latin-1 frame_id) cost those
        // characters, replaced by U+FFFD as rclpy replaces them, not the whole message: every
        // scan of such a driver used to be dropped.
        Ok(String::from_utf8_lossy(text).into_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::std_msgs::Header;

    /// A Header payload: zero stamp, then `frame_id` as the length `declared` and `bytes`.
    fn header_payload(declared: u32, bytes: &[u8]) -> Vec<u8> {
        let mut payload = CDR_LE_HEADER.to_vec();
        payload.extend_from_slice(&[0; 8]);
        payload.extend_from_slice(&declared.to_le_bytes());
        payload.extend_from_slice(bytes);
        payload
    }

    #[test]
    fn a_string_without_its_nul_terminator_is_refused() {
        assert_eq!(
            decode::<Header>(&header_payload(4, b"abc\0"))
                .unwrap()
                .frame_id,
            "abc"
        );
        assert_eq!(
            decode::<Header>(&header_payload(0, b"")).unwrap().frame_id,
            ""
        );
        // Used to decode as "ab" without an error.
        let e = decode::<Header>(&header_payload(3, b"abc")).unwrap_err();
        assert!(matches!(e, CdrError::Malformed { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains("std_msgs/msg/Header")
                && text.contains("string of length 3 without its NUL"),
            "{text}"
        );
    }
}
