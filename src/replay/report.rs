//! The last stage: the report of a replay, what it says about where its
//! inputs came from, and its summary built from the bins.

use serde::Serialize;

use crate::data::bag::Bag;
use crate::data::stream::Smoother;
use crate::metrics::{Averages, Band, StillReference, Summary};
use crate::physics::Field;
use crate::system::Trajectory;

use super::bins::Bin;
use super::options::ReplayOptions;
use super::settings::Settings;

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
        Smoother::Model { window } => {
            format!("the model's rollout fitted to the last {window} states")
        }
    };
    let which = if derived == trajs.len() {
        "every trajectory".to_string()
    } else {
        format!("{derived} of {} trajectories", trajs.len())
    };
    format!("estimated causally from the positions ({rule}), {which}")
}

fn empty_band() -> Band {
    Band {
        gmean: vec![],
        lo: vec![],
        hi: vec![],
    }
}

impl ReplayReport {
    /// The report of replaying `trajs` of `bag` through the model described
    /// as `model` with settings `p`, before anything is replayed.
    pub(super) fn new(
        model: String,
        bag: &Bag,
        trajs: &[&Trajectory],
        p: &Settings,
        opts: &ReplayOptions,
    ) -> ReplayReport {
        ReplayReport {
            model,
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
            summary: empty_summary(0),
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
            start_velocities: start_velocities(bag, trajs, opts),
            scored_against: opts.reference.as_ref().map_or_else(
                || "the replayed bag".to_string(),
                |r| {
                    let files: Vec<String> =
                        r.sources.iter().map(|p| p.display().to_string()).collect();
                    format!("reference {}", files.join(", "))
                },
            ),
        }
    }

    /// Fills the summary, the counts, mean leads and worst errors per grid
    /// point (of spacing `bin_width`) from `bins`, leaving out grid points no
    /// pair fell on, and the averages over leads.
    pub(super) fn summarize(&mut self, bins: &[Bin], bin_width: f64) {
        let mut s = empty_summary(self.starts);
        for (j, b) in bins.iter().enumerate().filter(|(_, b)| b.count() > 0) {
            s.t.push(j as f64 * bin_width);
            self.counts.push(b.count());
            self.mean_lead.push(b.lead_sum / b.count() as f64);
            let w = &mut self.worst;
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
        self.averages = s.time_average();
        self.summary = s;
    }
}

/// A summary of `n` starts with no grid points yet.
fn empty_summary(n: usize) -> Summary {
    Summary {
        t: vec![],
        n,
        re: empty_band(),
        ee: empty_band(),
        me: empty_band(),
        me_scaled: empty_band(),
        re_abs: empty_band(),
        me_abs: empty_band(),
    }
}
