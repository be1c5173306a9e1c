//! The search over candidate actions: sample control sequences, roll each
//! out through the model in parallel, keep the cheapest. Random shooting,
//! the cross-entropy method (CEM) and model-predictive path integral (MPPI),
//! as sampling-based planners on learned particle dynamics use them.

use super::controls::Controls;
use super::cost::Cost;
use crate::dynamics::Timing;
use crate::dynamics::{Dynamics, DynamicsError, Spread};
use crate::system::{Graph, State};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::time::Instant;
use thiserror::Error;

/// How candidates are drawn and refined. Every sampler draws around a mean
/// sequence (the warm start, else holding still), evaluates that mean too,
/// and keeps the cheapest sequence it evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", tag = "kind")]
pub enum Sampler {
    /// One round of `candidates` sequences, each velocity N(mean, σ²).
    Random {
        /// Sequences drawn.
        candidates: usize,
        /// Spread of each velocity, m/s.
        sigma: f64,
    },
    /// `iterations` rounds; each refits mean and spread to the `elites`
    /// cheapest.
    Cem {
        /// Sequences per round.
        candidates: usize,
        /// Rounds.
        iterations: usize,
        /// Sequences refitted to.
        elites: usize,
        /// Initial spread, m/s.
        sigma: f64,
    },
    /// `iterations` rounds; each moves the mean to the candidates' average
    /// weighted by exp(−(cost − min)/temperature), the spread fixed.
    Mppi {
        /// Sequences per round.
        candidates: usize,
        /// Rounds.
        iterations: usize,
        /// Spread, m/s.
        sigma: f64,
        /// Temperature λ, in cost units.
        temperature: f64,
    },
}

impl Sampler {
    fn candidates(self) -> usize {
        match self {
            Sampler::Random { candidates, .. }
            | Sampler::Cem { candidates, .. }
            | Sampler::Mppi { candidates, .. } => candidates,
        }
    }

    /// Rounds of the search (random shooting: one).
    pub fn iterations(self) -> usize {
        match self {
            Sampler::Random { .. } => 1,
            Sampler::Cem { iterations, .. } | Sampler::Mppi { iterations, .. } => iterations,
        }
    }

    fn sigma(self) -> f64 {
        match self {
            Sampler::Random { sigma, .. }
            | Sampler::Cem { sigma, .. }
            | Sampler::Mppi { sigma, .. } => sigma,
        }
    }
}

/// A planning problem: a model, the system and its state now, the horizon,
/// the cost, and the bound on the driven particles' speed.
pub struct Problem<'a> {
    /// What predicts the free particles.
    pub model: &'a dyn Dynamics,
    /// The system; its kinematic particles are the ones driven.
    pub graph: &'a Graph,
    /// The state to plan from.
    pub start: &'a State,
    /// Control step (`dt`), integration steps per control step
    /// (`substeps`) and control steps ahead (`horizon`).
    pub timing: Timing,
    /// What to minimise.
    pub cost: Cost,
    /// Largest speed of a driven particle along each axis, m/s.
    pub max_speed: f64,
}

/// Why planning failed.
#[derive(Debug, Error)]
pub enum PlanError {
    /// The problem is ill-posed; the message names the fix.
    #[error("{0}")]
    Problem(String),
    /// The model cannot predict this system (not a divergence: that costs +∞).
    #[error(transparent)]
    Model(#[from] DynamicsError),
}

crate::error::typed_errors!(PlanError);

/// One round of a search.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Iteration {
    /// Round number, from 1.
    pub iteration: usize,
    /// Cheapest cost so far.
    pub best: f64,
    /// Mean cost of this round's finite candidates.
    pub mean: f64,
    /// Candidates whose rollout diverged (cost +∞).
    pub diverged: usize,
}

/// A search's result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// The cheapest sequence evaluated.
    pub best: Controls,
    /// Its cost.
    pub cost: f64,
    /// Its predicted trajectory: the start, then one state per control step.
    pub predicted: Vec<State>,
    /// Every candidate's cost in the last round, in the order drawn (the
    /// round's mean first).
    pub costs: Vec<f64>,
    /// The rounds.
    pub iterations: Vec<Iteration>,
    /// Rollouts evaluated in all.
    pub evaluated: usize,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl Problem<'_> {
    /// The driven particles: the graph's kinematic ones.
    pub fn driven(&self) -> Vec<usize> {
        (0..self.graph.n())
            .filter(|&i| self.graph.is_kinematic(i))
            .collect()
    }

    /// The free particles: the ones the risk term averages over.
    pub fn free(&self) -> Vec<usize> {
        (0..self.graph.n())
            .filter(|&i| !self.graph.is_kinematic(i))
            .collect()
    }

    /// Numbers per control step.
    pub fn width(&self) -> usize {
        self.driven().len() * self.graph.dim
    }

    /// Checks the problem; the message names what to change.
    pub fn check(&self) -> Result<(), PlanError> {
        let bad = |m: String| Err(PlanError::Problem(m));
        if self.driven().is_empty() {
            return bad("the system has no kinematic particle to move: planning drives kinematic particles (mark a gripper or pusher kinematic)".into());
        }
        if self.timing.horizon == 0 || self.timing.substeps == 0 {
            return bad("horizon and substeps must be at least 1".into());
        }
        if !(self.timing.dt.is_finite() && self.timing.dt > 0.0) {
            return bad(format!(
                "dt must be positive and finite, got {}",
                self.timing.dt
            ));
        }
        if !(self.max_speed.is_finite() && self.max_speed > 0.0) {
            return bad(format!(
                "max speed must be positive, got {}",
                self.max_speed
            ));
        }
        let (n, d) = (self.graph.n(), self.graph.dim);
        if let Some(&p) = self.cost.particles.iter().find(|&&p| p >= n) {
            return bad(format!(
                "target particle {p} does not exist ({n} particles)"
            ));
        }
        if self.cost.particles.is_empty()
            || self.cost.targets.len() != self.cost.particles.len() * d
        {
            return bad(format!(
                "{} target numbers for {} particles in {d}D: give one {d}-vector per target particle",
                self.cost.targets.len(),
                self.cost.particles.len()
            ));
        }
        let weights_ok = [self.cost.effort, self.cost.speed, self.cost.risk]
            .iter()
            .all(|w| w.is_finite() && *w >= 0.0);
        if self.cost.targets.iter().any(|x| !x.is_finite()) || !weights_ok {
            return bad(
                "targets must be finite and the effort, speed and risk weights finite and ≥ 0"
                    .into(),
            );
        }
        if self.cost.risk > 0.0 && self.model.members() < 2 {
            return bad(format!(
                "a risk weight ({}) needs an ensemble, whose members' spread it weighs; {} is a \
                 single model (spread 0): train one with `mcgnode train --ensemble K`, or use \
                 risk 0",
                self.cost.risk,
                self.model.describe()
            ));
        }
        self.start
            .validate(self.graph)
            .map_err(DynamicsError::from)?;
        Ok(())
    }

    /// The predicted trajectory under `controls` (start, then one state per
    /// control step).
    pub fn rollout(&self, controls: &Controls) -> Result<Vec<State>, DynamicsError> {
        let drive = controls.drive(&self.driven(), self.graph.dim, self.start, self.timing);
        let timing = self.timing.with_horizon(controls.steps);
        self.model
            .rollout_driven(self.graph, self.start, timing, &drive)
    }

    /// [`Problem::rollout`] with each state's spread, empty for a single
    /// model ([`Dynamics::rollout_spread`]).
    pub fn rollout_spread(
        &self,
        controls: &Controls,
    ) -> Result<(Vec<State>, Spread), DynamicsError> {
        let drive = controls.drive(&self.driven(), self.graph.dim, self.start, self.timing);
        let timing = self.timing.with_horizon(controls.steps);
        self.model
            .rollout_spread(self.graph, self.start, timing, Some(&drive))
    }

    /// The cost of `controls`: +∞ when its rollout diverges. With a risk
    /// weight, the rollout is the ensemble's mean and the risk term its
    /// spread along it ([`Cost::risk_of`]); without one, exactly the cost
    /// of the plain rollout.
    pub fn cost_of(&self, controls: &Controls) -> Result<f64, PlanError> {
        let rolled = if self.cost.risk == 0.0 {
            self.rollout(controls).map(|s| (s, Vec::new()))
        } else {
            self.rollout_spread(controls)
        };
        match rolled {
            Ok((states, spread)) => Ok(self.scored(&states, &spread, controls)),
            Err(DynamicsError::Diverged(_)) => Ok(f64::INFINITY),
            Err(e) => Err(e.into()),
        }
    }

    /// The cost of a rollout (`states`, with `spread`) under `controls`.
    fn scored(&self, states: &[State], spread: &Spread, controls: &Controls) -> f64 {
        let base = self.cost.of(states, self.graph.dim, controls, self.timing);
        if self.cost.risk == 0.0 {
            return base;
        }
        base + self.cost.risk_of(spread, &self.free())
    }

    /// The costs of `group` (candidates of equal steps) from one joined
    /// rollout of `lanes`; `None` where they must run one by one (each alone
    /// then costs +∞ or errs as it would).
    fn together(&self, lanes: &super::lanes::Lanes, group: &[Controls]) -> Option<Vec<f64>> {
        let steps = group.first()?.steps;
        if group.iter().any(|c| c.steps != steps) {
            return None;
        }
        let (driven, g) = (self.driven(), self.graph);
        let drives: Vec<_> = group
            .iter()
            .map(|c| c.drive(&driven, g.dim, self.start, self.timing))
            .collect();
        let timing = self.timing.with_horizon(steps);
        let runs = lanes.rollouts(self.model, timing, &drives, self.cost.risk > 0.0)?;
        let cost = |((s, spread), c): (&(Vec<State>, Spread), &Controls)| self.scored(s, spread, c);
        Some(runs.iter().zip(group).map(cost).collect())
    }

    /// The costs of many candidates, spread over the cores (each candidate's
    /// cost does not depend on which thread computes it).
    /// Systems small enough are stepped several candidates at a time
    /// (`plan/lanes.rs`).
    pub fn costs(&self, candidates: &[Controls]) -> Result<Vec<f64>, PlanError> {
        let lanes = super::lanes::Lanes::new(self.model, self.graph, self.start);
        let group = lanes.as_ref().map_or(1, |l| l.width);
        let threads = crate::engine::all_cores().min(candidates.len()).max(1);
        // Whole groups per thread, so that only the last part has a remainder.
        let per = candidates.len().div_ceil(threads).div_ceil(group).max(1) * group;
        let lanes = lanes.as_ref();
        let part_costs = move |part: &[Controls]| -> Result<Vec<f64>, PlanError> {
            let Some(l) = lanes else {
                return part.iter().map(|c| self.cost_of(c)).collect();
            };
            let mut out = Vec::with_capacity(part.len());
            for g in part.chunks(l.width) {
                match self.together(l, g) {
                    Some(costs) => out.extend(costs),
                    None => out.extend(
                        g.iter()
                            .map(|c| self.cost_of(c))
                            .collect::<Result<Vec<_>, _>>()?,
                    ),
                }
            }
            Ok(out)
        };
        let parts: Vec<Result<Vec<f64>, PlanError>> = std::thread::scope(|s| {
            let handles: Vec<_> = candidates
                .chunks(per)
                .map(|part| s.spawn(move || part_costs(part)))
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(DynamicsError::ThreadPanicked.into()))
                })
                .collect()
        });
        let mut out = Vec::with_capacity(candidates.len());
        for p in parts {
            out.extend(p?);
        }
        Ok(out)
    }
}

/// Searches for the cheapest control sequence: `sampler`'s rounds around
/// `init` (the warm start; holding still when `None`), seeded by `seed`.
/// `on_iteration` sees each round and returns false to stop early (cancel),
/// keeping the best so far.
pub fn plan(
    problem: &Problem,
    sampler: Sampler,
    init: Option<&Controls>,
    seed: u64,
    mut on_iteration: impl FnMut(&Iteration) -> bool,
) -> Result<Plan, PlanError> {
    problem.check()?;
    let t0 = Instant::now();
    let mut search = Search::new(problem, sampler, init, seed)?;
    let (mut iterations, mut costs, mut evaluated) = (vec![], vec![], 0);
    for it in 1..=sampler.iterations().max(1) {
        let candidates = search.draw();
        costs = problem.costs(&candidates)?;
        evaluated += candidates.len();
        let report = search.keep(it, &candidates, &costs);
        let go_on = on_iteration(&report);
        iterations.push(report);
        search.refit(&candidates, &costs);
        if !go_on {
            break;
        }
    }
    let (cost, best) = search.best.expect("at least one round ran");
    let predicted = if cost.is_finite() {
        problem.rollout(&best)?
    } else {
        vec![problem.start.clone()]
    };
    Ok(Plan {
        best,
        cost,
        predicted,
        costs,
        iterations,
        evaluated,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// A search's state between rounds: the sampling distribution (mean and
/// spread per velocity), its random stream, and the cheapest sequence so far.
struct Search<'a> {
    problem: &'a Problem<'a>,
    sampler: Sampler,
    mean: Vec<f64>,
    sigma: Vec<f64>,
    rng: ChaCha8Rng,
    best: Option<(f64, Controls)>,
    /// Candidates by cost, cheapest first, of the last round.
    order: Vec<usize>,
}

impl<'a> Search<'a> {
    /// Checks the sampler and the warm start, and starts from them.
    fn new(
        problem: &'a Problem<'a>,
        sampler: Sampler,
        init: Option<&Controls>,
        seed: u64,
    ) -> Result<Self, PlanError> {
        let (h, w) = (problem.timing.horizon, problem.width());
        let n = sampler.candidates().max(1);
        if let Sampler::Cem { elites, .. } = sampler {
            if elites == 0 || elites > n {
                return Err(PlanError::Problem(format!(
                    "CEM needs 1 to {n} elites, got {elites}"
                )));
            }
        }
        if !(sampler.sigma().is_finite() && sampler.sigma() >= 0.0) {
            return Err(PlanError::Problem("sigma must be finite and ≥ 0".into()));
        }
        let mean = match init {
            Some(c) if c.steps == h && c.width == w => c.u.clone(),
            Some(c) => {
                return Err(PlanError::Problem(format!(
                    "the warm start has {} steps of {} numbers, the problem {h} of {w}",
                    c.steps, c.width
                )))
            }
            None => vec![0.0; h * w],
        };
        Ok(Search {
            problem,
            sampler,
            sigma: vec![sampler.sigma(); h * w],
            mean,
            rng: ChaCha8Rng::seed_from_u64(seed),
            best: None,
            order: vec![],
        })
    }

    /// One round's candidates: the mean first, then N(mean, σ²) draws, each
    /// velocity clipped to the speed bound.
    fn draw(&mut self) -> Vec<Controls> {
        let p = self.problem;
        let (h, w) = (p.timing.horizon, p.width());
        let clip = |x: f64| x.clamp(-p.max_speed, p.max_speed);
        let (mean, sigma, rng) = (&self.mean, &self.sigma, &mut self.rng);
        (0..self.sampler.candidates().max(1))
            .map(|k| {
                let u = mean
                    .iter()
                    .zip(sigma)
                    .map(|(m, s)| {
                        let z: f64 = if k == 0 {
                            0.0
                        } else {
                            StandardNormal.sample(rng)
                        };
                        clip(m + s * z)
                    })
                    .collect();
                Controls {
                    steps: h,
                    width: w,
                    u,
                }
            })
            .collect()
    }

    /// Ranks the round, keeps its cheapest if it beats the best so far, and
    /// reports the round.
    fn keep(&mut self, it: usize, candidates: &[Controls], costs: &[f64]) -> Iteration {
        let mut order: Vec<usize> = (0..candidates.len()).collect();
        order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]));
        let top = order[0];
        if self.best.as_ref().is_none_or(|(c, _)| costs[top] < *c) {
            self.best = Some((costs[top], candidates[top].clone()));
        }
        self.order = order;
        let finite: Vec<f64> = costs.iter().copied().filter(|c| c.is_finite()).collect();
        Iteration {
            iteration: it,
            best: self.best.as_ref().map_or(f64::INFINITY, |b| b.0),
            mean: finite.iter().sum::<f64>() / finite.len().max(1) as f64,
            diverged: candidates.len() - finite.len(),
        }
    }

    /// Moves the sampling distribution as the sampler says: CEM refits mean
    /// and spread to the elites, MPPI moves the mean to the cost-weighted
    /// average, random shooting stays.
    fn refit(&mut self, candidates: &[Controls], costs: &[f64]) {
        match self.sampler {
            Sampler::Random { .. } => {}
            Sampler::Cem { elites, .. } => {
                let elite: Vec<&Controls> = self.order[..elites]
                    .iter()
                    .filter(|&&k| costs[k].is_finite())
                    .map(|&k| &candidates[k])
                    .collect();
                if elite.is_empty() {
                    return;
                }
                let m = elite.len() as f64;
                for f in 0..self.mean.len() {
                    let mu = elite.iter().map(|c| c.u[f]).sum::<f64>() / m;
                    let var = elite.iter().map(|c| (c.u[f] - mu).powi(2)).sum::<f64>() / m;
                    self.mean[f] = mu;
                    self.sigma[f] = var.sqrt();
                }
            }
            Sampler::Mppi { temperature, .. } => {
                let lo = costs[self.order[0]];
                if !lo.is_finite() {
                    return;
                }
                let lambda = temperature.max(1e-12);
                let wts: Vec<f64> = costs.iter().map(|c| (-(c - lo) / lambda).exp()).collect();
                let total: f64 = wts.iter().sum();
                for (f, m) in self.mean.iter_mut().enumerate() {
                    *m = candidates
                        .iter()
                        .zip(&wts)
                        .map(|(c, wt)| wt * c.u[f])
                        .sum::<f64>()
                        / total;
                }
            }
        }
    }
}

#[cfg(test)]
#[path = "risk_tests.rs"]
mod risk_tests;
