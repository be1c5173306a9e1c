//! Our Train action (msg/Train.action): goal, result and feedback, and
//! conversions from the Train service's and the trainer's types.

use serde::{Deserialize, Serialize};

use crate::train::EpochReport;

use super::services::TrainResponse;

ros_action!("mcgnode_msgs":
    /// `mcgnode_msgs/action/Train`: training with per-epoch feedback and cancel.
    TrainAction(TrainGoal, TrainResult, TrainFeedback) = "Train"
);

/// Goal of `mcgnode_msgs/action/Train` (the Train service's request).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainGoal {
    /// Bags to train on; empty = what the node recorded.
    pub bags: Vec<String>,
    /// Model variant; empty = mcgnode.
    pub variant: String,
    /// Training epochs.
    pub epochs: u32,
    /// Random seed.
    pub seed: u64,
    /// Start from the served model file (weights and Adam state).
    pub fine_tune: bool,
}

/// Result of `mcgnode_msgs/action/Train` (the Train service's response).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainResult {
    /// Whether the new model was swapped in.
    pub success: bool,
    /// Details or the failure reason.
    pub message: String,
    /// Where the model was written.
    pub model_path: String,
    /// Training loss at the kept epoch.
    pub train_loss: f64,
    /// Validation loss at the kept epoch.
    pub validation_loss: f64,
    /// Fraction of the validation targets' mean square explained (NaN:
    /// unknown).
    pub explained: f64,
}

/// Feedback of `mcgnode_msgs/action/Train`, one per epoch.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainFeedback {
    /// Epoch just finished, from 1.
    pub epoch: u32,
    /// Epochs asked for.
    pub epochs: u32,
    /// Mean training loss of the epoch.
    pub train_loss: f64,
    /// Validation loss after the epoch.
    pub validation_loss: f64,
    /// Best validation loss so far.
    pub best_validation_loss: f64,
}

impl From<&EpochReport> for TrainFeedback {
    fn from(r: &EpochReport) -> Self {
        TrainFeedback {
            epoch: u32::try_from(r.epoch).unwrap_or(u32::MAX),
            epochs: u32::try_from(r.epochs).unwrap_or(u32::MAX),
            train_loss: r.train_loss,
            validation_loss: r.validation_loss,
            best_validation_loss: r.best,
        }
    }
}

impl From<TrainResponse> for TrainResult {
    fn from(r: TrainResponse) -> Self {
        TrainResult {
            success: r.success,
            message: r.message,
            model_path: r.model_path,
            train_loss: r.train_loss,
            validation_loss: r.validation_loss,
            explained: r.explained,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feedback_and_result_carry_the_figures() {
        let r = EpochReport {
            epoch: 3,
            epochs: 7,
            train_loss: 0.5,
            validation_loss: 0.25,
            best: 0.2,
            elapsed: 1.0,
        };
        let fb = TrainFeedback::from(&r);
        assert_eq!((fb.epoch, fb.epochs), (3, 7));
        assert_eq!(fb.best_validation_loss, 0.2);
        let res = TrainResult::from(TrainResponse {
            success: true,
            message: "m".into(),
            model_path: "/x.json".into(),
            train_loss: 1.0,
            validation_loss: 2.0,
            explained: 0.5,
        });
        assert!(res.success && res.model_path == "/x.json" && res.validation_loss == 2.0);
        assert_eq!(res.explained, 0.5);
    }
}
