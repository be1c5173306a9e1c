//! Checkpoints of a training run: everything [`fit`](mod@super::fit) needs to go on
//! exactly where it stopped (parameters, Adam's moments, the shuffling RNG and
//! the order it left, the best weights so far, the seconds spent), written
//! atomically every few minutes. A run of hours survives a stop or a crash
//! and, resumed, ends bit for bit where an uninterrupted run would.

use crate::gnode::file::{write_json_atomic, ModelFileError};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Format tag of a checkpoint file.
pub const FORMAT: &str = "mcgnode-checkpoint-1";

/// Where and how often [`fit`](mod@super::fit) saves its state.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpointing {
    /// The checkpoint file (JSON). When it exists, training resumes from it.
    pub path: PathBuf,
    /// Seconds between saves; the last epoch is always saved.
    pub every: f64,
}

impl Checkpointing {
    /// Seconds between saves unless told (`--checkpoint-every`): a minute,
    /// short against the hours a run worth resuming takes, long against a
    /// save's milliseconds.
    pub const EVERY: f64 = 60.0;
}

/// Why a checkpoint could not be used.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// The file exists but cannot be read.
    #[error("cannot read checkpoint {}: {source}", path.display())]
    Read {
        /// The checkpoint.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The file is not a checkpoint of this format.
    #[error("{} is not an mcgnode checkpoint ({FORMAT}): {why}; remove it to train afresh", path.display())]
    Parse {
        /// The checkpoint.
        path: PathBuf,
        /// Cause.
        why: String,
    },
    /// The checkpoint belongs to another training run.
    #[error(
        "checkpoint {} is of another training run ({what}: {found} there, {expected} in this one); \
         remove it to train afresh, or give this run another checkpoint path",
        path.display()
    )]
    Mismatch {
        /// The checkpoint.
        path: PathBuf,
        /// What differs.
        what: &'static str,
        /// The checkpoint's value.
        found: String,
        /// This run's value.
        expected: String,
    },
    /// Saving failed.
    #[error(transparent)]
    Write(#[from] ModelFileError),
}

crate::error::typed_errors!(CheckpointError);

/// What identifies a training run: a checkpoint resumes only the run it
/// came from. The epochs asked for are not part of it, so a finished run can
/// be extended.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunKey {
    /// Trainable parameters.
    pub parameters: usize,
    /// Training samples.
    pub train: usize,
    /// Validation samples.
    pub validation: usize,
    /// Seed of initialisation, split and shuffling.
    pub seed: u64,
    /// Batch size.
    pub batch: usize,
    /// Adam's learning rate.
    pub lr: f64,
    /// Learning-rate steps.
    pub lr_drops: Vec<(usize, f64)>,
    /// Early-stopping patience.
    pub patience: usize,
    /// Wall-clock budget, seconds.
    pub time_budget: Option<f64>,
    /// Validation loss of the initial parameters: a digest of the data, the
    /// architecture, its normalisation and its initialisation at once.
    pub initial_loss: f64,
}

impl RunKey {
    /// The first field in which `found` (a checkpoint's) differs from
    /// `self`: its name, the checkpoint's value and this run's.
    fn first_difference(&self, found: &RunKey) -> Option<(&'static str, String, String)> {
        use serde_json::{to_value, Value};
        let (Ok(Value::Object(want)), Ok(Value::Object(have))) = (to_value(self), to_value(found))
        else {
            return Some(("key", String::new(), String::new()));
        };
        // The digest last: a plainer difference explains it.
        let mut fields: Vec<_> = want.iter().collect();
        fields.sort_by_key(|(name, _)| *name == "initial_loss");
        fields.into_iter().find_map(|(name, w)| {
            let h = have.get(name).unwrap_or(&Value::Null);
            let same = match (name.as_str(), w.as_f64(), h.as_f64()) {
                // A sum in another order, or seconds printed and parsed, may differ in
                // the last bits.
                ("initial_loss" | "time_budget", Some(a), Some(b)) => {
                    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
                }
                _ => w == h,
            };
            (!same).then(|| (Self::describe(name), h.to_string(), w.to_string()))
        })
    }

    /// A field's name in messages.
    fn describe(field: &str) -> &'static str {
        match field {
            "parameters" => "parameters",
            "train" => "training samples",
            "validation" => "validation samples",
            "seed" => "seed",
            "batch" => "batch",
            "lr" => "learning rate",
            "lr_drops" => "learning-rate steps",
            "patience" => "patience",
            "time_budget" => "time budget",
            "initial_loss" => "initial validation loss (data, architecture or initialisation)",
            _ => "settings",
        }
    }
}

/// The shuffling RNG's position.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RngState {
    /// Seed, 32 bytes.
    pub seed: Vec<u8>,
    /// Stream.
    pub stream: u64,
    /// Word position (a u128, as a decimal string: JSON numbers stop at 2^64).
    pub word_pos: String,
}

impl RngState {
    /// The state of `rng`.
    pub fn of(rng: &ChaCha8Rng) -> Self {
        Self {
            seed: rng.get_seed().to_vec(),
            stream: rng.get_stream(),
            word_pos: rng.get_word_pos().to_string(),
        }
    }

    /// The RNG at this state.
    fn restore(&self, path: &Path) -> Result<ChaCha8Rng, CheckpointError> {
        use rand::SeedableRng;
        let bad = |why: &str| CheckpointError::Parse {
            path: path.to_path_buf(),
            why: why.to_string(),
        };
        let seed: [u8; 32] = self
            .seed
            .as_slice()
            .try_into()
            .map_err(|_| bad("the RNG seed is not 32 bytes"))?;
        let pos: u128 = self
            .word_pos
            .parse()
            .map_err(|_| bad("the RNG position is not a number"))?;
        let mut rng = ChaCha8Rng::from_seed(seed);
        rng.set_stream(self.stream);
        rng.set_word_pos(pos);
        Ok(rng)
    }
}

/// How far a training run has come: what [`fit`](mod@super::fit) carries from epoch
/// to epoch besides the parameters, Adam and the RNG.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// Last epoch completed.
    pub epoch: usize,
    /// Training seconds to the end of that epoch, over every session.
    pub seconds: f64,
    /// Training samples in the order the last shuffle left them (each
    /// epoch shuffles this order again).
    pub train_order: Vec<usize>,
    /// Lowest validation loss so far.
    pub best: f64,
    /// Its epoch.
    pub best_epoch: usize,
    /// Training loss of that epoch.
    pub best_train: f64,
    /// Parameters of that epoch.
    pub best_theta: Vec<f64>,
    /// Early stopping has ended the run.
    pub stopped_early: bool,
    /// The time budget has ended the run.
    pub out_of_time: bool,
}

impl Progress {
    /// A run about to start from `theta`, its samples in `train_order`.
    pub fn fresh(theta: &[f64], train_order: Vec<usize>) -> Self {
        Self {
            epoch: 0,
            seconds: 0.0,
            train_order,
            best: f64::INFINITY,
            best_epoch: 0,
            best_train: f64::NAN,
            best_theta: theta.to_vec(),
            stopped_early: false,
            out_of_time: false,
        }
    }
}

/// The state of a training run after an epoch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Always [`FORMAT`].
    pub format: String,
    /// The run it belongs to.
    pub key: RunKey,
    /// How far it has come.
    #[serde(flatten)]
    pub progress: Progress,
    /// Parameters after that epoch.
    pub theta: Vec<f64>,
    /// Adam's step count.
    pub adam_step: i32,
    /// Adam's first moments.
    pub adam_m: Vec<f64>,
    /// Adam's second moments.
    pub adam_v: Vec<f64>,
    /// The shuffling RNG.
    pub rng: RngState,
}

impl Checkpoint {
    /// The checkpoint at `path` if there is one, checked against `key`.
    pub fn load_for(path: &Path, key: &RunKey) -> Result<Option<Self>, CheckpointError> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(CheckpointError::Read {
                    path: path.to_path_buf(),
                    source,
                })
            }
        };
        let parse = |why: String| CheckpointError::Parse {
            path: path.to_path_buf(),
            why,
        };
        let c: Checkpoint = serde_json::from_str(&text).map_err(|e| parse(e.to_string()))?;
        if c.format != FORMAT {
            return Err(parse(format!("format {:?}", c.format)));
        }
        if let Some((what, found, expected)) = key.first_difference(&c.key) {
            return Err(CheckpointError::Mismatch {
                path: path.to_path_buf(),
                what,
                found,
                expected,
            });
        }
        let n = key.parameters;
        if [&c.theta, &c.adam_m, &c.adam_v, &c.progress.best_theta]
            .iter()
            .any(|v| v.len() != n)
            || c.progress.train_order.len() != key.train
        {
            return Err(parse("its vectors do not have the run's sizes".into()));
        }
        Ok(Some(c))
    }

    /// The shuffling RNG as it was.
    pub fn rng(&self, path: &Path) -> Result<ChaCha8Rng, CheckpointError> {
        self.rng.restore(path)
    }

    /// Writes the checkpoint atomically.
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        Ok(write_json_atomic(path, self)?)
    }
}
