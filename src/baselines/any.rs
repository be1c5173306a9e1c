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

/// Loads a model file of the GNODE family or a baseline, by its `format` field.
pub fn load_any_model(path: &Path) -> Result<LoadedModel> {
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
