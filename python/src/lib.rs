//! `mcgnode._mcgnode`, the native module of the `mcgnode` Python package:
//! bags, models, rollouts and training through the library's own entry
//! points, the ones the `mcgnode` command line calls, so that Python gets the
//! CLI's numbers bit for bit and its error messages word for word.
//!
//! - `read_bag` is [`mcgnode::data::bag::read_bags`] (every layout the CLI
//!   reads), each trajectory as numpy arrays.
//! - `load_model` is [`mcgnode::models::load_any_model`] and
//!   [`mcgnode::models::trained_for`], as `mcgnode rollout --model` loads a
//!   file, `still` or `truth:<system>`.
//! - `Model.rollout` checks the graph and field as `mcgnode rollout` does and
//!   calls the same [`mcgnode::dynamics::Dynamics::rollout`].
//! - `train` parses its options with `mcgnode train`'s own
//!   [`mcgnode::cli::train::Args`] and trains through
//!   [`mcgnode::cli::train::train`].
//!
//! Library errors are raised as `mcgnode.Error` with the message the CLI
//! prints after `error: `; arrays of the wrong shape as `ValueError`.

// The methods take what their Python signatures take (keyword arguments with
// defaults), so their arity is Python's.
#![allow(clippy::too_many_arguments)]

use std::ffi::CString;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcgnode::compat::TrainedFor;
use mcgnode::dynamics::{Dynamics, DynamicsError, Timing, STILL};
use mcgnode::models::truth::TRUTH_PREFIX;
use mcgnode::models::ModelKind;
use mcgnode::physics::Field;
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, State};
use numpy::ndarray::Axis;
use numpy::{AllowTypeChange, PyArray1, PyArrayLikeDyn, PyArrayMethods};
use pyo3::exceptions::{PyException, PyRuntimeWarning, PyTypeError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};

pyo3::create_exception!(
    mcgnode,
    Error,
    PyException,
    "A failure of the mcgnode library: a bag it cannot read, a model file that \
     does not load, data a model was not trained for, a rollout that diverged. \
     The message is the one the `mcgnode` command line prints after `error: `."
);

/// A library error as `mcgnode.Error`, with the CLI's message.
fn lib_err(e: impl Into<anyhow::Error>) -> PyErr {
    Error::new_err(mcgnode::cli::error_report(&e.into()))
}

/// Issues a Python warning of `category` (as the CLI prints `warning: ...`).
fn warn(py: Python<'_>, category: &Bound<'_, PyAny>, message: &str) -> PyResult<()> {
    let m = CString::new(message.replace('\0', " ")).expect("no NUL left");
    PyErr::warn(py, category, &m, 1)
}

/// `obj` as a float64 array: its shape and its values in C order. `what`
/// names it in the error.
fn array(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    let a: PyArrayLikeDyn<'_, f64, AllowTypeChange> = obj
        .extract()
        .map_err(|e| PyTypeError::new_err(format!("{what} must be an array of numbers: {e}")))?;
    let v = a.as_array();
    Ok((v.shape().to_vec(), v.iter().copied().collect()))
}

/// The first entry along the first axis of `obj` (a trajectory's first
/// state), as [`array`] gives it.
fn first(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    let a: PyArrayLikeDyn<'_, f64, AllowTypeChange> = obj
        .extract()
        .map_err(|e| PyTypeError::new_err(format!("{what} must be an array of numbers: {e}")))?;
    let v = a.as_array();
    if v.ndim() != 3 || v.shape()[0] == 0 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (states, particles, dim) with at least one state, got {:?}",
            v.shape()
        )));
    }
    let s = v.index_axis(Axis(0), 0);
    Ok((s.shape().to_vec(), s.iter().copied().collect()))
}

/// A non-negative integer held in a float (an edge end, a type id).
fn index(x: f64, what: impl FnOnce() -> String) -> PyResult<usize> {
    if x.is_finite() && x >= 0.0 && x.fract() == 0.0 && x < 4_294_967_296.0 {
        Ok(x as usize)
    } else {
        Err(PyValueError::new_err(format!(
            "{} must be a non-negative integer below 2^32, got {x}",
            what()
        )))
    }
}

/// The arrays of one state and its graph, as Python passes them.
struct Parts<'a, 'py> {
    positions: (Vec<usize>, Vec<f64>),
    velocities: (Vec<usize>, Vec<f64>),
    masses: &'a Bound<'py, PyAny>,
    edges: &'a Bound<'py, PyAny>,
    anchors: Option<&'a Bound<'py, PyAny>>,
    types: Option<&'a Bound<'py, PyAny>>,
    /// Contacts: the interaction radius (0: none) and the kinematic flags
    /// (particles,) (None: none kinematic).
    radius: f64,
    kinematic: Option<&'a Bound<'py, PyAny>>,
}

impl Parts<'_, '_> {
    /// The graph and state, validated by the library (its messages).
    fn build(self) -> PyResult<(Graph, State)> {
        let (shape, q) = self.positions;
        let [n, dim] = shape[..] else {
            return Err(PyValueError::new_err(format!(
                "positions must have shape (particles, dim), got {shape:?}"
            )));
        };
        if self.velocities.0 != shape {
            return Err(PyValueError::new_err(format!(
                "velocities must have the shape of positions, {shape:?}, got {:?}",
                self.velocities.0
            )));
        }
        let (mshape, masses) = array(self.masses, "masses")?;
        if mshape != [n] {
            return Err(PyValueError::new_err(format!(
                "masses must have shape ({n},), one per particle, got {mshape:?}"
            )));
        }
        let edges = edges(self.edges, n)?;
        let anchors = anchors(self.anchors, dim)?;
        let types = types(self.types, n)?;
        let kinematic = kinematic(self.kinematic)?;
        let graph = Graph {
            dim,
            types,
            masses,
            edges,
            anchors,
            interaction_radius: self.radius,
            kinematic,
        };
        graph.validate().map_err(lib_err)?;
        let state = State {
            q,
            v: self.velocities.1,
        };
        state.validate(&graph).map_err(lib_err)?;
        Ok((graph, state))
    }
}

/// The edges of `n` particles from an array (edges, 5) of rows (a, b,
/// kind, rest_length, stiffness); b ≥ n names anchor b − n.
fn edges(obj: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<Edge>> {
    let (eshape, e) = array(obj, "edges")?;
    let m = match eshape[..] {
        [0] => 0,
        [m, 5] => m,
        _ => {
            return Err(PyValueError::new_err(format!(
                "edges must have shape (edges, 5): rows (a, b, kind, rest_length, \
                 stiffness), got {eshape:?}"
            )))
        }
    };
    (0..m)
        .map(|k| {
            let r = &e[5 * k..5 * k + 5];
            let a = index(r[0], || format!("edges[{k}, 0] (a)"))?;
            let b = index(r[1], || format!("edges[{k}, 1] (b)"))?;
            let kind = match r[2] {
                0.0 => EdgeKind::Spring,
                1.0 => EdgeKind::Bar,
                x => {
                    return Err(PyValueError::new_err(format!(
                        "edges[{k}, 2] (kind) must be 0 (spring) or 1 (bar), got {x}"
                    )))
                }
            };
            Ok(Edge {
                a,
                b: if b < n {
                    Endpoint::Particle(b)
                } else {
                    Endpoint::Anchor(b - n)
                },
                kind,
                rest_length: r[3],
                stiffness: r[4],
            })
        })
        .collect()
}

/// The anchors from an array (anchors, dim) (none when absent or None).
fn anchors(obj: Option<&Bound<'_, PyAny>>, dim: usize) -> PyResult<Vec<Vec<f64>>> {
    Ok(match obj.filter(|a| !a.is_none()) {
        None => vec![],
        Some(a) => {
            let (ashape, v) = array(a, "anchors")?;
            match ashape[..] {
                [0] => vec![],
                [_, d] if d == dim => v.chunks(dim).map(<[f64]>::to_vec).collect(),
                _ => {
                    return Err(PyValueError::new_err(format!(
                        "anchors must have shape (anchors, {dim}), got {ashape:?}"
                    )))
                }
            }
        }
    })
}

/// The type ids of `n` particles from an array (particles,) (all 0 when
/// absent or None).
fn types(obj: Option<&Bound<'_, PyAny>>, n: usize) -> PyResult<Vec<u32>> {
    Ok(match obj.filter(|t| !t.is_none()) {
        None => vec![0; n],
        Some(t) => {
            let (tshape, v) = array(t, "types")?;
            if tshape != [n] {
                return Err(PyValueError::new_err(format!(
                    "types must have shape ({n},), one per particle, got {tshape:?}"
                )));
            }
            v.iter()
                .enumerate()
                .map(|(i, x)| index(*x, || format!("types[{i}]")).map(|t| t as u32))
                .collect::<PyResult<Vec<_>>>()?
        }
    })
}

/// The kinematic flags from a sequence of bools (none kinematic when absent
/// or None).
fn kinematic(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<bool>> {
    Ok(match obj.filter(|k| !k.is_none()) {
        None => vec![],
        Some(k) => {
            let flags: Vec<bool> = k.call_method0("tolist")?.extract().map_err(|_| {
                PyTypeError::new_err("kinematic must be a sequence of bools, one per particle")
            })?;
            flags
        }
    })
}

/// The kinematic particles' given positions over a rollout of `steps` steps
/// of `dt`: an array (steps + 1, kinematic particles, dim), velocities by
/// central differences; `None` when not given (they are held).
fn given_motion(
    graph: &Graph,
    positions: Option<&Bound<'_, PyAny>>,
    steps: usize,
    dt: f64,
) -> PyResult<Option<mcgnode::physics::Drive>> {
    let Some(p) = positions.filter(|p| !p.is_none()) else {
        return Ok(None);
    };
    let driven: Vec<usize> = (0..graph.n()).filter(|&i| graph.is_kinematic(i)).collect();
    let (shape, v) = array(p, "kinematic_positions")?;
    let want = [steps + 1, driven.len(), graph.dim];
    if driven.is_empty() || shape != want {
        return Err(PyValueError::new_err(format!(
            "kinematic_positions must have shape (steps + 1, kinematic particles, dim) = \
             {want:?}, got {shape:?}"
        )));
    }
    let rows = v
        .chunks(driven.len() * graph.dim)
        .map(<[f64]>::to_vec)
        .collect();
    Ok(Some(mcgnode::physics::Drive::from_positions(
        driven, graph.dim, dt, rows,
    )))
}

/// A float64 numpy array of `shape` holding `v` (no copy).
fn to_numpy<'py>(py: Python<'py>, v: Vec<f64>, shape: &[usize]) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, v).reshape(shape)?.into_any())
}

/// The `field` entry of a trajectory dict: `None` or
/// `{"gravity", "drag", "force"}`.
fn field_from(obj: Option<Bound<'_, PyAny>>) -> PyResult<Option<Field>> {
    let Some(f) = obj.filter(|f| !f.is_none()) else {
        return Ok(None);
    };
    let get = |k: &str| {
        f.get_item(k)
            .map_err(|_| PyValueError::new_err(format!("field must have the key {k:?}")))
    };
    Ok(Some(Field {
        gravity: get("gravity")?.extract()?,
        drag: get("drag")?.extract()?,
        force: get("force")?.extract()?,
    }))
}

fn field_dict<'py>(py: Python<'py>, f: &Field) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("gravity", f.gravity)?;
    d.set_item("drag", f.drag)?;
    d.set_item("force", f.force.clone())?;
    Ok(d)
}

/// One path or several, as `str`, `os.PathLike` or a sequence of them.
fn paths(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<PathBuf>> {
    if obj.cast::<PyString>().is_ok() || obj.hasattr("__fspath__")? {
        return Ok(vec![obj.extract()?]);
    }
    obj.try_iter()
        .and_then(|it| it.map(|p| p?.extract::<PathBuf>()).collect())
        .map_err(|_| PyTypeError::new_err(format!("{what} must be a path or a list of paths")))
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
fn read_bag<'py>(
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

/// A model to roll out: a model file of any kind, `still` or
/// `truth:<system>`, as `mcgnode.load_model` loads it.
#[pyclass(module = "mcgnode", name = "Model", frozen)]
struct Model {
    reference: String,
    name: String,
    dynamics: Arc<dyn Dynamics>,
    trained: TrainedFor,
}

/// Loads a model as `mcgnode rollout --model REF` does: a model file (GNODE
/// family or a baseline), `"still"` (nothing moves, the reference every
/// model must beat) or `"truth:<system>"` (the simulator, e.g.
/// `"truth:spring"`). Raises mcgnode.Error with the library's message.
#[pyfunction]
fn load_model(py: Python<'_>, r#ref: PathBuf) -> PyResult<Model> {
    let reference = r#ref.display().to_string();
    py.detach(|| {
        let model = mcgnode::models::ModelRef::from_path(&r#ref)?;
        let loaded = mcgnode::models::load_any_model(&model)?;
        let trained = mcgnode::models::trained_for(&model)?;
        Ok::<_, mcgnode::Error>(Model {
            reference,
            name: loaded.name,
            dynamics: loaded.dynamics,
            trained,
        })
    })
    .map_err(lib_err)
}

impl Model {
    /// Whether the model's total forces are its own predictions (the
    /// constrained variants, the simulator, and `still`'s zeros) rather
    /// than m·q̈ of predicted accelerations; and whether it has pairwise ones.
    fn force_kind(&self) -> Option<bool> {
        if self.name == STILL {
            return Some(false);
        }
        if self.name.starts_with(TRUTH_PREFIX) {
            return Some(true);
        }
        match self.name.parse::<ModelKind>() {
            Ok(ModelKind::Family(v)) if v.biases().constrained => Some(v.biases().pairwise),
            _ => None,
        }
    }

    /// The graph check of `mcgnode rollout` (and of the node, for
    /// accelerations and forces): what the model was trained on.
    fn check(&self, graph: &Graph, field: Option<&Field>) -> PyResult<()> {
        self.trained.check(graph, field).map_err(lib_err)
    }

    /// The rollout `mcgnode rollout` runs, from `start`, as a dict of arrays.
    fn roll<'py>(
        &self,
        py: Python<'py>,
        graph: &Graph,
        start: &State,
        field: Option<&Field>,
        (steps, dt, every): (usize, f64, usize),
        drive: Option<&mcgnode::physics::Drive>,
    ) -> PyResult<Bound<'py, PyDict>> {
        self.check(graph, field)?;
        if let Some(o) = self
            .trained
            .range
            .as_ref()
            .and_then(|r| r.check(graph, start, mcgnode::compat::OUT_OF_RANGE_SIGMAS))
        {
            warn(
                py,
                py.get_type::<PyRuntimeWarning>().as_any(),
                &format!(
                    "the initial state is out of the model's training range: {o}; the rollout \
                     is an extrapolation"
                ),
            )?;
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(lib_err(DynamicsError::TimeStep(dt)));
        }
        let timing = Timing::integration(dt, steps, every.max(1));
        let states = py
            .detach(|| match drive {
                Some(d) => self.dynamics.rollout_driven(graph, start, timing, d),
                None => self.dynamics.rollout(graph, start, timing),
            })
            .map_err(lib_err)?;
        let (n, d) = (graph.n(), graph.dim);
        let shape = [states.len(), n, d];
        let mut q = Vec::with_capacity(states.len() * n * d);
        let mut v = Vec::with_capacity(states.len() * n * d);
        for s in &states {
            q.extend_from_slice(&s.q);
            v.extend_from_slice(&s.v);
        }
        let stamps: Vec<f64> = (0..states.len()).map(|k| (k * every) as f64 * dt).collect();
        let out = PyDict::new(py);
        out.set_item("positions", to_numpy(py, q, &shape)?)?;
        out.set_item("velocities", to_numpy(py, v, &shape)?)?;
        out.set_item("stamps", PyArray1::from_vec(py, stamps))?;
        Ok(out)
    }

    /// The graph and the states of (positions, velocities) given as one
    /// state (particles, dim) or a stack of them (k, particles, dim); true
    /// for a stack.
    fn states(
        positions: &Bound<'_, PyAny>,
        velocities: &Bound<'_, PyAny>,
        masses: &Bound<'_, PyAny>,
        edges: &Bound<'_, PyAny>,
        anchors: Option<&Bound<'_, PyAny>>,
        types: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<(Graph, Vec<State>, bool)> {
        let (qs, q) = array(positions, "positions")?;
        let (vs, v) = array(velocities, "velocities")?;
        if qs != vs {
            return Err(PyValueError::new_err(format!(
                "velocities must have the shape of positions, {qs:?}, got {vs:?}"
            )));
        }
        let (k, per) = match qs[..] {
            [_, _] => (1, qs.clone()),
            [k, n, d] if k > 0 => (k, vec![n, d]),
            _ => {
                return Err(PyValueError::new_err(format!(
                    "positions must have shape (particles, dim) or (states, particles, dim), \
                     got {qs:?}"
                )))
            }
        };
        let len = per[0] * per[1];
        let (graph, s0) = Parts {
            radius: 0.0,
            kinematic: None,
            positions: (per.clone(), q[..len].to_vec()),
            velocities: (per, v[..len].to_vec()),
            masses,
            edges,
            anchors,
            types,
        }
        .build()?;
        let mut states = vec![s0];
        for i in 1..k {
            let s = State {
                q: q[i * len..(i + 1) * len].to_vec(),
                v: v[i * len..(i + 1) * len].to_vec(),
            };
            s.validate(&graph).map_err(lib_err)?;
            states.push(s);
        }
        Ok((graph, states, qs.len() == 3))
    }
}

#[pymethods]
impl Model {
    /// The reference it was loaded from (a path, "still" or "truth:<system>").
    #[getter]
    fn reference(&self) -> &str {
        &self.reference
    }

    /// Its kind: "mcgnode", "gnode", ..., "lgn", "hgn", "gns", "still" or
    /// "truth:<system>".
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// Whether `forces` answers: the model predicts forces (CGNODE, CDGNODE,
    /// MCGNODE, the simulator) or is `still`.
    #[getter]
    fn predicts_forces(&self) -> bool {
        self.force_kind().is_some()
    }

    /// A one-line description of the model.
    fn describe(&self) -> String {
        self.dynamics.describe()
    }

    fn __repr__(&self) -> String {
        format!("<mcgnode.Model {} ({})>", self.reference, self.name)
    }

    /// Rolls the model out from the first state of `trajectory` (a dict as
    /// `read_bag` returns it) for `steps` steps of `dt`, keeping the start and
    /// every `every`-th state: exactly `mcgnode rollout --initial BAG
    /// --trajectory ID --duration steps*dt --dt dt --save-every every`, bit
    /// for bit. `dt` defaults to the trajectory's `dt` (as the CLI's does).
    /// The graph and the trajectory's `field` are checked against what the
    /// model was trained on, as the CLI checks them; a start out of the
    /// model's training range warns (RuntimeWarning).
    ///
    /// Returns {"positions", "velocities"}: float64 arrays
    /// (steps // every + 1, particles, dim), and "stamps" (seconds).
    #[pyo3(signature = (trajectory, steps, dt=None, every=1, *, kinematic_positions=None))]
    fn rollout<'py>(
        &self,
        py: Python<'py>,
        trajectory: &Bound<'py, PyAny>,
        steps: usize,
        dt: Option<f64>,
        every: usize,
        kinematic_positions: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let get = |k: &str| -> PyResult<Option<Bound<'py, PyAny>>> {
            let v = trajectory.call_method1("get", (k,)).map_err(|_| {
                PyTypeError::new_err("trajectory must be a dict as read_bag returns it")
            })?;
            Ok((!v.is_none()).then_some(v))
        };
        let need = |k: &str| {
            get(k)?.ok_or_else(|| PyValueError::new_err(format!("trajectory has no {k:?}")))
        };
        let positions = first(&need("positions")?, "trajectory[\"positions\"]")?;
        let velocities = first(&need("velocities")?, "trajectory[\"velocities\"]")?;
        let (masses, edges, anchors, types) = (
            need("masses")?,
            need("edges")?,
            get("anchors")?,
            get("types")?,
        );
        let radius = get("interaction_radius")?
            .map(|r| r.extract::<f64>())
            .transpose()?
            .unwrap_or(0.0);
        let kinematic = get("kinematic")?;
        let (graph, start) = Parts {
            positions,
            velocities,
            masses: &masses,
            edges: &edges,
            anchors: anchors.as_ref(),
            types: types.as_ref(),
            radius,
            kinematic: kinematic.as_ref(),
        }
        .build()?;
        let field = field_from(get("field")?)?;
        let dt = match dt {
            Some(dt) => dt,
            None => get("dt")?
                .map(|d| d.extract::<f64>())
                .transpose()?
                .ok_or_else(|| {
                    Error::new_err(
                        "the trajectory does not say its step (no system_config, one state): \
                         pass dt",
                    )
                })?,
        };
        let drive = given_motion(&graph, kinematic_positions, steps, dt)?;
        self.roll(
            py,
            &graph,
            &start,
            field.as_ref(),
            (steps, dt, every),
            drive.as_ref(),
        )
    }

    /// `rollout` from arrays: positions and velocities (particles, dim),
    /// masses (particles,), edges (edges, 5) as `read_bag` gives them, anchors
    /// (anchors, dim), types (particles,; default all 0). The graph is
    /// checked against what the model was trained on (the field is not
    /// known here, so it is not).
    #[pyo3(signature = (positions, velocities, masses, edges, anchors=None, *, steps, dt, types=None, every=1, interaction_radius=0.0, kinematic=None, kinematic_positions=None))]
    #[allow(clippy::too_many_arguments)] // the Python keywords
    fn rollout_arrays<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        velocities: &Bound<'py, PyAny>,
        masses: &Bound<'py, PyAny>,
        edges: &Bound<'py, PyAny>,
        anchors: Option<&Bound<'py, PyAny>>,
        steps: usize,
        dt: f64,
        types: Option<&Bound<'py, PyAny>>,
        every: usize,
        interaction_radius: f64,
        kinematic: Option<&Bound<'py, PyAny>>,
        kinematic_positions: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (graph, start) = Parts {
            positions: array(positions, "positions")?,
            velocities: array(velocities, "velocities")?,
            masses,
            edges,
            anchors,
            types,
            radius: interaction_radius,
            kinematic,
        }
        .build()?;
        let drive = given_motion(&graph, kinematic_positions, steps, dt)?;
        self.roll(py, &graph, &start, None, (steps, dt, every), drive.as_ref())
    }

    /// The model's accelerations q̈ at one state (positions and velocities
    /// (particles, dim)) or at a stack of states ((k, particles, dim)); the
    /// result has their shape. Arrays as in `rollout_arrays`.
    #[pyo3(signature = (positions, velocities, masses, edges, anchors=None, *, types=None))]
    fn accelerations<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        velocities: &Bound<'py, PyAny>,
        masses: &Bound<'py, PyAny>,
        edges: &Bound<'py, PyAny>,
        anchors: Option<&Bound<'py, PyAny>>,
        types: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (graph, states, stacked) =
            Self::states(positions, velocities, masses, edges, anchors, types)?;
        self.check(&graph, None)?;
        let mut out = vec![vec![0.0; graph.ndof()]; states.len()];
        py.detach(|| self.dynamics.acceleration_batch(&graph, &states, &mut out))
            .map_err(lib_err)?;
        let (n, d) = (graph.n(), graph.dim);
        let flat: Vec<f64> = out.into_iter().flatten().collect();
        if stacked {
            to_numpy(py, flat, &[states.len(), n, d])
        } else {
            to_numpy(py, flat, &[n, d])
        }
    }

    /// The forces the model predicts at one state: {"total": (particles,
    /// dim), the total force on each particle; "pairs": int64 (pairs, 2),
    /// rows (a, b); "pair_forces": (pairs, dim), the force on a due to b
    /// (b feels its opposite)}.
    /// Pairwise forces come from MCGNODE and the simulator (`truth:`); CGNODE
    /// and CDGNODE predict total forces only (no pairs), `still` zeros. NODE,
    /// GNODE and the baselines predict accelerations, not forces: they raise
    /// mcgnode.Error (use `accelerations`).
    #[pyo3(signature = (positions, velocities, masses, edges, anchors=None, *, types=None))]
    fn forces<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        velocities: &Bound<'py, PyAny>,
        masses: &Bound<'py, PyAny>,
        edges: &Bound<'py, PyAny>,
        anchors: Option<&Bound<'py, PyAny>>,
        types: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        if self.force_kind().is_none() {
            return Err(Error::new_err(format!(
                "{} ({}) predicts accelerations, not forces: only cgnode, cdgnode and mcgnode \
                 models and truth:<system> predict forces (pairwise ones: mcgnode and truth); \
                 use accelerations()",
                self.reference, self.name
            )));
        }
        let (graph, states, stacked) =
            Self::states(positions, velocities, masses, edges, anchors, types)?;
        if stacked {
            return Err(PyValueError::new_err(
                "forces takes one state: positions of shape (particles, dim)",
            ));
        }
        self.check(&graph, None)?;
        let f = py
            .detach(|| self.dynamics.forces(&graph, &states[0]))
            .map_err(lib_err)?;
        let (n, d) = (graph.n(), graph.dim);
        let m = f.edges.len();
        let mut pairs = Vec::with_capacity(2 * m);
        let mut pf = Vec::with_capacity(d * m);
        for e in &f.edges {
            pairs.extend_from_slice(&[e.a as i64, e.b as i64]);
            pf.extend_from_slice(&e.force);
        }
        let out = PyDict::new(py);
        out.set_item("total", to_numpy(py, f.total, &[n, d])?)?;
        out.set_item("pairs", PyArray1::from_vec(py, pairs).reshape([m, 2])?)?;
        out.set_item("pair_forces", to_numpy(py, pf, &[m, d])?)?;
        Ok(out)
    }
}

/// One `mcgnode train` argument from a keyword argument's value (or one
/// item of a list for a repeatable option).
fn arg_value(id: &str, v: &Bound<'_, PyAny>) -> PyResult<String> {
    if v.hasattr("__fspath__")? {
        return Ok(v.extract::<PathBuf>()?.display().to_string());
    }
    if v.cast::<PyString>().is_ok() {
        return v.extract();
    }
    match id {
        // (epoch, lr)
        "lr_drop" if v.cast::<PyTuple>().is_ok() || v.cast::<PyList>().is_ok() => {
            let (e, lr): (Bound<'_, PyAny>, Bound<'_, PyAny>) = v.extract()?;
            Ok(format!("{}:{}", e.str()?, lr.str()?))
        }
        // (block, sizes)
        "block_hidden" if v.cast::<PyTuple>().is_ok() => {
            let (b, sizes): (String, Bound<'_, PyAny>) = v.extract()?;
            let sizes: Vec<String> = if sizes.cast::<PyString>().is_ok() {
                vec![sizes.extract()?]
            } else if let Ok(one) = sizes.extract::<usize>() {
                vec![one.to_string()]
            } else {
                sizes
                    .try_iter()?
                    .map(|s| Ok(s?.str()?.to_string()))
                    .collect::<PyResult<_>>()?
            };
            Ok(format!("{b}={}", sizes.join(",")))
        }
        _ => Ok(v.str()?.to_string()),
    }
}

/// The command line of `mcgnode train` that `train()`'s arguments stand
/// for: `--model VARIANT`, `--data` per bag, `--out OUT`, then each keyword
/// option as its flag (a bool flag when true; a dict, or a list for a
/// repeated option, one flag per item). An unknown keyword is refused with
/// the list of known ones.
fn train_argv(
    cmd: &clap::Command,
    bags: &Bound<'_, PyAny>,
    out: &Path,
    variant: String,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Vec<String>> {
    let mut argv: Vec<String> = vec!["--model".into(), variant];
    for b in paths(bags, "bags")? {
        argv.push("--data".into());
        argv.push(b.display().to_string());
    }
    argv.push("--out".into());
    argv.push(out.display().to_string());
    for (k, v) in options.into_iter().flat_map(PyDictMethods::iter) {
        let key: String = k.extract()?;
        let Some(arg) = cmd.get_arguments().find(|a| {
            a.get_id() == key.as_str() && !["model", "data", "out"].contains(&key.as_str())
        }) else {
            let known: Vec<&str> = cmd
                .get_arguments()
                .map(|a| a.get_id().as_str())
                .filter(|a| !["model", "data", "out"].contains(a))
                .collect();
            return Err(PyTypeError::new_err(format!(
                "train() got an unexpected keyword argument '{key}' (the variant is variant=; \
                 options: {})",
                known.join(", ")
            )));
        };
        if v.is_none() {
            continue;
        }
        let flag = format!("--{}", arg.get_long().unwrap_or(key.as_str()));
        if matches!(arg.get_action(), clap::ArgAction::SetTrue) {
            if v.extract::<bool>()? {
                argv.push(flag);
            }
            continue;
        }
        let repeated = matches!(arg.get_action(), clap::ArgAction::Append);
        let items = option_items(&key, &v, repeated)?;
        for item in items {
            argv.push(format!("{flag}={}", arg_value(&key, &item)?));
        }
    }
    Ok(argv)
}

/// The items a keyword option's value `v` gives: a dict's (key, value)
/// pairs; a list's entries when the option repeats (for lr_drop a lone
/// (epoch, lr) pair is one item); else the value itself.
fn option_items<'py>(
    key: &str,
    v: &Bound<'py, PyAny>,
    repeated: bool,
) -> PyResult<Vec<Bound<'py, PyAny>>> {
    Ok(if let Ok(d) = v.cast::<PyDict>() {
        d.items().iter().collect()
    } else if repeated && (v.cast::<PyList>().is_ok() || v.cast::<PyTuple>().is_ok()) {
        // A list of items; for lr_drop a lone (epoch, lr) pair is one item.
        let t = v.cast::<PyTuple>();
        if key == "lr_drop"
            && t.is_ok_and(|t| {
                t.len() == 2 && t.get_item(0).is_ok_and(|x| x.extract::<usize>().is_ok())
            })
        {
            vec![v.clone()]
        } else {
            v.try_iter()?.collect::<PyResult<_>>()?
        }
    } else {
        vec![v.clone()]
    })
}

/// Trains a model on `bags` (a path or a list of paths, each a bag as
/// `read_bag` takes it) and writes its model file to `out`: `mcgnode train
/// --data BAGS --out OUT --model VARIANT [options]`, with the CLI's parser,
/// defaults and checks. `variant` is the CLI's `--model` (node, gnode,
/// cgnode, cdgnode, mcgnode, lgn, hgn, gns); every other `train` option is a
/// keyword of the same name with underscores (`epochs=300`, `seed=1`,
/// `recipe="paper"`, `edge_physics=True`, `lr_drop=[(300, 1e-3)]`,
/// `block_hidden={"edge_out": [16, 16]}`, `quiet=True`, ...). Progress goes
/// to stderr as the CLI prints it (unless quiet); a model that explains
/// little of its targets warns (UserWarning).
///
/// Returns the model file's training report as a dict (seed, epochs_run,
/// best_epoch, train_loss, validation_loss, explained, seconds, ...), with
/// "out", "summary" (the line the CLI prints at the end) and
/// "explained_line". Raises mcgnode.Error with the CLI's message.
#[pyfunction]
#[pyo3(signature = (bags, out, *, variant, **options))]
fn train<'py>(
    py: Python<'py>,
    bags: &Bound<'py, PyAny>,
    out: PathBuf,
    variant: String,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    use clap::{Args as _, FromArgMatches as _};
    use mcgnode::cli::train::Args;
    let cmd = Args::augment_args(clap::Command::new("mcgnode train")).no_binary_name(true);
    let argv = train_argv(&cmd, bags, &out, variant, options)?;
    let args = cmd
        .try_get_matches_from(&argv)
        .and_then(|m| Args::from_arg_matches(&m))
        .map_err(|e| {
            let text = e.render().to_string();
            let line = text.lines().next().unwrap_or_default();
            PyValueError::new_err(line.strip_prefix("error: ").unwrap_or(line).to_string())
        })?;
    let quiet = args.quiet;
    let mut interrupted: Option<PyErr> = None;
    let result = {
        let interrupted = &mut interrupted;
        py.detach(move || {
            let mut progress = mcgnode::cli::train::progress(quiet);
            let log = |m: &str| {
                if !quiet {
                    eprintln!("{m}");
                }
            };
            // Ctrl-C in Python cancels training at the end of an epoch. (The
            // closure gives check_signals the lifetime attach hands it.)
            #[allow(clippy::redundant_closure_for_method_calls)]
            let on_epoch = |r: &mcgnode::train::EpochReport| {
                if let Err(e) = Python::attach(|py| py.check_signals()) {
                    *interrupted = Some(e);
                    return false;
                }
                progress(r)
            };
            mcgnode::cli::train::train(&args, log, on_epoch).map(|t| (t, args))
        })
    };
    if let Some(e) = interrupted {
        return Err(e);
    }
    let (report, args) = result.map_err(lib_err)?;
    let summary = mcgnode::cli::train::summary(&args.out, &report);
    if !quiet {
        eprintln!("{summary}");
        eprintln!("{}", report.explained_line());
    }
    if let Some(w) = report.explained_warning() {
        let w = w.strip_prefix("warning: ").unwrap_or(&w);
        warn(py, py.get_type::<PyUserWarning>().as_any(), w)?;
    }
    let json = serde_json::to_string(&report).map_err(lib_err)?;
    let d = py
        .import("json")?
        .call_method1("loads", (json,))?
        .cast_into::<PyDict>()?;
    d.set_item("out", args.out.display().to_string())?;
    d.set_item("summary", summary)?;
    d.set_item("explained_line", report.explained_line())?;
    Ok(d)
}

/// The native module: imported by the `mcgnode` package, which re-exports it.
#[pymodule]
#[pyo3(name = "_mcgnode")]
fn native_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // What the binary does first (candle's thread count, the allocator).
    mcgnode::alloc::prepare_for_candle();
    m.add("Error", m.py().get_type::<Error>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<Model>()?;
    m.add_function(wrap_pyfunction!(read_bag, m)?)?;
    m.add_function(wrap_pyfunction!(load_model, m)?)?;
    m.add_function(wrap_pyfunction!(train, m)?)?;
    Ok(())
}
