//! `sensor_msgs`: laser scans (and the compressed image a Marker may carry as texture).

use serde::{Deserialize, Serialize};

use crate::ros_message;
use crate::std_msgs::Header;

/// `sensor_msgs/msg/LaserScan`: one rotation of a planar Lidar. Angles in rad about +z of
/// `header.frame_id` (0 is +x), times in s, ranges in m; a range outside
/// [`range_min`, `range_max`] (including `inf` and `NaN`) is not a valid return.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct LaserScan {
    pub header: Header,
    pub angle_min: f32,
    pub angle_max: f32,
    pub angle_increment: f32,
    pub time_increment: f32,
    pub scan_time: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: Vec<f32>,
    pub intensities: Vec<f32>,
}
ros_message!(
    LaserScan,
    "sensor_msgs/msg/LaserScan",
    "std_msgs/Header header # timestamp in the header is the acquisition time of the first ray in the scan.
float32 angle_min            # start angle of the scan [rad]
float32 angle_max            # end angle of the scan [rad]
float32 angle_increment      # angular distance between measurements [rad]
float32 time_increment       # time between measurements [seconds]
float32 scan_time            # time between scans [seconds]
float32 range_min            # minimum range value [m]
float32 range_max            # maximum range value [m]
float32[] ranges             # range data [m] (values < range_min or > range_max should be discarded)
float32[] intensities        # intensity data [device-specific units]
",
    [Header],
    "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"
);

/// `sensor_msgs/msg/CompressedImage`: an image in `format` (e.g. `png`, `jpeg`).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub format: String,
    pub data: Vec<u8>,
}
ros_message!(
    CompressedImage,
    "sensor_msgs/msg/CompressedImage",
    "std_msgs/Header header\nstring format\nuint8[] data\n",
    [Header],
    "RIHS01_15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a"
);
