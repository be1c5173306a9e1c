//! The paper's error metrics ("Evaluation Metric", Bishnoi et al.) and their
//! summary over many trajectories.
//!
//! Per time step, hats denoting the prediction:
//! * RE(t) = ‖q̂ − q‖₂ / (‖q̂‖₂ + ‖q‖₂), positions of all particles stacked;
//! * EE(t) = |Ĥ − H| / (|Ĥ| + |H|), H the system's known Hamiltonian
//!   ([`crate::physics::hamiltonian`]) evaluated on the predicted and the true
//!   state;
//! * ME(t) = ‖P̂ − P‖₂ / (‖P̂‖₂ + ‖P‖₂), P the total linear momentum.
//!
//! Beside these relative errors, the absolute ones the paper shows for the
//! peridynamic solid: ‖q̂ − q‖₂ ([`ErrorCurves::re_abs`]) and ‖P̂ − P‖₂
//! ([`ErrorCurves::me_abs`]).
//!
//! A rollout that diverged (non-finite state) scores the worst value from
//! then on: 1 for the relative errors (their maximum), [`DIVERGED`] for the
//! absolute ones ([`ErrorCurves::diverged`]).
//!
//! A ratio 0/0 (both quantities exactly zero) is defined as 0: the prediction
//! matches. Caveat for ME: when the true momentum is zero (the spring starts)
//! both momenta sit at round-off level and ME is close to 1 for any prediction
//! that is not bit-identical; [`ErrorCurves::me_scaled`] divides by the
//! momentum scale Σ m|v̂| + Σ m|v| instead, which stays meaningful there.

use serde::{Deserialize, Serialize};

use crate::physics::{hamiltonian, Field};
use crate::system::{Graph, State};

/// Values are clamped to this before taking logs (a zero error would
/// otherwise have log −∞), so an exact zero shows up as 1e-300.
pub const LOG_FLOOR: f64 = 1e-300;

/// The absolute error of a diverged rollout: a finite stand-in for +∞ so
/// that logs, bands and JSON stay finite.
pub const DIVERGED: f64 = 1e300;

/// z-value of a two-sided 95% normal band.
const Z95: f64 = 1.96;

/// Why error curves cannot be computed or summarised.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MetricsError {
    /// Truth, prediction and times of different lengths.
    #[error("{truth} true states, {pred} predicted states and {times} times: they must match")]
    Lengths {
        /// True states.
        truth: usize,
        /// Predicted states.
        pred: usize,
        /// Times.
        times: usize,
    },
    /// Nothing to compare.
    #[error("no states to compare")]
    NoStates,
    /// The graph is invalid.
    #[error(transparent)]
    System(#[from] crate::system::SystemError),
    /// The field is invalid.
    #[error(transparent)]
    Physics(#[from] crate::physics::PhysicsError),
    /// A true or predicted state does not fit the graph or is not finite.
    #[error("{which} state {k}: {cause}")]
    State {
        /// "true" or "predicted".
        which: &'static str,
        /// Its index.
        k: usize,
        /// What is wrong.
        cause: crate::system::SystemError,
    },
    /// No curves to summarise.
    #[error("no error curves to summarise")]
    NoCurves,
    /// A curve of another length than the first.
    #[error("curve {curve} has a different length than curve 0 ({len})")]
    CurveLength {
        /// The curve.
        curve: usize,
        /// The first curve's length.
        len: usize,
    },
    /// A curve at other times than the first.
    #[error("curve {curve} has time {time} at index {index}, curve 0 has {first}")]
    CurveTime {
        /// The curve.
        curve: usize,
        /// The index.
        index: usize,
        /// Its time there.
        time: f64,
        /// The first curve's.
        first: f64,
    },
    /// A negative or non-finite error.
    #[error("curve {curve} has an invalid error value {value}")]
    Value {
        /// The curve.
        curve: usize,
        /// The value.
        value: f64,
    },
}

crate::error::typed_errors!(MetricsError);

/// Error curves of one predicted trajectory against the truth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorCurves {
    /// Times of the states.
    pub t: Vec<f64>,
    /// Rollout (position) error RE(t).
    pub re: Vec<f64>,
    /// Energy violation error EE(t).
    pub ee: Vec<f64>,
    /// Momentum error ME(t) as in the paper.
    pub me: Vec<f64>,
    /// ‖P̂ − P‖ / (Σ m|v̂| + Σ m|v|): momentum error relative to the scale of
    /// the motion, in [0, 1]; meaningful also when P ≈ 0.
    pub me_scaled: Vec<f64>,
    /// Absolute rollout error ‖q̂ − q‖₂.
    #[serde(default)]
    pub re_abs: Vec<f64>,
    /// Absolute momentum error ‖P̂ − P‖₂.
    #[serde(default)]
    pub me_abs: Vec<f64>,
}

impl ErrorCurves {
    /// Curves of a rollout that diverged: `curves` covers the states before
    /// divergence; the remaining times up to `times.len()` get the worst
    /// values (relative 1, absolute [`DIVERGED`]).
    pub fn diverged(mut curves: ErrorCurves, times: &[f64]) -> ErrorCurves {
        let k = curves.t.len();
        for &t in &times[k.min(times.len())..] {
            curves.t.push(t);
            curves.re.push(1.0);
            curves.ee.push(1.0);
            curves.me.push(1.0);
            curves.me_scaled.push(1.0);
            curves.re_abs.push(DIVERGED);
            curves.me_abs.push(DIVERGED);
        }
        curves
    }
}

/// a / b with 0/0 = 0.
fn ratio(a: f64, b: f64) -> f64 {
    if a == 0.0 && b == 0.0 {
        0.0
    } else {
        a / b
    }
}

fn norm(x: impl Iterator<Item = f64>) -> f64 {
    x.map(|a| a * a).sum::<f64>().sqrt()
}

/// Σ m_i |v_i|.
fn momentum_scale(graph: &Graph, s: &State) -> f64 {
    let d = graph.dim;
    graph
        .masses
        .iter()
        .enumerate()
        .map(|(i, m)| m * norm(s.v[i * d..(i + 1) * d].iter().copied()))
        .sum()
}

/// RE, EE and ME at every time of `truth` and `pred` (same length as `times`).
///
/// Errors if the lengths differ, there are no states, or a state does not
/// fit the graph or is not finite (a diverged prediction).
pub fn error_curves(
    graph: &Graph,
    field: &Field,
    truth: &[State],
    pred: &[State],
    times: &[f64],
) -> Result<ErrorCurves, MetricsError> {
    if truth.len() != pred.len() || truth.len() != times.len() {
        return Err(MetricsError::Lengths {
            truth: truth.len(),
            pred: pred.len(),
            times: times.len(),
        });
    }
    if truth.is_empty() {
        return Err(MetricsError::NoStates);
    }
    graph.validate()?;
    field.validate(graph.dim)?;
    let mut c = ErrorCurves {
        t: times.to_vec(),
        re: Vec::with_capacity(times.len()),
        ee: Vec::with_capacity(times.len()),
        me: Vec::with_capacity(times.len()),
        me_scaled: Vec::with_capacity(times.len()),
        re_abs: Vec::with_capacity(times.len()),
        me_abs: Vec::with_capacity(times.len()),
    };
    for (k, (s, p)) in truth.iter().zip(pred).enumerate() {
        s.validate(graph).map_err(|cause| MetricsError::State {
            which: "true",
            k,
            cause,
        })?;
        p.validate(graph).map_err(|cause| MetricsError::State {
            which: "predicted",
            k,
            cause,
        })?;
        // In a periodic box a particle wrapped across a face by one side
        // only is its minimum image away, not a box length.
        let mut diff: Vec<f64> = p.q.iter().zip(&s.q).map(|(a, b)| a - b).collect();
        if let Some(pb) = &graph.periodic_box {
            diff.chunks_mut(graph.dim.max(1))
                .for_each(|c| pb.min_image(c));
        }
        let dq = norm(diff.iter().copied());
        c.re.push(ratio(
            dq,
            norm(p.q.iter().copied()) + norm(s.q.iter().copied()),
        ));
        let (h, hp) = (hamiltonian(graph, field, s), hamiltonian(graph, field, p));
        c.ee.push(ratio((hp - h).abs(), hp.abs() + h.abs()));
        let (m, mp) = (s.momentum(graph), p.momentum(graph));
        let dm = norm(mp.iter().zip(&m).map(|(a, b)| a - b));
        c.me.push(ratio(
            dm,
            norm(mp.iter().copied()) + norm(m.iter().copied()),
        ));
        c.me_scaled.push(ratio(
            dm,
            momentum_scale(graph, p) + momentum_scale(graph, s),
        ));
        c.re_abs.push(dq);
        c.me_abs.push(dm);
    }
    Ok(c)
}

/// Geometric mean and 95% band of one metric over trajectories, per time.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Band {
    /// exp(mean(log x)) over trajectories.
    pub gmean: Vec<f64>,
    /// exp(mean(log x) − 1.96·sd(log x)).
    pub lo: Vec<f64>,
    /// exp(mean(log x) + 1.96·sd(log x)).
    pub hi: Vec<f64>,
}

/// Summary of many trajectories' error curves.
///
/// Per time, each metric is summarised on log scale: the geometric mean
/// exp(mean(log x)) and the band exp(mean ± 1.96·sd) of the log-values, sd
/// the sample standard deviation (n − 1; 0 for a single trajectory). This is
/// the spread of the trajectories (where 95% of them lie if the log-errors
/// are normal), not a confidence interval of the mean. Values are clamped to
/// [`LOG_FLOOR`] before the log.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Times.
    pub t: Vec<f64>,
    /// Number of trajectories summarised.
    pub n: usize,
    /// Rollout error.
    pub re: Band,
    /// Energy violation error.
    pub ee: Band,
    /// Momentum error (paper definition).
    pub me: Band,
    /// Momentum error relative to the momentum scale.
    pub me_scaled: Band,
    /// Absolute rollout error (empty where not computed, e.g. replay).
    #[serde(default)]
    pub re_abs: Band,
    /// Absolute momentum error (empty where not computed).
    #[serde(default)]
    pub me_abs: Band,
}

fn band(curves: &[ErrorCurves], pick: impl Fn(&ErrorCurves) -> &Vec<f64>) -> Band {
    let len = curves[0].t.len();
    let n = curves.len() as f64;
    let mut b = Band {
        gmean: Vec::with_capacity(len),
        lo: Vec::with_capacity(len),
        hi: Vec::with_capacity(len),
    };
    for k in 0..len {
        let logs = curves.iter().map(|c| floored_ln(pick(c)[k]));
        let mean = logs.clone().sum::<f64>() / n;
        let var = if curves.len() > 1 {
            logs.map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        let (gmean, lo, hi) = log_band(mean, var);
        b.gmean.push(gmean);
        b.lo.push(lo);
        b.hi.push(hi);
    }
    b
}

/// ln of an error, clamped to [`LOG_FLOOR`] first so zero stays finite.
pub(crate) fn floored_ln(x: f64) -> f64 {
    x.max(LOG_FLOOR).ln()
}

/// (geometric mean, lo, hi) of the 95% normal band in log space, from the
/// mean and sample variance of the [`floored_ln`] of the errors: the band of
/// every summary ([`summarize`], and `replay`'s streaming statistics).
pub(crate) fn log_band(mean: f64, var: f64) -> (f64, f64, f64) {
    let half = Z95 * var.sqrt();
    (mean.exp(), (mean - half).exp(), (mean + half).exp())
}

/// `rows` indices spread evenly over `0..n`, first and last included (all of
/// them when there are no more than `rows`): the rows a table of a curve
/// prints.
pub fn evenly_spaced(n: usize, rows: usize) -> Vec<usize> {
    let rows = rows.max(2);
    if n <= rows {
        (0..n).collect()
    } else {
        (0..rows).map(|k| k * (n - 1) / (rows - 1)).collect()
    }
}

/// Summarises curves that share their times (within 1e-9 relative).
///
/// Errors on no curves, differing times or lengths, or non-finite / negative
/// values.
pub fn summarize(curves: &[ErrorCurves]) -> Result<Summary, MetricsError> {
    let first = curves.first().ok_or(MetricsError::NoCurves)?;
    let len = first.t.len();
    for (i, c) in curves.iter().enumerate() {
        if [
            c.t.len(),
            c.re.len(),
            c.ee.len(),
            c.me.len(),
            c.me_scaled.len(),
            c.re_abs.len(),
            c.me_abs.len(),
        ]
        .iter()
        .any(|l| *l != len)
        {
            return Err(MetricsError::CurveLength { curve: i, len });
        }
        for (k, (a, b)) in c.t.iter().zip(&first.t).enumerate() {
            if (a - b).abs() > 1e-9 * a.abs().max(b.abs()).max(1.0) {
                return Err(MetricsError::CurveTime {
                    curve: i,
                    index: k,
                    time: *a,
                    first: *b,
                });
            }
        }
        let mut vals =
            c.re.iter()
                .chain(&c.ee)
                .chain(&c.me)
                .chain(&c.me_scaled)
                .chain(&c.re_abs)
                .chain(&c.me_abs);
        if let Some(x) = vals.find(|x| !(x.is_finite() && **x >= 0.0)) {
            return Err(MetricsError::Value {
                curve: i,
                value: *x,
            });
        }
    }
    Ok(Summary {
        t: first.t.clone(),
        n: curves.len(),
        re: band(curves, |c| &c.re),
        ee: band(curves, |c| &c.ee),
        me: band(curves, |c| &c.me),
        me_scaled: band(curves, |c| &c.me_scaled),
        re_abs: band(curves, |c| &c.re_abs),
        me_abs: band(curves, |c| &c.me_abs),
    })
}

/// Time-averaged errors of a [`Summary`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Averages {
    /// RE.
    pub re: f64,
    /// EE.
    pub ee: f64,
    /// ME as in the paper.
    pub me: f64,
    /// ME relative to the momentum scale.
    pub me_scaled: f64,
    /// Absolute rollout error.
    #[serde(default)]
    pub re_abs: f64,
    /// Absolute momentum error.
    #[serde(default)]
    pub me_abs: f64,
}

impl Summary {
    /// Time averages of the geometric-mean curves: the arithmetic mean over
    /// the times after the first (at t = 0 prediction and truth coincide, so
    /// errors there are exactly 0 and say nothing). NaN without such times.
    pub fn time_average(&self) -> Averages {
        let avg = |b: &Band| {
            let x = &b.gmean[1.min(b.gmean.len())..];
            if x.is_empty() {
                f64::NAN
            } else {
                x.iter().sum::<f64>() / x.len() as f64
            }
        };
        Averages {
            re: avg(&self.re),
            ee: avg(&self.ee),
            me: avg(&self.me),
            me_scaled: avg(&self.me_scaled),
            re_abs: avg(&self.re_abs),
            me_abs: avg(&self.me_abs),
        }
    }

    /// (RE, EE, ME) geometric means at the stored time nearest to `t`; NaN
    /// for a summary without times.
    pub fn at(&self, t: f64) -> (f64, f64, f64) {
        let k = self
            .t
            .iter()
            .enumerate()
            .min_by(|a, b| (a.1 - t).abs().total_cmp(&(b.1 - t).abs()))
            .map(|(k, _)| k);
        match k {
            Some(k) => (self.re.gmean[k], self.ee.gmean[k], self.me.gmean[k]),
            None => (f64::NAN, f64::NAN, f64::NAN),
        }
    }
}

/// How a model compares with predicting that nothing moves
/// ([`crate::dynamics::Still`]) on the same trajectories: the one reference
/// every model must beat, shown beside it always.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StillReference {
    /// The reference's RE (geometric mean over trajectories) at each time of
    /// the model's summary.
    pub re: Vec<f64>,
    /// Its RE time average (t > 0).
    pub re_mean: f64,
    /// The reference's time-average RE over the model's: how many times
    /// better than standing still the model is (below 1: worse).
    pub times_better: f64,
    /// The model's RE time average is above the reference's.
    pub worse: bool,
}

impl StillReference {
    /// The reference's summary `still` beside a model whose RE time average
    /// is `model_re` (on the same times).
    pub fn new(still: &Summary, model_re: f64) -> StillReference {
        let re_mean = still.time_average().re;
        StillReference {
            re: still.re.gmean.clone(),
            re_mean,
            times_better: re_mean / model_re,
            // A NaN model error (diverged everywhere) counts as worse.
            worse: model_re.is_nan() || model_re > re_mean,
        }
    }

    /// The table cell of the reference's RE at time index `i` (empty past
    /// its times), for a column beside the model's.
    pub fn cell(&self, i: usize) -> String {
        self.re
            .get(i)
            .map_or(String::new(), |x| format!("  {x:>8.3e}"))
    }

    /// The line under a table: the warning for a model worse than standing
    /// still, else how many times below it the model's mean RE is.
    pub fn verdict(&self, model_re: f64) -> String {
        match self.warning(model_re) {
            Some(w) => format!("{w}\n"),
            None => format!(
                "mean RE {:.1}x below standing still (`--model still`: {:.3e})\n",
                self.times_better, self.re_mean
            ),
        }
    }

    /// The warning a model worse than standing still gets, else `None`.
    pub fn warning(&self, model_re: f64) -> Option<String> {
        self.worse.then(|| {
            format!(
                "WARNING: the model is worse than predicting that nothing moves (mean RE \
                 {model_re:.3e} against {:.3e} for `--model still`): its predictions are \
                 not to be trusted; retrain it (mcgnode train's default recipe, more epochs \
                 or more data)",
                self.re_mean
            )
        })
    }
}
