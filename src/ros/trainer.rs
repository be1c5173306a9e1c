//! What every training shares: the [`Trainer`] (the handles training needs:
//! model, recorder, diagnostics, clock; the swap publisher and the model
//! folder), the one-at-a-time [`claim`], and why a training was refused or
//! failed ([`TrainingError`]).
//!
//! Models go to [`model_dir`]: `<record_dir>/models` when the node records,
//! else `<temp dir>/mcgnode-models`.
//!
//! The Train action ([`super::action`]) and services build on a [`Trainer`],
//! and the node wires them, so none of them imports the node.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

use ros2_client::log::LogLevel;
use ros2_client::{Node, Publisher, Server};

use crate::gnode::Variant;

use super::clock::Clock;
use super::handles::{Diagnostics, ModelHandle, RecorderHandle};
use super::params::NodeParams;
use super::qos::{publisher, reliable_qos, server};
use super::resource_names::Names;
use super::topics::{LOAD_MODEL_SERVICE, MODEL_SWAP_TOPIC, TRAIN_SERVICE};
use super::wire::{
    LoadModel, LoadModelRequest, LoadModelResponse, ModelSwap, Train, TrainRequest, TrainResponse,
};

/// Training state and the handles it needs, shared by the Train and
/// LoadModel services and the Train action.
pub struct Trainer {
    /// The model to replace.
    pub(super) model: Arc<ModelHandle>,
    /// The recordings trained on when a request names no bags.
    pub(super) recorder: Arc<RecorderHandle>,
    /// The log.
    pub(super) diag: Arc<Diagnostics>,
    /// Stamps swap announcements.
    pub(super) clock: Arc<Clock>,
    /// Set while a training runs (service or action).
    pub(super) busy: AtomicBool,
    /// Announces swaps.
    pub(super) swap: Publisher<ModelSwap>,
    /// Where trained models are written.
    pub(super) model_dir: PathBuf,
    /// Numbers model files written by this process.
    pub(super) seq: AtomicU64,
}

/// The Train and LoadModel servers, for [`super::service::serve`] with
/// [`super::training_services::train_call`] and
/// [`super::training_services::load_call`].
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
        source: crate::gnode::file::ModelFileError,
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

/// File name of the `seq`-th model trained by this process.
pub fn model_file_name(variant: Variant, unix_secs: u64, pid: u32, seq: u64) -> String {
    format!("{variant}-{unix_secs}-{pid}-{seq}.json")
}

#[cfg(test)]
mod tests {
    use super::*;

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
