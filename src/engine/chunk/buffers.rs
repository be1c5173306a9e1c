//! The chunk's buffers: sized for a number of states and edges
//! ([`Chunk::reserve`]), the directed edges laid out over them
//! ([`Chunk::lay_out`]), and the contact pairs those edges include.

use super::{Chunk, Model};
use crate::engine::gather::IndexSums;
use crate::gnode::plan::GraphPlan;
use crate::physics::neighbors::NeighborSearch;

/// The contact pairs of a chunk's states: state `s`'s are
/// `pairs[starts[s]..starts[s + 1]]`.
#[derive(Clone, Debug, Default)]
pub(super) struct Contacts {
    search: Option<NeighborSearch>,
    pairs: Vec<(usize, usize)>,
    starts: Vec<usize>,
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

impl Chunk {
    /// Makes room for `bs` states with `edges` directed edges in all
    /// (allocates only when growing; contact counts grow with headroom, so a
    /// rollout whose contacts vary a little stops allocating).
    #[allow(clippy::too_many_lines)] // one line per buffer, sized in one place
    pub(super) fn reserve(&mut self, m: &Model, bs: usize, edges: usize, record: bool) {
        if bs <= self.cap && edges <= self.edge_cap && record == self.record {
            return;
        }
        let edges = if m.plan.has_contacts() {
            edges.max(self.edge_cap) + edges / 4 + 16
        } else {
            edges
        };
        let a = &m.arch;
        // NODE's `embed` and `types` size no weight: they must size no
        // buffer either (a corrupt file's 2^32 would be an abort).
        let (em, types) = if a.biases.graph {
            (a.embed, a.types)
        } else {
            (0, 0)
        };
        let (n, d) = (m.plan.n, m.plan.dim);
        let nodes = bs * n;
        let rmax = nodes.max(edges).max(bs).max(types * types).max(1);
        let width = m.mlps.iter().map(|(_, x)| x.width()).max().unwrap_or(1);
        let z = |len: usize| vec![0.0; len];
        // Buffers only the reverse pass reads: none for inference.
        let g = |len: usize| if record { vec![0.0; len] } else { vec![] };
        let outs = if a.biases.graph {
            d * nodes
        } else {
            d * n * bs
        };
        let contacts = std::mem::take(&mut self.contacts);
        let split = std::mem::take(&mut self.split);
        let scratch = std::mem::take(&mut self.scratch);
        *self = Chunk {
            split,
            scratch,
            cap: bs,
            record,
            laid: 0,
            edges: 0,
            edge_cap: edges,
            contacts,
            recv: vec![0; edges],
            send: vec![0; edges],
            x: z(if a.biases.graph {
                a.node_features() * nodes
            } else {
                2 * n * d * bs
            }),
            xn: z(if a.biases.graph {
                a.node_features() * nodes
            } else {
                0
            }),
            w_in: z(a.edge_features() * edges),
            h: (0..=a.rounds).map(|_| z(em * nodes)).collect(),
            he: (0..=a.rounds).map(|_| z(em * edges)).collect(),
            hs: (0..a.rounds).map(|_| z(em * edges)).collect(),
            hr: (0..a.rounds).map(|_| z(em * edges)).collect(),
            hp: (0..a.rounds).map(|_| z(em * edges)).collect(),
            gp: z(em * edges),
            msg: z(em * edges),
            agg: z(em * nodes),
            glob: z(em * nodes),
            f_edge: z(d * edges),
            f_body: z(d * nodes),
            out: z(outs),
            geq: z(outs),
            acc: z(outs),
            tgt: z(outs),
            tapes: m
                .mlps
                .iter()
                .map(|(_, x)| {
                    if record {
                        x.tape(rmax)
                    } else {
                        x.inference_tape()
                    }
                })
                .collect(),
            dq: z(bs * m.plan.bars.len() * d),
            kmat: z(bs * m.plan.bars.len().pow(2)),
            lam: z(bs * m.plan.bars.len()),
            piv: vec![0; bs * m.plan.bars.len()],
            rhs: z(m.plan.bars.len()),
            solved: vec![false; bs],
            gacc: g(outs),
            gout: g(outs),
            gh: g(em * nodes),
            gh_prev: g(em * nodes),
            ghe: g(em * edges),
            ghe_prev: g(em * edges),
            gs: g(em * edges),
            gr: g(em * edges),
            gz: g(em * rmax),
            gmsg: g(em * edges),
            gglob: g(em * nodes),
            gf_edge: g(d * edges),
            gminv: g(nodes),
            inputs: false,
            gxn: g(if a.biases.graph {
                a.node_features() * nodes
            } else {
                2 * n * d * bs
            }),
            gw: g(a.edge_features() * edges),
            gqv: g(2 * d * nodes),
            gdq: g(bs * m.plan.bars.len() * d),
            inv_m: z(types),
            g_mass: Vec::with_capacity(types),
            eye: (0..types * types)
                .map(|k| if k / types == k % types { 1.0 } else { 0.0 })
                .collect(),
            type_embed: z(em * types),
            node_ty: (0..if a.biases.graph { nodes } else { 0 })
                .map(|r| m.plan.types[r % n])
                .collect(),
            // (`em`, `types`: 0 for NODE.)
            pair: if m.by_type { vec![0; edges] } else { vec![] },
            pair_in: z(3 * em * types * types),
            pair_out: z(em * types * types),
            g_pair_out: g(em * types * types),
            g_pair_in: g(3 * em * types * types),
            sums: IndexSums::default(),
            g_type: g(em * types),
            by_type_done: false,
            same_params: false,
            s1: g(width * rmax),
            s2: g(width * rmax),
            grad: g(m.layout.len()),
            sse: 0.0,
        };
    }

    /// Directed edges of `bs` states of the graph, in the plan's order
    /// ([`GraphPlan::directed_edges`]): first every state's edges one way
    /// (fixed, then its contacts), then all reversed, so edge `e` and
    /// `e + half` are the two directions of one bar, spring or contact. The
    /// constant edge inputs after q_i − q_j
    /// ([`crate::gnode::arch::EdgeConst`]) are written with them. Without contacts the layout
    /// depends on `bs` alone and is kept.
    pub(super) fn lay_out(&mut self, m: &Model, bs: usize) {
        let contacts = m.plan.has_contacts();
        // Remembers this layout's pairs either way; `laid` is 0 after the
        // buffers were made anew.
        let same_pairs = contacts && self.contacts.laid_again();
        if self.laid == bs && (!contacts || same_pairs) {
            return;
        }
        let a = &m.arch;
        let edges = if contacts {
            2 * (bs * m.plan.n_edges() + self.contacts.pairs.len())
        } else {
            bs * m.plan.recv.len()
        };
        let (recv, send, w_in) = (&mut self.recv, &mut self.send, &mut self.w_in);
        let (pair, node_ty, t) = (&mut self.pair, &self.node_ty, a.types);
        let (pairs, starts) = if contacts {
            (&self.contacts.pairs[..], &self.contacts.starts[..])
        } else {
            (&[][..], &[][..])
        };
        let mut x = [0.0; crate::gnode::arch::EdgeConst::MAX_WIDTH];
        m.plan.directed_edges(bs, pairs, starts, |k, e| {
            recv[k] = e.recv;
            send[k] = e.send;
            if let Some(p) = pair.get_mut(k) {
                *p = node_ty[e.recv] * t + node_ty[e.send];
            }
            let mut f = a.dim;
            for c in a.edge_consts() {
                let x = &mut x[..c.width()];
                c.values(a, &m.plan, e.fixed, x);
                for v in x.iter() {
                    w_in[f * edges + k] = *v;
                    f += 1;
                }
            }
        });
        self.edges = edges;
        self.laid = bs;
    }
}
