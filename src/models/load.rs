//! Loading any model file, GNODE family or baseline, behind [`Dynamics`];
//! and a model to serve or replay ([`load_model`]: a file checked against its
//! training data, or the ground truth `truth:<system>`); what a model
//! reference says it was trained on ([`trained_for`]).

use super::reference::ModelRef;
use super::truth;
use crate::baselines::file::FORMAT as BASELINE_FORMAT;
use crate::baselines::TrainedBaseline;
use crate::compat::TrainedFor;
use crate::dynamics::Dynamics;
use crate::error::{Context, Result};
use crate::kernel::TrainedModel;
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

/// Loads what `model` names: a model file of the GNODE family or a
/// baseline, by its `format` field; the "nothing moves" reference
/// [`crate::dynamics::Still`]; or the simulator itself (`truth:<system>`),
/// whose errors at another step (`evaluate --dt`) are the floor that step
/// puts under every model's.
pub fn load_any_model(model: &ModelRef) -> Result<LoadedModel> {
    let path = match model {
        ModelRef::Still => {
            return Ok(LoadedModel {
                name: crate::dynamics::STILL.to_string(),
                start_fingerprints: vec![],
                dynamics: Arc::new(crate::dynamics::Still),
            })
        }
        ModelRef::Truth(kind) => {
            return Ok(LoadedModel {
                name: model.to_string(),
                start_fingerprints: vec![],
                dynamics: truth::truth(*kind),
            })
        }
        ModelRef::File(path) => path,
    };
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
    let name = m.file.hyper.variant.name().to_string();
    let start_fingerprints = m.file.trained_on.start_fingerprints.clone();
    let dynamics: Arc<dyn Dynamics> = if m.file.members.is_empty() {
        Arc::new(m)
    } else {
        Arc::new(crate::kernel::Ensemble::from_file(&m.file)?)
    };
    Ok(LoadedModel {
        dynamics,
        name,
        start_fingerprints,
    })
}

/// The ground truth, or a model (file or `still`) wrapped in
/// [`super::Checked`] so it refuses data it was not trained for: the model
/// the node serves and `replay` rolls out.
pub fn load_model(model: &ModelRef) -> Result<Arc<dyn Dynamics>> {
    if let ModelRef::Truth(kind) = model {
        return Ok(truth::truth(*kind));
    }
    let m = load_any_model(model).with_context(|| format!("loading model {model}"))?;
    let trained = trained_for(model)?;
    Ok(Arc::new(super::Checked::new(m.dynamics, trained)))
}

/// What `model` was trained on: its file's training description
/// ([`TrainedFor::from_model_file`]); for the reference `still`
/// ([`crate::dynamics::Still`]) nothing, since it fits any data; for the
/// simulator, its own system (the dimension and edges are checked by the
/// simulator itself; the field is its default's).
pub fn trained_for(model: &ModelRef) -> Result<TrainedFor> {
    match model {
        ModelRef::Still => Ok(TrainedFor {
            model: crate::dynamics::STILL.into(),
            ..TrainedFor::default()
        }),
        ModelRef::Truth(kind) => truth::truth(*kind)
            .trained_for()
            .cloned()
            .ok_or_else(|| crate::error::err!("{model} does not say what it simulates")),
        ModelRef::File(path) => TrainedFor::from_model_file(path),
    }
}
