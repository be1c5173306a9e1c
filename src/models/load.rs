//! Loading any model file, GNODE family or baseline, behind [`Dynamics`];
//! and a model to serve or replay ([`load_model`]: a file checked against its
//! training data, or the ground truth `truth:<system>`); what a model
//! reference says it was trained on ([`trained_for`]).

use super::truth;
use crate::baselines::file::FORMAT as BASELINE_FORMAT;
use crate::baselines::TrainedBaseline;
use crate::compat::TrainedFor;
use crate::dynamics::Dynamics;
use crate::error::{Context, Result};
use crate::kernel::TrainedModel;
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

/// Loads a model file of the GNODE family or a baseline, by its `format` field;
/// or, for the path `still`, the "nothing moves" reference
/// [`crate::dynamics::Still`]; or, for `truth:<system>`, the simulator itself,
/// whose errors at another step (`evaluate --dt`) are the floor that step puts
/// under every model's.
pub fn load_any_model(path: &Path) -> Result<LoadedModel> {
    if path == Path::new(crate::dynamics::STILL) {
        return Ok(LoadedModel {
            name: crate::dynamics::STILL.to_string(),
            start_fingerprints: vec![],
            dynamics: Arc::new(crate::dynamics::Still),
        });
    }
    if let Some(name) = path.to_str().filter(|p| truth::is_truth(p)) {
        return Ok(LoadedModel {
            name: name.to_string(),
            start_fingerprints: vec![],
            dynamics: truth::load_truth(name)?,
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

/// `truth:<system>`, or a trained model file (GNODE family or baseline)
/// wrapped in [`super::Checked`] so it refuses data it was not
/// trained for: the model the node serves and `replay` rolls out.
pub fn load_model(model: &str) -> Result<Arc<dyn Dynamics>> {
    if truth::is_truth(model) {
        return Ok(truth::load_truth(model)?);
    }
    let m = load_any_model(Path::new(model)).with_context(|| format!("loading model {model}"))?;
    let trained = trained_for(Path::new(model))?;
    Ok(Arc::new(super::Checked::new(m.dynamics, trained)))
}

/// What the model at `path` was trained on: its file's training description
/// ([`TrainedFor::from_model_file`]), or for the reference `still`
/// ([`crate::dynamics::Still`]) nothing, since it fits any data.
pub fn trained_for(path: &Path) -> crate::error::Result<TrainedFor> {
    if path == Path::new(crate::dynamics::STILL) {
        // The reference fits any data.
        return Ok(TrainedFor {
            model: crate::dynamics::STILL.into(),
            ..TrainedFor::default()
        });
    }
    if let Some(name) = path.to_str().filter(|p| truth::is_truth(p)) {
        // The simulator fits its own system (the dimension and edges are
        // checked by the simulator itself; the field is its default's).
        return truth::load_truth(name)?
            .trained_for()
            .cloned()
            .ok_or_else(|| crate::error::err!("{name} does not say what it simulates"));
    }
    TrainedFor::from_model_file(path)
}
