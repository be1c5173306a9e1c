//! Live accuracy (no DDS here): for every incoming state, compare it with
//! what the node predicted for that moment from earlier states, at a few lead
//! times, and keep running figures per lead time.
//!
//! - When a state at time `t` has been predicted, [`Tracker::expect`] keeps
//!   the predicted states at `t + lead` for each lead time (those the
//!   prediction reaches), keyed by trajectory id and target time.
//! - When a state arrives, [`Tracker::observe`] compares it with every kept
//!   prediction whose target lies within half a prediction step of its stamp,
//!   with the project's metrics ([`crate::metrics::error_curves`]: RE of the
//!   positions and, when the field is known, EE of the energy), and forgets
//!   predictions for earlier times, which can no longer match.
//! - Memory is bounded: at most `capacity` predictions are kept, the oldest
//!   dropped first (counted in [`Tracker::overflowed`]).
//! - A state of another trajectory, or one before the last, starts over
//!   (a new run or a replayed bag): predictions, figures and the alarm level
//!   of the old run are dropped, so a lead reports only once the new run has
//!   reached it. The node keeps one tracker per stream (trajectory id,
//!   [`Live`]), so interleaved streams never mix.
//!
//! A lead time is compared only when incoming stamps fall on it: with states
//! every 0.1 s, a lead of 0.15 s never matches. The running value is the mean
//! of the last `window` comparisons; [`alarm`] turns it into a diagnostic
//! level against two thresholds.

use std::collections::VecDeque;
use std::sync::{Mutex, PoisonError};

use crate::data::stream::Streams;
use crate::dynamics::{KeptStates, Timing};
use crate::metrics::error_curves;
use crate::physics::Field;
use crate::system::{Graph, State};

use super::input::Input;
use super::params::NodeParams;
use super::wire::LiveAccuracy;

pub use crate::data::stream::Nanos;

/// One prediction waiting for the state it is about.
#[derive(Clone, Debug)]
struct Pending {
    trajectory: u32,
    target: Nanos,
    lead: usize,
    state: State,
}

/// One comparison of an incoming state with a prediction made `lead`
/// seconds of system time earlier.
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// Lead time, seconds.
    pub lead: f64,
    /// Relative error of the positions (the paper's RE).
    pub re: f64,
    /// Relative energy error (the paper's EE); `None` when the field is
    /// unknown, so the energy is not computable.
    pub ee: Option<f64>,
}

/// Running figures at one lead time.
#[derive(Clone, Debug, PartialEq)]
pub struct LeadAccuracy {
    /// Lead time, seconds.
    pub lead: f64,
    /// Comparisons made so far (since the start or the last reset).
    pub compared: u64,
    /// Latest RE (NaN before the first comparison).
    pub re: f64,
    /// Mean RE of the last `window` comparisons (NaN before the first).
    pub re_mean: f64,
    /// Latest EE (NaN when none was computable).
    pub ee: f64,
    /// Mean EE of the last `window` comparisons with a computable energy
    /// (NaN when there were none).
    pub ee_mean: f64,
}

/// Diagnostic levels of `alarm` (diagnostic_msgs/DiagnosticStatus).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// Every running RE at or below the warning threshold.
    Ok = 0,
    /// A running RE above the warning threshold.
    Warn = 1,
    /// A running RE above the error threshold.
    Error = 2,
}

/// Keeps predictions until their moment comes and scores them.
#[derive(Debug)]
pub struct Tracker {
    leads: Vec<f64>,
    window: usize,
    capacity: usize,
    pending: VecDeque<Pending>,
    /// Per lead: the last `window` (RE, EE) pairs.
    recent: Vec<VecDeque<(f64, Option<f64>)>>,
    compared: Vec<u64>,
    /// Trajectory and stamp of the latest observed state.
    last: Option<(u32, Nanos)>,
    overflowed: u64,
}

impl Tracker {
    /// Tracks `leads` (seconds), averaging over the last `window` comparisons
    /// and keeping at most `capacity` predictions.
    pub fn new(leads: &[f64], window: usize, capacity: usize) -> Self {
        Tracker {
            leads: leads.to_vec(),
            window: window.max(1),
            capacity: capacity.max(1),
            pending: VecDeque::new(),
            recent: vec![VecDeque::new(); leads.len()],
            compared: vec![0; leads.len()],
            last: None,
            overflowed: 0,
        }
    }

    /// Whether this tracker was built for these settings.
    pub fn is_for(&self, leads: &[f64], window: usize, capacity: usize) -> bool {
        self.leads == leads && self.window == window.max(1) && self.capacity == capacity.max(1)
    }

    /// The lead times, seconds.
    pub fn leads(&self) -> &[f64] {
        &self.leads
    }

    /// Predictions dropped because `capacity` were already kept.
    pub fn overflowed(&self) -> u64 {
        self.overflowed
    }

    /// Predictions kept now.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// For a prediction timed by `timing` (its kept states
    /// [`Timing::kept_dt`] apart): `(lead index, kept state k)` for each
    /// lead time that is a whole number `k ≥ 1` of them (within half of
    /// one) no further than the last. The others cannot be compared with
    /// this prediction.
    pub fn steps(&self, timing: Timing) -> Vec<(usize, usize)> {
        let (dt, last) = (timing.kept_dt(), timing.kept() - 1);
        if !(dt.is_finite() && dt > 0.0) {
            return Vec::new();
        }
        self.leads
            .iter()
            .enumerate()
            .filter_map(|(i, &lead)| {
                let k = (lead / dt).round();
                let whole = (k * dt - lead).abs() <= 0.5 * dt;
                (whole && k >= 1.0 && k <= last as f64).then_some((i, k as usize))
            })
            .collect()
    }

    /// Compares the incoming `state` of `trajectory` at time `t` with every
    /// prediction for a time within `tolerance` of `t`, and forgets the
    /// predictions for earlier times. `field` is `None` when unknown (no EE).
    pub fn observe(
        &mut self,
        trajectory: u32,
        t: Nanos,
        tolerance: Nanos,
        graph: &Graph,
        field: Option<&Field>,
        state: &State,
    ) -> Vec<Comparison> {
        if let Some((id, last)) = self.last {
            if id != trajectory || t < last {
                self.restart();
            }
        }
        self.last = Some((trajectory, t));
        let mut matched = Vec::new();
        self.pending.retain(|p| {
            if p.trajectory != trajectory || p.target < t - tolerance {
                return false;
            }
            if (p.target - t).abs() <= tolerance {
                matched.push((p.lead, p.state.clone()));
                return false;
            }
            true
        });
        matched.sort_by_key(|(lead, _)| *lead);
        let mut out = Vec::with_capacity(matched.len());
        for (lead, predicted) in matched {
            let Some((re, ee)) = score(graph, field, state, &predicted) else {
                continue;
            };
            let recent = &mut self.recent[lead];
            if recent.len() == self.window {
                recent.pop_front();
            }
            recent.push_back((re, ee));
            self.compared[lead] += 1;
            out.push(Comparison {
                lead: self.leads[lead],
                re,
                ee,
            });
        }
        out
    }

    /// Forgets the run: predictions and figures (settings and the overflow
    /// count stay).
    pub fn restart(&mut self) {
        self.pending.clear();
        self.recent.iter_mut().for_each(VecDeque::clear);
        self.compared.iter_mut().for_each(|c| *c = 0);
        self.last = None;
    }

    /// Keeps the states predicted from the state of `trajectory` at time `t`:
    /// `(lead index, predicted state at t + lead)`.
    pub fn expect(&mut self, trajectory: u32, t: Nanos, predicted: Vec<(usize, State)>) {
        for (lead, state) in predicted {
            let Some(&secs) = self.leads.get(lead) else {
                continue;
            };
            if self.pending.len() == self.capacity {
                self.pending.pop_front();
                self.overflowed += 1;
            }
            self.pending.push_back(Pending {
                trajectory,
                target: t.saturating_add((secs * 1e9).round() as Nanos),
                lead,
                state,
            });
        }
    }

    /// The running figures per lead time.
    pub fn summary(&self) -> Vec<LeadAccuracy> {
        self.leads
            .iter()
            .zip(&self.recent)
            .zip(&self.compared)
            .map(|((&lead, recent), &compared)| {
                let (re, ee) = recent.back().copied().unwrap_or((f64::NAN, None));
                LeadAccuracy {
                    lead,
                    compared,
                    re,
                    re_mean: mean(recent.iter().map(|r| Some(r.0))),
                    ee: ee.unwrap_or(f64::NAN),
                    ee_mean: mean(recent.iter().map(|r| r.1)),
                }
            })
            .collect()
    }
}

/// Mean of the present values (NaN when none).
fn mean(values: impl Iterator<Item = Option<f64>>) -> f64 {
    let (sum, n) = values
        .flatten()
        .fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        sum / n as f64
    }
}

/// RE and EE of `predicted` against `truth` by the project's metrics; a
/// prediction that diverged scores the worst values (1), as in
/// [`crate::metrics`]; a state that does not fit the graph is not scored.
fn score(
    graph: &Graph,
    field: Option<&Field>,
    truth: &State,
    predicted: &State,
) -> Option<(f64, Option<f64>)> {
    if !predicted
        .q
        .iter()
        .chain(&predicted.v)
        .all(|x| x.is_finite())
    {
        return Some((1.0, field.map(|_| 1.0)));
    }
    // RE does not depend on the field: without one, score with none acting
    // and report no EE.
    let none = Field {
        gravity: 0.0,
        drag: 0.0,
        force: Vec::new(),
    };
    let c = error_curves(
        graph,
        field.unwrap_or(&none),
        std::slice::from_ref(truth),
        std::slice::from_ref(predicted),
        &[0.0],
    )
    .ok()?;
    Some((c.re[0], field.map(|_| c.ee[0])))
}

/// The drift alarm: the worst running RE (mean of the window) over the lead
/// times against `warn` and `error` (0 disables a threshold), with the lead
/// time and value in the message.
pub fn alarm(figures: &[LeadAccuracy], warn: f64, error: f64) -> (Level, String) {
    let worst = figures
        .iter()
        .filter(|f| f.re_mean.is_finite())
        .max_by(|a, b| a.re_mean.total_cmp(&b.re_mean));
    let Some(w) = worst else {
        return (Level::Ok, "no comparisons yet".into());
    };
    let (level, name, threshold) = if error > 0.0 && w.re_mean > error {
        (Level::Error, "accuracy_error_re", error)
    } else if warn > 0.0 && w.re_mean > warn {
        (Level::Warn, "accuracy_warn_re", warn)
    } else {
        return (
            Level::Ok,
            format!("worst running RE {:.3e} at lead {} s", w.re_mean, w.lead),
        );
    };
    (
        level,
        format!(
            "drift: running RE at lead {} s is {:.3e}, above {name} = {threshold}",
            w.lead, w.re_mean
        ),
    )
}

/// What one incoming state changed.
#[derive(Clone, Debug, PartialEq)]
pub struct Update {
    /// The figures after it, when it was compared with anything.
    pub message: Option<LiveAccuracy>,
    /// The new alarm level and message, when the level changed.
    pub alarm_changed: Option<(Level, String)>,
}

/// One stream's tracker and the alarm level it last reported.
type StreamTracker = (Tracker, Level);

/// The trackers of the node's streams and what they were built for.
#[derive(Debug)]
struct LiveState {
    /// Lead times, window, capacity, streams.
    settings: (Vec<f64>, usize, usize, usize),
    streams: Streams<StreamTracker>,
    /// The stream scored last (what the diagnostics report).
    latest: Option<u32>,
}

/// The node's live accuracy: one [`Tracker`] per stream (trajectory id, at
/// most `input_max_streams`) behind a lock, rebuilt when its parameters
/// change at run time, each with the alarm level it last reported.
#[derive(Debug)]
pub struct Live {
    state: Mutex<LiveState>,
}

impl Default for Live {
    fn default() -> Self {
        Live {
            state: Mutex::new(LiveState {
                settings: (Vec::new(), 1, 1, 1),
                streams: Streams::new(1),
                latest: None,
            }),
        }
    }
}

impl Live {
    /// Scores `input` against the predictions made for its moment in its
    /// stream, then keeps the states of `predicted` (its own prediction:
    /// the input, then one state every `dt`) at the lead times. A stream that started over ([`Input::reset`]) starts
    /// its figures and alarm over too. Nothing happens when
    /// `accuracy_lead_times` is empty.
    pub fn update(&self, p: &NodeParams, input: &Input, predicted: &KeptStates) -> Update {
        let mut none = Update {
            message: None,
            alarm_changed: None,
        };
        if p.accuracy_lead_times.is_empty() {
            return none;
        }
        let t = input.stamp;
        let tolerance = (p.dt * 0.5e9).round() as Nanos;
        let id = input.trajectory_id;
        let mut guard = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let live = &mut *guard;
        let (window, capacity) = (p.accuracy_window as usize, p.accuracy_max_pending as usize);
        let streams = p.input_max_streams as usize;
        // Compared in place: no copy of the lead times per message.
        let (leads, w, c, n) = &live.settings;
        if *leads != p.accuracy_lead_times || (*w, *c, *n) != (window, capacity, streams) {
            live.streams = Streams::new(streams);
            live.settings = (p.accuracy_lead_times.clone(), window, capacity, streams);
        }
        live.latest = Some(id);
        let (tracker, level) = live.streams.get_or_insert_with(id, || {
            (
                Tracker::new(&p.accuracy_lead_times, window, capacity),
                Level::Ok,
            )
        });
        if input.reset.is_some() {
            tracker.restart();
            *level = Level::Ok;
        }
        let compared = tracker.observe(
            id,
            t,
            tolerance,
            &input.graph,
            input.field.as_ref(),
            &input.state,
        );
        let kept = p.timing().with_horizon(predicted.len().saturating_sub(1));
        let ahead: Vec<(usize, State)> = tracker
            .steps(kept)
            .into_iter()
            .filter(|&(_, k)| k < predicted.len())
            .map(|(lead, k)| (lead, predicted.state(k)))
            .collect();
        tracker.expect(id, t, ahead);
        if compared.is_empty() {
            return none;
        }
        let figures = tracker.summary();
        let (now, why) = alarm(&figures, p.accuracy_warn_re, p.accuracy_error_re);
        if now != *level {
            *level = now;
            none.alarm_changed = Some((now, why.clone()));
        }
        none.message = Some(LiveAccuracy {
            header: input.message.header.clone(),
            trajectory_id: id,
            lead_times: figures.iter().map(|f| f.lead).collect(),
            compared: figures.iter().map(|f| f.compared).collect(),
            re: figures.iter().map(|f| f.re).collect(),
            re_mean: figures.iter().map(|f| f.re_mean).collect(),
            ee: figures.iter().map(|f| f.ee).collect(),
            ee_mean: figures.iter().map(|f| f.ee_mean).collect(),
            level: now as u8,
            message: why,
        });
        none
    }

    /// The running figures and the alarm now of the stream scored last, and
    /// the predictions dropped for capacity over all streams (`None` when
    /// live accuracy is off).
    pub fn figures(&self, p: &NodeParams) -> Option<(Vec<LeadAccuracy>, Level, String, u64)> {
        if p.accuracy_lead_times.is_empty() {
            return None;
        }
        let guard = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let overflowed = guard.streams.values().map(|(t, _)| t.overflowed()).sum();
        let latest = guard
            .latest
            .and_then(|id| Some((id, guard.streams.get(id)?)));
        let Some((id, (tracker, _))) = latest else {
            let fresh = Tracker::new(&p.accuracy_lead_times, 1, 1).summary();
            return Some((fresh, Level::Ok, "no comparisons yet".into(), overflowed));
        };
        let figures = tracker.summary();
        let (level, why) = alarm(&figures, p.accuracy_warn_re, p.accuracy_error_re);
        Some((
            figures,
            level,
            format!("trajectory {id}: {why}"),
            overflowed,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{hamiltonian, SystemConfig, SystemKind};

    const S: Nanos = 1_000_000_000;

    fn setup() -> (Graph, Field, State) {
        let cfg = SystemConfig::new(SystemKind::Spring, 5);
        let g = cfg.graph();
        let s = cfg.start_for(&g, 3, 0);
        (g, cfg.field, s)
    }

    fn shifted(s: &State, dx: f64) -> State {
        let mut p = s.clone();
        p.q.iter_mut().for_each(|x| *x += dx);
        p
    }

    /// RE and EE as the paper defines them, written out independently.
    fn by_hand(g: &Graph, f: &Field, truth: &State, pred: &State) -> (f64, f64) {
        let n = |x: &[f64]| x.iter().map(|a| a * a).sum::<f64>().sqrt();
        let d: Vec<f64> = pred.q.iter().zip(&truth.q).map(|(a, b)| a - b).collect();
        let re = n(&d) / (n(&pred.q) + n(&truth.q));
        let (h, hp) = (hamiltonian(g, f, truth), hamiltonian(g, f, pred));
        (re, (hp - h).abs() / (hp.abs() + h.abs()))
    }

    #[test]
    fn steps_keep_whole_leads_within_the_horizon() {
        let t = Tracker::new(&[0.1, 0.5, 1.0, 0.015], 5, 100);
        // dt 0.01, 50 steps: 0.1 s is step 10, 0.5 s step 50; 1 s is beyond
        // the horizon; 0.015 s is 1.5 steps.
        assert_eq!(t.steps(Timing::new(0.01, 10, 50)), vec![(0, 10), (1, 50)]);
        assert_eq!(t.steps(Timing::new(0.0, 1, 50)), vec![]);
        // Kept every 2nd step of 0.01 s: 0.1 s is kept state 5, and 0.015 s
        // is within half of one 0.02 s kept step of state 1.
        let every2 = Timing {
            keep_every: 2,
            ..Timing::new(0.01, 1, 50)
        };
        assert_eq!(every2.kept(), 26);
        assert_eq!(t.steps(every2), vec![(0, 5), (1, 25), (3, 1)]);
    }

    #[test]
    fn predictions_are_matched_at_their_time_and_scored_by_the_metrics() {
        let (g, f, s) = setup();
        let mut t = Tracker::new(&[0.1, 0.2], 2, 100);
        let tol = S / 200; // half of a 0.01 s step
                           // From the state at 0: predictions for 0.1 s and 0.2 s.
        assert!(t.observe(1, 0, tol, &g, Some(&f), &s).is_empty());
        t.expect(1, 0, vec![(0, shifted(&s, 0.01)), (1, shifted(&s, 0.03))]);
        // From the state at 0.1 s: predictions for 0.2 s and 0.3 s.
        let s1 = shifted(&s, 0.002);
        let c = t.observe(1, S / 10 + 1_000, tol, &g, Some(&f), &s1);
        assert_eq!(c.len(), 1);
        let (re, ee) = by_hand(&g, &f, &s1, &shifted(&s, 0.01));
        assert_eq!(c[0].lead, 0.1);
        assert!((c[0].re - re).abs() <= 1e-12 * re, "{} vs {re}", c[0].re);
        assert!((c[0].ee.unwrap() - ee).abs() <= 1e-12 + 1e-9 * ee);
        t.expect(1, S / 10, vec![(0, shifted(&s, 0.02)), (1, s.clone())]);
        // At 0.2 s both leads match: 0.1 s (from 0.1) and 0.2 s (from 0).
        let c = t.observe(1, 2 * S / 10, tol, &g, None, &s);
        let leads: Vec<f64> = c.iter().map(|c| c.lead).collect();
        assert_eq!(leads, vec![0.1, 0.2]);
        assert!(c.iter().all(|c| c.ee.is_none()), "no field, no EE");
        let (re01, _) = by_hand(&g, &f, &s, &shifted(&s, 0.02));
        let (re02, _) = by_hand(&g, &f, &s, &shifted(&s, 0.03));
        assert!((c[0].re - re01).abs() < 1e-12 && (c[1].re - re02).abs() < 1e-12);
        // Running means over the window of 2 at lead 0.1: (re, re01).
        let sum = t.summary();
        assert_eq!(sum[0].compared, 2);
        assert!((sum[0].re_mean - f64::midpoint(re, re01)).abs() < 1e-12);
        assert!(
            (sum[0].ee_mean - ee).abs() < 1e-9,
            "EE mean over known ones"
        );
        assert_eq!(sum[1].compared, 1);
        // Only the prediction for 0.3 s is left.
        assert_eq!(t.pending(), 1);
    }

    #[test]
    fn unmatched_and_old_runs_are_forgotten_and_memory_is_bounded() {
        let (g, f, s) = setup();
        let tol = S / 2000;
        let mut t = Tracker::new(&[0.1], 3, 4);
        for k in 0..10 {
            t.expect(1, k * S / 100, vec![(0, s.clone())]);
        }
        assert_eq!(t.pending(), 4, "capacity");
        assert_eq!(t.overflowed(), 6);
        // A state at 0.185 s: the predictions for 0.16 .. 0.18 s are past.
        assert!(t
            .observe(1, 185 * S / 1000, tol, &g, Some(&f), &s)
            .is_empty());
        assert_eq!(t.pending(), 1);
        // Another trajectory starts over.
        assert!(t
            .observe(2, 190 * S / 1000, tol, &g, Some(&f), &s)
            .is_empty());
        assert_eq!(t.pending(), 0);
    }

    #[test]
    fn alarm_levels_follow_the_thresholds() {
        let fig = |lead, re_mean| LeadAccuracy {
            lead,
            compared: 3,
            re: re_mean,
            re_mean,
            ee: f64::NAN,
            ee_mean: f64::NAN,
        };
        let figures = [fig(0.1, 0.001), fig(1.0, 0.02)];
        assert_eq!(alarm(&figures, 0.05, 0.1).0, Level::Ok);
        let (level, msg) = alarm(&figures, 0.01, 0.1);
        assert_eq!(level, Level::Warn);
        assert!(
            msg.contains("lead 1 s") && msg.contains("2.000e-2"),
            "{msg}"
        );
        assert_eq!(alarm(&figures, 0.01, 0.015).0, Level::Error);
        assert_eq!(alarm(&figures, 0.0, 0.0).0, Level::Ok, "0 disables");
        assert_eq!(alarm(&[], 0.01, 0.02).0, Level::Ok);
    }

    /// The measured failure: a new trajectory must not report the previous
    /// one's comparisons or inherit its alarm.
    #[test]
    fn a_new_trajectory_starts_its_figures_and_alarm_from_nothing() {
        use crate::data::msg::{ParticleState, Time};
        use crate::ros::input::{Accepted, Inputs};
        let mut cfg = SystemConfig::new(SystemKind::Spring, 5);
        cfg.states = 21;
        let g = cfg.graph();
        let model = crate::models::truth::load_truth("truth:spring").unwrap();
        let p = NodeParams {
            dt: 0.1,
            substeps: 100,
            horizon: 10,
            accuracy_lead_times: vec![0.5, 1.0],
            accuracy_window: 3,
            accuracy_warn_re: 1e-3,
            accuracy_error_re: 5e-3,
            ..NodeParams::default()
        };
        let (inputs, live) = (Inputs::default(), Live::default());
        let run = |id: u32, sec: i32, drift: f64| {
            let tr = cfg.simulate_one(&g, cfg.start_for(&g, 3 + u64::from(id), 0), 0);
            let mut out = Vec::new();
            for (k, s) in tr.samples.iter().enumerate() {
                let mut s = s.clone();
                s.state.q.iter_mut().for_each(|x| *x += drift * k as f64);
                let mut m = ParticleState::from_sample(id, k as u32, "spring", &g, &s);
                m.header.stamp = Time {
                    sec: sec + (k / 10) as i32,
                    nanosec: (k % 10) as u32 * 100_000_000,
                };
                let Accepted::Ready(input) = inputs.accept(&p, m).unwrap() else {
                    panic!("full states are ready");
                };
                let mut pred = crate::dynamics::Predicted::default();
                let (graph, state) = (&input.graph, &input.state);
                crate::ros::predict::predict_into(
                    model.as_ref(),
                    graph,
                    state,
                    p.timing(),
                    &mut pred,
                )
                .unwrap();
                out.push((k, live.update(&p, &input, &pred.states)));
            }
            out
        };
        // Run 1 drifts away from what the model predicts: an ERROR alarm.
        let first = run(1, 100, 0.01);
        let last = first.last().unwrap().1.message.clone().unwrap();
        assert_eq!(last.level, Level::Error as u8, "{last:?}");
        assert!(last.compared.iter().all(|&c| c > 0));
        // Run 2 follows the model: every figure is its own, from nothing.
        let second = run(2, 300, 0.0);
        for (k, u) in &second {
            let Some(m) = &u.message else {
                // Nothing to compare before lead 0.5 s.
                assert!(*k < 5, "state {k} of run 2 compared nothing");
                continue;
            };
            assert_eq!(m.trajectory_id, 2);
            assert!(*k >= 5, "state {k} compared with run 1: {m:?}");
            assert_eq!(m.compared[0], *k as u64 - 4, "state {k}: {m:?}");
            let reached_1s = *k >= 10;
            assert_eq!(m.compared[1] > 0, reached_1s, "state {k}: {m:?}");
            assert!(m.re[1].is_nan() != reached_1s, "state {k}: {m:?}");
            assert_eq!(m.level, Level::Ok as u8, "state {k}: {m:?}");
        }
        // Run 2 never raised or cleared an alarm it did not cause.
        assert!(second.iter().all(|(_, u)| u.alarm_changed.is_none()));
    }
}
