//! Our actions (msg/Train.action, msg/Plan.action): goal, result and
//! feedback, and conversions from the services' and the trainer's types.

use serde::{Deserialize, Serialize};

use crate::train::EpochReport;

use super::services::{PlanRequest, PlanResponse, TrainResponse};
use crate::plan::Iteration;

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

ros_action!("mcgnode_msgs":
    /// `mcgnode_msgs/action/Plan`: planning with per-round feedback and cancel.
    PlanAction(PlanGoal, PlanResult, PlanFeedback) = "Plan"
);

/// Goal of `mcgnode_msgs/action/Plan`: the Plan service's request, field for
/// field (the same bytes on the wire).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct PlanGoal(pub PlanRequest);

/// Result of `mcgnode_msgs/action/Plan`: the Plan service's response.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct PlanResult(pub PlanResponse);

/// Feedback of `mcgnode_msgs/action/Plan`, one per round of the search.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanFeedback {
    /// Round just finished, from 1.
    pub iteration: u32,
    /// Rounds asked for.
    pub iterations: u32,
    /// Cheapest cost so far.
    pub best_cost: f64,
    /// Mean cost of this round's finite candidates.
    pub mean_cost: f64,
    /// Candidates of this round whose rollout diverged.
    pub diverged: u32,
}

impl PlanFeedback {
    /// The feedback of round `it` of `iterations`.
    pub fn of(it: &Iteration, iterations: usize) -> Self {
        let n = |x: usize| u32::try_from(x).unwrap_or(u32::MAX);
        PlanFeedback {
            iteration: n(it.iteration),
            iterations: n(iterations),
            best_cost: it.best,
            mean_cost: it.mean,
            diverged: n(it.diverged),
        }
    }
}
