//! A model wrapped with what it was trained on ([`Checked`]).

use std::sync::Arc;

use crate::compat::{Passed, TrainedFor};
use crate::dynamics::{Dynamics, DynamicsError, Forces, Predicted, Rollout};
use crate::system::{Graph, State};

/// A model with what it was trained on: [`Dynamics::supports`] also refuses
/// graphs the model was not trained for, and
/// [`Dynamics::trained_for`] lets a caller check the data's field.
pub struct Checked {
    inner: Arc<dyn Dynamics>,
    trained: TrainedFor,
    /// The last graph checked: a stream of one system is checked once.
    passed: Passed,
}

impl Checked {
    /// Wraps `inner`.
    pub fn new(inner: Arc<dyn Dynamics>, trained: TrainedFor) -> Checked {
        Checked {
            inner,
            trained,
            passed: Passed::default(),
        }
    }

    /// [`TrainedFor::check`] without a field, once per graph in a row.
    fn check(&self, graph: &Graph) -> Result<(), DynamicsError> {
        Ok(self.passed.check(0, &self.trained, graph, None)?)
    }

    /// How many graph checks ran in full (not skipped as the last graph).
    pub fn full_checks(&self) -> u64 {
        self.passed.full_checks()
    }
}

impl Dynamics for Checked {
    fn describe(&self) -> String {
        self.inner.describe()
    }

    fn supports(&self, graph: &Graph) -> Result<(), DynamicsError> {
        self.check(graph)?;
        self.inner.supports(graph)
    }

    fn trained_for(&self) -> Option<&TrainedFor> {
        Some(&self.trained)
    }

    fn steps_copies_together(&self) -> bool {
        self.inner.steps_copies_together()
    }

    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        self.check(graph)?;
        self.inner.acceleration(graph, state, out)
    }

    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError> {
        self.check(graph)?;
        self.inner.forces(graph, state)
    }

    fn predict_into(
        &self,
        graph: &Graph,
        start: &State,
        timing: crate::dynamics::Timing,
        out: &mut Predicted,
    ) -> Result<(), DynamicsError> {
        self.check(graph)?;
        self.inner.predict_into(graph, start, timing, out)
    }

    fn rollout(
        &self,
        graph: &Graph,
        start: &State,
        timing: crate::dynamics::Timing,
    ) -> Result<Vec<State>, DynamicsError> {
        self.check(graph)?;
        self.inner.rollout(graph, start, timing)
    }

    fn state_gradient(
        &self,
        graph: &Graph,
    ) -> Result<Option<Box<dyn crate::dynamics::StateGradient>>, DynamicsError> {
        self.check(graph)?;
        self.inner.state_gradient(graph)
    }

    fn rollout_driven(
        &self,
        graph: &Graph,
        start: &State,
        timing: crate::dynamics::Timing,
        drive: &crate::physics::Drive,
    ) -> Result<Vec<State>, DynamicsError> {
        self.check(graph)?;
        self.inner.rollout_driven(graph, start, timing, drive)
    }

    fn acceleration_batch(
        &self,
        graph: &Graph,
        states: &[State],
        out: &mut [Vec<f64>],
    ) -> Result<(), DynamicsError> {
        self.check(graph)?;
        self.inner.acceleration_batch(graph, states, out)
    }

    fn rollout_many(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: crate::dynamics::Timing,
    ) -> Result<Vec<Rollout>, DynamicsError> {
        self.check(graph)?;
        self.inner.rollout_many(graph, starts, timing)
    }

    fn members(&self) -> usize {
        self.inner.members()
    }

    fn rollout_many_spread(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: crate::dynamics::Timing,
    ) -> Result<Vec<(Rollout, crate::dynamics::Spread)>, DynamicsError> {
        self.check(graph)?;
        self.inner.rollout_many_spread(graph, starts, timing)
    }

    fn rollout_spread(
        &self,
        graph: &Graph,
        start: &State,
        timing: crate::dynamics::Timing,
        drive: Option<&crate::physics::Drive>,
    ) -> Result<(Vec<State>, crate::dynamics::Spread), DynamicsError> {
        self.check(graph)?;
        self.inner.rollout_spread(graph, start, timing, drive)
    }
}
