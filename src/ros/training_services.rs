//! The Train and LoadModel services' work, each on the node's [`Trainer`]:
//! the Train call returns when training has ended (its response holds the
//! model path and losses; epochs bound how long that takes): callers that
//! want progress or cancel use the action ([`super::action`]).

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use ros2_client::log::LogLevel;

use super::model_swap::load_and_swap;
use super::trainer::{claim, Trainer, BUSY};
use super::training::run_training;
use super::wire::{LoadModelRequest, LoadModelResponse, TrainRequest, TrainResponse};

/// The Train service's work: refused at once while another training runs,
/// else trains (blocking) and answers when done.
pub fn train_call(shared: &Arc<Trainer>, req: TrainRequest) -> TrainResponse {
    let Some(_claim) = claim(shared) else {
        shared.log(LogLevel::Warn, &format!("Train service: {BUSY}"));
        return TrainResponse {
            success: false,
            message: BUSY.to_string(),
            ..TrainResponse::default()
        };
    };
    run_training(
        shared,
        &req,
        &AtomicBool::new(false),
        |_| {},
        "Train service",
    )
}

/// The LoadModel service's work: [`load_and_swap`] of the request's path.
pub fn load_call(shared: &Arc<Trainer>, req: LoadModelRequest) -> LoadModelResponse {
    load_and_swap(shared, &req.path)
}
