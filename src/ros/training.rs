//! The training job, shared by the Train service
//! ([`super::training_services`]) and the Train action ([`super::action`]):
//! a request checked, the bags chosen, the model trained (or fine-tuned),
//! then saved and swapped in ([`super::model_swap`]).
//!
//! Training runs on a thread of its own (tokio's blocking pool) while the node
//! keeps predicting with the old model. Only when training succeeds is the new
//! model saved and swapped in. A failed, refused or cancelled training leaves
//! the old model in place and says why (response and log). One training at a
//! time: a second request, by service or action, is refused at once
//! ([`super::trainer::claim`]).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use ros2_client::log::LogLevel;

use crate::gnode::{ModelFile, Variant};
use crate::models::{train_from_bags, ModelKind};
use crate::train::{EpochReport, ModelOptions, Recipe, TrainConfig};

use super::model_swap::{save_and_load, swap};
use super::trainer::{Trainer, TrainingError};
use super::wire::{TrainRequest, TrainResponse};

/// Variant trained when a request leaves it empty.
pub const DEFAULT_VARIANT: Variant = Variant::Mcgnode;

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
    progress: impl FnMut(&EpochReport),
    source: &str,
) -> TrainResponse {
    let start = Instant::now();
    let job = Job { shared, source };
    let what = match prepare(&job, req) {
        Ok(x) => x,
        Err(failed) => return failed,
    };
    let variant = what.variant;
    let file = match train(&job, req, what, cancel, progress) {
        Ok(f) => f,
        Err(failed) => return failed,
    };
    // A cancel after the last epoch still wins: nothing is swapped.
    if cancel.load(Ordering::Acquire) {
        return job.fail("training cancelled after its last epoch".into());
    }
    swap_in(&job, file, variant, start)
}

/// One training and who asked for it (`source`, named in its messages).
struct Job<'a> {
    shared: &'a Trainer,
    source: &'a str,
}

impl Job<'_> {
    /// Logs `msg` under the caller's name.
    fn log(&self, level: LogLevel, msg: &str) {
        self.shared.log(level, &format!("{}: {msg}", self.source));
    }

    /// The answer of a training that did not happen or failed, logged: the
    /// old model stays.
    fn fail(&self, why: String) -> TrainResponse {
        let message = format!(
            "{why}; still serving {}",
            self.shared.model.get().describe()
        );
        self.log(LogLevel::Warn, &message);
        TrainResponse {
            success: false,
            message,
            ..TrainResponse::default()
        }
    }
}

/// What a request trains.
struct Prepared {
    variant: Variant,
    /// The served file a fine-tuning starts from.
    init: Option<Box<ModelFile>>,
    bags: Vec<PathBuf>,
}

/// What a request trains, checked; `Err`: the failed answer.
fn prepare(job: &Job, req: &TrainRequest) -> Result<Prepared, TrainResponse> {
    let variant = match check_request(req) {
        Ok(v) => v,
        Err(e) => return Err(job.fail(format!("bad request: {e}"))),
    };
    let (variant, init) = if req.fine_tune {
        match fine_tune_start(job.shared, &req.variant) {
            Ok((v, f, path)) => {
                job.log(
                    LogLevel::Info,
                    &format!("fine-tuning the served model {}", path.display()),
                );
                (v, Some(Box::new(f)))
            }
            Err(e @ (TrainingError::NotAFile(_) | TrainingError::ReadServed { .. })) => {
                return Err(job.fail(format!(
                    "cannot fine-tune: {e} (load one with LoadModel, or train without fine_tune)"
                )))
            }
            Err(e) => return Err(job.fail(format!("cannot fine-tune: {e}"))),
        }
    } else {
        (variant, None)
    };
    let bags = match training_bags(job.shared, &req.bags) {
        Ok(b) => b,
        Err(e @ (TrainingError::NoRecording | TrainingError::NothingRecorded(_))) => {
            return Err(job.fail(format!("no bags given and {e}")))
        }
        Err(e) => return Err(job.fail(e.to_string())),
    };
    Ok(Prepared {
        variant,
        init,
        bags,
    })
}

/// Trains `variant` (from `init` when fine-tuning) on `bags` with the
/// default recipe and the request's epochs and seed, reporting each epoch to
/// `progress` and every tenth to the log; `Err`: the failed answer.
fn train(
    job: &Job,
    req: &TrainRequest,
    Prepared {
        variant,
        init,
        bags,
    }: Prepared,
    cancel: &AtomicBool,
    mut progress: impl FnMut(&EpochReport),
) -> Result<ModelFile, TrainResponse> {
    job.log(
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
    let (opts, mut cfg) = node_settings(req.epochs as usize);
    cfg.seed = req.seed;
    cfg.init = init;
    let every = (cfg.epochs / 10).max(1);
    let trained = train_from_bags(
        ModelKind::Family(variant),
        &bags,
        &opts,
        &cfg,
        |m| job.log(LogLevel::Info, m),
        |r| {
            progress(r);
            if r.epoch % every == 0 || r.epoch == r.epochs {
                job.log(
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
    match trained.map(crate::models::TrainedFile::into_family) {
        Ok(Some(f)) => Ok(f),
        Ok(None) => Err(job.fail(format!("{variant} did not train a GNODE-family file"))),
        Err(e) => Err(job.fail(TrainingError::Train(e).to_string())),
    }
}

/// Saves the trained `file`, swaps it in, and answers with its figures and
/// timings (`start`: when the request came).
fn swap_in(job: &Job, file: ModelFile, variant: Variant, start: Instant) -> TrainResponse {
    // From here to the swap is what a caller waits on top of training.
    let trained_at = Instant::now();
    let (train_loss, validation_loss) = (file.training.train_loss, file.training.validation_loss);
    let epochs_run = file.training.epochs_run;
    let explained = file.training.explained.unwrap_or(f64::NAN);
    let learned = file.training.explained_line();
    if let Some(w) = file.training.explained_warning() {
        job.log(LogLevel::Warn, &w);
    }
    let (path, model) = match save_and_load(job.shared, file, variant) {
        Ok(x) => x,
        Err(e) => return job.fail(e.to_string()),
    };
    let took = trained_at.duration_since(start).as_secs_f64();
    let path_s = path.display().to_string();
    let source = job.source;
    let locked = swap(
        job.shared,
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
pub(super) fn served_file(shared: &Trainer) -> Result<(PathBuf, ModelFile), TrainingError> {
    let Some(path) = shared.model.file() else {
        return Err(TrainingError::NotAFile(shared.model.get().describe()));
    };
    let file = ModelFile::load(&path).map_err(|source| TrainingError::ReadServed {
        path: path.clone(),
        source,
    })?;
    Ok((path, file))
}

/// What the node trains with (Train requests and drift retraining):
/// `mcgnode train`'s defaults, the default recipe, with the epochs given.
pub(super) fn node_settings(epochs: usize) -> (ModelOptions, TrainConfig) {
    let mut cfg = TrainConfig::for_recipe(Recipe::default());
    cfg.set_epochs(epochs);
    (ModelOptions::default(), cfg)
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
}
