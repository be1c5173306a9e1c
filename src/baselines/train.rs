//! Training a baseline with the same semantics as [`crate::train::train`]:
//! Adam, batches, a seeded 75:25 split, early stopping on the validation loss
//! with the best weights kept, `on_epoch` returning false to cancel.
//!
//! The loop itself is [`crate::train::fit`], shared with the GNODE family.

use super::file::{BaselineFile, FORMAT};
use super::net::{BaselineHyper, BaselineNet};
use super::trained::TrainedBaseline;
use crate::error::{bail, Result};
use crate::gnode::batch::Batch;
use crate::gnode::graph_plan::GraphPlan;
use crate::system::{Graph, State};
use crate::train::{
    check_data, fit, flat_params, set_flat_params, BaselineObjective, CandleObjective, EngineKind,
    EpochReport, Objective, TrainConfig,
};
use candle_core::Tensor;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Trains a fresh baseline on states of one graph with their accelerations
/// (HGN derives its (q̇, ṗ) targets from them, see [`super::hgn::loss`]).
/// `on_epoch` sees every epoch and returns false to cancel.
pub fn train_baseline(
    hyper: BaselineHyper,
    graph: &Graph,
    states: &[State],
    acc: &[Vec<f64>],
    cfg: &TrainConfig,
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<TrainedBaseline> {
    check_data(graph, states, acc, cfg)?;
    if let Some(why) = super::trained::contact_refusal(&hyper, graph) {
        bail!("{why}");
    }
    crate::alloc::prepare_for_candle();
    if cfg.init.is_some() {
        bail!("--init (warm start) is for the GNODE family; baselines train from scratch");
    }
    if graph.dim != hyper.dim {
        bail!("the model is {}D, the data {}D", hyper.dim, graph.dim);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let net = BaselineNet::new(hyper, &mut rng)?;
    let plan = GraphPlan::new(graph);
    let masses = &graph.masses;
    let loss = |idx: &[usize]| -> Result<Tensor> {
        let s: Vec<&State> = idx.iter().map(|&i| &states[i]).collect();
        let a: Vec<&[f64]> = idx.iter().map(|&i| acc[i].as_slice()).collect();
        net.loss(&Batch::new(&plan, &s, Some(&a), net.hyper.types)?, masses)
    };
    let mut theta = flat_params(&net.store)?;
    let exec = match cfg.engine {
        EngineKind::Native => Some(
            net.hyper
                .executor(&net.param_sizes()?, graph, cfg.threads)?,
        ),
        EngineKind::Candle => None,
    };
    let mut obj: Box<dyn Objective + '_> = match exec {
        Some(exec) => Box::new(BaselineObjective::new(exec, states, acc)),
        None => Box::new(CandleObjective::with_threads(
            &net.store,
            loss,
            cfg.threads,
        )?),
    };
    let mut adam = crate::train::Adam::new(cfg.lr, theta.len());
    let sp = crate::train::split(states.len(), cfg, &mut rng);
    // HGN's loss is on (q̇, ṗ): its trivial predictor says zero for both.
    let trivial = match net.hyper.kind {
        super::net::Kind::Hgn => super::hgn::trivial_loss(states, acc, masses, &sp.validation),
        _ => crate::train::trivial_loss_free(acc, &sp.validation, |f| {
            !graph.is_kinematic(f / graph.dim)
        }),
    };
    let training = fit(
        &mut theta,
        sp,
        cfg,
        &mut rng,
        obj.as_mut(),
        &mut adam,
        on_epoch,
    )?
    .with_trivial(trivial);
    drop(obj);
    set_flat_params(&net.store, &theta)?;
    let file = BaselineFile {
        format: FORMAT.to_string(),
        crate_version: env!("CARGO_PKG_VERSION").to_string(),
        hyper: net.hyper.clone(),
        trained_on: None,
        training,
        weights: net.store.weights()?,
    };
    drop(net);
    TrainedBaseline::from_file(file)
}

/// Trains a baseline from trajectory bags (on ParticleState topic `topic`
/// when they hold several), as [`crate::train::train_from_bags`] does for the
/// GNODE family (same data, split and loop); returns the file.
pub(crate) fn train_baseline_from_bags(
    kind: super::net::Kind,
    bags: &[std::path::PathBuf],
    topic: Option<&str>,
    radius: Option<f64>,
    cfg: &TrainConfig,
    mut log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<BaselineFile> {
    log(&format!("training {kind}"));
    let mut data = crate::train::load_training_data_from(bags, topic, &mut log)?;
    crate::train::set_radius(&mut data.dataset.graph, radius, &mut log)?;
    crate::train::apply_data_options(&mut data.dataset, cfg, &mut log)?;
    data.trained_on.states = data.dataset.len();
    let ds = &data.dataset;
    // The default recipe was measured on the GNODE family: the baselines keep
    // their papers' settings unless they are given.
    let mut cfg = cfg.clone();
    cfg.auto = crate::train::Auto::default();
    let cfg = &cfg;
    let types = ds.graph.type_count();
    let engine = match cfg.engine {
        EngineKind::Native => "the native engine (hand-written gradients)",
        EngineKind::Candle => "candle's autodiff",
    };
    log(&format!("gradients by {engine}"));
    let mut hyper = BaselineHyper::new(kind, ds.graph.dim, types);
    hyper.interaction_radius = ds.graph.interaction_radius;
    let trained = train_baseline(hyper, &ds.graph, &ds.states, &ds.acc, cfg, on_epoch)?;
    let mut file = trained.file;
    file.trained_on = Some(data.trained_on);
    Ok(file)
}
