//! Our services (msg/*.srv): request and response of each, and the service
//! that pairs them.

use serde::{Deserialize, Serialize};

use crate::data::msg::ParticleState;

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
