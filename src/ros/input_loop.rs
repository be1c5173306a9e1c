//! The input loop: each incoming `ParticleState` checked, recorded, predicted
//! and scored on the blocking pool, then its trajectory, forces, markers and
//! live accuracy published; a drift alarm can start a retraining.

use std::sync::atomic::Ordering;
use std::sync::{Arc, PoisonError};
use std::time::Instant;

use ros2_client::log::LogLevel;
use ros2_client::{Publisher, Subscription};

use crate::data::msg::ParticleState;
use crate::data::stream::Reset;

use super::accuracy::{self, Level};
use super::drift_retraining::retrain_on_drift;
use super::handles::{Handles, Warning};
use super::input::Accepted;
use super::markers::MarkerSource;
use super::params::NodeParams;
use super::predict::{self, Prediction};
use super::trainer::Trainer;
use super::wire::{LiveAccuracy, MarkerArray, ParticleForces, PredictedTrajectory};

/// A state's prediction, its live-accuracy update, and the spread alarm's
/// change (raised or cleared, why) if it changed.
type Handled = (Prediction, accuracy::Update, Option<(bool, String)>);

/// Checks, records and predicts one incoming state, and scores it against
/// what was predicted for its moment (blocking work). `None`: a
/// position-only state kept as its stream's history while it warms up.
fn handle_state(
    h: &Handles,
    msg: ParticleState,
    received_ns: u64,
) -> Result<Option<Handled>, predict::PredictError> {
    // Refused before anything is recorded or predicted: an oversized state
    // would hold memory and its prediction could not be delivered promptly.
    if let Some(why) = h.lifecycle.refusal() {
        return Err(predict::PredictError::Inactive(why));
    }
    let params = h.params.get();
    predict::check_size(&msg, params.max_particles)?;
    h.recorder.record(|r| r.state(received_ns, &msg));
    let id = msg.trajectory_id;
    let (model, generation) = h.model.served();
    let input = match h
        .inputs
        .accept_with(&params, msg, Some((model.as_ref(), generation)))?
    {
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
    // The buffers of the last prediction, refilled: the input loop awaits
    // each state's job, so they are never wanted twice at once.
    let mut kept = h.predicted.lock().unwrap_or_else(PoisonError::into_inner);
    let outside = predict::predict_served(
        (model.as_ref(), generation),
        &h.passed,
        &input,
        &params,
        &mut kept,
    )
    .inspect_err(|e| {
        if matches!(e, predict::PredictError::OutOfRange(_)) {
            h.diag.stats.out_of_range.fetch_add(1, Ordering::Relaxed);
        }
    })?;
    if let Some(o) = outside {
        h.diag.stats.out_of_range.fetch_add(1, Ordering::Relaxed);
        h.diag.failed(
            &format!("out-of-range input, predicted anyway: {o}"),
            Warning::OutOfRange,
        );
    }
    let p = predict::messages(&input.message, &input.graph, params.dt, &kept)?;
    let spread_alarm = h
        .diag
        .stats
        .note_spread(id, &kept.spread, params.spread_warn);
    h.recorder
        .record(|r| r.prediction(h.clock.now_log_ns(), &p.trajectory, &p.forces));
    let scored = h.accuracy.update(&params, &input, &kept.states);
    Ok(Some((p, scored, spread_alarm)))
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

/// What the input loop publishes.
pub(super) struct Outputs {
    pub(super) trajectory: Publisher<PredictedTrajectory>,
    pub(super) forces: Publisher<ParticleForces>,
    pub(super) accuracy: Publisher<LiveAccuracy>,
    /// Shared with the tasks that draw markers ([`publish_markers`]).
    pub(super) markers: Arc<Publisher<MarkerArray>>,
    /// When the last markers went out (`markers_period`).
    pub(super) last_markers: Option<Instant>,
}

/// What the markers of `p` are drawn from when they are on and
/// `markers_period` has passed since the last ones (`last` is then reset).
fn markers_due(
    params: &NodeParams,
    last: &mut Option<Instant>,
    p: &Prediction,
) -> Option<MarkerSource> {
    let due =
        params.markers && last.is_none_or(|t| t.elapsed().as_secs_f64() >= params.markers_period);
    due.then(|| {
        *last = Some(Instant::now());
        MarkerSource::new(&p.trajectory, &p.forces)
    })
}

/// Draws and publishes (and records) markers on another thread, so that
/// neither the prediction they show nor the next input waits for them.
fn publish_markers(h: &Handles, publisher: &Arc<Publisher<MarkerArray>>, source: MarkerSource) {
    let (h, publisher) = (h.clone(), Arc::clone(publisher));
    tokio::spawn(async move {
        let Ok(m) = tokio::task::spawn_blocking(move || source.markers()).await else {
            h.diag.failed("drawing the markers failed", Warning::Input);
            return;
        };
        h.recorder.record(|r| r.markers(h.clock.now_log_ns(), &m));
        if let Err(e) = publisher.async_publish(m).await {
            let why = format!("publishing the markers failed: {e:?}");
            h.diag.failed(&why, Warning::Input);
        }
    });
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

/// The next ParticleState of the input topic (sequence gaps counted as
/// dropped), or why it was refused; counted as received either way.
async fn take_state(
    h: &Handles,
    input: &Subscription<ParticleState>,
    last_seen: &mut std::collections::HashMap<String, i64>,
) -> Option<ParticleState> {
    let stats = &h.diag.stats;
    let taken = input.async_take().await;
    stats.received.fetch_add(1, Ordering::Relaxed);
    match taken {
        Ok((msg, info)) => {
            let gap = sequence_gap(last_seen, &info);
            stats.dropped.fetch_add(gap, Ordering::Relaxed);
            Some(msg)
        }
        Err(e) => {
            // A sample that does not decode as a ParticleState.
            h.diag.reject(&format!("undecodable ParticleState: {e:?}"));
            None
        }
    }
}

/// For each incoming state (of the input topic, or from `trackers`: the
/// PoseArray and PointCloud2 tasks, which count them as received): predict,
/// publish trajectory and forces, and the live accuracy when the state was
/// compared with earlier predictions; a drift alarm starts a retraining with
/// `trainer` when `accuracy_retrain` is on, a spread alarm when
/// `spread_retrain` is.
pub(super) async fn input_loop(
    h: Handles,
    input: Subscription<ParticleState>,
    mut trackers: tokio::sync::mpsc::Receiver<ParticleState>,
    mut out: Outputs,
    trainer: Arc<Trainer>,
) {
    // Last sequence number seen from each publisher.
    let mut last_seen: std::collections::HashMap<String, i64> = Default::default();
    loop {
        let taken = tokio::select! {
            taken = take_state(&h, &input, &mut last_seen) => taken,
            Some(state) = trackers.recv() => Some(state),
        };
        let Some(msg) = taken else { continue };
        let received_ns = h.clock.now_log_ns();
        let worker = h.clone();
        let job = tokio::task::spawn_blocking(move || handle_state(&worker, msg, received_ns));
        let (prediction, scored, spread_alarm) = match job.await {
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
        let p = h.params.get();
        if let Some((level, why)) = &scored.alarm_changed {
            log_alarm(&h, *level, why);
            if *level != Level::Ok && p.accuracy_retrain {
                start_retraining(&trainer, &p, why);
            }
        }
        if let Some((raised, why)) = &spread_alarm {
            let level = if *raised {
                LogLevel::Warn
            } else {
                LogLevel::Info
            };
            h.diag.log(level, why);
            if *raised && p.spread_retrain {
                start_retraining(&trainer, &p, why);
            }
        }
        out.publish(&h, prediction, scored.message).await;
    }
}

/// Starts a retraining after an alarm (`why`), off the input loop: it
/// records for a while, then trains; the outcome is logged by
/// [`retrain_on_drift`] itself.
fn start_retraining(trainer: &Arc<Trainer>, p: &Arc<NodeParams>, why: &str) {
    let (trainer, p, why) = (trainer.clone(), p.clone(), why.to_string());
    tokio::task::spawn_blocking(move || {
        let _ = retrain_on_drift(&trainer, &p, &why);
    });
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
        // The markers' inputs taken, they are drawn after the prediction is
        // out (drawing 1,000 particles × 100 steps took 12–28 ms).
        let markers = markers_due(&h.params.get(), &mut self.last_markers, &p);
        let sent_traj = self.trajectory.async_publish(p.trajectory).await;
        let sent_forces = self.forces.async_publish(p.forces).await;
        if let Some(source) = markers {
            publish_markers(h, &self.markers, source);
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
