//! The tracker decoders: good messages decode to their positions (every
//! layout), and malformed ones are each refused with a reason of their own.

use std::collections::BTreeSet;

use super::*;
use crate::data::msg::{Point, Time};
use crate::ros::wire::Pose;

fn expect(n: usize, dim: usize) -> Expect {
    Expect {
        frame_id: "world".into(),
        n,
        dim,
    }
}

fn header(frame: &str) -> Header {
    Header {
        stamp: Time { sec: 3, nanosec: 7 },
        frame_id: frame.into(),
    }
}

fn pts(n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let i = i as f64;
            [0.5 * i, -1.25 + i, 0.125 * i]
        })
        .collect()
}

fn poses(frame: &str, points: &[[f64; 3]]) -> PoseArray {
    PoseArray {
        header: header(frame),
        poses: points
            .iter()
            .map(|p| Pose {
                position: Point {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                },
                ..Pose::default()
            })
            .collect(),
    }
}

fn field(name: &str, offset: u32, datatype: u8) -> PointField {
    PointField {
        name: name.into(),
        offset,
        datatype,
        count: 1,
    }
}

/// A cloud of `points` with fields `fields`, `step` bytes a point, rows of
/// `width` points and `pad` bytes after each row.
struct Cloud {
    fields: Vec<PointField>,
    step: u32,
    width: u32,
    pad: u32,
    big: bool,
}

impl Cloud {
    fn xyz32(step: u32) -> Cloud {
        Cloud {
            fields: vec![
                field("intensity", 0, POINT_FIELD_FLOAT32),
                field("x", 4, POINT_FIELD_FLOAT32),
                field("y", 8, POINT_FIELD_FLOAT32),
                field("z", 12, POINT_FIELD_FLOAT32),
            ],
            step,
            width: 0,
            pad: 0,
            big: false,
        }
    }

    fn build(&self, frame: &str, points: &[[f64; 3]]) -> PointCloud2 {
        let width = if self.width == 0 {
            points.len() as u32
        } else {
            self.width
        };
        let height = (points.len() as u32).checked_div(width).unwrap_or(0);
        let row_step = width * self.step + self.pad;
        let mut data = vec![0u8; (row_step * height) as usize];
        for (i, p) in points.iter().enumerate() {
            let (row, col) = (i as u32 / width.max(1), i as u32 % width.max(1));
            let at = (row * row_step + col * self.step) as usize;
            for f in &self.fields {
                let Some(k) = ["x", "y", "z"].iter().position(|a| *a == f.name) else {
                    continue;
                };
                let o = at + f.offset as usize;
                let bytes: Vec<u8> = match (f.datatype, self.big) {
                    (POINT_FIELD_FLOAT64, false) => p[k].to_le_bytes().to_vec(),
                    (POINT_FIELD_FLOAT64, true) => p[k].to_be_bytes().to_vec(),
                    (_, false) => (p[k] as f32).to_le_bytes().to_vec(),
                    (_, true) => (p[k] as f32).to_be_bytes().to_vec(),
                };
                if o + bytes.len() <= data.len() {
                    data[o..o + bytes.len()].copy_from_slice(&bytes);
                }
            }
        }
        PointCloud2 {
            header: header(frame),
            height,
            width,
            fields: self.fields.clone(),
            is_bigendian: self.big,
            point_step: self.step,
            row_step,
            data,
            is_dense: true,
        }
    }
}

fn as_xyz(v: &[Vector3]) -> Vec<[f64; 3]> {
    v.iter().map(|p| [p.x, p.y, p.z]).collect()
}

#[test]
fn good_pose_arrays_and_clouds_decode_to_their_positions() {
    let mut out = Vec::new();
    let p = pts(6);
    pose_positions(&poses("world", &p), &expect(6, 3), &mut out).unwrap();
    assert_eq!(as_xyz(&out), p);
    // Values exact in f32 (multiples of 1/8), so every layout gives them back.
    let layouts = [
        Cloud::xyz32(16),
        Cloud::xyz32(32),
        Cloud {
            width: 3,
            pad: 5,
            ..Cloud::xyz32(20)
        },
        Cloud {
            big: true,
            ..Cloud::xyz32(16)
        },
        Cloud {
            fields: vec![
                field("z", 0, POINT_FIELD_FLOAT64),
                field("y", 8, POINT_FIELD_FLOAT64),
                field("x", 16, POINT_FIELD_FLOAT32),
                field("rgb", 20, 6),
            ],
            big: true,
            width: 2,
            ..Cloud::xyz32(24)
        },
    ];
    for c in &layouts {
        let m = c.build("world", &p);
        cloud_positions(&m, &expect(6, 3), &mut out).unwrap_or_else(|e| panic!("{e} for {m:?}"));
        assert_eq!(as_xyz(&out), p, "{m:?}");
    }
    // 2-D: z = 0 everywhere.
    let flat: Vec<[f64; 3]> = p.iter().map(|q| [q[0], q[1], 0.0]).collect();
    pose_positions(&poses("world", &flat), &expect(6, 2), &mut out).unwrap();
    cloud_positions(
        &Cloud::xyz32(16).build("world", &flat),
        &expect(6, 2),
        &mut out,
    )
    .unwrap();
    assert_eq!(as_xyz(&out), flat);
}

/// Every reason differs from the others; none is empty.
fn all_distinct(reasons: &[String]) {
    let set: BTreeSet<&String> = reasons.iter().collect();
    assert_eq!(set.len(), reasons.len(), "{reasons:#?}");
    assert!(reasons.iter().all(|r| r.len() > 20), "{reasons:#?}");
}

#[test]
fn malformed_pose_arrays_are_refused_each_with_its_reason() {
    let e = expect(5, 3);
    let p = pts(5);
    let with = |i: usize, k: usize, v: f64| {
        let mut q = p.clone();
        q[i][k] = v;
        poses("world", &q)
    };
    let mut bad = vec![
        (poses("world", &[]), "has 0 points"),
        (poses("world", &p[..1]), "has 1 points"),
        (poses("world", &p[..4]), "has 4 points"),
        (poses("world", &pts(6)), "has 6 points"),
        (poses("world", &pts(50)), "has 50 points"),
        (
            poses("camera", &p),
            "\"camera\" is not the frame_id parameter \"world\"",
        ),
        (poses("", &p), "frame_id \"\""),
        (poses("World", &p), "\"World\""),
        (poses("/world", &p), "\"/world\""),
        (poses("map", &pts(4)), "\"map\""),
    ];
    for (i, k) in [(0, 0), (1, 1), (2, 2), (4, 0), (3, 1)] {
        bad.push((with(i, k, f64::NAN), "NaN is not finite"));
    }
    bad.push((with(0, 1, f64::INFINITY), "y = inf"));
    bad.push((with(4, 2, f64::NEG_INFINITY), "z = -inf"));
    let flat: Vec<[f64; 3]> = p.iter().map(|q| [q[0], q[1], 0.0]).collect();
    let mut reasons = Vec::new();
    let mut out = Vec::new();
    for (m, needle) in &bad {
        let why = pose_positions(m, &e, &mut out).unwrap_err().to_string();
        assert!(
            why.contains(needle) && why.contains("PoseArray"),
            "{why} lacks {needle}"
        );
        reasons.push(why);
    }
    // A 2-D template: z off the plane.
    for i in [1, 3, 4] {
        let mut q = flat.clone();
        q[i][2] = 0.5 * i as f64;
        let why = pose_positions(&poses("world", &q), &expect(5, 2), &mut out)
            .unwrap_err()
            .to_string();
        assert!(why.contains("template is 2-D"), "{why}");
        reasons.push(why);
    }
    assert!(reasons.len() >= 20, "{}", reasons.len());
    all_distinct(&reasons);
}

/// Clouds whose x, y, z fields are wrong, each with what its refusal says.
fn bad_field_clouds(p: &[[f64; 3]]) -> Vec<(PointCloud2, &'static str)> {
    let with_fields = |fields: Vec<PointField>| {
        Cloud {
            fields,
            ..Cloud::xyz32(16)
        }
        .build("world", p)
    };
    let f32s = |x: u32, y: u32, z: u32| {
        vec![
            field("x", x, POINT_FIELD_FLOAT32),
            field("y", y, POINT_FIELD_FLOAT32),
            field("z", z, POINT_FIELD_FLOAT32),
        ]
    };
    let count3 = PointField {
        count: 3,
        ..field("y", 4, 7)
    };
    vec![
        (with_fields(f32s(0, 4, 8)[..2].to_vec()), "no field 'z'"),
        (
            with_fields(vec![field("y", 4, 7), field("z", 8, 7)]),
            "no field 'x'",
        ),
        (
            with_fields(vec![field("X", 0, 7), field("y", 4, 7), field("z", 8, 7)]),
            "\"X\"",
        ),
        (
            with_fields([f32s(0, 4, 8), vec![field("x", 12, 7)]].concat()),
            "'x' is declared twice",
        ),
        (
            with_fields(vec![field("x", 0, 2), field("y", 4, 7), field("z", 8, 7)]),
            "datatype 2",
        ),
        (
            with_fields(vec![field("x", 0, 7), field("y", 4, 5), field("z", 8, 7)]),
            "datatype 5",
        ),
        (
            with_fields(vec![field("x", 0, 7), field("y", 4, 7), field("z", 8, 0)]),
            "datatype 0",
        ),
        (
            with_fields(vec![field("x", 0, 7), count3, field("z", 8, 7)]),
            "count 3",
        ),
        (
            with_fields(f32s(0, 4, 14)),
            "offset 14 (4 bytes) does not fit in point_step 16",
        ),
        (
            with_fields(vec![field("x", 0, 7), field("y", 4, 7), field("z", 12, 8)]),
            "(8 bytes)",
        ),
        (
            Cloud::xyz32(12).build("world", p),
            "'z' at offset 12 (4 bytes) does not fit in point_step 12",
        ),
    ]
}

/// Clouds of the wrong frame, size, layout or values, each with what its
/// refusal says.
fn bad_layout_clouds(p: &[[f64; 3]]) -> Vec<(PointCloud2, &'static str)> {
    let good = Cloud::xyz32(16);
    let edit = |f: &dyn Fn(&mut PointCloud2)| {
        let mut m = good.build("world", p);
        f(&mut m);
        m
    };
    let mut nan = p.to_vec();
    nan[2][1] = f64::NAN;
    let mut inf = p.to_vec();
    inf[4][0] = f64::INFINITY;
    let big = Cloud {
        big: true,
        ..Cloud::xyz32(16)
    };
    vec![
        (good.build("world", &p[..4]), "has 4 points"),
        (good.build("world", &pts(6)), "has 6 points"),
        (good.build("world", &[]), "has 0 points"),
        (
            good.build("camera_link", p),
            "\"camera_link\" is not the frame_id",
        ),
        (good.build("", p), "frame_id \"\""),
        (
            edit(&|m| m.point_step = 8),
            "'y' at offset 8 (4 bytes) does not fit in point_step 8",
        ),
        (
            edit(&|m| m.point_step = 32),
            "row_step 80 is less than width 5 × point_step 32",
        ),
        (edit(&|m| m.row_step = 70), "row_step 70"),
        (edit(&|m| m.data.truncate(79)), "data has 79 bytes"),
        (edit(&|m| m.data.clear()), "data has 0 bytes"),
        (edit(&|m| m.data.push(0)), "data has 81 bytes"),
        (edit(&|m| m.height = 2), "has 10 points"),
        (edit(&|m| m.height = 7), "has 35 points"),
        (
            edit(&|m| {
                m.height = 5;
                m.width = 1;
            }),
            "height 5 × row_step 80 = 400",
        ),
        (edit(&|m| m.width = u32::MAX), "has 4294967295 points"),
        (good.build("world", &nan), "point 2: y = NaN"),
        (good.build("world", &inf), "point 4: x = inf"),
        // The same NaN read big-endian: the same reason (dropped below).
        (big.build("world", &nan), "point 2: y = NaN"),
    ]
}

#[test]
fn malformed_clouds_are_refused_each_with_its_reason() {
    let e = expect(5, 3);
    let p = pts(5);
    let mut reasons = Vec::new();
    let mut out = Vec::new();
    for (m, needle) in bad_field_clouds(&p).iter().chain(&bad_layout_clouds(&p)) {
        let why = cloud_positions(m, &e, &mut out).unwrap_err().to_string();
        assert!(
            why.contains(needle) && why.contains("PointCloud2"),
            "{why} lacks {needle}"
        );
        reasons.push(why);
    }
    reasons.pop();
    // A 2-D template: z off the plane.
    let why = cloud_positions(
        &Cloud::xyz32(16).build("world", &p),
        &expect(5, 2),
        &mut out,
    )
    .unwrap_err()
    .to_string();
    assert!(
        why.contains("point 1: z = 0.125, but the template is 2-D"),
        "{why}"
    );
    reasons.push(why);
    assert!(reasons.len() >= 20, "{}", reasons.len());
    all_distinct(&reasons);
}
