//! Tracker messages into positions: `geometry_msgs/PoseArray` (one pose per
//! particle) and `sensor_msgs/PointCloud2` (one point per particle: the x, y
//! and z fields found by name, FLOAT32 or FLOAT64, any point step, organised
//! or not, either byte order), each checked against what the template
//! expects ([`Expect`]: frame, particle count, dimension). Whatever does not
//! fit is refused with the reason ([`TrackerError`]); nothing here panics.
//! The positions become a position-only `ParticleState` of the template in
//! [`super::tracker_input`].

use crate::data::msg::{Header, Vector3};

use super::wire::tracker::{POINT_FIELD_FLOAT32, POINT_FIELD_FLOAT64};
use super::wire::{PointCloud2, PointField, PoseArray};

/// What a tracker message must match.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Expect {
    /// `header.frame_id` (the `frame_id` parameter).
    pub frame_id: String,
    /// Particles of the template.
    pub n: usize,
    /// Its dimension (2: z must be 0).
    pub dim: usize,
}

/// Why a tracker message was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TrackerError {
    /// `header.frame_id` is not the expected frame.
    #[error(
        "{kind} frame_id {got:?} is not the frame_id parameter {want:?} (no tf2 lookup is \
         made: publish in {want:?} or set frame_id)"
    )]
    Frame {
        /// The message type.
        kind: &'static str,
        /// The message's frame.
        got: String,
        /// The parameter.
        want: String,
    },
    /// Not one point per particle of the template.
    #[error("{kind} has {got} points; the template (input_template) has {want} particles")]
    Count {
        /// The message type.
        kind: &'static str,
        /// Points in the message.
        got: usize,
        /// Particles in the template.
        want: usize,
    },
    /// A coordinate that is NaN or infinite.
    #[error("{kind} point {index}: {axis} = {value} is not finite")]
    NotFinite {
        /// The message type.
        kind: &'static str,
        /// The point.
        index: usize,
        /// `x`, `y` or `z`.
        axis: char,
        /// Its value.
        value: f64,
    },
    /// A z off the plane of a 2-D template.
    #[error("{kind} point {index}: z = {value}, but the template is 2-D (publish z = 0)")]
    OffPlane {
        /// The message type.
        kind: &'static str,
        /// The point.
        index: usize,
        /// Its z.
        value: f64,
    },
    /// No field of that name.
    #[error("PointCloud2 has no field {axis:?} (fields: [{fields}]); x, y and z are needed")]
    MissingField {
        /// `x`, `y` or `z`.
        axis: char,
        /// The fields it has.
        fields: String,
    },
    /// A field named twice.
    #[error("PointCloud2 field {0:?} is declared twice")]
    DuplicateField(char),
    /// A coordinate field that is not a float.
    #[error(
        "PointCloud2 field {axis:?} has datatype {datatype}; x, y and z must be FLOAT32 (7) \
         or FLOAT64 (8)"
    )]
    FieldType {
        /// `x`, `y` or `z`.
        axis: char,
        /// Its datatype.
        datatype: u8,
    },
    /// A coordinate field of several elements.
    #[error("PointCloud2 field {axis:?} has count {count}; x, y and z need count 1")]
    FieldCount {
        /// `x`, `y` or `z`.
        axis: char,
        /// Its count.
        count: u32,
    },
    /// A coordinate field reaching past the end of its point.
    #[error(
        "PointCloud2 field {axis:?} at offset {offset} ({size} bytes) does not fit in \
         point_step {point_step}"
    )]
    FieldOutside {
        /// `x`, `y` or `z`.
        axis: char,
        /// Its offset.
        offset: u32,
        /// Its size in bytes.
        size: u32,
        /// The point step.
        point_step: u32,
    },
    /// Rows shorter than their points.
    #[error(
        "PointCloud2 row_step {row_step} is less than width {width} × point_step {point_step}"
    )]
    RowStep {
        /// The row step.
        row_step: u32,
        /// Points per row.
        width: u32,
        /// Bytes per point.
        point_step: u32,
    },
    /// `data` is not `height × row_step` bytes.
    #[error("PointCloud2 data has {got} bytes; height {height} × row_step {row_step} = {want}")]
    DataLength {
        /// Bytes given.
        got: usize,
        /// Rows.
        height: u32,
        /// Bytes per row.
        row_step: u32,
        /// Bytes expected.
        want: u64,
    },
}

crate::error::typed_errors!(TrackerError);

const POSES: &str = "PoseArray";
const CLOUD: &str = "PointCloud2";

/// The frame first: a message in another frame is refused whatever it holds.
fn check_frame(kind: &'static str, header: &Header, e: &Expect) -> Result<(), TrackerError> {
    if header.frame_id == e.frame_id {
        Ok(())
    } else {
        Err(TrackerError::Frame {
            kind,
            got: header.frame_id.clone(),
            want: e.frame_id.clone(),
        })
    }
}

fn check_count(kind: &'static str, got: usize, e: &Expect) -> Result<(), TrackerError> {
    if got == e.n {
        Ok(())
    } else {
        Err(TrackerError::Count {
            kind,
            got,
            want: e.n,
        })
    }
}

/// Point `index` as a position: finite, and on the plane of a 2-D template.
fn point(
    kind: &'static str,
    index: usize,
    xyz: [f64; 3],
    dim: usize,
) -> Result<Vector3, TrackerError> {
    for (axis, value) in ['x', 'y', 'z'].into_iter().zip(xyz) {
        if !value.is_finite() {
            return Err(TrackerError::NotFinite {
                kind,
                index,
                axis,
                value,
            });
        }
    }
    if dim == 2 && xyz[2] != 0.0 {
        return Err(TrackerError::OffPlane {
            kind,
            index,
            value: xyz[2],
        });
    }
    Ok(Vector3 {
        x: xyz[0],
        y: xyz[1],
        z: xyz[2],
    })
}

/// The positions of a PoseArray's poses, into `out` (cleared first).
pub fn pose_positions(
    m: &PoseArray,
    e: &Expect,
    out: &mut Vec<Vector3>,
) -> Result<(), TrackerError> {
    out.clear();
    check_frame(POSES, &m.header, e)?;
    check_count(POSES, m.poses.len(), e)?;
    for (i, pose) in m.poses.iter().enumerate() {
        let p = pose.position;
        out.push(point(POSES, i, [p.x, p.y, p.z], e.dim)?);
    }
    Ok(())
}

/// Where one coordinate lives in a point: offset and width (4 or 8 bytes).
#[derive(Clone, Copy, Debug)]
struct Coord {
    offset: usize,
    wide: bool,
}

/// The x, y and z fields, found by name and checked against the point step.
fn coords(fields: &[PointField], point_step: u32) -> Result<[Coord; 3], TrackerError> {
    let mut out = [Coord {
        offset: 0,
        wide: false,
    }; 3];
    for (slot, axis) in out.iter_mut().zip(['x', 'y', 'z']) {
        let mut named = fields
            .iter()
            .filter(|f| f.name.len() == 1 && f.name.starts_with(axis));
        let Some(f) = named.next() else {
            let names: Vec<String> = fields.iter().map(|f| format!("{:?}", f.name)).collect();
            return Err(TrackerError::MissingField {
                axis,
                fields: names.join(", "),
            });
        };
        if named.next().is_some() {
            return Err(TrackerError::DuplicateField(axis));
        }
        let size = match f.datatype {
            POINT_FIELD_FLOAT32 => 4,
            POINT_FIELD_FLOAT64 => 8,
            datatype => return Err(TrackerError::FieldType { axis, datatype }),
        };
        if f.count != 1 {
            return Err(TrackerError::FieldCount {
                axis,
                count: f.count,
            });
        }
        if u64::from(f.offset) + u64::from(size) > u64::from(point_step) {
            return Err(TrackerError::FieldOutside {
                axis,
                offset: f.offset,
                size,
                point_step,
            });
        }
        *slot = Coord {
            offset: f.offset as usize,
            wide: size == 8,
        };
    }
    Ok(out)
}

/// The layout checks of a PointCloud2: one point per particle, rows that
/// hold their points, and exactly `height × row_step` bytes.
fn check_layout(m: &PointCloud2, e: &Expect) -> Result<(), TrackerError> {
    let points = u64::from(m.height) * u64::from(m.width);
    check_count(CLOUD, usize::try_from(points).unwrap_or(usize::MAX), e)?;
    if u64::from(m.row_step) < u64::from(m.width) * u64::from(m.point_step) {
        return Err(TrackerError::RowStep {
            row_step: m.row_step,
            width: m.width,
            point_step: m.point_step,
        });
    }
    let want = u64::from(m.height) * u64::from(m.row_step);
    if m.data.len() as u64 != want {
        return Err(TrackerError::DataLength {
            got: m.data.len(),
            height: m.height,
            row_step: m.row_step,
            want,
        });
    }
    Ok(())
}

/// One coordinate of the point at byte `at` (in bounds: checked before).
fn read(data: &[u8], at: usize, c: Coord, big: bool) -> f64 {
    let start = at + c.offset;
    if c.wide {
        let mut b = [0u8; 8];
        b.copy_from_slice(&data[start..start + 8]);
        if big {
            f64::from_be_bytes(b)
        } else {
            f64::from_le_bytes(b)
        }
    } else {
        let mut b = [0u8; 4];
        b.copy_from_slice(&data[start..start + 4]);
        f64::from(if big {
            f32::from_be_bytes(b)
        } else {
            f32::from_le_bytes(b)
        })
    }
}

/// The positions of a PointCloud2's points (row by row), into `out`
/// (cleared first).
pub fn cloud_positions(
    m: &PointCloud2,
    e: &Expect,
    out: &mut Vec<Vector3>,
) -> Result<(), TrackerError> {
    out.clear();
    check_frame(CLOUD, &m.header, e)?;
    check_layout(m, e)?;
    let [cx, cy, cz] = coords(&m.fields, m.point_step)?;
    let (row_step, step) = (m.row_step as usize, m.point_step as usize);
    for row in 0..m.height as usize {
        for col in 0..m.width as usize {
            let at = row * row_step + col * step;
            let xyz = [cx, cy, cz].map(|c| read(&m.data, at, c, m.is_bigendian));
            out.push(point(CLOUD, out.len(), xyz, e.dim)?);
        }
    }
    Ok(())
}

#[cfg(test)]
#[path = "tracker_tests.rs"]
mod tests;
