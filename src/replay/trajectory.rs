//! The second stage: every start state of one trajectory rolled out to the
//! later recorded states within the horizon, and the errors binned by lead.

use crate::data::bag::Bag;
use crate::data::stream::{Estimate, History, Smoother, StreamOptions};
use crate::dynamics::{Dynamics, DynamicsError, Timing};
use crate::error::{bail, Result};
use crate::estimate::{FitOptions, ModelFit};
use crate::metrics::error_curves;
use crate::system::{State, Trajectory};

use super::bins::Bin;
use super::report::ReplayReport;
use super::settings::Settings;

/// Rolls `model` from `from` over `span` seconds in equal steps of at most
/// `dt`, returning the final state.
fn advance(
    model: &dyn Dynamics,
    tr: &Trajectory,
    from: &State,
    span: f64,
    dt: f64,
) -> Result<State, DynamicsError> {
    // The 1e-9 keeps an interval that is a whole number of steps (up to
    // round-off in the stamps) from getting one extra tiny step.
    let steps = ((span / dt) * (1.0 - 1e-9)).ceil().max(1.0) as usize;
    let h = span / steps as f64;
    let mut states = model.rollout(&tr.graph, from, Timing::integration(h, steps, steps))?;
    states
        .pop()
        .ok_or_else(|| DynamicsError::Model("the model returned no states".into()))
}

/// The state each recorded state starts a prediction from: the recorded one,
/// or with `causal` its positions with velocities estimated from it and the
/// states before ([`History`], as the node does; `None` while warming up).
/// The model smoother fits the history's window through `model` (steps of at
/// most `dt`) at the states predicted from (every `stride`-th), each fit
/// warm-started from the one before rolled on to its window; where its
/// rollout diverges the history's own estimate stands.
fn start_states(
    model: &dyn Dynamics,
    tr: &Trajectory,
    (causal, stream): (bool, &StreamOptions),
    dt: f64,
    stride: usize,
) -> Result<Vec<Option<State>>> {
    if !causal {
        return Ok(tr.samples.iter().map(|s| Some(s.state.clone())).collect());
    }
    let mut fit = match stream.smoother {
        Smoother::Model { .. } => Some(
            ModelFit::new(model, &tr.graph, FitOptions::with_dt(dt))
                .map_err(|e| crate::error::err!("trajectory {}: {e}", tr.id))?,
        ),
        _ => None,
    };
    let mut h = History::default();
    let starts = tr.samples.iter().enumerate().map(|(k, s)| {
        let t = (s.t * 1e9).round() as crate::data::stream::Nanos;
        let (reset, est) = h.push(stream, &tr.graph, t, &s.state.q);
        let Estimate::Ready(state) = est else {
            return None;
        };
        let Some(fit) = fit.as_mut() else {
            return Some(state);
        };
        if reset.is_some() {
            fit.reset();
        }
        if k % stride != 0 {
            // Not predicted from: its estimate is never used.
            return Some(state);
        }
        let (stamps, positions) = h.window();
        Some(fit.fit(&stamps, &positions).map_or(state, |f| f.state))
    });
    Ok(starts.collect())
}

/// The reference trajectory for `tr`: same id, graph, and stamps (to 1 µs).
pub(super) fn reference_for<'a>(reference: &'a Bag, tr: &Trajectory) -> Result<&'a Trajectory> {
    let r = reference
        .trajectories
        .iter()
        .find(|r| r.id == tr.id)
        .ok_or_else(|| crate::error::err!("the reference bag has no trajectory {}", tr.id))?;
    if r.graph != tr.graph || r.samples.len() != tr.samples.len() {
        bail!(
            "reference trajectory {} does not match the replayed one ({} states against {}, \
             or another graph): pass the recording the replayed bag was made from",
            tr.id,
            r.samples.len(),
            tr.samples.len()
        );
    }
    if let Some(k) = (0..r.samples.len()).find(|&k| (r.samples[k].t - tr.samples[k].t).abs() > 1e-6)
    {
        bail!(
            "reference trajectory {}: state {k} is at {} s, the replayed one at {} s",
            tr.id,
            r.samples[k].t,
            tr.samples[k].t
        );
    }
    Ok(r)
}

/// Replays every start state of one trajectory into the bins.
#[allow(clippy::too_many_arguments)]
pub(super) fn replay_trajectory(
    model: &dyn Dynamics,
    tr: &Trajectory,
    truth: Option<&Trajectory>,
    (causal, stream): (bool, &StreamOptions),
    p: &Settings,
    stride: usize,
    bins: &mut [Bin],
    report: &mut ReplayReport,
) -> Result<()> {
    model
        .supports(&tr.graph)
        .map_err(|e| crate::error::err!("trajectory {}: the model cannot take it: {e}", tr.id))?;
    // Leads a little past the horizon (stamp round-off) still count.
    let limit = p.horizon + 1e-6 * p.bin_width;
    let s = &tr.samples;
    let starts = start_states(model, tr, (causal, stream), p.dt, stride)?;
    let truth_of = |j: usize| truth.map_or(&s[j].state, |r| &r.samples[j].state);
    for k in (0..s.len()).step_by(stride) {
        let Some(start) = &starts[k] else {
            // Still warming up, as the node would be: not a start.
            continue;
        };
        let t0 = s[k].t;
        let targets: Vec<usize> = (k + 1..s.len())
            .take_while(|&j| s[j].t - t0 <= limit)
            .collect();
        if targets.is_empty() {
            continue;
        }
        report.starts += 1;
        // Lead 0: the start itself, errors exactly 0.
        bins[0].push(0.0, [0.0; 4]);
        let mut cur = start.clone();
        let mut t_cur = t0;
        let mut truths = Vec::with_capacity(targets.len());
        let mut pred = Vec::with_capacity(targets.len());
        let mut leads = Vec::with_capacity(targets.len());
        let mut failed = false;
        for &j in &targets {
            match advance(model, tr, &cur, s[j].t - t_cur, p.dt) {
                Ok(next) => {
                    cur = next;
                    t_cur = s[j].t;
                    truths.push(truth_of(j).clone());
                    pred.push(cur.clone());
                    leads.push(s[j].t - t0);
                }
                Err(e) => {
                    report.diverged += 1;
                    report.first_failure.get_or_insert_with(|| {
                        format!("trajectory {}, start {k} (t = {t0} s): {e}", tr.id)
                    });
                    failed = true;
                    break;
                }
            }
        }
        let bin_of = |lead: f64| ((lead / p.bin_width).round() as usize).clamp(1, p.bins);
        if !pred.is_empty() {
            let c = error_curves(&tr.graph, &p.field, &truths, &pred, &leads)
                .map_err(|e| crate::error::err!("trajectory {}, start {k}: {e}", tr.id))?;
            for i in 0..leads.len() {
                bins[bin_of(leads[i])].push(leads[i], [c.re[i], c.ee[i], c.me[i], c.me_scaled[i]]);
            }
        }
        if failed {
            for &j in &targets[pred.len()..] {
                let lead = s[j].t - t0;
                bins[bin_of(lead)].push(lead, [1.0; 4]);
            }
        }
        report.comparisons += targets.len();
    }
    Ok(())
}
