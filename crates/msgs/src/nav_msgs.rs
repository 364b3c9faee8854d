//! `nav_msgs`: odometry and occupancy-grid maps.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::geometry_msgs::{Pose, PoseWithCovariance, TwistWithCovariance};
use crate::ros_message;
use crate::std_msgs::Header;

/// `nav_msgs/msg/Odometry`: the pose of `child_frame_id` in `header.frame_id` (usually
/// `odom`), and its velocity in `child_frame_id`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}
ros_message!(
    Odometry,
    "nav_msgs/msg/Odometry",
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    [Header, PoseWithCovariance, TwistWithCovariance],
    "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
);

/// `nav_msgs/msg/MapMetaData`: size and placement of an occupancy grid.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MapMetaData {
    pub map_load_time: Time,
    /// Cell edge, m.
    pub resolution: f32,
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// Pose of cell (0, 0)'s corner in the map frame.
    pub origin: Pose,
}
ros_message!(
    MapMetaData,
    "nav_msgs/msg/MapMetaData",
    "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\ngeometry_msgs/Pose origin\n",
    [Time, Pose],
    "RIHS01_2772d4b2000ef2b35dbaeb80fd3946c1369f817fb4f75677d916d27c17d763c8"
);

/// `nav_msgs/msg/OccupancyGrid`: a 2D map, row-major from cell (0, 0); each cell is the
/// occupancy probability in percent (0..100) or -1 for unknown.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct OccupancyGrid {
    pub header: Header,
    pub info: MapMetaData,
    pub data: Vec<i8>,
}
ros_message!(
    OccupancyGrid,
    "nav_msgs/msg/OccupancyGrid",
    "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
    [Header, MapMetaData],
    "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7"
);
