//! `tf2_msgs`: transforms on `/tf` and `/tf_static`.

use serde::{Deserialize, Serialize};

use crate::geometry_msgs::TransformStamped;
use crate::ros_message;

/// `tf2_msgs/msg/TFMessage`: a batch of transforms.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TFMessage {
    pub transforms: Vec<TransformStamped>,
}
ros_message!(
    TFMessage,
    "tf2_msgs/msg/TFMessage",
    "geometry_msgs/TransformStamped[] transforms\n",
    [TransformStamped],
    "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
);
