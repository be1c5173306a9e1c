//! `read_bag`: the ParticleState trajectories of bags as numpy arrays.

use mcgnode::physics::Field;
use mcgnode::system::{EdgeKind, Endpoint, Graph};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::arrays::to_numpy;
use crate::{lib_err, paths};

/// A field as the dict `read_bag` gives: `{"gravity", "drag", "force"}`.
fn field_dict<'py>(py: Python<'py>, f: &Field) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("gravity", f.gravity)?;
    d.set_item("drag", f.drag)?;
    d.set_item("force", f.force.clone())?;
    Ok(d)
}

/// The edges of `g` as rows (a, b, kind, rest_length, stiffness), b ≥
/// particles naming anchor b − particles, kind 0 spring, 1 bar, 2 contact.
fn edge_rows(g: &Graph) -> Vec<f64> {
    let np = g.n();
    let mut edges = Vec::with_capacity(5 * g.edges.len());
    for e in &g.edges {
        let b = match e.b {
            Endpoint::Particle(b) => b,
            Endpoint::Anchor(k) => np + k,
        };
        let kind = match e.kind {
            EdgeKind::Spring => 0.0,
            EdgeKind::Bar => 1.0,
            EdgeKind::Contact => 2.0,
        };
        edges.extend_from_slice(&[e.a as f64, b as f64, kind, e.rest_length, e.stiffness]);
    }
    edges
}

/// The ParticleState trajectories of a bag, read as `mcgnode` reads them:
/// an MCAP file, a rosbag2 directory (MCAP or sqlite3 storage, any
/// compression), a `.db3` file, or a list of such paths (trajectories of
/// several bags are concatenated in order). `topic` chooses among several
/// ParticleState topics.
///
/// Returns a list of dicts, one per trajectory (sorted by id):
///
/// - `id`, `system` (`"spring"`, `"pendulum"`, ... or `""`), `dim` (2 or 3)
/// - `positions`, `velocities`: float64 arrays (states, particles, dim);
///   `accelerations` the same when every message carries them, else None
/// - `stamps`: float64 (states,), seconds from the trajectory's first stamp
/// - `masses` (particles,), `types` (particles,) uint32
/// - `edges`: float64 (edges, 5), rows (a, b, kind, rest_length, stiffness);
///   b >= particles is anchor b - particles; kind 0 spring, 1 bar (2, a
///   contact, never comes from a bag: contacts are rebuilt from positions)
/// - `anchors`: float64 (anchors, dim)
/// - `interaction_radius`: float, 0 when the system has fixed edges only
///   (closer pairs touch through contact edges rebuilt from positions)
/// - `kinematic`: bool (particles,), True for a particle whose motion is
///   given (a wall, a floor, a pusher); all False when the bag marks none
/// - `periodic_box`: None, or {"lower", "upper": float64 (dim,), "periodic":
///   bool (dim,)} when the bag states a box (`rollout` wraps in it)
/// - `field`: {"gravity", "drag", "force"} as the messages (else the bag's
///   simulator record) state it, or None when the bag does not say
/// - `dt`, `save_every`: the step and saving interval `mcgnode rollout
///   --initial` takes by default (the simulator's record, else the interval
///   of the stamps and 1); `dt` is None for a lone state without a record
/// - `velocities_derived`: True when the messages had no velocities and
///   they were derived from positions and stamps
///
/// Raises mcgnode.Error with the library's message when the bag cannot be read.
#[pyfunction]
#[pyo3(signature = (path, topic=None))]
pub(crate) fn read_bag<'py>(
    py: Python<'py>,
    path: &Bound<'py, PyAny>,
    topic: Option<String>,
) -> PyResult<Bound<'py, PyList>> {
    let paths = paths(path, "path")?;
    let (bag, cfg) = py
        .detach(|| {
            let bag =
                mcgnode::data::bag::read_bags(&paths, &mcgnode::data::bag::ReadOptions { topic })?;
            // As `mcgnode rollout --initial` reads its field and step.
            let cfg = mcgnode::data::field::bag_system(&bag)?;
            Ok::<_, anyhow::Error>((bag, cfg))
        })
        .map_err(lib_err)?;
    let field = bag.field.clone().or(cfg.as_ref().map(|c| c.field.clone()));
    let out = PyList::empty(py);
    for tr in &bag.trajectories {
        let g = &tr.graph;
        let (s, n, d) = (tr.samples.len(), g.n(), g.dim);
        let d3 = [s, n, d];
        let mut q = Vec::with_capacity(s * n * d);
        let mut v = Vec::with_capacity(s * n * d);
        let mut acc = Vec::with_capacity(s * n * d);
        let mut all_acc = true;
        for x in &tr.samples {
            q.extend_from_slice(&x.state.q);
            v.extend_from_slice(&x.state.v);
            match &x.acc {
                Some(a) if all_acc => acc.extend_from_slice(a),
                _ => all_acc = false,
            }
        }
        let stamps: Vec<f64> = tr.samples.iter().map(|x| x.t).collect();
        let edges = edge_rows(g);
        let anchors: Vec<f64> = g.anchors.iter().flatten().copied().collect();
        let stamp_dt = tr.samples.get(1).map(|x| x.t - tr.samples[0].t);
        let (dt, every) = match (&cfg, stamp_dt) {
            (Some(c), _) => (Some(c.dt), c.save_every),
            (None, Some(dt)) => (Some(dt), 1),
            (None, None) => (None, 1),
        };
        let t = PyDict::new(py);
        t.set_item("id", tr.id)?;
        t.set_item("system", &tr.system)?;
        t.set_item("dim", d)?;
        t.set_item("positions", to_numpy(py, q, &d3)?)?;
        t.set_item("velocities", to_numpy(py, v, &d3)?)?;
        if all_acc {
            t.set_item("accelerations", to_numpy(py, acc, &d3)?)?;
        } else {
            t.set_item("accelerations", py.None())?;
        }
        t.set_item("stamps", PyArray1::from_vec(py, stamps))?;
        t.set_item("masses", PyArray1::from_vec(py, g.masses.clone()))?;
        t.set_item("types", PyArray1::from_vec(py, g.types.clone()))?;
        t.set_item("edges", to_numpy(py, edges, &[g.edges.len(), 5])?)?;
        t.set_item("anchors", to_numpy(py, anchors, &[g.anchors.len(), d])?)?;
        t.set_item("interaction_radius", g.interaction_radius)?;
        let kinematic: Vec<bool> = (0..n).map(|i| g.kinematic.get(i) == Some(&true)).collect();
        t.set_item("kinematic", PyArray1::from_vec(py, kinematic))?;
        match &g.periodic_box {
            Some(b) => {
                let pb = PyDict::new(py);
                pb.set_item("lower", PyArray1::from_vec(py, b.lower.clone()))?;
                pb.set_item("upper", PyArray1::from_vec(py, b.upper.clone()))?;
                pb.set_item("periodic", PyArray1::from_vec(py, b.periodic.clone()))?;
                t.set_item("periodic_box", pb)?;
            }
            None => t.set_item("periodic_box", py.None())?,
        }
        match &field {
            Some(f) => t.set_item("field", field_dict(py, f)?)?,
            None => t.set_item("field", py.None())?,
        }
        t.set_item("dt", dt)?;
        t.set_item("save_every", every)?;
        t.set_item(
            "velocities_derived",
            bag.derived_velocities.contains(&tr.id),
        )?;
        out.append(t)?;
    }
    Ok(out)
}
