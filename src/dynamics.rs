//! The one interface between "something that knows the dynamics" (a trained
//! model, or the ground-truth physics) and whoever uses it (rollouts, metrics,
//! the ROS node).

use crate::system::{Graph, State};

/// Forces a model attributes to a state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Forces {
    /// Total force per particle, `n * dim`.
    pub total: Vec<f64>,
    /// Pairwise forces f_ab on particle `a` due to particle `b` (so f_ba = −f_ab),
    /// one entry per particle edge, when the model has them (MCGNODE).
    pub edges: Vec<EdgeForce>,
}

/// The force on particle `a` due to particle `b`.
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeForce {
    /// Particle receiving the force.
    pub a: usize,
    /// Particle exerting it.
    pub b: usize,
    /// The force, `dim` components.
    pub force: Vec<f64>,
}

/// Something that predicts accelerations of a particle system.
pub trait Dynamics: Send + Sync {
    /// A short human-readable description ("mcgnode trained on 5-spring", ...).
    fn describe(&self) -> String;

    /// Whether this graph can be handled (particle types known, dimension, ...).
    fn supports(&self, graph: &Graph) -> Result<(), String>;

    /// Accelerations at a state, written to `out` (`n * dim`).
    fn acceleration(&self, graph: &Graph, state: &State, out: &mut [f64]) -> Result<(), String>;

    /// Forces at a state.
    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, String>;

    /// Velocity-Verlet rollout of `steps` steps of `dt`, keeping `start` and
    /// every `every`-th state (so a coarse output can come from a fine
    /// integration step).
    ///
    /// The velocity-dependent acceleration at the new position is evaluated at
    /// the half-step velocity, which keeps the scheme explicit.
    fn rollout_every(
        &self,
        graph: &Graph,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<Vec<State>, String> {
        self.supports(graph)?;
        start.validate(graph)?;
        let every = every.max(1);
        let mut out = Vec::with_capacity(steps / every + 1);
        let mut s = start.clone();
        let mut a = vec![0.0; graph.ndof()];
        self.acceleration(graph, &s, &mut a)?;
        out.push(s.clone());
        for step in 1..=steps {
            for ((q, v), a) in s.q.iter_mut().zip(s.v.iter_mut()).zip(&a) {
                *q += *v * dt + 0.5 * a * dt * dt;
                *v += 0.5 * a * dt;
            }
            self.acceleration(graph, &s, &mut a)?;
            for (v, a) in s.v.iter_mut().zip(&a) {
                *v += 0.5 * a * dt;
            }
            if s.q.iter().chain(&s.v).any(|x| !x.is_finite()) {
                return Err(format!(
                    "rollout diverged (non-finite state) at step {step}"
                ));
            }
            if step % every == 0 {
                out.push(s.clone());
            }
        }
        Ok(out)
    }

    /// Velocity-Verlet rollout: `steps + 1` states including `start`.
    fn rollout(
        &self,
        graph: &Graph,
        start: &State,
        dt: f64,
        steps: usize,
    ) -> Result<Vec<State>, String> {
        self.rollout_every(graph, start, dt, steps, 1)
    }
}
