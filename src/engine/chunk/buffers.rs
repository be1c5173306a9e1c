//! The chunk's buffers: sized for a number of states and edges
//! ([`Chunk::reserve`]), the directed edges laid out over them
//! ([`Chunk::lay_out`]), fixed and contact.

use super::{Chunk, Model};

impl Chunk {
    /// Makes room for `bs` states with `edges` directed edges in all
    /// (allocates only when growing; contact counts grow with headroom, so a
    /// rollout whose contacts vary a little stops allocating).
    pub(super) fn reserve(&mut self, m: &Model, bs: usize, edges: usize, record: bool) {
        if bs <= self.cap && edges <= self.edge_cap && record == self.record {
            return;
        }
        let edges = if m.plan.has_contacts() {
            edges.max(self.edge_cap) + edges / 4 + 16
        } else {
            edges
        };
        let z = Sizes::new(m, bs, edges);
        *self = Chunk {
            split: std::mem::take(&mut self.split),
            scratch: std::mem::take(&mut self.scratch),
            contacts: std::mem::take(&mut self.contacts),
            cap: bs,
            record,
            edge_cap: edges,
            ..Chunk::default()
        };
        self.make_forward(m, &z);
        self.make_constraint(m, &z);
        if record {
            self.make_reverse(m, &z);
        }
    }

    /// The forward pass's buffers: inputs, states, messages and outputs, and
    /// the MLPs' tapes (with activations only when recording).
    fn make_forward(&mut self, m: &Model, z: &Sizes) {
        let a = &m.arch;
        let (em, nodes, edges) = (z.em, z.nodes, z.edges);
        let zero = |len: usize| vec![0.0; len];
        self.recv = vec![0; edges];
        self.send = vec![0; edges];
        self.x = zero(if a.biases.graph {
            a.node_features() * nodes
        } else {
            2 * z.n * z.d * z.bs
        });
        self.xn = zero(if a.biases.graph {
            a.node_features() * nodes
        } else {
            0
        });
        self.w_in = zero(a.edge_features() * edges);
        self.h = (0..=a.rounds).map(|_| zero(em * nodes)).collect();
        self.he = (0..=a.rounds).map(|_| zero(em * edges)).collect();
        self.hs = (0..a.rounds).map(|_| zero(em * edges)).collect();
        self.hr = (0..a.rounds).map(|_| zero(em * edges)).collect();
        self.hp = (0..a.rounds).map(|_| zero(em * edges)).collect();
        self.gp = zero(em * edges);
        self.msg = zero(em * edges);
        self.agg = zero(em * nodes);
        self.glob = zero(em * nodes);
        self.f_edge = zero(z.d * edges);
        self.f_body = zero(z.d * nodes);
        self.out = zero(z.outs);
        self.geq = zero(z.outs);
        self.acc = zero(z.outs);
        self.tgt = zero(z.outs);
        let record = self.record;
        self.tapes = (m.mlps.iter())
            .map(|(_, x)| {
                if record {
                    x.tape(z.rmax)
                } else {
                    x.inference_tape()
                }
            })
            .collect();
    }

    /// The constraint's buffers and the by-type ones (one-hot rows, type
    /// embeddings, type pairs).
    fn make_constraint(&mut self, m: &Model, z: &Sizes) {
        let (em, types, bars) = (z.em, z.types, m.plan.bars.len());
        let zero = |len: usize| vec![0.0; len];
        self.dq = zero(z.bs * bars * z.d);
        self.kmat = zero(z.bs * bars.pow(2));
        self.lam = zero(z.bs * bars);
        self.piv = vec![0; z.bs * bars];
        self.rhs = zero(bars);
        self.solved = vec![false; z.bs];
        self.inv_m = zero(types);
        self.g_mass = Vec::with_capacity(types);
        self.eye = (0..types * types)
            .map(|k| if k / types == k % types { 1.0 } else { 0.0 })
            .collect();
        self.type_embed = zero(em * types);
        self.node_ty = (0..if m.arch.biases.graph { z.nodes } else { 0 })
            .map(|r| m.plan.types[r % z.n])
            .collect();
        // (`em`, `types`: 0 for NODE.)
        self.pair = if m.by_type { vec![0; z.edges] } else { vec![] };
        self.pair_in = zero(3 * em * types * types);
        self.pair_out = zero(em * types * types);
    }

    /// The buffers only the reverse pass reads (none for inference).
    fn make_reverse(&mut self, m: &Model, z: &Sizes) {
        let a = &m.arch;
        let (em, nodes, edges, types) = (z.em, z.nodes, z.edges, z.types);
        let zero = |len: usize| vec![0.0; len];
        self.gacc = zero(z.outs);
        self.gout = zero(z.outs);
        self.gh = zero(em * nodes);
        self.gh_prev = zero(em * nodes);
        self.ghe = zero(em * edges);
        self.ghe_prev = zero(em * edges);
        self.gs = zero(em * edges);
        self.gr = zero(em * edges);
        self.gz = zero(em * z.rmax);
        self.gmsg = zero(em * edges);
        self.gglob = zero(em * nodes);
        self.gf_edge = zero(z.d * edges);
        self.gminv = zero(nodes);
        self.gxn = zero(if a.biases.graph {
            a.node_features() * nodes
        } else {
            2 * z.n * z.d * z.bs
        });
        self.gw = zero(a.edge_features() * edges);
        self.gqv = zero(2 * z.d * nodes);
        self.gdq = zero(z.bs * m.plan.bars.len() * z.d);
        self.g_pair_out = zero(em * types * types);
        self.g_pair_in = zero(3 * em * types * types);
        self.g_type = zero(em * types);
        self.s1 = zero(z.width * z.rmax);
        self.s2 = zero(z.width * z.rmax);
        self.grad = zero(m.layout.len());
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

/// What [`Chunk::reserve`] sizes the buffers by.
struct Sizes {
    bs: usize,
    edges: usize,
    /// Embedding width and particle types: 0 for NODE, whose `embed` and
    /// `types` size no weight and so must size no buffer either (a corrupt
    /// file's 2^32 would be an abort).
    em: usize,
    types: usize,
    n: usize,
    d: usize,
    nodes: usize,
    /// The most rows an MLP runs over (its tape's and scratch's length).
    rmax: usize,
    /// The widest MLP layer.
    width: usize,
    /// The decoder's output, `d × rows`.
    outs: usize,
}

impl Sizes {
    fn new(m: &Model, bs: usize, edges: usize) -> Self {
        let a = &m.arch;
        let (em, types) = if a.biases.graph {
            (a.embed, a.types)
        } else {
            (0, 0)
        };
        let (n, d) = (m.plan.n, m.plan.dim);
        let nodes = bs * n;
        Self {
            bs,
            edges,
            em,
            types,
            n,
            d,
            nodes,
            rmax: nodes.max(edges).max(bs).max(types * types).max(1),
            width: m.mlps.iter().map(|(_, x)| x.width()).max().unwrap_or(1),
            outs: if a.biases.graph {
                d * nodes
            } else {
                d * n * bs
            },
        }
    }
}
