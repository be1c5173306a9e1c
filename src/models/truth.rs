//! The ground-truth physics as a model: [`Truth`], the exact dynamics behind
//! the [`Dynamics`] trait (so rollouts, metrics and the ROS node can treat it
//! like a trained model), and servable by name (`--model truth:spring`,
//! `truth:pendulum`): a reference server, and what the node's tests serve.

use std::sync::Arc;

use crate::dynamics::{Dynamics, DynamicsError, EdgeForce, Forces, Rollout};
use crate::physics::constraints::{acceleration, Bars};
use crate::physics::integrator::Integrator;
use crate::physics::{applied_forces, Field, SystemConfig, SystemKind};
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

    fn supports(&self, graph: &Graph) -> Result<(), DynamicsError> {
        graph.validate()?;
        // It knows no contact stiffness, so it would drop the contact forces.
        if graph.has_contacts() {
            return Err(
                crate::physics::PhysicsError::NoContactLaw(graph.interaction_radius).into(),
            );
        }
        Ok(self.field.validate(graph.dim)?)
    }

    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        state.validate(graph)?;
        if out.len() != graph.ndof() {
            return Err(DynamicsError::OutputSize {
                got: out.len(),
                need: graph.ndof(),
            });
        }
        out.copy_from_slice(&acceleration(graph, &self.field, state));
        Ok(())
    }

    /// Total force m·q̈ (constraint forces included) and, per particle edge,
    /// the spring force or the bar's constraint force on `a` due to `b`.
    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError> {
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
    fn rollout(
        &self,
        graph: &Graph,
        start: &State,
        timing: crate::dynamics::Timing,
    ) -> Result<Vec<State>, DynamicsError> {
        self.supports(graph)?;
        let it = Integrator::new(graph, &self.field, timing.step(), start.clone())?;
        integrate(it, graph, timing)
    }

    /// The simulator's integrator with the kinematic particles on `drive`.
    fn rollout_driven(
        &self,
        graph: &Graph,
        start: &State,
        timing: crate::dynamics::Timing,
        drive: &crate::physics::Drive,
    ) -> Result<Vec<State>, DynamicsError> {
        self.supports(graph)?;
        drive.check(graph, timing.steps())?;
        let (dt, drive) = (timing.step(), drive.clone());
        let it = Integrator::driven(graph, &self.field, 0.0, dt, start.clone(), drive)?;
        integrate(it, graph, timing)
    }

    /// [`Dynamics::rollout`] (RATTLE) per start; the truth does not diverge.
    fn rollout_many(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: crate::dynamics::Timing,
    ) -> Result<Vec<Rollout>, DynamicsError> {
        crate::dynamics::rollout_each(self, graph, starts, timing)
    }
}

/// `timing`'s steps of `it`: its start, then every kept state.
fn integrate(
    mut it: Integrator,
    graph: &Graph,
    timing: crate::dynamics::Timing,
) -> Result<Vec<State>, DynamicsError> {
    let mut out = Vec::with_capacity(timing.kept());
    out.push(it.state().clone());
    for step in 1..=timing.steps() {
        it.step();
        if it.state().validate(graph).is_err() {
            return Err(DynamicsError::Diverged(step));
        }
        if timing.keeps(step) {
            out.push(it.state().clone());
        }
    }
    Ok(out)
}

/// Prefix of model names that select the ground-truth physics.
pub const TRUTH_PREFIX: &str = "truth:";

/// Whether a model name selects the ground truth rather than a file.
pub fn is_truth(model: &str) -> bool {
    model.starts_with(TRUTH_PREFIX)
}

/// The exact dynamics in the field of the paper's `spring` or `pendulum`
/// system named `truth:<system>` (see [`truth`]).
pub fn load_truth(model: &str) -> Result<Arc<dyn Dynamics>, TruthError> {
    let name = model
        .strip_prefix(TRUTH_PREFIX)
        .ok_or_else(|| TruthError::NotTruth(model.to_string()))?;
    Ok(truth(name.parse()?))
}

/// The exact dynamics in the field of the paper's `kind` system (no gravity
/// for springs, g = 10 for pendulums), named `truth:<kind>`; they work for
/// any graph of springs and bars, not only the paper's.
pub fn truth(kind: SystemKind) -> Arc<dyn Dynamics> {
    let model = format!("{TRUTH_PREFIX}{kind}");
    let field = SystemConfig::new(kind, 1).field;
    let trained = crate::compat::TrainedFor::truth(&model, field.clone());
    Arc::new(super::Checked::new(
        Arc::new(TruthModel {
            name: model,
            truth: Truth { field },
        }),
        trained,
    ))
}

/// A model name that selects no ground truth.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TruthError {
    /// The name does not start with `truth:`.
    #[error("{0:?} is not a truth:<system> model name")]
    NotTruth(String),
    /// `truth:` names no system kind.
    #[error(transparent)]
    UnknownSystem(#[from] crate::names::UnknownName),
}

crate::error::typed_errors!(TruthError);

/// [`Truth`] under the name it was selected by, so diagnostics say which.
struct TruthModel {
    name: String,
    truth: Truth,
}

impl Dynamics for TruthModel {
    fn describe(&self) -> String {
        format!("{}: {}", self.name, self.truth.describe())
    }

    fn supports(&self, graph: &crate::system::Graph) -> Result<(), DynamicsError> {
        self.truth.supports(graph)
    }

    /// Forces edge by edge.
    fn steps_copies_together(&self) -> bool {
        true
    }

    fn acceleration(
        &self,
        graph: &crate::system::Graph,
        state: &crate::system::State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        self.truth.acceleration(graph, state, out)
    }

    fn forces(
        &self,
        graph: &crate::system::Graph,
        state: &crate::system::State,
    ) -> Result<crate::dynamics::Forces, DynamicsError> {
        self.truth.forces(graph, state)
    }

    // The simulator's integrator (Verlet + SHAKE/RATTLE for bars), not the
    // trait's unconstrained default: replay and serve call these.
    fn rollout(
        &self,
        graph: &crate::system::Graph,
        start: &crate::system::State,
        timing: crate::dynamics::Timing,
    ) -> Result<Vec<crate::system::State>, DynamicsError> {
        self.truth.rollout(graph, start, timing)
    }

    fn rollout_many(
        &self,
        graph: &crate::system::Graph,
        starts: &[crate::system::State],
        timing: crate::dynamics::Timing,
    ) -> Result<Vec<crate::dynamics::Rollout>, DynamicsError> {
        self.truth.rollout_many(graph, starts, timing)
    }

    fn rollout_driven(
        &self,
        graph: &crate::system::Graph,
        start: &crate::system::State,
        timing: crate::dynamics::Timing,
        drive: &crate::physics::Drive,
    ) -> Result<Vec<crate::system::State>, DynamicsError> {
        self.truth.rollout_driven(graph, start, timing, drive)
    }

    fn acceleration_batch(
        &self,
        graph: &crate::system::Graph,
        states: &[crate::system::State],
        out: &mut [Vec<f64>],
    ) -> Result<(), DynamicsError> {
        self.truth.acceleration_batch(graph, states, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selects_the_systems_field() {
        let spring = load_truth("truth:spring").unwrap();
        let pendulum = load_truth("truth:pendulum").unwrap();
        assert!(spring.describe().contains("g = 0"), "{}", spring.describe());
        assert!(
            pendulum.describe().contains("g = 10"),
            "{}",
            pendulum.describe()
        );
        let e = load_truth("truth:rope").err().unwrap().to_string();
        assert!(e.contains("unknown system kind"), "{e}");
        assert!(load_truth("model.bin").is_err());
    }

    #[test]
    fn pendulum_truth_falls_under_gravity() {
        let cfg = SystemConfig::new(SystemKind::Pendulum, 2);
        let graph = cfg.graph();
        let state = cfg.start_for(&graph, 1, 0);
        let m = load_truth("truth:pendulum").unwrap();
        let mut a = vec![0.0; graph.ndof()];
        m.acceleration(&graph, &state, &mut a).unwrap();
        assert!(a.iter().all(|x| x.is_finite()));
        assert!(a.iter().any(|x| x.abs() > 1e-6), "{a:?}");
    }
}
