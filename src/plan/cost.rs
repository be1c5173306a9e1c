//! What a plan minimises: how far chosen particles are from their targets
//! (and how fast they still move), at the end of the horizon or along it,
//! plus the control effort.

use super::controls::Controls;
use crate::dynamics::Timing;
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
