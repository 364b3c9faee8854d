//! `rosgraph_msgs`: the simulated clock on `/clock`.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::ros_message;

/// `rosgraph_msgs/msg/Clock`: the current time for nodes with `use_sim_time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Clock {
    pub clock: Time,
}
ros_message!(
    Clock,
    "rosgraph_msgs/msg/Clock",
    "builtin_interfaces/Time clock\n",
    [Time],
    "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"
);
