//! Training a baseline with the same semantics as [`crate::train::train`]:
//! Adam, batches, a seeded 75:25 split, early stopping on the validation loss
//! with the best weights kept, `on_epoch` returning false to cancel.
//!
//! The loop and the flat-vector Adam mirror `crate::train` (whose Adam is
//! private and tied to `Net`); factoring both over a `ParamStore` + loss
//! closure would remove the copy.

use super::file::{BaselineFile, FORMAT};
use super::net::{BaselineHyper, BaselineNet};
use super::trained::TrainedBaseline;
use crate::model::batch::Batch;
use crate::model::file::TrainingReport;
use crate::model::params::ParamStore;
use crate::model::plan::GraphPlan;
use crate::system::{Graph, State};
use crate::train::{EpochReport, TrainConfig};
use anyhow::{bail, Result};
use candle_core::Tensor;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

/// Adam (Kingma & Ba) on flat parameter vectors.
pub struct Adam {
    lr: f64,
    m: Vec<Vec<f64>>,
    v: Vec<Vec<f64>>,
    t: i32,
}

impl Adam {
    /// Zero moments for the store's parameters.
    pub fn new(lr: f64, store: &ParamStore) -> Self {
        let sizes: Vec<usize> = store.vars().iter().map(|v| v.elem_count()).collect();
        Self {
            lr,
            m: sizes.iter().map(|&n| vec![0.0; n]).collect(),
            v: sizes.iter().map(|&n| vec![0.0; n]).collect(),
            t: 0,
        }
    }

    /// One update from the gradients of a loss.
    pub fn step(
        &mut self,
        store: &ParamStore,
        grads: &candle_core::backprop::GradStore,
    ) -> Result<()> {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        const EPS: f64 = 1e-8;
        self.t += 1;
        let c1 = 1.0 - B1.powi(self.t);
        let c2 = 1.0 - B2.powi(self.t);
        for (k, var) in store.vars().iter().enumerate() {
            let Some(g) = grads.get(var) else { continue };
            let g = g.flatten_all()?.to_vec1::<f64>()?;
            let mut p = var.as_tensor().flatten_all()?.to_vec1::<f64>()?;
            let (m, v) = (&mut self.m[k], &mut self.v[k]);
            for i in 0..p.len() {
                m[i] = B1 * m[i] + (1.0 - B1) * g[i];
                v[i] = B2 * v[i] + (1.0 - B2) * g[i] * g[i];
                p[i] -= self.lr * (m[i] / c1) / ((v[i] / c2).sqrt() + EPS);
            }
            var.set(&Tensor::from_vec(p, var.shape(), var.device())?)?;
        }
        Ok(())
    }
}

/// Mean loss over a set of states, in chunks.
pub fn mean_loss(
    net: &BaselineNet,
    plan: &GraphPlan,
    masses: &[f64],
    states: &[&State],
    acc: &[&[f64]],
) -> Result<f64> {
    let mut total = 0.0;
    for (s, a) in states.chunks(500).zip(acc.chunks(500)) {
        let b = Batch::new(plan, s, Some(a), net.hyper.types)?;
        total += net.loss(&b, masses)?.to_scalar::<f64>()? * s.len() as f64;
    }
    Ok(total / states.len().max(1) as f64)
}

/// Trains a fresh baseline on states of one graph with their accelerations
/// (HGN derives its (q̇, ṗ) targets from them, see [`super::hgn::loss`]).
/// `on_epoch` sees every epoch and returns false to cancel.
pub fn train_baseline(
    hyper: BaselineHyper,
    graph: &Graph,
    states: &[State],
    acc: &[Vec<f64>],
    cfg: &TrainConfig,
    mut on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<TrainedBaseline> {
    if states.len() != acc.len() {
        bail!("{} states but {} accelerations", states.len(), acc.len());
    }
    if states.len() < 2 {
        bail!("need at least 2 states to train (got {})", states.len());
    }
    if !(cfg.validation > 0.0 && cfg.validation < 1.0) {
        bail!("validation fraction must be in (0, 1)");
    }
    if cfg.batch == 0 || cfg.epochs == 0 {
        bail!("batch size and epochs must be positive");
    }
    graph.validate().map_err(anyhow::Error::msg)?;
    if graph.dim != hyper.dim {
        bail!("the model is {}D, the data {}D", hyper.dim, graph.dim);
    }
    for (i, (s, a)) in states.iter().zip(acc).enumerate() {
        s.validate(graph)
            .map_err(|e| anyhow::anyhow!("state {i}: {e}"))?;
        if a.len() != graph.ndof() || a.iter().any(|x| !x.is_finite()) {
            bail!("accelerations of state {i} have the wrong size or are not finite");
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let net = BaselineNet::new(hyper, &mut rng)?;
    let plan = GraphPlan::new(graph);
    let masses = &graph.masses;

    let mut order: Vec<usize> = (0..states.len()).collect();
    order.shuffle(&mut rng);
    let n_val =
        ((states.len() as f64 * cfg.validation).round() as usize).clamp(1, states.len() - 1);
    let (val_idx, train_idx) = order.split_at(n_val);
    let mut train_idx = train_idx.to_vec();
    let val_s: Vec<&State> = val_idx.iter().map(|&i| &states[i]).collect();
    let val_a: Vec<&[f64]> = val_idx.iter().map(|&i| acc[i].as_slice()).collect();

    let mut adam = Adam::new(cfg.lr, &net.store);
    let start = Instant::now();
    let mut best = f64::INFINITY;
    let mut best_weights = net.store.weights()?;
    let (mut best_epoch, mut best_train) = (0, f64::NAN);
    let mut epochs_run = 0;
    let mut stopped_early = false;
    for epoch in 1..=cfg.epochs {
        train_idx.shuffle(&mut rng);
        let (mut sum, mut count) = (0.0, 0usize);
        for chunk in train_idx.chunks(cfg.batch) {
            let s: Vec<&State> = chunk.iter().map(|&i| &states[i]).collect();
            let a: Vec<&[f64]> = chunk.iter().map(|&i| acc[i].as_slice()).collect();
            let b = Batch::new(&plan, &s, Some(&a), net.hyper.types)?;
            let loss = net.loss(&b, masses)?;
            let l = loss.to_scalar::<f64>()?;
            if !l.is_finite() {
                bail!("training diverged at epoch {epoch} (loss {l})");
            }
            adam.step(&net.store, &loss.backward()?)?;
            sum += l * chunk.len() as f64;
            count += chunk.len();
        }
        let train_loss = sum / count as f64;
        let val = mean_loss(&net, &plan, masses, &val_s, &val_a)?;
        epochs_run = epoch;
        if !val.is_finite() {
            bail!("validation loss is not finite at epoch {epoch}");
        }
        if val < best {
            best = val;
            best_epoch = epoch;
            best_train = train_loss;
            best_weights = net.store.weights()?;
        }
        let report = EpochReport {
            epoch,
            epochs: cfg.epochs,
            train_loss,
            validation_loss: val,
            best,
            elapsed: start.elapsed().as_secs_f64(),
        };
        if !on_epoch(&report) {
            bail!("training cancelled at epoch {epoch}");
        }
        if epoch - best_epoch >= cfg.patience {
            stopped_early = true;
            break;
        }
    }
    let mut net = net;
    net.store.load(&best_weights)?;
    let file = BaselineFile {
        format: FORMAT.to_string(),
        crate_version: env!("CARGO_PKG_VERSION").to_string(),
        hyper: net.hyper.clone(),
        trained_on: None,
        training: TrainingReport {
            seed: cfg.seed,
            epochs_requested: cfg.epochs,
            epochs_run,
            best_epoch,
            train_loss: best_train,
            validation_loss: best,
            stopped_early,
            seconds: start.elapsed().as_secs_f64(),
            batch: cfg.batch,
            lr: cfg.lr,
            patience: cfg.patience,
        },
        weights: net.store.weights()?,
    };
    Ok(TrainedBaseline { file, net })
}
