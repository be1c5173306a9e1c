//! The training loop every trainable model shares ([`fit`]): checks on the
//! data, the seeded split, epochs of Adam steps with validation and early
//! stopping, checkpoints, and the trivial predictor's loss.

use super::adam::Adam;
use super::checkpoint::{self, Checkpoint, Progress, RngState, RunKey};
use super::config::TrainConfig;
use super::objective::Objective;
use crate::error::{bail, Result};
use crate::gnode::file::TrainingReport;
use crate::system::{Graph, State};
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

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
    check_fit_settings(theta, cfg, adam)?;
    let (mut run, resumed_at, key) =
        start_run(theta, train_idx, val_idx, cfg, rng, objective, adam)?;
    let mut grad = vec![0.0; theta.len()];
    let start = Instant::now();
    let mut last_save = Instant::now();
    let before = run.seconds;
    let first = run.epoch + 1;
    for epoch in first..=cfg.epochs {
        if run.stopped_early || run.out_of_time {
            break;
        }
        let train_loss = train_epoch(theta, &mut run, epoch, cfg, rng, objective, adam, &mut grad)?;
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
                save_checkpoint(&ck.path, key, &run, theta, adam, rng)?;
                last_save = Instant::now();
            }
        }
        if !on_epoch(&report) {
            bail!("training cancelled at epoch {epoch}");
        }
    }
    theta.copy_from_slice(&run.best_theta);
    Ok(fit_report(cfg, &run, resumed_at))
}

/// Refuses settings [`fit`] cannot run with: an optimiser state of another
/// size than the parameters, a time budget or checkpoint interval that is
/// not a number of seconds.
fn check_fit_settings(theta: &[f64], cfg: &TrainConfig, adam: &Adam) -> Result<()> {
    let (_, m, _) = adam.state();
    if m.len() != theta.len() {
        bail!(
            "optimiser state has {} entries, the model {}",
            m.len(),
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
    Ok(())
}

/// The run's starting progress: fresh, or taken up from the checkpoint when
/// [`TrainConfig::checkpoint`] names one that exists for this run. Also the
/// epoch it was resumed at, and the run's key when it checkpoints.
fn start_run(
    theta: &mut [f64],
    train_idx: Vec<usize>,
    val_idx: &[usize],
    cfg: &TrainConfig,
    rng: &mut ChaCha8Rng,
    objective: &mut dyn Objective,
    adam: &mut Adam,
) -> Result<(Progress, Option<usize>, Option<RunKey>)> {
    let mut run = Progress::fresh(theta, train_idx);
    let Some(ck) = &cfg.checkpoint else {
        return Ok((run, None, None));
    };
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
    let mut resumed_at = None;
    if let Some(c) = Checkpoint::load_for(&ck.path, &key)? {
        run = resume(c, &ck.path, &run.train_order, theta, rng, adam, cfg.lr)?;
        resumed_at = Some(run.epoch);
    }
    Ok((run, resumed_at, Some(key)))
}

/// One epoch's Adam steps over shuffled batches of the training samples, at
/// the epoch's learning rate; returns the mean training loss.
#[allow(clippy::too_many_arguments)]
fn train_epoch(
    theta: &mut [f64],
    run: &mut Progress,
    epoch: usize,
    cfg: &TrainConfig,
    rng: &mut ChaCha8Rng,
    objective: &mut dyn Objective,
    adam: &mut Adam,
    grad: &mut [f64],
) -> Result<f64> {
    adam.set_lr(cfg.lr_at(epoch));
    run.train_order.shuffle(rng);
    let (mut sum, mut count) = (0.0, 0usize);
    for chunk in run.train_order.chunks(cfg.batch) {
        let lv = objective.loss_grad(theta, chunk, grad)?;
        if !lv.is_finite() {
            bail!("training diverged at epoch {epoch} (loss {lv})");
        }
        adam.step(theta, grad);
        sum += lv * chunk.len() as f64;
        count += chunk.len();
    }
    Ok(sum / count as f64)
}

/// Saves the run's state to `path`: its progress, parameters, Adam and RNG.
fn save_checkpoint(
    path: &std::path::Path,
    key: &RunKey,
    run: &Progress,
    theta: &[f64],
    adam: &Adam,
    rng: &ChaCha8Rng,
) -> Result<()> {
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
    c.save(path)?;
    Ok(())
}

/// The figures of a finished run for the model file.
fn fit_report(cfg: &TrainConfig, run: &Progress, resumed_at: Option<usize>) -> TrainingReport {
    TrainingReport {
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
    }
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
