//! Velocity Verlet, with SHAKE/RATTLE projection when the graph has bars.
//!
//! Without bars one step is exactly the scheme the learned-model rollout uses:
//! q' = q + v dt + ½a dt²; v½ = v + ½a dt; a' = M⁻¹F(q', v½); v' = v½ + ½a' dt.
//! With bars the unconstrained a is used the same way, then
//! * SHAKE: q' −= M⁻¹A(q)ᵀγ with γ from Newton iterations until every bar
//!   length is exact to [`Integrator::TOL`] (relative), v½ gets the same kick;
//! * RATTLE: v' −= M⁻¹A(q')ᵀμ with μ solving A(q') v' = 0 exactly.
//!
//! RATTLE is symplectic, so without drag the energy error stays bounded.

use super::forces::applied_forces;
use super::projection::Projector;
use super::verlet;
use super::Field;
use super::PhysicsError;
use crate::system::{Graph, State};

/// A velocity-Verlet(+RATTLE) integrator that owns the state it advances.
///
/// Steps do not allocate (except for redundant bars, which fall back to SVD).
#[derive(Clone, Debug)]
pub struct Integrator {
    graph: Graph,
    field: Field,
    dt: f64,
    state: State,
    /// Unconstrained acceleration M⁻¹F at the current q and the last
    /// half-step velocity (the value the next step starts from).
    acc: Vec<f64>,
    projector: Projector,
    steps: u64,
}

impl Integrator {
    /// Relative bar-length tolerance of the SHAKE iteration.
    pub const TOL: f64 = Projector::TOL;
    /// Newton iterations allowed per step before giving up (counted in
    /// [`Integrator::shake_failures`]).
    pub const MAX_ITER: usize = Projector::MAX_ITER;

    /// Checks the inputs and computes the starting acceleration.
    pub fn new(graph: &Graph, field: &Field, dt: f64, start: State) -> Result<Self, PhysicsError> {
        graph.validate()?;
        field.validate(graph.dim)?;
        start.validate(graph)?;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(PhysicsError::TimeStep(dt));
        }
        if let Some(e) = graph.bars().find(|e| e.rest_length <= 0.0) {
            return Err(PhysicsError::BarLength(e.a));
        }
        let mut it = Integrator {
            graph: graph.clone(),
            field: field.clone(),
            dt,
            state: start,
            acc: vec![0.0; graph.ndof()],
            projector: Projector::new(graph),
            steps: 0,
        };
        it.update_acc();
        Ok(it)
    }

    /// acc = M⁻¹ F(q, v) for the current state.
    fn update_acc(&mut self) {
        let s = &self.state;
        true_acceleration(&self.graph, &self.field, &s.q, &s.v, &mut self.acc);
    }

    /// One step of length dt.
    pub fn step(&mut self) {
        let (graph, field) = (&self.graph, &self.field);
        let s = &mut self.state;
        let accel = |q: &[f64], v: &[f64], acc: &mut [f64]| {
            true_acceleration(graph, field, q, v, acc);
            Ok::<(), std::convert::Infallible>(())
        };
        let Ok(()) = verlet::step(
            &mut s.q,
            &mut s.v,
            &mut self.acc,
            self.dt,
            Some(&mut self.projector),
            accel,
        );
        self.steps += 1;
    }

    /// `n` steps.
    pub fn advance(&mut self, n: usize) {
        for _ in 0..n {
            self.step();
        }
    }

    /// The current state.
    pub fn state(&self) -> &State {
        &self.state
    }

    /// The system being integrated.
    pub fn graph(&self) -> &Graph {
        &self.graph
    }

    /// The field acting on it.
    pub fn field(&self) -> &Field {
        &self.field
    }

    /// The time step.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Time since the start, `steps * dt`.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.dt
    }

    /// Newton iterations SHAKE has taken in total (a cost diagnostic).
    pub fn shake_iterations(&self) -> u64 {
        self.projector.iterations()
    }

    /// Steps whose SHAKE iteration did not reach [`Integrator::TOL`] within
    /// [`Integrator::MAX_ITER`] iterations, or whose constraint matrix could
    /// not be solved (degenerate bars). 0 for a healthy run.
    pub fn shake_failures(&self) -> u64 {
        self.projector.failures()
    }
}

/// acc = M⁻¹ F(q, v): the applied forces over the masses (bars are the
/// projector's job).
fn true_acceleration(graph: &Graph, field: &Field, q: &[f64], v: &[f64], acc: &mut [f64]) {
    let d = graph.dim;
    applied_forces(graph, field, q, v, acc);
    for (i, m) in graph.masses.iter().enumerate() {
        for c in 0..d {
            acc[i * d + c] /= m;
        }
    }
}
