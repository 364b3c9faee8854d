//! `diagnostic_msgs`: health reports on `/diagnostics`.

use serde::{Deserialize, Serialize};

use crate::ros_message;
use crate::std_msgs::Header;

/// `diagnostic_msgs/msg/DiagnosticArray`: the status of several components at one time.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}
ros_message!(
    DiagnosticArray,
    "diagnostic_msgs/msg/DiagnosticArray",
    "std_msgs/Header header\nDiagnosticStatus[] status\n",
    [Header, DiagnosticStatus],
    "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e"
);

/// `diagnostic_msgs/msg/DiagnosticStatus`: one component's health; `level` is one of the
/// level constants.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    pub level: u8,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub name: String,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub message: String,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}
ros_message!(
    DiagnosticStatus,
    "diagnostic_msgs/msg/DiagnosticStatus",
    "byte OK=0
byte WARN=1
byte ERROR=2
byte STALE=3

byte level
string name
string message
string hardware_id
KeyValue[] values
",
    [KeyValue],
    "RIHS01_b0e3e692ea2d54a8af2f4ef1930e81556a2db55216b771f8a7d2724ed47bf0e4"
);

impl DiagnosticStatus {
    pub const OK: u8 = 0;
    pub const WARN: u8 = 1;
    pub const ERROR: u8 = 2;
    pub const STALE: u8 = 3;
}

/// `diagnostic_msgs/msg/KeyValue`: one named value of a status.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub key: String,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub value: String,
}
ros_message!(
    KeyValue,
    "diagnostic_msgs/msg/KeyValue",
    "string key\nstring value\n",
    [],
    "RIHS01_d68081eaa540288c5440753baecef0c4e16e81a5f78ad68902ded5100413bb42"
);

impl KeyValue {
    pub fn new(key: impl Into<String>, value: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            value: value.into(),
        }
    }
}
