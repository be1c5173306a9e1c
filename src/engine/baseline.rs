//! The baselines written on the executor behind one trait, [`ExecutorModel`]:
//! GNS ([`Gns`]), and LGN and HGN ([`Potential`]); [`BaselineExecutor`]
//! holds either.

use super::gns::Gns;
use super::potential::Potential;
use super::samples::Samples;
use crate::system::State;

/// What a baseline on the executor offers training and rollouts: its
/// samples, its loss with or without the gradient, and its accelerations.
/// The results do not depend on the thread count it was made with.
pub trait ExecutorModel {
    /// `states` and their targets (one per state, or none) packed for this
    /// network ([`Samples`]). Build them once per data set, not per batch.
    ///
    /// # Panics
    /// If a state or target does not fit the graph, or there are targets but
    /// not one per state.
    fn samples<'a>(&self, states: &'a [State], targets: &'a [Vec<f64>]) -> Samples<'a>;

    /// The loss of the states `idx` of `samples` against their targets, and
    /// its gradient into `grad`.
    ///
    /// # Panics
    /// If `samples` were not made by this network's [`ExecutorModel::samples`]
    /// for its graph (with targets).
    fn loss_grad(
        &mut self,
        theta: &[f64],
        samples: &Samples,
        idx: &[usize],
        grad: &mut [f64],
    ) -> f64;

    /// [`ExecutorModel::loss_grad`]'s loss alone.
    fn loss(&mut self, theta: &[f64], samples: &Samples, idx: &[usize]) -> f64;

    /// Predicted accelerations of `states` (node-major, one vector each):
    /// the forward pass alone, for rollouts.
    fn accelerations(&mut self, theta: &[f64], states: &[State]) -> Vec<Vec<f64>>;
}

/// A baseline on the executor.
pub enum BaselineExecutor {
    /// GNS.
    Gns(Gns),
    /// LGN or HGN.
    Potential(Potential),
}

impl BaselineExecutor {
    /// The network, whichever it is.
    fn net(&self) -> &dyn ExecutorModel {
        match self {
            Self::Gns(g) => g,
            Self::Potential(p) => p,
        }
    }

    fn net_mut(&mut self) -> &mut dyn ExecutorModel {
        match self {
            Self::Gns(g) => g,
            Self::Potential(p) => p,
        }
    }
}

impl ExecutorModel for BaselineExecutor {
    fn samples<'a>(&self, states: &'a [State], targets: &'a [Vec<f64>]) -> Samples<'a> {
        self.net().samples(states, targets)
    }

    fn loss_grad(
        &mut self,
        theta: &[f64],
        samples: &Samples,
        idx: &[usize],
        grad: &mut [f64],
    ) -> f64 {
        self.net_mut().loss_grad(theta, samples, idx, grad)
    }

    fn loss(&mut self, theta: &[f64], samples: &Samples, idx: &[usize]) -> f64 {
        self.net_mut().loss(theta, samples, idx)
    }

    fn accelerations(&mut self, theta: &[f64], states: &[State]) -> Vec<Vec<f64>> {
        self.net_mut().accelerations(theta, states)
    }
}
