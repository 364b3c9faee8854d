//! `rcl_interfaces`: a node's log records on `/rosout`.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::ros_message;

/// `rcl_interfaces/msg/Log`: one log record of a node, as rcl publishes it on /rosout;
/// `level` is one of the severity constants, `name` the node's logger name
/// (`robot1.localiser`).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Log {
    pub stamp: Time,
    pub level: u8,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub name: String,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub msg: String,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub file: String,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub function: String,
    pub line: u32,
}
ros_message!(
    Log,
    "rcl_interfaces/msg/Log",
    "uint8 DEBUG=10
uint8 INFO=20
uint8 WARN=30
uint8 ERROR=40
uint8 FATAL=50

builtin_interfaces/Time stamp
uint8 level
string name
string msg
string file
string function
uint32 line
",
    [Time],
    "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac"
);

impl Log {
    pub const DEBUG: u8 = 10;
    pub const INFO: u8 = 20;
    pub const WARN: u8 = 30;
    pub const ERROR: u8 = 40;
    pub const FATAL: u8 = 50;
}
