//! Wire structs of the node's own interfaces (msg/*.msg, msg/*.srv other than
//! ParticleState, which lives in [`crate::data::msg`]): plain serde structs with
//! the fields in .msg order, which is what CDR needs.

use ros2_client::Message;
use serde::{Deserialize, Serialize};

use crate::data::msg::{Header, ParticleState, Vector3};

/// ROS package of our interfaces.
pub const PACKAGE: &str = "mcgnode_msgs";

/// `mcgnode_msgs/msg/PredictedTrajectory`: the graph once (in `initial`),
/// then positions and velocities per predicted step.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PredictedTrajectory {
    /// Copied from the input state.
    pub header: Header,
    /// The state the prediction starts from, as received.
    pub initial: ParticleState,
    /// Time step between states, seconds.
    pub dt: f64,
    /// Predicted states: state `k` is `k + 1` steps after `initial`.
    pub steps: u32,
    /// `positions[k * n + i]`: particle `i` in state `k`.
    pub positions: Vec<Vector3>,
    /// `velocities[k * n + i]`: particle `i` in state `k`.
    pub velocities: Vec<Vector3>,
}

impl PredictedTrajectory {
    /// Particles per state.
    pub fn particles(&self) -> usize {
        self.initial.positions.len()
    }

    /// Positions of state `k` (empty when there is no such state).
    pub fn positions_at(&self, k: usize) -> &[Vector3] {
        let n = self.particles();
        self.positions.get(k * n..(k + 1) * n).unwrap_or_default()
    }

    /// State `k` as a full message: `initial`'s graph and field, the
    /// predicted positions and velocities, stamped `(k + 1)·dt` after the
    /// input (in integer nanoseconds) with step `initial.step + k + 1`.
    pub fn state(&self, k: usize) -> Option<ParticleState> {
        let n = self.particles();
        if k >= self.steps as usize {
            return None;
        }
        let mut s = self.initial.clone();
        s.positions = self.positions.get(k * n..(k + 1) * n)?.to_vec();
        s.velocities = self.velocities.get(k * n..(k + 1) * n)?.to_vec();
        s.accelerations.clear();
        let k1 = u32::try_from(k + 1).unwrap_or(u32::MAX);
        s.step = self.initial.step.saturating_add(k1);
        // f64 seconds since the epoch would lose sub-microsecond steps.
        let offset = (f64::from(k1) * self.dt * 1e9).round() as i64;
        s.header = Header {
            stamp: crate::data::msg::Time::from_nanos(
                self.header.stamp.as_nanos().saturating_add(offset),
            ),
            frame_id: self.header.frame_id.clone(),
        };
        Some(s)
    }
}

/// `mcgnode_msgs/msg/ParticleForces`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleForces {
    /// Copied from the input state.
    pub header: Header,
    /// Total force per particle.
    pub total: Vec<Vector3>,
    /// Receiving particle of each pairwise force.
    pub edge_a: Vec<u32>,
    /// Exerting particle of each pairwise force.
    pub edge_b: Vec<u32>,
    /// f_ab, when the model has pairwise forces.
    pub edge_force: Vec<Vector3>,
}

/// `mcgnode_msgs/msg/NodeDiagnostics`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NodeDiagnostics {
    /// Stamped with the node's clock.
    pub header: Header,
    /// States received on the input topic.
    pub received: u64,
    /// Of those, rejected.
    pub rejected: u64,
    /// Predictions published.
    pub predicted: u64,
    /// Latest rejection or failure reason.
    pub last_error: String,
    /// Description of the served model.
    pub model: String,
    /// States with an input outside the model's training range.
    pub out_of_range: u64,
    /// Position-only states predicted from estimated velocities.
    pub derived: u64,
    /// Position-only states held as history while their stream warms up.
    pub warming_up: u64,
    /// Times a stream's history started over.
    pub history_resets: u64,
}

/// `mcgnode_msgs/msg/LiveAccuracy`: running accuracy per lead time.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LiveAccuracy {
    /// Stamp and frame of the incoming state compared.
    pub header: Header,
    /// Trajectory of that state.
    pub trajectory_id: u32,
    /// Lead times, seconds.
    pub lead_times: Vec<f64>,
    /// Comparisons so far per lead time.
    pub compared: Vec<u64>,
    /// Latest RE per lead time (NaN: none yet).
    pub re: Vec<f64>,
    /// Mean RE of the window per lead time.
    pub re_mean: Vec<f64>,
    /// Latest EE per lead time (NaN: not computable).
    pub ee: Vec<f64>,
    /// Mean EE of the window per lead time.
    pub ee_mean: Vec<f64>,
    /// Drift alarm level ([`DIAGNOSTIC_OK`], [`DIAGNOSTIC_WARN`] or
    /// [`DIAGNOSTIC_ERROR`]).
    pub level: u8,
    /// Why, or the worst running RE.
    pub message: String,
}
impl Message for LiveAccuracy {}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    /// What is measured.
    pub key: String,
    /// Its value, as text.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// [`DIAGNOSTIC_OK`], [`DIAGNOSTIC_WARN`], [`DIAGNOSTIC_ERROR`] or
    /// [`DIAGNOSTIC_STALE`].
    pub level: u8,
    /// Name of the component (`mcgnode: predictions`).
    pub name: String,
    /// Summary of the status.
    pub message: String,
    /// Hardware the status is about (the node's name here).
    pub hardware_id: String,
    /// Counters and details.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/msg/DiagnosticArray`, the standard `/diagnostics` message.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamped with the node's clock.
    pub header: Header,
    /// One status per component.
    pub status: Vec<DiagnosticStatus>,
}

/// `DiagnosticStatus.level`: all is well.
pub const DIAGNOSTIC_OK: u8 = 0;
/// `DiagnosticStatus.level`: something needs attention.
pub const DIAGNOSTIC_WARN: u8 = 1;
/// `DiagnosticStatus.level`: something failed.
pub const DIAGNOSTIC_ERROR: u8 = 2;
/// `DiagnosticStatus.level`: no recent information.
pub const DIAGNOSTIC_STALE: u8 = 3;

/// `mcgnode_msgs/msg/ModelSwap`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelSwap {
    /// When the swap happened.
    pub header: Header,
    /// Description of the model replaced.
    pub old_model: String,
    /// Description of the new model.
    pub new_model: String,
    /// Why.
    pub reason: String,
}

/// Request of `mcgnode_msgs/srv/Rollout`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RolloutRequest {
    /// Where to start.
    pub initial: ParticleState,
    /// Steps to predict.
    pub steps: u32,
    /// Time step; 0 = the node's `dt` parameter.
    pub dt: f64,
}
impl Message for RolloutRequest {}

/// Response of `mcgnode_msgs/srv/Rollout`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RolloutResponse {
    /// Whether `trajectory` holds a prediction.
    pub success: bool,
    /// Why it failed, when it did.
    pub message: String,
    /// The prediction.
    pub trajectory: PredictedTrajectory,
}
impl Message for RolloutResponse {}

/// Request of `mcgnode_msgs/srv/Train`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainRequest {
    /// Bags to train on; empty = what the node recorded.
    pub bags: Vec<String>,
    /// Model variant.
    pub variant: String,
    /// Training epochs.
    pub epochs: u32,
    /// Random seed.
    pub seed: u64,
    /// Start from the served model file (weights and Adam state).
    pub fine_tune: bool,
}
impl Message for TrainRequest {}

/// Response of `mcgnode_msgs/srv/Train`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainResponse {
    /// Whether training finished.
    pub success: bool,
    /// Details or the failure reason.
    pub message: String,
    /// Where the model was written.
    pub model_path: String,
    /// Final training loss.
    pub train_loss: f64,
    /// Final validation loss.
    pub validation_loss: f64,
    /// Fraction of the validation targets' mean square explained (NaN:
    /// unknown).
    pub explained: f64,
}
impl Message for TrainResponse {}

/// Request of `mcgnode_msgs/srv/LoadModel`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoadModelRequest {
    /// Model file to load.
    pub path: String,
}
impl Message for LoadModelRequest {}

/// Response of `mcgnode_msgs/srv/LoadModel`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoadModelResponse {
    /// Whether the model was swapped in.
    pub success: bool,
    /// Details or the failure reason.
    pub message: String,
}
impl Message for LoadModelResponse {}

/// Request of `mcgnode_msgs/srv/Replay`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReplayRequest {
    /// Bag to replay.
    pub bag: String,
}
impl Message for ReplayRequest {}

/// Response of `mcgnode_msgs/srv/Replay`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReplayResponse {
    /// Whether the replay ran.
    pub success: bool,
    /// Details or the failure reason.
    pub message: String,
    /// The error report as JSON.
    pub report_json: String,
}
impl Message for ReplayResponse {}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::msg::{decode_cdr, encode_cdr};

    /// Field order is what CDR depends on: a round trip through bytes with
    /// nested arrays of structs must give back the same message.
    #[test]
    fn nested_messages_round_trip_through_cdr() {
        let state = ParticleState {
            dimension: 2,
            types: vec![0, 1],
            masses: vec![1.0, 2.0],
            system: "spring".into(),
            ..ParticleState::default()
        };
        let resp = RolloutResponse {
            success: true,
            message: "ok".into(),
            trajectory: PredictedTrajectory {
                header: Header {
                    frame_id: "world".into(),
                    ..Header::default()
                },
                initial: state.clone(),
                dt: 0.5,
                steps: 2,
                positions: [state.positions.clone(), state.positions.clone()].concat(),
                velocities: [state.velocities.clone(), state.velocities].concat(),
            },
        };
        let back: RolloutResponse = decode_cdr(&encode_cdr(&resp).unwrap()).unwrap();
        assert_eq!(back, resp);
    }
}
