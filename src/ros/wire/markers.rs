//! `visualization_msgs/MarkerArray` and what a marker is made of, fields in
//! the order of ROS 2 Kilted's .msg files, with the schema rosbag2 records.

use serde::{Deserialize, Serialize};

use crate::data::msg::{ros2msg_schema, Header, Point, Vector3, DEP_HEADER, DEP_TIME};

use super::RosType;

ros_types!("visualization_msgs" / "msg":
    MarkerArray = "MarkerArray",
    Marker = "Marker",
    UvCoordinate = "UVCoordinate",
    MeshFile = "MeshFile",
);
ros_types!("geometry_msgs" / "msg": Pose = "Pose", Quaternion = "Quaternion");
ros_types!("std_msgs" / "msg": ColorRgba = "ColorRGBA");
ros_types!("builtin_interfaces" / "msg": Duration = "Duration");
ros_types!("sensor_msgs" / "msg": CompressedImage = "CompressedImage");

/// `Marker.type`: an arrow from `points[0]` to `points[1]`.
pub const ARROW: i32 = 0;
/// `Marker.type`: a line segment between each pair of `points`.
pub const LINE_LIST: i32 = 5;
/// `Marker.type`: a cube at each of `points`.
pub const CUBE_LIST: i32 = 6;
/// `Marker.type`: a sphere at each of `points`.
pub const SPHERE_LIST: i32 = 7;
/// `Marker.action`: add or replace.
pub const ADD: i32 = 0;
/// `Marker.action`: remove every marker shown so far.
pub const DELETEALL: i32 = 3;

/// `builtin_interfaces/Duration`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Duration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds.
    pub nanosec: u32,
}

/// `geometry_msgs/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `std_msgs/ColorRGBA`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorRgba {
    /// Red, 0–1.
    pub r: f32,
    /// Green, 0–1.
    pub g: f32,
    /// Blue, 0–1.
    pub b: f32,
    /// Opacity, 0–1.
    pub a: f32,
}

/// `sensor_msgs/CompressedImage` (a marker's texture; unused here).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Header.
    pub header: Header,
    /// Image format.
    pub format: String,
    /// Bytes.
    pub data: Vec<u8>,
}

/// `visualization_msgs/UVCoordinate` (texture coordinates; unused here).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UvCoordinate {
    /// u.
    pub u: f32,
    /// v.
    pub v: f32,
}

/// `visualization_msgs/MeshFile` (an embedded mesh; unused here).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshFile {
    /// File name.
    pub filename: String,
    /// Bytes.
    pub data: Vec<u8>,
}

/// `visualization_msgs/Marker`, fields in the order of ROS 2 Kilted's .msg.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[allow(missing_docs)] // the .msg documents them
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    #[serde(rename = "type")]
    pub kind: i32,
    pub action: i32,
    pub pose: Pose,
    pub scale: Vector3,
    pub color: ColorRgba,
    pub lifetime: Duration,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRgba>,
    pub texture_resource: String,
    pub texture: CompressedImage,
    pub uv_coordinates: Vec<UvCoordinate>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}

/// `visualization_msgs/MarkerArray`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerArray {
    /// The markers, drawn together.
    pub markers: Vec<Marker>,
}

/// Full ros2msg schema of `MarkerArray` (as rosbag2 records it), so that
/// Foxglove and mcap-ros2-support decode recorded markers.
pub fn marker_array_schema() -> String {
    const MARKER: &str = "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\n\
        int32 LINE_STRIP=4\nint32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\n\
        int32 POINTS=8\nint32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n\
        int32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\
        std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
        geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
        builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n\
        std_msgs/ColorRGBA[] colors\nstring texture_resource\n\
        sensor_msgs/CompressedImage texture\nUVCoordinate[] uv_coordinates\nstring text\n\
        string mesh_resource\nMeshFile mesh_file\nbool mesh_use_embedded_materials\n";
    const XYZ: &str = "float64 x\nfloat64 y\nfloat64 z\n";
    ros2msg_schema(
        "Marker[] markers\n",
        &[
            (Marker::SCHEMA_NAME, MARKER),
            DEP_HEADER,
            DEP_TIME,
            (
                Pose::SCHEMA_NAME,
                "Point position\nQuaternion orientation\n",
            ),
            (Point::SCHEMA_NAME, XYZ),
            (
                Quaternion::SCHEMA_NAME,
                "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
            ),
            (Vector3::SCHEMA_NAME, XYZ),
            (
                ColorRgba::SCHEMA_NAME,
                "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
            ),
            (Duration::SCHEMA_NAME, "int32 sec\nuint32 nanosec\n"),
            (
                CompressedImage::SCHEMA_NAME,
                "std_msgs/Header header\nstring format\nuint8[] data\n",
            ),
            (UvCoordinate::SCHEMA_NAME, "float32 u\nfloat32 v\n"),
            (MeshFile::SCHEMA_NAME, "string filename\nuint8[] data\n"),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_schema_names_every_nested_type() {
        let s = marker_array_schema();
        for t in [
            "visualization_msgs/Marker",
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "geometry_msgs/Pose",
            "geometry_msgs/Point",
            "geometry_msgs/Quaternion",
            "geometry_msgs/Vector3",
            "std_msgs/ColorRGBA",
            "builtin_interfaces/Duration",
            "sensor_msgs/CompressedImage",
            "visualization_msgs/UVCoordinate",
            "visualization_msgs/MeshFile",
        ] {
            assert!(s.contains(&format!("MSG: {t}\n")), "schema lacks {t}");
        }
    }
}
