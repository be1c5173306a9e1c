//! The node proper: DDS entities from the parameters, and the event loop that
//! answers incoming states and Rollout calls until SIGINT/SIGTERM.
//!
//! Model work runs on tokio's blocking pool so DDS discovery and the other
//! tasks keep going while a long rollout computes. Every failure is logged and
//! counted; nothing in the loop panics on bad input.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError, RwLock};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{anyhow, Context as _};
use ros2_client::log::LogLevel;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::rosout::{NodeLoggingHandle, RosoutRaw};
use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, NodeName, NodeOptions, ParameterValue,
    Publisher, QosProfile, Server, ServiceMapping, ServiceTypeName, Subscription,
};

use crate::data::msg::{ParticleState, PARTICLE_STATE_TYPE};
use crate::dynamics::Dynamics;

use super::msgs::{
    DiagnosticArray, DiagnosticStatus, KeyValue, NodeDiagnostics, ParticleForces,
    PredictedTrajectory, ReplayRequest, ReplayResponse, RolloutRequest, RolloutResponse,
    DIAGNOSTIC_OK, DIAGNOSTIC_WARN, PACKAGE,
};
use super::params::{NodeParams, NODE_NAME, RUNTIME_SETTABLE};
use super::predict::{self, Prediction};
use super::record::Recorder;
use super::service::{self, OnFailure::Warn};
use super::yaml::Scalar;

/// Counters reported in `NodeDiagnostics`.
#[derive(Debug, Default)]
pub struct Stats {
    /// States received.
    pub received: AtomicU64,
    /// States rejected (malformed, unsupported, or the model failed).
    pub rejected: AtomicU64,
    /// Predictions published.
    pub predicted: AtomicU64,
    /// States lost before the node took them: gaps in a publisher's sequence
    /// numbers (e.g. the input queue overflowed while the node was busy).
    pub dropped: AtomicU64,
    /// Latest failure reason.
    pub last_error: Mutex<String>,
}

/// At most one warning per period; the next one says how many were held back.
#[derive(Debug)]
pub struct RateLimiter {
    period: Duration,
    last: Option<Instant>,
    suppressed: u64,
}

impl RateLimiter {
    /// A limiter letting one event through per `period`.
    pub fn new(period: Duration) -> Self {
        RateLimiter {
            period,
            last: None,
            suppressed: 0,
        }
    }

    /// `Some(n)` if an event at `now` may be reported, `n` being how many were
    /// suppressed since the last report; `None` if it must be suppressed.
    pub fn allow(&mut self, now: Instant) -> Option<u64> {
        match self.last {
            Some(t) if now.saturating_duration_since(t) < self.period => {
                self.suppressed += 1;
                None
            }
            _ => {
                self.last = Some(now);
                Some(std::mem::take(&mut self.suppressed))
            }
        }
    }
}

/// Logs to stderr and to /rosout.
pub struct Logger {
    rosout: NodeLoggingHandle,
}

impl Logger {
    /// Logs `msg` at `level`.
    pub fn log(&self, level: LogLevel, msg: &str) {
        let tag = match level {
            LogLevel::Fatal => "FATAL",
            LogLevel::Error => "ERROR",
            LogLevel::Warn => "WARN",
            LogLevel::Info => "INFO",
            LogLevel::Debug => "DEBUG",
        };
        eprintln!("[{tag}] [{:.6}] [{NODE_NAME}]: {msg}", wall_secs());
        self.rosout.rosout_raw(
            ros2_client::builtin_interfaces::Time::now(),
            level,
            NODE_NAME,
            msg,
            file!(),
            "",
            line!(),
        );
    }
}

/// What the tasks share.
pub(super) struct Shared {
    /// The parameters now: those in [`RUNTIME_SETTABLE`] change at run time.
    params: Arc<RwLock<NodeParams>>,
    /// Behind a lock so a model swap (Train, LoadModel) can replace it.
    pub(super) model: RwLock<Arc<dyn Dynamics>>,
    stats: Stats,
    /// Limits warnings about bad input states.
    warn_input: Mutex<RateLimiter>,
    /// Limits warnings about failed service calls (the caller gets the reason).
    warn_service: Mutex<RateLimiter>,
    /// Limits warnings about recording failures.
    warn_record: Mutex<RateLimiter>,
    pub(super) log: Logger,
    /// System time, or `/clock` with `use_sim_time`.
    pub(super) clock: super::clock::Clock,
    /// MCAP recording, when `record_dir` is set.
    pub(super) recorder: Option<Mutex<Recorder>>,
    /// Train/LoadModel state and the swap announcer.
    pub(super) training: super::training::Training,
}

impl Shared {
    /// A copy of the parameters now.
    pub(super) fn params(&self) -> NodeParams {
        self.params
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// The model served now.
    pub(super) fn model(&self) -> Arc<dyn Dynamics> {
        self.model
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// A failed service call: last error and a rate-limited warning.
    pub(super) fn service_failed(&self, why: &str) {
        self.failed(why, &self.warn_service);
    }

    /// Counts a rejected input and warns, rate-limited.
    fn reject(&self, why: &str) {
        self.stats.rejected.fetch_add(1, Ordering::Relaxed);
        self.failed(why, &self.warn_input);
    }

    /// Records a failure as the last error and warns, rate-limited by `limiter`.
    fn failed(&self, why: &str, limiter: &Mutex<RateLimiter>) {
        why.clone_into(
            &mut self
                .stats
                .last_error
                .lock()
                .unwrap_or_else(PoisonError::into_inner),
        );
        let period = Duration::from_secs_f64(self.params().warn_period);
        let allowed = {
            let mut l = limiter.lock().unwrap_or_else(PoisonError::into_inner);
            l.period = period;
            l.allow(Instant::now())
        };
        if let Some(suppressed) = allowed {
            let more = if suppressed > 0 {
                format!(" ({suppressed} similar warnings suppressed)")
            } else {
                String::new()
            };
            self.log.log(LogLevel::Warn, &format!("{why}{more}"));
        }
    }

    /// Records with the recorder, if any; failures are warned about.
    pub(super) fn record(&self, what: impl FnOnce(&mut Recorder) -> Result<(), String>) {
        if let Some(r) = &self.recorder {
            let result = what(&mut r.lock().unwrap_or_else(PoisonError::into_inner));
            if let Err(e) = result {
                self.failed(&e, &self.warn_record);
            }
        }
    }

    /// Checks, records and predicts one incoming state (blocking work).
    fn handle_state(&self, msg: ParticleState, received_ns: u64) -> Result<Prediction, String> {
        // Refused before anything is recorded or predicted: an oversized state
        // would hold memory and its prediction could not be delivered promptly.
        let params = self.params();
        predict::check_size(&msg, params.max_particles)?;
        self.record(|r| r.state(received_ns, &msg));
        let model = self.model();
        // A state the model was not trained for (another dimension, edge kinds
        // or field) is refused with the reason, not predicted.
        if let Some(t) = model.trained_for() {
            let (graph, _) = msg.to_parts().map_err(|e| e.to_string())?;
            let field = msg.field().map_err(|e| e.to_string())?;
            t.check(&graph, field.as_ref()).map_err(|e| e.to_string())?;
        }
        let p = predict::predict(
            model.as_ref(),
            &msg,
            params.dt,
            params.horizon,
            params.substeps,
        )?;
        self.record(|r| r.prediction(self.clock.now_log_ns(), &p.trajectory, &p.forces));
        Ok(p)
    }

    fn diagnostics(&self) -> NodeDiagnostics {
        NodeDiagnostics {
            header: self.clock.header(),
            received: self.stats.received.load(Ordering::Relaxed),
            rejected: self.stats.rejected.load(Ordering::Relaxed),
            predicted: self.stats.predicted.load(Ordering::Relaxed),
            last_error: self
                .stats
                .last_error
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone(),
            model: self.model().describe(),
        }
    }
}

/// Seconds since the Unix epoch (0 if the clock is before it).
fn wall_secs() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// Topic QoS from the parameters: volatile, keep-last `qos_depth`.
fn topic_qos(p: &NodeParams) -> QosProfile {
    let q = QosProfile::publisher_default()
        .durability(Durability::Volatile)
        .history(History::KeepLast {
            depth: p.qos_depth as usize,
        });
    if p.qos_reliable {
        q.reliability_reliable(WhenFull::DEFAULT)
    } else {
        q.reliability_best_effort()
    }
}

/// `/clock` QoS: best-effort keep-last 1 (as rclpy's time source), which
/// matches reliable and best-effort publishers.
fn clock_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_best_effort()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 1 })
}

/// Follows `/clock` (with `use_sim_time`).
async fn clock_loop(shared: Arc<Shared>, sub: Subscription<super::clock::ClockMsg>) {
    loop {
        match sub.async_take().await {
            Ok((msg, _)) => shared.clock.set(&msg),
            Err(e) => shared.log.log(
                LogLevel::Warn,
                &format!("undecodable /clock message: {e:?}"),
            ),
        }
    }
}

/// Service QoS that rclpy clients match: reliable, volatile, keep-last 10.
fn service_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

fn ros_name(s: &str) -> anyhow::Result<Name> {
    Name::parse(s).map_err(|e| anyhow!("invalid ROS name {s:?}: {e:?}"))
}

/// A ROS parameter value as parameter-file text, for [`NodeParams::set`].
fn scalar(value: &ParameterValue) -> Scalar {
    match value {
        ParameterValue::Boolean(b) => Scalar::Bool(*b),
        ParameterValue::Integer(i) => Scalar::Int(*i),
        ParameterValue::Double(x) => Scalar::Float(*x),
        ParameterValue::String(s) => Scalar::Str(s.clone()),
        other => Scalar::Str(format!("{other:?}")),
    }
}

/// Checks a run-time change of parameter `name` against `current`: only
/// [`RUNTIME_SETTABLE`] parameters, with the same type and range checks as at
/// start. The refusal says why and what to do instead.
pub fn check_runtime_change(
    current: &NodeParams,
    name: &str,
    value: &ParameterValue,
) -> Result<NodeParams, String> {
    if !RUNTIME_SETTABLE.contains(&name) {
        return Err(format!(
            "parameter {name} cannot change at run time (it shapes topics, services, QoS, \
             files or the model); restart the node with --set {name}=...; settable now: {}",
            RUNTIME_SETTABLE.join(", ")
        ));
    }
    let mut p = current.clone();
    p.set(name, &scalar(value), false)?;
    Ok(p)
}

/// Every parameter of [`SPECS`](super::params::SPECS) as a ROS parameter, so
/// rclpy can list and get them all; those in [`RUNTIME_SETTABLE`] can be set
/// (validated, then applied to `live`), the others refuse with the reason.
fn declare_parameters(p: &NodeParams, live: Arc<RwLock<NodeParams>>) -> NodeOptions {
    use super::params::{Kind, SPECS};
    let values: Vec<(&'static str, ParameterValue)> = SPECS
        .iter()
        .map(|(key, kind, _)| {
            let text = p.raw_value(key);
            let v = match kind {
                Kind::Str | Kind::Topic => ParameterValue::String(text),
                Kind::Bool => ParameterValue::Boolean(text == "true"),
                Kind::Int(..) => ParameterValue::Integer(text.parse().unwrap_or_default()),
                Kind::Double(_) => ParameterValue::Double(text.parse().unwrap_or_default()),
            };
            (*key, v)
        })
        .collect();
    let initial = values.clone();
    let (check, apply) = (live.clone(), live);
    values
        .into_iter()
        .fold(NodeOptions::new().enable_rosout(true), |o, (k, v)| {
            o.declare_parameter(k, v)
        })
        // Declaring goes through the validator too: the start values pass.
        .parameter_validator(Box::new(move |name, value| {
            if initial.iter().any(|(k, v)| *k == name && v == value) {
                return Ok(());
            }
            let current = check.read().unwrap_or_else(PoisonError::into_inner);
            check_runtime_change(&current, name, value).map(|_| ())
        }))
        // Runs after the validator, and for every declared value at start.
        // Other parameters (read-only ones, ros2-client's use_sim_time) need
        // nothing here: the validator refuses changes to the read-only ones.
        .parameter_set_action(Box::new(move |name, value| {
            if !RUNTIME_SETTABLE.contains(&name) {
                return Ok(());
            }
            let mut current = apply.write().unwrap_or_else(PoisonError::into_inner);
            *current = check_runtime_change(&current, name, value)?;
            Ok(())
        }))
}

/// The node's DDS endpoints.
struct Endpoints {
    input: Subscription<ParticleState>,
    trajectory: Publisher<PredictedTrajectory>,
    forces: Publisher<ParticleForces>,
    diagnostics: Publisher<NodeDiagnostics>,
    standard_diagnostics: Publisher<DiagnosticArray>,
    rollout: Server<RolloutRequest, RolloutResponse>,
}

/// Runs the node in `domain_id` until SIGINT or SIGTERM.
pub fn serve(params: NodeParams, model: Arc<dyn Dynamics>, domain_id: u16) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let live = Arc::new(RwLock::new(params.clone()));
    let p_sim = params.use_sim_time;
    let context = Context::with_options(ContextOptions::new().domain_id(domain_id))
        .map_err(|e| anyhow!("creating the DDS participant in domain {domain_id}: {e:?}"))?;
    let mut node = context
        .new_node(
            NodeName::new("/", NODE_NAME).map_err(|e| anyhow!("node name: {e:?}"))?,
            declare_parameters(&params, live.clone()),
        )
        .map_err(|e| anyhow!("creating the node: {e:?}"))?;

    let qos = topic_qos(&params);
    let topic = |name: &str, pkg: &str, ty: &str| {
        node.create_topic(&ros_name(name)?, MessageTypeName::new(pkg, ty), &qos)
            .map_err(|e| anyhow!("creating topic {name}: {e:?}"))
    };
    let state_type = PARTICLE_STATE_TYPE
        .rsplit('/')
        .next()
        .unwrap_or("ParticleState");
    let input_topic = topic(&params.input_topic, PACKAGE, state_type)?;
    let traj_topic = topic(&params.trajectory_topic, PACKAGE, "PredictedTrajectory")?;
    let forces_topic = topic(&params.forces_topic, PACKAGE, "ParticleForces")?;
    let diag_topic = topic(&params.diagnostics_topic, PACKAGE, "NodeDiagnostics")?;
    let std_diag_topic = node
        .create_topic(
            &ros_name(STANDARD_DIAGNOSTICS_TOPIC)?,
            MessageTypeName::new("diagnostic_msgs", "DiagnosticArray"),
            &service_qos(),
        )
        .map_err(|e| anyhow!("creating topic {STANDARD_DIAGNOSTICS_TOPIC}: {e:?}"))?;
    let e = |what: &'static str| move |err| anyhow!("creating {what}: {err:?}");
    let endpoints = Endpoints {
        input: node
            .create_subscription(&input_topic, Some(qos.clone()))
            .map_err(e("the input subscription"))?,
        trajectory: node
            .create_publisher(&traj_topic, Some(qos.clone()))
            .map_err(e("the trajectory publisher"))?,
        forces: node
            .create_publisher(&forces_topic, Some(qos.clone()))
            .map_err(e("the forces publisher"))?,
        diagnostics: node
            .create_publisher(&diag_topic, Some(qos.clone()))
            .map_err(e("the diagnostics publisher"))?,
        standard_diagnostics: node
            .create_publisher(&std_diag_topic, Some(service_qos()))
            .map_err(e("the /diagnostics publisher"))?,
        rollout: node
            .create_server(
                ServiceMapping::Enhanced,
                &ros_name(&params.rollout_service)?,
                &ServiceTypeName::new(PACKAGE, "Rollout"),
                service_qos(),
                service_qos(),
            )
            .map_err(e("the Rollout service"))?,
    };
    let (training, training_endpoints) = super::training::create(&mut node, &params)?;
    let replay = node
        .create_server(
            ServiceMapping::Enhanced,
            &ros_name(REPLAY_SERVICE)?,
            &ServiceTypeName::new(PACKAGE, "Replay"),
            service_qos(),
            service_qos(),
        )
        .map_err(e("the Replay service"))?;
    let clock_sub = if params.use_sim_time {
        let clock_topic = node
            .create_topic(
                &ros_name(super::clock::CLOCK_TOPIC)?,
                MessageTypeName::new("rosgraph_msgs", "Clock"),
                &clock_qos(),
            )
            .map_err(|e| anyhow!("creating topic /clock: {e:?}"))?;
        Some(
            node.create_subscription::<super::clock::ClockMsg>(&clock_topic, Some(clock_qos()))
                .map_err(e("the /clock subscription"))?,
        )
    } else {
        None
    };
    let spinner = node.spinner().map_err(e("the node spinner"))?;
    let recorder = if params.record_dir.is_empty() {
        None
    } else {
        Some(Mutex::new(
            Recorder::new(&params, &model.describe()).map_err(anyhow::Error::msg)?,
        ))
    };
    let limiter = || {
        Mutex::new(RateLimiter::new(Duration::from_secs_f64(
            params.warn_period,
        )))
    };
    let shared = Arc::new(Shared {
        warn_input: limiter(),
        warn_service: limiter(),
        warn_record: limiter(),
        recorder,
        training,
        model: RwLock::new(model),
        stats: Stats::default(),
        log: Logger {
            rosout: node.logging_handle(),
        },
        params: live,
        clock: super::clock::Clock::new(p_sim),
    });
    let p = shared.params();
    shared.log.log(
        LogLevel::Info,
        &format!(
            "serving {} in domain {domain_id}: {} -> {} + {} (horizon {}, dt {}), service {}",
            shared.model().describe(),
            p.input_topic,
            p.trajectory_topic,
            p.forces_topic,
            p.horizon,
            p.dt,
            p.rollout_service
        ),
    );

    let result = runtime.block_on(async {
        tokio::spawn(async move {
            if let Err(e) = spinner.spin().await {
                eprintln!("[ERROR] [{NODE_NAME}]: node spinner stopped: {e:?}");
            }
        });
        let Endpoints {
            input,
            trajectory,
            forces,
            diagnostics,
            standard_diagnostics,
            rollout,
        } = endpoints;
        tokio::spawn(input_loop(shared.clone(), input, trajectory, forces));
        tokio::spawn(service::serve(
            shared.clone(),
            rollout,
            "Rollout",
            Warn,
            rollout_call,
        ));
        if let Some(sub) = clock_sub {
            tokio::spawn(clock_loop(shared.clone(), sub));
        }
        tokio::spawn(service::serve(
            shared.clone(),
            replay,
            "Replay",
            Warn,
            replay_call,
        ));
        tokio::spawn(diagnostics_loop(
            shared.clone(),
            diagnostics,
            standard_diagnostics,
        ));
        super::training::spawn(shared.clone(), training_endpoints);
        wait_for_shutdown().await
    });
    shared
        .log
        .log(LogLevel::Info, "shutting down (signal received)");
    node.stop_spinner();
    // Cancel the tasks (and drop their DDS entities) before the participant.
    runtime.shutdown_timeout(Duration::from_secs(2));
    if let Some(r) = &shared.recorder {
        let mut r = r.lock().unwrap_or_else(PoisonError::into_inner);
        match r.finish() {
            Ok(()) => shared.log.log(
                LogLevel::Info,
                &format!(
                    "recorded {} bag(s) in {}",
                    r.finished.len(),
                    r.dir().display()
                ),
            ),
            Err(e) => shared.log.log(LogLevel::Error, &e),
        }
    }
    drop(node);
    drop(context);
    result
}

/// Resolves on the first SIGINT or SIGTERM.
async fn wait_for_shutdown() -> anyhow::Result<()> {
    use tokio::signal::unix::{signal, SignalKind};
    let mut term = signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
    let mut int = signal(SignalKind::interrupt()).context("installing the SIGINT handler")?;
    tokio::select! {
        _ = term.recv() => {}
        _ = int.recv() => {}
    }
    Ok(())
}

/// For each incoming state: predict, publish trajectory and forces.
async fn input_loop(
    shared: Arc<Shared>,
    input: Subscription<ParticleState>,
    trajectory: Publisher<PredictedTrajectory>,
    forces: Publisher<ParticleForces>,
) {
    // Last sequence number seen from each publisher.
    let mut last_seen: std::collections::HashMap<String, i64> = Default::default();
    loop {
        let msg = match input.async_take().await {
            Ok((msg, info)) => {
                let publisher = format!("{:?}", info.publisher_gid());
                let sn = info.sequence_number();
                if let Some(prev) = last_seen.insert(publisher, sn) {
                    let gap = sn.saturating_sub(prev).saturating_sub(1);
                    if gap > 0 {
                        let gap = u64::try_from(gap).unwrap_or(0);
                        shared.stats.dropped.fetch_add(gap, Ordering::Relaxed);
                    }
                }
                msg
            }
            Err(e) => {
                // A sample that does not decode as a ParticleState.
                shared.stats.received.fetch_add(1, Ordering::Relaxed);
                shared.reject(&format!("undecodable ParticleState: {e:?}"));
                continue;
            }
        };
        shared.stats.received.fetch_add(1, Ordering::Relaxed);
        let received_ns = shared.clock.now_log_ns();
        let worker = shared.clone();
        let job = tokio::task::spawn_blocking(move || worker.handle_state(msg, received_ns));
        let prediction = match job.await {
            Ok(Ok(p)) => p,
            Ok(Err(why)) => {
                shared.reject(&format!("rejected input: {why}"));
                continue;
            }
            Err(join) => {
                shared.reject(&format!("prediction task failed: {join}"));
                continue;
            }
        };
        let sent_traj = trajectory.async_publish(prediction.trajectory).await;
        let sent_forces = forces.async_publish(prediction.forces).await;
        match (sent_traj, sent_forces) {
            (Ok(()), Ok(())) => {
                shared.stats.predicted.fetch_add(1, Ordering::Relaxed);
            }
            (Err(e), _) => shared.failed(
                &format!("publishing the trajectory failed: {e:?}"),
                &shared.warn_input,
            ),
            (_, Err(e)) => shared.failed(
                &format!("publishing the forces failed: {e:?}"),
                &shared.warn_input,
            ),
        }
    }
}

/// The Rollout service's work with the node's current parameters.
fn rollout_call(shared: &Arc<Shared>, req: RolloutRequest) -> RolloutResponse {
    let p = shared.params();
    let limits = RolloutLimits {
        default_dt: p.dt,
        fine_dt: p.dt / f64::from(p.substeps.max(1)),
        max_steps: p.max_rollout_steps,
        max_particles: p.max_particles,
    };
    rollout_response(shared.model().as_ref(), &req, &limits)
}

/// What the Rollout service accepts and how it integrates, from the node's
/// parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RolloutLimits {
    /// Step of a request with `dt = 0` (the `dt` parameter).
    pub default_dt: f64,
    /// Longest integration step (`dt / substeps`).
    pub fine_dt: f64,
    /// `max_rollout_steps`.
    pub max_steps: u32,
    /// `max_particles`.
    pub max_particles: u32,
}

/// The Rollout service's work: checks the request, then predicts. `dt = 0` in
/// the request means `default_dt`; the model is integrated with steps no
/// longer than `fine_dt` and sampled every `dt`.
pub fn rollout_response(
    model: &dyn Dynamics,
    req: &RolloutRequest,
    limits: &RolloutLimits,
) -> RolloutResponse {
    let fail = |message: String| RolloutResponse {
        success: false,
        message,
        ..RolloutResponse::default()
    };
    let RolloutLimits {
        default_dt,
        fine_dt,
        max_steps,
        max_particles,
    } = *limits;
    if req.steps > max_steps {
        return fail(format!(
            "steps = {} exceeds max_rollout_steps = {max_steps}",
            req.steps
        ));
    }
    if let Err(e) = predict::check_size(&req.initial, max_particles) {
        return fail(e);
    }
    let dt = if req.dt == 0.0 { default_dt } else { req.dt };
    let (graph, start) = match predict::accept(model, &req.initial) {
        Ok(x) => x,
        Err(e) => return fail(e),
    };
    let substeps = if dt.is_finite() && dt > 0.0 {
        ((dt / fine_dt).round() as u32).max(1)
    } else {
        1
    };
    match predict::trajectory(model, &req.initial, &graph, &start, dt, req.steps, substeps) {
        Ok(trajectory) => RolloutResponse {
            success: true,
            message: format!("{} states, dt = {dt}", trajectory.states.len()),
            trajectory,
        },
        Err(e) => fail(e),
    }
}

/// Name of the Replay service (`mcgnode_msgs/srv/Replay`).
pub const REPLAY_SERVICE: &str = "/mcgnode/replay";

/// The Replay service's work: the bag through the model served now, with the
/// node's dt and horizon (see [`crate::replay::replay_as_node`]).
fn replay_call(shared: &Arc<Shared>, req: ReplayRequest) -> ReplayResponse {
    let p = shared.params();
    match crate::replay::replay_as_node(
        shared.model().as_ref(),
        &req.bag,
        p.dt,
        p.substeps,
        p.horizon,
    ) {
        Ok((r, json)) => ReplayResponse {
            success: true,
            message: format!(
                "{} starts, {} comparisons, mean RE {:.3e}",
                r.starts, r.comparisons, r.averages.re
            ),
            report_json: json,
        },
        Err(e) => ReplayResponse {
            message: format!("{e:#}"),
            ..ReplayResponse::default()
        },
    }
}

/// The standard diagnostics topic (`diagnostic_msgs/msg/DiagnosticArray`).
pub const STANDARD_DIAGNOSTICS_TOPIC: &str = "/diagnostics";

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
                kv("dropped", dropped.to_string()),
                kv("last_error", d.last_error.clone()),
                kv("model", d.model.clone()),
            ],
        }],
    }
}

/// Publishes `NodeDiagnostics` and the standard `/diagnostics` every
/// `diagnostics_period`.
async fn diagnostics_loop(
    shared: Arc<Shared>,
    publisher: Publisher<NodeDiagnostics>,
    standard: Publisher<DiagnosticArray>,
) {
    let period = shared.params().diagnostics_period;
    let mut tick = tokio::time::interval(Duration::from_secs_f64(period));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut before = (0, 0);
    loop {
        tick.tick().await;
        let d = shared.diagnostics();
        let dropped = shared.stats.dropped.load(Ordering::Relaxed);
        let array = standard_diagnostics(&d, dropped, before);
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
    fn rate_limiter_lets_one_through_per_period_and_counts_the_rest() {
        let mut r = RateLimiter::new(Duration::from_secs(5));
        let t0 = Instant::now();
        assert_eq!(r.allow(t0), Some(0));
        assert_eq!(r.allow(t0 + Duration::from_secs(1)), None);
        assert_eq!(r.allow(t0 + Duration::from_secs(4)), None);
        assert_eq!(r.allow(t0 + Duration::from_secs(6)), Some(2));
        assert_eq!(r.allow(t0 + Duration::from_secs(7)), None);
    }

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
    fn rollout_service_checks_its_request() {
        let model = crate::models::truth::load_truth("truth:spring").unwrap();
        let req = RolloutRequest {
            steps: 50,
            ..RolloutRequest::default()
        };
        let limits = |max_steps| RolloutLimits {
            default_dt: 0.01,
            fine_dt: 0.01,
            max_steps,
            max_particles: 100,
        };
        let r = rollout_response(model.as_ref(), &req, &limits(10));
        assert!(
            !r.success && r.message.contains("max_rollout_steps"),
            "{}",
            r.message
        );
        let r = rollout_response(model.as_ref(), &req, &limits(100));
        assert!(
            !r.success && r.message.contains("malformed"),
            "{}",
            r.message
        );
        let mut big = req.clone();
        big.initial.masses = vec![1.0; 101];
        let r = rollout_response(model.as_ref(), &big, &limits(100));
        assert!(
            !r.success && r.message.contains("max_particles = 100") && r.message.contains("101"),
            "{}",
            r.message
        );
    }
}
