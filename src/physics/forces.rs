//! Applied (non-constraint) forces and the energy they derive from.
//!
//! Springs, gravity along −y (coordinate 1), linear drag −c·q̇ and a constant
//! force per particle. Constraint (bar) forces live in [`super::constraints`].

use super::Field;
use crate::system::{EdgeKind, Endpoint, Graph, State};

/// Position of an edge's far end: a particle's coordinates or an anchor.
pub(crate) fn end_pos<'a>(graph: &'a Graph, q: &'a [f64], b: Endpoint) -> &'a [f64] {
    let d = graph.dim;
    match b {
        Endpoint::Particle(j) => &q[j * d..(j + 1) * d],
        Endpoint::Anchor(j) => &graph.anchors[j],
    }
}

/// The external force component `c` (an empty force vector means zero).
fn ext(field: &Field, c: usize) -> f64 {
    field.force.get(c).copied().unwrap_or(0.0)
}

/// Writes the total applied force at (q, v) to `out` (`n * dim`), without
/// allocating. Bars contribute nothing here.
///
/// A spring whose ends coincide has no direction; it then exerts no force.
pub fn applied_forces(graph: &Graph, field: &Field, q: &[f64], v: &[f64], out: &mut [f64]) {
    let d = graph.dim;
    for (i, m) in graph.masses.iter().enumerate() {
        for c in 0..d {
            let k = i * d + c;
            out[k] = -field.drag * v[k] + ext(field, c);
        }
        if d >= 2 {
            out[i * d + 1] -= m * field.gravity;
        }
    }
    for e in graph.edges.iter().filter(|e| e.kind == EdgeKind::Spring) {
        let a = e.a;
        let mut diff = [0.0; 3];
        let pb = end_pos(graph, q, e.b);
        for c in 0..d {
            diff[c] = q[a * d + c] - pb[c];
        }
        if let Some(b) = graph.periodic() {
            b.min_image(&mut diff[..d]);
        }
        let r = diff[..d].iter().map(|x| x * x).sum::<f64>().sqrt();
        if r == 0.0 {
            continue;
        }
        // Force on a: −k (r − r0) (q_a − q_b)/r; the opposite on b.
        let s = -e.stiffness * (r - e.rest_length) / r;
        for c in 0..d {
            out[a * d + c] += s * diff[c];
        }
        if let Endpoint::Particle(b) = e.b {
            for c in 0..d {
                out[b * d + c] -= s * diff[c];
            }
        }
    }
}

/// Potential energy: springs ½k(r − r0)², gravity m g y, and −F·q for the
/// constant force (drag has no potential).
pub fn potential_energy(graph: &Graph, field: &Field, q: &[f64]) -> f64 {
    let d = graph.dim;
    let mut u = 0.0;
    for e in graph.edges.iter().filter(|e| e.kind == EdgeKind::Spring) {
        let pb = end_pos(graph, q, e.b);
        let mut diff = [0.0; 3];
        for c in 0..d {
            diff[c] = q[e.a * d + c] - pb[c];
        }
        if let Some(b) = graph.periodic() {
            b.min_image(&mut diff[..d]);
        }
        let r = diff[..d].iter().map(|x| x * x).sum::<f64>().sqrt();
        u += 0.5 * e.stiffness * (r - e.rest_length).powi(2);
    }
    for (i, m) in graph.masses.iter().enumerate() {
        if d >= 2 {
            u += m * field.gravity * q[i * d + 1];
        }
        for c in 0..d {
            u -= ext(field, c) * q[i * d + c];
        }
    }
    u
}

/// Kinetic energy ½ Σ m |v|².
pub fn kinetic_energy(graph: &Graph, state: &State) -> f64 {
    let d = graph.dim;
    graph
        .masses
        .iter()
        .enumerate()
        .map(|(i, m)| {
            0.5 * m
                * state.v[i * d..(i + 1) * d]
                    .iter()
                    .map(|x| x * x)
                    .sum::<f64>()
        })
        .sum()
}

/// Total energy: kinetic + spring + m g y − F·q (drag has no potential).
///
/// The state must match the graph (see [`State::validate`]).
pub fn hamiltonian(graph: &Graph, field: &Field, state: &State) -> f64 {
    kinetic_energy(graph, state) + potential_energy(graph, field, &state.q)
}
