//! Ground-truth physics as a servable model (`--model truth:spring`,
//! `truth:pendulum`): a reference server, and what the node's tests serve.

use std::sync::Arc;

use crate::dynamics::Dynamics;
use crate::physics::{SystemConfig, SystemKind, Truth};

/// Prefix of model names that select the ground-truth physics.
pub const TRUTH_PREFIX: &str = "truth:";

/// Whether a model name selects the ground truth rather than a file.
pub fn is_truth(model: &str) -> bool {
    model.starts_with(TRUTH_PREFIX)
}

/// The exact dynamics in the field of the paper's `spring` or `pendulum`
/// system (no gravity for springs, g = 10 for pendulums); they work for any
/// graph of springs and bars, not only the paper's.
pub fn load_truth(model: &str) -> Result<Arc<dyn Dynamics>, String> {
    let name = model
        .strip_prefix(TRUTH_PREFIX)
        .ok_or_else(|| format!("{model:?} is not a truth:<system> model name"))?;
    let kind: SystemKind = name.parse()?;
    let field = SystemConfig::new(kind, 1).field;
    let trained = crate::compat::TrainedFor::truth(model, field.clone());
    Ok(Arc::new(crate::compat::Checked::new(
        Arc::new(TruthModel {
            name: model.to_string(),
            truth: Truth { field },
        }),
        trained,
    )))
}

/// [`Truth`] under the name it was selected by, so diagnostics say which.
struct TruthModel {
    name: String,
    truth: Truth,
}

impl Dynamics for TruthModel {
    fn describe(&self) -> String {
        format!("{}: {}", self.name, self.truth.describe())
    }

    fn supports(&self, graph: &crate::system::Graph) -> Result<(), String> {
        self.truth.supports(graph)
    }

    fn acceleration(
        &self,
        graph: &crate::system::Graph,
        state: &crate::system::State,
        out: &mut [f64],
    ) -> Result<(), String> {
        self.truth.acceleration(graph, state, out)
    }

    fn forces(
        &self,
        graph: &crate::system::Graph,
        state: &crate::system::State,
    ) -> Result<crate::dynamics::Forces, String> {
        self.truth.forces(graph, state)
    }

    fn rollout(
        &self,
        graph: &crate::system::Graph,
        start: &crate::system::State,
        dt: f64,
        steps: usize,
    ) -> Result<Vec<crate::system::State>, String> {
        self.truth.rollout(graph, start, dt, steps)
    }

    // The simulator's integrator (Verlet + SHAKE/RATTLE for bars), not the
    // trait's unconstrained default: replay and serve call these.
    fn rollout_every(
        &self,
        graph: &crate::system::Graph,
        start: &crate::system::State,
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<Vec<crate::system::State>, String> {
        self.truth.rollout_every(graph, start, dt, steps, every)
    }

    fn rollout_many(
        &self,
        graph: &crate::system::Graph,
        starts: &[crate::system::State],
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<Vec<crate::dynamics::Rollout>, String> {
        self.truth.rollout_many(graph, starts, dt, steps, every)
    }

    fn acceleration_batch(
        &self,
        graph: &crate::system::Graph,
        states: &[crate::system::State],
        out: &mut [Vec<f64>],
    ) -> Result<(), String> {
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
        let e = load_truth("truth:rope").err().unwrap();
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
