//! Loading any model file, GNODE family or baseline, behind [`Dynamics`].

use super::file::FORMAT as BASELINE_FORMAT;
use super::TrainedBaseline;
use crate::dynamics::Dynamics;
use crate::model::TrainedModel;
use anyhow::{Context, Result};
use std::path::Path;
use std::sync::Arc;

/// A loaded model of either kind.
pub struct LoadedModel {
    /// The model.
    pub dynamics: Arc<dyn Dynamics>,
    /// Its name ("mcgnode", "lgn", ...).
    pub name: String,
    /// Fingerprints of its training starts (empty if unknown).
    pub start_fingerprints: Vec<String>,
}

/// Loads a model file of the GNODE family or a baseline, by its `format` field
/// (or, for the path `still`, the "nothing moves" reference [`crate::dynamics::Still`]).
pub fn load_any_model(path: &Path) -> Result<LoadedModel> {
    if path == Path::new(crate::dynamics::STILL) {
        return Ok(LoadedModel {
            name: crate::dynamics::STILL.to_string(),
            start_fingerprints: vec![],
            dynamics: Arc::new(crate::dynamics::Still),
        });
    }
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read model file {}", path.display()))?;
    let format = serde_json::from_str::<serde_json::Value>(&text)
        .ok()
        .and_then(|v| v.get("format").and_then(|f| f.as_str()).map(str::to_string));
    if format.as_deref() == Some(BASELINE_FORMAT) {
        let b = TrainedBaseline::load(path)?;
        let fps = b
            .file
            .trained_on
            .as_ref()
            .map(|t| t.start_fingerprints.clone())
            .unwrap_or_default();
        return Ok(LoadedModel {
            name: b.file.hyper.kind.name().to_string(),
            start_fingerprints: fps,
            dynamics: Arc::new(b),
        });
    }
    let m = TrainedModel::load(path)?;
    Ok(LoadedModel {
        name: m.file.hyper.variant.name().to_string(),
        start_fingerprints: m.file.trained_on.start_fingerprints.clone(),
        dynamics: Arc::new(m),
    })
}

/// A model of the GNODE family or a baseline, named as on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// NODE, GNODE, CGNODE, CDGNODE, MCGNODE.
    Family(crate::model::Variant),
    /// LGN, HGN, GNS.
    Baseline(super::Kind),
}

impl ModelKind {
    /// The lower-case name ("mcgnode", "lgn", ...).
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Family(v) => v.name(),
            ModelKind::Baseline(k) => k.name(),
        }
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ModelKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.parse::<crate::model::Variant>() {
            Ok(v) => Ok(ModelKind::Family(v)),
            Err(_) => s
                .parse::<super::Kind>()
                .map(ModelKind::Baseline)
                .map_err(|_| {
                    format!(
                        "unknown model {s:?}; expected one of node, gnode, cgnode, cdgnode, \
                     mcgnode, lgn, hgn, gns"
                    )
                }),
        }
    }
}

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
            let f = super::train_baseline_from_bags(
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
