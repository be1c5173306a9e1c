//! Python values to the library's: numpy arrays to shapes and values, the
//! graph and state of one particle system, its field and the kinematic
//! particles' given motion (and back: [`to_numpy`]). Shared by `Model`'s
//! methods (models.rs) and `read_bag` (bags.rs).

use mcgnode::physics::Field;
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, State};
use numpy::ndarray::Axis;
use numpy::{AllowTypeChange, PyArray1, PyArrayLikeDyn, PyArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

use crate::lib_err;

/// `obj` as a float64 array: its shape and its values in C order. `what`
/// names it in the error.
pub(crate) fn array(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    let a: PyArrayLikeDyn<'_, f64, AllowTypeChange> = obj
        .extract()
        .map_err(|e| PyTypeError::new_err(format!("{what} must be an array of numbers: {e}")))?;
    let v = a.as_array();
    Ok((v.shape().to_vec(), v.iter().copied().collect()))
}

/// The first entry along the first axis of `obj` (a trajectory's first
/// state), as [`array`] gives it.
pub(crate) fn first(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
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
pub(crate) struct Parts<'a, 'py> {
    pub(crate) positions: (Vec<usize>, Vec<f64>),
    pub(crate) velocities: (Vec<usize>, Vec<f64>),
    pub(crate) masses: &'a Bound<'py, PyAny>,
    pub(crate) edges: &'a Bound<'py, PyAny>,
    pub(crate) anchors: Option<&'a Bound<'py, PyAny>>,
    pub(crate) types: Option<&'a Bound<'py, PyAny>>,
    /// Contacts: the interaction radius (0: none) and the kinematic flags
    /// (particles,) (None: none kinematic).
    pub(crate) radius: f64,
    pub(crate) kinematic: Option<&'a Bound<'py, PyAny>>,
    /// A periodic box (a read_bag dict's `periodic_box`; None: none).
    pub(crate) periodic_box: Option<&'a Bound<'py, PyAny>>,
}

impl Parts<'_, '_> {
    /// The graph and state, validated by the library (its messages).
    pub(crate) fn build(self) -> PyResult<(Graph, State)> {
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
        let periodic_box = self.periodic_box.map(periodic_box).transpose()?;
        let graph = Graph {
            dim,
            types,
            masses,
            edges,
            anchors,
            interaction_radius: self.radius,
            kinematic,
            periodic_box,
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
pub(crate) fn given_motion(
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
pub(crate) fn to_numpy<'py>(
    py: Python<'py>,
    v: Vec<f64>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, v).reshape(shape)?.into_any())
}

/// The `field` entry of a trajectory dict: `None` or
/// `{"gravity", "drag", "force"}`.
pub(crate) fn field_from(obj: Option<Bound<'_, PyAny>>) -> PyResult<Option<Field>> {
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

/// A box as read_bag gives it: {"lower", "upper"} (dim,) floats and
/// "periodic" (dim,) bools.
fn periodic_box(b: &Bound<'_, PyAny>) -> PyResult<mcgnode::system::PeriodicBox> {
    let item = |k: &str| {
        b.get_item(k).map_err(|_| {
            PyValueError::new_err(format!(
                "periodic_box must be a dict with \"lower\", \"upper\" and \"periodic\" (no {k:?})"
            ))
        })
    };
    let floats = |k: &str| -> PyResult<Vec<f64>> { Ok(array(&item(k)?, k)?.1) };
    let periodic: Vec<bool> = item("periodic")?
        .try_iter()?
        .map(|x| x?.is_truthy())
        .collect::<PyResult<_>>()?;
    Ok(mcgnode::system::PeriodicBox {
        lower: floats("lower")?,
        upper: floats("upper")?,
        periodic,
    })
}
