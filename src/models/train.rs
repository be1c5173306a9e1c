//! Training a model of any kind from bags: the one training entry point, which
//! the CLI, `reproduce` and the ROS node share.

use super::ModelKind;
use crate::baselines::BaselineFile;
use crate::error::{Context, Result};
use crate::gnode::file::{Member, ModelFile, TrainingReport};
use crate::train::{EpochReport, ModelOptions, TrainConfig};
use std::path::{Path, PathBuf};

/// A trained model's file, of either kind, not yet saved.
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)] // one per training, moved rarely
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
/// From an ensemble (`cfg.init` with members) it trains an ensemble of as
/// many members, each warm-started from its own weights.
pub fn train_from_bags(
    kind: ModelKind,
    bags: &[PathBuf],
    opts: &ModelOptions,
    cfg: &TrainConfig,
    log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<TrainedFile> {
    // An ensemble's members each warm-start from their own weights.
    if let Some(members) = init_members(cfg) {
        let cfg = TrainConfig {
            ensemble: members,
            ..cfg.clone()
        };
        return train_ensemble_from_bags(kind, bags, opts, &cfg, log, on_epoch);
    }
    train_one(kind, bags, opts, cfg, log, on_epoch)
}

/// [`train_from_bags`] of one model (`cfg.init`, if any, a single model).
fn train_one(
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

/// The members of `cfg.init` when it is an ensemble (at least 2).
fn init_members(cfg: &TrainConfig) -> Option<usize> {
    cfg.init
        .as_ref()
        .filter(|f| !f.members.is_empty())
        .map(|f| f.members.len() + 1)
}

/// [`train_from_bags`] (or, with `cfg.ensemble` above 1,
/// [`train_ensemble_from_bags`]), then saves the file to `out`; returns its
/// training figures.
pub fn train_any_from_bags(
    kind: ModelKind,
    bags: &[PathBuf],
    opts: &ModelOptions,
    cfg: &TrainConfig,
    log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
    out: &Path,
) -> Result<TrainingReport> {
    let f = if cfg.ensemble > 1 {
        train_ensemble_from_bags(kind, bags, opts, cfg, log, on_epoch)?
    } else {
        train_from_bags(kind, bags, opts, cfg, log, on_epoch)?
    };
    f.save(out)?;
    Ok(f.training().clone())
}

/// An ensemble of `cfg.ensemble` GNODE-family members trained as [`train_from_bags`]
/// would train one, member `i` with seed `cfg.seed + i` (initialisation,
/// split and data order), one after another, into one file: the first
/// member's, with the others in [`ModelFile::members`]. Its training report
/// is the first member's, with the seconds of all of them.
pub fn train_ensemble_from_bags(
    kind: ModelKind,
    bags: &[PathBuf],
    opts: &ModelOptions,
    cfg: &TrainConfig,
    mut log: impl FnMut(&str),
    mut on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<TrainedFile> {
    let k = cfg.ensemble;
    if !matches!(kind, ModelKind::Family(_)) {
        crate::error::bail!(
            "--ensemble is for the GNODE family (node, gnode, cgnode, cdgnode, mcgnode); \
             train {} without it",
            kind.name()
        );
    }
    if cfg.checkpoint.is_some() && k > 1 {
        crate::error::bail!("--checkpoint saves one run: drop it or train with --ensemble 1");
    }
    let inits = cfg.init.as_ref().map(|f| f.member_files());
    if let Some(m) = init_members(cfg).filter(|&m| m != k.max(1)) {
        crate::error::bail!(
            "the --init model is an ensemble of {m} members, each warm-started from its own \
             weights: train with --ensemble {m} (or without --ensemble)"
        );
    }
    let mut first: Option<ModelFile> = None;
    let mut seconds = 0.0;
    for i in 0..k.max(1) {
        let member_cfg = TrainConfig {
            seed: cfg.seed.wrapping_add(i as u64),
            // Member i of an ensemble --init from member i (a single model
            // --init starts every member from its weights).
            init: inits
                .as_ref()
                .map(|f| Box::new(f[i.min(f.len() - 1)].clone())),
            ..cfg.clone()
        };
        log(&format!(
            "ensemble member {} of {k} (seed {})",
            i + 1,
            member_cfg.seed
        ));
        let f = train_one(kind, bags, opts, &member_cfg, &mut log, &mut on_epoch)?
            .into_family()
            .ok_or_else(|| crate::error::err!("an ensemble member is not of the GNODE family"))?;
        seconds += f.training.seconds;
        match first.as_mut() {
            None => first = Some(f),
            Some(m) => m.members.push(Member {
                training: f.training,
                weights: f.weights,
            }),
        }
    }
    let mut file = first.ok_or_else(|| crate::error::err!("an ensemble needs K >= 1"))?;
    file.training.seconds = seconds;
    Ok(TrainedFile::Family(file))
}
