//! Our services (msg/*.srv): request and response of each, and the service
//! that pairs them.

use serde::{Deserialize, Serialize};

use crate::data::msg::{ParticleState, Point, Vector3};

use super::mcgnode::PredictedTrajectory;

ros_services!("mcgnode_msgs":
    /// `mcgnode_msgs/srv/Rollout`: a prediction on request.
    Rollout(RolloutRequest, RolloutResponse) = "Rollout",
    /// `mcgnode_msgs/srv/Train`: training in the background, then a swap.
    Train(TrainRequest, TrainResponse) = "Train",
    /// `mcgnode_msgs/srv/LoadModel`: a swap to a model file.
    LoadModel(LoadModelRequest, LoadModelResponse) = "LoadModel",
    /// `mcgnode_msgs/srv/Replay`: a bag replayed through the served model.
    Replay(ReplayRequest, ReplayResponse) = "Replay",
    /// `mcgnode_msgs/srv/Plan`: the kinematic particles' motion planned
    /// through the served model.
    Plan(PlanRequest, PlanResponse) = "Plan",
);

/// Request of `mcgnode_msgs/srv/Rollout`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RolloutRequest {
    /// Where to start.
    pub initial: ParticleState,
    /// Steps to predict.
    pub steps: u32,
    /// Time step; 0 = the node's `dt` parameter.
    pub dt: f64,
    /// The kinematic particles' given positions at every integration step
    /// (steps × substeps + 1 rows of one point per kinematic particle);
    /// empty: they are held.
    pub kinematic_positions: Vec<Point>,
    /// Their velocities, the same shape; empty: derived from the positions.
    pub kinematic_velocities: Vec<Vector3>,
}

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

/// Request of `mcgnode_msgs/srv/LoadModel`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoadModelRequest {
    /// Model file to load.
    pub path: String,
}

/// Response of `mcgnode_msgs/srv/LoadModel`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoadModelResponse {
    /// Whether the model was swapped in.
    pub success: bool,
    /// Details or the failure reason.
    pub message: String,
}

/// Request of `mcgnode_msgs/srv/Replay`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReplayRequest {
    /// Bag to replay.
    pub bag: String,
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::msg::{decode_cdr, encode_cdr};
    use crate::data::msg::{Header, ParticleState};
    use crate::ros::wire::PredictedTrajectory;

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
                initial: state,
                dt: 0.5,
                steps: 2,
                positions: vec![0.5, -1.0, 2.0, 0.25, 1.5, 3.0, -0.5, 4.0],
                velocities: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0],
                spread: vec![0.125, 0.25, 0.5, 1.0],
            },
        };
        let back: RolloutResponse = decode_cdr(&encode_cdr(&resp).unwrap()).unwrap();
        assert_eq!(back, resp);
    }
}

/// Request of `mcgnode_msgs/srv/Plan` (msg/Plan.srv says what each field means).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanRequest {
    /// Where to plan from.
    pub initial: ParticleState,
    /// Particles with targets.
    pub particles: Vec<u32>,
    /// Their targets.
    pub targets: Vec<Point>,
    /// "final", "along" (empty: final).
    pub cost: String,
    /// Weight of the control effort.
    pub effort: f64,
    /// Weight of the chosen particles' squared speed.
    pub speed: f64,
    /// Control steps of the node's dt (0: its horizon).
    pub horizon: u32,
    /// "random", "cem", "mppi" (empty: cem).
    pub sampler: String,
    /// Candidates per round (0: 256).
    pub candidates: u32,
    /// Rounds (0: 4).
    pub iterations: u32,
    /// CEM elites (0: 16).
    pub elites: u32,
    /// Spread of sampled velocities, m/s (0: 0.5).
    pub sigma: f64,
    /// MPPI temperature (0: 0.1).
    pub temperature: f64,
    /// Speed bound, m/s (0: 2).
    pub max_speed: f64,
    /// Seed of the sampling.
    pub seed: u64,
    /// Gradient steps refining the search's best sequence (0: none).
    pub refine: u32,
}

/// Response of `mcgnode_msgs/srv/Plan`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanResponse {
    /// Whether a plan was made.
    pub success: bool,
    /// Details, or why it failed.
    pub message: String,
    /// The best sequence's cost.
    pub cost: f64,
    /// Holding the kinematic particles still's cost.
    pub hold_still_cost: f64,
    /// The driven (kinematic) particles.
    pub driven: Vec<u32>,
    /// The best sequence, step-major, one vector per driven particle.
    pub best: Vec<Vector3>,
    /// The driven particles' positions at every integration step.
    pub kinematic_positions: Vec<Point>,
    /// Their velocities.
    pub kinematic_velocities: Vec<Vector3>,
    /// The best sequence's predicted trajectory.
    pub trajectory: PredictedTrajectory,
    /// The last round's candidate costs.
    pub costs: Vec<f64>,
    /// Planning wall time, seconds.
    pub seconds: f64,
}
