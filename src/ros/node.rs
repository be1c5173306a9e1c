//! The node proper: DDS entities from the parameters, and the event loop that
//! answers incoming states and Rollout calls until SIGINT/SIGTERM.
//!
//! Model work runs on tokio's blocking pool so DDS discovery and the other
//! tasks keep going while a long rollout computes. Every failure is logged and
//! counted; nothing in the loop panics on bad input.

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::error::{err, Context as _};
use ros2_client::log::LogLevel;
use ros2_client::parameters::{NumericRange, ParameterDescriptor, ParameterType};
use ros2_client::{
    Context, ContextOptions, Node, NodeName, NodeOptions, ParameterValue, Publisher, Server,
    Subscription,
};

use crate::data::msg::ParticleState;
use crate::dynamics::Dynamics;

use super::accuracy::{self, Level};
use super::action::{self, TrainActionServer};
use super::calls::{plan_call, replay_call, rollout_call};
use super::handles::{
    Diagnostics, Handles, LiveParams, Logger, ModelHandle, RecorderHandle, Warning,
};
use super::input::Accepted;
use super::markers::prediction_markers;
use super::names::{Names, RosArgs};
use super::params::{runtime_settable, NodeParams, ParamError, ParamValue, Spec, NODE_NAME, SPECS};
use super::predict::{self, Prediction};
use super::qos::{clock_qos, publisher, reliable_qos, server, subscription, topic_qos};
use super::record::Recorder;
use super::service::{self, OnFailure::Warn};
use super::topics::{
    CLOCK_TOPIC, LIVE_ACCURACY_TOPIC, PLAN_SERVICE, REPLAY_SERVICE, STANDARD_DIAGNOSTICS_TOPIC,
};
use super::training::{self, Trainer, TrainerHandles, TrainingServers};
use super::wire::{ClockMsg, LoadModel, MarkerArray, Plan, Replay, Rollout, RosService, Train};
use super::wire::{
    DiagnosticArray, DiagnosticStatus, KeyValue, LiveAccuracy, NodeDiagnostics, ParticleForces,
    PlanRequest, PlanResponse, PredictedTrajectory, ReplayRequest, ReplayResponse, RolloutRequest,
    RolloutResponse, DIAGNOSTIC_OK, DIAGNOSTIC_WARN,
};
use super::yaml::Scalar;
use crate::data::stream::Reset;

/// Checks, records and predicts one incoming state, and scores it against
/// what was predicted for its moment (blocking work). `None`: a
/// position-only state kept as its stream's history while it warms up.
fn handle_state(
    h: &Handles,
    msg: ParticleState,
    received_ns: u64,
) -> Result<Option<(Prediction, accuracy::Update)>, predict::PredictError> {
    // Refused before anything is recorded or predicted: an oversized state
    // would hold memory and its prediction could not be delivered promptly.
    if let Some(why) = h.lifecycle.refusal() {
        return Err(predict::PredictError::Inactive(why));
    }
    let params = h.params.get();
    predict::check_size(&msg, params.max_particles)?;
    h.recorder.record(|r| r.state(received_ns, &msg));
    let id = msg.trajectory_id;
    let input = match h.inputs.accept(&params, msg)? {
        Accepted::Ready(input) => {
            note_reset(h, id, input.reset.as_ref());
            if input.derived {
                h.diag.stats.derived.fetch_add(1, Ordering::Relaxed);
            }
            input
        }
        Accepted::WarmingUp { reset, .. } => {
            note_reset(h, id, reset.as_ref());
            h.diag.stats.warming_up.fetch_add(1, Ordering::Relaxed);
            return Ok(None);
        }
    };
    let model = h.model.get();
    // A state the model was not trained for (another dimension, edge kinds
    // or field) is refused with the reason, not predicted.
    if let Some(t) = model.trained_for() {
        t.check(&input.graph, input.field.as_ref())?;
        if let Some(o) = t
            .range
            .as_ref()
            .and_then(|r| r.check(&input.graph, &input.state, params.out_of_range_sigmas))
        {
            h.diag.stats.out_of_range.fetch_add(1, Ordering::Relaxed);
            if params.out_of_range_refuse {
                return Err(predict::PredictError::OutOfRange(o));
            }
            h.diag.failed(
                &format!("out-of-range input, predicted anyway: {o}"),
                Warning::OutOfRange,
            );
        }
    }
    let p = predict::predict_parts(
        model.as_ref(),
        &input.message,
        &input.graph,
        &input.state,
        params.dt,
        params.horizon,
        params.substeps,
    )?;
    h.recorder
        .record(|r| r.prediction(h.clock.now_log_ns(), &p.trajectory, &p.forces));
    let scored = h.accuracy.update(&params, &input, &p);
    Ok(Some((p, scored)))
}

/// Counts and logs a stream starting over (not rate-limited: it happens once
/// per run, and says why predictions pause for a warm-up).
fn note_reset(h: &Handles, trajectory: u32, reset: Option<&Reset>) {
    if let Some(why) = reset {
        h.diag.stats.history_resets.fetch_add(1, Ordering::Relaxed);
        h.diag.log(
            LogLevel::Info,
            &format!("input stream {trajectory} starts over: {why}"),
        );
    }
}

/// The counters now, stamped with the node's clock.
fn node_diagnostics(h: &Handles) -> NodeDiagnostics {
    NodeDiagnostics {
        header: h.clock.header(),
        ..h.diag.snapshot(&h.model.get().describe())
    }
}

/// Follows `/clock` (with `use_sim_time`).
async fn clock_loop(h: Handles, sub: Subscription<ClockMsg>) {
    loop {
        match sub.async_take().await {
            Ok((msg, _)) => h.clock.set(&msg),
            Err(e) => h.diag.log(
                LogLevel::Warn,
                &format!("undecodable /clock message: {e:?}"),
            ),
        }
    }
}

/// A ROS parameter value as parameter-file text, for [`NodeParams::set`].
fn scalar(value: &ParameterValue) -> Scalar {
    match value {
        ParameterValue::Boolean(b) => Scalar::Bool(*b),
        ParameterValue::Integer(i) => Scalar::Int(*i),
        ParameterValue::Double(x) => Scalar::Float(*x),
        ParameterValue::String(s) => Scalar::Str(s.clone()),
        ParameterValue::DoubleArray(xs) => {
            Scalar::List(xs.iter().map(|x| Scalar::Float(*x)).collect())
        }
        ParameterValue::IntegerArray(xs) => {
            Scalar::List(xs.iter().map(|i| Scalar::Int(*i)).collect())
        }
        other => Scalar::Str(format!("{other:?}")),
    }
}

/// Checks a run-time change of parameter `name` against `current`: only
/// parameters settable at run time ([`Spec::runtime`]), with the same type and range checks as at
/// start. The refusal says why and what to do instead.
pub fn check_runtime_change(
    current: &NodeParams,
    name: &str,
    value: &ParameterValue,
) -> Result<NodeParams, ParamError> {
    if !runtime_settable(name) {
        return Err(ParamError::NotRuntime(name.to_string()));
    }
    let mut p = current.clone();
    p.set(name, &scalar(value), false)?;
    p.check_together()?;
    Ok(p)
}

/// What `describe_parameters` (`ros2 param describe`) answers for a
/// parameter of the one table: its documentation, whether it can change at
/// run time, and its range.
fn descriptor(
    &Spec {
        name,
        kind,
        doc,
        runtime,
    }: &Spec,
) -> ParameterDescriptor {
    use super::params::Kind;
    let range = match kind {
        Kind::Int(lo, hi) => NumericRange::IntegerRange {
            from_value: i64::from(lo),
            to_value: i64::from(hi),
            step: 1,
        },
        Kind::Double(_) => NumericRange::FloatingPointRange {
            from_value: 0.0,
            to_value: f64::MAX,
            step: 0.0,
        },
        _ => NumericRange::NotSpecified,
    };
    let constraints = match kind {
        Kind::Topic => "a ROS 2 name: absolute (/a), relative to the namespace (a) or to the \
                        node (~/a)"
            .to_string(),
        Kind::Double(true) => "finite and > 0".to_string(),
        Kind::Double(false) => "finite and >= 0".to_string(),
        Kind::Doubles(max) => format!("at most {max} finite numbers > 0"),
        Kind::Choice(words) => format!("one of {}", words.join(", ")),
        _ => String::new(),
    };
    ParameterDescriptor {
        name: name.to_string(),
        param_type: ParameterType::NotSet,
        description: doc.to_string(),
        additional_constraints: constraints,
        read_only: !runtime,
        dynamic_typing: false,
        range,
    }
}

/// Every parameter of [`SPECS`] as a ROS parameter, so rclpy can list and
/// get them all; those settable at run time ([`Spec::runtime`]) can be set
/// (validated, then applied to `live`), the others refuse with the reason.
fn declare_parameters(p: &NodeParams, live: LiveParams) -> NodeOptions {
    let values: Vec<(&'static str, ParameterValue)> = SPECS
        .iter()
        .filter_map(|s| {
            let v = match p.value(s.name)? {
                ParamValue::Str(x) => ParameterValue::String(x.to_string()),
                ParamValue::Bool(x) => ParameterValue::Boolean(x),
                ParamValue::Int(x) => ParameterValue::Integer(i64::from(x)),
                ParamValue::Double(x) => ParameterValue::Double(x),
                ParamValue::Doubles(xs) => ParameterValue::DoubleArray(xs.to_vec()),
            };
            Some((s.name, v))
        })
        .collect();
    let initial = values.clone();
    let (check, apply) = (live.clone(), live);
    let described = SPECS
        .iter()
        .fold(NodeOptions::new().enable_rosout(true), |o, s| {
            o.describe_parameter(descriptor(s))
        });
    values
        .into_iter()
        .fold(described, |o, (k, v)| o.declare_parameter(k, v))
        // Declaring goes through the validator too: the start values pass.
        .parameter_validator(Box::new(move |name, value| {
            if initial.iter().any(|(k, v)| *k == name && v == value) {
                return Ok(());
            }
            // ros2-client takes the refusal as text.
            check_runtime_change(&check.get(), name, value)
                .map(|_| ())
                .map_err(|e| e.to_string())
        }))
        // Runs after the validator, and for every declared value at start.
        // Other parameters (read-only ones, ros2-client's use_sim_time) need
        // nothing here: the validator refuses changes to the read-only ones.
        .parameter_set_action(Box::new(move |name, value| {
            if !runtime_settable(name) {
                return Ok(());
            }
            apply
                .update(|current| check_runtime_change(current, name, value))
                .map_err(|e| e.to_string())
        }))
}

/// The node's own DDS endpoints (training's are in [`training::create`] and
/// [`action::create`]).
struct Endpoints {
    input: Subscription<ParticleState>,
    trajectory: Publisher<PredictedTrajectory>,
    forces: Publisher<ParticleForces>,
    accuracy: Publisher<LiveAccuracy>,
    markers: Publisher<MarkerArray>,
    diagnostics: Publisher<NodeDiagnostics>,
    standard_diagnostics: Publisher<DiagnosticArray>,
    rollout: Server<RolloutRequest, RolloutResponse>,
    replay: Server<ReplayRequest, ReplayResponse>,
    plan: Server<PlanRequest, PlanResponse>,
    /// With `use_sim_time` only.
    clock: Option<Subscription<ClockMsg>>,
}

impl Endpoints {
    /// Topics, publishers, subscriptions and servers as the parameters say.
    fn create(
        node: &mut Node,
        params: &NodeParams,
        names: &Names,
    ) -> crate::error::Result<Endpoints> {
        let qos = topic_qos(params);
        Ok(Endpoints {
            input: subscription(node, names, &params.input_topic, &qos)?,
            trajectory: publisher(node, names, &params.trajectory_topic, &qos)?,
            forces: publisher(node, names, &params.forces_topic, &qos)?,
            accuracy: publisher(node, names, LIVE_ACCURACY_TOPIC, &qos)?,
            markers: publisher(node, names, &params.markers_topic, &qos)?,
            diagnostics: publisher(node, names, &params.diagnostics_topic, &qos)?,
            standard_diagnostics: publisher(
                node,
                names,
                STANDARD_DIAGNOSTICS_TOPIC,
                &reliable_qos(),
            )?,
            rollout: server::<Rollout>(node, names, &params.rollout_service)?,
            replay: server::<Replay>(node, names, REPLAY_SERVICE)?,
            plan: server::<Plan>(node, names, PLAN_SERVICE)?,
            clock: if params.use_sim_time {
                Some(subscription(node, names, CLOCK_TOPIC, &clock_qos())?)
            } else {
                None
            },
        })
    }

    /// Starts one task per loop: input, diagnostics, /clock, and one per
    /// service (inside the runtime).
    fn spawn(self, h: &Handles, trainer: &Arc<Trainer>) {
        let outputs = Outputs {
            trajectory: self.trajectory,
            forces: self.forces,
            accuracy: self.accuracy,
            markers: self.markers,
            last_markers: None,
        };
        let input = input_loop(h.clone(), self.input, outputs, trainer.clone());
        tokio::spawn(input);
        tokio::spawn(diagnostics_loop(
            h.clone(),
            self.diagnostics,
            self.standard_diagnostics,
        ));
        if let Some(sub) = self.clock {
            tokio::spawn(clock_loop(h.clone(), sub));
        }
        let d = h.diag.clone();
        let rollout = service::serve(
            h.clone(),
            d.clone(),
            self.rollout,
            Rollout::NAME,
            Warn,
            rollout_call,
        );
        tokio::spawn(rollout);
        tokio::spawn(service::serve(
            h.clone(),
            d.clone(),
            self.replay,
            Replay::NAME,
            Warn,
            replay_call,
        ));
        tokio::spawn(service::serve(
            h.clone(),
            d,
            self.plan,
            Plan::NAME,
            Warn,
            plan_call,
        ));
    }
}

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
    let (trainer, servers) = training::create(&mut node, &params, &names, trainer_handles(&h))?;
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

/// Starts the Train and LoadModel services and the Train action.
fn spawn_training(
    trainer: Arc<Trainer>,
    servers: TrainingServers,
    action_server: TrainActionServer,
) {
    use service::OnFailure::Quiet;
    let d = trainer.diagnostics();
    let (train, load) = (servers.train, servers.load);
    tokio::spawn(service::serve(
        trainer.clone(),
        d.clone(),
        train,
        Train::NAME,
        Quiet,
        training::train_call,
    ));
    tokio::spawn(service::serve(
        trainer.clone(),
        d,
        load,
        LoadModel::NAME,
        Quiet,
        training::load_call,
    ));
    action::spawn(trainer, action_server);
}

/// Says what the node serves, where.
fn log_start(h: &Handles, names: &Names, domain_id: u16) {
    let p = h.params.get();
    h.diag.log(
        LogLevel::Info,
        &format!(
            "serving {} in domain {domain_id}: {} -> {} + {} (horizon {}, dt {}), service {}",
            h.model.get().describe(),
            p.input_topic,
            p.trajectory_topic,
            p.forces_topic,
            p.horizon,
            p.dt,
            p.rollout_service
        ),
    );
    if p.lifecycle {
        h.diag.log(
            LogLevel::Info,
            &format!(
                "managed lifecycle: unconfigured, predicting nothing until configure and \
                 activate ({}/change_state)",
                names.fqn()
            ),
        );
    }
    if !p.accuracy_lead_times.is_empty() {
        let t = accuracy::Tracker::new(&p.accuracy_lead_times, 1, 1);
        let reachable: Vec<f64> = t
            .steps(p.dt, p.horizon)
            .iter()
            .map(|(i, _)| p.accuracy_lead_times[*i])
            .collect();
        let level = if reachable.len() == p.accuracy_lead_times.len() {
            LogLevel::Info
        } else {
            LogLevel::Warn
        };
        // A lead the prediction does not reach, or not a whole number of
        // steps, is never compared: say so once rather than stay silent.
        h.diag.log(
            level,
            &format!(
                "live accuracy on {LIVE_ACCURACY_TOPIC} at lead times {:?} s; comparable with \
                 horizon {} x dt {}: {reachable:?}",
                p.accuracy_lead_times, p.horizon, p.dt
            ),
        );
    }
}

/// Closes the open bag at shutdown and says what was recorded.
fn finish_recording(h: &Handles) {
    match h.recorder.finish() {
        None => {}
        Some(Ok((dir, finished))) => h.diag.log(
            LogLevel::Info,
            &format!("recorded {} bag(s) in {}", finished.len(), dir.display()),
        ),
        Some(Err(e)) => h.diag.log(LogLevel::Error, &e.to_string()),
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

/// What the input loop publishes.
struct Outputs {
    trajectory: Publisher<PredictedTrajectory>,
    forces: Publisher<ParticleForces>,
    accuracy: Publisher<LiveAccuracy>,
    markers: Publisher<MarkerArray>,
    /// When the last markers went out (`markers_period`).
    last_markers: Option<Instant>,
}

/// The markers of `p` when they are on and `markers_period` has passed since
/// the last ones (`last` is then reset).
fn markers_due(
    params: &NodeParams,
    last: &mut Option<Instant>,
    p: &Prediction,
) -> Option<MarkerArray> {
    let due =
        params.markers && last.is_none_or(|t| t.elapsed().as_secs_f64() >= params.markers_period);
    due.then(|| {
        *last = Some(Instant::now());
        prediction_markers(&p.trajectory, &p.forces)
    })
}

/// Logs a change of the drift alarm: at its level, or as news when it clears.
fn log_alarm(h: &Handles, level: Level, why: &str) {
    let log_level = match level {
        Level::Ok => LogLevel::Info,
        Level::Warn => LogLevel::Warn,
        Level::Error => LogLevel::Error,
    };
    let prefix = if level == Level::Ok {
        "drift alarm cleared: "
    } else {
        ""
    };
    h.diag.log(log_level, &format!("{prefix}{why}"));
}

/// For each incoming state: predict, publish trajectory and forces, and the
/// live accuracy when the state was compared with earlier predictions; a
/// drift alarm starts a retraining with `trainer` when `accuracy_retrain` is on.
async fn input_loop(
    h: Handles,
    input: Subscription<ParticleState>,
    mut out: Outputs,
    trainer: Arc<Trainer>,
) {
    let stats = &h.diag.stats;
    // Last sequence number seen from each publisher.
    let mut last_seen: std::collections::HashMap<String, i64> = Default::default();
    loop {
        let msg = match input.async_take().await {
            Ok((msg, info)) => {
                let gap = sequence_gap(&mut last_seen, &info);
                stats.dropped.fetch_add(gap, Ordering::Relaxed);
                msg
            }
            Err(e) => {
                // A sample that does not decode as a ParticleState.
                stats.received.fetch_add(1, Ordering::Relaxed);
                h.diag.reject(&format!("undecodable ParticleState: {e:?}"));
                continue;
            }
        };
        stats.received.fetch_add(1, Ordering::Relaxed);
        let received_ns = h.clock.now_log_ns();
        let worker = h.clone();
        let job = tokio::task::spawn_blocking(move || handle_state(&worker, msg, received_ns));
        let (prediction, scored) = match job.await {
            Ok(Ok(Some(p))) => p,
            Ok(Ok(None)) => continue,
            Ok(Err(why)) => {
                h.diag.reject(&format!("rejected input: {why}"));
                continue;
            }
            Err(join) => {
                h.diag.reject(&format!("prediction task failed: {join}"));
                continue;
            }
        };
        if let Some((level, why)) = &scored.alarm_changed {
            log_alarm(&h, *level, why);
            let p = h.params.get();
            if *level != Level::Ok && p.accuracy_retrain {
                // Off the input loop: it records for a while, then trains.
                let (trainer, why) = (trainer.clone(), why.clone());
                tokio::task::spawn_blocking(move || {
                    // The outcome is logged by retrain_on_drift itself.
                    let _ = training::retrain_on_drift(&trainer, &p, &why);
                });
            }
        }
        out.publish(&h, prediction, scored.message).await;
    }
}

/// States a publisher sent that never reached us: the gap in its DDS
/// sequence numbers since the last sample taken from it.
fn sequence_gap(
    last_seen: &mut std::collections::HashMap<String, i64>,
    info: &ros2_client::MessageInfo,
) -> u64 {
    let publisher = format!("{:?}", info.publisher_gid());
    let sn = info.sequence_number();
    last_seen.insert(publisher, sn).map_or(0, |prev| {
        u64::try_from(sn.saturating_sub(prev).saturating_sub(1)).unwrap_or(0)
    })
}

impl Outputs {
    /// Publishes a prediction (trajectory, forces, the markers when due) and
    /// the live accuracy; counts it as predicted when trajectory and forces
    /// went out, else warns.
    async fn publish(&mut self, h: &Handles, p: Prediction, accuracy: Option<LiveAccuracy>) {
        let markers = markers_due(&h.params.get(), &mut self.last_markers, &p);
        let sent_traj = self.trajectory.async_publish(p.trajectory).await;
        let sent_forces = self.forces.async_publish(p.forces).await;
        if let Some(m) = markers {
            h.recorder.record(|r| r.markers(h.clock.now_log_ns(), &m));
            if let Err(e) = self.markers.async_publish(m).await {
                let why = format!("publishing the markers failed: {e:?}");
                h.diag.failed(&why, Warning::Input);
            }
        }
        if let Some(m) = accuracy {
            if let Err(e) = self.accuracy.async_publish(m).await {
                let why = format!("publishing the live accuracy failed: {e:?}");
                h.diag.failed(&why, Warning::Input);
            }
        }
        let failed = match (sent_traj, sent_forces) {
            (Ok(()), Ok(())) => None,
            (Err(e), _) => Some(format!("publishing the trajectory failed: {e:?}")),
            (_, Err(e)) => Some(format!("publishing the forces failed: {e:?}")),
        };
        match failed {
            None => {
                h.diag.stats.predicted.fetch_add(1, Ordering::Relaxed);
            }
            Some(why) => h.diag.failed(&why, Warning::Input),
        }
    }
}

/// The counters as a standard `DiagnosticArray` with one status, `mcgnode:
/// predictions`: WARN when states were rejected or dropped since the previous
/// report (`before`), OK otherwise.
pub fn standard_diagnostics(
    d: &NodeDiagnostics,
    dropped: u64,
    before: (u64, u64),
) -> DiagnosticArray {
    let (rejected_now, dropped_now) = (
        d.rejected.saturating_sub(before.0),
        dropped.saturating_sub(before.1),
    );
    let (level, message) = if rejected_now > 0 || dropped_now > 0 {
        (
            DIAGNOSTIC_WARN,
            format!(
                "{rejected_now} states rejected, {dropped_now} dropped since the last report; \
                 last error: {}",
                d.last_error
            ),
        )
    } else {
        (DIAGNOSTIC_OK, format!("serving {}", d.model))
    };
    let kv = |key: &str, value: String| KeyValue {
        key: key.into(),
        value,
    };
    DiagnosticArray {
        header: d.header.clone(),
        status: vec![DiagnosticStatus {
            level,
            name: format!("{NODE_NAME}: predictions"),
            message,
            hardware_id: NODE_NAME.into(),
            values: vec![
                kv("received", d.received.to_string()),
                kv("rejected", d.rejected.to_string()),
                kv("predicted", d.predicted.to_string()),
                kv("out_of_range", d.out_of_range.to_string()),
                kv("derived", d.derived.to_string()),
                kv("warming_up", d.warming_up.to_string()),
                kv("history_resets", d.history_resets.to_string()),
                kv("dropped", dropped.to_string()),
                kv("last_error", d.last_error.clone()),
                kv("model", d.model.clone()),
            ],
        }],
    }
}

/// Live accuracy as a standard diagnostic status, `mcgnode: live accuracy`:
/// the drift alarm's level and message, and per lead time the running and
/// latest RE and EE and the number of comparisons (`re_mean@0.5s`, ...).
pub fn accuracy_status(
    figures: &[accuracy::LeadAccuracy],
    level: Level,
    why: &str,
    overflowed: u64,
) -> DiagnosticStatus {
    let kv = |key: String, value: String| KeyValue { key, value };
    let mut values = Vec::with_capacity(5 * figures.len() + 1);
    for f in figures {
        let at = |what: &str| format!("{what}@{}s", f.lead);
        values.push(kv(at("compared"), f.compared.to_string()));
        values.push(kv(at("re_mean"), format!("{:.6e}", f.re_mean)));
        values.push(kv(at("re"), format!("{:.6e}", f.re)));
        values.push(kv(at("ee_mean"), format!("{:.6e}", f.ee_mean)));
        values.push(kv(at("ee"), format!("{:.6e}", f.ee)));
    }
    values.push(kv("pending_dropped".into(), overflowed.to_string()));
    DiagnosticStatus {
        level: level as u8,
        name: format!("{NODE_NAME}: live accuracy"),
        message: why.to_string(),
        hardware_id: NODE_NAME.into(),
        values,
    }
}

/// Publishes `NodeDiagnostics` and the standard `/diagnostics` every
/// `diagnostics_period`.
async fn diagnostics_loop(
    h: Handles,
    publisher: Publisher<NodeDiagnostics>,
    standard: Publisher<DiagnosticArray>,
) {
    let period = h.params.get().diagnostics_period;
    let mut tick = tokio::time::interval(Duration::from_secs_f64(period));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut before = (0, 0);
    loop {
        tick.tick().await;
        let d = node_diagnostics(&h);
        let dropped = h.diag.stats.dropped.load(Ordering::Relaxed);
        let mut array = standard_diagnostics(&d, dropped, before);
        if let Some((figures, level, why, overflowed)) = h.accuracy.figures(&h.params.get()) {
            array
                .status
                .push(accuracy_status(&figures, level, &why, overflowed));
        }
        before = (d.rejected, dropped);
        if let Err(e) = publisher.async_publish(d).await {
            eprintln!("[WARN] [{NODE_NAME}]: publishing diagnostics failed: {e:?}");
        }
        if let Err(e) = standard.async_publish(array).await {
            eprintln!("[WARN] [{NODE_NAME}]: publishing /diagnostics failed: {e:?}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_diagnostics_warn_on_new_rejections_only() {
        let d = NodeDiagnostics {
            received: 10,
            rejected: 3,
            predicted: 7,
            last_error: "state too large".into(),
            model: "truth:spring".into(),
            ..NodeDiagnostics::default()
        };
        let a = standard_diagnostics(&d, 2, (1, 2));
        let s = &a.status[0];
        assert_eq!(s.level, DIAGNOSTIC_WARN);
        assert!(
            s.message.contains("2 states rejected, 0 dropped"),
            "{}",
            s.message
        );
        assert!(s.message.contains("state too large"), "{}", s.message);
        let value = |k: &str| {
            s.values
                .iter()
                .find(|v| v.key == k)
                .map(|v| v.value.clone())
        };
        assert_eq!(value("dropped").as_deref(), Some("2"));
        assert_eq!(value("predicted").as_deref(), Some("7"));
        let quiet = standard_diagnostics(&d, 2, (3, 2));
        assert_eq!(quiet.status[0].level, DIAGNOSTIC_OK);
    }

    #[test]
    fn lead_times_change_at_run_time_from_a_double_array() {
        let p = NodeParams::default();
        let set = |v| check_runtime_change(&p, "accuracy_lead_times", &v);
        let q = set(ParameterValue::DoubleArray(vec![0.1, 1.0])).unwrap();
        assert_eq!(q.accuracy_lead_times, vec![0.1, 1.0]);
        let q = set(ParameterValue::IntegerArray(vec![1, 2])).unwrap();
        assert_eq!(q.accuracy_lead_times, vec![1.0, 2.0]);
        let e = set(ParameterValue::DoubleArray(vec![0.1, 0.0]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("must be finite and > 0"), "{e}");
        let e = set(ParameterValue::Double(0.5)).unwrap_err().to_string();
        assert!(e.contains("must be a list"), "{e}");
    }

    #[test]
    fn accuracy_status_carries_level_lead_and_values() {
        let f = accuracy::LeadAccuracy {
            lead: 0.5,
            compared: 4,
            re: 0.03,
            re_mean: 0.02,
            ee: f64::NAN,
            ee_mean: f64::NAN,
        };
        let (level, why) = accuracy::alarm(std::slice::from_ref(&f), 0.01, 0.1);
        let s = accuracy_status(&[f], level, &why, 0);
        assert_eq!(s.level, crate::ros::wire::DIAGNOSTIC_WARN);
        assert!(s.message.contains("lead 0.5 s"), "{}", s.message);
        let get = |k: &str| s.values.iter().find(|v| v.key == k).map(|v| &v.value);
        assert_eq!(get("compared@0.5s").map(String::as_str), Some("4"));
        assert_eq!(get("re_mean@0.5s").map(String::as_str), Some("2.000000e-2"));
        assert_eq!(get("ee_mean@0.5s").map(String::as_str), Some("NaN"));
    }
}
