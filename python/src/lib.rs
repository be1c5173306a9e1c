//! `mcgnode._mcgnode`, the native module of the `mcgnode` Python package:
//! bags, models, rollouts and training through the library's own entry
//! points, the ones the `mcgnode` command line calls, so that Python gets the
//! CLI's numbers bit for bit and its error messages word for word. One
//! module a job:
//!
//! - `bags.rs`: `read_bag` is [`mcgnode::data::bag::read_bags`] (every layout
//!   the CLI reads), each trajectory as numpy arrays.
//! - `models.rs`: `load_model` is [`mcgnode::models::load_any_model`] and
//!   [`mcgnode::models::trained_for`], as `mcgnode rollout --model` loads a
//!   file, `still` or `truth:<system>`; `Model.rollout` checks the graph and
//!   field as `mcgnode rollout` does and calls the same
//!   [`mcgnode::dynamics::Dynamics::rollout`].
//! - `training.rs`: `train` turns its keywords into the library's
//!   [`mcgnode::train::ModelOptions`] and [`mcgnode::train::TrainConfig`]
//!   from the defaults `mcgnode train` has, and trains through
//!   [`mcgnode::models::train_any_from_bags`].
//! - `arrays.rs`: numpy arrays to graphs, states and fields, and back.
//!
//! Library errors are raised as `mcgnode.Error` with the message the CLI
//! prints after `error: `; arrays of the wrong shape as `ValueError`.

// The methods take what their Python signatures take (keyword arguments with
// defaults), so their arity is Python's.
#![allow(clippy::too_many_arguments)]

use std::ffi::CString;
use std::path::PathBuf;

use pyo3::exceptions::{PyException, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::PyString;

mod arrays;
mod bags;
mod models;
mod training;

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

/// One path or several, as `str`, `os.PathLike` or a sequence of them.
fn paths(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<PathBuf>> {
    if obj.cast::<PyString>().is_ok() || obj.hasattr("__fspath__")? {
        return Ok(vec![obj.extract()?]);
    }
    obj.try_iter()
        .and_then(|it| it.map(|p| p?.extract::<PathBuf>()).collect())
        .map_err(|_| PyTypeError::new_err(format!("{what} must be a path or a list of paths")))
}

/// The native module: imported by the `mcgnode` package, which re-exports it.
#[pymodule]
#[pyo3(name = "_mcgnode")]
fn native_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // What the binary does first (candle's thread count, the allocator).
    mcgnode::alloc::prepare_for_candle();
    m.add("Error", m.py().get_type::<Error>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // train()'s keywords (the tests hold them to `mcgnode train --help`).
    m.add("_TRAIN_OPTIONS", training::OPTIONS.to_vec())?;
    m.add_class::<models::Model>()?;
    m.add_function(wrap_pyfunction!(bags::read_bag, m)?)?;
    m.add_function(wrap_pyfunction!(models::load_model, m)?)?;
    m.add_function(wrap_pyfunction!(training::train, m)?)?;
    Ok(())
}
