//! Replay: feed every recorded state of a bag through a model, as the node
//! would receive it, and score the predictions against the states recorded
//! after it: RE, EE and ME (the paper's metrics, [`crate::metrics`]) as a
//! function of *lead time* (how far ahead the prediction looks).
//!
//! For each start state k the model is rolled out from the recorded state to
//! the times of the following recorded states up to `horizon` seconds later.
//! Each gap between recorded times is cut into equal steps no longer than
//! `dt`, so the rollout lands exactly on every recorded time: irregular stamps
//! work. Bags recorded by the node (inputs plus prediction topics) and
//! simulated bags both work: only `ParticleState` messages are read.
//!
//! Summary over start states: every (start, lead) pair goes to the nearest
//! point of a lead-time grid (spacing `bin_width`), and each grid point gets
//! the geometric mean and 95% band of its errors, exactly as
//! [`crate::metrics::summarize`] defines them, computed streaming (a long node
//! recording can have millions of pairs). Grid points no pair fell on are
//! left out. The grid starts with lead 0 (errors exactly 0), as
//! [`crate::evaluate`]'s curves start with t = 0, so
//! [`Summary::time_average`] skips it the same way.

use std::time::Instant;

use crate::error::{bail, Context as _, Result};
use serde::Serialize;

use crate::data::bag::Bag;
use crate::data::field::bag_system;
use crate::data::stream::{Estimate, History, Smoother, StreamOptions};
use crate::dynamics::{Dynamics, DynamicsError};
use crate::metrics::{error_curves, floored_ln, log_band, Averages, Band, StillReference, Summary};
use crate::physics::Field;
use crate::system::{State, Trajectory};

/// Grid points used when the bag's stamps are irregular and no `bins` is given.
pub const DEFAULT_IRREGULAR_BINS: usize = 20;
/// Default horizon, in recorded intervals, for bags that do not say the node's.
pub const DEFAULT_HORIZON_INTERVALS: f64 = 10.0;
/// Largest number of grid points accepted.
pub const MAX_BINS: usize = 100_000;
/// Replay settings; `Default` takes everything from the bag.
#[derive(Clone, Debug, Default)]
pub struct ReplayOptions {
    /// Largest integration step, seconds. Default: the bag's simulator step
    /// (`system_config`), else the recording node's `dt` metadata, else the
    /// interval of evenly spaced header stamps.
    pub dt: Option<f64>,
    /// Longest lead time, seconds. Default: the recording node's horizon × dt
    /// (its metadata), else [`DEFAULT_HORIZON_INTERVALS`] median recorded
    /// intervals.
    pub horizon: Option<f64>,
    /// Lead-time grid points after lead 0 (spacing horizon / bins). Default:
    /// one per recorded interval when the stamps are regular (no binning at
    /// all), else [`DEFAULT_IRREGULAR_BINS`].
    pub bins: Option<usize>,
    /// Field for the energy error. Default: the bag's
    /// ([`crate::data::field::bag_field`]); refused when it cannot be known.
    pub field: Option<Field>,
    /// Replay at most this many trajectories (the first ones, by id).
    pub max_trajectories: Option<usize>,
    /// Use every `stride`-th recorded state as a start (0 and 1: all).
    pub stride: usize,
    /// Start from positions only, with velocities estimated causally from
    /// the states before (the node's rule for position-only streams,
    /// [`crate::data::stream`]), even where the bag records velocities.
    /// Position-only trajectories are always started this way.
    pub positions_only: bool,
    /// How those velocities are estimated.
    pub stream: StreamOptions,
    /// Score against this bag's states (same trajectory ids and stamps, e.g.
    /// the noise-free recording of a noisy one) instead of the replayed
    /// bag's own.
    pub reference: Option<Bag>,
}

/// Result of a replay.
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    /// Model description.
    pub model: String,
    /// System name of the first trajectory ("" when the messages do not say).
    pub system: String,
    /// Particles in the first trajectory's graph.
    pub particles: usize,
    /// Trajectories replayed.
    pub trajectories: usize,
    /// Start states replayed (states with a later one within the horizon).
    pub starts: usize,
    /// (start, lead) pairs compared.
    pub comparisons: usize,
    /// Starts whose rollout failed (diverged) before the horizon; their
    /// remaining leads count with errors 1, the metrics' limit for a
    /// prediction that runs away.
    pub diverged: usize,
    /// The first rollout failure, if any.
    pub first_failure: Option<String>,
    /// Largest integration step, seconds.
    pub dt: f64,
    /// Where `dt` came from.
    pub dt_source: String,
    /// Longest lead time, seconds.
    pub horizon: f64,
    /// Where `horizon` came from.
    pub horizon_source: String,
    /// Spacing of the lead-time grid, seconds.
    pub bin_width: f64,
    /// Whether every recorded interval was the same (to 1e-6 relative).
    pub regular_stamps: bool,
    /// Field used for the energy error.
    pub field: Field,
    /// Where the field came from.
    pub field_source: String,
    /// Pairs per grid point (same order as `summary.t`).
    pub counts: Vec<usize>,
    /// Mean actual lead time of the pairs of each grid point, seconds.
    pub mean_lead: Vec<f64>,
    /// Geometric means and 95% bands per grid point; `summary.t` is the lead time.
    pub summary: Summary,
    /// Largest error per grid point (the log-scale band is uninformative
    /// when some pairs are bit-exact, their errors floored at 1e-300).
    pub worst: Worst,
    /// Averages of the geometric-mean curves over leads > 0.
    pub averages: Averages,
    /// Wall time of the replay, seconds.
    pub seconds: f64,
    /// The "nothing moves" reference replayed on the same starts and leads
    /// (`None` when the model is that reference).
    pub still: Option<StillReference>,
    /// Where the start states' velocities came from: "recorded", or the
    /// causal estimate (as the node makes it for position-only states).
    pub start_velocities: String,
    /// What the predictions were scored against: "the replayed bag" or the
    /// reference bag's files.
    pub scored_against: String,
}

/// The largest value of each metric per grid point.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Worst {
    /// RE.
    pub re: Vec<f64>,
    /// EE.
    pub ee: Vec<f64>,
    /// ME (paper definition).
    pub me: Vec<f64>,
    /// ME relative to the momentum scale.
    pub me_scaled: Vec<f64>,
}

/// Streaming mean and variance (Welford) of the log of one metric.
#[derive(Clone, Copy, Debug, Default)]
struct LogStats {
    n: usize,
    mean: f64,
    m2: f64,
    max: f64,
}

impl LogStats {
    fn push(&mut self, x: f64) {
        self.max = self.max.max(x);
        let l = floored_ln(x);
        self.n += 1;
        let d = l - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (l - self.mean);
    }

    /// (geometric mean, lo, hi) as [`crate::metrics::summarize`] defines them.
    fn band(&self) -> (f64, f64, f64) {
        let var = if self.n > 1 {
            self.m2 / (self.n - 1) as f64
        } else {
            0.0
        };
        log_band(self.mean, var)
    }
}

/// Everything that fell on one grid point.
#[derive(Clone, Debug, Default)]
struct Bin {
    /// RE, EE, ME, ME scaled.
    stats: [LogStats; 4],
    lead_sum: f64,
}

impl Bin {
    fn push(&mut self, lead: f64, errors: [f64; 4]) {
        self.lead_sum += lead;
        for (s, e) in self.stats.iter_mut().zip(errors) {
            // A non-finite error (an overflowing prediction) counts at its limit, 1.
            s.push(if e.is_finite() { e } else { 1.0 });
        }
    }

    fn count(&self) -> usize {
        self.stats[0].n
    }
}

/// The settings a replay runs with, resolved from the options and the bag.
struct Plan {
    dt: f64,
    dt_source: String,
    horizon: f64,
    horizon_source: String,
    bin_width: f64,
    bins: usize,
    regular: bool,
    field: Field,
    field_source: String,
}

fn positive(x: f64, what: &str) -> Result<f64> {
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        bail!("{what} must be a positive finite number, got {x}")
    }
}

fn plan(bag: &Bag, trajs: &[&Trajectory], opts: &ReplayOptions) -> Result<Plan> {
    let sys = bag_system(bag)?;
    let meta = bag.meta()?;
    let node_dt = meta.node_dt;
    let (dt, dt_source) = match (opts.dt, &sys, node_dt) {
        (Some(dt), _, _) => (dt, "option"),
        (None, Some(s), _) => (s.dt, "bag system_config (simulator step)"),
        (None, None, Some(dt)) => (dt, "bag metadata dt (the recording node's step)"),
        (None, None, None) => match crate::data::field::stamp_interval(bag) {
            Some(d) => (d, "the header stamps (their interval)"),
            None => bail!(
                "the bag does not say its integration step (no system_config or dt metadata, \
                 and its stamps are not evenly spaced); pass --dt"
            ),
        },
    };
    let dt = positive(dt, "dt")?;
    let mut intervals: Vec<f64> = trajs
        .iter()
        .flat_map(|t| t.samples.windows(2).map(|w| w[1].t - w[0].t))
        .collect();
    if intervals.is_empty() {
        bail!("no trajectory has two recorded states: nothing to compare a prediction with");
    }
    intervals.sort_by(f64::total_cmp);
    let median = intervals[intervals.len() / 2];
    let (lo, hi) = (intervals[0], intervals[intervals.len() - 1]);
    let regular = hi - lo <= 1e-6 * median;
    let node_horizon = meta.node_horizon.map(f64::from);
    let (horizon, horizon_source) = match (opts.horizon, node_horizon, node_dt) {
        (Some(h), _, _) => (h, "option".to_string()),
        (None, Some(h), Some(d)) => (h * d, "the recording node's horizon × dt".to_string()),
        _ => (
            DEFAULT_HORIZON_INTERVALS * median,
            format!("{DEFAULT_HORIZON_INTERVALS} median recorded intervals"),
        ),
    };
    let horizon = positive(horizon, "horizon")?;
    let (bins, bin_width) = match opts.bins {
        Some(b) if b == 0 || b > MAX_BINS => bail!("bins must be in 1..={MAX_BINS}, got {b}"),
        Some(b) => (b, horizon / b as f64),
        None if regular => {
            // Leads are whole intervals: one grid point each, nothing binned.
            let b = (horizon / median + 1e-6).floor() as usize;
            if b == 0 {
                bail!(
                    "horizon {horizon} s is shorter than the recorded interval {median} s: \
                     no recorded state to compare with"
                );
            }
            (b.min(MAX_BINS), median)
        }
        None => (
            DEFAULT_IRREGULAR_BINS,
            horizon / DEFAULT_IRREGULAR_BINS as f64,
        ),
    };
    let origin = crate::data::field::bag_field(bag, opts.field.as_ref())?
        .ok_or_else(|| crate::data::field::unknown_field_error("the energy error"))?;
    let (field, field_source) = (origin.field, origin.source);
    Ok(Plan {
        dt,
        dt_source: dt_source.into(),
        horizon,
        horizon_source,
        bin_width,
        bins,
        regular,
        field,
        field_source,
    })
}

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
    let mut states = model.rollout_every(&tr.graph, from, h, steps, steps)?;
    states
        .pop()
        .ok_or_else(|| DynamicsError::Model("the model returned no states".into()))
}

/// The state each recorded state starts a prediction from: the recorded one,
/// or with `causal` its positions with velocities estimated from it and the
/// states before ([`History`], as the node does; `None` while warming up).
fn start_states(tr: &Trajectory, causal: bool, stream: &StreamOptions) -> Vec<Option<State>> {
    if !causal {
        return tr.samples.iter().map(|s| Some(s.state.clone())).collect();
    }
    let mut h = History::default();
    tr.samples
        .iter()
        .map(|s| {
            let t = (s.t * 1e9).round() as crate::data::stream::Nanos;
            match h.push(stream, &tr.graph, t, &s.state.q).1 {
                Estimate::Ready(state) => Some(state),
                Estimate::WarmingUp { .. } => None,
            }
        })
        .collect()
}

/// The reference trajectory for `tr`: same id, graph, and stamps (to 1 µs).
fn reference_for<'a>(reference: &'a Bag, tr: &Trajectory) -> Result<&'a Trajectory> {
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
fn replay_trajectory(
    model: &dyn Dynamics,
    tr: &Trajectory,
    truth: Option<&Trajectory>,
    (causal, stream): (bool, &StreamOptions),
    p: &Plan,
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
    let starts = start_states(tr, causal, stream);
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

/// Replays `bag` through `model`: every recorded state (every `stride`-th) is
/// a start, every later recorded state within the horizon a comparison.
///
/// Errors (never panics) on a bag without `ParticleState` trajectories, a
/// graph the model cannot take, bad options, or when no state has a later
/// one within the horizon.
pub fn replay(model: &dyn Dynamics, bag: &Bag, opts: &ReplayOptions) -> Result<ReplayReport> {
    let mut report = replay_model(model, bag, opts)?;
    let reference = crate::dynamics::Still;
    if model.describe() != reference.describe() {
        let still = replay_model(&reference, bag, opts)?;
        report.still = Some(StillReference::new(&still.summary, report.averages.re));
    }
    Ok(report)
}

/// [`replay`] without the reference.
fn replay_model(model: &dyn Dynamics, bag: &Bag, opts: &ReplayOptions) -> Result<ReplayReport> {
    let started = Instant::now();
    let trajs: Vec<&Trajectory> = bag
        .trajectories
        .iter()
        .take(opts.max_trajectories.unwrap_or(usize::MAX))
        .collect();
    if trajs.is_empty() {
        bail!("the bag has no ParticleState messages (no trajectories to replay)");
    }
    let p = plan(bag, &trajs, opts)?;
    let mut bins = vec![Bin::default(); p.bins + 1];
    let mut report = ReplayReport {
        model: model.describe(),
        system: trajs[0].system.clone(),
        particles: trajs[0].graph.n(),
        trajectories: trajs.len(),
        starts: 0,
        comparisons: 0,
        diverged: 0,
        first_failure: None,
        dt: p.dt,
        dt_source: p.dt_source.clone(),
        horizon: p.horizon,
        horizon_source: p.horizon_source.clone(),
        bin_width: p.bin_width,
        regular_stamps: p.regular,
        field: p.field.clone(),
        field_source: p.field_source.clone(),
        counts: vec![],
        mean_lead: vec![],
        summary: Summary {
            t: vec![],
            n: 0,
            re: empty_band(),
            ee: empty_band(),
            me: empty_band(),
            me_scaled: empty_band(),
            re_abs: empty_band(),
            me_abs: empty_band(),
        },
        worst: Worst::default(),
        averages: Averages {
            re: f64::NAN,
            ee: f64::NAN,
            me: f64::NAN,
            me_scaled: f64::NAN,
            re_abs: f64::NAN,
            me_abs: f64::NAN,
        },
        seconds: 0.0,
        still: None,
        start_velocities: start_velocities(bag, &trajs, opts),
        scored_against: opts.reference.as_ref().map_or_else(
            || "the replayed bag".to_string(),
            |r| {
                let files: Vec<String> =
                    r.sources.iter().map(|p| p.display().to_string()).collect();
                format!("reference {}", files.join(", "))
            },
        ),
    };
    for tr in &trajs {
        let truth = opts
            .reference
            .as_ref()
            .map(|r| reference_for(r, tr))
            .transpose()?;
        let causal = opts.positions_only || bag.derived_velocities.contains(&tr.id);
        replay_trajectory(
            model,
            tr,
            truth,
            (causal, &opts.stream),
            &p,
            opts.stride.max(1),
            &mut bins,
            &mut report,
        )?;
    }
    if report.starts == 0 {
        bail!(
            "no recorded state has a later one within the horizon ({} s): nothing to compare",
            p.horizon
        );
    }
    let mut s = Summary {
        t: vec![],
        n: report.starts,
        re: empty_band(),
        ee: empty_band(),
        me: empty_band(),
        me_scaled: empty_band(),
        re_abs: empty_band(),
        me_abs: empty_band(),
    };
    for (j, b) in bins.iter().enumerate().filter(|(_, b)| b.count() > 0) {
        s.t.push(j as f64 * p.bin_width);
        report.counts.push(b.count());
        report.mean_lead.push(b.lead_sum / b.count() as f64);
        let w = &mut report.worst;
        let worst = [&mut w.re, &mut w.ee, &mut w.me, &mut w.me_scaled];
        for ((band, stats), worst) in [&mut s.re, &mut s.ee, &mut s.me, &mut s.me_scaled]
            .into_iter()
            .zip(&b.stats)
            .zip(worst)
        {
            worst.push(stats.max);
            let (g, lo, hi) = stats.band();
            band.gmean.push(g);
            band.lo.push(lo);
            band.hi.push(hi);
        }
    }
    report.averages = s.time_average();
    report.summary = s;
    report.seconds = started.elapsed().as_secs_f64();
    Ok(report)
}

/// Says where the start states' velocities come from.
fn start_velocities(bag: &Bag, trajs: &[&Trajectory], opts: &ReplayOptions) -> String {
    let derived = trajs
        .iter()
        .filter(|t| opts.positions_only || bag.derived_velocities.contains(&t.id))
        .count();
    if derived == 0 {
        return "recorded".into();
    }
    let rule = match opts.stream.smoother {
        Smoother::None => "three-point difference at the newest state".to_string(),
        Smoother::Poly { window, order } => {
            format!("degree-{order} fit over the last {window} states")
        }
    };
    let which = if derived == trajs.len() {
        "every trajectory".to_string()
    } else {
        format!("{derived} of {} trajectories", trajs.len())
    };
    format!("estimated causally from the positions ({rule}), {which}")
}

/// Reads the bag at `path` and replays it (what the node's Replay service
/// does with its current model); the error names the file.
pub fn replay_bag(
    model: &dyn Dynamics,
    path: &std::path::Path,
    opts: &ReplayOptions,
) -> Result<ReplayReport> {
    let bag = crate::data::read_trajectories(path)
        .with_context(|| format!("reading bag {}", path.display()))?;
    replay(model, &bag, opts)
}

/// What the node's Replay service does: replays the bag at `path` through
/// `model` the way the node predicts (integration steps of `dt / substeps`,
/// `horizon_steps` steps of `dt` ahead) and returns the report with its JSON
/// encoding.
pub fn replay_as_node(
    model: &dyn Dynamics,
    path: &str,
    dt: f64,
    substeps: u32,
    horizon_steps: u32,
) -> Result<(ReplayReport, String)> {
    replay_as_node_with(
        model,
        path,
        (dt, substeps, horizon_steps),
        StreamOptions::default(),
    )
}

/// [`replay_as_node`] with the node's stream settings (how it estimates
/// the velocities of position-only states): `(dt, substeps, horizon_steps)`.
pub fn replay_as_node_with(
    model: &dyn Dynamics,
    path: &str,
    (dt, substeps, horizon_steps): (f64, u32, u32),
    stream: StreamOptions,
) -> Result<(ReplayReport, String)> {
    if path.trim().is_empty() {
        bail!("no bag given: set `bag` to the path of an MCAP file");
    }
    let opts = ReplayOptions {
        dt: Some(dt / f64::from(substeps.max(1))),
        horizon: Some(f64::from(horizon_steps) * dt),
        stream,
        ..ReplayOptions::default()
    };
    let report = replay_bag(model, std::path::Path::new(path), &opts)?;
    let json = serde_json::to_string(&report).context("encoding the replay report")?;
    Ok((report, json))
}

fn empty_band() -> Band {
    Band {
        gmean: vec![],
        lo: vec![],
        hi: vec![],
    }
}

/// Seconds to 9 significant decimals without trailing zeros (stamps are ns,
/// so 0.9999999999999998 reads as 1).
fn secs(x: f64) -> String {
    let s = format!("{x:.9}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() || s == "-" {
        "0".into()
    } else {
        s.into()
    }
}

/// A plain-text table of a report at up to `rows` lead times (at least 2).
pub fn table(r: &ReplayReport, rows: usize) -> String {
    let s = &r.summary;
    let mut out = format!(
        "{} replayed on {}-particle {} ({} trajectories, {} starts, {} comparisons, \
         dt {}, horizon {} s, lead grid {} s):\n",
        r.model,
        r.particles,
        if r.system.is_empty() {
            "system"
        } else {
            &r.system
        },
        r.trajectories,
        r.starts,
        r.comparisons,
        secs(r.dt),
        secs(r.horizon),
        secs(r.bin_width)
    );
    if r.start_velocities != "recorded" {
        out += &format!("start velocities: {}\n", r.start_velocities);
    }
    if r.scored_against != "the replayed bag" {
        out += &format!("scored against: {}\n", r.scored_against);
    }
    let still = r.still.as_ref();
    out += &format!(
        "{:>9}  {:>8}  {:>10}  {:>10}  {:>10}  {:>10}{}\n",
        "lead [s]",
        "pairs",
        "RE",
        "EE",
        "ME",
        "ME scaled",
        if still.is_some() { "  RE still" } else { "" }
    );
    let still_at = |i: usize| still.map_or(String::new(), |x| x.cell(i));
    let n = s.t.len();
    let rows = rows.max(2);
    let picks: Vec<usize> = if n <= rows {
        (0..n).collect()
    } else {
        (0..rows).map(|k| k * (n - 1) / (rows - 1)).collect()
    };
    for i in picks {
        out += &format!(
            "{:>9.4}  {:>8}  {:>10.3e}  {:>10.3e}  {:>10.3e}  {:>10.3e}{}\n",
            s.t[i],
            r.counts[i],
            s.re.gmean[i],
            s.ee.gmean[i],
            s.me.gmean[i],
            s.me_scaled.gmean[i],
            still_at(i)
        );
    }
    let a = &r.averages;
    out += &format!(
        "{:>9}  {:>8}  {:>10.3e}  {:>10.3e}  {:>10.3e}  {:>10.3e}{}\n",
        "mean",
        "",
        a.re,
        a.ee,
        a.me,
        a.me_scaled,
        still.map_or(String::new(), |x| format!("  {:>8.3e}", x.re_mean))
    );
    if let Some(x) = still {
        out += &x.verdict(a.re);
    }
    if r.diverged > 0 {
        out += &format!(
            "{} of {} rollouts failed before the horizon (counted with errors 1); first: {}\n",
            r.diverged,
            r.starts,
            r.first_failure.as_deref().unwrap_or("")
        );
    }
    out += &format!("energy field: {} ({:?})\n", r.field_source, r.field);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::{summarize, ErrorCurves};

    /// The streaming band must be what `summarize` computes from whole curves.
    #[test]
    fn streaming_band_matches_summarize() {
        let vals = [
            [0.1, 0.2, 0.0, 3e-5],
            [0.5, 1e-7, 0.3, 2e-4],
            [0.02, 0.7, 0.9, 1.0],
        ];
        let curves: Vec<ErrorCurves> = vals
            .iter()
            .map(|v| ErrorCurves {
                t: vec![1.0],
                re: vec![v[0]],
                ee: vec![v[1]],
                me: vec![v[2]],
                me_scaled: vec![v[3]],
                re_abs: vec![0.0],
                me_abs: vec![0.0],
            })
            .collect();
        let want = summarize(&curves).unwrap();
        let mut bin = Bin::default();
        for v in vals {
            bin.push(1.0, v);
        }
        let bands = [&want.re, &want.ee, &want.me, &want.me_scaled];
        for (b, stats) in bands.iter().zip(&bin.stats) {
            let (g, lo, hi) = stats.band();
            for (x, y) in [(g, b.gmean[0]), (lo, b.lo[0]), (hi, b.hi[0])] {
                assert!((x - y).abs() <= 1e-12 * y.abs(), "{x} vs {y}");
            }
        }
        let mut one = LogStats::default();
        one.push(0.25);
        assert_eq!(
            one.band(),
            (0.25f64.ln().exp(), 0.25f64.ln().exp(), 0.25f64.ln().exp())
        );
    }
}
