//! The `mcgnode` metadata record of a bag, typed: one struct writes and reads
//! every key. The record is provenance (how a bag was made); what training and
//! evaluation need travels with the messages themselves.

use std::collections::BTreeMap;

use super::DataError;
use crate::physics::SystemConfig;

/// Key of the simulator configuration (JSON of [`SystemConfig`]).
pub const KEY_SYSTEM_CONFIG: &str = "system_config";
/// Key of the simulation seed.
pub const KEY_SEED: &str = "seed";
/// Key of the integrator that produced simulated data (`verlet`, `rk4`).
pub const KEY_INTEGRATOR: &str = "integrator";
/// Key naming the program that wrote the bag.
pub const KEY_GENERATOR: &str = "generator";
/// Key of the model the recording node served (kept current across swaps).
pub const KEY_MODEL: &str = "model";
/// Key naming the recorder (`mcgnode serve`).
pub const KEY_RECORDER: &str = "recorder";
/// Key of the recording node's prediction step, seconds.
pub const KEY_NODE_DT: &str = "dt";
/// Key of the recording node's horizon, in steps of `dt`.
pub const KEY_NODE_HORIZON: &str = "horizon";

/// Every key mcgnode writes, with what it holds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BagMetadata {
    /// The simulator configuration that made the data.
    pub system_config: Option<SystemConfig>,
    /// The simulation seed.
    pub seed: Option<u64>,
    /// The integrator of simulated data.
    pub integrator: Option<String>,
    /// The program that wrote the bag.
    pub generator: Option<String>,
    /// The model the recording node served.
    pub model: Option<String>,
    /// The recorder.
    pub recorder: Option<String>,
    /// The recording node's prediction step, seconds.
    pub node_dt: Option<f64>,
    /// The recording node's horizon, steps of `node_dt`.
    pub node_horizon: Option<u32>,
    /// Keys this build does not know, kept as they are.
    pub other: BTreeMap<String, String>,
}

impl BagMetadata {
    /// Reads the record's key/values; a value that does not parse is an error
    /// naming its key.
    pub fn from_map(map: &BTreeMap<String, String>) -> Result<BagMetadata, DataError> {
        let bad = |key: &str, v: &str, e: String| {
            DataError::Trajectory(format!("bag metadata {key} = {v:?} is not valid: {e}"))
        };
        let mut m = BagMetadata::default();
        for (k, v) in map {
            match k.as_str() {
                KEY_SYSTEM_CONFIG => {
                    m.system_config =
                        Some(serde_json::from_str(v).map_err(|e| bad(k, v, e.to_string()))?)
                }
                KEY_SEED => m.seed = Some(v.trim().parse().map_err(|e| bad(k, v, format!("{e}")))?),
                KEY_INTEGRATOR => m.integrator = Some(v.clone()),
                KEY_GENERATOR => m.generator = Some(v.clone()),
                KEY_MODEL => m.model = Some(v.clone()),
                KEY_RECORDER => m.recorder = Some(v.clone()),
                KEY_NODE_DT => {
                    m.node_dt = Some(v.trim().parse().map_err(|e| bad(k, v, format!("{e}")))?)
                }
                KEY_NODE_HORIZON => {
                    m.node_horizon = Some(v.trim().parse().map_err(|e| bad(k, v, format!("{e}")))?)
                }
                _ => {
                    m.other.insert(k.clone(), v.clone());
                }
            }
        }
        Ok(m)
    }

    /// The record's key/values (only the keys that are set).
    pub fn to_map(&self) -> Result<BTreeMap<String, String>, DataError> {
        let mut out = self.other.clone();
        let mut put = |k: &str, v: Option<String>| {
            if let Some(v) = v {
                out.insert(k.to_string(), v);
            }
        };
        put(
            KEY_SYSTEM_CONFIG,
            self.system_config
                .as_ref()
                .map(serde_json::to_string)
                .transpose()
                .map_err(|e| DataError::Trajectory(format!("system_config: {e}")))?,
        );
        put(KEY_SEED, self.seed.map(|s| s.to_string()));
        put(KEY_INTEGRATOR, self.integrator.clone());
        put(KEY_GENERATOR, self.generator.clone());
        put(KEY_MODEL, self.model.clone());
        put(KEY_RECORDER, self.recorder.clone());
        // `{:?}` keeps every digit of a float (and a `.0`).
        put(KEY_NODE_DT, self.node_dt.map(|d| format!("{d:?}")));
        put(KEY_NODE_HORIZON, self.node_horizon.map(|h| h.to_string()));
        Ok(out)
    }
}
