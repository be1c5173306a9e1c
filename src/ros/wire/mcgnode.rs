//! Our messages (msg/*.msg other than ParticleState, whose struct lives in
//! [`crate::data::msg`]).

use serde::{Deserialize, Serialize};

use crate::data::msg::{Header, ParticleState, Vector3};

#[cfg(doc)]
use super::diagnostics::{DIAGNOSTIC_ERROR, DIAGNOSTIC_OK, DIAGNOSTIC_WARN};

ros_types!("mcgnode_msgs" / "msg":
    PredictedTrajectory = "PredictedTrajectory",
    ParticleForces = "ParticleForces",
    NodeDiagnostics = "NodeDiagnostics",
    LiveAccuracy = "LiveAccuracy",
    ModelSwap = "ModelSwap",
);

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
