//! `load_model` and `Model`: rollouts, accelerations and forces of any
//! model `mcgnode rollout` loads, through the same entry points.

use std::path::PathBuf;
use std::sync::Arc;

use mcgnode::compat::TrainedFor;
use mcgnode::dynamics::{Dynamics, DynamicsError, Timing, STILL};
use mcgnode::models::truth::TRUTH_PREFIX;
use mcgnode::models::ModelKind;
use mcgnode::physics::Field;
use mcgnode::system::{Graph, State};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeWarning, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::{array, field_from, first, given_motion, to_numpy, Parts};
use crate::{lib_err, warn, Error};

/// A model to roll out: a model file of any kind, `still` or
/// `truth:<system>`, as `mcgnode.load_model` loads it.
#[pyclass(module = "mcgnode", name = "Model", frozen)]
pub(crate) struct Model {
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
pub(crate) fn load_model(py: Python<'_>, r#ref: PathBuf) -> PyResult<Model> {
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
        let (states, spread) = py
            .detach(|| self.dynamics.rollout_spread(graph, start, timing, drive))
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
        // An ensemble's spread, (states, particles); a single model has none.
        if !spread.is_empty() {
            let flat: Vec<f64> = spread.iter().flatten().copied().collect();
            out.set_item("spread", to_numpy(py, flat, &[spread.len(), n])?)?;
        }
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
            periodic_box: None,
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

    /// Models averaged in its predictions: K for a file trained with
    /// `--ensemble K`, else 1.
    #[getter]
    fn members(&self) -> usize {
        self.dynamics.members()
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
        let periodic_box = get("periodic_box")?;
        let (graph, start) = Parts {
            positions,
            velocities,
            masses: &masses,
            edges: &edges,
            anchors: anchors.as_ref(),
            types: types.as_ref(),
            radius,
            kinematic: kinematic.as_ref(),
            periodic_box: periodic_box.as_ref(),
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
            periodic_box: None,
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
