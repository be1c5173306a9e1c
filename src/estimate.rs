//! The model-based estimate of a stream's newest state (`velocity_smoother:
//! model`, `replay --smoother model`): the state at the oldest stamp of a
//! window of noisy positions is fitted by least squares through the learned
//! model's own rollout (velocity Verlet on its accelerations, SHAKE/RATTLE on
//! its bars, the steps the planner's reverse pass sees), and rolled to the
//! newest stamp. Unlike a polynomial, the fit follows whatever the model
//! knows of the motion over the window, so the window can span a large part
//! of a period, and noise is averaged over all of it.
//!
//! Levenberg–Marquardt on the residuals q_k(x₀) − y_k: the Jacobian by
//! forward differences of the rollout (2·n·d + 1 rollouts of the window per
//! iteration). At the node's sizes (a few particles, windows of 10–30
//! states) that is cheaper than the one reverse sweep per residual that an
//! exact Jacobian would take, and Gauss–Newton needs no more than the
//! Jacobian's first 7 digits. Each fit is warm-started from the previous
//! one (its rollout at this window's oldest stamp) and bounded in iterations
//! and time.

use std::time::{Duration, Instant};

use nalgebra::{DMatrix, DVector};

use crate::data::stream::Nanos;
use crate::dynamics::{Dynamics, DynamicsError, StateGradient};
use crate::physics::{verlet, Projector};
use crate::system::{Graph, State};

/// The relative gain in the residuals' sum of squares below which a fit
/// stops: at the noise floor the estimate no longer moves.
const CONVERGED: f64 = 1e-4;

/// Bounds on one fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
    /// Largest integration step (seconds); an interval between stamps is cut
    /// into equal steps no longer than this.
    pub dt: f64,
    /// Levenberg–Marquardt iterations at most.
    pub iterations: usize,
    /// Wall time at most: no iteration is started that, as slow as the
    /// slowest before it, would pass it (the best state so far is returned).
    pub budget: Duration,
}

impl FitOptions {
    /// Iterations and budget as the node uses them, with steps of `dt`.
    pub fn with_dt(dt: f64) -> Self {
        FitOptions {
            dt,
            iterations: 8,
            budget: Duration::from_millis(4),
        }
    }
}

/// One fit's outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct Fitted {
    /// The state at the window's newest stamp.
    pub state: State,
    /// Root mean square of the residuals (position units) before and after.
    pub rms_start: f64,
    /// After the fit.
    pub rms: f64,
    /// Iterations taken.
    pub iterations: usize,
    /// Whether it started from the previous fit.
    pub warm: bool,
}

/// A stream's fitter: the model's accelerations on one graph, and the
/// previous fit's states at its stamps (the warm start).
pub struct ModelFit {
    model: Box<dyn StateGradient>,
    proj: Option<Projector>,
    graph: Graph,
    opts: FitOptions,
    previous: Vec<(Nanos, State)>,
}

impl ModelFit {
    /// A fitter for `graph` through `model`, or why there is none: the fit
    /// needs a model of the GNODE family (the engine's accelerations), and
    /// a graph without kinematic particles (their motion is not the model's).
    pub fn new(
        model: &dyn Dynamics,
        graph: &Graph,
        opts: FitOptions,
    ) -> Result<Self, DynamicsError> {
        if graph.kinematic.iter().any(|&k| k) {
            return Err(DynamicsError::Model(
                "the model smoother fits free particles only; this graph has kinematic ones \
                 (use velocity_smoother poly)"
                    .into(),
            ));
        }
        if !(opts.dt > 0.0 && opts.dt.is_finite()) {
            return Err(DynamicsError::Model(format!(
                "the model smoother's integration step {} s must be positive",
                opts.dt
            )));
        }
        let model = model.state_gradient(graph)?.ok_or_else(|| {
            DynamicsError::Model(format!(
                "{} cannot be fitted through: the model smoother needs a model file of the GNODE \
                 family (NODE, GNODE, CGNODE, CDGNODE, MCGNODE); use velocity_smoother poly",
                model.describe()
            ))
        })?;
        let proj = model.projector();
        Ok(ModelFit {
            model,
            proj,
            graph: graph.clone(),
            opts,
            previous: vec![],
        })
    }

    /// Forgets the warm start (the stream started over).
    pub fn reset(&mut self) {
        self.previous.clear();
    }

    /// Fits the window of `positions` at `stamps` (oldest first, at least 3,
    /// strictly increasing). `Err` only when the model's rollout diverges
    /// from every start tried.
    pub fn fit(&mut self, stamps: &[Nanos], positions: &[&[f64]]) -> Result<Fitted, DynamicsError> {
        let t0 = Instant::now();
        let nd = self.graph.ndof();
        let m = stamps.len();
        if m < 3 || positions.len() != m || positions.iter().any(|q| q.len() != nd) {
            return Err(DynamicsError::Model(format!(
                "the model smoother needs at least 3 states of {nd} coordinates, got {m}"
            )));
        }
        let y: Vec<f64> = positions.iter().flat_map(|q| q.iter().copied()).collect();
        let warm = self.warm_start(stamps[0]);
        let start = warm
            .clone()
            .unwrap_or_else(|| cold_start(stamps, positions));
        let mut x: Vec<f64> = start.q.iter().chain(&start.v).copied().collect();
        let (mut r, mut traj) = self.residuals(stamps, &x, &y)?;
        let rms_of = |r: &[f64]| (r.iter().map(|e| e * e).sum::<f64>() / r.len() as f64).sqrt();
        let rms_start = rms_of(&r);
        let mut lambda = 1e-3;
        let mut iterations = 0;
        // An iteration is not started when one more like the slowest so far
        // would pass the budget.
        let mut slowest = Duration::ZERO;
        while iterations < self.opts.iterations && t0.elapsed() + slowest < self.opts.budget {
            let started = Instant::now();
            iterations += 1;
            let jac = self.jacobian(stamps, &x, &r, &y)?;
            match self.lm_step(&jac, &r, &x, lambda, stamps, &y) {
                Some((xn, rn, tn)) if dot(&rn, &rn) < dot(&r, &r) => {
                    let gain = 1.0 - dot(&rn, &rn) / dot(&r, &r);
                    (x, r, traj) = (xn, rn, tn);
                    lambda = (lambda * 0.3).max(1e-9);
                    // Converged: a further step would move the residuals'
                    // sum of squares by less than this fraction.
                    if gain < CONVERGED {
                        break;
                    }
                }
                _ => {
                    lambda *= 10.0;
                    if lambda > 1e6 {
                        break;
                    }
                }
            }
            slowest = slowest.max(started.elapsed());
        }
        let state = traj.last().expect("a window of ≥ 3 states").clone();
        self.previous = stamps.iter().copied().zip(traj).collect();
        Ok(Fitted {
            state,
            rms_start,
            rms: rms_of(&r),
            iterations,
            warm: warm.is_some(),
        })
    }

    /// The previous fit's state at `t0`: at that stamp if the previous
    /// window had it, else its newest state before `t0` rolled on to `t0`
    /// through the model (a caller that fits only some states, as `replay`
    /// fits the ones it predicts from, keeps its warm start). `None` without
    /// a previous fit before `t0` or when that roll diverges.
    fn warm_start(&mut self, t0: Nanos) -> Option<State> {
        if let Some((_, s)) = self.previous.iter().find(|(t, _)| *t == t0) {
            return Some(s.clone());
        }
        let (t, s) = self.previous.iter().rev().find(|(t, _)| *t < t0)?.clone();
        let (mut q, mut v) = (s.q, s.v);
        let mut a = vec![0.0; q.len()];
        self.model.acceleration(&q, &v, &mut a);
        let span = (t0 - t) as f64 * 1e-9;
        let steps = ((span / self.opts.dt) * (1.0 - 1e-9)).ceil().max(1.0) as usize;
        let h = span / steps as f64;
        for _ in 0..steps {
            self.step(&mut q, &mut v, &mut a, h).ok()?;
        }
        Some(State { q, v })
    }

    /// One damped Gauss–Newton step from `x`: (JᵀJ + λ diag JᵀJ) δ = −Jᵀr.
    #[allow(clippy::too_many_arguments)]
    fn lm_step(
        &mut self,
        jac: &DMatrix<f64>,
        r: &[f64],
        x: &[f64],
        lambda: f64,
        stamps: &[Nanos],
        y: &[f64],
    ) -> Option<(Vec<f64>, Vec<f64>, Vec<State>)> {
        let jt = jac.transpose();
        let mut a = &jt * jac;
        for i in 0..a.nrows() {
            a[(i, i)] += lambda * a[(i, i)].max(1e-300);
        }
        let g = &jt * DVector::from_column_slice(r);
        let delta = a.cholesky()?.solve(&g);
        let xn: Vec<f64> = x.iter().zip(delta.iter()).map(|(a, d)| a - d).collect();
        let (rn, tn) = self.residuals(stamps, &xn, y).ok()?;
        Some((xn, rn, tn))
    }

    /// ∂r/∂x by forward differences, one rollout per coordinate of x.
    fn jacobian(
        &mut self,
        stamps: &[Nanos],
        x: &[f64],
        r: &[f64],
        y: &[f64],
    ) -> Result<DMatrix<f64>, DynamicsError> {
        let nd = self.graph.ndof();
        let span = (stamps[stamps.len() - 1] - stamps[0]) as f64 * 1e-9;
        let scale_q = x[..nd].iter().fold(1e-3_f64, |m, a| m.max(a.abs()));
        let mut jac = DMatrix::zeros(r.len(), x.len());
        let mut xp = x.to_vec();
        for c in 0..x.len() {
            // √ε of the coordinate's scale: the difference's round-off and
            // its truncation balance.
            let h = 1.5e-8 * if c < nd { scale_q } else { scale_q / span };
            xp[c] = x[c] + h;
            let (rp, _) = self.residuals(stamps, &xp, y)?;
            xp[c] = x[c];
            for (k, (a, b)) in rp.iter().zip(r).enumerate() {
                jac[(k, c)] = (a - b) / h;
            }
        }
        Ok(jac)
    }

    /// The residuals q_k − y_k of the rollout from x = (q₀, q̇₀) at the
    /// oldest stamp, and the rolled states at every stamp.
    fn residuals(
        &mut self,
        stamps: &[Nanos],
        x: &[f64],
        y: &[f64],
    ) -> Result<(Vec<f64>, Vec<State>), DynamicsError> {
        let nd = self.graph.ndof();
        let (mut q, mut v) = (x[..nd].to_vec(), x[nd..].to_vec());
        let mut a = vec![0.0; nd];
        self.model.acceleration(&q, &v, &mut a);
        let mut states = Vec::with_capacity(stamps.len());
        states.push(State {
            q: q.clone(),
            v: v.clone(),
        });
        for w in stamps.windows(2) {
            let span = (w[1] - w[0]) as f64 * 1e-9;
            let steps = ((span / self.opts.dt) * (1.0 - 1e-9)).ceil().max(1.0) as usize;
            let h = span / steps as f64;
            for j in 0..steps {
                self.step(&mut q, &mut v, &mut a, h)
                    .map_err(|()| DynamicsError::Diverged(states.len() * steps + j))?;
            }
            states.push(State {
                q: q.clone(),
                v: v.clone(),
            });
        }
        let r = states
            .iter()
            .flat_map(|s| s.q.iter())
            .zip(y)
            .map(|(a, b)| a - b)
            .collect();
        Ok((r, states))
    }

    /// One velocity-Verlet step of `h`, projected onto the bars; `Err` when
    /// the state is no longer finite.
    fn step(&mut self, q: &mut [f64], v: &mut [f64], a: &mut [f64], h: f64) -> Result<(), ()> {
        if let Some(p) = self.proj.as_mut() {
            p.begin(q);
        }
        verlet::drift(q, v, a, h);
        if let Some(p) = self.proj.as_mut() {
            p.shake(q, v, h);
        }
        self.model.acceleration(q, v, a);
        verlet::kick(v, a, h);
        if let Some(p) = self.proj.as_mut() {
            p.rattle(q, v);
        }
        if q.iter().chain(v.iter()).all(|x| x.is_finite()) {
            Ok(())
        } else {
            Err(())
        }
    }
}

/// The start without a previous fit: the oldest positions, with the
/// velocity of a straight line fitted through the window's first half.
fn cold_start(stamps: &[Nanos], positions: &[&[f64]]) -> State {
    let half = (stamps.len() / 2).max(2);
    let t: Vec<f64> = stamps[..half]
        .iter()
        .map(|s| (s - stamps[0]) as f64 * 1e-9)
        .collect();
    let tm = t.iter().sum::<f64>() / half as f64;
    let var: f64 = t.iter().map(|a| (a - tm) * (a - tm)).sum();
    let nd = positions[0].len();
    let v = (0..nd)
        .map(|i| {
            let qm = positions[..half].iter().map(|q| q[i]).sum::<f64>() / half as f64;
            t.iter()
                .zip(&positions[..half])
                .map(|(a, q)| (a - tm) * (q[i] - qm))
                .sum::<f64>()
                / var
        })
        .collect();
    State {
        q: positions[0].to_vec(),
        v,
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
#[path = "estimate_tests.rs"]
mod tests;
