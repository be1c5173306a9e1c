//! A training set as the engine reads it: each state's positions,
//! velocities and target accelerations transposed to the chunk's
//! feature-major order, one contiguous record per state.
//!
//! A batch picks states at random; read from their own vectors, scattered
//! over the heap, each state cost a cache miss for its `State` and then one
//! for each vector it points to, one after the other (about a tenth of a
//! 5-spring epoch). A record's address follows from its index, so a chunk
//! asks for its states' lines ahead of reading them and copies rows.

use super::gather::prefetch;
use crate::system::State;

/// States whose records are asked for ahead of the one being read: all of
/// a chunk's at once queued behind one another in the CPU's miss buffers
/// (a 5-spring epoch on two threads 5.51–5.67 ms, against 5.31–5.39 ms eight
/// ahead; four and sixteen were no better).
const AHEAD: usize = 8;

/// States of one graph and (for training) their target accelerations,
/// node-major as given, and for graph models packed into records.
#[derive(Debug)]
pub struct Samples<'a> {
    states: &'a [State],
    targets: &'a [Vec<f64>],
    /// Per state: q, q̇ and (with targets) the target, each `d` rows of `n`.
    packed: Vec<f64>,
    n: usize,
    d: usize,
}

impl<'a> Samples<'a> {
    /// `states` of `n` particles in `d` dimensions with `targets` (one per
    /// state, or none), packed into records when `pack`.
    ///
    /// # Panics
    /// If a state or target does not have `n · d` numbers, or there are
    /// targets but not one per state (the caller validated them).
    pub(crate) fn new(
        n: usize,
        d: usize,
        pack: bool,
        states: &'a [State],
        targets: &'a [Vec<f64>],
    ) -> Self {
        let nd = n * d;
        assert!(
            targets.is_empty() || targets.len() == states.len(),
            "{} targets for {} states",
            targets.len(),
            states.len()
        );
        let mut packed = vec![];
        if pack {
            let with_targets = !targets.is_empty();
            packed.reserve(states.len() * nd * (2 + usize::from(with_targets)));
            for (k, s) in states.iter().enumerate() {
                let t = targets.get(k).map(Vec::as_slice);
                for x in [Some(&s.q[..]), Some(&s.v[..]), t].into_iter().flatten() {
                    assert_eq!(x.len(), nd, "a state of {n} particles in {d} dimensions");
                    for c in 0..d {
                        packed.extend(x.iter().skip(c).step_by(d));
                    }
                }
            }
        }
        Self {
            states,
            targets,
            packed,
            n,
            d,
        }
    }

    /// Whether these samples were laid out for a graph of `n` particles in
    /// `d` dimensions, packed or not as `pack` says.
    pub(crate) fn laid_out_for(&self, n: usize, d: usize, pack: bool) -> bool {
        let packed = !self.packed.is_empty();
        (self.n, self.d) == (n, d) && (packed == pack || self.states.is_empty())
    }

    /// The states as given.
    pub(crate) fn states(&self) -> &'a [State] {
        self.states
    }

    /// The targets as given (empty: none).
    pub(crate) fn targets(&self) -> &'a [Vec<f64>] {
        self.targets
    }

    /// Numbers in one record.
    fn stride(&self) -> usize {
        self.n * self.d * (2 + usize::from(!self.targets.is_empty()))
    }

    /// State `k`'s record, when packed: q, q̇ and the target (if any), each
    /// `d` feature rows of `n` particles.
    pub(crate) fn record(&self, k: usize) -> Option<&[f64]> {
        if self.packed.is_empty() {
            return None;
        }
        let w = self.stride();
        Some(&self.packed[k * w..(k + 1) * w])
    }

    /// The records of states `idx`, in order, each asked for [`AHEAD`]
    /// states before it is read.
    ///
    /// # Panics
    /// If the states are not packed.
    pub(crate) fn records<'s>(&'s self, idx: &'s [usize]) -> impl Iterator<Item = &'s [f64]> {
        self.ask_for(&idx[..AHEAD.min(idx.len())]);
        idx.iter().enumerate().map(move |(s, &k)| {
            if let Some(&next) = idx.get(s + AHEAD) {
                self.ask_for(&[next]);
            }
            self.record(k).expect("packed samples")
        })
    }

    /// Asks the CPU to bring states `idx` into cache ahead of their use.
    pub(crate) fn ask_for(&self, idx: &[usize]) {
        for &k in idx {
            if let Some(r) = self.record(k) {
                prefetch(r);
                continue;
            }
            prefetch(&self.states[k].q);
            prefetch(&self.states[k].v);
            if let Some(a) = self.targets.get(k) {
                prefetch(a);
            }
        }
    }

    /// How many states.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// Whether there are no states.
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record holds each state's vectors transposed: row `c` of q is
    /// coordinate `c` of every particle, then q̇'s rows, then the target's.
    #[test]
    fn records_are_the_states_transposed() {
        let (n, d) = (3, 2);
        let state = |k: f64| State {
            q: (0..n * d).map(|i| k * 100.0 + i as f64).collect(),
            v: (0..n * d).map(|i| -(k * 100.0 + i as f64)).collect(),
        };
        let states = vec![state(0.0), state(1.0)];
        let targets: Vec<Vec<f64>> = (0..2)
            .map(|k| (0..n * d).map(|i| 0.5 + f64::from(k) + i as f64).collect())
            .collect();
        let s = Samples::new(n, d, true, &states, &targets);
        for (k, st) in states.iter().enumerate() {
            let r = s.record(k).unwrap();
            assert_eq!(r.len(), 3 * n * d);
            for (f, x) in [&st.q, &st.v, &targets[k]].into_iter().enumerate() {
                for c in 0..d {
                    for i in 0..n {
                        assert_eq!(r[(f * d + c) * n + i], x[i * d + c], "{k} {f} {c} {i}");
                    }
                }
            }
        }
        let bare = Samples::new(n, d, true, &states, &[]);
        assert_eq!(bare.record(1).unwrap(), &s.record(1).unwrap()[..2 * n * d]);
        let flat = Samples::new(n, d, false, &states, &targets);
        assert!(flat.record(0).is_none());
        // Each engine takes only samples laid out for its own model.
        assert!(s.laid_out_for(n, d, true) && flat.laid_out_for(n, d, false));
        assert!(!s.laid_out_for(n, d, false) && !flat.laid_out_for(n, d, true));
        assert!(!s.laid_out_for(n + 1, d, true) && !s.laid_out_for(n, d + 1, true));
    }
}
