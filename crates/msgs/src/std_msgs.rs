//! `std_msgs`: the header of stamped messages, and colours.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::ros_message;

/// `std_msgs/msg/Header`: when the data was measured and in which coordinate frame.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub frame_id: String,
}
ros_message!(
    Header,
    "std_msgs/msg/Header",
    "builtin_interfaces/Time stamp\nstring frame_id\n",
    [Time],
    "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"
);

impl Header {
    /// A header stamped `stamp` in frame `frame_id`.
    pub fn new(stamp: Time, frame_id: impl Into<String>) -> Self {
        Self {
            stamp,
            frame_id: frame_id.into(),
        }
    }
}

/// `std_msgs/msg/ColorRGBA`: a colour, each channel 0..1.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ColorRGBA {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}
ros_message!(
    ColorRGBA,
    "std_msgs/msg/ColorRGBA",
    "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    [],
    "RIHS01_77a7a5b9ae477306097665106e0413ba74440245b1f3d0c6d6405fe5c7813fe8"
);

impl ColorRGBA {
    pub const fn new(r: f32, g: f32, b: f32, a: f32) -> Self {
        Self { r, g, b, a }
    }
}
