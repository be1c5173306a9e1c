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

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, PoisonError};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::anyhow;
use ros2_client::log::LogLevel;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{
    MessageTypeName, Name, Node, Publisher, QosProfile, Server, ServiceMapping, ServiceTypeName,
};

use crate::data::msg::{Header, Time};
use crate::dynamics::Dynamics;
use crate::kernel::TrainedModel;
use crate::model::Variant;
use crate::train::{train_from_bags, EpochReport, ModelOptions, TrainConfig};

use super::msgs::{
    LoadModelRequest, LoadModelResponse, ModelSwap, TrainRequest, TrainResponse, PACKAGE,
};
use super::node::Shared;
use super::params::NodeParams;

/// Name of the Train service.
pub const TRAIN_SERVICE: &str = "/mcgnode/train";
/// Name of the LoadModel service.
pub const LOAD_MODEL_SERVICE: &str = "/mcgnode/load_model";
/// Topic announcing every model swap (`mcgnode_msgs/msg/ModelSwap`).
pub const MODEL_SWAP_TOPIC: &str = "/mcgnode/model_swap";
/// Variant trained when a request leaves it empty.
pub const DEFAULT_VARIANT: Variant = Variant::Mcgnode;

/// Training state shared by the node's tasks.
pub struct Training {
    /// Set while a training runs (service or action).
    busy: AtomicBool,
    /// Announces swaps.
    swap: Publisher<ModelSwap>,
    /// Where trained models are written.
    model_dir: PathBuf,
    /// Numbers model files written by this process.
    seq: AtomicU64,
}

/// The Train and LoadModel servers, handed to [`spawn`].
pub struct TrainingEndpoints {
    train: Server<TrainRequest, TrainResponse>,
    load: Server<LoadModelRequest, LoadModelResponse>,
    action: super::action::TrainActionServer,
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

/// Reliable, volatile, keep-last 10: what rclpy's defaults match.
pub(super) fn reliable_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

fn name(s: &str) -> anyhow::Result<Name> {
    Name::parse(s).map_err(|e| anyhow!("invalid ROS name {s:?}: {e:?}"))
}

/// Creates the swap publisher, the Train and LoadModel servers and the Train
/// action server.
pub(super) fn create(
    node: &mut Node,
    params: &NodeParams,
) -> anyhow::Result<(Training, TrainingEndpoints)> {
    let qos = reliable_qos();
    let topic = node
        .create_topic(
            &name(MODEL_SWAP_TOPIC)?,
            MessageTypeName::new(PACKAGE, "ModelSwap"),
            &qos,
        )
        .map_err(|e| anyhow!("creating topic {MODEL_SWAP_TOPIC}: {e:?}"))?;
    let swap = node
        .create_publisher(&topic, Some(qos.clone()))
        .map_err(|e| anyhow!("creating the model swap publisher: {e:?}"))?;
    let train = node
        .create_server(
            ServiceMapping::Enhanced,
            &name(TRAIN_SERVICE)?,
            &ServiceTypeName::new(PACKAGE, "Train"),
            qos.clone(),
            qos.clone(),
        )
        .map_err(|e| anyhow!("creating the Train service: {e:?}"))?;
    let load = node
        .create_server(
            ServiceMapping::Enhanced,
            &name(LOAD_MODEL_SERVICE)?,
            &ServiceTypeName::new(PACKAGE, "LoadModel"),
            qos.clone(),
            qos,
        )
        .map_err(|e| anyhow!("creating the LoadModel service: {e:?}"))?;
    let action = super::action::create(node)?;
    let training = Training {
        busy: AtomicBool::new(false),
        swap,
        model_dir: model_dir(params),
        seq: AtomicU64::new(0),
    };
    Ok((
        training,
        TrainingEndpoints {
            train,
            load,
            action,
        },
    ))
}

/// Starts the Train, LoadModel and Train-action tasks (inside the runtime).
pub(super) fn spawn(shared: Arc<Shared>, endpoints: TrainingEndpoints) {
    shared.log.log(
        LogLevel::Info,
        &format!(
            "services {TRAIN_SERVICE}, {LOAD_MODEL_SERVICE}; action {}; swaps announced on \
             {MODEL_SWAP_TOPIC}; trained models go to {}",
            super::action::TRAIN_ACTION,
            shared.training.model_dir.display()
        ),
    );
    let quiet = super::service::OnFailure::Quiet;
    tokio::spawn(super::service::serve(
        shared.clone(),
        endpoints.train,
        "Train",
        quiet,
        train_call,
    ));
    tokio::spawn(super::service::serve(
        shared.clone(),
        endpoints.load,
        "LoadModel",
        quiet,
        |shared, req: LoadModelRequest| load_and_swap(shared, &req.path),
    ));
    super::action::spawn(shared, endpoints.action);
}

/// The right to train, held for the training's duration; released on drop.
pub struct Claim(Arc<Shared>);

impl Drop for Claim {
    fn drop(&mut self) {
        self.0.training.busy.store(false, Ordering::Release);
    }
}

/// The right to train, or `None` while another training runs.
pub(super) fn claim(shared: &Arc<Shared>) -> Option<Claim> {
    shared
        .training
        .busy
        .compare_exchange(false, true, Ordering::AcqRel, Ordering::Acquire)
        .is_ok()
        .then(|| Claim(shared.clone()))
}

/// Why a second training is refused.
pub const BUSY: &str = "refused: a training is already running (one at a time)";

/// Replaces the served model, announces it on the swap topic and in the log;
/// returns how long the write lock was held.
pub(super) fn swap(shared: &Shared, model: Arc<dyn Dynamics>, reason: &str) -> Duration {
    let new_model = model.describe();
    let start = Instant::now();
    let old = std::mem::replace(
        &mut *shared.model.write().unwrap_or_else(PoisonError::into_inner),
        model,
    );
    let locked = start.elapsed();
    // Bags recorded from now on (and the open one) name the new model.
    shared.record(|r| r.set_model(&new_model));
    let msg = ModelSwap {
        header: Header {
            stamp: Time::from_nanos(shared.clock.now_ns()),
            frame_id: String::new(),
        },
        old_model: old.describe(),
        new_model: new_model.clone(),
        reason: reason.to_string(),
    };
    let published = shared.training.swap.publish(msg);
    shared.log.log(
        LogLevel::Info,
        &format!(
            "model swapped ({:.1} µs under the lock): now serving {new_model} (was {}); {reason}",
            locked.as_secs_f64() * 1e6,
            old.describe()
        ),
    );
    if let Err(e) = published {
        shared.log.log(
            LogLevel::Warn,
            &format!("announcing the model swap on {MODEL_SWAP_TOPIC} failed: {e:?}"),
        );
    }
    locked
}

/// The variant of a request: empty means [`DEFAULT_VARIANT`].
pub fn request_variant(variant: &str) -> Result<Variant, String> {
    if variant.trim().is_empty() {
        Ok(DEFAULT_VARIANT)
    } else {
        variant
            .trim()
            .parse()
            .map_err(|e: crate::names::UnknownName| e.to_string())
    }
}

/// Checks a request's fields before any work: variant, epochs, bag paths.
pub fn check_request(req: &TrainRequest) -> Result<Variant, String> {
    let variant = request_variant(&req.variant)?;
    if req.epochs == 0 {
        return Err("epochs must be at least 1".into());
    }
    if let Some(missing) = req.bags.iter().find(|b| !Path::new(b).is_file()) {
        return Err(format!("bag {missing:?} does not exist or is not a file"));
    }
    Ok(variant)
}

/// File name of the `seq`-th model trained by this process.
pub fn model_file_name(variant: Variant, unix_secs: u64, pid: u32, seq: u64) -> String {
    format!("{variant}-{unix_secs}-{pid}-{seq}.json")
}

/// The bags to train on: the request's, or this run's recordings (the open
/// bag is closed first, so its footer is written and it reads back whole).
fn training_bags(shared: &Shared, bags: &[String]) -> Result<Vec<PathBuf>, String> {
    if !bags.is_empty() {
        return Ok(bags.iter().map(PathBuf::from).collect());
    }
    let Some(recorder) = &shared.recorder else {
        return Err(
            "no bags given and the node records nothing (set record_dir to train on what it sees)"
                .into(),
        );
    };
    let mut r = recorder.lock().unwrap_or_else(PoisonError::into_inner);
    r.finish()?;
    if r.finished.is_empty() {
        return Err(format!(
            "no bags given and the node has recorded nothing yet in {}",
            r.dir().display()
        ));
    }
    Ok(r.finished.clone())
}

/// Trains as `req` asks (blocking; `source` names the caller in messages),
/// reporting each epoch to `progress`; `cancel` is polled after every epoch.
/// On success the model file is written and swapped in.
pub(super) fn run_training(
    shared: &Shared,
    req: &TrainRequest,
    cancel: &AtomicBool,
    mut progress: impl FnMut(&EpochReport),
    source: &str,
) -> TrainResponse {
    let start = Instant::now();
    let log = |level, msg: &str| shared.log.log(level, &format!("{source}: {msg}"));
    let fail = |why: String| {
        let message = format!("{why}; still serving {}", shared.model().describe());
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
    let bags = match training_bags(shared, &req.bags) {
        Ok(b) => b,
        Err(e) => return fail(e),
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
    let cfg = TrainConfig {
        epochs: req.epochs as usize,
        seed: req.seed,
        ..TrainConfig::default()
    };
    let every = (cfg.epochs / 10).max(1);
    let trained = train_from_bags(
        variant,
        &bags,
        &ModelOptions::default(),
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
    let file = match trained {
        Ok(f) => f,
        Err(e) => return fail(format!("training failed: {e:#}")),
    };
    // A cancel after the last epoch still wins: nothing is swapped.
    if cancel.load(Ordering::Acquire) {
        return fail("training cancelled after its last epoch".into());
    }
    // From here to the swap is what a caller waits on top of training.
    let trained_at = Instant::now();
    let seq = shared.training.seq.fetch_add(1, Ordering::Relaxed);
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let path =
        shared
            .training
            .model_dir
            .join(model_file_name(variant, secs, std::process::id(), seq));
    if let Err(e) = file.save(&path) {
        return fail(format!("saving the model failed: {e:#}"));
    }
    let (train_loss, validation_loss) = (file.training.train_loss, file.training.validation_loss);
    let epochs_run = file.training.epochs_run;
    let trained_for = match serde_json::to_value(&file) {
        Ok(v) => crate::compat::TrainedFor::from_model_json(&path.display().to_string(), &v),
        Err(e) => return fail(format!("the trained model does not serialise: {e}")),
    };
    let model: Arc<dyn crate::dynamics::Dynamics> = match TrainedModel::from_file(file) {
        Ok(m) => Arc::new(crate::models::Checked::new(Arc::new(m), trained_for)),
        Err(e) => return fail(format!("the trained model does not load: {e:#}")),
    };
    let took = trained_at.duration_since(start).as_secs_f64();
    let path_s = path.display().to_string();
    let locked = swap(
        shared,
        model,
        &format!(
            "{source}: {variant} trained for {epochs_run} epochs in {took:.1} s \
             (validation {validation_loss:.3e}); model {path_s}"
        ),
    );
    let save_and_swap = trained_at.elapsed().as_secs_f64() * 1e3;
    TrainResponse {
        success: true,
        message: format!(
            "trained {variant} for {epochs_run} epochs in {took:.1} s; saved, loaded and \
             swapped in {save_and_swap:.1} ms ({:.1} µs under the lock)",
            locked.as_secs_f64() * 1e6
        ),
        model_path: path_s,
        train_loss,
        validation_loss,
    }
}

/// The Train service's work: refused at once while another training runs,
/// else trains (blocking) and answers when done.
fn train_call(shared: &Arc<Shared>, req: TrainRequest) -> TrainResponse {
    let Some(_claim) = claim(shared) else {
        shared
            .log
            .log(LogLevel::Warn, &format!("Train service: {BUSY}"));
        return TrainResponse {
            success: false,
            message: BUSY.into(),
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

/// Loads `path` (a model file or `truth:*`) and swaps it in; a bad file
/// leaves the old model.
pub(super) fn load_and_swap(shared: &Shared, path: &str) -> LoadModelResponse {
    let fail = |why: String| {
        let message = format!("{why}; still serving {}", shared.model().describe());
        shared
            .log
            .log(LogLevel::Warn, &format!("LoadModel: {message}"));
        LoadModelResponse {
            success: false,
            message,
        }
    };
    if path.trim().is_empty() {
        return fail("no path given".into());
    }
    match crate::models::load_model(path) {
        Err(e) => fail(format!("cannot load {path}: {e:#}")),
        Ok(model) => {
            let description = model.describe();
            let locked = swap(shared, model, &format!("LoadModel: model {path}"));
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
        assert_eq!(check_request(&ok), Ok(DEFAULT_VARIANT));
        let named = TrainRequest {
            variant: "gnode".into(),
            ..ok.clone()
        };
        assert_eq!(check_request(&named), Ok(Variant::Gnode));
        let bad_variant = TrainRequest {
            variant: "lstm".into(),
            ..ok.clone()
        };
        assert!(check_request(&bad_variant)
            .unwrap_err()
            .contains("unknown model"));
        let no_epochs = TrainRequest {
            epochs: 0,
            ..ok.clone()
        };
        assert!(check_request(&no_epochs).unwrap_err().contains("epochs"));
        let missing = TrainRequest {
            bags: vec!["/nonexistent/x.mcap".into()],
            ..ok
        };
        let e = check_request(&missing).unwrap_err();
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
