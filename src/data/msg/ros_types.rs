//! The standard ROS message types ParticleState is built from
//! (`builtin_interfaces/Time`, `std_msgs/Header`, `geometry_msgs/Vector3` and
//! `Point`), and their ros2msg definitions as schema dependency blocks.

use serde::{Deserialize, Serialize};

/// `std_msgs/Header` definition, as a ros2msg dependency block (name, text).
pub const DEP_HEADER: (&str, &str) = (
    "std_msgs/Header",
    "# Standard metadata for higher-level stamped data types.\n\
     builtin_interfaces/Time stamp\n\
     string frame_id\n",
);
/// `builtin_interfaces/Time` definition, as a ros2msg dependency block.
pub const DEP_TIME: (&str, &str) = (
    "builtin_interfaces/Time",
    "# Time since the epoch (here: simulation time).\n\
     int32 sec\n\
     uint32 nanosec\n",
);
/// `geometry_msgs/Vector3` definition, as a ros2msg dependency block.
pub const DEP_VECTOR3: (&str, &str) =
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n");
/// `geometry_msgs/Point` definition, as a ros2msg dependency block.
pub const DEP_POINT: (&str, &str) = ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n");

/// Builds a ros2msg schema as rosbag2 writes it: the main definition, then each
/// dependency as a block headed by a line of 80 `=` and `MSG: pkg/Type`.
pub fn ros2msg_schema(main: &str, deps: &[(&str, &str)]) -> String {
    let mut s = main.to_string();
    for (name, text) in deps {
        if !s.ends_with('\n') {
            s.push('\n');
        }
        s.push_str(&"=".repeat(80));
        s.push_str("\nMSG: ");
        s.push_str(name);
        s.push('\n');
        s.push_str(text);
    }
    s
}

/// `builtin_interfaces/Time` in its wire layout.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds, `0..1_000_000_000`.
    pub nanosec: u32,
}

impl Time {
    /// Seconds to `Time`, rounded to the nearest nanosecond. Saturates outside the
    /// `i32` seconds range, and maps NaN to zero (writers validate times first).
    pub fn from_secs(t: f64) -> Time {
        Time::from_nanos(if t.is_nan() {
            0
        } else {
            (t * 1e9).round() as i64 // `as` saturates, which is what we want here
        })
    }

    /// Nanoseconds to `Time` (floor division, so `nanosec` is always in range).
    pub fn from_nanos(ns: i64) -> Time {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = ns.rem_euclid(1_000_000_000) as u32;
        match i32::try_from(sec) {
            Ok(sec) => Time { sec, nanosec },
            Err(_) if sec < 0 => Time {
                sec: i32::MIN,
                nanosec: 0,
            },
            Err(_) => Time {
                sec: i32::MAX,
                nanosec: 999_999_999,
            },
        }
    }

    /// Total nanoseconds (exact).
    pub fn as_nanos(&self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }

    /// Seconds as a float.
    pub fn as_secs(&self) -> f64 {
        self.as_nanos() as f64 * 1e-9
    }
}

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Time stamp.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

/// `geometry_msgs/Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component (0 in 2D).
    pub z: f64,
}

/// `geometry_msgs/Point`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x coordinate.
    pub x: f64,
    /// y coordinate.
    pub y: f64,
    /// z coordinate (0 in 2D).
    pub z: f64,
}

impl Vector3 {
    /// The vector of 2 or 3 coordinates (z = 0 in 2D).
    pub fn from_coords(c: &[f64]) -> Self {
        let [x, y, z] = xyz(c);
        Self { x, y, z }
    }
}

impl Point {
    /// The point of 2 or 3 coordinates (z = 0 in 2D).
    pub fn from_coords(c: &[f64]) -> Self {
        let [x, y, z] = xyz(c);
        Self { x, y, z }
    }
}

/// `[x, y, z]` of a particle's flat coordinates, 0 where it has none.
fn xyz(c: &[f64]) -> [f64; 3] {
    std::array::from_fn(|i| c.get(i).copied().unwrap_or(0.0))
}

#[cfg(test)]
mod tests {
    use super::{Point, Vector3};

    /// 2D coordinates get z = 0, 3D ones keep theirs; a vector and a point
    /// of the same numbers agree.
    #[test]
    fn coordinates_pad_to_three() {
        let v = Vector3::from_coords(&[1.5, -2.0]);
        assert_eq!((v.x, v.y, v.z), (1.5, -2.0, 0.0));
        let p = Point::from_coords(&[1.5, -2.0, 4.0]);
        assert_eq!((p.x, p.y, p.z), (1.5, -2.0, 4.0));
        assert_eq!(Point::from_coords(&[]), Point::default());
        let flat = [1.0, 2.0, 3.0, 4.0];
        let vs = super::super::to_vec3(&flat, 2);
        assert_eq!(
            vs,
            [
                Vector3::from_coords(&[1.0, 2.0]),
                Vector3::from_coords(&[3.0, 4.0])
            ]
        );
    }
}
