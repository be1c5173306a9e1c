//! The model file: human-readable metadata plus weights, JSON, written atomically.

use super::params::Weights;
use super::variant::Hyper;
use crate::system::{EdgeKind, Graph};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Why a model file (or another JSON file written atomically) could not be
/// read or written.
#[derive(Debug, thiserror::Error)]
pub enum ModelFileError {
    /// The file cannot be read.
    #[error("cannot read model file {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not the JSON of a model file.
    #[error("{} is not a valid mcgnode model file: {source}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// Where and why.
        source: serde_json::Error,
    },
    /// A model file of another format version.
    #[error("{}: unsupported model format {found:?} (expected {FORMAT})", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// Its format tag.
        found: String,
    },
    /// Writing failed at step `what`.
    #[error("writing {}: {what}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The step (creating the folder, the temporary file, syncing, renaming).
        what: &'static str,
        /// Why.
        source: std::io::Error,
    },
    /// The value does not encode as JSON.
    #[error("writing {}: encoding JSON: {source}", path.display())]
    Encode {
        /// The file.
        path: PathBuf,
        /// Why.
        source: serde_json::Error,
    },
}

crate::error::typed_errors!(ModelFileError);

/// Format tag written in every model file.
pub const FORMAT: &str = "mcgnode-model/1";

/// What the model was trained on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainedOn {
    /// System name from the bag ("spring", "pendulum", or "").
    pub system: String,
    /// Particle count of the training graph.
    pub particles: usize,
    /// Spatial dimension.
    pub dim: usize,
    /// Bag path as given.
    pub bag: String,
    /// SHA-256 of the training bag.
    pub bag_sha256: String,
    /// Where the target accelerations came from ("recorded" or "finite-difference").
    pub accelerations: String,
    /// Trajectories and states used.
    pub trajectories: usize,
    /// States used (train + validation).
    pub states: usize,
    /// Fingerprints of each training trajectory's first state, so that an
    /// evaluation can refuse a test set that starts where training did.
    pub start_fingerprints: Vec<String>,
    /// The bag's system metadata (JSON), if it had any.
    pub system_config: Option<serde_json::Value>,
    /// The distinct kinds of particle edge of the training graph (absent in
    /// files written before it existed): a model without edge-physics inputs
    /// refuses graphs whose edges differ from these.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub edge_params: Vec<EdgeParams>,
}

/// One kind of edge: what it is, its rest length and stiffness.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EdgeParams {
    /// Spring or bar.
    pub kind: EdgeKind,
    /// Rest length (a bar's length).
    pub rest_length: f64,
    /// Stiffness (0 for bars).
    pub stiffness: f64,
}

impl EdgeParams {
    /// Whether two kinds are the same (lengths and stiffnesses to 1e-9 relative).
    pub fn same(&self, o: &EdgeParams) -> bool {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-300);
        self.kind == o.kind
            && close(self.rest_length, o.rest_length)
            && (close(self.stiffness, o.stiffness) || self.kind == EdgeKind::Bar)
    }

    /// The distinct kinds of a graph's particle edges (edges to anchors are
    /// not seen by the network), in first-seen order.
    pub fn of(graph: &Graph) -> Vec<EdgeParams> {
        let mut out: Vec<EdgeParams> = vec![];
        for (_, _, e) in graph.particle_edges() {
            let p = EdgeParams {
                kind: e.kind,
                rest_length: e.rest_length,
                stiffness: if e.kind == EdgeKind::Bar {
                    0.0
                } else {
                    e.stiffness
                },
            };
            if !out.iter().any(|x| x.same(&p)) {
                out.push(p);
            }
        }
        out
    }
}

/// How training went.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingReport {
    /// RNG seed (initialisation, split, shuffling).
    pub seed: u64,
    /// Epochs asked for.
    pub epochs_requested: usize,
    /// Epochs run.
    pub epochs_run: usize,
    /// Epoch whose weights were kept (lowest validation loss).
    pub best_epoch: usize,
    /// Training loss (MSE on accelerations) at the best epoch.
    pub train_loss: f64,
    /// Validation loss at the best epoch.
    pub validation_loss: f64,
    /// Whether early stopping ended training.
    pub stopped_early: bool,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Batch size.
    pub batch: usize,
    /// Adam learning rate.
    pub lr: f64,
    /// Early-stopping patience, epochs.
    pub patience: usize,
    /// Gaussian noise added to the target accelerations, percent of their
    /// standard deviation (0 in files written before this field existed).
    #[serde(default)]
    pub noise: f64,
    /// Training pairs kept by subsampling; `None`: all of them (and in files
    /// written before this field existed).
    #[serde(default)]
    pub points: Option<usize>,
    /// Learning-rate steps (after epoch, rate), if the schedule had any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lr_drops: Vec<(usize, f64)>,
    /// Wall-clock budget in seconds, if training had one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_budget: Option<f64>,
    /// Whether the time budget ended training.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub out_of_time: bool,
    /// The epoch of the checkpoint training resumed from, if it did (the
    /// seconds then count every session).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resumed_at: Option<usize>,
    /// The trivial predictor's validation loss, in the loss's units: zero
    /// acceleration (for HGN zero q̇ and ṗ), i.e. the validation targets'
    /// mean square. `None` in files written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trivial_loss: Option<f64>,
    /// How much of the targets the model explains: 1 − validation_loss /
    /// trivial_loss (1 is perfect, 0 no better than predicting nothing, < 0
    /// worse). `None` in files written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub explained: Option<f64>,
}

/// Below this explained fraction `train` warns that the model learned little
/// (measured: models under it rolled out no better than a few times standing
/// still; see the README's "Defaults that learn").
pub const EXPLAINED_WARN: f64 = 0.99;

impl TrainingReport {
    /// Records the trivial predictor's validation loss and the fraction
    /// explained against it (left `None` when the targets are all zero).
    pub fn with_trivial(mut self, trivial_loss: f64) -> Self {
        self.trivial_loss = Some(trivial_loss);
        self.explained = (trivial_loss > 0.0).then(|| 1.0 - self.validation_loss / trivial_loss);
        self
    }

    /// One line: the fraction explained with both losses, or that it is unknown.
    pub fn explained_line(&self) -> String {
        match (self.explained, self.trivial_loss) {
            (Some(f), Some(t)) => format!(
                "explains {:.2} % of the validation targets' mean square (validation MSE \
                 {:.3e} against {t:.3e} for predicting zero acceleration)",
                100.0 * f,
                self.validation_loss
            ),
            _ => "explained fraction unknown (file written before it was recorded, or all \
                  targets zero)"
                .to_string(),
        }
    }

    /// A warning with what to try when the model explains less than
    /// [`EXPLAINED_WARN`], else `None`.
    pub fn explained_warning(&self) -> Option<String> {
        let f = self.explained?;
        (f < EXPLAINED_WARN).then(|| {
            format!(
                "warning: the model explains only {:.2} % of the targets (below {} %): its \
                 rollouts may be no better than predicting that nothing moves. Try more \
                 epochs (--epochs), the default recipe if another was used (--recipe \
                 auto), wider edge MLPs (--block-hidden edge_em=32,32 --block-hidden \
                 edge_out=32,32), or more trajectories; compare with `mcgnode evaluate \
                 --model still`",
                100.0 * f,
                100.0 * EXPLAINED_WARN
            )
        })
    }
}

/// A trained model on disk.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Always `FORMAT`.
    pub format: String,
    /// Version of mcgnode that wrote it.
    pub crate_version: String,
    /// Architecture.
    pub hyper: Hyper,
    /// Training data.
    pub trained_on: TrainedOn,
    /// Training outcome.
    pub training: TrainingReport,
    /// Parameters.
    pub weights: Weights,
    /// Adam's state at the end of training, so that `train --init` can
    /// continue where it stopped (absent in files written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub optimizer: Option<AdamState>,
    /// The other members of an ensemble (`train --ensemble K`: K − 1 of
    /// them; this file's own weights are the first member). Absent in
    /// single-model files, which load unchanged.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub members: Vec<Member>,
}

/// One more member of an ensemble: the same architecture and data, trained
/// from another seed (initialisation, split and data order).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Member {
    /// How its training went (its seed among them).
    pub training: TrainingReport,
    /// Its parameters.
    pub weights: Weights,
}

impl ModelFile {
    /// The members of the ensemble this file holds, each as a single-model
    /// file (one for a single model).
    pub fn member_files(&self) -> Vec<ModelFile> {
        let first = ModelFile {
            members: vec![],
            ..self.clone()
        };
        let mut out = vec![first.clone()];
        for m in &self.members {
            out.push(ModelFile {
                training: m.training.clone(),
                weights: m.weights.clone(),
                optimizer: None,
                ..first.clone()
            });
        }
        out
    }

    /// How much of its validation targets the weakest member explains
    /// (the model's own figure for a single model); unknown if any
    /// member's is. An ensemble is judged by every member, not its first.
    pub fn explained_by_all(&self) -> Option<f64> {
        std::iter::once(&self.training)
            .chain(self.members.iter().map(|m| &m.training))
            .map(|t| t.explained)
            .try_fold(f64::INFINITY, |least, e| e.map(|e| least.min(e)))
    }
}

/// Adam's moments (named like the weights) and step count.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdamState {
    /// Updates taken.
    pub step: i32,
    /// First moments.
    pub m: Weights,
    /// Second moments.
    pub v: Weights,
}

impl ModelFile {
    /// Writes the file atomically (temporary file in the same folder, then rename).
    pub fn save(&self, path: &Path) -> Result<(), ModelFileError> {
        write_json_atomic(path, self)
    }

    /// Reads and checks a model file.
    pub fn load(path: &Path) -> Result<Self, ModelFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| ModelFileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let m: ModelFile = serde_json::from_str(&text).map_err(|source| ModelFileError::Parse {
            path: path.to_path_buf(),
            source,
        })?;
        if m.format != FORMAT {
            return Err(ModelFileError::Format {
                path: path.to_path_buf(),
                found: m.format,
            });
        }
        Ok(m)
    }
}

/// Writes `value` as pretty JSON to `path` atomically: a temporary file in the
/// same folder, synced, made 0644 (tempfile creates 0600; model files are
/// ordinary shareable files), then renamed over `path`.
pub fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), ModelFileError> {
    use std::io::Write;
    let at = |what: &'static str| {
        move |source| ModelFileError::Write {
            path: path.to_path_buf(),
            what,
            source,
        }
    };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir).map_err(at("creating its folder"))?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(at("creating a temporary file"))?;
    serde_json::to_writer_pretty(&mut tmp, value).map_err(|source| ModelFileError::Encode {
        path: path.to_path_buf(),
        source,
    })?;
    tmp.write_all(b"\n").map_err(at("writing"))?;
    tmp.as_file().sync_all().map_err(at("syncing"))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))
            .map_err(at("setting permissions"))?;
    }
    tmp.persist(path)
        .map_err(|e| at("renaming into place")(e.error))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::gnode::Variant;
    use crate::physics::{SystemConfig, SystemKind};

    /// The weakest member's figure, the single model's own, unknown if any
    /// member's is.
    #[test]
    fn an_ensemble_explains_what_its_weakest_member_does() {
        let g = SystemConfig::new(SystemKind::HeldChain, 3).graph();
        let model = |seed| crate::testing::random_model(Variant::Mcgnode, &g, seed);
        let mut file = model(1).expect("model").1.file;
        assert_eq!(file.explained_by_all(), None);
        file.training.explained = Some(0.99);
        assert_eq!(file.explained_by_all(), Some(0.99));
        let mut other = model(2).expect("model").1.file;
        other.training.explained = Some(0.9);
        file.members.push(super::Member {
            training: other.training.clone(),
            weights: other.weights.clone(),
        });
        assert_eq!(file.explained_by_all(), Some(0.9));
        file.members[0].training.explained = None;
        assert_eq!(file.explained_by_all(), None);
    }
}
