//! Training: MSE on accelerations, Adam, batches of 100, a seeded 75:25 split,
//! early stopping on the validation loss (the best weights are kept).

use crate::data::dataset::Dataset;
use crate::engine::Engine;
use crate::error::{bail, Result};
use crate::model::batch::Batch;
use crate::model::file::AdamState;
use crate::model::file::TrainingReport;
use crate::model::params::ParamStore;
use crate::model::plan::GraphPlan;
use crate::model::{ArchPreset, EdgeInput, Hyper, MessageFn, Net, Variant};
use crate::system::{Graph, State};
use candle_core::Tensor;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::time::Instant;

pub mod checkpoint;
pub mod recipe;
pub use checkpoint::{Checkpoint, CheckpointError, Checkpointing};
use checkpoint::{Progress, RngState, RunKey};
pub use recipe::{Auto, Recipe};

// Bag loading lives with the data; its paths under `train` are kept.
pub use crate::data::load::{load_training_data, load_training_data_from, TrainingData};

/// Training settings.
#[derive(Clone, Debug)]
pub struct TrainConfig {
    /// Maximum epochs (paper: 10,000).
    pub epochs: usize,
    /// Adam learning rate (paper: 1e-3).
    pub lr: f64,
    /// Batch size (paper: 100).
    pub batch: usize,
    /// Fraction of states held out for validation (paper: 0.25).
    pub validation: f64,
    /// Stop when the validation loss has not improved for this many epochs.
    pub patience: usize,
    /// Seed for initialisation, split and shuffling (and, through distinct
    /// streams, subsampling and noise).
    pub seed: u64,
    /// Gaussian noise on the target accelerations, percent of their standard
    /// deviation (paper's noise experiments: 0, 1, 5, 10). Applied by
    /// [`apply_data_options`].
    pub noise: f64,
    /// Train on a seeded random subset of this many states (paper's
    /// data-efficiency experiments: 100 to 10,000); `None`: all. Applied by
    /// [`apply_data_options`].
    pub points: Option<usize>,
    /// Gradient engine of the GNODE family (the baselines always use candle).
    pub engine: EngineKind,
    /// Threads of the native engine; results do not depend on it.
    pub threads: usize,
    /// Warm start: continue from this model's weights (and its Adam state when
    /// it has one). Its hyperparameters must be the ones trained.
    pub init: Option<Box<crate::model::ModelFile>>,
    /// Scale inputs and outputs by statistics of the training split (stored
    /// in the model file; see [`crate::model::Norm`]).
    pub normalize: bool,
    /// Step schedule: after epoch `e`, learning rate `lr` (pairs in any order;
    /// the latest passed applies).
    pub lr_drops: Vec<(usize, f64)>,
    /// Stop after the first epoch that ends this many seconds after training
    /// started (the best weights so far are kept): a wall-clock budget, as a
    /// robot retraining between tasks has, and what `reproduce` gives the
    /// baselines to compare them with MCGNODE at equal time.
    pub time_budget: Option<f64>,
    /// Save the run's state as it goes, and resume from the file when it
    /// exists (see [`checkpoint`]).
    pub checkpoint: Option<Checkpointing>,
    /// Settings the default recipe chooses from the data instead of taking
    /// them from this config ([`recipe`]; none by default).
    pub auto: Auto,
}

impl TrainConfig {
    /// The learning rate of epoch `epoch` (from 1).
    pub fn lr_at(&self, epoch: usize) -> f64 {
        self.lr_drops
            .iter()
            .filter(|(e, _)| epoch > *e)
            .max_by_key(|(e, _)| *e)
            .map_or(self.lr, |(_, lr)| *lr)
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 10_000,
            lr: 1e-3,
            batch: 100,
            validation: 0.25,
            patience: 1_000,
            seed: 0,
            noise: 0.0,
            points: None,
            engine: EngineKind::Native,
            threads: crate::engine::all_cores(),
            init: None,
            normalize: true,
            lr_drops: vec![],
            time_budget: None,
            checkpoint: None,
            auto: Auto::default(),
        }
    }
}

impl TrainConfig {
    /// This config with the settings in [`TrainConfig::auto`] chosen by the
    /// default recipe for `states` states of `graph` (before the split), and
    /// a line saying what was chosen (`None` when nothing was).
    pub fn resolved(&self, graph: &Graph, states: usize) -> (TrainConfig, Option<String>) {
        self.resolved_for(recipe::directed_edges(graph), states)
    }

    /// [`TrainConfig::resolved`] for states of `edges` directed edges each
    /// (with contacts: [`recipe::directed_edges_in`]).
    pub fn resolved_for(&self, edges: usize, states: usize) -> (TrainConfig, Option<String>) {
        let a = self.auto;
        let mut c = self.clone();
        c.auto = Auto::default();
        if !a.any() {
            return (c, None);
        }
        let warm = self.init.is_some();
        if a.batch {
            c.batch = recipe::batch_for_edges(edges);
        }
        if a.lr {
            c.lr = if warm { 1e-3 } else { 1e-2 };
        }
        if a.epochs {
            let n_val = ((states as f64 * c.validation).round() as usize)
                .clamp(1, states.saturating_sub(1).max(1));
            c.epochs = recipe::epochs_for(states.saturating_sub(n_val), c.batch);
        }
        if a.lr_drops && !warm {
            c.lr_drops = vec![((c.epochs * 2).div_ceil(3), c.lr / 10.0)];
        }
        let drops = c
            .lr_drops
            .iter()
            .map(|(e, lr)| format!(", {lr:e} after epoch {e}"))
            .collect::<String>();
        let line = format!(
            "recipe: batch {} states ({} directed edges each), {} epochs, lr {:e}{drops}{}",
            c.batch,
            edges,
            c.epochs,
            c.lr,
            if warm { " (warm start)" } else { "" }
        );
        (c, Some(line))
    }
}

/// One epoch's figures, handed to the progress callback.
#[derive(Clone, Debug)]
pub struct EpochReport {
    /// Epoch number, from 1.
    pub epoch: usize,
    /// Epochs asked for.
    pub epochs: usize,
    /// Mean training loss over the epoch's batches.
    pub train_loss: f64,
    /// Validation loss after the epoch.
    pub validation_loss: f64,
    /// Best validation loss so far.
    pub best: f64,
    /// Seconds since training started.
    pub elapsed: f64,
}

/// The result of training.
pub struct Trained {
    /// The model with the best weights.
    pub net: Net,
    /// Figures for the model file.
    pub report: TrainingReport,
    /// Adam's state after the last epoch.
    pub optimizer: crate::model::file::AdamState,
}

/// Adam (Kingma & Ba) on one flat parameter vector: the same update for
/// both engines and every model kind.
pub struct Adam {
    lr: f64,
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl Adam {
    /// Zero moments for `len` parameters.
    pub fn new(lr: f64, len: usize) -> Self {
        Self {
            lr,
            m: vec![0.0; len],
            v: vec![0.0; len],
            t: 0,
        }
    }

    /// Continues from a saved state (moments flat, in parameter order).
    pub fn resume(lr: f64, step: i32, m: Vec<f64>, v: Vec<f64>) -> Self {
        Self { lr, m, v, t: step }
    }

    /// Sets the learning rate (a schedule's step).
    pub fn set_lr(&mut self, lr: f64) {
        self.lr = lr;
    }

    /// (updates taken, first moments, second moments).
    pub fn state(&self) -> (i32, &[f64], &[f64]) {
        (self.t, &self.m, &self.v)
    }

    /// One update of `theta` from `grad`.
    pub fn step(&mut self, theta: &mut [f64], grad: &[f64]) {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        const EPS: f64 = 1e-8;
        self.t += 1;
        let c1 = 1.0 - B1.powi(self.t);
        let c2 = 1.0 - B2.powi(self.t);
        for (((p, g), m), v) in theta.iter_mut().zip(grad).zip(&mut self.m).zip(&mut self.v) {
            *m = B1 * *m + (1.0 - B1) * g;
            *v = B2 * *v + (1.0 - B2) * g * g;
            *p -= self.lr * (*m / c1) / ((*v / c2).sqrt() + EPS);
        }
    }
}

/// What [`fit`] minimises: a mean loss over samples, with its gradient, as a
/// function of one flat parameter vector.
pub trait Objective {
    /// Mean loss over the samples `idx` at `theta`, its gradient written to `grad`.
    fn loss_grad(&mut self, theta: &[f64], idx: &[usize], grad: &mut [f64]) -> Result<f64>;
    /// Mean loss over the samples `idx` at `theta`.
    fn loss(&mut self, theta: &[f64], idx: &[usize]) -> Result<f64>;
}

/// The parameters of a candle store as one flat vector, in definition order.
pub fn flat_params(store: &ParamStore) -> Result<Vec<f64>> {
    let mut out = vec![];
    for v in store.vars() {
        out.extend(v.as_tensor().flatten_all()?.to_vec1::<f64>()?);
    }
    Ok(out)
}

/// Sets a candle store's parameters from a flat vector (definition order).
pub fn set_flat_params(store: &ParamStore, theta: &[f64]) -> Result<()> {
    let mut at = 0;
    for v in store.vars() {
        let n = v.elem_count();
        v.set(&Tensor::from_vec(
            theta[at..at + n].to_vec(),
            v.shape(),
            v.device(),
        )?)?;
        at += n;
    }
    if at != theta.len() {
        bail!("{} parameters given, the model has {at}", theta.len());
    }
    Ok(())
}

/// A candle loss `loss(indices)` over a store, differentiated by candle's
/// autodiff: the reference engine, and the one the baselines use. With more
/// than one thread, a batch is cut into one chunk per thread whose gradients
/// are summed in order (so results depend on the thread count only through
/// rounding); candle itself runs each chunk on one thread.
pub struct CandleObjective<'a, F> {
    store: &'a ParamStore,
    loss: F,
    pool: Option<rayon::ThreadPool>,
    threads: usize,
}

impl<'a, F: Fn(&[usize]) -> Result<Tensor> + Sync> CandleObjective<'a, F> {
    /// The objective of `loss` on `store`'s parameters, on one thread.
    pub fn new(store: &'a ParamStore, loss: F) -> Self {
        Self {
            store,
            loss,
            pool: None,
            threads: 1,
        }
    }

    /// The same, with batches cut over `threads` threads.
    pub fn with_threads(store: &'a ParamStore, loss: F, threads: usize) -> Result<Self> {
        let threads = threads.max(1);
        let pool = if threads > 1 {
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()?,
            )
        } else {
            None
        };
        Ok(Self {
            store,
            loss,
            pool,
            threads,
        })
    }

    /// Mean loss and its gradient over one chunk.
    fn chunk(&self, idx: &[usize], with_grad: bool) -> Result<(f64, Vec<f64>)> {
        let l = (self.loss)(idx)?;
        let value = l.to_scalar::<f64>()?;
        let mut out = vec![];
        if with_grad {
            let grads = l.backward()?;
            for var in self.store.vars() {
                match grads.get(&var) {
                    Some(g) => out.extend(g.flatten_all()?.to_vec1::<f64>()?),
                    // Parameters the loss does not read have no gradient.
                    None => out.extend(std::iter::repeat_n(0.0, var.elem_count())),
                }
            }
        }
        Ok((value, out))
    }

    /// The chunks of `idx` (at most `max` samples each, at least one per
    /// thread when there are enough), evaluated in order.
    fn chunks(
        &self,
        idx: &[usize],
        max: usize,
        with_grad: bool,
    ) -> Result<Vec<(usize, f64, Vec<f64>)>> {
        let size = idx.len().div_ceil(self.threads).clamp(1, max);
        let parts: Vec<&[usize]> = idx.chunks(size).collect();
        let run = |c: &&[usize]| -> Result<(usize, f64, Vec<f64>)> {
            let (l, g) = self.chunk(c, with_grad)?;
            Ok((c.len(), l, g))
        };
        match &self.pool {
            Some(pool) if parts.len() > 1 => pool.install(|| parts.par_iter().map(run).collect()),
            _ => parts.iter().map(run).collect(),
        }
    }
}

impl<F: Fn(&[usize]) -> Result<Tensor> + Sync> Objective for CandleObjective<'_, F> {
    fn loss_grad(&mut self, theta: &[f64], idx: &[usize], grad: &mut [f64]) -> Result<f64> {
        set_flat_params(self.store, theta)?;
        let n = idx.len() as f64;
        let parts = self.chunks(idx, usize::MAX, true)?;
        if let [(_, l, g)] = parts.as_slice() {
            grad.copy_from_slice(g);
            return Ok(*l);
        }
        grad.fill(0.0);
        let mut total = 0.0;
        for (len, l, g) in parts {
            let w = len as f64 / n;
            total += l * w;
            for (x, y) in grad.iter_mut().zip(&g) {
                *x += y * w;
            }
        }
        Ok(total)
    }

    fn loss(&mut self, theta: &[f64], idx: &[usize]) -> Result<f64> {
        set_flat_params(self.store, theta)?;
        let total: f64 = self
            .chunks(idx, 1000, false)?
            .iter()
            .map(|(len, l, _)| l * *len as f64)
            .sum();
        Ok(total / idx.len() as f64)
    }
}

/// The hand-written engine on one graph's states and target accelerations.
pub struct EngineObjective<'a> {
    engine: &'a mut Engine,
    states: &'a [State],
    targets: &'a [Vec<f64>],
}

impl<'a> EngineObjective<'a> {
    /// The objective of `engine` on these states and targets.
    pub fn new(engine: &'a mut Engine, states: &'a [State], targets: &'a [Vec<f64>]) -> Self {
        Self {
            engine,
            states,
            targets,
        }
    }
}

impl Objective for EngineObjective<'_> {
    fn loss_grad(&mut self, theta: &[f64], idx: &[usize], grad: &mut [f64]) -> Result<f64> {
        Ok(self
            .engine
            .loss_grad(theta, self.states, self.targets, idx, grad))
    }

    fn loss(&mut self, theta: &[f64], idx: &[usize]) -> Result<f64> {
        Ok(self.engine.loss(theta, self.states, self.targets, idx))
    }
}

/// Checks training data against its graph and the settings.
pub fn check_data(
    graph: &Graph,
    states: &[State],
    acc: &[Vec<f64>],
    cfg: &TrainConfig,
) -> Result<()> {
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
    graph.validate()?;
    for (i, (s, a)) in states.iter().zip(acc).enumerate() {
        s.validate(graph)
            .map_err(|e| crate::error::err!("state {i}: {e}"))?;
        if a.len() != graph.ndof() || a.iter().any(|x| !x.is_finite()) {
            bail!("accelerations of state {i} have the wrong size or are not finite");
        }
    }
    Ok(())
}

/// Sample indices held out for validation, and the rest.
#[derive(Clone, Debug)]
pub struct Split {
    /// Validation samples.
    pub validation: Vec<usize>,
    /// Training samples.
    pub train: Vec<usize>,
}

/// The seeded split of `n` samples (validation fraction from `cfg`).
pub fn split(n: usize, cfg: &TrainConfig, rng: &mut ChaCha8Rng) -> Split {
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(rng);
    let n_val = ((n as f64 * cfg.validation).round() as usize).clamp(1, n - 1);
    let train = order.split_off(n_val);
    Split {
        validation: order,
        train,
    }
}

/// The loop every trainable model shares: a [`split`] of the samples,
/// shuffled batches, Adam on the flat
/// parameters `theta` (from `adam`'s state, which is left as the last epoch
/// made it), validation after every epoch, early stopping; the best parameters
/// are left in `theta`. `on_epoch` returns false to cancel.
///
/// With [`TrainConfig::checkpoint`], the run's state is saved as it goes and,
/// when the file exists, taken up from it: the result is the one an
/// uninterrupted run gives, and the seconds and time budget count every
/// session.
pub fn fit(
    theta: &mut [f64],
    split: Split,
    cfg: &TrainConfig,
    rng: &mut ChaCha8Rng,
    objective: &mut dyn Objective,
    adam: &mut Adam,
    mut on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<TrainingReport> {
    let Split {
        validation: val_idx,
        train: train_idx,
    } = split;
    let val_idx = val_idx.as_slice();
    if adam.m.len() != theta.len() {
        bail!(
            "optimiser state has {} entries, the model {}",
            adam.m.len(),
            theta.len()
        );
    }
    if let Some(b) = cfg.time_budget {
        if !(b > 0.0 && b.is_finite()) {
            bail!("the time budget must be a positive number of seconds, got {b}");
        }
    }
    if let Some(ck) = &cfg.checkpoint {
        if !(ck.every >= 0.0 && ck.every.is_finite()) {
            bail!(
                "the checkpoint interval must be a number of seconds >= 0, got {}",
                ck.every
            );
        }
    }
    let mut run = Progress::fresh(theta, train_idx);
    let mut resumed_at = None;
    let key = match &cfg.checkpoint {
        Some(ck) => {
            let key = RunKey {
                parameters: theta.len(),
                train: run.train_order.len(),
                validation: val_idx.len(),
                seed: cfg.seed,
                batch: cfg.batch,
                lr: cfg.lr,
                lr_drops: cfg.lr_drops.clone(),
                patience: cfg.patience,
                time_budget: cfg.time_budget,
                initial_loss: objective.loss(theta, val_idx)?,
            };
            if let Some(c) = Checkpoint::load_for(&ck.path, &key)? {
                run = resume(c, &ck.path, &run.train_order, theta, rng, adam, cfg.lr)?;
                resumed_at = Some(run.epoch);
            }
            Some(key)
        }
        None => None,
    };
    let mut grad = vec![0.0; theta.len()];
    let start = Instant::now();
    let mut last_save = Instant::now();
    let before = run.seconds;
    let first = run.epoch + 1;
    for epoch in first..=cfg.epochs {
        if run.stopped_early || run.out_of_time {
            break;
        }
        adam.set_lr(cfg.lr_at(epoch));
        run.train_order.shuffle(rng);
        let (mut sum, mut count) = (0.0, 0usize);
        for chunk in run.train_order.chunks(cfg.batch) {
            let lv = objective.loss_grad(theta, chunk, &mut grad)?;
            if !lv.is_finite() {
                bail!("training diverged at epoch {epoch} (loss {lv})");
            }
            adam.step(theta, &grad);
            sum += lv * chunk.len() as f64;
            count += chunk.len();
        }
        let train_loss = sum / count as f64;
        let val = objective.loss(theta, val_idx)?;
        run.epoch = epoch;
        if !val.is_finite() {
            bail!("validation loss is not finite at epoch {epoch}");
        }
        if val < run.best {
            run.best = val;
            run.best_epoch = epoch;
            run.best_train = train_loss;
            run.best_theta.copy_from_slice(theta);
        }
        let report = EpochReport {
            epoch,
            epochs: cfg.epochs,
            train_loss,
            validation_loss: val,
            best: run.best,
            elapsed: before + start.elapsed().as_secs_f64(),
        };
        // Seconds to the end of the last epoch: the report, the checkpoint
        // and a resumed finished run state the same figure, so a budget
        // derived from it matches exactly.
        run.seconds = report.elapsed;
        run.stopped_early = epoch - run.best_epoch >= cfg.patience;
        run.out_of_time =
            !run.stopped_early && cfg.time_budget.is_some_and(|b| report.elapsed >= b);
        if let (Some(ck), Some(key)) = (&cfg.checkpoint, &key) {
            let last = epoch == cfg.epochs || run.stopped_early || run.out_of_time;
            if last || last_save.elapsed().as_secs_f64() >= ck.every {
                let (adam_step, m, v) = adam.state();
                let c = Checkpoint {
                    format: checkpoint::FORMAT.into(),
                    key: key.clone(),
                    progress: run.clone(),
                    theta: theta.to_vec(),
                    adam_step,
                    adam_m: m.to_vec(),
                    adam_v: v.to_vec(),
                    rng: RngState::of(rng),
                };
                c.save(&ck.path)?;
                last_save = Instant::now();
            }
        }
        if !on_epoch(&report) {
            bail!("training cancelled at epoch {epoch}");
        }
    }
    theta.copy_from_slice(&run.best_theta);
    Ok(TrainingReport {
        seed: cfg.seed,
        epochs_requested: cfg.epochs,
        epochs_run: run.epoch,
        best_epoch: run.best_epoch,
        train_loss: run.best_train,
        validation_loss: run.best,
        stopped_early: run.stopped_early,
        seconds: run.seconds,
        batch: cfg.batch,
        lr: cfg.lr,
        patience: cfg.patience,
        noise: cfg.noise,
        points: cfg.points,
        lr_drops: cfg.lr_drops.clone(),
        time_budget: cfg.time_budget,
        out_of_time: run.out_of_time,
        resumed_at,
        trivial_loss: None,
        explained: None,
    })
}

/// Takes up a checkpoint (already checked against the run's key) for a run
/// whose training samples are `train_order`: the parameters, Adam and the
/// RNG as it left them, and its progress.
fn resume(
    c: Checkpoint,
    path: &std::path::Path,
    train_order: &[usize],
    theta: &mut [f64],
    rng: &mut ChaCha8Rng,
    adam: &mut Adam,
    lr: f64,
) -> Result<Progress> {
    let (mut have, mut want) = (c.progress.train_order.clone(), train_order.to_vec());
    have.sort_unstable();
    want.sort_unstable();
    if have != want {
        bail!(
            "checkpoint {} holds another training split; remove it to train afresh",
            path.display()
        );
    }
    *rng = c.rng(path)?;
    *adam = Adam::resume(lr, c.adam_step, c.adam_m, c.adam_v);
    theta.copy_from_slice(&c.theta);
    Ok(c.progress)
}

/// The trivial predictor's loss on the samples `idx`: the MSE of predicting
/// zero acceleration, i.e. the targets' mean square (every entry weighs the
/// same, as in the training loss).
pub fn trivial_loss(acc: &[Vec<f64>], idx: &[usize]) -> f64 {
    trivial_loss_free(acc, idx, |_| true)
}

/// [`trivial_loss`] over the coordinates `free(f)` keeps (the free
/// particles', as the GNODE family's loss).
pub fn trivial_loss_free(acc: &[Vec<f64>], idx: &[usize], free: impl Fn(usize) -> bool) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for &i in idx {
        for (f, a) in acc[i].iter().enumerate() {
            if free(f) {
                sum += a * a;
                count += 1;
            }
        }
    }
    if count == 0 {
        0.0
    } else {
        sum / count as f64
    }
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
    if cfg.normalize && cfg.init.is_none() && net.hyper.norm.is_none() {
        let s: Vec<&State> = sp.train.iter().map(|&i| &states[i]).collect();
        let a: Vec<&[f64]> = sp.train.iter().map(|&i| acc[i].as_slice()).collect();
        net.set_norm(Some(crate::model::Norm::from_data(graph, &s, &a)));
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

/// Which engine computes the GNODE family's gradients.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EngineKind {
    /// Hand-written reverse mode on the kernel's layout, over all cores (default).
    Native,
    /// Candle's autodiff: the reference.
    Candle,
}

/// Whether MCGNODE learns a body-force branch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BodyForce {
    /// On unless the bag says the system is closed (no field, no anchors).
    Auto,
    /// Always learn body forces.
    On,
    /// Never: internal forces only, momentum conserved exactly.
    Off,
}

/// Architecture choices on top of a variant's paper defaults.
#[derive(Clone, Debug)]
pub struct ModelOptions {
    /// Hidden units of the graph MLPs.
    pub hidden: usize,
    /// Embedding width.
    pub embed: usize,
    /// Message-passing rounds.
    pub rounds: usize,
    /// Body-force branch (MCGNODE).
    pub body_force: BodyForce,
    /// One-hot width; default: largest type in the data + 1.
    pub types: Option<usize>,
    /// The ParticleState topic to train on, when a bag holds several.
    pub topic: Option<String>,
    /// Architecture preset (the authors' code by default).
    pub arch: ArchPreset,
    /// Hidden layers per graph MLP, overriding the preset.
    pub hidden_layers: Option<usize>,
    /// Message functions, overriding the preset.
    pub message: Option<MessageFn>,
    /// Edge-update input, overriding the preset.
    pub edge_input: Option<EdgeInput>,
    /// Per-block hidden sizes (block weight prefix → sizes).
    pub block_hidden: std::collections::BTreeMap<String, Vec<usize>>,
    /// Edges read their rest length and stiffness.
    pub edge_physics: bool,
    /// The interaction radius to train with, overriding the bags' (none:
    /// theirs).
    pub radius: Option<f64>,
    /// With [`Recipe::Auto`], the blocks that embed and decode edges get the
    /// recipe's widths ([`recipe::edge_blocks`]) unless `block_hidden` names
    /// them; [`Recipe::Paper`] (the default here) adds nothing.
    pub recipe: Recipe,
}

impl Default for ModelOptions {
    fn default() -> Self {
        Self {
            hidden: 5,
            embed: 5,
            rounds: 1,
            body_force: BodyForce::Auto,
            types: None,
            topic: None,
            arch: ArchPreset::Authors,
            hidden_layers: None,
            message: None,
            edge_input: None,
            block_hidden: Default::default(),
            edge_physics: false,
            radius: None,
            recipe: Recipe::Paper,
        }
    }
}

impl ModelOptions {
    /// The hyperparameters these options give a variant on a `dim`-D graph of
    /// `particles` particles with `types` types (body force left on).
    pub fn hyper(
        &self,
        variant: Variant,
        dim: usize,
        types: usize,
        particles: usize,
    ) -> Result<Hyper> {
        let mut h = Hyper::new(variant, dim, types, particles).with_preset(self.arch);
        h.hidden = self.hidden;
        h.embed = self.embed;
        h.rounds = self.rounds;
        h.hidden_layers = self.hidden_layers.unwrap_or(h.hidden_layers);
        h.message = self.message.unwrap_or(h.message);
        h.edge_input = self.edge_input.unwrap_or(h.edge_input);
        h.block_hidden = self.block_hidden.clone();
        if self.recipe == Recipe::Auto {
            for (block, sizes) in recipe::edge_blocks(variant) {
                h.block_hidden.entry(block.to_string()).or_insert(sizes);
            }
        }
        h.edge_physics = self.edge_physics;
        let known: Vec<String> = crate::model::Arch::new(&h)
            .mlps
            .iter()
            .map(|(b, _)| b.prefix())
            .collect();
        if let Some(bad) = h.block_hidden.keys().find(|k| !known.contains(k)) {
            bail!(
                "--block-hidden names block {bad:?}, which a {variant} model does not have (it has: {})",
                known.join(", ")
            );
        }
        if h.hidden == 0 || h.embed == 0 {
            bail!("--hidden and --embed must be positive");
        }
        Ok(h)
    }
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
    if graph.has_contacts() || graph.n_kinematic() > 0 {
        log(&format!(
            "contacts within radius {} (found at every state); {} kinematic particles, left out of the loss",
            graph.interaction_radius,
            graph.n_kinematic()
        ));
    }
    Ok(())
}

/// Trains a model from trajectory bags and returns the model file (not yet saved).
pub(crate) fn train_from_bags(
    variant: crate::model::Variant,
    bags: &[std::path::PathBuf],
    opts: &ModelOptions,
    cfg: &TrainConfig,
    mut log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<crate::model::ModelFile> {
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
    let types = opts.types.unwrap_or(
        ds.graph
            .types
            .iter()
            .map(|&t| t as usize + 1)
            .max()
            .unwrap_or(1),
    );
    let mut hyper = opts.hyper(variant, ds.graph.dim, types, ds.graph.n())?;
    hyper.interaction_radius = ds.graph.interaction_radius;
    hyper.body_force = match opts.body_force {
        BodyForce::On => true,
        BodyForce::Off => false,
        BodyForce::Auto => match &data.closed {
            Some((closed, _)) => !closed,
            // A warm start keeps its model's branch (below).
            None if variant == crate::model::Variant::Mcgnode && cfg.init.is_none() => bail!(
                "the training bags do not say whether the system is closed (their messages \
                 leave the field unknown, there is no system_config metadata, and the data do \
                 not show a closed system): pass --body-force off for a closed system \
                 (momentum conserved exactly) or --body-force on"
            ),
            None => true,
        },
    };
    if let Some(init) = &cfg.init {
        // A warm start keeps the architecture it was trained with.
        let h = &init.hyper;
        if h.variant != variant {
            bail!("--init model is a {} model, not {variant}", h.variant);
        }
        if h.dim != ds.graph.dim || ds.graph.types.iter().any(|&t| t as usize >= h.types) {
            bail!(
                "--init model is {}D with {} particle types; the data are {}D with types up to {}",
                h.dim,
                h.types,
                ds.graph.dim,
                types - 1
            );
        }
        if !variant.biases().graph && h.particles != ds.graph.n() {
            bail!(
                "--init NODE model was built for {} particles, the data have {}",
                h.particles,
                ds.graph.n()
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
        hyper = h.clone();
    }
    if variant == crate::model::Variant::Mcgnode {
        let why = match (&opts.body_force, &data.closed) {
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
    let trained = train(hyper, &ds.graph, &ds.states, &ds.acc, cfg, on_epoch)?;
    Ok(crate::model::ModelFile {
        format: crate::model::file::FORMAT.to_string(),
        crate_version: env!("CARGO_PKG_VERSION").to_string(),
        hyper: trained.net.hyper.clone(),
        trained_on: data.trained_on,
        training: trained.report,
        weights: trained.net.store.weights()?,
        optimizer: Some(trained.optimizer),
    })
}
