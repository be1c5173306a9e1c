//! A rollout and the forces at its start, in flat buffers a caller keeps
//! from one call to the next: what the node fills for every incoming state.
//! Refilling them for a graph of the same size allocates nothing.

use super::{EdgeForce, Forces};
use crate::system::State;

/// The states a rollout kept, one after another (`n·d` coordinates each).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KeptStates {
    width: usize,
    q: Vec<f64>,
    v: Vec<f64>,
}

impl KeptStates {
    /// Forgets the states, keeping the memory, for states of `width` (`n·d`)
    /// coordinates.
    pub fn clear(&mut self, width: usize) {
        self.width = width;
        self.q.clear();
        self.v.clear();
    }

    /// Appends a state; `q` and `v` must be `width` long.
    pub fn push(&mut self, q: &[f64], v: &[f64]) {
        debug_assert!(q.len() == self.width && v.len() == self.width);
        self.q.extend_from_slice(q);
        self.v.extend_from_slice(v);
    }

    /// How many states are kept.
    pub fn len(&self) -> usize {
        self.q.len().checked_div(self.width).unwrap_or(0)
    }

    /// Whether no state is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Positions of state `k`.
    pub fn q(&self, k: usize) -> &[f64] {
        &self.q[k * self.width..(k + 1) * self.width]
    }

    /// Velocities of state `k`.
    pub fn v(&self, k: usize) -> &[f64] {
        &self.v[k * self.width..(k + 1) * self.width]
    }

    /// Positions of states `k` onwards, one after another.
    pub fn q_from(&self, k: usize) -> &[f64] {
        &self.q[(k * self.width).min(self.q.len())..]
    }

    /// Velocities of states `k` onwards, one after another.
    pub fn v_from(&self, k: usize) -> &[f64] {
        &self.v[(k * self.width).min(self.v.len())..]
    }

    /// State `k`, copied out.
    pub fn state(&self, k: usize) -> State {
        State {
            q: self.q(k).to_vec(),
            v: self.v(k).to_vec(),
        }
    }

    /// The kept states, copied out.
    pub fn to_states(&self) -> Vec<State> {
        (0..self.len()).map(|k| self.state(k)).collect()
    }

    /// Replaces the content with `states` of `width` coordinates.
    pub fn fill(&mut self, width: usize, states: &[State]) {
        self.clear(width);
        for s in states {
            self.push(&s.q, &s.v);
        }
    }
}

/// [`Forces`] in flat buffers: totals, then each pairwise force's particles
/// and vector.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FlatForces {
    /// Total force per particle, `n·d`.
    pub total: Vec<f64>,
    /// `(a, b)` of each pairwise force f_ab (on `a` due to `b`).
    pub pairs: Vec<(usize, usize)>,
    /// The pairwise forces, `d` numbers each, in the order of `pairs`.
    pub pair_force: Vec<f64>,
}

impl FlatForces {
    /// Forgets the forces, keeping the memory.
    pub fn clear(&mut self) {
        self.total.clear();
        self.pairs.clear();
        self.pair_force.clear();
    }

    /// Replaces the content with `f`.
    pub fn fill(&mut self, f: &Forces) {
        self.clear();
        self.total.extend_from_slice(&f.total);
        for e in &f.edges {
            self.pairs.push((e.a, e.b));
            self.pair_force.extend_from_slice(&e.force);
        }
    }

    /// The forces as [`Forces`], pairwise vectors of `dim` numbers.
    pub fn to_forces(&self, dim: usize) -> Forces {
        Forces {
            total: self.total.clone(),
            edges: self
                .pairs
                .iter()
                .zip(self.pair_force.chunks(dim.max(1)))
                .map(|(&(a, b), f)| EdgeForce {
                    a,
                    b,
                    force: f.to_vec(),
                })
                .collect(),
        }
    }
}

/// What [`super::Dynamics::predict_into`] fills: the kept states of a rollout
/// (the start first) and the forces at its start.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Predicted {
    /// The start and every kept state after it.
    pub states: KeptStates,
    /// Forces at the start.
    pub forces: FlatForces,
    /// An ensemble's spread ([`super::Spread`]) flat, `n` numbers per kept
    /// state in the order of `states`; empty for a single model.
    pub spread: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_and_forces_round_trip() {
        let states = vec![
            State {
                q: vec![1.0, 2.0],
                v: vec![3.0, 4.0],
            },
            State {
                q: vec![5.0, 6.0],
                v: vec![7.0, 8.0],
            },
        ];
        let mut p = Predicted::default();
        p.states.fill(2, &states);
        assert_eq!(p.states.len(), 2);
        assert_eq!(p.states.v(1), &[7.0, 8.0]);
        assert_eq!(p.states.to_states(), states);
        let f = Forces {
            total: vec![1.0, -1.0],
            edges: vec![EdgeForce {
                a: 0,
                b: 1,
                force: vec![1.0, 0.5],
            }],
        };
        p.forces.fill(&f);
        assert_eq!(p.forces.to_forces(2), f);
        // Refilled with less, nothing of the first content is left.
        p.states.fill(2, &states[..1]);
        assert_eq!(p.states.to_states(), states[..1]);
        p.forces.clear();
        assert_eq!(p.forces.to_forces(2), Forces::default());
    }
}
