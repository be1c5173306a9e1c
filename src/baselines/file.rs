//! A trained baseline on disk: JSON like [`crate::gnode::ModelFile`], with its
//! own format tag so neither loader mistakes one for the other.

use super::net::BaselineHyper;
use crate::error::{bail, Context, Result};
use crate::gnode::file::{TrainedOn, TrainingReport};
use crate::gnode::params::Weights;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Format tag written in every baseline file.
pub const FORMAT: &str = "mcgnode-baseline/1";

/// A trained baseline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaselineFile {
    /// Always [`FORMAT`].
    pub format: String,
    /// Version of mcgnode that wrote it.
    pub crate_version: String,
    /// Architecture.
    pub hyper: BaselineHyper,
    /// Training data, when trained from bags.
    pub trained_on: Option<TrainedOn>,
    /// Training outcome.
    pub training: TrainingReport,
    /// Parameters.
    pub weights: Weights,
}

impl BaselineFile {
    /// Writes the file atomically (temporary file in the same folder, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::gnode::file::write_json_atomic(path, self)
            .with_context(|| format!("writing baseline file {}", path.display()))
    }

    /// Reads and checks a baseline file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read baseline file {}", path.display()))?;
        let m: BaselineFile = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a valid mcgnode baseline file", path.display()))?;
        if m.format != FORMAT {
            bail!(
                "{}: unsupported baseline format {:?} (expected {FORMAT})",
                path.display(),
                m.format
            );
        }
        Ok(m)
    }
}
