//! The contact pairs of a chunk's states, found afresh at each run (from a
//! Verlet list in a rollout), and whether the edges laid out last still
//! fit them.

use crate::gnode::graph_plan::GraphPlan;
use crate::physics::neighbors::NeighborSearch;

/// The contact pairs of a chunk's states: state `s`'s are
/// `pairs[starts[s]..starts[s + 1]]`.
#[derive(Clone, Debug, Default)]
pub(super) struct Contacts {
    search: Option<NeighborSearch>,
    pub(super) pairs: Vec<(usize, usize)>,
    pub(super) starts: Vec<usize>,
    /// The pairs and starts the edge arrays were last laid out for: a
    /// rollout step whose contacts are those of the step before (a resting
    /// pile, a held object) reuses the layout.
    laid_pairs: Vec<(usize, usize)>,
    laid_starts: Vec<usize>,
}

impl Contacts {
    /// Whether the pairs found are those last laid out; if not, remembers
    /// them as laid out now.
    pub(super) fn laid_again(&mut self) -> bool {
        if self.pairs == self.laid_pairs && self.starts == self.laid_starts {
            return true;
        }
        self.laid_pairs.clone_from(&self.pairs);
        self.laid_starts.clone_from(&self.starts);
        false
    }
}

impl Contacts {
    /// Finds the contacts of each state `positions` yields; returns the
    /// number of directed edges of those states, fixed and contact.
    pub(super) fn find<'a>(
        &mut self,
        plan: &GraphPlan,
        positions: impl Iterator<Item = &'a [f64]>,
    ) -> usize {
        self.pairs.clear();
        self.starts.clear();
        self.starts.push(0);
        let search = self.search.get_or_insert_with(|| plan.contact_search());
        for q in positions {
            plan.contacts(search, q, &mut self.pairs);
            self.starts.push(self.pairs.len());
        }
        2 * ((self.starts.len() - 1) * plan.n_edges() + self.pairs.len())
    }

    /// [`Contacts::find`] for one state of a rollout (consecutive calls see
    /// nearby positions): the same pairs, from a Verlet list.
    pub(super) fn find_moving(&mut self, plan: &GraphPlan, q: &[f64]) -> usize {
        self.pairs.clear();
        self.starts.clear();
        self.starts.push(0);
        let search = self.search.get_or_insert_with(|| plan.contact_search());
        plan.contacts_moving(search, q, &mut self.pairs);
        self.starts.push(self.pairs.len());
        2 * (plan.n_edges() + self.pairs.len())
    }
}
