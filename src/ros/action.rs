//! The Train action (`mcgnode_msgs/action/Train`, msg/Train.action): the same
//! training as the Train service, with per-epoch feedback and cancel.
//!
//! A goal is refused while another training runs. A cancel makes the next
//! epoch's callback stop training; the goal ends CANCELED and the old model
//! stays. Failures end ABORTED with the reason in the result's `message`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use ros2_client::action::{ExecutingGoalHandle, GoalEndStatus};
use ros2_client::action_msgs::GoalId;
use ros2_client::log::LogLevel;
use ros2_client::Node;

use super::resource_names::Names;

use super::topics::TRAIN_ACTION;
use super::trainer::{claim, Claim, Trainer, BUSY};
use super::training::run_training;
use super::wire::{
    TrainAction, TrainFeedback, TrainGoal, TrainRequest, TrainResponse, TrainResult,
};

type ActionServer = super::qos::ActionServerOf<TrainAction>;

/// The Train action server, handed to [`spawn`].
pub struct TrainActionServer(ActionServer, String);

/// The goal being executed and its cancel flag.
type Running = Arc<Mutex<Option<(GoalId, Arc<AtomicBool>)>>>;

/// Creates the action server (QoS as rclpy's action defaults).
pub fn create(node: &mut Node, names: &Names) -> crate::error::Result<TrainActionServer> {
    let (server, name) = super::qos::action_server::<TrainAction>(node, names, TRAIN_ACTION)?;
    Ok(TrainActionServer(server, name))
}

/// Starts the goal and cancel tasks (inside the runtime).
pub fn spawn(shared: Arc<Trainer>, server: TrainActionServer) {
    shared.log(LogLevel::Info, &format!("action {}", server.1));
    let server = Arc::new(server.0);
    let running: Running = Arc::new(Mutex::new(None));
    tokio::spawn(goal_loop(shared.clone(), server.clone(), running.clone()));
    tokio::spawn(cancel_loop(shared, server, running));
}

/// Accepts goals while no training runs, and starts each.
async fn goal_loop(shared: Arc<Trainer>, server: Arc<ActionServer>, running: Running) {
    let warn = |m: String| shared.log(LogLevel::Warn, &format!("Train action: {m}"));
    loop {
        let handle = match server.receive_new_goal().await {
            Ok(h) => h,
            Err(e) => {
                warn(format!("undecodable goal: {e:?}"));
                continue;
            }
        };
        let Some(goal) = server.get_new_goal(handle.clone()) else {
            continue;
        };
        let Some(claim) = claim(&shared) else {
            warn(format!("goal {BUSY}"));
            if let Err(e) = server.reject_goal(handle).await {
                warn(format!("rejecting a goal failed: {e:?}"));
            }
            continue;
        };
        let accepted = match server.accept_goal(handle).await {
            Ok(a) => a,
            Err(e) => {
                warn(format!("accepting a goal failed: {e:?}"));
                continue;
            }
        };
        let executing = match server.start_executing_goal(accepted).await {
            Ok(x) => x,
            Err(e) => {
                warn(format!("starting a goal failed: {e:?}"));
                continue;
            }
        };
        let cancel = Arc::new(AtomicBool::new(false));
        *running.lock().unwrap_or_else(PoisonError::into_inner) =
            Some((executing.goal_id(), cancel.clone()));
        let req = TrainRequest {
            bags: goal.bags,
            variant: goal.variant,
            epochs: goal.epochs,
            seed: goal.seed,
            fine_tune: goal.fine_tune,
        };
        tokio::spawn(execute(
            shared.clone(),
            server.clone(),
            running.clone(),
            executing,
            req,
            cancel,
            claim,
        ));
    }
}

/// Trains for one goal, forwarding feedback, then sends the result.
async fn execute(
    shared: Arc<Trainer>,
    server: Arc<ActionServer>,
    running: Running,
    handle: ExecutingGoalHandle<TrainGoal>,
    req: TrainRequest,
    cancel: Arc<AtomicBool>,
    claim: Claim,
) {
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<TrainFeedback>();
    let (worker, flag) = (shared.clone(), cancel.clone());
    let job = tokio::task::spawn_blocking(move || {
        let _claim = claim;
        run_training(
            &worker,
            &req,
            &flag,
            |r| {
                // The receiver lives until the job ends.
                let _ = tx.send(TrainFeedback::from(r));
            },
            "Train action",
        )
    });
    let resp = super::qos::forward_feedback::<TrainAction, _>(&server, &handle, &mut rx, job).await;
    let resp = resp.unwrap_or_else(|join| TrainResponse {
        success: false,
        message: format!("training task failed: {join}"),
        ..TrainResponse::default()
    });
    *running.lock().unwrap_or_else(PoisonError::into_inner) = None;
    let status = if resp.success {
        GoalEndStatus::Succeeded
    } else if cancel.load(Ordering::Acquire) {
        GoalEndStatus::Canceled
    } else {
        GoalEndStatus::Aborted
    };
    // Resolves once the client has asked for the result.
    if let Err(e) = server
        .send_result_response(handle, status, TrainResult::from(resp))
        .await
    {
        shared.log(
            LogLevel::Warn,
            &format!("Train action: sending the result failed: {e:?}"),
        );
    }
}

/// Accepts cancel requests for the running goal; others are refused.
async fn cancel_loop(shared: Arc<Trainer>, server: Arc<ActionServer>, running: Running) {
    loop {
        let request = match server.receive_cancel_request().await {
            Ok(r) => r,
            Err(e) => {
                shared.log(
                    LogLevel::Warn,
                    &format!("Train action: undecodable cancel request: {e:?}"),
                );
                continue;
            }
        };
        let current = running
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        let to_cancel: Vec<GoalId> = match &current {
            Some((id, flag)) if request.contains_goal(id) => {
                flag.store(true, Ordering::Release);
                shared.log(
                    LogLevel::Info,
                    "Train action: cancel requested; stopping after the current epoch",
                );
                vec![*id]
            }
            _ => Vec::new(),
        };
        if let Err(e) = server
            .respond_to_cancel_requests(&request, to_cancel.into_iter())
            .await
        {
            shared.log(
                LogLevel::Warn,
                &format!("Train action: answering a cancel failed: {e:?}"),
            );
        }
    }
}
