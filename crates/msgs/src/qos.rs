//! ROS 2 quality-of-service profiles, shared by the bag writer (`offered_qos_profiles`) and
//! the DDS transport, so a topic is offered the same way live and in a recording.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    Reliable,
    BestEffort,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Durability {
    Volatile,
    TransientLocal,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum History {
    KeepLast(u32),
    KeepAll,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct QosProfile {
    pub reliability: Reliability,
    pub durability: Durability,
    pub history: History,
}

impl QosProfile {
    /// rclcpp's `SensorDataQoS`: best effort, keep last 5.
    pub const fn sensor_data() -> Self {
        Self {
            reliability: Reliability::BestEffort,
            durability: Durability::Volatile,
            history: History::KeepLast(5),
        }
    }

    /// Reliable, volatile, keep last `depth`.
    pub const fn reliable(depth: u32) -> Self {
        Self {
            reliability: Reliability::Reliable,
            durability: Durability::Volatile,
            history: History::KeepLast(depth),
        }
    }

    /// Reliable, transient local ("latched"), keep last `depth`: late subscribers get the last messages.
    pub const fn latched(depth: u32) -> Self {
        Self {
            reliability: Reliability::Reliable,
            durability: Durability::TransientLocal,
            history: History::KeepLast(depth),
        }
    }
}
