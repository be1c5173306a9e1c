//! Training a model of any kind from bags: the one training entry point, which
//! the CLI, `reproduce` and the ROS node share.

use super::ModelKind;
use crate::baselines::BaselineFile;
use crate::error::{Context, Result};
use crate::gnode::file::{ModelFile, TrainingReport};
use crate::train::{EpochReport, ModelOptions, TrainConfig};
use std::path::{Path, PathBuf};

/// A trained model's file, of either kind, not yet saved.
#[derive(Clone, Debug)]
pub enum TrainedFile {
    /// The GNODE family.
    Family(ModelFile),
    /// A baseline (LGN, HGN, GNS, ...).
    Baseline(BaselineFile),
}

impl TrainedFile {
    /// Its training figures.
    pub fn training(&self) -> &TrainingReport {
        match self {
            Self::Family(f) => &f.training,
            Self::Baseline(f) => &f.training,
        }
    }

    /// Writes it to `out`.
    pub fn save(&self, out: &Path) -> Result<()> {
        let saving = || format!("saving {}", out.display());
        match self {
            Self::Family(f) => f.save(out).with_context(saving),
            Self::Baseline(f) => f.save(out).with_context(saving),
        }
    }

    /// The GNODE-family file, if it is one.
    pub fn into_family(self) -> Option<ModelFile> {
        match self {
            Self::Family(f) => Some(f),
            Self::Baseline(_) => None,
        }
    }
}

/// Trains any model from bags (the GNODE family with `opts`; baselines use
/// their paper architecture, and `opts.topic` only) and returns its file.
pub fn train_from_bags(
    kind: ModelKind,
    bags: &[PathBuf],
    opts: &ModelOptions,
    cfg: &TrainConfig,
    log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<TrainedFile> {
    Ok(match kind {
        ModelKind::Family(v) => TrainedFile::Family(crate::train::train_from_bags(
            v, bags, opts, cfg, log, on_epoch,
        )?),
        ModelKind::Baseline(k) => {
            TrainedFile::Baseline(crate::baselines::train_baseline_from_bags(
                k,
                bags,
                opts.topic.as_deref(),
                opts.radius,
                cfg,
                log,
                on_epoch,
            )?)
        }
    })
}

/// [`train_from_bags`], then saves the file to `out`; returns its training figures.
pub fn train_any_from_bags(
    kind: ModelKind,
    bags: &[PathBuf],
    opts: &ModelOptions,
    cfg: &TrainConfig,
    log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
    out: &Path,
) -> Result<TrainingReport> {
    let f = train_from_bags(kind, bags, opts, cfg, log, on_epoch)?;
    f.save(out)?;
    Ok(f.training().clone())
}
