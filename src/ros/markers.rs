//! What a prediction looks like in RViz and Foxglove: a
//! `visualization_msgs/MarkerArray` with the particles, the edges, the
//! predicted paths and the force on each particle, in the input state's
//! frame. The node publishes it on `markers_topic` and records it beside the
//! states, so a recorded bag opens in Foxglove's 3D panel.

use ros2_client::Message;
use serde::{Deserialize, Serialize};

use crate::data::msg::{
    ros2msg_schema, Header, ParticleState, Point, Vector3, DEP_HEADER, DEP_TIME,
};

use super::msgs::{ParticleForces, PredictedTrajectory};

/// `visualization_msgs/msg/MarkerArray`'s type name.
pub const MARKER_ARRAY_TYPE: &str = "visualization_msgs/msg/MarkerArray";

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

/// Above this many particles the forces are drawn as one line list instead
/// of one arrow marker each (an arrow costs a whole marker on the wire).
pub const MAX_ARROWS: usize = 200;

/// Most path segments drawn: larger predictions draw every k-th step (and
/// the last), so that a 1,000-particle, 100-step prediction does not double
/// the node's traffic with a 5 MB picture.
pub const MAX_PATH_SEGMENTS: usize = 20_000;

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

impl Message for MarkerArray {}

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
            ("visualization_msgs/Marker", MARKER),
            DEP_HEADER,
            DEP_TIME,
            (
                "geometry_msgs/Pose",
                "Point position\nQuaternion orientation\n",
            ),
            ("geometry_msgs/Point", XYZ),
            (
                "geometry_msgs/Quaternion",
                "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
            ),
            ("geometry_msgs/Vector3", XYZ),
            (
                "std_msgs/ColorRGBA",
                "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
            ),
            ("builtin_interfaces/Duration", "int32 sec\nuint32 nanosec\n"),
            (
                "sensor_msgs/CompressedImage",
                "std_msgs/Header header\nstring format\nuint8[] data\n",
            ),
            ("visualization_msgs/UVCoordinate", "float32 u\nfloat32 v\n"),
            (
                "visualization_msgs/MeshFile",
                "string filename\nuint8[] data\n",
            ),
        ],
    )
}

/// Frame of markers whose input state names none (RViz needs one).
pub const DEFAULT_FRAME: &str = "world";

const GREY: ColorRgba = rgba(0.6, 0.6, 0.6, 1.0);
const DARK: ColorRgba = rgba(0.2, 0.2, 0.2, 1.0);
const PATH: ColorRgba = rgba(0.1, 0.45, 0.9, 0.8);
const FORCE: ColorRgba = rgba(0.9, 0.25, 0.1, 1.0);

const fn rgba(r: f32, g: f32, b: f32, a: f32) -> ColorRgba {
    ColorRgba { r, g, b, a }
}

/// A colour per particle type, cycling through a small palette.
fn type_color(t: u32) -> ColorRgba {
    const PALETTE: [ColorRgba; 4] = [
        rgba(0.95, 0.6, 0.1, 1.0),
        rgba(0.2, 0.7, 0.3, 1.0),
        rgba(0.6, 0.3, 0.8, 1.0),
        rgba(0.1, 0.6, 0.8, 1.0),
    ];
    PALETTE[t as usize % PALETTE.len()]
}

fn point(v: &Vector3) -> Point {
    Point {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

/// Where edge end `i` is: particle `i`, or anchor `i - n` (`None` when out
/// of range).
fn endpoint(s: &ParticleState, i: u32) -> Option<Point> {
    let (i, n) = (i as usize, s.positions.len());
    if i < n {
        Some(point(&s.positions[i]))
    } else {
        s.anchors.get(i - n).copied()
    }
}

/// The length markers are sized by: the median edge length, else the
/// spread of the positions, else 1.
fn length_scale(s: &ParticleState) -> f64 {
    let mut lengths: Vec<f64> = s
        .edge_a
        .iter()
        .zip(&s.edge_b)
        .filter_map(|(&a, &b)| {
            let (p, q) = (endpoint(s, a)?, endpoint(s, b)?);
            let d = ((p.x - q.x).powi(2) + (p.y - q.y).powi(2) + (p.z - q.z).powi(2)).sqrt();
            (d > 0.0 && d.is_finite()).then_some(d)
        })
        .collect();
    lengths.sort_by(f64::total_cmp);
    if let Some(m) = lengths.get(lengths.len() / 2) {
        return *m;
    }
    let spread = s
        .positions
        .iter()
        .flat_map(|p| [p.x, p.y, p.z])
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    if spread > 0.0 && spread.is_finite() {
        spread
    } else {
        1.0
    }
}

/// The markers of one prediction: a DELETEALL (so that markers of an earlier,
/// larger graph disappear), then the particles (a sphere list coloured by
/// type), the edges (springs grey, bars dark), anchors (cubes), every
/// particle's predicted path (every k-th step above [`MAX_PATH_SEGMENTS`]
/// segments), and the total force on each particle (arrows
/// scaled so the largest is half the median edge length; one line list above
/// [`MAX_ARROWS`] particles).
pub fn prediction_markers(
    trajectory: &PredictedTrajectory,
    forces: &ParticleForces,
) -> MarkerArray {
    let s = &trajectory.initial;
    let mut header = trajectory.header.clone();
    if header.frame_id.is_empty() {
        header.frame_id = DEFAULT_FRAME.into();
    }
    let l = length_scale(s);
    let base = |ns: &str, id: i32, kind: i32, size: f64, color: ColorRgba| Marker {
        header: header.clone(),
        ns: ns.into(),
        id,
        kind,
        action: ADD,
        scale: Vector3 {
            x: size,
            y: size,
            z: size,
        },
        color,
        ..Marker::default()
    };
    let mut out = vec![Marker {
        header: header.clone(),
        action: DELETEALL,
        ..Marker::default()
    }];
    let mut particles = base("particles", 0, SPHERE_LIST, 0.3 * l, GREY);
    particles.points = s.positions.iter().map(point).collect();
    particles.colors = s.types.iter().map(|&t| type_color(t)).collect();
    if particles.colors.len() != particles.points.len() {
        particles.colors.clear();
    }
    out.push(particles);
    let mut edges = base("edges", 0, LINE_LIST, 0.05 * l, GREY);
    for (k, (&a, &b)) in s.edge_a.iter().zip(&s.edge_b).enumerate() {
        if let (Some(p), Some(q)) = (endpoint(s, a), endpoint(s, b)) {
            let c = if s.edge_kind.get(k) == Some(&crate::data::msg::EDGE_BAR) {
                DARK
            } else {
                GREY
            };
            edges.points.extend([p, q]);
            edges.colors.extend([c, c]);
        }
    }
    if !edges.points.is_empty() {
        out.push(edges);
    }
    if !s.anchors.is_empty() {
        let mut anchors = base("anchors", 0, CUBE_LIST, 0.2 * l, DARK);
        anchors.points.clone_from(&s.anchors);
        out.push(anchors);
    }
    let mut paths = base("predicted_paths", 0, LINE_LIST, 0.03 * l, PATH);
    let mut prev: Vec<Point> = s.positions.iter().map(point).collect();
    let steps = trajectory.steps as usize;
    let stride = (s.positions.len() * steps)
        .div_ceil(MAX_PATH_SEGMENTS)
        .max(1);
    let drawn = (0..steps).filter(|k| (k + 1) % stride == 0 || k + 1 == steps);
    for k in drawn {
        for (p, q) in prev.iter_mut().zip(trajectory.positions_at(k)) {
            let q = point(q);
            paths.points.extend([*p, q]);
            *p = q;
        }
    }
    if !paths.points.is_empty() {
        out.push(paths);
    }
    out.extend(force_markers(&base, s, &forces.total, l));
    MarkerArray { markers: out }
}

/// Arrows (or, above [`MAX_ARROWS`] particles, one line list) from each
/// particle along its total force, the largest half of `l` long.
fn force_markers(
    base: &dyn Fn(&str, i32, i32, f64, ColorRgba) -> Marker,
    s: &ParticleState,
    total: &[Vector3],
    l: f64,
) -> Vec<Marker> {
    let norm = |f: &Vector3| (f.x * f.x + f.y * f.y + f.z * f.z).sqrt();
    let largest = total.iter().map(norm).fold(0.0_f64, f64::max);
    if !(largest > 0.0 && largest.is_finite()) || total.len() != s.positions.len() {
        return vec![];
    }
    let k = 0.5 * l / largest;
    let ends = s.positions.iter().zip(total).map(|(p, f)| {
        let a = point(p);
        let b = Point {
            x: a.x + k * f.x,
            y: a.y + k * f.y,
            z: a.z + k * f.z,
        };
        (a, b)
    });
    if total.len() > MAX_ARROWS {
        let mut lines = base("forces", 0, LINE_LIST, 0.04 * l, FORCE);
        lines.points = ends.flat_map(|(a, b)| [a, b]).collect();
        return vec![lines];
    }
    ends.enumerate()
        .map(|(i, (a, b))| {
            let mut m = base("forces", i as i32, ARROW, 0.0, FORCE);
            // ARROW with points: x = shaft diameter, y = head diameter, z = head length.
            m.scale = Vector3 {
                x: 0.04 * l,
                y: 0.08 * l,
                z: 0.1 * l,
            };
            m.points = vec![a, b];
            m
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::msg::encode_cdr;
    use crate::models::truth::load_truth;
    use crate::physics::{SystemConfig, SystemKind};
    use crate::system::Sample;

    fn predicted(
        kind: SystemKind,
        n: usize,
        horizon: u32,
    ) -> (PredictedTrajectory, ParticleForces) {
        let cfg = SystemConfig::new(kind, n);
        let graph = cfg.graph();
        let state = cfg.start_for(&graph, 3, 0);
        let sample = Sample {
            t: 0.0,
            state,
            acc: None,
        };
        let msg = ParticleState::from_sample(0, 0, kind.name(), &graph, &sample);
        let model = load_truth(&format!("truth:{}", kind.name())).unwrap();
        let p = super::super::predict::predict(model.as_ref(), &msg, 0.01, horizon, 1).unwrap();
        (p.trajectory, p.forces)
    }

    fn by_ns<'a>(m: &'a MarkerArray, ns: &str) -> Vec<&'a Marker> {
        m.markers.iter().filter(|x| x.ns == ns).collect()
    }

    #[test]
    fn markers_draw_the_input_its_prediction_and_its_forces() {
        let (t, f) = predicted(SystemKind::Pendulum, 4, 7);
        let m = prediction_markers(&t, &f);
        let s = &t.initial;
        assert_eq!(m.markers[0].action, DELETEALL);
        assert_eq!(m.markers[1].header.frame_id, DEFAULT_FRAME);
        let parts = by_ns(&m, "particles");
        assert_eq!(parts.len(), 1);
        let pos: Vec<Point> = s.positions.iter().map(point).collect();
        assert_eq!(parts[0].points, pos);
        assert_eq!(parts[0].colors.len(), 4);
        // One segment per edge; the pivot bar ends at the anchor.
        let edges = by_ns(&m, "edges")[0];
        assert_eq!(edges.points.len(), 2 * s.edge_a.len());
        assert!(edges.points.contains(&s.anchors[0]));
        assert_eq!(by_ns(&m, "anchors")[0].points, s.anchors);
        // Paths: per step, one segment per particle from where it was.
        let paths = by_ns(&m, "predicted_paths")[0];
        assert_eq!(paths.points.len(), 2 * 4 * 7);
        let last: Vec<Point> = t.positions_at(6).iter().map(point).collect();
        let ends: Vec<Point> = paths.points.iter().skip(1).step_by(2).copied().collect();
        assert_eq!(&ends[ends.len() - 4..], &last[..]);
        assert_eq!(&paths.points[0], &pos[0]);
        // Arrows along the forces, the largest half the median edge length.
        let arrows = by_ns(&m, "forces");
        assert_eq!(arrows.len(), 4);
        let l = length_scale(s);
        let mut longest = 0.0_f64;
        for (a, (p, fo)) in arrows.iter().zip(s.positions.iter().zip(&f.total)) {
            assert_eq!(a.kind, ARROW);
            assert_eq!(a.points[0], point(p));
            let d = [
                a.points[1].x - p.x,
                a.points[1].y - p.y,
                a.points[1].z - p.z,
            ];
            let fv = [fo.x, fo.y, fo.z];
            let dot: f64 = d.iter().zip(&fv).map(|(x, y)| x * y).sum();
            let nd = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            let nf = fv.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!(
                (dot - nd * nf).abs() <= 1e-12 * nd * nf,
                "arrow not along its force"
            );
            longest = longest.max(nd);
        }
        assert!((longest - 0.5 * l).abs() < 1e-12 * l, "{longest} vs {l}");
        // What goes on the wire decodes back to the same markers.
        let bytes = encode_cdr(&m).unwrap();
        let back: MarkerArray = crate::data::msg::decode_cdr(&bytes).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn large_graphs_get_one_line_list_of_forces_and_frames_are_kept() {
        let (mut t, f) = predicted(SystemKind::Spring, MAX_ARROWS + 1, 2);
        t.header.frame_id = "lab".into();
        let m = prediction_markers(&t, &f);
        let forces = by_ns(&m, "forces");
        assert_eq!(forces.len(), 1);
        assert_eq!(forces[0].kind, LINE_LIST);
        assert_eq!(forces[0].points.len(), 2 * (MAX_ARROWS + 1));
        assert!(m.markers.iter().all(|x| x.header.frame_id == "lab"));
        // 1,000 particles x 100 steps: every 5th step, ending at the last.
        let (t, f) = predicted(SystemKind::Spring, 1000, 100);
        let m = prediction_markers(&t, &f);
        let paths = by_ns(&m, "predicted_paths")[0];
        assert_eq!(paths.points.len(), 2 * MAX_PATH_SEGMENTS);
        let last: Vec<Point> = t.positions_at(99).iter().map(point).collect();
        let ends: Vec<Point> = paths.points.iter().skip(1).step_by(2).copied().collect();
        assert_eq!(&ends[ends.len() - 1000..], &last[..]);
    }

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
