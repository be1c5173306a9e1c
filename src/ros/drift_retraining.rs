//! Retraining on a drift alarm (with `accuracy_retrain`): a warm start of
//! the served model on what is recorded next, swapped in only if it beats
//! the old model on a held-out recording.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use ros2_client::log::LogLevel;

use crate::dynamics::Dynamics;
use crate::gnode::ModelFile;
use crate::kernel::TrainedModel;
use crate::models::{train_from_bags, ModelKind};

use super::model_swap::{save_and_load, swap};
use super::params::NodeParams;
use super::trainer::{claim, Trainer, TrainingError};
use super::training::{node_settings, served_file};

/// Retrains after a drift alarm (`why`), blocking: warm-starts the served
/// model file (`train --init` semantics,
/// [`TrainConfig::init`](crate::train::TrainConfig::init)) on the bags
/// recorded during the `accuracy_retrain_after` seconds after the alarm,
/// holding the last of them out, and swaps the new model in only if its
/// replayed RE on that held-out bag (as the node predicts:
/// [`crate::replay::replay_as_node`]) is below the old model's. Returns
/// what was decided, or why nothing was tried; either way it is logged.
pub fn retrain_on_drift(
    trainer: &Arc<Trainer>,
    p: &NodeParams,
    why: &str,
) -> Result<String, TrainingError> {
    const SOURCE: &str = "drift retraining";
    let result = retrain(trainer, p, why);
    match &result {
        Ok(m) => trainer.log(LogLevel::Info, &format!("{SOURCE}: {m}")),
        // A retraining (or a requested training) already runs: expected
        // while the alarm flickers, not worth a warning.
        Err(e @ TrainingError::Busy) => trainer.log(LogLevel::Info, &format!("{SOURCE}: {e}")),
        Err(e) => trainer.log(LogLevel::Warn, &format!("{SOURCE}: {e}")),
    }
    result
}

fn retrain(trainer: &Arc<Trainer>, p: &NodeParams, why: &str) -> Result<String, TrainingError> {
    let Some(_claim) = claim(trainer) else {
        return Err(TrainingError::Busy);
    };
    let (init_path, init) = served_file(trainer)?;
    let recent = record_after_alarm(trainer, p, why, &init_path)?;
    let Some((held_out, train)) = recent.split_last().filter(|(_, t)| !t.is_empty()) else {
        return Err(TrainingError::TooFewBags {
            recorded: recent.len(),
            after: p.accuracy_retrain_after,
        });
    };
    let variant = init.hyper.variant;
    let explained_old = init.explained_by_all();
    let file = warm_start(init, p, train)?;
    let held = held_out.display().to_string();
    let (re_old, re_new) = held_out_re(trainer, p, &held, &file)?;
    let explained_new = file.explained_by_all();
    let percent =
        |f: Option<f64>| f.map_or("unknown".to_string(), |f| format!("{:.2} %", 100.0 * f));
    let weakest = if file.members.is_empty() {
        ""
    } else {
        " (its weakest member)"
    };
    let figures = format!(
        "held-out RE (mean over lead times, {held}) {re_new:.3e} for the retrained model \
         against {re_old:.3e} for the served one; explains{weakest} {} of its validation targets \
         against {} for the served one; trained on {} bag(s) for {} epochs",
        percent(explained_new),
        percent(explained_old),
        train.len(),
        file.training.epochs_run
    );
    // A model that explains less of its targets than the served one did of
    // its own is not swapped in, even when it happened to replay better.
    let explains_less = matches!((explained_old, explained_new), (Some(o), Some(n)) if n < o);
    if re_new.is_finite() && re_new < re_old && !explains_less {
        let (path, model) = save_and_load(trainer, file, variant)?;
        let reason = format!("{}: {figures}", "drift retraining");
        swap(trainer, model, Some(path.clone()), &reason);
        Ok(format!("swapped in {}: {figures}", path.display()))
    } else {
        Ok(format!("kept the served model: {figures}"))
    }
}

/// The bags recorded during the `accuracy_retrain_after` seconds after the
/// alarm (`why`), blocking: the bag open at the alarm is closed first, so
/// they hold only what the system did after the drift was seen.
fn record_after_alarm(
    trainer: &Trainer,
    p: &NodeParams,
    why: &str,
    init_path: &Path,
) -> Result<Vec<PathBuf>, TrainingError> {
    let before = match trainer.recorder.finish() {
        None => return Err(TrainingError::NoRecording),
        Some(r) => r?.1.len(),
    };
    trainer.log(
        LogLevel::Info,
        &format!(
            "drift retraining after \"{why}\": recording {} s, then warm-starting {} for {} epochs",
            p.accuracy_retrain_after,
            init_path.display(),
            p.accuracy_retrain_epochs
        ),
    );
    std::thread::sleep(Duration::from_secs_f64(p.accuracy_retrain_after));
    let bags = match trainer.recorder.finish() {
        Some(r) => r?.1,
        None => Vec::new(),
    };
    Ok(bags.get(before..).unwrap_or_default().to_vec())
}

/// Trains from `init` (`train --init` semantics,
/// [`TrainConfig::init`](crate::train::TrainConfig::init)) on `train` for
/// `accuracy_retrain_epochs` epochs, with the node's settings
/// ([`node_settings`]).
fn warm_start(
    init: ModelFile,
    p: &NodeParams,
    train: &[PathBuf],
) -> Result<ModelFile, TrainingError> {
    let variant = init.hyper.variant;
    let (opts, mut cfg) = node_settings(p.accuracy_retrain_epochs as usize);
    cfg.init = Some(Box::new(init));
    train_from_bags(
        ModelKind::Family(variant),
        train,
        &opts,
        &cfg,
        |_| {},
        |_| true,
    )
    .map_err(TrainingError::Train)?
    .into_family()
    .ok_or_else(|| {
        TrainingError::Train(crate::error::Error::msg(format!(
            "{variant} did not train a GNODE-family file"
        )))
    })
}

/// The replayed RE (as the node predicts) on the held-out bag `held` of the
/// served model and of the retrained `file`, in that order.
fn held_out_re(
    trainer: &Trainer,
    p: &NodeParams,
    held: &str,
    file: &ModelFile,
) -> Result<(f64, f64), TrainingError> {
    let score = |m: &dyn Dynamics| {
        crate::replay::replay_as_node(m, held, p.timing())
            .map(|(r, _)| r.averages.re)
            .map_err(|source| TrainingError::Replay {
                bag: held.to_string(),
                source,
            })
    };
    let old = trainer.model.get();
    let candidate = TrainedModel::from_file(file.clone()).map_err(TrainingError::Load)?;
    Ok((score(old.as_ref())?, score(&candidate)?))
}
