//! The node's own DDS endpoints (topics, services, `/clock`) and the tasks
//! that serve them: the input loop, the diagnostics loop, `/clock`, and one
//! service loop per service, training's included.

use std::sync::Arc;

use ros2_client::log::LogLevel;
use ros2_client::{Node, Publisher, Server, Subscription};

use crate::data::msg::ParticleState;

use super::action::{self, TrainActionServer};
use super::calls::{plan_call, replay_call, rollout_call};
use super::diagnostics::diagnostics_loop;
use super::handles::Handles;
use super::input_loop::{input_loop, Outputs};
use super::params::NodeParams;
use super::qos::{clock_qos, input_qos, publisher, reliable_qos, server, subscription, topic_qos};
use super::resource_names::Names;
use super::service::{self, OnFailure::Warn};
use super::topics::{
    CLOCK_TOPIC, LIVE_ACCURACY_TOPIC, PLAN_SERVICE, REPLAY_SERVICE, STANDARD_DIAGNOSTICS_TOPIC,
};
use super::tracker_input::TrackerInputs;
use super::trainer::{Trainer, TrainingServers};
use super::training_services;
use super::wire::{ClockMsg, LoadModel, MarkerArray, Plan, Replay, Rollout, RosService, Train};
use super::wire::{
    DiagnosticArray, LiveAccuracy, NodeDiagnostics, ParticleForces, PlanRequest, PlanResponse,
    PredictedTrajectory, ReplayRequest, ReplayResponse, RolloutRequest, RolloutResponse,
};

/// The node's own DDS endpoints (training's are in [`super::trainer::create`] and
/// [`action::create`]).
pub(super) struct Endpoints {
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
    /// PoseArray and PointCloud2 input, when a topic is set.
    trackers: Option<TrackerInputs>,
}

impl Endpoints {
    /// Topics, publishers, subscriptions and servers as the parameters say.
    pub(super) fn create(
        node: &mut Node,
        params: &NodeParams,
        names: &Names,
    ) -> crate::error::Result<Endpoints> {
        let qos = topic_qos(params);
        Ok(Endpoints {
            input: subscription(node, names, &params.input_topic, &input_qos(params))?,
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
            trackers: TrackerInputs::create(node, params, names)?,
        })
    }

    /// Starts one task per loop: input, diagnostics, /clock, and one per
    /// service (inside the runtime).
    pub(super) fn spawn(self, h: &Handles, trainer: &Arc<Trainer>) {
        let outputs = Outputs {
            trajectory: self.trajectory,
            forces: self.forces,
            accuracy: self.accuracy,
            markers: Arc::new(self.markers),
            last_markers: None,
        };
        // Tracker states wait here for the input loop (a few: the input QoS
        // history holds the rest, and keeps the newest).
        let (tx, rx) = tokio::sync::mpsc::channel(4);
        if let Some(t) = self.trackers {
            t.spawn(h, &tx);
        }
        let input = input_loop(h.clone(), self.input, rx, outputs, trainer.clone());
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

/// Starts the Train and LoadModel services and the Train action.
pub(super) fn spawn_training(
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
        training_services::train_call,
    ));
    tokio::spawn(service::serve(
        trainer.clone(),
        d,
        load,
        LoadModel::NAME,
        Quiet,
        training_services::load_call,
    ));
    action::spawn(trainer, action_server);
}
