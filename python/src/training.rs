//! `train`: the keyword arguments of `mcgnode.train` as the library's typed
//! options ([`ModelOptions`], [`TrainConfig`]), starting from the same
//! defaults `mcgnode train` starts from (`ModelOptions::for_recipe` and
//! `TrainConfig::for_recipe` of the chosen recipe), then trained through
//! [`mcgnode::models::train_any_from_bags`], as the CLI trains.

use std::path::PathBuf;

use clap::ValueEnum;
use mcgnode::cli::choices::{
    ArchArg, BodyForceArg, EdgeInputArg, EngineArg, MessageFnArg, RecipeArg,
};
use mcgnode::models::ModelKind;
use mcgnode::train::{Checkpointing, ModelOptions, Recipe, TrainConfig};
use pyo3::exceptions::{PyTypeError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};

use crate::{lib_err, paths, warn};

/// The keyword options of `train()`: `mcgnode train`'s options (bar
/// `--model`, `--data` and `--out`, which are `variant`, `bags` and `out`),
/// dashes as underscores. A Python test checks them against `mcgnode train
/// --help`.
pub(crate) const OPTIONS: &[&str] = &[
    "topic",
    "recipe",
    "epochs",
    "seed",
    "lr",
    "lr_drop",
    "batch",
    "max_seconds",
    "patience",
    "hidden",
    "embed",
    "rounds",
    "arch",
    "hidden_layers",
    "messages",
    "edge_update",
    "block_hidden",
    "noise",
    "points",
    "body_force",
    "engine",
    "threads",
    "edge_physics",
    "radius",
    "no_normalize",
    "init",
    "checkpoint",
    "checkpoint_every",
    "ensemble",
    "quiet",
];

/// A bad value of keyword `key`, as a ValueError naming it.
fn bad(key: &str, why: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("train() argument '{key}': {why}"))
}

/// The value of keyword `key` as `T`, or a ValueError naming `key`.
fn get<'py, T>(key: &str, v: &Bound<'py, PyAny>) -> PyResult<T>
where
    T: FromPyObjectOwned<'py>,
    for<'a> <T as FromPyObject<'a, 'py>>::Error: Into<PyErr>,
{
    v.extract::<T>().map_err(|e| bad(key, e.into()))
}

/// The value of keyword `key` as one of the value enum `T`'s names (the
/// CLI's names for it).
fn choice<T: ValueEnum>(key: &str, v: &Bound<'_, PyAny>) -> PyResult<T> {
    let s: String = get(key, v)?;
    T::from_str(&s, false).map_err(|_| {
        let names: Vec<String> = T::value_variants()
            .iter()
            .filter_map(|x| x.to_possible_value().map(|p| p.get_name().to_string()))
            .collect();
        bad(key, format!("{s:?} is not one of {}", names.join(", ")))
    })
}

/// The items of a repeatable option's value: a dict's (key, value) pairs,
/// a list's or tuple's entries, else the value itself.
fn items<'py>(v: &Bound<'py, PyAny>) -> PyResult<Vec<Bound<'py, PyAny>>> {
    Ok(if let Ok(d) = v.cast::<PyDict>() {
        d.items().iter().collect()
    } else if v.cast::<PyList>().is_ok() || v.cast::<PyTuple>().is_ok() {
        v.try_iter()?.collect::<PyResult<_>>()?
    } else {
        vec![v.clone()]
    })
}

/// `lr_drop`: (epoch, lr) pairs, a list of them or of `"EPOCH:LR"` strings.
fn lr_drops(v: &Bound<'_, PyAny>) -> PyResult<Vec<(usize, f64)>> {
    const KEY: &str = "lr_drop";
    let lone_pair = v
        .cast::<PyTuple>()
        .is_ok_and(|t| t.len() == 2 && t.get_item(0).is_ok_and(|x| x.extract::<usize>().is_ok()));
    let list = if lone_pair {
        vec![v.clone()]
    } else {
        items(v)?
    };
    list.iter()
        .map(|item| {
            if item.cast::<PyString>().is_ok() {
                let s: String = item.extract()?;
                return mcgnode::cli::train::parse_drop(&s).map_err(|e| bad(KEY, e));
            }
            let (e, lr): (usize, f64) = item.extract().map_err(|_| {
                bad(
                    KEY,
                    format!("expected (epoch, lr) pairs such as (300, 1e-3), got {item}"),
                )
            })?;
            if lr.is_finite() && lr > 0.0 {
                Ok((e, lr))
            } else {
                Err(bad(
                    KEY,
                    format!("the learning rate after epoch {e} must be positive, got {lr}"),
                ))
            }
        })
        .collect()
}

/// `block_hidden`: `{block: sizes}`, (block, sizes) pairs or `"BLOCK=SIZES"`
/// strings; sizes a list of positive integers, one integer or `"16,16"`.
fn block_hidden(v: &Bound<'_, PyAny>) -> PyResult<Vec<(String, Vec<usize>)>> {
    const KEY: &str = "block_hidden";
    items(v)?
        .iter()
        .map(|item| {
            if item.cast::<PyString>().is_ok() {
                let s: String = item.extract()?;
                return mcgnode::cli::train::parse_block(&s).map_err(|e| bad(KEY, e));
            }
            let (block, sizes): (String, Bound<'_, PyAny>) = item.extract().map_err(|_| {
                bad(
                    KEY,
                    format!(
                        "expected {{block: sizes}} such as {{\"edge_out\": [16, 16]}}, got {item}"
                    ),
                )
            })?;
            if sizes.cast::<PyString>().is_ok() {
                let s: String = sizes.extract()?;
                return mcgnode::cli::train::parse_block(&format!("{block}={s}"))
                    .map_err(|e| bad(KEY, e));
            }
            let sizes: Vec<usize> = match sizes.extract::<usize>() {
                Ok(one) => vec![one],
                Err(_) => sizes.extract().map_err(|_| {
                    bad(
                        KEY,
                        format!("the sizes of {block:?} must be positive integers, got {sizes}"),
                    )
                })?,
            };
            if let Some(z) = sizes.iter().find(|&&n| n == 0) {
                return Err(bad(
                    KEY,
                    format!("hidden size {z} of {block:?} is not a positive integer"),
                ));
            }
            Ok((block, sizes))
        })
        .collect()
}

/// What `train()`'s keywords stand for: the options, the config, and
/// whether to print nothing.
struct Settings {
    opts: ModelOptions,
    cfg: TrainConfig,
    quiet: bool,
}

/// Sets the option `k` of `s` to `v` (neither the recipe nor the
/// checkpoint's, which [`settings`] sets).
fn set(s: &mut Settings, k: &str, v: &Bound<'_, PyAny>) -> PyResult<()> {
    let (o, c) = (&mut s.opts, &mut s.cfg);
    match k {
        "topic" => o.topic = Some(get(k, v)?),
        "epochs" => c.set_epochs(get(k, v)?),
        "seed" => c.seed = get(k, v)?,
        "lr" => c.set_lr(get(k, v)?),
        "lr_drop" => {
            let drops = lr_drops(v)?;
            // As `--lr-drop` given no times: the recipe's step stays.
            if !drops.is_empty() {
                c.set_lr_drops(drops);
            }
        }
        "batch" => c.set_batch(get(k, v)?),
        "max_seconds" => c.time_budget = Some(get(k, v)?),
        "patience" => c.patience = get(k, v)?,
        "hidden" => o.hidden = get(k, v)?,
        "embed" => o.embed = get(k, v)?,
        "rounds" => o.rounds = get(k, v)?,
        "arch" => o.arch = choice::<ArchArg>(k, v)?.into(),
        "hidden_layers" => o.hidden_layers = Some(get(k, v)?),
        "messages" => o.message = Some(choice::<MessageFnArg>(k, v)?.into()),
        "edge_update" => o.edge_input = Some(choice::<EdgeInputArg>(k, v)?.into()),
        "block_hidden" => o.block_hidden = block_hidden(v)?.into_iter().collect(),
        "noise" => c.noise = get(k, v)?,
        "points" => c.points = Some(get(k, v)?),
        "body_force" => o.body_force = choice::<BodyForceArg>(k, v)?.into(),
        "engine" => c.engine = choice::<EngineArg>(k, v)?.into(),
        "threads" => c.threads = get(k, v)?,
        "edge_physics" => o.edge_physics = get(k, v)?,
        "radius" => o.radius = Some(get(k, v)?),
        "no_normalize" => c.normalize = !get::<bool>(k, v)?,
        "init" => {
            let path: PathBuf = get(k, v)?;
            let file = mcgnode::gnode::ModelFile::load(&path).map_err(lib_err)?;
            c.init = Some(Box::new(file));
        }
        "ensemble" => {
            let n: usize = get(k, v)?;
            if !(1..=64).contains(&n) {
                return Err(bad(k, format!("{n} members: give 1 to 64")));
            }
            c.ensemble = n;
        }
        "quiet" => s.quiet = get(k, v)?,
        _ => unreachable!("{k} is in OPTIONS but not handled"),
    }
    Ok(())
}

/// The typed settings of `train()`'s keyword `options`: the defaults of the
/// recipe they name (the default recipe when none), each given option set
/// (None leaves an option at its default). An unknown keyword is a
/// TypeError listing the known ones, a bad value a ValueError naming its
/// keyword.
fn settings(options: Option<&Bound<'_, PyDict>>) -> PyResult<Settings> {
    let mut given: Vec<(String, Bound<'_, PyAny>)> = vec![];
    for (k, v) in options.into_iter().flat_map(PyDictMethods::iter) {
        let key: String = k.extract()?;
        if !OPTIONS.contains(&key.as_str()) {
            return Err(PyTypeError::new_err(format!(
                "train() got an unexpected keyword argument '{key}' (the variant is variant=; \
                 options: {})",
                OPTIONS.join(", ")
            )));
        }
        if !v.is_none() {
            given.push((key, v));
        }
    }
    let recipe = match given.iter().find(|(k, _)| k == "recipe") {
        Some((k, v)) => Recipe::from(choice::<RecipeArg>(k, v)?),
        None => Recipe::default(),
    };
    let mut s = Settings {
        opts: ModelOptions::for_recipe(recipe),
        cfg: TrainConfig::for_recipe(recipe),
        quiet: false,
    };
    let (mut checkpoint, mut every): (Option<PathBuf>, Option<f64>) = (None, None);
    for (key, v) in &given {
        match key.as_str() {
            "recipe" => {}
            "checkpoint" => checkpoint = Some(get(key, v)?),
            "checkpoint_every" => every = Some(get(key, v)?),
            k => set(&mut s, k, v)?,
        }
    }
    s.cfg.checkpoint = match (checkpoint, every) {
        (None, Some(_)) => {
            return Err(bad(
                "checkpoint_every",
                "needs checkpoint= (the file to save to)",
            ))
        }
        (path, every) => path.map(|path| Checkpointing {
            path,
            every: every.unwrap_or(Checkpointing::EVERY),
        }),
    };
    Ok(s)
}

/// Trains a model on `bags` (a path or a list of paths, each a bag as
/// `read_bag` takes it) and writes its model file to `out`: `mcgnode train
/// --data BAGS --out OUT --model VARIANT [options]`, with the CLI's
/// defaults. `variant` is the CLI's `--model` (node, gnode, cgnode, cdgnode,
/// mcgnode, lgn, hgn, gns); every other `train` option is a keyword of the
/// same name with underscores (`epochs=300`, `seed=1`, `recipe="paper"`,
/// `edge_physics=True`, `lr_drop=[(300, 1e-3)]`, `block_hidden={"edge_out":
/// [16, 16]}`, `quiet=True`, ...). Progress goes to stderr as the CLI prints
/// it (unless quiet); a model that explains little of its targets warns
/// (UserWarning).
///
/// Returns the model file's training report as a dict (seed, epochs_run,
/// best_epoch, train_loss, validation_loss, explained, seconds, ...), with
/// "out", "summary" (the line the CLI prints at the end) and
/// "explained_line". Raises mcgnode.Error with the CLI's message; an unknown
/// keyword TypeError, a bad value ValueError naming its keyword.
#[pyfunction]
#[pyo3(signature = (bags, out, *, variant, **options))]
pub(crate) fn train<'py>(
    py: Python<'py>,
    bags: &Bound<'py, PyAny>,
    out: PathBuf,
    variant: String,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let kind: ModelKind = variant.parse().map_err(|e| bad("variant", e))?;
    let bags = paths(bags, "bags")?;
    let Settings { opts, cfg, quiet } = settings(options)?;
    let mut interrupted: Option<PyErr> = None;
    let result = {
        let interrupted = &mut interrupted;
        py.detach(|| {
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
            mcgnode::models::train_any_from_bags(kind, &bags, &opts, &cfg, log, on_epoch, &out)
        })
    };
    if let Some(e) = interrupted {
        return Err(e);
    }
    let report = result.map_err(lib_err)?;
    let summary = mcgnode::cli::train::summary(&out, &report);
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
    d.set_item("out", out.display().to_string())?;
    d.set_item("summary", summary)?;
    d.set_item("explained_line", report.explained_line())?;
    Ok(d)
}
