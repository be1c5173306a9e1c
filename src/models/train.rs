//! Training a model of any kind from bags and saving its model file.

use super::ModelKind;
use crate::error::{Context, Result};
use std::path::Path;

/// Trains any model from bags (the GNODE family with `opts`; baselines use
/// their paper architecture), saves it to `out` and returns its training figures.
pub fn train_any_from_bags(
    kind: ModelKind,
    bags: &[std::path::PathBuf],
    opts: &crate::train::ModelOptions,
    cfg: &crate::train::TrainConfig,
    log: impl FnMut(&str),
    on_epoch: impl FnMut(&crate::train::EpochReport) -> bool,
    out: &Path,
) -> Result<crate::model::file::TrainingReport> {
    let saving = || format!("saving {}", out.display());
    Ok(match kind {
        ModelKind::Family(v) => {
            let f = crate::train::train_from_bags(v, bags, opts, cfg, log, on_epoch)?;
            f.save(out).with_context(saving)?;
            f.training
        }
        ModelKind::Baseline(k) => {
            let f = crate::baselines::train_baseline_from_bags(
                k,
                bags,
                opts.topic.as_deref(),
                cfg,
                log,
                on_epoch,
            )?;
            f.save(out).with_context(saving)?;
            f.training
        }
    })
}
