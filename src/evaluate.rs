//! Evaluation: roll a model out from each test trajectory's first state and
//! compare with what was recorded (RE, EE, ME over time, paper's metrics).

use crate::data::bag::Bag;
use crate::data::field::{bag_field, bag_system, stamp_interval, unknown_field_error};
use crate::dynamics::{Dynamics, Timing};
use crate::error::{bail, Result};
use crate::lagrange_metrics::{self as lb, LagrangeMetrics};
use crate::metrics::{error_curves, summarize, ErrorCurves, StillReference, Summary};
use crate::physics::{Field, SystemConfig};
use crate::system::{fingerprint, State, Trajectory};
use serde::Serialize;
use std::time::Instant;

/// Evaluation settings.
#[derive(Clone, Debug, Default)]
pub struct EvalOptions {
    /// Integration step; default: the bag's simulator step, else the interval
    /// of its header stamps.
    pub dt: Option<f64>,
    /// Field for the Hamiltonian; default: the bag's ([`bag_field`]).
    pub field: Option<Field>,
    /// Evaluate at most this many trajectories.
    pub max_trajectories: Option<usize>,
    /// Evaluate even if test starts coincide with training starts.
    pub allow_overlap: bool,
    /// Particle spacing of LagrangeBench's E_kin (volume dx^d); default: the
    /// bag metadata's `dx`, else 1 (unit volume).
    pub dx: Option<f64>,
    /// Sinkhorn on at most this many particles (evenly strided); default all.
    pub sinkhorn_particles: Option<usize>,
}

/// Bag metadata key of the particle spacing (LagrangeBench's `dx`).
pub const KEY_DX: &str = "dx";

/// The benchmark metrics' settings, resolved.
#[derive(Clone, Copy, Debug)]
struct LbSettings {
    dx: f64,
    sinkhorn_particles: Option<usize>,
}

/// Result of an evaluation.
#[derive(Clone, Debug, Serialize)]
pub struct Evaluation {
    /// Model description.
    pub model: String,
    /// System name.
    pub system: String,
    /// Particles in the test graph.
    pub particles: usize,
    /// Trajectories evaluated.
    pub trajectories: usize,
    /// Integration step used.
    pub dt: f64,
    /// Where `dt` came from.
    pub dt_source: String,
    /// Field of the Hamiltonian behind EE.
    pub field: Field,
    /// Where the field came from.
    pub field_source: String,
    /// Integration steps per trajectory.
    pub steps: usize,
    /// Wall time of all rollouts, seconds.
    pub rollout_seconds: f64,
    /// Trajectories whose rollout diverged (non-finite state); from then on
    /// they score the worst errors (see [`crate::metrics`]).
    pub diverged: usize,
    /// Geometric means and 95% bands over trajectories.
    pub summary: Summary,
    /// Time averages of the geometric-mean curves (t > 0).
    pub averages: crate::metrics::Averages,
    /// The "nothing moves" reference on the same trajectories (`None` when
    /// the model is that reference).
    pub still: Option<StillReference>,
    /// LagrangeBench's metrics (MSE5/10/20, Sinkhorn, E_kin MSE) of the
    /// model, mean over trajectories ([`crate::lagrange_metrics`]).
    pub lagrange: LagrangeMetrics,
    /// The same of the standing-still predictor on the same starts (`None`
    /// when the model is that predictor).
    pub still_lagrange: Option<LagrangeMetrics>,
    /// Particle spacing behind E_kin, and where it came from.
    pub dx: f64,
    /// Where `dx` came from.
    pub dx_source: String,
    /// Particles Sinkhorn was computed on (`None`: all).
    pub sinkhorn_particles: Option<usize>,
    /// The ensemble's spread beside its error ([`crate::calibration`]).
    pub calibration: crate::calibration::Calibration,
    /// Per-trajectory curves.
    #[serde(skip)]
    pub curves: Vec<ErrorCurves>,
}

/// Rolls `model` out from each trajectory's first state and scores it.
/// `train_starts` are the fingerprints of the model's training starts: a test
/// trajectory that starts at one of them is refused (unless allowed).
pub fn evaluate(
    model: &dyn Dynamics,
    train_starts: &[String],
    bag: &Bag,
    opts: &EvalOptions,
) -> Result<Evaluation> {
    let sys = bag_system(bag)?;
    let (dt, dt_source) = step(bag, opts, sys.as_ref())?;
    if !(dt.is_finite() && dt > 0.0) {
        bail!("time step must be positive, got {dt}");
    }
    let origin = bag_field(bag, opts.field.as_ref())?
        .ok_or_else(|| unknown_field_error("the energy error"))?;
    let field = origin.field.clone();
    let trajs: Vec<_> = bag
        .trajectories
        .iter()
        .take(opts.max_trajectories.unwrap_or(usize::MAX))
        .collect();
    if trajs.is_empty() {
        bail!("the bag has no trajectories");
    }
    if !opts.allow_overlap {
        refuse_overlap(&trajs, train_starts)?;
    }
    let groups = group(&trajs, dt)?;
    let (dx, dx_source) = spacing(bag, opts)?;
    let lbs = LbSettings {
        dx,
        sinkhorn_particles: opts.sinkhorn_particles,
    };
    let start = Instant::now();
    let (scored, diverged, steps_total, samples) = score(model, &trajs, &groups, dt, &field, lbs)?;
    let calibration = crate::calibration::Calibration::new(model.members(), &samples);
    let rollout_seconds = start.elapsed().as_secs_f64();
    let (curves, lagrange) = split(scored)?;
    let summary = summarize(&curves)?;
    let averages = summary.time_average();
    let reference = crate::dynamics::Still;
    let (still, still_lagrange) = if model.describe() == reference.describe() {
        (None, None)
    } else {
        let (c, _, _, _) = score(&reference, &trajs, &groups, dt, &field, lbs)?;
        let (c, l) = split(c)?;
        let s = summarize(&c)?;
        (Some(StillReference::new(&s, averages.re)), Some(l))
    };
    Ok(Evaluation {
        averages,
        model: model.describe(),
        system: trajs[0].system.clone(),
        particles: trajs[0].graph.n(),
        trajectories: trajs.len(),
        dt,
        dt_source: dt_source.to_string(),
        field,
        field_source: origin.source,
        steps: steps_total,
        rollout_seconds,
        diverged,
        summary,
        still,
        lagrange,
        still_lagrange,
        dx,
        dx_source,
        sinkhorn_particles: opts.sinkhorn_particles,
        calibration,
        curves,
    })
}

/// The particle spacing of E_kin: `--dx`, the bag metadata's `dx`, or 1.
fn spacing(bag: &Bag, opts: &EvalOptions) -> Result<(f64, String)> {
    let (dx, source) = match (opts.dx, bag.metadata.get(KEY_DX)) {
        (Some(dx), _) => (dx, "--dx".to_string()),
        (None, Some(v)) => match v.trim().parse::<f64>() {
            Ok(dx) => (dx, "the bag metadata's dx".to_string()),
            Err(e) => bail!("bag metadata {KEY_DX} = {v:?} is not a number ({e}); pass --dx"),
        },
        (None, None) => (
            1.0,
            "unit volume (the bag says no dx; pass --dx)".to_string(),
        ),
    };
    if !(dx.is_finite() && dx > 0.0) {
        bail!("the particle spacing dx must be finite and positive, got {dx} (from {source})");
    }
    Ok((dx, source))
}

/// Curves and the mean of the benchmark metrics of scored trajectories.
fn split(
    scored: Vec<(ErrorCurves, LagrangeMetrics)>,
) -> Result<(Vec<ErrorCurves>, LagrangeMetrics)> {
    let (curves, lagrange): (Vec<_>, Vec<_>) = scored.into_iter().unzip();
    let mean =
        lb::average(&lagrange).ok_or_else(|| crate::error::err!("no trajectory to score"))?;
    Ok((curves, mean))
}

/// Whether a recording moves its kinematic particles (a gripper, a pusher):
/// then rollouts follow that recorded motion instead of holding them.
pub fn kinematic_moves(tr: &crate::system::Trajectory) -> bool {
    let (g, d) = (&tr.graph, tr.graph.dim);
    let Some(first) = tr.samples.first() else {
        return false;
    };
    (0..g.n()).filter(|&i| g.is_kinematic(i)).any(|i| {
        let start = &first.state.q[i * d..(i + 1) * d];
        tr.samples
            .iter()
            .any(|s| &s.state.q[i * d..(i + 1) * d] != start)
    })
}

/// A rollout of `model` from the recording's first state with its kinematic
/// particles moved as recorded (cubic Hermite between the recorded states,
/// [`crate::physics::Drive::from_samples`]); a rollout that diverges keeps
/// only its start and the step it diverged at.
fn driven_rollout(
    model: &dyn Dynamics,
    tr: &crate::system::Trajectory,
    timing: Timing,
) -> Result<crate::dynamics::Rollout> {
    let g = &tr.graph;
    let drive = crate::physics::Drive::from_samples(g, &tr.samples, timing.step(), timing.steps())
        .map_err(|e| crate::error::err!("trajectory {}: {e}", tr.id))?;
    let start = tr.samples[0].state.clone();
    match model.rollout_driven(g, &start, timing, &drive) {
        Ok(states) => Ok(crate::dynamics::Rollout {
            states,
            diverged_at: None,
        }),
        Err(crate::dynamics::DynamicsError::Diverged(step)) => Ok(crate::dynamics::Rollout {
            states: vec![start],
            diverged_at: Some(step),
        }),
        Err(e) => Err(crate::error::err!("trajectory {}: {e}", tr.id)),
    }
}

/// One rollout group: (save every, steps, members of `trajs`).
type Group = (usize, usize, Vec<usize>);

/// The integration step and where it comes from: `--dt`, the bag's
/// system_config, or its evenly spaced header stamps.
fn step(bag: &Bag, opts: &EvalOptions, sys: Option<&SystemConfig>) -> Result<(f64, &'static str)> {
    Ok(match (opts.dt, sys) {
        (Some(dt), _) => (dt, "--dt"),
        (None, Some(s)) => (s.dt, "the bag's system_config"),
        (None, None) => match stamp_interval(bag) {
            Some(d) => (d, "the header stamps"),
            None => bail!(
                "the bag does not say its integration step and its stamps are not evenly \
                 spaced; pass --dt"
            ),
        },
    })
}

/// Refuses test trajectories that start where training trajectories did
/// (`train_starts`: their fingerprints).
fn refuse_overlap(trajs: &[&Trajectory], train_starts: &[String]) -> Result<()> {
    let train: std::collections::HashSet<&String> = train_starts.iter().collect();
    let overlap = trajs
        .iter()
        .filter(|t| train.contains(&fingerprint(&t.samples[0].state)))
        .count();
    if overlap > 0 {
        bail!(
            "{overlap} of {} test trajectories start where training trajectories did; \
             evaluate on a bag simulated with another seed (or pass --allow-overlap)",
            trajs.len()
        );
    }
    Ok(())
}

/// Groups the trajectories on the same graph with the same sampling, to be
/// rolled out together (the candle baselines batch them; see
/// Dynamics::rollout_many). Refuses a saved interval that is not a multiple
/// of `dt`.
fn group(trajs: &[&Trajectory], dt: f64) -> Result<Vec<Group>> {
    let mut groups: Vec<Group> = vec![];
    for (i, tr) in trajs.iter().enumerate() {
        let times: Vec<f64> = tr.samples.iter().map(|s| s.t).collect();
        let interval = if times.len() > 1 {
            times[1] - times[0]
        } else {
            dt
        };
        let every = ((interval / dt).round() as usize).max(1);
        if ((every as f64 * dt - interval) / interval).abs() > 1e-6 {
            bail!(
                "trajectory {}: saved interval {interval} s is not a multiple of dt {dt}",
                tr.id
            );
        }
        let steps = every * (times.len() - 1);
        match groups
            .iter_mut()
            .find(|(e, st, m)| *e == every && *st == steps && trajs[m[0]].graph == tr.graph)
        {
            Some(g) => g.2.push(i),
            None => groups.push((every, steps, vec![i])),
        }
    }
    Ok(groups)
}

/// A scored trajectory: its error curves and benchmark metrics.
type Scored = (ErrorCurves, LagrangeMetrics);

/// What [`score`] returns: the scored trajectories in trajectory order, how
/// many diverged, the steps of the last group, and the spread beside the
/// error of each rollout that neither diverged nor was driven.
type Scores = (Vec<Scored>, usize, usize, Vec<crate::calibration::Sample>);

/// Rolls `model` out over every group and scores each trajectory.
fn score(
    model: &dyn Dynamics,
    trajs: &[&crate::system::Trajectory],
    groups: &[Group],
    dt: f64,
    field: &Field,
    lbs: LbSettings,
) -> Result<Scores> {
    let mut samples = vec![];
    let mut scored: Vec<Option<Scored>> = vec![None; trajs.len()];
    let mut steps_total = 0;
    let mut diverged = 0;
    for (every, steps, members) in groups {
        let g = &trajs[members[0]].graph;
        let starts: Vec<State> = members
            .iter()
            .map(|&i| trajs[i].samples[0].state.clone())
            .collect();
        let driven = members.iter().any(|&i| kinematic_moves(trajs[i]));
        let timing = Timing::integration(dt, *steps, *every);
        let rollouts: Vec<_> = if driven {
            members
                .iter()
                .map(|&i| Ok((driven_rollout(model, trajs[i], timing)?, None)))
                .collect::<Result<Vec<_>>>()?
        } else {
            model
                .rollout_many_spread(g, &starts, timing)
                .map_err(|e| crate::error::err!("trajectory {}: {e}", trajs[members[0]].id))?
                .into_iter()
                .map(|(r, s)| (r, Some(s)))
                .collect()
        };
        steps_total = *steps;
        for (&i, (r, spread)) in members.iter().zip(rollouts) {
            diverged += usize::from(r.diverged_at.is_some());
            if let (Some(sp), None) = (&spread, r.diverged_at) {
                samples.push(calibration_sample(trajs[i], &r, sp));
            }
            scored[i] = Some(score_one(trajs[i], field, &r, lbs)?);
        }
    }
    Ok((
        scored.into_iter().flatten().collect(),
        diverged,
        steps_total,
        samples,
    ))
}

/// The spread beside the error of one rollout that neither diverged nor
/// was driven.
fn calibration_sample(
    tr: &Trajectory,
    r: &crate::dynamics::Rollout,
    spread: &[Vec<f64>],
) -> crate::calibration::Sample {
    let times: Vec<f64> = tr.samples.iter().map(|s| s.t).collect();
    let k = r.states.len().min(times.len());
    let truth: Vec<State> = tr.samples[..k].iter().map(|s| s.state.clone()).collect();
    crate::calibration::Sample::new(tr.graph.dim, &times[..k], &truth, &r.states[..k], spread)
}

/// The error curves and benchmark metrics of one rollout `r` of `tr`.
fn score_one(
    tr: &Trajectory,
    field: &Field,
    r: &crate::dynamics::Rollout,
    lbs: LbSettings,
) -> Result<Scored> {
    let g = &tr.graph;
    let times: Vec<f64> = tr.samples.iter().map(|s| s.t).collect();
    let k = r.states.len().min(times.len());
    let truth: Vec<State> = tr.samples[..k].iter().map(|s| s.state.clone()).collect();
    let c = error_curves(g, field, &truth, &r.states[..k], &times[..k])
        .map_err(|e| crate::error::err!("trajectory {}: {e}", tr.id))?;
    if r.diverged_at.is_some() {
        let frames = times.len().saturating_sub(1).min(lb::HORIZON);
        return Ok((ErrorCurves::diverged(c, &times), lb::diverged(frames)));
    }
    fn frames(states: &[State]) -> lb::Frames<'_> {
        lb::Frames {
            q: states.iter().map(|s| s.q.as_slice()).collect(),
        }
    }
    let (t, p) = (&truth[..], &r.states[..k]);
    let frame_dt = if k > 1 { times[1] - times[0] } else { 0.0 };
    let m = lb::trajectory_metrics_sampled(
        &frames(t),
        &frames(p),
        g.dim,
        frame_dt,
        lbs.dx,
        lbs.sinkhorn_particles,
        g.periodic_box.as_ref(),
    )
    .map_err(|e| crate::error::err!("trajectory {}: LagrangeBench metrics: {e}", tr.id))?;
    Ok((c, m))
}

/// A plain-text table of a summary at a few times.
pub fn table(e: &Evaluation, rows: usize) -> String {
    let s = &e.summary;
    let still = e.still.as_ref();
    let mut out = format!(
        "{} on {}-particle {} ({} trajectories, dt {}):\n{:>8}  {:>10}  {:>10}  {:>10}  {:>10}{}\n",
        e.model,
        e.particles,
        e.system,
        e.trajectories,
        e.dt,
        "t [s]",
        "RE",
        "EE",
        "ME",
        "ME scaled",
        if still.is_some() { "  RE still" } else { "" }
    );
    let still_at = |i: usize| still.map_or(String::new(), |r| r.cell(i));
    let n = s.t.len();
    for i in crate::metrics::evenly_spaced(n, rows) {
        out += &format!(
            "{:>8.3}  {:>10.3e}  {:>10.3e}  {:>10.3e}  {:>10.3e}{}\n",
            s.t[i],
            s.re.gmean[i],
            s.ee.gmean[i],
            s.me.gmean[i],
            s.me_scaled.gmean[i],
            still_at(i)
        );
    }
    let a = s.time_average();
    if e.diverged > 0 {
        out += &format!(
            "({} of {} rollouts diverged: worst errors from then on)\n",
            e.diverged, e.trajectories
        );
    }
    out += &format!(
        "{:>8}  {:>10.3e}  {:>10.3e}  {:>10.3e}  {:>10.3e}{}\n",
        "mean",
        a.re,
        a.ee,
        a.me,
        a.me_scaled,
        still.map_or(String::new(), |r| format!("  {:>8.3e}", r.re_mean))
    );
    if let Some(r) = still {
        out += &r.verdict(a.re);
    }
    out += &lagrange_table(e);
    let c = &e.calibration;
    if c.members > 1 {
        let leads: Vec<String> = c
            .spread_at_leads
            .iter()
            .map(|l| format!("{} s {:.2e}", l.lead, l.mean_spread))
            .collect();
        let opt = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.2}"));
        out += &format!(
            "ensemble of {}: mean spread {}; Spearman(spread, error) at 1 s {}, \
             within 2 spreads {}\n",
            c.members,
            leads.join(", "),
            opt(c.spearman_spread_error_1s),
            opt(c.within_2_spreads)
        );
    }
    out += &format!(
        "(dt from {}; field for EE from {})\n",
        e.dt_source, e.field_source
    );
    out
}

/// The benchmark metrics of the model and of standing still, a row each.
fn lagrange_table(e: &Evaluation) -> String {
    let cell = |v: Option<f64>| v.map_or(format!("{:>10}", "-"), |v| format!("{v:>10.3e}"));
    let row = |name: &str, m: &LagrangeMetrics| {
        format!(
            "{name:>8}  {}  {}  {}  {}  {}\n",
            cell(m.mse5),
            cell(m.mse10),
            cell(m.mse20),
            cell(Some(m.sinkhorn)),
            cell(m.e_kin_mse)
        )
    };
    let sampled = e
        .sinkhorn_particles
        .filter(|&k| k < e.particles)
        .map_or(String::new(), |k| format!(", Sinkhorn on {k} particles"));
    let mut out = format!(
        "LagrangeBench metrics over the first {} frames (dx {} from {}{sampled}):\n\
         {:>8}  {:>10}  {:>10}  {:>10}  {:>10}  {:>10}\n",
        e.lagrange.frames, e.dx, e.dx_source, "", "MSE5", "MSE10", "MSE20", "Sinkhorn", "E_kin MSE"
    );
    out += &row("model", &e.lagrange);
    if let Some(s) = &e.still_lagrange {
        out += &row("still", s);
    }
    out
}
