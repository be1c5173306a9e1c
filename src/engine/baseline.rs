//! The baselines written on the executor behind one type: GNS ([`Gns`]),
//! and LGN and HGN ([`Potential`]).

use super::gns::Gns;
use super::potential::Potential;
use super::samples::Samples;
use crate::system::State;

/// A baseline on the executor.
pub enum BaselineExecutor {
    /// GNS.
    Gns(Gns),
    /// LGN or HGN.
    Potential(Potential),
}

impl BaselineExecutor {
    /// `states` and their targets laid out for this network.
    ///
    /// # Panics
    /// As [`Gns::samples`].
    pub fn samples<'a>(&self, states: &'a [State], targets: &'a [Vec<f64>]) -> Samples<'a> {
        match self {
            Self::Gns(g) => g.samples(states, targets),
            Self::Potential(p) => p.samples(states, targets),
        }
    }

    /// The loss of the states `idx` and its gradient into `grad`.
    ///
    /// # Panics
    /// As [`Gns::loss_grad`].
    pub fn loss_grad(
        &mut self,
        theta: &[f64],
        samples: &Samples,
        idx: &[usize],
        grad: &mut [f64],
    ) -> f64 {
        match self {
            Self::Gns(g) => g.loss_grad(theta, samples, idx, grad),
            Self::Potential(p) => p.loss_grad(theta, samples, idx, grad),
        }
    }

    /// The loss alone.
    pub fn loss(&mut self, theta: &[f64], samples: &Samples, idx: &[usize]) -> f64 {
        match self {
            Self::Gns(g) => g.loss(theta, samples, idx),
            Self::Potential(p) => p.loss(theta, samples, idx),
        }
    }

    /// Predicted accelerations of `states` (node-major, one vector each).
    pub fn accelerations(&mut self, theta: &[f64], states: &[State]) -> Vec<Vec<f64>> {
        match self {
            Self::Gns(g) => g.accelerations(theta, states),
            Self::Potential(p) => p.accelerations(theta, states),
        }
    }
}
