//! What a prediction looks like in RViz and Foxglove: a
//! `visualization_msgs/MarkerArray` with the particles, the edges, the
//! predicted paths and the force on each particle, in the input state's
//! frame. The node publishes it on `markers_topic` and records it beside the
//! states, so a recorded bag opens in Foxglove's 3D panel.

use crate::data::msg::{ParticleState, Point, Vector3};

use super::wire::markers::{
    ColorRgba, Marker, MarkerArray, ADD, ARROW, CUBE_LIST, DELETEALL, LINE_LIST, SPHERE_LIST,
};
use super::wire::{ParticleForces, PredictedTrajectory};

/// Above this many particles the forces are drawn as one line list instead
/// of one arrow marker each (an arrow costs a whole marker on the wire).
pub const MAX_ARROWS: usize = 200;

/// Most path segments drawn: larger predictions draw every k-th step (and
/// the last), so that a 1,000-particle, 100-step prediction does not double
/// the node's traffic with a 5 MB picture.
pub const MAX_PATH_SEGMENTS: usize = 20_000;

/// Frame of markers whose input state names none (RViz needs one).
pub const DEFAULT_FRAME: &str = "world";

const GREY: ColorRgba = rgba(0.6, 0.6, 0.6, 1.0);
const DARK: ColorRgba = rgba(0.2, 0.2, 0.2, 1.0);
const PATH: ColorRgba = rgba(0.1, 0.45, 0.9, 0.8);
const FORCE: ColorRgba = rgba(0.9, 0.25, 0.1, 1.0);
/// Contact edges: a light cyan, apart from springs, bars and forces.
const CONTACT: ColorRgba = rgba(0.3, 0.85, 0.95, 0.9);

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

/// Flat coordinates of a trajectory (`d` per particle) as points, z = 0 in 2D.
fn points(flat: &[f64], d: usize) -> impl Iterator<Item = Point> + '_ {
    flat.chunks(d.max(1)).map(Point::from_coords)
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
/// particle's predicted path (every k-th step above `MAX_PATH_SEGMENTS`
/// segments), and the total force on each particle (arrows
/// scaled so the largest is half the median edge length; one line list above
/// `MAX_ARROWS` particles).
pub fn prediction_markers(
    trajectory: &PredictedTrajectory,
    forces: &ParticleForces,
) -> MarkerArray {
    draw(trajectory, forces, drawn_steps(trajectory))
}

/// [`prediction_markers`] with the paths through the states `drawn`.
fn draw(
    trajectory: &PredictedTrajectory,
    forces: &ParticleForces,
    drawn: impl Iterator<Item = usize>,
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
    if let Some(contacts) = contact_lines(s) {
        let mut m = base("contacts", 0, LINE_LIST, 0.04 * l, CONTACT);
        m.points = contacts;
        out.push(m);
    }
    if !s.anchors.is_empty() {
        let mut anchors = base("anchors", 0, CUBE_LIST, 0.2 * l, DARK);
        anchors.points.clone_from(&s.anchors);
        out.push(anchors);
    }
    let mut paths = base("predicted_paths", 0, LINE_LIST, 0.03 * l, PATH);
    let mut prev: Vec<Point> = s.positions.iter().map(point).collect();
    let d = trajectory.dim();
    for k in drawn {
        for (p, q) in prev.iter_mut().zip(points(trajectory.positions_at(k), d)) {
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

/// The predicted states the paths draw: every k-th, so that at most
/// [`MAX_PATH_SEGMENTS`] segments are drawn, and the last.
fn drawn_steps(trajectory: &PredictedTrajectory) -> impl Iterator<Item = usize> {
    let steps = trajectory.steps as usize;
    let stride = (trajectory.particles() * steps)
        .div_ceil(MAX_PATH_SEGMENTS)
        .max(1);
    (0..steps).filter(move |k| (k + 1) % stride == 0 || k + 1 == steps)
}

/// What the markers of a prediction are drawn from, taken before the
/// prediction is published (which consumes it): the trajectory with only
/// the states its paths draw (no velocities) and the forces. A fraction of
/// a clone's copy, so that the node publishes the trajectory first and
/// draws the markers afterwards, off the prediction's latency (drawing
/// 1,000 particles × 100 steps took 12–28 ms).
pub struct MarkerSource {
    part: PredictedTrajectory,
    forces: ParticleForces,
}

impl MarkerSource {
    /// The parts of a prediction its markers read.
    pub fn new(trajectory: &PredictedTrajectory, forces: &ParticleForces) -> Self {
        let positions: Vec<f64> = drawn_steps(trajectory)
            .flat_map(|k| trajectory.positions_at(k).iter().copied())
            .collect();
        let per_state = (trajectory.particles() * trajectory.dim()).max(1);
        let part = PredictedTrajectory {
            header: trajectory.header.clone(),
            initial: trajectory.initial.clone(),
            dt: trajectory.dt,
            #[allow(clippy::cast_possible_truncation)] // at most the original's u32 count
            steps: (positions.len() / per_state) as u32,
            positions,
            velocities: vec![],
            spread: vec![],
        };
        Self {
            part,
            forces: forces.clone(),
        }
    }

    /// [`prediction_markers`] of the prediction this was taken from.
    pub fn markers(&self) -> MarkerArray {
        draw(&self.part, &self.forces, 0..self.part.steps as usize)
    }
}

/// The contact edges of the input state as line ends: every pair closer than
/// its interaction radius that no edge joins and that are not both
/// kinematic, as the models find them (`None` without a radius or contacts).
fn contact_lines(s: &ParticleState) -> Option<Vec<Point>> {
    let n = s.positions.len();
    if s.interaction_radius.is_nan() || s.interaction_radius <= 0.0 || n < 2 {
        return None;
    }
    let bonds = s
        .edge_a
        .iter()
        .zip(&s.edge_b)
        .map(|(&a, &b)| (a as usize, b as usize))
        .filter(move |&(a, b)| a < n && b < n && a != b);
    let kinematic = if s.kinematic.len() == n {
        s.kinematic.clone()
    } else {
        vec![]
    };
    let mut search = crate::physics::neighbors::NeighborSearch::excluding(n, bonds, kinematic);
    let q: Vec<f64> = s.positions.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    let pairs = search.search(&q, 3, s.interaction_radius);
    (!pairs.is_empty()).then(|| {
        pairs
            .iter()
            .flat_map(|&(a, b)| [point(&s.positions[a]), point(&s.positions[b])])
            .collect()
    })
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
    use crate::dynamics::Timing;
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
        let p = super::super::predict::predict(
            model.as_ref(),
            &msg,
            Timing::new(0.01, 1, horizon as usize),
        )
        .unwrap();
        (p.trajectory, p.forces)
    }

    /// Contacts are drawn in their own colour: one segment per pair the
    /// brute-force search finds at the input state, none on walls alone.
    #[test]
    fn contacts_get_their_own_lines() {
        let cfg = SystemConfig::new(SystemKind::CollidingLattices, 32);
        let graph = cfg.graph();
        let mut state = cfg.start_for(&graph, 3, 0);
        // Squeezed to half size: unbonded pairs of each lattice come closer than R.
        state.q.iter_mut().for_each(|x| *x *= 0.5);
        let pairs = crate::physics::neighbors::brute_force_pairs(&graph, &state.q, 1.0);
        assert!(!pairs.is_empty());
        let sample = Sample {
            t: 0.0,
            state,
            acc: None,
        };
        let msg = ParticleState::from_sample(0, 0, "", &graph, &sample);
        let p =
            super::super::predict::predict(&crate::dynamics::Still, &msg, Timing::new(0.01, 1, 3))
                .unwrap();
        let m = prediction_markers(&p.trajectory, &p.forces);
        let c = by_ns(&m, "contacts");
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].points.len(), 2 * pairs.len());
        assert_eq!(c[0].color, CONTACT);
        let (a, b) = pairs[0];
        let at = |i: usize| point(&msg.positions[i]);
        assert_eq!(c[0].points[..2], [at(a), at(b)]);
        // Without a radius: no contact lines.
        let mut plain = msg.clone();
        plain.interaction_radius = 0.0;
        assert!(contact_lines(&plain).is_none());
    }

    /// The thinned copy the node draws from gives the full prediction's
    /// markers: paths through every state, through every 5th (1,000 × 100),
    /// and through every other plus the last, which is more states than
    /// the segment budget would pick anew (7,000 × 5).
    #[test]
    fn a_marker_source_draws_the_full_predictions_markers() {
        for (kind, n, horizon) in [
            (SystemKind::Pendulum, 4, 7),
            (SystemKind::Spring, 1000, 100),
            (SystemKind::Spring, 7000, 5),
        ] {
            let (t, f) = predicted(kind, n, horizon);
            let source = MarkerSource::new(&t, &f);
            if n == 1000 {
                assert_eq!(source.part.positions.len(), 20 * n * 2, "thinned (2D)");
            }
            assert_eq!(
                source.markers(),
                prediction_markers(&t, &f),
                "{kind:?} {n} × {horizon}"
            );
        }
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
        let last: Vec<Point> = points(t.positions_at(6), 2).collect();
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
        let last: Vec<Point> = points(t.positions_at(99), 2).collect();
        let ends: Vec<Point> = paths.points.iter().skip(1).step_by(2).copied().collect();
        assert_eq!(&ends[ends.len() - 1000..], &last[..]);
    }
}
