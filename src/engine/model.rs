//! What the baselines written on the executor share, whichever network
//! they are: [`ExecutorModel`] (GNS, LGN and HGN implement it, and
//! [`super::BaselineExecutor`] dispatches through it).

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
