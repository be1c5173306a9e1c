//! What the node's tasks share, as separate handles, each owning one concern:
//! [`LiveParams`] (the parameters now), [`ModelHandle`] (the model served
//! now), [`Diagnostics`] (counters, the log and rate-limited warnings) and
//! [`RecorderHandle`] (MCAP recording), beside the clock and live accuracy
//! ([`Live`]). A task takes the handles it needs;
//! [`Handles`] bundles them for the node's own loops.
//!
//! This module imports no other task module (node, training, action,
//! service): they all import it, so the module graph has no cycle.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError, RwLock};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use ros2_client::log::LogLevel;
use ros2_client::rosout::{NodeLoggingHandle, RosoutRaw};

use crate::dynamics::Dynamics;

use super::accuracy::Live;
use super::clock::Clock;
use super::params::NodeParams;
use super::record::{RecordError, Recorder};
use super::resource_names::severity;
use super::wire::NodeDiagnostics;

/// The parameters now: those settable at run time
/// ([`super::params::Spec::runtime`]) change while the node runs.
#[derive(Clone, Debug)]
pub struct LiveParams(Arc<RwLock<Arc<NodeParams>>>);

impl LiveParams {
    /// Starts from `params`.
    pub fn new(params: NodeParams) -> Self {
        LiveParams(Arc::new(RwLock::new(Arc::new(params))))
    }

    /// The parameters now: a shared snapshot (a change replaces it, so a
    /// reader's copy never changes under it), not a copy of the set.
    pub fn get(&self) -> Arc<NodeParams> {
        Arc::clone(&self.0.read().unwrap_or_else(PoisonError::into_inner))
    }

    /// Replaces the parameters with `f(current)`, unless `f` refuses.
    pub fn update<E>(&self, f: impl FnOnce(&NodeParams) -> Result<NodeParams, E>) -> Result<(), E> {
        let mut p = self.0.write().unwrap_or_else(PoisonError::into_inner);
        *p = Arc::new(f(&p)?);
        Ok(())
    }
}

/// The model served now, behind a lock so a swap (Train, LoadModel) can
/// replace it while predictions go on: readers clone the `Arc` and predict
/// outside the lock. Beside it, the file it came from (`None` for
/// `truth:*`), which a warm-start retraining continues from.
pub struct ModelHandle(RwLock<Served>);

/// The model served, its file, and how many swaps came before it.
struct Served(Arc<dyn Dynamics>, Option<PathBuf>, u64);

impl ModelHandle {
    /// Serves `model`, loaded from `file` when it came from one.
    pub fn new(model: Arc<dyn Dynamics>, file: Option<PathBuf>) -> Self {
        ModelHandle(RwLock::new(Served(model, file, 0)))
    }

    fn read(&self) -> std::sync::RwLockReadGuard<'_, Served> {
        self.0.read().unwrap_or_else(PoisonError::into_inner)
    }

    /// The model served now.
    pub fn get(&self) -> Arc<dyn Dynamics> {
        self.read().0.clone()
    }

    /// The model served now and its generation (swaps before it): what names
    /// it in caches, where a freed model's address could be reused.
    pub fn served(&self) -> (Arc<dyn Dynamics>, u64) {
        let s = self.read();
        (s.0.clone(), s.2)
    }

    /// The file of the model served now, if it came from one.
    pub fn file(&self) -> Option<PathBuf> {
        self.read().1.clone()
    }

    /// Serves `model` (from `file`) from now on; returns the old model and
    /// how long the write lock was held.
    pub fn replace(
        &self,
        model: Arc<dyn Dynamics>,
        file: Option<PathBuf>,
    ) -> (Arc<dyn Dynamics>, Duration) {
        let start = Instant::now();
        let mut s = self.0.write().unwrap_or_else(PoisonError::into_inner);
        let generation = s.2 + 1;
        let old = std::mem::replace(&mut *s, Served(model, file, generation));
        (old.0, start.elapsed())
    }
}

/// The most streams whose spread alarms are remembered at once.
const MAX_ALARMED_STREAMS: usize = 4096;

/// Counters reported in `NodeDiagnostics`.
#[derive(Debug, Default)]
pub struct Stats {
    /// States received.
    pub received: AtomicU64,
    /// States rejected (malformed, unsupported, or the model failed).
    pub rejected: AtomicU64,
    /// Predictions published.
    pub predicted: AtomicU64,
    /// States with an input outside the served model's training range
    /// (predicted anyway unless `out_of_range_refuse`, then also rejected).
    pub out_of_range: AtomicU64,
    /// Position-only states whose velocities were estimated from their
    /// stream's history, then predicted from.
    pub derived: AtomicU64,
    /// Position-only states held as history only: their stream had too few
    /// states yet for a velocity estimate (not rejected).
    pub warming_up: AtomicU64,
    /// Times a stream's history started over (graph change, stamp before
    /// the previous one, a gap longer than `input_max_gap`).
    pub history_resets: AtomicU64,
    /// States lost before the node took them: gaps in a publisher's sequence
    /// numbers (e.g. the input queue overflowed while the node was busy).
    pub dropped: AtomicU64,
    /// Latest failure reason.
    pub last_error: Mutex<String>,
    /// An ensemble's latest prediction: its largest particle spread along
    /// the horizon; `None` for a single model or before a prediction.
    pub spread_max: Mutex<Option<f64>>,
    /// The streams (trajectory ids) whose spread alarm (`spread_warn`) is
    /// raised: each stream's changes are logged, and may start a retraining
    /// (`spread_retrain`). One per stream, so one stream's agreement never
    /// clears another's alarm.
    pub spread_alarmed: Mutex<BTreeSet<u32>>,
}

impl Stats {
    /// Notes the spread of stream `stream`'s latest prediction (flat, empty
    /// for a single model) against the alarm threshold `warn` (0 = off),
    /// and returns that stream's alarm change, if it changed: raised
    /// (`true`) or cleared, with why. A NaN spread raises it, as on
    /// `/diagnostics`.
    pub fn note_spread(&self, stream: u32, spread: &[f64], warn: f64) -> Option<(bool, String)> {
        let max = spread.iter().copied().reduce(f64::max);
        *self
            .spread_max
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = max;
        let max = max?;
        let raised = warn > 0.0 && (max.is_nan() || max > warn);
        let mut alarmed = self
            .spread_alarmed
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let changed = if raised {
            // Bounded: ids are the publishers' choice; the oldest alarm of
            // a stream long gone is forgotten rather than memory grown.
            if alarmed.len() >= MAX_ALARMED_STREAMS && !alarmed.contains(&stream) {
                alarmed.pop_first();
            }
            alarmed.insert(stream)
        } else {
            alarmed.remove(&stream)
        };
        changed.then(|| {
            let why = if raised {
                format!("spread alarm on stream {stream}: the ensemble disagrees, largest spread {max:.3e} above spread_warn = {warn}")
            } else {
                format!("spread alarm cleared on stream {stream}: largest spread {max:.3e}, spread_warn = {warn}")
            };
            (raised, why)
        })
    }

    /// The latest prediction's largest spread, `None` for a single model.
    pub fn spread_max(&self) -> Option<f64> {
        *self
            .spread_max
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
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
    /// The node's name, as the log lines say it.
    name: String,
    /// Below this severity nothing is logged (`--log-level`; default info).
    min: u8,
}

impl Logger {
    /// Logs through the node's /rosout handle as `name`, at `level` and
    /// above (`None`: info).
    pub fn new(rosout: NodeLoggingHandle, name: &str, level: Option<LogLevel>) -> Self {
        Logger {
            rosout,
            name: name.to_string(),
            min: severity(level.unwrap_or(LogLevel::Info)),
        }
    }

    /// Logs `msg` at `level`.
    pub fn log(&self, level: LogLevel, msg: &str) {
        if severity(level) < self.min {
            return;
        }
        let tag = match level {
            LogLevel::Fatal => "FATAL",
            LogLevel::Error => "ERROR",
            LogLevel::Warn => "WARN",
            LogLevel::Info => "INFO",
            LogLevel::Debug => "DEBUG",
        };
        eprintln!("[{tag}] [{:.6}] [{}]: {msg}", wall_secs(), self.name);
        self.rosout.rosout_raw(
            ros2_client::builtin_interfaces::Time::now(),
            level,
            &self.name,
            msg,
            file!(),
            "",
            line!(),
        );
    }
}

/// Seconds since the Unix epoch (0 if the clock is before it).
fn wall_secs() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// Which kind of failure a warning is about: each kind has its own rate
/// limit, so a flood of one does not hide the others.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Warning {
    /// Bad input states, failed publishing.
    Input,
    /// Failed service calls (the caller gets the reason).
    Service,
    /// Recording failures.
    Record,
    /// States outside the model's training range.
    OutOfRange,
}

/// Counters, the log and rate-limited warnings.
pub struct Diagnostics {
    /// The counters reported in `NodeDiagnostics`.
    pub stats: Stats,
    limiters: [Mutex<RateLimiter>; 4],
    log: Logger,
    /// The warning period is a run-time parameter.
    params: LiveParams,
}

impl Diagnostics {
    /// Counters at zero; warnings rate-limited by `warn_period` of `params`.
    pub fn new(log: Logger, params: LiveParams) -> Self {
        let period = Duration::from_secs_f64(params.get().warn_period);
        Diagnostics {
            stats: Stats::default(),
            limiters: std::array::from_fn(|_| Mutex::new(RateLimiter::new(period))),
            log,
            params,
        }
    }

    /// Logs `msg` at `level` (stderr and /rosout), not rate-limited.
    pub fn log(&self, level: LogLevel, msg: &str) {
        self.log.log(level, msg);
    }

    /// Counts a rejected input and warns, rate-limited.
    pub fn reject(&self, why: &str) {
        self.stats.rejected.fetch_add(1, Ordering::Relaxed);
        self.failed(why, Warning::Input);
    }

    /// Records a failure as the last error and warns, rate-limited per kind.
    pub fn failed(&self, why: &str, kind: Warning) {
        why.clone_into(
            &mut self
                .stats
                .last_error
                .lock()
                .unwrap_or_else(PoisonError::into_inner),
        );
        let period = Duration::from_secs_f64(self.params.get().warn_period);
        let allowed = {
            let mut l = self.limiters[kind as usize]
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
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

    /// The counters as a `NodeDiagnostics` message (header left default).
    pub fn snapshot(&self, model: &str) -> NodeDiagnostics {
        NodeDiagnostics {
            received: self.stats.received.load(Ordering::Relaxed),
            rejected: self.stats.rejected.load(Ordering::Relaxed),
            predicted: self.stats.predicted.load(Ordering::Relaxed),
            out_of_range: self.stats.out_of_range.load(Ordering::Relaxed),
            derived: self.stats.derived.load(Ordering::Relaxed),
            warming_up: self.stats.warming_up.load(Ordering::Relaxed),
            history_resets: self.stats.history_resets.load(Ordering::Relaxed),
            last_error: self
                .stats
                .last_error
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone(),
            model: model.to_string(),
            ..NodeDiagnostics::default()
        }
    }
}

/// MCAP recording when `record_dir` is set; otherwise every call is a no-op.
pub struct RecorderHandle {
    recorder: Option<Mutex<Recorder>>,
    /// Recording failures are warned about, not fatal.
    diag: Arc<Diagnostics>,
}

impl RecorderHandle {
    /// Records with `recorder`, if any.
    pub fn new(recorder: Option<Recorder>, diag: Arc<Diagnostics>) -> Self {
        RecorderHandle {
            recorder: recorder.map(Mutex::new),
            diag,
        }
    }

    /// Records with the recorder, if any; failures are warned about.
    pub fn record(&self, what: impl FnOnce(&mut Recorder) -> Result<(), RecordError>) {
        if let Some(r) = &self.recorder {
            let result = what(&mut r.lock().unwrap_or_else(PoisonError::into_inner));
            if let Err(e) = result {
                self.diag.failed(&e.to_string(), Warning::Record);
            }
        }
    }

    /// Finishes the open chunk on a timer, every [`Recorder::flush_period`],
    /// so an idle stream's last messages reach the file too; returns at once
    /// when the node does not record or every message finishes its chunk.
    pub async fn flush_loop(self: Arc<Self>) {
        let Some(r) = &self.recorder else {
            return;
        };
        let period = r
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .flush_period();
        let Some(period) = period else {
            return;
        };
        let mut tick = tokio::time::interval(period);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tick.tick().await;
            self.record(|r| r.flush_due(Instant::now(), period));
        }
    }

    /// Closes the open bag (its footer written, so it reads back whole) and
    /// returns the folder and every bag finished so far; `None` when the node
    /// does not record.
    pub fn finish(&self) -> Option<Result<(PathBuf, Vec<PathBuf>), RecordError>> {
        self.finish_with(Recorder::finish)
    }

    /// [`RecorderHandle::finish`] for good (shutdown): a later record, such
    /// as markers still being drawn, is dropped instead of opening a bag
    /// nobody closes ([`Recorder::close`]).
    pub fn close(&self) -> Option<Result<(PathBuf, Vec<PathBuf>), RecordError>> {
        self.finish_with(Recorder::close)
    }

    fn finish_with(
        &self,
        end: fn(&mut Recorder) -> Result<(), RecordError>,
    ) -> Option<Result<(PathBuf, Vec<PathBuf>), RecordError>> {
        let r = self.recorder.as_ref()?;
        let mut r = r.lock().unwrap_or_else(PoisonError::into_inner);
        Some(end(&mut r).map(|()| (r.dir().to_path_buf(), r.finished.clone())))
    }
}

/// Every handle, for the node's own loops and the Rollout and Replay calls.
#[derive(Clone)]
pub struct Handles {
    /// The parameters now.
    pub params: LiveParams,
    /// The model served now.
    pub model: Arc<ModelHandle>,
    /// Counters and the log.
    pub diag: Arc<Diagnostics>,
    /// Recording.
    pub recorder: Arc<RecorderHandle>,
    /// System time, or `/clock` with `use_sim_time`.
    pub clock: Arc<Clock>,
    /// Live accuracy of the predictions.
    pub accuracy: Arc<Live>,
    /// The input streams (velocities of position-only states).
    pub inputs: Arc<super::input::Inputs>,
    /// The managed-node state: only an active node predicts.
    pub lifecycle: Arc<super::lifecycle::Lifecycle>,
    /// The last system the served model was checked for (graph, field):
    /// a stream of one system is checked once, and again after a swap.
    pub passed: Arc<crate::compat::Passed>,
    /// The last prediction's buffers, refilled by the next (no allocation
    /// while the system stays the same).
    pub predicted: Arc<std::sync::Mutex<crate::dynamics::Predicted>>,
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

    /// Each stream raises and clears its own alarm; the threshold 0 is off.
    #[test]
    fn spread_alarms_are_per_stream() {
        let stats = Stats::default();
        let (high, low) = ([0.0, 0.5, 0.1], [0.01, 0.02]);
        let raised = stats.note_spread(1, &high, 0.2).expect("raised on 1");
        assert!(raised.0 && raised.1.contains("stream 1"), "{raised:?}");
        assert_eq!(stats.note_spread(1, &high, 0.2), None, "no change");
        // Another stream's agreement leaves stream 1's alarm raised.
        assert_eq!(stats.note_spread(2, &low, 0.2), None);
        assert!(stats.note_spread(2, &high, 0.2).is_some_and(|c| c.0));
        let cleared = stats.note_spread(1, &low, 0.2).expect("cleared on 1");
        assert!(!cleared.0 && cleared.1.contains("cleared on stream 1"));
        assert_eq!(stats.spread_max(), Some(0.02));
        assert_eq!(stats.note_spread(3, &[f64::NAN], 0.0), None, "0 is off");
        assert!(stats.note_spread(3, &[f64::NAN], 0.2).is_some_and(|c| c.0));
        assert_eq!(stats.note_spread(3, &[], 0.2), None, "single model");
    }
}
