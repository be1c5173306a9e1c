//! The velocity-Verlet step, written once: the ground truth, every learned
//! model's rollout and the lockstep batch all compose these two halves.
//!
//! q ← q + q̇ dt + ½ q̈ dt², q̇ ← q̇ + ½ q̈ dt (the drift); then the new
//! acceleration, evaluated at the half-step velocity (which keeps the scheme
//! explicit for velocity-dependent forces); then q̇ ← q̇ + ½ q̈ dt (the kick).
//! With a [`Projector`], SHAKE projects the drift and RATTLE the kick onto the bars.

use super::Projector;
use crate::system::Graph;

/// Wraps positions into `graph`'s periodic box (nothing without one): every
/// rollout calls it after the drift.
#[inline]
pub fn wrap(graph: &Graph, q: &mut [f64]) {
    if let Some(b) = graph.periodic() {
        b.wrap(q);
    }
}

/// First half: positions to the new step, velocities half way.
#[inline]
pub fn drift(q: &mut [f64], v: &mut [f64], a: &[f64], dt: f64) {
    for ((q, v), a) in q.iter_mut().zip(v.iter_mut()).zip(a) {
        *q += *v * dt + 0.5 * a * dt * dt;
        *v += 0.5 * a * dt;
    }
}

/// Second half: velocities the rest of the way with the new acceleration.
#[inline]
pub fn kick(v: &mut [f64], a: &[f64], dt: f64) {
    for (v, a) in v.iter_mut().zip(a) {
        *v += 0.5 * a * dt;
    }
}

/// One whole step: `a` holds q̈ at the current state on entry and at the new
/// one on return; `accel(q, v, a)` evaluates it (at the half-step velocity).
pub fn step<E>(
    q: &mut [f64],
    v: &mut [f64],
    a: &mut [f64],
    dt: f64,
    projector: Option<&mut Projector>,
    accel: impl FnOnce(&[f64], &[f64], &mut [f64]) -> Result<(), E>,
) -> Result<(), E> {
    step_placed(q, v, a, dt, projector, |_, _| {}, accel)
}

/// [`step`] with `place(q, v)` between the drift and the evaluation: it puts
/// driven (kinematic) particles where their given motion has them at the new
/// step ([`super::drive::Drive::place`]), so the forces are those of that
/// configuration. Driven particles have zero q̈, so the kick leaves the
/// velocity placed.
pub fn step_placed<E>(
    q: &mut [f64],
    v: &mut [f64],
    a: &mut [f64],
    dt: f64,
    mut projector: Option<&mut Projector>,
    place: impl FnOnce(&mut [f64], &mut [f64]),
    accel: impl FnOnce(&[f64], &[f64], &mut [f64]) -> Result<(), E>,
) -> Result<(), E> {
    if let Some(p) = projector.as_deref_mut() {
        p.begin(q);
    }
    drift(q, v, a, dt);
    if let Some(p) = projector.as_deref_mut() {
        p.shake(q, v, dt);
    }
    place(q, v);
    accel(q, v, a)?;
    kick(v, a, dt);
    if let Some(p) = projector {
        p.rattle(q, v);
    }
    Ok(())
}
