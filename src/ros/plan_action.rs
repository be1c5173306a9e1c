//! The Plan action (`mcgnode_msgs/action/Plan`, msg/Plan.action): the Plan
//! service's work with feedback after each round of the search and cancel.
//!
//! Goals run side by side, each on the blocking pool. A cancel makes the
//! search stop after its current round; the goal ends CANCELED with the best
//! sequence found so far. A refused request ends ABORTED with the reason in
//! the result's `message`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use ros2_client::action::{ExecutingGoalHandle, GoalEndStatus};
use ros2_client::action_msgs::GoalId;
use ros2_client::log::LogLevel;
use ros2_client::Node;

use super::calls::plan_call_with;
use super::handles::Handles;
use super::resource_names::Names;
use super::topics::PLAN_ACTION;
use super::wire::{PlanAction, PlanFeedback, PlanGoal, PlanResult};

type ActionServer = super::qos::ActionServerOf<PlanAction>;

/// The Plan action server, handed to [`spawn`].
pub struct PlanActionServer(ActionServer, String);

/// The goals being executed and their cancel flags.
type Running = Arc<Mutex<Vec<(GoalId, Arc<AtomicBool>)>>>;

/// Creates the action server (QoS as rclpy's action defaults).
pub fn create(node: &mut Node, names: &Names) -> crate::error::Result<PlanActionServer> {
    let (server, name) = super::qos::action_server::<PlanAction>(node, names, PLAN_ACTION)?;
    Ok(PlanActionServer(server, name))
}

/// Starts the goal and cancel tasks (inside the runtime).
pub fn spawn(h: Handles, server: PlanActionServer) {
    h.diag.log(LogLevel::Info, &format!("action {}", server.1));
    let server = Arc::new(server.0);
    let running: Running = Arc::new(Mutex::new(Vec::new()));
    tokio::spawn(goal_loop(h.clone(), server.clone(), running.clone()));
    tokio::spawn(cancel_loop(h, server, running));
}

fn warn(h: &Handles, m: &str) {
    h.diag.log(LogLevel::Warn, &format!("Plan action: {m}"));
}

/// Accepts every goal and starts it.
async fn goal_loop(h: Handles, server: Arc<ActionServer>, running: Running) {
    loop {
        let handle = match server.receive_new_goal().await {
            Ok(x) => x,
            Err(e) => {
                warn(&h, &format!("undecodable goal: {e:?}"));
                continue;
            }
        };
        let Some(PlanGoal(req)) = server.get_new_goal(handle.clone()) else {
            continue;
        };
        let accepted = match server.accept_goal(handle).await {
            Ok(a) => a,
            Err(e) => {
                warn(&h, &format!("accepting a goal failed: {e:?}"));
                continue;
            }
        };
        let executing = match server.start_executing_goal(accepted).await {
            Ok(x) => x,
            Err(e) => {
                warn(&h, &format!("starting a goal failed: {e:?}"));
                continue;
            }
        };
        let cancel = Arc::new(AtomicBool::new(false));
        running
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((executing.goal_id(), cancel.clone()));
        let job = execute(
            h.clone(),
            server.clone(),
            running.clone(),
            executing,
            req,
            cancel,
        );
        tokio::spawn(job);
    }
}

/// Plans for one goal, forwarding a feedback per round, then sends the result.
async fn execute(
    h: Handles,
    server: Arc<ActionServer>,
    running: Running,
    handle: ExecutingGoalHandle<PlanGoal>,
    req: super::wire::PlanRequest,
    cancel: Arc<AtomicBool>,
) {
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<PlanFeedback>();
    let (worker, flag) = (h.clone(), cancel.clone());
    let rounds = super::plan::rounds(&req);
    let job = tokio::task::spawn_blocking(move || {
        plan_call_with(&worker, &req, &mut |it| {
            // The receiver lives until the job ends.
            let _ = tx.send(PlanFeedback::of(it, rounds));
            !flag.load(Ordering::Acquire)
        })
    });
    let resp = super::qos::forward_feedback::<PlanAction, _>(&server, &handle, &mut rx, job).await;
    let id = handle.goal_id();
    running
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .retain(|(g, _)| *g != id);
    let resp = resp.unwrap_or_else(|join| super::wire::PlanResponse {
        message: format!("planning task failed: {join}"),
        ..Default::default()
    });
    let status = if !resp.success {
        GoalEndStatus::Aborted
    } else if cancel.load(Ordering::Acquire) {
        GoalEndStatus::Canceled
    } else {
        GoalEndStatus::Succeeded
    };
    // Resolves once the client has asked for the result.
    if let Err(e) = server
        .send_result_response(handle, status, PlanResult(resp))
        .await
    {
        warn(&h, &format!("sending the result failed: {e:?}"));
    }
}

/// Accepts cancel requests for running goals; others are refused.
async fn cancel_loop(h: Handles, server: Arc<ActionServer>, running: Running) {
    loop {
        let request = match server.receive_cancel_request().await {
            Ok(r) => r,
            Err(e) => {
                warn(&h, &format!("undecodable cancel request: {e:?}"));
                continue;
            }
        };
        let to_cancel: Vec<GoalId> = running
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .filter(|(id, _)| request.contains_goal(id))
            .map(|(id, flag)| {
                flag.store(true, Ordering::Release);
                *id
            })
            .collect();
        if !to_cancel.is_empty() {
            h.diag.log(
                LogLevel::Info,
                "Plan action: cancel requested; stopping after the current round",
            );
        }
        if let Err(e) = server
            .respond_to_cancel_requests(&request, to_cancel.into_iter())
            .await
        {
            warn(&h, &format!("answering a cancel failed: {e:?}"));
        }
    }
}
