//! The baselines written on the executor behind one type: GNS ([`Gns`]),
//! and LGN and HGN ([`Potential`]), each an [`ExecutorModel`].

use super::gns::Gns;
use super::model::ExecutorModel;
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
