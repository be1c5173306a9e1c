//! The ground-truth physics behind the [`Dynamics`] trait, so rollouts,
//! metrics and the ROS node can treat it like a trained model.

use super::constraints::{acceleration, Bars};
use super::forces::applied_forces;
use super::integrator::Integrator;
use super::Field;
use crate::dynamics::{Dynamics, EdgeForce, Forces, Rollout};
use crate::system::{EdgeKind, Endpoint, Graph, State};

/// Exact dynamics of a graph in a field.
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    /// The field the particles sit in.
    pub field: Field,
}

impl Dynamics for Truth {
    fn describe(&self) -> String {
        format!(
            "ground-truth physics (g = {}, drag = {}, force = {:?})",
            self.field.gravity, self.field.drag, self.field.force
        )
    }

    fn supports(&self, graph: &Graph) -> Result<(), String> {
        graph.validate()?;
        self.field.validate(graph.dim)
    }

    fn acceleration(&self, graph: &Graph, state: &State, out: &mut [f64]) -> Result<(), String> {
        state.validate(graph)?;
        if out.len() != graph.ndof() {
            return Err(format!(
                "output has {} slots, need {}",
                out.len(),
                graph.ndof()
            ));
        }
        out.copy_from_slice(&acceleration(graph, &self.field, state));
        Ok(())
    }

    /// Total force m·q̈ (constraint forces included) and, per particle edge,
    /// the spring force or the bar's constraint force on `a` due to `b`.
    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, String> {
        self.supports(graph)?;
        state.validate(graph)?;
        let d = graph.dim;
        let acc = acceleration(graph, &self.field, state);
        let total: Vec<f64> = acc
            .iter()
            .enumerate()
            .map(|(k, a)| a * graph.masses[k / d])
            .collect();
        // Bar multipliers from the constraint force each bar's particle-a end
        // feels: Aᵀλ at a is λ_j d_j summed over bars; recover λ by solving the
        // same system the acceleration used.
        let mut applied = vec![0.0; graph.ndof()];
        applied_forces(graph, &self.field, &state.q, &state.v, &mut applied);
        let mut bars = Bars::new(graph);
        let k = bars.k();
        let mut dirs = vec![0.0; k * d];
        bars.dirs(graph, &state.q, &mut dirs);
        let mut unc = applied.clone();
        for (i, x) in unc.iter_mut().enumerate() {
            *x /= graph.masses[i / d];
        }
        for j in 0..k {
            let w2: f64 = (0..d)
                .map(|c| {
                    let vb = bars.b[j].map_or(0.0, |b| state.v[b * d + c]);
                    (state.v[bars.a[j] * d + c] - vb).powi(2)
                })
                .sum();
            bars.rhs[j] = bars.mul(graph, &dirs, &unc, j) + w2;
        }
        if k > 0 {
            bars.solve(graph, &dirs, &dirs);
        }
        let mut edges = vec![];
        let mut bar_j = 0;
        for e in &graph.edges {
            let is_bar = e.kind == EdgeKind::Bar;
            let j = bar_j;
            if is_bar {
                bar_j += 1;
            }
            let Endpoint::Particle(b) = e.b else { continue };
            let diff: Vec<f64> = (0..d)
                .map(|c| state.q[e.a * d + c] - state.q[b * d + c])
                .collect();
            let force = if is_bar {
                diff.iter().map(|x| -bars.rhs[j] * x).collect()
            } else {
                let r = diff.iter().map(|x| x * x).sum::<f64>().sqrt();
                if r == 0.0 {
                    vec![0.0; d]
                } else {
                    let s = -e.stiffness * (r - e.rest_length) / r;
                    diff.iter().map(|x| s * x).collect()
                }
            };
            edges.push(EdgeForce { a: e.a, b, force });
        }
        Ok(Forces { total, edges })
    }

    /// Velocity Verlet with SHAKE/RATTLE (exact for bars), not the generic
    /// unconstrained rollout.
    fn rollout_every(
        &self,
        graph: &Graph,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<Vec<State>, String> {
        self.supports(graph)?;
        let every = every.max(1);
        let mut it = Integrator::new(graph, &self.field, dt, start.clone())?;
        let mut out = Vec::with_capacity(steps / every + 1);
        out.push(start.clone());
        for step in 1..=steps {
            it.step();
            if it.state().validate(graph).is_err() {
                return Err(format!(
                    "rollout diverged (non-finite state) at step {step}"
                ));
            }
            if step % every == 0 {
                out.push(it.state().clone());
            }
        }
        Ok(out)
    }

    /// [`Dynamics::rollout_every`] (RATTLE) per start; the truth does not diverge.
    fn rollout_many(
        &self,
        graph: &Graph,
        starts: &[State],
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<Vec<Rollout>, String> {
        starts
            .iter()
            .map(|s| {
                Ok(Rollout {
                    states: self.rollout_every(graph, s, dt, steps, every)?,
                    diverged_at: None,
                })
            })
            .collect()
    }
}
