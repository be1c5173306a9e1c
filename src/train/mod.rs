//! Training: MSE on accelerations, Adam, batches of 100, a seeded 75:25 split,
//! early stopping on the validation loss (the best weights are kept).
//!
//! - [`config`]: the settings ([`TrainConfig`]) and the gradient engine.
//! - [`options`]: architecture choices ([`ModelOptions`], the body-force branch).
//! - [`adam`]: the optimiser.
//! - [`objective`]: the loss and its gradient, by candle or the native engine.
//! - [`fit`](mod@fit): the training loop, with early stopping and checkpoints.
//! - [`checkpoint`]: a run's state saved and taken up.
//! - [`recipe`]: settings chosen from the data.
//!
//! This file trains a model of given hyperparameters ([`train`]) and a model
//! from bags (`train_from_bags`); the bags are read by
//! [`crate::data::load`].

use crate::data::dataset::Dataset;
use crate::engine::Engine;
use crate::error::{bail, Result};
use crate::gnode::batch::Batch;
use crate::gnode::file::{AdamState, TrainingReport};
use crate::gnode::graph_plan::GraphPlan;
use crate::gnode::{Hyper, Net};
use crate::system::{Graph, State};
use candle_core::Tensor;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub mod adam;
pub mod checkpoint;
pub mod config;
pub mod fit;
pub mod objective;
pub mod options;
pub mod recipe;

pub use adam::Adam;
pub use checkpoint::{Checkpoint, CheckpointError, Checkpointing};
pub use config::{EngineKind, TrainConfig};
pub use fit::{check_data, fit, split, trivial_loss, trivial_loss_free, EpochReport, Split};
pub use objective::{
    flat_params, set_flat_params, BaselineObjective, CandleObjective, EngineObjective, Objective,
};
pub use options::{BodyForce, ModelOptions};
pub use recipe::{Auto, Recipe};

// Bag loading lives with the data; its paths under `train` are kept.
pub use crate::data::load::{load_training_data, load_training_data_from, TrainingData};

/// The result of training.
pub struct Trained {
    /// The model with the best weights.
    pub net: Net,
    /// Figures for the model file.
    pub report: TrainingReport,
    /// Adam's state after the last epoch.
    pub optimizer: crate::gnode::file::AdamState,
}

/// Mixed into [`TrainConfig::seed`] for the subsample's stream ("points"), so
/// it is independent of initialisation and shuffling.
const POINTS_STREAM: u64 = 0x706f_696e_7473;
/// Mixed into [`TrainConfig::seed`] for the noise stream ("noise").
const NOISE_STREAM: u64 = 0x6e_6f69_7365;

/// Applies the data options of `cfg` to a training set: first the subsample
/// ([`TrainConfig::points`], [`Dataset::subsample`]), then the noise
/// ([`TrainConfig::noise`], [`Dataset::add_noise`]), so the noise scale is
/// that of the data actually trained on. `log` says what was done.
pub fn apply_data_options(
    ds: &mut Dataset,
    cfg: &TrainConfig,
    mut log: impl FnMut(&str),
) -> Result<()> {
    if let Some(points) = cfg.points {
        let total = ds.len();
        ds.subsample(points, cfg.seed ^ POINTS_STREAM)?;
        log(&format!("using {points} of {total} states"));
    }
    let sigma = ds.add_noise(cfg.noise, cfg.seed ^ NOISE_STREAM)?;
    if cfg.noise > 0.0 {
        log(&format!(
            "added {}% noise: σ = {sigma:.3e} to accelerations",
            cfg.noise
        ));
    }
    Ok(())
}

/// Trains a fresh model of `hyper` on states of one graph with their
/// accelerations. `on_epoch` sees every epoch and returns false to cancel.
pub fn train(
    hyper: Hyper,
    graph: &Graph,
    states: &[State],
    acc: &[Vec<f64>],
    cfg: &TrainConfig,
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<Trained> {
    check_data(graph, states, acc, cfg)?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    // Both engines start from the same seeded initialisation (or the warm start).
    let mut net = Net::new(hyper, &mut rng)?;
    let sp = split(states.len(), cfg, &mut rng);
    prepare(&mut net, graph, (states, acc), &sp.train, cfg)?;
    // One flat parameter order for both engines (the architecture's), in
    // which Adam's moments are stored by name too.
    let layout = crate::engine::Layout::new(&net.parts.arch);
    if !layout
        .names()
        .into_iter()
        .eq(net.store.names().iter().map(String::as_str))
    {
        bail!("internal error: the candle store and the engine order parameters differently");
    }
    let mut theta = layout.flatten(&net.store.weights()?)?;
    let mut adam = match cfg.init.as_ref().and_then(|f| f.optimizer.as_ref()) {
        Some(st) => Adam::resume(
            cfg.lr,
            st.step,
            layout.flatten(&st.m)?,
            layout.flatten(&st.v)?,
        ),
        None => Adam::new(cfg.lr, theta.len()),
    };
    let plan = GraphPlan::new(graph);
    let loss = |idx: &[usize]| -> Result<Tensor> {
        let s: Vec<&State> = idx.iter().map(|&i| &states[i]).collect();
        let a: Vec<&[f64]> = idx.iter().map(|&i| acc[i].as_slice()).collect();
        net.loss(&Batch::new(&plan, &s, Some(&a), net.hyper.types)?)
    };
    let (mut engine, mut native, mut candle);
    let objective: &mut dyn Objective = match cfg.engine {
        EngineKind::Candle => {
            candle = CandleObjective::new(&net.store, loss);
            &mut candle
        }
        EngineKind::Native => {
            engine = Engine::new(&net.hyper, graph, cfg.threads)?;
            native = EngineObjective::new(&mut engine, states, acc);
            &mut native
        }
    };
    let trivial = trivial_loss_free(acc, &sp.validation, |f| !graph.is_kinematic(f / graph.dim));
    let report = fit(
        &mut theta, sp, cfg, &mut rng, objective, &mut adam, on_epoch,
    )?
    .with_trivial(trivial);
    net.store.load(&layout.weights(&theta))?;
    let (step, m, v) = adam.state();
    let optimizer = AdamState {
        step,
        m: layout.weights(m),
        v: layout.weights(v),
    };
    Ok(Trained {
        net,
        report,
        optimizer,
    })
}

/// The fresh `net`'s normalisation from the training states `train` (when
/// asked for and not given), or the warm start's weights (`--init`).
fn prepare(
    net: &mut Net,
    graph: &Graph,
    (states, acc): (&[State], &[Vec<f64>]),
    train: &[usize],
    cfg: &TrainConfig,
) -> Result<()> {
    if cfg.normalize && cfg.init.is_none() && net.hyper.norm.is_none() {
        let s: Vec<&State> = train.iter().map(|&i| &states[i]).collect();
        let a: Vec<&[f64]> = train.iter().map(|&i| acc[i].as_slice()).collect();
        net.set_norm(Some(crate::gnode::Norm::from_data(graph, &s, &a)));
    }
    if let Some(init) = &cfg.init {
        if init.hyper != net.hyper {
            bail!(
                "--init model has another architecture ({:?}) than the one to train ({:?})",
                init.hyper,
                net.hyper
            );
        }
        net.store.load(&init.weights)?;
    }
    Ok(())
}

/// Applies `--radius` (when given) to the training graph and says what the
/// models will see of contacts and kinematic particles.
pub fn set_radius(graph: &mut Graph, radius: Option<f64>, mut log: impl FnMut(&str)) -> Result<()> {
    if let Some(r) = radius {
        if !(r.is_finite() && r >= 0.0) {
            bail!("--radius {r} must be a finite number ≥ 0 (0: fixed edges only)");
        }
        graph.interaction_radius = r;
    }
    let contacts = if graph.has_contacts() {
        format!(
            "contacts within radius {} (found at every state)",
            graph.interaction_radius
        )
    } else {
        "no contact edges (radius 0)".to_string()
    };
    if graph.has_contacts() || graph.n_kinematic() > 0 {
        log(&format!(
            "{contacts}; {} kinematic particles, left out of the loss",
            graph.n_kinematic()
        ));
    }
    Ok(())
}

/// Trains a model from trajectory bags and returns the model file (not yet saved).
pub(crate) fn train_from_bags(
    variant: crate::gnode::Variant,
    bags: &[std::path::PathBuf],
    opts: &ModelOptions,
    cfg: &TrainConfig,
    mut log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<crate::gnode::ModelFile> {
    log(&format!("training {variant}"));
    let mut data = load_training_data_from(bags, opts.topic.as_deref(), &mut log)?;
    set_radius(&mut data.dataset.graph, opts.radius, &mut log)?;
    apply_data_options(&mut data.dataset, cfg, &mut log)?;
    data.trained_on.states = data.dataset.len();
    let ds = &data.dataset;
    let edges = recipe::directed_edges_in(&ds.graph, &ds.states);
    let (cfg, chosen) = cfg.resolved_for(edges, ds.len());
    let cfg = &cfg;
    if let Some(line) = chosen {
        log(&line);
    }
    let types = opts.types.unwrap_or(ds.graph.type_count());
    let mut hyper = opts.hyper(variant, ds.graph.dim, types, ds.graph.n())?;
    hyper.interaction_radius = ds.graph.interaction_radius;
    hyper.body_force = body_force(variant, opts.body_force, data.closed.as_ref(), cfg)?;
    if let Some(init) = &cfg.init {
        // A warm start keeps the architecture it was trained with.
        hyper = warm_start_hyper(init, variant, &ds.graph, types, &mut log)?;
    }
    if variant == crate::gnode::Variant::Mcgnode {
        log_body_force(&hyper, opts.body_force, data.closed.as_ref(), cfg, &mut log);
    }
    let trained = train(hyper, &ds.graph, &ds.states, &ds.acc, cfg, on_epoch)?;
    Ok(crate::gnode::ModelFile {
        format: crate::gnode::file::FORMAT.to_string(),
        crate_version: env!("CARGO_PKG_VERSION").to_string(),
        hyper: trained.net.hyper.clone(),
        trained_on: data.trained_on,
        training: trained.report,
        weights: trained.net.store.weights()?,
        optimizer: Some(trained.optimizer),
        members: vec![],
    })
}

/// Whether a `variant` model trained on data that are `closed` (or not, or
/// that do not say) learns a body-force branch: as `asked`, or with
/// [`BodyForce::Auto`] unless the data are closed. A fresh MCGNODE on data
/// that do not say is refused.
fn body_force(
    variant: crate::gnode::Variant,
    asked: BodyForce,
    closed: Option<&(bool, String)>,
    cfg: &TrainConfig,
) -> Result<bool> {
    Ok(match asked {
        BodyForce::On => true,
        BodyForce::Off => false,
        BodyForce::Auto => match closed {
            Some((closed, _)) => !closed,
            // A warm start keeps its model's branch (below).
            None if variant == crate::gnode::Variant::Mcgnode && cfg.init.is_none() => bail!(
                "the training bags do not say whether the system is closed (their messages \
                 leave the field unknown, there is no system_config metadata, and the data do \
                 not show a closed system): pass --body-force off for a closed system \
                 (momentum conserved exactly) or --body-force on"
            ),
            None => true,
        },
    })
}

/// The hyperparameters of the `--init` model, checked to fit a `variant`
/// model on `graph` (with particle types up to `types - 1`); `log` says what
/// training continues from.
fn warm_start_hyper(
    init: &crate::gnode::ModelFile,
    variant: crate::gnode::Variant,
    graph: &Graph,
    types: usize,
    mut log: impl FnMut(&str),
) -> Result<Hyper> {
    let h = &init.hyper;
    if h.variant != variant {
        bail!("--init model is a {} model, not {variant}", h.variant);
    }
    if h.dim != graph.dim || graph.types.iter().any(|&t| t as usize >= h.types) {
        bail!(
            "--init model is {}D with {} particle types; the data are {}D with types up to {}",
            h.dim,
            h.types,
            graph.dim,
            types - 1
        );
    }
    if !variant.biases().graph && h.particles != graph.n() {
        bail!(
            "--init NODE model was built for {} particles, the data have {}",
            h.particles,
            graph.n()
        );
    }
    log(&format!(
        "continuing from a model trained for {} epochs (validation MSE {:.3e}), {}",
        init.training.epochs_run,
        init.training.validation_loss,
        if init.optimizer.is_some() {
            "with its Adam state"
        } else {
            "with a fresh Adam state"
        }
    ));
    Ok(h.clone())
}

/// Says whether an MCGNODE model learns body forces, and why.
fn log_body_force(
    hyper: &Hyper,
    asked: BodyForce,
    closed: Option<&(bool, String)>,
    cfg: &TrainConfig,
    mut log: impl FnMut(&str),
) {
    let why = match (asked, closed) {
        _ if cfg.init.is_some() => ", from the --init model".to_string(),
        (BodyForce::Auto, Some((_, why))) => format!(", from {why}"),
        (BodyForce::Auto, None) => String::new(),
        _ => ", as asked".to_string(),
    };
    log(&format!(
        "body-force branch: {}{why}",
        if hyper.body_force {
            "on"
        } else {
            "off (closed system: momentum is conserved exactly)"
        }
    ));
}
