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
//!
//! Contacts ([`super::contact`]) add their forces at every evaluation, from
//! pairs searched anew at that q. Kinematic particles have zero acceleration
//! and exert and receive forces like any other: without a [`Drive`] they must
//! start at rest and so never move; with one ([`Integrator::driven`])
//! they are placed where it has them before every evaluation.

use super::contact::Contacts;
use super::drive::Drive;
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
    /// Contact forces when the graph has a radius and k_c > 0.
    contacts: Option<Contacts>,
    /// The kinematic particles' given motion, one row per step.
    drive: Option<Drive>,
    steps: u64,
}

impl Integrator {
    /// Relative bar-length tolerance of the SHAKE iteration.
    pub const TOL: f64 = Projector::TOL;
    /// Newton iterations allowed per step before giving up (counted in
    /// [`Integrator::shake_failures`]).
    pub const MAX_ITER: usize = Projector::MAX_ITER;

    /// Checks the inputs and computes the starting acceleration (no contact
    /// forces: [`Integrator::with_contacts`] adds them).
    pub fn new(graph: &Graph, field: &Field, dt: f64, start: State) -> Result<Self, PhysicsError> {
        Self::with_contacts(graph, field, 0.0, dt, start)
    }

    /// [`Integrator::new`] with contact stiffness k_c: pairs closer than the
    /// graph's interaction radius repel by ½ k_c (R − r)² (nothing when the
    /// radius or k_c is 0).
    pub fn with_contacts(
        graph: &Graph,
        field: &Field,
        contact_stiffness: f64,
        dt: f64,
        start: State,
    ) -> Result<Self, PhysicsError> {
        Self::build(graph, field, contact_stiffness, dt, start, None)
    }

    /// [`Integrator::with_contacts`] with the kinematic particles moved along
    /// `drive` (which should cover the steps that will be taken; past its end
    /// they stay at its last row): placed at its row 0 at the start and at
    /// row k before the evaluation of step k, so they may start moving.
    pub fn driven(
        graph: &Graph,
        field: &Field,
        contact_stiffness: f64,
        dt: f64,
        start: State,
        drive: Drive,
    ) -> Result<Self, PhysicsError> {
        Self::build(graph, field, contact_stiffness, dt, start, Some(drive))
    }

    fn build(
        graph: &Graph,
        field: &Field,
        contact_stiffness: f64,
        dt: f64,
        mut start: State,
        drive: Option<Drive>,
    ) -> Result<Self, PhysicsError> {
        graph.validate()?;
        field.validate(graph.dim)?;
        start.validate(graph)?;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(PhysicsError::TimeStep(dt));
        }
        if let Some(e) = graph.bars().find(|e| e.rest_length <= 0.0) {
            return Err(PhysicsError::BarLength(e.a));
        }
        check_bars(graph)?;
        match &drive {
            None => check_at_rest(graph, &start)?,
            Some(d) => {
                d.check(graph, 0)
                    .map_err(|e| PhysicsError::Drive(e.to_string()))?;
                d.place(0, &mut start.q, &mut start.v);
            }
        }
        if !(contact_stiffness.is_finite() && contact_stiffness >= 0.0) {
            return Err(PhysicsError::ContactStiffness(contact_stiffness));
        }
        let contacts = (graph.has_contacts() && contact_stiffness > 0.0)
            .then(|| Contacts::new(graph, contact_stiffness));
        let mut it = Integrator {
            graph: graph.clone(),
            field: field.clone(),
            dt,
            state: start,
            acc: vec![0.0; graph.ndof()],
            projector: Projector::new(graph),
            contacts,
            drive,
            steps: 0,
        };
        it.update_acc();
        Ok(it)
    }

    /// acc = M⁻¹ F(q, v) for the current state.
    fn update_acc(&mut self) {
        let s = &self.state;
        let c = self.contacts.as_mut();
        true_acceleration(&self.graph, &self.field, c, &s.q, &s.v, &mut self.acc);
    }

    /// One step of length dt.
    pub fn step(&mut self) {
        let (graph, field) = (&self.graph, &self.field);
        let contacts = self.contacts.as_mut();
        let s = &mut self.state;
        let accel = |q: &[f64], v: &[f64], acc: &mut [f64]| {
            true_acceleration(graph, field, contacts, q, v, acc);
            Ok::<(), std::convert::Infallible>(())
        };
        let (drive, row) = (self.drive.as_ref(), self.steps as usize + 1);
        let place = |q: &mut [f64], v: &mut [f64]| {
            verlet::wrap(graph, q);
            if let Some(d) = drive {
                d.place(row.min(d.steps()), q, v);
            }
        };
        let Ok(()) = verlet::step_placed(
            &mut s.q,
            &mut s.v,
            &mut self.acc,
            self.dt,
            Some(&mut self.projector),
            place,
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

    /// The exact constrained acceleration at the current state, contacts
    /// included (kinematic particles: 0), as bags record it.
    pub fn exact_acceleration(&mut self) -> Vec<f64> {
        let mut out = vec![0.0; self.graph.ndof()];
        let (graph, field, s) = (&self.graph, &self.field, &self.state);
        let contacts = self.contacts.as_mut();
        super::constraints::acceleration_with(graph, field, s, &mut out, |q, f| {
            if let Some(c) = contacts {
                c.add_forces(q, graph.dim, f);
            }
        });
        out
    }

    /// Contact energy Σ ½ k_c (R − r)² at the current state (0 without contacts).
    pub fn contact_energy(&mut self) -> f64 {
        match self.contacts.as_mut() {
            Some(c) => c.energy(&self.state.q, self.graph.dim),
            None => 0.0,
        }
    }

    /// Steps whose SHAKE iteration did not reach [`Integrator::TOL`] within
    /// [`Integrator::MAX_ITER`] iterations, or whose constraint matrix could
    /// not be solved (degenerate bars). 0 for a healthy run.
    pub fn shake_failures(&self) -> u64 {
        self.projector.failures()
    }
}

/// acc = M⁻¹ F(q, v): the applied and contact forces over the masses (bars
/// are the projector's job), zero for kinematic particles.
fn true_acceleration(
    graph: &Graph,
    field: &Field,
    contacts: Option<&mut Contacts>,
    q: &[f64],
    v: &[f64],
    acc: &mut [f64],
) {
    let d = graph.dim;
    applied_forces(graph, field, q, v, acc);
    if let Some(c) = contacts {
        c.add_forces(q, d, acc);
    }
    for (i, m) in graph.masses.iter().enumerate() {
        let held = graph.is_kinematic(i);
        for c in 0..d {
            acc[i * d + c] = if held { 0.0 } else { acc[i * d + c] / m };
        }
    }
}

/// Without a drive kinematic particles are held still, so they must start at
/// rest.
fn check_at_rest(graph: &Graph, start: &State) -> Result<(), PhysicsError> {
    let d = graph.dim;
    if let Some(i) = (0..graph.n())
        .find(|&i| graph.is_kinematic(i) && start.v[i * d..(i + 1) * d].iter().any(|x| *x != 0.0))
    {
        return Err(PhysicsError::KinematicMoving(i));
    }
    Ok(())
}

/// No bar may end at a kinematic particle (SHAKE would move it).
fn check_bars(graph: &Graph) -> Result<(), PhysicsError> {
    let touches = |e: &&crate::system::Edge| {
        graph.is_kinematic(e.a)
            || matches!(e.b, crate::system::Endpoint::Particle(b) if graph.is_kinematic(b))
    };
    if let Some(e) = graph.bars().find(touches) {
        return Err(PhysicsError::KinematicBar(e.a));
    }
    Ok(())
}
