//! Retraining and model swaps: the Train and LoadModel services, the swap
//! announcement on `/mcgnode/model_swap`, and the training job shared with the
//! Train action ([`super::action`]).
//!
//! Training runs on a thread of its own (tokio's blocking pool) while the node
//! keeps predicting with the old model. Only when training succeeds is the new
//! model saved (atomically) to the model folder and swapped in under the
//! model's write lock, which in-flight predictions never wait on for long: they
//! clone the `Arc` and predict outside the lock. A failed, refused or cancelled
//! training leaves the old model in place and says why (response and log).
//!
//! The Train service call returns when training has ended (its response holds
//! the model path and losses; epochs bound how long that takes): callers that
//! want progress or cancel use the action. One training at a time: a second
//! request, by service or action, is refused at once.
//!
//! Models go to [`model_dir`]: `<record_dir>/models` when the node records,
//! else `<temp dir>/mcgnode-models`.
//!
//! With `accuracy_retrain`, a drift alarm starts [`retrain_on_drift`]: a
//! warm start of the served model on what is recorded next, swapped in only
//! if it beats the old model on a held-out recording.
//!
//! A [`Trainer`] holds only the handles training needs (model, recorder,
//! diagnostics, clock); the Train action ([`super::action`]) builds on it, and
//! the node wires both, so neither imports the node.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use ros2_client::log::LogLevel;
use ros2_client::{Node, Publisher, Server};

use crate::data::msg::{Header, Time};
use crate::dynamics::Dynamics;
use crate::kernel::TrainedModel;
use crate::model::{ModelFile, Variant};
use crate::models::{train_from_bags, ModelKind, ModelRef};
use crate::train::{Auto, EpochReport, ModelOptions, Recipe, TrainConfig};

use super::clock::Clock;
use super::handles::{Diagnostics, ModelHandle, RecorderHandle};
use super::names::Names;
use super::params::NodeParams;
use super::qos::{publisher, reliable_qos, server};
use super::topics::{LOAD_MODEL_SERVICE, MODEL_SWAP_TOPIC, TRAIN_SERVICE};
use super::wire::{
    LoadModel, LoadModelRequest, LoadModelResponse, ModelSwap, Train, TrainRequest, TrainResponse,
};

/// Variant trained when a request leaves it empty.
pub const DEFAULT_VARIANT: Variant = Variant::Mcgnode;

/// Training state and the handles it needs, shared by the Train and
/// LoadModel services and the Train action.
pub struct Trainer {
    /// The model to replace.
    model: Arc<ModelHandle>,
    /// The recordings trained on when a request names no bags.
    recorder: Arc<RecorderHandle>,
    /// The log.
    diag: Arc<Diagnostics>,
    /// Stamps swap announcements.
    clock: Arc<Clock>,
    /// Set while a training runs (service or action).
    busy: AtomicBool,
    /// Announces swaps.
    swap: Publisher<ModelSwap>,
    /// Where trained models are written.
    model_dir: PathBuf,
    /// Numbers model files written by this process.
    seq: AtomicU64,
}

/// The Train and LoadModel servers, for [`super::service::serve`] with
/// [`train_call`] and [`load_call`].
pub struct TrainingServers {
    /// The Train service.
    pub train: Server<TrainRequest, TrainResponse>,
    /// The LoadModel service.
    pub load: Server<LoadModelRequest, LoadModelResponse>,
}

/// Where trained models go: `<record_dir>/models`, or
/// `<temp dir>/mcgnode-models` when the node does not record.
pub fn model_dir(params: &NodeParams) -> PathBuf {
    if !params.model_dir.is_empty() {
        PathBuf::from(&params.model_dir)
    } else if params.record_dir.is_empty() {
        std::env::temp_dir().join("mcgnode-models")
    } else {
        Path::new(&params.record_dir).join("models")
    }
}

/// The handles a [`Trainer`] works with.
pub struct TrainerHandles {
    /// The model to replace.
    pub model: Arc<ModelHandle>,
    /// The recordings trained on when a request names no bags.
    pub recorder: Arc<RecorderHandle>,
    /// The log.
    pub diag: Arc<Diagnostics>,
    /// Stamps swap announcements.
    pub clock: Arc<Clock>,
}

/// Creates the swap publisher and the Train and LoadModel servers.
pub fn create(
    node: &mut Node,
    params: &NodeParams,
    names: &Names,
    handles: TrainerHandles,
) -> crate::error::Result<(Arc<Trainer>, TrainingServers)> {
    let swap = publisher(node, names, MODEL_SWAP_TOPIC, &reliable_qos())?;
    let train = server::<Train>(node, names, TRAIN_SERVICE)?;
    let load = server::<LoadModel>(node, names, LOAD_MODEL_SERVICE)?;
    let TrainerHandles {
        model,
        recorder,
        diag,
        clock,
    } = handles;
    let trainer = Trainer {
        model,
        recorder,
        diag,
        clock,
        busy: AtomicBool::new(false),
        swap,
        model_dir: model_dir(params),
        seq: AtomicU64::new(0),
    };
    trainer.log(
        LogLevel::Info,
        &format!(
            "services {}, {}; swaps announced on {}; trained models go to {}",
            names.resolve(TRAIN_SERVICE)?,
            names.resolve(LOAD_MODEL_SERVICE)?,
            names.resolve(MODEL_SWAP_TOPIC)?,
            trainer.model_dir.display()
        ),
    );
    Ok((Arc::new(trainer), TrainingServers { train, load }))
}

impl Trainer {
    /// Logs through the node's log.
    pub fn log(&self, level: LogLevel, msg: &str) {
        self.diag.log(level, msg);
    }

    /// The node's diagnostics (for the service loop's failure reports).
    pub fn diagnostics(&self) -> Arc<Diagnostics> {
        self.diag.clone()
    }
}

/// The right to train, held for the training's duration; released on drop.
pub struct Claim(Arc<Trainer>);

impl Drop for Claim {
    fn drop(&mut self) {
        self.0.busy.store(false, Ordering::Release);
    }
}

/// The right to train, or `None` while another training runs.
pub fn claim(trainer: &Arc<Trainer>) -> Option<Claim> {
    trainer
        .busy
        .compare_exchange(false, true, Ordering::AcqRel, Ordering::Acquire)
        .is_ok()
        .then(|| Claim(trainer.clone()))
}

/// Why a training (requested, or after a drift alarm) was refused or failed;
/// the message goes to the caller's reply and the log.
#[derive(Debug, thiserror::Error)]
pub enum TrainingError {
    /// Another training runs.
    #[error("refused: a training is already running (one at a time)")]
    Busy,
    /// The request names no known variant.
    #[error(transparent)]
    Variant(#[from] crate::names::UnknownName),
    /// The request asks for no epochs.
    #[error("epochs must be at least 1")]
    NoEpochs,
    /// A requested bag is not there.
    #[error("bag {0:?} does not exist or is not a file")]
    MissingBag(String),
    /// No bags given and no recording to train on.
    #[error("the node records nothing (set record_dir to train on what it sees)")]
    NoRecording,
    /// No bags given and nothing recorded yet.
    #[error("the node has recorded nothing yet in {}", .0.display())]
    NothingRecorded(PathBuf),
    /// Closing the recording failed.
    #[error(transparent)]
    Record(#[from] super::record::RecordError),
    /// The served model has no file to start from.
    #[error("the served model ({0}) is not a model file")]
    NotAFile(String),
    /// The served model's file does not read back.
    #[error("cannot read the served model {}: {source}", path.display())]
    ReadServed {
        /// Its file.
        path: PathBuf,
        /// Why.
        source: crate::model::file::ModelFileError,
    },
    /// A fine-tuning request names another variant than the served one.
    #[error(
        "the served model is {served}, the request asks for {requested}; leave variant empty to \
         fine-tune it"
    )]
    OtherVariant {
        /// The served model's variant.
        served: Variant,
        /// The request's.
        requested: String,
    },
    /// Training failed.
    #[error("training failed: {0:#}")]
    Train(crate::error::Error),
    /// The trained model does not save.
    #[error("saving the model failed: {0:#}")]
    Save(crate::error::Error),
    /// The trained model does not load back.
    #[error("the trained model does not load: {0:#}")]
    Load(crate::error::Error),
    /// The held-out bag does not replay.
    #[error("replaying the held-out bag {bag} failed: {source:#}")]
    Replay {
        /// The bag.
        bag: String,
        /// Why.
        source: crate::error::Error,
    },
    /// Too few bags recorded after a drift alarm.
    #[error(
        "{recorded} bag(s) recorded in the {after} s after the alarm; need 2 (the last is held \
         out): set record_split_seconds below accuracy_retrain_after"
    )]
    TooFewBags {
        /// Bags recorded.
        recorded: usize,
        /// `accuracy_retrain_after`, seconds.
        after: f64,
    },
}

crate::error::typed_errors!(TrainingError);

/// Why a second training is refused.
pub const BUSY: TrainingError = TrainingError::Busy;

/// Replaces the served model, announces it on the swap topic and in the log;
/// returns how long the write lock was held.
pub fn swap(
    shared: &Trainer,
    model: Arc<dyn Dynamics>,
    file: Option<PathBuf>,
    reason: &str,
) -> Duration {
    let new_model = model.describe();
    let (old, locked) = shared.model.replace(model, file);
    // Bags recorded from now on (and the open one) name the new model.
    shared.recorder.record(|r| r.set_model(&new_model));
    let msg = ModelSwap {
        header: Header {
            stamp: Time::from_nanos(shared.clock.now_ns()),
            frame_id: String::new(),
        },
        old_model: old.describe(),
        new_model: new_model.clone(),
        reason: reason.to_string(),
    };
    let published = shared.swap.publish(msg);
    shared.log(
        LogLevel::Info,
        &format!(
            "model swapped ({:.1} µs under the lock): now serving {new_model} (was {}); {reason}",
            locked.as_secs_f64() * 1e6,
            old.describe()
        ),
    );
    if let Err(e) = published {
        shared.log(
            LogLevel::Warn,
            &format!("announcing the model swap on {MODEL_SWAP_TOPIC} failed: {e:?}"),
        );
    }
    locked
}

/// The variant of a request: empty means [`DEFAULT_VARIANT`].
pub fn request_variant(variant: &str) -> Result<Variant, TrainingError> {
    if variant.trim().is_empty() {
        Ok(DEFAULT_VARIANT)
    } else {
        Ok(variant.trim().parse()?)
    }
}

/// Checks a request's fields before any work: variant, epochs, bag paths.
pub fn check_request(req: &TrainRequest) -> Result<Variant, TrainingError> {
    let variant = request_variant(&req.variant)?;
    if req.epochs == 0 {
        return Err(TrainingError::NoEpochs);
    }
    if let Some(missing) = req.bags.iter().find(|b| !Path::new(b).is_file()) {
        return Err(TrainingError::MissingBag(missing.clone()));
    }
    Ok(variant)
}

/// File name of the `seq`-th model trained by this process.
pub fn model_file_name(variant: Variant, unix_secs: u64, pid: u32, seq: u64) -> String {
    format!("{variant}-{unix_secs}-{pid}-{seq}.json")
}

/// The bags to train on: the request's, or this run's recordings (the open
/// bag is closed first, so its footer is written and it reads back whole).
fn training_bags(shared: &Trainer, bags: &[String]) -> Result<Vec<PathBuf>, TrainingError> {
    if !bags.is_empty() {
        return Ok(bags.iter().map(PathBuf::from).collect());
    }
    let Some(finished) = shared.recorder.finish() else {
        return Err(TrainingError::NoRecording);
    };
    let (dir, finished) = finished?;
    if finished.is_empty() {
        return Err(TrainingError::NothingRecorded(dir));
    }
    Ok(finished)
}

/// Trains as `req` asks (blocking; `source` names the caller in messages),
/// reporting each epoch to `progress`; `cancel` is polled after every epoch.
/// On success the model file is written and swapped in.
pub fn run_training(
    shared: &Trainer,
    req: &TrainRequest,
    cancel: &AtomicBool,
    mut progress: impl FnMut(&EpochReport),
    source: &str,
) -> TrainResponse {
    let start = Instant::now();
    let log = |level, msg: &str| shared.log(level, &format!("{source}: {msg}"));
    let fail = |why: String| {
        let message = format!("{why}; still serving {}", shared.model.get().describe());
        log(LogLevel::Warn, &message);
        TrainResponse {
            success: false,
            message,
            ..TrainResponse::default()
        }
    };
    let variant = match check_request(req) {
        Ok(v) => v,
        Err(e) => return fail(format!("bad request: {e}")),
    };
    let (variant, init) = if req.fine_tune {
        match fine_tune_start(shared, &req.variant) {
            Ok((v, f, path)) => {
                log(
                    LogLevel::Info,
                    &format!("fine-tuning the served model {}", path.display()),
                );
                (v, Some(Box::new(f)))
            }
            Err(e @ (TrainingError::NotAFile(_) | TrainingError::ReadServed { .. })) => {
                return fail(format!(
                    "cannot fine-tune: {e} (load one with LoadModel, or train without fine_tune)"
                ))
            }
            Err(e) => return fail(format!("cannot fine-tune: {e}")),
        }
    } else {
        (variant, None)
    };
    let bags = match training_bags(shared, &req.bags) {
        Ok(b) => b,
        Err(e @ (TrainingError::NoRecording | TrainingError::NothingRecorded(_))) => {
            return fail(format!("no bags given and {e}"))
        }
        Err(e) => return fail(e.to_string()),
    };
    log(
        LogLevel::Info,
        &format!(
            "training {variant} for {} epochs (seed {}) on {} bag(s): {}",
            req.epochs,
            req.seed,
            bags.len(),
            bags.iter()
                .map(|b| b.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    );
    // The default recipe, as `mcgnode train` has it, with the epochs asked for.
    let cfg = TrainConfig {
        epochs: req.epochs as usize,
        seed: req.seed,
        init,
        auto: Auto::GIVEN_EPOCHS,
        ..TrainConfig::default()
    };
    let every = (cfg.epochs / 10).max(1);
    let trained = train_from_bags(
        ModelKind::Family(variant),
        &bags,
        &auto_options(),
        &cfg,
        |m| log(LogLevel::Info, m),
        |r| {
            progress(r);
            if r.epoch % every == 0 || r.epoch == r.epochs {
                log(
                    LogLevel::Info,
                    &format!(
                        "epoch {}/{}: train {:.3e}, validation {:.3e}",
                        r.epoch, r.epochs, r.train_loss, r.validation_loss
                    ),
                );
            }
            !cancel.load(Ordering::Acquire)
        },
    );
    let file = match trained.map(crate::models::TrainedFile::into_family) {
        Ok(Some(f)) => f,
        Ok(None) => return fail(format!("{variant} did not train a GNODE-family file")),
        Err(e) => return fail(TrainingError::Train(e).to_string()),
    };
    // A cancel after the last epoch still wins: nothing is swapped.
    if cancel.load(Ordering::Acquire) {
        return fail("training cancelled after its last epoch".into());
    }
    // From here to the swap is what a caller waits on top of training.
    let trained_at = Instant::now();
    let (train_loss, validation_loss) = (file.training.train_loss, file.training.validation_loss);
    let epochs_run = file.training.epochs_run;
    let explained = file.training.explained.unwrap_or(f64::NAN);
    let learned = file.training.explained_line();
    if let Some(w) = file.training.explained_warning() {
        log(LogLevel::Warn, &w);
    }
    let (path, model) = match save_and_load(shared, file, variant) {
        Ok(x) => x,
        Err(e) => return fail(e.to_string()),
    };
    let took = trained_at.duration_since(start).as_secs_f64();
    let path_s = path.display().to_string();
    let locked = swap(
        shared,
        model,
        Some(path),
        &format!(
            "{source}: {variant} trained for {epochs_run} epochs in {took:.1} s \
             (validation {validation_loss:.3e}; {learned}); model {path_s}"
        ),
    );
    let save_and_swap = trained_at.elapsed().as_secs_f64() * 1e3;
    TrainResponse {
        success: true,
        message: format!(
            "trained {variant} for {epochs_run} epochs in {took:.1} s; {learned}; saved, \
             loaded and swapped in {save_and_swap:.1} ms ({:.1} µs under the lock)",
            locked.as_secs_f64() * 1e6
        ),
        model_path: path_s,
        train_loss,
        validation_loss,
        explained,
    }
}

/// The served model file a fine-tuning starts from, with its variant, which
/// a request's `variant` must match when it names one.
fn fine_tune_start(
    shared: &Trainer,
    requested: &str,
) -> Result<(Variant, ModelFile, PathBuf), TrainingError> {
    let (path, file) = served_file(shared)?;
    let variant = file.hyper.variant;
    if !requested.trim().is_empty() && request_variant(requested)? != variant {
        return Err(TrainingError::OtherVariant {
            served: variant,
            requested: requested.trim().to_string(),
        });
    }
    Ok((variant, file, path))
}

/// The file of the served model, read back: what a warm start begins from.
fn served_file(shared: &Trainer) -> Result<(PathBuf, ModelFile), TrainingError> {
    let Some(path) = shared.model.file() else {
        return Err(TrainingError::NotAFile(shared.model.get().describe()));
    };
    let file = ModelFile::load(&path).map_err(|source| TrainingError::ReadServed {
        path: path.clone(),
        source,
    })?;
    Ok((path, file))
}

/// Saves a trained model (atomically) to the model folder and loads it as
/// the node serves models (checked against what it was trained for).
fn save_and_load(
    shared: &Trainer,
    file: ModelFile,
    variant: Variant,
) -> Result<(PathBuf, Arc<dyn Dynamics>), TrainingError> {
    let seq = shared.seq.fetch_add(1, Ordering::Relaxed);
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let path = shared
        .model_dir
        .join(model_file_name(variant, secs, std::process::id(), seq));
    file.save(&path)
        .map_err(|e| TrainingError::Save(e.into()))?;
    let v = serde_json::to_value(&file).map_err(|e| TrainingError::Save(e.into()))?;
    let trained_for = crate::compat::TrainedFor::from_model_json(&path.display().to_string(), &v);
    let m = TrainedModel::from_file(file).map_err(TrainingError::Load)?;
    Ok((
        path,
        Arc::new(crate::models::Checked::new(Arc::new(m), trained_for)),
    ))
}

/// Retrains after a drift alarm (`why`), blocking: warm-starts the served
/// model file (`train --init` semantics, [`TrainConfig::init`]) on the bags
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
    // Close the bag open at the alarm: the bags after it hold only what the
    // system did after the drift was seen.
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
    let recent = bags.get(before..).unwrap_or_default();
    let Some((held_out, train)) = recent.split_last().filter(|(_, t)| !t.is_empty()) else {
        return Err(TrainingError::TooFewBags {
            recorded: recent.len(),
            after: p.accuracy_retrain_after,
        });
    };
    let variant = init.hyper.variant;
    let explained_old = init.training.explained;
    let cfg = TrainConfig {
        epochs: p.accuracy_retrain_epochs as usize,
        init: Some(Box::new(init)),
        auto: Auto::GIVEN_EPOCHS,
        ..TrainConfig::default()
    };
    let file = train_from_bags(
        ModelKind::Family(variant),
        train,
        &auto_options(),
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
    })?;
    let held = held_out.display().to_string();
    let score = |m: &dyn Dynamics| {
        crate::replay::replay_as_node(m, &held, p.dt, p.substeps, p.horizon)
            .map(|(r, _)| r.averages.re)
            .map_err(|source| TrainingError::Replay {
                bag: held.clone(),
                source,
            })
    };
    let old = trainer.model.get();
    let candidate = TrainedModel::from_file(file.clone()).map_err(TrainingError::Load)?;
    let (re_old, re_new) = (score(old.as_ref())?, score(&candidate)?);
    let explained_new = file.training.explained;
    let percent =
        |f: Option<f64>| f.map_or("unknown".to_string(), |f| format!("{:.2} %", 100.0 * f));
    let figures = format!(
        "held-out RE (mean over lead times, {held}) {re_new:.3e} for the retrained model \
         against {re_old:.3e} for the served one; explains {} of its validation targets \
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

/// The architecture options of `mcgnode train`'s default recipe.
fn auto_options() -> ModelOptions {
    ModelOptions {
        recipe: Recipe::Auto,
        ..ModelOptions::default()
    }
}

/// The Train service's work: refused at once while another training runs,
/// else trains (blocking) and answers when done.
pub fn train_call(shared: &Arc<Trainer>, req: TrainRequest) -> TrainResponse {
    let Some(_claim) = claim(shared) else {
        shared.log(LogLevel::Warn, &format!("Train service: {BUSY}"));
        return TrainResponse {
            success: false,
            message: BUSY.to_string(),
            ..TrainResponse::default()
        };
    };
    run_training(
        shared,
        &req,
        &AtomicBool::new(false),
        |_| {},
        "Train service",
    )
}

/// The LoadModel service's work: [`load_and_swap`] of the request's path.
pub fn load_call(shared: &Arc<Trainer>, req: LoadModelRequest) -> LoadModelResponse {
    load_and_swap(shared, &req.path)
}

/// Loads `path` (a model file or `truth:*`) and swaps it in; a bad file
/// leaves the old model.
pub fn load_and_swap(shared: &Trainer, path: &str) -> LoadModelResponse {
    let fail = |why: String| {
        let message = format!("{why}; still serving {}", shared.model.get().describe());
        shared.log(LogLevel::Warn, &format!("LoadModel: {message}"));
        LoadModelResponse {
            success: false,
            message,
        }
    };
    if path.trim().is_empty() {
        return fail("no path given".into());
    }
    let loaded = path
        .parse::<ModelRef>()
        .map_err(crate::Error::from)
        .and_then(|r| Ok((crate::models::load_model(&r)?, r)));
    match loaded {
        Err(e) => fail(format!("cannot load {path}: {e:#}")),
        Ok((model, reference)) => {
            let description = model.describe();
            let file = reference.file().map(Path::to_path_buf);
            let locked = swap(shared, model, file, &format!("LoadModel: model {path}"));
            LoadModelResponse {
                success: true,
                message: format!(
                    "now serving {description} ({:.1} µs under the lock)",
                    locked.as_secs_f64() * 1e6
                ),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_are_checked_before_any_work() {
        let ok = TrainRequest {
            epochs: 3,
            ..TrainRequest::default()
        };
        assert_eq!(check_request(&ok).unwrap(), DEFAULT_VARIANT);
        let named = TrainRequest {
            variant: "gnode".into(),
            ..ok.clone()
        };
        assert_eq!(check_request(&named).unwrap(), Variant::Gnode);
        let bad_variant = TrainRequest {
            variant: "lstm".into(),
            ..ok.clone()
        };
        assert!(check_request(&bad_variant)
            .unwrap_err()
            .to_string()
            .contains("unknown model"));
        let no_epochs = TrainRequest {
            epochs: 0,
            ..ok.clone()
        };
        assert!(check_request(&no_epochs)
            .unwrap_err()
            .to_string()
            .contains("epochs"));
        let missing = TrainRequest {
            bags: vec!["/nonexistent/x.mcap".into()],
            ..ok
        };
        let e = check_request(&missing).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/x.mcap"), "{e}");
    }

    #[test]
    fn model_dir_follows_record_dir() {
        let p = NodeParams {
            record_dir: "/data/rec".into(),
            ..NodeParams::default()
        };
        assert_eq!(model_dir(&p), Path::new("/data/rec/models"));
        let q = NodeParams::default();
        assert!(model_dir(&q).starts_with(std::env::temp_dir()));
        assert_ne!(
            model_file_name(Variant::Mcgnode, 5, 7, 0),
            model_file_name(Variant::Mcgnode, 5, 7, 1)
        );
    }
}
