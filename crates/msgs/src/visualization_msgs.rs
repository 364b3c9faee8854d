//! `visualization_msgs`: markers for rviz2 and Foxglove.
//!
//! The layout is ROS 2 Humble's, which includes the texture and mesh-file fields added
//! before Humble was released; Jazzy's Marker is byte-identical on the wire (it only adds
//! the constant `ARROW_STRIP = 12`, which Humble's rviz2 does not draw). Foxy and Galactic
//! lack those fields and cannot read these markers.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Duration;
use crate::geometry_msgs::{Point, Pose, Vector3};
use crate::ros_message;
use crate::sensor_msgs::CompressedImage;
use crate::std_msgs::{ColorRGBA, Header};

/// `visualization_msgs/msg/Marker`: one shape to draw. `type` is one of the shape constants,
/// `action` one of the action constants; `scale` is in m, `lifetime` 0 means forever.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Marker {
    pub header: Header,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub ns: String,
    pub id: i32,
    pub r#type: i32,
    pub action: i32,
    pub pose: Pose,
    pub scale: Vector3,
    pub color: ColorRGBA,
    pub lifetime: Duration,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRGBA>,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub texture_resource: String,
    pub texture: CompressedImage,
    pub uv_coordinates: Vec<UVCoordinate>,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub text: String,
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}
ros_message!(
    Marker,
    "visualization_msgs/msg/Marker",
    "int32 ARROW=0
int32 CUBE=1
int32 SPHERE=2
int32 CYLINDER=3
int32 LINE_STRIP=4
int32 LINE_LIST=5
int32 CUBE_LIST=6
int32 SPHERE_LIST=7
int32 POINTS=8
int32 TEXT_VIEW_FACING=9
int32 MESH_RESOURCE=10
int32 TRIANGLE_LIST=11

int32 ADD=0
int32 MODIFY=0
int32 DELETE=2
int32 DELETEALL=3

std_msgs/Header header
string ns
int32 id
int32 type
int32 action
geometry_msgs/Pose pose
geometry_msgs/Vector3 scale
std_msgs/ColorRGBA color
builtin_interfaces/Duration lifetime
bool frame_locked
geometry_msgs/Point[] points
std_msgs/ColorRGBA[] colors
string texture_resource
sensor_msgs/CompressedImage texture
UVCoordinate[] uv_coordinates
string text
string mesh_resource
MeshFile mesh_file
bool mesh_use_embedded_materials
",
    [
        Header,
        Pose,
        Vector3,
        ColorRGBA,
        Duration,
        Point,
        CompressedImage,
        UVCoordinate,
        MeshFile
    ],
    "RIHS01_45b13ccf791f225962bf74e746f9644518855d783a6f42ba0cc14fde2b4f3ce0"
);

impl Marker {
    pub const ARROW: i32 = 0;
    pub const CUBE: i32 = 1;
    pub const SPHERE: i32 = 2;
    pub const CYLINDER: i32 = 3;
    pub const LINE_STRIP: i32 = 4;
    pub const LINE_LIST: i32 = 5;
    pub const CUBE_LIST: i32 = 6;
    pub const SPHERE_LIST: i32 = 7;
    pub const POINTS: i32 = 8;
    pub const TEXT_VIEW_FACING: i32 = 9;
    pub const MESH_RESOURCE: i32 = 10;
    pub const TRIANGLE_LIST: i32 = 11;

    pub const ADD: i32 = 0;
    pub const MODIFY: i32 = 0;
    pub const DELETE: i32 = 2;
    pub const DELETEALL: i32 = 3;
}

/// `visualization_msgs/msg/MarkerArray`: markers published together.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}
ros_message!(
    MarkerArray,
    "visualization_msgs/msg/MarkerArray",
    "Marker[] markers\n",
    [Marker],
    "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf"
);

/// `visualization_msgs/msg/UVCoordinate`: a texture coordinate of a triangle-list vertex.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct UVCoordinate {
    pub u: f32,
    pub v: f32,
}
ros_message!(
    UVCoordinate,
    "visualization_msgs/msg/UVCoordinate",
    "float32 u\nfloat32 v\n",
    [],
    "RIHS01_f27f7ed21fe360c6066944f856b801a0c0d1e94e815b6886444b42d90b196a26"
);

/// `visualization_msgs/msg/MeshFile`: a mesh sent inline instead of by `mesh_resource`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct MeshFile {
    #[serde(deserialize_with = "crate::codec::terminated_string")]
    pub filename: String,
    pub data: Vec<u8>,
}
ros_message!(
    MeshFile,
    "visualization_msgs/msg/MeshFile",
    "string filename\nuint8[] data\n",
    [],
    "RIHS01_7710ece15a148fb7c9b546364cfb215bb06098087bd6394fe5b73a493508f8c4"
);
