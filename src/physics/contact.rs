//! The ground truth's contact law: two particles closer than the interaction
//! radius R repel through the harmonic soft-sphere potential
//! V(r) = ½ k_c (R − r)² (r < R; 0 beyond), the force on i being
//! k_c (R − r) (q_i − q_j)/r and its opposite on j, so momentum is exact.
//!
//! V and its force are continuous at r = R (the force's derivative is not),
//! so a pair entering or leaving contact does not kick the energy.
//! The pairs are the contact pairs of [`super::neighbors`], rebuilt at every
//! evaluation; bonded pairs keep their bond and get no contact force, and two
//! kinematic particles none either (neither moves, so it would do nothing).

use super::neighbors::NeighborSearch;
use crate::system::Graph;

/// The soft-sphere law: its radius and stiffness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactLaw {
    /// Interaction radius R (a pair interacts when r < R).
    pub radius: f64,
    /// Contact stiffness k_c.
    pub stiffness: f64,
}

impl ContactLaw {
    /// V(r) = ½ k_c (R − r)² inside the radius, 0 outside.
    pub fn potential(&self, r: f64) -> f64 {
        if r < self.radius {
            0.5 * self.stiffness * (self.radius - r).powi(2)
        } else {
            0.0
        }
    }

    /// −V'(r) = k_c (R − r) inside the radius (repulsive, ≥ 0), 0 outside.
    pub fn repulsion(&self, r: f64) -> f64 {
        if r < self.radius {
            self.stiffness * (self.radius - r)
        } else {
            0.0
        }
    }
}

/// Contact forces and energy of one graph, with the search buffers they reuse
/// (no allocation per evaluation once warm).
#[derive(Clone, Debug)]
pub struct Contacts {
    law: ContactLaw,
    search: NeighborSearch,
}

impl Contacts {
    /// Contacts of `graph` at its interaction radius with stiffness `k_c`.
    pub fn new(graph: &Graph, stiffness: f64) -> Self {
        Contacts {
            law: ContactLaw {
                radius: graph.interaction_radius,
                stiffness,
            },
            search: NeighborSearch::new(graph),
        }
    }

    /// The law.
    pub fn law(&self) -> ContactLaw {
        self.law
    }

    /// Adds the contact forces at `q` to `out` (both `n * dim`). Coincident
    /// particles have no direction and exert none on each other.
    pub fn add_forces(&mut self, q: &[f64], dim: usize, out: &mut [f64]) {
        let law = self.law;
        self.search.search(q, dim, law.radius);
        for k in 0..self.search.pairs().len() {
            let (i, j) = self.search.pairs()[k];
            let mut diff = [0.0; 3];
            self.search.delta(q, dim, (i, j), &mut diff);
            let r = diff[..dim].iter().map(|x| x * x).sum::<f64>().sqrt();
            if r == 0.0 {
                continue;
            }
            let s = law.repulsion(r) / r;
            for c in 0..dim {
                out[i * dim + c] += s * diff[c];
                out[j * dim + c] -= s * diff[c];
            }
        }
    }

    /// Total contact energy Σ V(r_ij) at `q`.
    pub fn energy(&mut self, q: &[f64], dim: usize) -> f64 {
        let law = self.law;
        self.search.search(q, dim, law.radius);
        let mut diff = [0.0; 3];
        let mut u = 0.0;
        for &(i, j) in self.search.pairs() {
            self.search.delta(q, dim, (i, j), &mut diff);
            u += law.potential(diff[..dim].iter().map(|x| x * x).sum::<f64>().sqrt());
        }
        u
    }

    /// The contact pairs of the last evaluation.
    pub fn pairs(&self) -> &[(usize, usize)] {
        self.search.pairs()
    }
}

/// The contact energy of `graph` at `q` with stiffness `k_c` (a one-off
/// evaluation; [`Contacts`] reuses its buffers).
pub fn contact_energy(graph: &Graph, stiffness: f64, q: &[f64]) -> f64 {
    Contacts::new(graph, stiffness).energy(q, graph.dim)
}
