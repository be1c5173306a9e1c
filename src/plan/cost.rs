//! What a plan minimises: how far chosen particles are from their targets
//! (and how fast they still move), at the end of the horizon or along it,
//! plus the control effort and, for an ensemble, a risk term: how much its
//! members disagree along the candidate's rollout.

use super::controls::Controls;
use crate::dynamics::{Spread, Timing};
use crate::system::State;
use serde::{Deserialize, Serialize};

/// When the distance to the targets counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CostKind {
    /// At the end of the horizon only.
    Final,
    /// At every control step of the horizon (its mean): get there soon and
    /// stay.
    Along,
}

/// A cost on a predicted trajectory and the controls that made it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Cost {
    /// When distances count.
    pub kind: CostKind,
    /// The particles that have targets.
    pub particles: Vec<usize>,
    /// Their targets, `dim` numbers each.
    pub targets: Vec<f64>,
    /// Weight of the control effort Σ|u|²·T.
    pub effort: f64,
    /// Weight of the chosen particles' squared speed, counted where their
    /// distances are: "get there and stay" rather than "fly through".
    #[serde(default)]
    pub speed: f64,
    /// Weight of the risk term ([`Cost::risk_of`]): an ensemble's spread
    /// along the rollout; 0 (the default) leaves the cost as without it.
    #[serde(default)]
    pub risk: f64,
}

impl Cost {
    /// Squared distance to the targets plus the speed term, at `s`.
    fn at(&self, s: &State, dim: usize) -> f64 {
        let speed2: f64 = self
            .particles
            .iter()
            .map(|&p| {
                s.v[p * dim..(p + 1) * dim]
                    .iter()
                    .map(|x| x * x)
                    .sum::<f64>()
            })
            .sum();
        self.distance2(s, dim) + self.speed * speed2
    }

    /// Squared distance of the chosen particles to their targets in `s`.
    pub fn distance2(&self, s: &State, dim: usize) -> f64 {
        self.particles
            .iter()
            .enumerate()
            .map(|(j, &p)| {
                (0..dim)
                    .map(|c| (s.q[p * dim + c] - self.targets[j * dim + c]).powi(2))
                    .sum::<f64>()
            })
            .sum()
    }

    /// The risk term of a rollout whose kept states have `spread` (the
    /// start, then one per control step; [`Spread`]): `risk` × the sum over
    /// the control steps k = 1..H of the mean over the `free` particles of
    /// their spread (the members' standard deviation of position). 0 when
    /// `risk` is 0, and for a single model (its spread is empty).
    pub fn risk_of(&self, spread: &Spread, free: &[usize]) -> f64 {
        if self.risk == 0.0 || free.is_empty() {
            return 0.0;
        }
        let mean = |s: &Vec<f64>| {
            free.iter()
                .map(|&i| s.get(i).copied().unwrap_or(0.0))
                .sum::<f64>()
                / free.len() as f64
        };
        self.risk * spread.iter().skip(1).map(mean).sum::<f64>()
    }

    /// The cost of `states` (the start, then one per control step) under
    /// `controls`; +∞ for a trajectory cut short (a diverged rollout).
    pub fn of(&self, states: &[State], dim: usize, controls: &Controls, timing: Timing) -> f64 {
        if states.len() != controls.steps + 1 {
            return f64::INFINITY;
        }
        let reach = match self.kind {
            CostKind::Final => states.last().map_or(0.0, |s| self.at(s, dim)),
            CostKind::Along => {
                states[1..].iter().map(|s| self.at(s, dim)).sum::<f64>()
                    / controls.steps.max(1) as f64
            }
        };
        reach + self.effort * controls.effort(timing)
    }
}
