//! Model swaps: a new model replaces the served one under the model's write
//! lock, which in-flight predictions never wait on for long (they clone the
//! `Arc` and predict outside the lock), and is announced on
//! `/mcgnode/model_swap` and in the log. A trained model is first saved
//! (atomically) to the model folder and loaded back as the node serves
//! models; a file that does not load leaves the old model in place.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use ros2_client::log::LogLevel;

use crate::data::msg::{Header, Time};
use crate::dynamics::Dynamics;
use crate::gnode::{ModelFile, Variant};
use crate::kernel::TrainedModel;
use crate::models::ModelRef;

use super::topics::MODEL_SWAP_TOPIC;
use super::trainer::{model_file_name, Trainer, TrainingError};
use super::wire::{LoadModelResponse, ModelSwap};

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

/// Saves a trained model (atomically) to the model folder and loads it as
/// the node serves models (checked against what it was trained for).
pub(super) fn save_and_load(
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
