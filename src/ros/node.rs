//! The node proper: DDS entities from the parameters, wired to the shared
//! handles, and the tasks that answer incoming states and calls until
//! SIGINT/SIGTERM ([`super::endpoints`], [`super::input_loop`],
//! [`super::diagnostics`]; parameters in [`super::param_server`]).
//!
//! Model work runs on tokio's blocking pool so DDS discovery and the other
//! tasks keep going while a long rollout computes. Every failure is logged and
//! counted; nothing in the loop panics on bad input.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use crate::error::{err, Context as _};
use ros2_client::log::LogLevel;
use ros2_client::{Context, ContextOptions, Node, NodeName};

use crate::dynamics::Dynamics;

use super::accuracy;
use super::action;
use super::diagnostics::{finish_recording, log_start};
use super::endpoints::{spawn_training, Endpoints};
use super::handles::{Diagnostics, Handles, LiveParams, Logger, ModelHandle, RecorderHandle};
use super::param_server::declare_parameters;
use super::params::{NodeParams, NODE_NAME};
use super::record::Recorder;
use super::resource_names::{Names, RosArgs};
use super::trainer::{self, TrainerHandles};

/// The handles of a node serving `model`, logging through `node` at
/// `log_level` and above.
fn handles(
    node: &Node,
    (params, names, log_level): (&NodeParams, &Names, Option<LogLevel>),
    live: LiveParams,
    (model, file): (Arc<dyn Dynamics>, Option<PathBuf>),
) -> crate::error::Result<Handles> {
    let recorder = if params.record_dir.is_empty() {
        None
    } else {
        Some(Recorder::new(params, &model.describe())?)
    };
    let diag = Arc::new(Diagnostics::new(
        Logger::new(node.logging_handle(), names.node(), log_level),
        live.clone(),
    ));
    Ok(Handles {
        params: live,
        model: Arc::new(ModelHandle::new(model, file)),
        recorder: Arc::new(RecorderHandle::new(recorder, diag.clone())),
        diag,
        clock: Arc::new(super::clock::Clock::new(params.use_sim_time)),
        accuracy: Arc::new(accuracy::Live::default()),
        inputs: Arc::new(super::input::Inputs::default()),
        passed: Arc::new(crate::compat::Passed::default()),
        predicted: Default::default(),
        lifecycle: Arc::new(super::lifecycle::Lifecycle::new(if params.lifecycle {
            super::lifecycle::Primary::Unconfigured
        } else {
            super::lifecycle::Primary::Active
        })),
    })
}

/// Runs the node in `domain_id` until SIGINT or SIGTERM, named and
/// remapped as `ros` (`--ros-args`) says, serving `model` (loaded from
/// `file`, when it is one: what fine-tuning starts from).
pub fn serve(
    params: NodeParams,
    ros: &RosArgs,
    model: (Arc<dyn Dynamics>, Option<PathBuf>),
    domain_id: u16,
) -> crate::error::Result<()> {
    let names = ros.names()?;
    // Every topic and service parameter as the absolute name it resolves to,
    // for the endpoints, the recordings and the log alike.
    let params = params.resolved(&names)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let live = LiveParams::new(params.clone());
    let context = Context::with_options(ContextOptions::new().domain_id(domain_id))
        .map_err(|e| err!("creating the DDS participant in domain {domain_id}: {e:?}"))?;
    let name =
        NodeName::new(names.namespace(), names.node()).map_err(|e| err!("node name: {e:?}"))?;
    let mut node = context
        .new_node(name, declare_parameters(&params, live.clone()))
        .map_err(|e| err!("creating the node: {e:?}"))?;
    let endpoints = Endpoints::create(&mut node, &params, &names)?;
    let h = handles(&node, (&params, &names, ros.log_level), live, model)?;
    let (trainer, servers) = trainer::create(&mut node, &params, &names, trainer_handles(&h))?;
    let action_server = action::create(&mut node, &names)?;
    let plan_action = super::plan_action::create(&mut node, &names)?;
    let lifecycle = super::lifecycle_services::create(&mut node, &names)?;
    let spinner = node
        .spinner()
        .map_err(|e| err!("the node spinner: {e:?}"))?;
    log_start(&h, &names, domain_id);
    let result = runtime.block_on(async {
        tokio::spawn(async move {
            if let Err(e) = spinner.spin().await {
                eprintln!("[ERROR] [{NODE_NAME}]: node spinner stopped: {e:?}");
            }
        });
        endpoints.spawn(&h, &trainer);
        tokio::spawn(h.recorder.clone().flush_loop());
        super::plan_action::spawn(h.clone(), plan_action);
        spawn_training(trainer, servers, action_server);
        super::lifecycle_services::spawn(
            h.lifecycle.clone(),
            h.diag.clone(),
            h.clock.clone(),
            lifecycle,
        );
        wait_for_shutdown().await
    });
    h.diag
        .log(LogLevel::Info, "shutting down (signal received)");
    node.stop_spinner();
    // Cancel the tasks (and drop their DDS entities) before the participant.
    runtime.shutdown_timeout(Duration::from_secs(2));
    finish_recording(&h);
    drop(node);
    drop(context);
    result
}

/// The handles training works with.
fn trainer_handles(h: &Handles) -> TrainerHandles {
    TrainerHandles {
        model: h.model.clone(),
        recorder: h.recorder.clone(),
        diag: h.diag.clone(),
        clock: h.clock.clone(),
    }
}

/// Resolves on the first SIGINT or SIGTERM.
async fn wait_for_shutdown() -> crate::error::Result<()> {
    use tokio::signal::unix::{signal, SignalKind};
    let mut term = signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
    let mut int = signal(SignalKind::interrupt()).context("installing the SIGINT handler")?;
    tokio::select! {
        _ = term.recv() => {}
        _ = int.recv() => {}
    }
    Ok(())
}
