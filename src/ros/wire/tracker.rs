//! What trackers and cameras publish: `geometry_msgs/PoseArray` and
//! `sensor_msgs/PointCloud2` (decoded into positions by
//! `ros/tracker.rs`).

use serde::{Deserialize, Serialize};

use crate::data::msg::{Header, Point};

ros_types!("geometry_msgs" / "msg":
    Quaternion = "Quaternion",
    Pose = "Pose",
    PoseArray = "PoseArray",
);
ros_types!("sensor_msgs" / "msg": PointField = "PointField", PointCloud2 = "PointCloud2");

/// `geometry_msgs/msg/Quaternion`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
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

/// `geometry_msgs/msg/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Where.
    pub position: Point,
    /// Which way (ignored: particles are points).
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseArray`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseArray {
    /// Stamp and frame of the poses.
    pub header: Header,
    /// One per particle, in the template's order.
    pub poses: Vec<Pose>,
}

/// `sensor_msgs/msg/PointField`: one field of a point.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointField {
    /// Its name (`x`, `y`, `z`, `intensity`, ...).
    pub name: String,
    /// Bytes from the start of the point.
    pub offset: u32,
    /// One of the `POINT_FIELD_*` datatypes.
    pub datatype: u8,
    /// Elements in the field.
    pub count: u32,
}

/// `PointField` datatype INT8 (the others follow in order up to FLOAT64).
pub const POINT_FIELD_INT8: u8 = 1;
/// `PointField` datatype FLOAT32.
pub const POINT_FIELD_FLOAT32: u8 = 7;
/// `PointField` datatype FLOAT64.
pub const POINT_FIELD_FLOAT64: u8 = 8;

/// `sensor_msgs/msg/PointCloud2`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointCloud2 {
    /// Stamp and frame of the points.
    pub header: Header,
    /// Rows (1: an unorganised cloud).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// The fields of each point.
    pub fields: Vec<PointField>,
    /// Byte order of `data`.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// `row_step * height` bytes.
    pub data: Vec<u8>,
    /// No invalid points.
    pub is_dense: bool,
}
