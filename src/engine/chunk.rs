//! One chunk of a batch: the forward pass of the GNODE family over several
//! states of one graph at once (the states side by side as one disjoint
//! graph, feature-major), the squared error against the targets, and the
//! hand-written reverse pass. Every buffer lives here and is reused.

use super::dense::{simd, squareplus_in_place, times_squareplus_grad, Mlp, Out, Simd, Tape};
use super::fused::{BodyBlocks, Branch, EdgeBlocks, EDGE_BLOCK, FUSED_EDGES};
use super::gather::{
    add_indexed, copy_row, edge_differences, gather_rows, scatter_add_rows, sum_by_index, Gather,
    IndexSums,
};
use super::layout::Layout;
use super::samples::Samples;
use super::split::{Scratch, Split};
use crate::gnode::arch::{Arch, Block, Decoder, NodeInput};
use crate::gnode::plan::{BarEnd, GraphPlan};
use crate::gnode::solve::{lu_factor_in_place, lu_solve_one};
use crate::gnode::variant::EdgeInput;
use crate::physics::neighbors::NeighborSearch;

/// The read-only part: architecture, parameter offsets, graph.
#[derive(Clone, Debug)]
pub(crate) struct Model {
    pub(crate) arch: Arch,
    pub(crate) layout: Layout,
    mlps: Vec<(Block, Mlp)>,
    log_mass: Option<usize>,
    pub(crate) plan: GraphPlan,
    /// Bars at each particle with their sign in A: (bar, ±1).
    incid: Vec<Vec<(usize, f64)>>,
    /// One-hot node inputs: node states before round 1 depend on the type
    /// alone, so the node embedding runs once per type and round 0's edge
    /// update once per ordered type pair (each edge reads its pair's row).
    by_type: bool,
    /// Whether any stage reads per-node states: not MCGNODE's one round
    /// by type, whose edge update reads type pairs and whose decoder edges.
    nodes_read: bool,
    /// Whether any MLP reads the scaled node inputs: the node embedding
    /// unless by type, and the body branch's.
    xn_read: bool,
    /// Whether inference may take the fused pass ([`super::fused`]):
    /// MCGNODE's one round by type, where nothing reads per-node states
    /// (which implies a pairwise decoder, hence an edge update).
    fusable: bool,
}

impl Model {
    pub(crate) fn new(arch: Arch, plan: GraphPlan) -> Self {
        let layout = Layout::new(&arch);
        let mlps = arch
            .mlps
            .iter()
            .map(|(b, _)| (*b, layout.mlp(&arch, *b).expect("block is in arch")))
            .collect();
        let mut incid = vec![vec![]; plan.n];
        for (r, bar) in plan.bars.iter().enumerate() {
            incid[bar.a].push((r, 1.0));
            if let BarEnd::Particle(b) = bar.b {
                incid[b].push((r, -1.0));
            }
        }
        let by_type = arch.biases.graph && matches!(arch.node_input, NodeInput::TypeOnly);
        let nodes_read = !by_type
            || arch.rounds > 1
            || (0..arch.rounds).any(|l| arch.updates_nodes(l))
            || matches!(arch.decoder, Decoder::Node { .. });
        let xn_read = !by_type || arch.mlps.iter().any(|(b, _)| *b == Block::GlobalEmbed);
        let fusable = !nodes_read && arch.rounds == 1;
        Self {
            log_mass: layout.log_mass(),
            by_type,
            nodes_read,
            xn_read,
            fusable,
            arch,
            layout,
            mlps,
            plan,
            incid,
        }
    }

    /// Index of a block's MLP (and tape).
    fn ix(&self, b: Block) -> Option<usize> {
        self.mlps.iter().position(|(x, _)| *x == b)
    }

    fn mlp(&self, i: usize) -> &Mlp {
        &self.mlps[i].1
    }

    /// (particles, dimension, graph model): what reading outputs needs.
    pub(crate) fn shape(&self) -> (usize, usize, bool) {
        (self.plan.n, self.plan.dim, self.arch.biases.graph)
    }

    /// Rows one state adds: NODE has one row per state, graph models one per
    /// particle and one per directed edge.
    pub(crate) fn rows_per_state(&self) -> usize {
        if self.arch.biases.graph {
            self.plan.n + self.plan.recv.len()
        } else {
            1
        }
    }
}

/// Buffers for up to `cap` states, and this chunk's results.
#[derive(Clone, Debug, Default)]
pub(crate) struct Chunk {
    cap: usize,
    /// Whether the buffers are a training run's (tapes and gradients) or
    /// inference's (neither).
    record: bool,
    /// States the edge index arrays are laid out for.
    laid: usize,
    /// Directed edges laid out (fixed and contact, over all `laid` states),
    /// and how many the buffers hold.
    edges: usize,
    edge_cap: usize,
    /// Contact pairs of the states being run, found afresh each run.
    contacts: Contacts,
    recv: Vec<usize>,
    send: Vec<usize>,
    /// Raw inputs (one-hot, q, q̇) for the constraint; NODE: scaled (q, q̇).
    x: Vec<f64>,
    /// Scaled node inputs (one-hot, (q − μ)/σ_q, q̇/σ_v) for the MLPs.
    xn: Vec<f64>,
    w_in: Vec<f64>,
    h: Vec<Vec<f64>>,
    he: Vec<Vec<f64>>,
    hs: Vec<Vec<f64>>,
    hr: Vec<Vec<f64>>,
    /// h_i ⊙ h_j per round (product edge updates).
    hp: Vec<Vec<f64>>,
    msg: Vec<f64>,
    agg: Vec<f64>,
    glob: Vec<f64>,
    f_edge: Vec<f64>,
    f_body: Vec<f64>,
    /// Decoder output: forces (constrained) or accelerations, `d × rows`.
    out: Vec<f64>,
    /// N − Aᵀλ, `d × rows` (constrained).
    geq: Vec<f64>,
    acc: Vec<f64>,
    tgt: Vec<f64>,
    tapes: Vec<Tape>,
    dq: Vec<f64>,
    /// Per state: K = A M⁻¹ Aᵀ, LU-factored in place by the forward pass,
    /// and its pivots.
    kmat: Vec<f64>,
    lam: Vec<f64>,
    piv: Vec<usize>,
    rhs: Vec<f64>,
    solved: Vec<bool>,
    gacc: Vec<f64>,
    gout: Vec<f64>,
    gh: Vec<f64>,
    gh_prev: Vec<f64>,
    ghe: Vec<f64>,
    ghe_prev: Vec<f64>,
    gs: Vec<f64>,
    gr: Vec<f64>,
    gp: Vec<f64>,
    gz: Vec<f64>,
    gmsg: Vec<f64>,
    gglob: Vec<f64>,
    gf_edge: Vec<f64>,
    gminv: Vec<f64>,
    /// Whether the reverse pass also computes ∂L/∂(q, q̇) of the inputs
    /// ([`Chunk::input_vjp`]; planning gradients), not only ∂L/∂θ.
    inputs: bool,
    /// ∂L/∂(scaled node inputs) (graph models) or ∂L/∂x (NODE), like `xn`/`x`.
    gxn: Vec<f64>,
    /// ∂L/∂(edge inputs), like `w_in`.
    gw: Vec<f64>,
    /// ∂L/∂(raw q, q̇) through the constraint, feature-major `2d × nodes`.
    gqv: Vec<f64>,
    /// ∂L/∂(q_a − q_b) of each bar, `bs × bars × d`.
    gdq: Vec<f64>,
    /// Inverse masses per particle type (constrained variants).
    inv_m: Vec<f64>,
    /// The log-mass gradients while they are summed (no-bar reverse pass).
    g_mass: Vec<f64>,
    /// The one-hot rows of every type, feature-major `types × types`, and
    /// their node embeddings `embed × types` (inference).
    eye: Vec<f64>,
    type_embed: Vec<f64>,
    /// Each row's particle type (`types[row % n]`, without the division).
    node_ty: Vec<usize>,
    /// Round 0's edge update by type pair ([`Model::by_type`]): its inputs
    /// and outputs (`types²` rows), each edge's pair (recv type · types +
    /// send type), and the reverse pass's ∂L/∂ of its outputs, its inputs
    /// and the type embeddings.
    pair: Vec<usize>,
    pair_in: Vec<f64>,
    pair_out: Vec<f64>,
    g_pair_out: Vec<f64>,
    g_pair_in: Vec<f64>,
    /// [`sum_by_index`]'s buffers.
    sums: IndexSums,
    g_type: Vec<f64>,
    /// Whether the type embeddings and pair outputs above hold an inference
    /// pass's values (cleared when the buffers are made), and whether the
    /// caller of [`Chunk::forward_one`] passed the parameters of the pass
    /// before: then they are still right (they read the parameters alone),
    /// and a rollout computes them once, not once a step.
    by_type_done: bool,
    same_params: bool,
    s1: Vec<f64>,
    s2: Vec<f64>,
    /// ∂(Σ squared errors · scale)/∂θ of the last [`Chunk::run`] with gradients.
    pub(crate) grad: Vec<f64>,
    /// Σ squared errors of the last run.
    pub(crate) sse: f64,
    /// The edge MLPs' rows over two cores (large graphs, inference only).
    pub(crate) split: Split,
    /// This thread's scratch for [`Split::blocks`].
    scratch: Scratch,
}

/// `fn $name(&mut self, args)` running `$any` (an `#[inline(always)]`
/// method) compiled for AVX-512F or AVX2 with FMA, whichever [`simd`]
/// chose, or as built: the same code, so the same bits, in the widest
/// vectors the CPU has.
macro_rules! widest {
    ($(#[$doc:meta])* fn $name:ident => $any:ident($($arg:ident: $ty:ty),* $(,)?)) => {
        $(#[$doc])*
        fn $name(&mut self, $($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx512f,fma")]
            unsafe fn avx512(c: &mut Chunk, $($arg: $ty),*) {
                c.$any($($arg),*);
            }
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            unsafe fn avx2(c: &mut Chunk, $($arg: $ty),*) {
                c.$any($($arg),*);
            }
            match simd() {
                // SAFETY: the CPU supports AVX-512F and FMA (`simd` checked).
                #[cfg(target_arch = "x86_64")]
                Simd::Avx512 => unsafe { avx512(self, $($arg),*) },
                // SAFETY: the CPU supports AVX2 and FMA (`simd` checked).
                #[cfg(target_arch = "x86_64")]
                Simd::Avx2 => unsafe { avx2(self, $($arg),*) },
                _ => self.$any($($arg),*),
            }
        }
    };
}

/// The contact pairs of a chunk's states: state `s`'s are
/// `pairs[starts[s]..starts[s + 1]]`.
#[derive(Clone, Debug, Default)]
struct Contacts {
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
    fn laid_again(&mut self) -> bool {
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
    fn find<'a>(&mut self, plan: &GraphPlan, positions: impl Iterator<Item = &'a [f64]>) -> usize {
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
    fn find_moving(&mut self, plan: &GraphPlan, q: &[f64]) -> usize {
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
    fn reserve(&mut self, m: &Model, bs: usize, edges: usize, record: bool) {
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
    fn lay_out(&mut self, m: &Model, bs: usize) {
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

    /// Forward pass and squared error over the states `idx`, then (when `scale`
    /// is given) the reverse pass of `scale · Σ squared errors` into `grad`.
    pub(crate) fn run(
        &mut self,
        m: &Model,
        th: &[f64],
        samples: &Samples,
        idx: &[usize],
        scale: Option<f64>,
    ) {
        let bs = idx.len();
        let edges = if m.plan.has_contacts() {
            let states = samples.states();
            let q = idx.iter().map(|&k| states[k].q.as_slice());
            self.contacts.find(&m.plan, q)
        } else {
            bs * m.plan.recv.len()
        };
        // Tapes only for a reverse pass: without one, the inference path
        // (the same bits; fused for MCGNODE).
        self.reserve(m, bs, edges, scale.is_some());
        self.lay_out(m, bs);
        if m.arch.biases.graph {
            self.fill_graph_inputs(m, samples, idx);
            self.forward_graph(m, th);
        } else {
            self.fill_flat_inputs(m, samples, idx);
            self.forward_flat(m, th, bs);
        }
        let len = self.rows_out(m, bs);
        let mut sse = 0.0;
        let (n, d) = (m.plan.n, m.plan.dim);
        let (graph, masked) = (m.arch.biases.graph, !m.plan.kinematic.is_empty());
        for i in 0..len {
            // Kinematic particles' motion is given: no loss, no gradient.
            let particle = if graph { i % n } else { i / bs / d };
            if masked && m.plan.is_kinematic(particle) {
                if scale.is_some() {
                    self.gacc[i] = 0.0;
                }
                continue;
            }
            let e = self.acc[i] - self.tgt[i];
            sse += e * e;
            if let Some(s) = scale {
                self.gacc[i] = 2.0 * s * e;
            }
        }
        self.sse = sse;
        if scale.is_some() {
            self.grad.fill(0.0);
            if m.arch.biases.graph {
                self.backward_graph(m, th, bs);
            } else {
                self.backward_flat(m, th, bs);
            }
        }
    }

    /// Accelerations of the last run for state `s` of the chunk, node-major.
    pub(crate) fn acceleration(
        &self,
        shape: (usize, usize, bool),
        bs: usize,
        s: usize,
        out: &mut [f64],
    ) {
        let (n, d, graph) = shape;
        for i in 0..n {
            for c in 0..d {
                out[i * d + c] = if graph {
                    self.acc[c * bs * n + s * n + i]
                } else {
                    self.acc[(i * d + c) * bs + s]
                };
            }
        }
    }

    fn rows_out(&self, m: &Model, bs: usize) -> usize {
        m.plan.dim * m.plan.n * bs
    }

    fn fill_flat_inputs(&mut self, m: &Model, samples: &Samples, idx: &[usize]) {
        let bs = idx.len();
        let nd = m.plan.n * m.plan.dim;
        let (states, targets) = (samples.states(), samples.targets());
        samples.ask_for(idx);
        for (s, &k) in idx.iter().enumerate() {
            self.put_flat_state(m, s, bs, &states[k].q, &states[k].v);
            if let Some(t) = targets.get(k) {
                for (f, x) in t[..nd].iter().enumerate() {
                    self.tgt[f * bs + s] = *x;
                }
            }
        }
    }

    /// NODE's scaled (q, q̇) of state `s` of `bs`.
    fn put_flat_state(&mut self, m: &Model, s: usize, bs: usize, q: &[f64], v: &[f64]) {
        let nd = m.plan.n * m.plan.dim;
        let nm = &m.arch.norm;
        for f in 0..nd {
            self.x[f * bs + s] = (q[f] - nm.q_mean[f % m.plan.dim]) / nm.q_scale;
            self.x[(nd + f) * bs + s] = v[f] / nm.v_scale;
        }
    }

    fn forward_flat(&mut self, m: &Model, th: &[f64], bs: usize) {
        let i = m.ix(Block::Flat).expect("NODE has a flat MLP");
        let nd = m.plan.n * m.plan.dim;
        m.mlp(i).forward(
            th,
            &self.x[..2 * nd * bs],
            &[],
            bs,
            &mut self.tapes[i],
            &mut self.acc[..nd * bs],
        );
        let k = m.arch.norm.out_scale;
        self.acc[..nd * bs].iter_mut().for_each(|a| *a *= k);
    }

    fn backward_flat(&mut self, m: &Model, th: &[f64], bs: usize) {
        let i = m.ix(Block::Flat).expect("NODE has a flat MLP");
        let nd = m.plan.n * m.plan.dim;
        let k = m.arch.norm.out_scale;
        self.gacc[..nd * bs].iter_mut().for_each(|g| *g *= k);
        let gx = self.inputs.then(|| {
            let gx = &mut self.gxn[..2 * nd * bs];
            gx.fill(0.0);
            (gx, &mut [][..])
        });
        m.mlp(i).backward(
            th,
            &mut self.grad,
            &self.x[..2 * nd * bs],
            &[],
            bs,
            &self.tapes[i],
            &self.gacc[..nd * bs],
            gx,
            &mut self.s1,
            &mut self.s2,
        );
    }

    /// Node inputs and targets of the states `idx`, from their records
    /// ([`Samples`] packs every graph model's states).
    fn fill_graph_inputs(&mut self, m: &Model, samples: &Samples, idx: &[usize]) {
        self.clear_one_hot(m, idx.len() * m.plan.n);
        self.put_graph_records(m, samples, idx);
    }

    fn clear_one_hot(&mut self, m: &Model, nodes: usize) {
        let t = m.arch.types;
        self.x[..t * nodes].fill(0.0);
        self.xn[..t * nodes].fill(0.0);
    }

    widest! {
        /// Node inputs of state `s` (one-hot, q, q̇ raw in `x`, scaled in `xn`)
        /// from node-major `q`, `v`; the one-hot rows must have been cleared.
        fn put_graph_state => put_graph_state_any(
            m: &Model, s: usize, nodes: usize, q: &[f64], v: &[f64]
        )
    }

    #[inline(always)]
    #[allow(clippy::inline_always)]
    fn put_graph_state_any(&mut self, m: &Model, s: usize, nodes: usize, q: &[f64], v: &[f64]) {
        let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
        let at = |f: usize| f * nodes + s * n..f * nodes + (s + 1) * n;
        // Transposed first, then scaled a feature row at a time: the
        // divisions run in vectors (one by one they were a sixteenth of a
        // 50-spring rollout step).
        for c in 0..d {
            for (x, y) in self.x[at(t + c)].iter_mut().zip(q.chunks_exact(d)) {
                *x = y[c];
            }
            for (x, y) in self.x[at(t + d + c)].iter_mut().zip(v.chunks_exact(d)) {
                *x = y[c];
            }
        }
        self.finish_graph_state(m, s, nodes);
    }

    widest! {
        /// [`Chunk::put_graph_state`] and the targets for the states `idx`
        /// from their packed records: rows copied, no transposing.
        fn put_graph_records => put_graph_records_any(m: &Model, samples: &Samples, idx: &[usize])
    }

    #[inline(always)]
    #[allow(clippy::inline_always)]
    fn put_graph_records_any(&mut self, m: &Model, samples: &Samples, idx: &[usize]) {
        let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
        let nodes = idx.len() * n;
        for (s, r) in samples.records(idx).enumerate() {
            for (f, row) in r.chunks_exact(n).enumerate() {
                let to = if f < 2 * d {
                    &mut self.x[(t + f) * nodes + s * n..]
                } else {
                    &mut self.tgt[(f - 2 * d) * nodes + s * n..]
                };
                copy_row(&mut to[..n], row);
            }
            self.finish_graph_state(m, s, nodes);
        }
    }

    /// State `s`'s one-hot rows, and its inputs scaled into `xn` from the
    /// raw rows of `x`.
    #[inline(always)]
    #[allow(clippy::inline_always)]
    fn finish_graph_state(&mut self, m: &Model, s: usize, nodes: usize) {
        let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
        let nm = &m.arch.norm;
        let at = |f: usize| f * nodes + s * n..f * nodes + (s + 1) * n;
        for (i, &ty) in m.plan.types.iter().enumerate() {
            self.x[ty * nodes + s * n + i] = 1.0;
            if m.xn_read {
                self.xn[ty * nodes + s * n + i] = 1.0;
            }
        }
        if !m.xn_read {
            return;
        }
        for c in 0..d {
            let (mean, qs, vs) = (nm.q_mean[c], nm.q_scale, nm.v_scale);
            for (z, &y) in self.xn[at(t + c)].iter_mut().zip(&self.x[at(t + c)]) {
                *z = (y - mean) / qs;
            }
            for (z, &y) in self.xn[at(t + d + c)]
                .iter_mut()
                .zip(&self.x[at(t + d + c)])
            {
                *z = y / vs;
            }
        }
    }

    /// Sizes the buffers for one state (inference) and, without contacts,
    /// lays out its edges; with contacts the edges are found at each state.
    pub(crate) fn reserve_one(&mut self, m: &Model) {
        self.reserve(m, 1, m.plan.recv.len(), false);
        if !m.plan.has_contacts() {
            self.lay_out(m, 1);
        }
    }

    /// Forward pass of one state given as node-major slices, for inference:
    /// no targets, no loss, no reverse pass. Read the results with
    /// [`Chunk::acceleration`], [`Chunk::decoded`] and [`Chunk::edge_outputs`].
    pub(crate) fn forward_one(&mut self, m: &Model, th: &[f64], q: &[f64], v: &[f64], same: bool) {
        self.same_params = same;
        if m.plan.has_contacts() {
            let edges = self.contacts.find_moving(&m.plan, q);
            self.reserve(m, 1, edges, false);
            self.lay_out(m, 1);
        } else {
            self.reserve_one(m);
        }
        if m.arch.biases.graph {
            self.clear_one_hot(m, m.plan.n);
            self.put_graph_state(m, 0, m.plan.n, q, v);
            self.forward_graph(m, th);
        } else {
            self.put_flat_state(m, 0, 1, q, v);
            self.forward_flat(m, th, 1);
        }
    }

    /// Reverse mode through one state, for planning gradients: with
    /// L = Σ ḡ·q̈ (ḡ = `gacc`, node-major), ∂L/∂q into `gq` and ∂L/∂q̇ into
    /// `gv` (node-major), and q̈ itself into `acc`. Positions reach q̈ through
    /// the node inputs, the edge inputs w_ij = q_i − q_j and the constraint;
    /// velocities through the node inputs and Ȧq̇. Contact edges are those
    /// of this state (the set is piecewise constant in q). Kinematic
    /// particles' q̈ is 0 (their motion is given), so their rows of `gacc`
    /// count for nothing, as in [`Chunk::forward_one`]'s callers.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn input_vjp(
        &mut self,
        m: &Model,
        th: &[f64],
        q: &[f64],
        v: &[f64],
        gacc: &[f64],
        acc: &mut [f64],
        gq: &mut [f64],
        gv: &mut [f64],
    ) {
        let edges = if m.plan.has_contacts() {
            self.contacts.find(&m.plan, std::iter::once(q))
        } else {
            m.plan.recv.len()
        };
        self.reserve(m, 1, edges, true);
        self.lay_out(m, 1);
        let (n, d, graph) = m.shape();
        if graph {
            self.clear_one_hot(m, n);
            self.put_graph_state(m, 0, n, q, v);
            self.forward_graph(m, th);
        } else {
            self.put_flat_state(m, 0, 1, q, v);
            self.forward_flat(m, th, 1);
        }
        self.acceleration((n, d, graph), 1, 0, acc);
        for i in 0..n {
            let held = m.plan.is_kinematic(i);
            for c in 0..d {
                // Feature-major either way: graph rows are particles, NODE's
                // features are (i, c) over one state.
                let at = if graph { c * n + i } else { i * d + c };
                self.gacc[at] = if held { 0.0 } else { gacc[i * d + c] };
                if held {
                    acc[i * d + c] = 0.0;
                }
            }
        }
        self.inputs = true;
        // No parameter gradients: planning discards them, and an empty
        // buffer tells every layer to skip them (half the reverse pass).
        let kept = std::mem::take(&mut self.grad);
        if graph {
            self.backward_graph(m, th, 1);
        } else {
            self.backward_flat(m, th, 1);
        }
        self.grad = kept;
        self.inputs = false;
        let nm = &m.arch.norm;
        if !graph {
            let nd = n * d;
            for f in 0..nd {
                gq[f] = self.gxn[f] / nm.q_scale;
                gv[f] = self.gxn[nd + f] / nm.v_scale;
            }
            return;
        }
        let t = m.arch.types;
        for i in 0..n {
            for c in 0..d {
                gq[i * d + c] = self.gxn[(t + c) * n + i] / nm.q_scale + self.gqv[c * n + i];
                gv[i * d + c] =
                    self.gxn[(t + d + c) * n + i] / nm.v_scale + self.gqv[(d + c) * n + i];
            }
        }
        let ne = self.edges;
        for c in 0..d {
            let gw = &self.gw[c * ne..(c + 1) * ne];
            for ((g, &r), &s) in gw.iter().zip(&self.recv).zip(&self.send) {
                gq[r * d + c] += g / nm.w_scale;
                gq[s * d + c] -= g / nm.w_scale;
            }
        }
    }

    /// The decoder's output of the last run (forces of constrained models,
    /// accelerations of the others; scaled), feature-major `d × rows`.
    pub(crate) fn decoded(&self) -> &[f64] {
        &self.out
    }

    /// The edge decoder's raw output of the last run (pairwise models),
    /// feature-major `d × edges`, before antisymmetrising and scaling.
    pub(crate) fn edge_outputs(&self) -> &[f64] {
        &self.f_edge
    }

    /// The directed edges of the last run: receivers, senders (rows; for one
    /// state, particles), fixed and contact.
    pub(crate) fn laid_edges(&self) -> (&[usize], &[usize]) {
        (&self.recv[..self.edges], &self.send[..self.edges])
    }

    widest! {
        /// The graph models' forward pass, compiled for the widest vectors the
        /// CPU has (the activations and gathers between the MLPs are a third of
        /// an inference step); the same bits on every path.
        fn forward_graph => forward_graph_any(m: &Model, th: &[f64])
    }

    // The paper's forward pass, inlined into the vector copies above with
    // its stages (each #[inline(always)] to stay inside them).
    #[inline(always)]
    #[allow(clippy::inline_always)]
    fn forward_graph_any(&mut self, m: &Model, th: &[f64]) {
        let a = &m.arch;
        let (d, t, em) = (m.plan.dim, a.types, a.embed);
        let bs = self.laid;
        let nodes = bs * m.plan.n;
        let nf = a.node_features();
        // Encode: nodes from the type (by type) or (one-hot, q, q̇), edges
        // from w_ij = q_i − q_j.
        // The type embeddings and round 0's pair outputs are functions of
        // the parameters alone: kept from the last step when those are the
        // same (inference records no tape that would need them again).
        let kept = m.by_type && !self.record && self.by_type_done && self.same_params;
        self.by_type_done = m.by_type && !self.record;
        let i = m.ix(Block::NodeEmbed).expect("graph model");
        let h0 = &mut self.h[0][..em * nodes];
        let (by_type, nodes_read) = (m.by_type, m.nodes_read);
        if by_type {
            // One embedding per type, the same bits as per node, a sixth of
            // an inference step's square roots fewer.
            let emb = &mut self.type_embed[..em * t];
            if !kept {
                m.mlp(i)
                    .forward(th, &self.eye[..t * t], &[], t, &mut self.tapes[i], emb);
                squareplus_in_place(emb);
            }
            if nodes_read {
                let ty = &self.node_ty[..nodes];
                for k in 0..em {
                    let (hk, ek) = (
                        &mut h0[k * nodes..(k + 1) * nodes],
                        &emb[k * t..(k + 1) * t],
                    );
                    for (h, &y) in hk.iter_mut().zip(ty) {
                        *h = ek[y];
                    }
                }
            }
        } else {
            let (x, tape) = (&self.xn[..nf * nodes], &mut self.tapes[i]);
            m.mlp(i).forward(th, x, &[], nodes, tape, h0);
            squareplus_in_place(h0);
        }
        if by_type && a.rounds > 0 && a.updates_edges(0) {
            self.pair_outputs(m, th, kept);
        }
        // MCGNODE's one round by type at inference: the edges' stages fused
        // block by block, the blocks over both cores on a large graph.
        let fused = m.fusable && !self.record && self.edges >= FUSED_EDGES;
        if fused {
            self.edge_blocks(m, th);
        } else {
            self.edge_stages(m, th);
        }
        self.decode(m, th, fused);
        // Constrain.
        if a.constrained {
            self.constrain(m, th, bs, kept);
        } else {
            self.acc[..d * nodes].copy_from_slice(&self.out[..d * nodes]);
        }
    }

    /// The edges' stages one after the other over all rows: the edge
    /// embedding from w_ij = q_i − q_j, then message passing.
    #[inline(always)]
    #[allow(clippy::too_many_lines, clippy::inline_always)] // the rounds as one loop nest
    fn edge_stages(&mut self, m: &Model, th: &[f64]) {
        let a = &m.arch;
        let (d, t, em) = (m.plan.dim, a.types, a.embed);
        let nodes = self.laid * m.plan.n;
        let edges = self.edges;
        let (by_type, nodes_read) = (m.by_type, m.nodes_read);
        for c in 0..d {
            let q = &self.x[(t + c) * nodes..(t + c + 1) * nodes];
            let w = &mut self.w_in[c * edges..(c + 1) * edges];
            edge_differences(w, q, &self.recv, &self.send, a.norm.w_scale);
        }
        let i = m.ix(Block::EdgeEmbed).expect("graph model");
        let he0 = &mut self.he[0][..em * edges];
        let w_in = &self.w_in[..a.edge_features() * edges];
        let tape = &mut self.tapes[i];
        (self.split).forward(m.mlp(i), th, (w_in, &[]), edges, tape, he0, true);
        // Message passing.
        for l in 0..a.rounds {
            let (hl, hn) = self.h.split_at_mut(l + 1);
            let (hl, hn) = (&hl[l][..em * nodes], &mut hn[0][..em * nodes]);
            let (hel, hen) = self.he.split_at_mut(l + 1);
            let (hel, hen) = (&hel[l][..em * edges], &mut hen[0][..em * edges]);
            let (hs, hr) = (&mut self.hs[l][..em * edges], &mut self.hr[l][..em * edges]);
            let by_pair = by_type && l == 0;
            if !by_pair || a.updates_nodes(l) {
                gather_rows(hs, hl, &self.send[..edges], Gather::Set);
                gather_rows(hr, hl, &self.recv[..edges], Gather::Set);
            }
            if a.updates_nodes(l) {
                // h_i ← sqp(h_i + Σ_j W_V(h_j ‖ h_ij)).
                let i = m.ix(Block::Message(l)).expect("round");
                let msg = &mut self.msg[..em * edges];
                let tape = &mut self.tapes[i];
                (self.split).forward(m.mlp(i), th, (hs, hel), edges, tape, msg, false);
                let agg = &mut self.agg[..em * nodes];
                agg.fill(0.0);
                scatter_add_rows(agg, msg, &self.recv[..edges]);
                for ((x, h), g) in hn.iter_mut().zip(hl).zip(agg.iter()) {
                    *x = h + g;
                }
                squareplus_in_place(hn);
            } else if nodes_read {
                hn.copy_from_slice(hl);
            }
            if a.updates_edges(l) && by_pair {
                // The same MLP on the types² pairs' inputs (above), read per edge.
                let (tt, po) = (t * t, &self.pair_out[..em * t * t]);
                let pair = &self.pair[..edges];
                for k in 0..em {
                    let (x, old, pk) = (
                        &mut hen[k * edges..(k + 1) * edges],
                        &hel[k * edges..(k + 1) * edges],
                        &po[k * tt..(k + 1) * tt],
                    );
                    add_indexed(x, old, pk, pair);
                }
                squareplus_in_place(hen);
            } else if a.updates_edges(l) {
                // h_ij ← sqp(h_ij + W_E(h_i ‖ h_j)), from the node states before the round.
                let i = m.ix(Block::EdgeUpdate(l)).expect("round");
                let tape = &mut self.tapes[i];
                let split = &mut self.split;
                match a.edge_input {
                    EdgeInput::Concat => {
                        split.forward(m.mlp(i), th, (hr, hs), edges, tape, hen, false)
                    }
                    EdgeInput::Product => {
                        let hp = &mut self.hp[l][..em * edges];
                        for ((p, r), s) in hp.iter_mut().zip(hr.iter()).zip(hs.iter()) {
                            *p = r * s;
                        }
                        split.forward(m.mlp(i), th, (hp, &[]), edges, tape, hen, false);
                    }
                }
                for (x, old) in hen.iter_mut().zip(hel) {
                    *x += old;
                }
                squareplus_in_place(hen);
            } else {
                hen.copy_from_slice(hel);
            }
        }
    }

    /// The body branch and the decoder into `out`; `fused`: the edge
    /// decoder's outputs are already in `f_edge` ([`Chunk::edge_blocks`]).
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside forward_graph's vector copies
    fn decode(&mut self, m: &Model, th: &[f64], fused: bool) {
        let a = &m.arch;
        let (d, em) = (m.plan.dim, a.embed);
        let nodes = self.laid * m.plan.n;
        let edges = self.edges;
        let nf = a.node_features();
        // Global (body) embedding of (one-hot, q, q̇) (with the edges' blocks
        // when fused).
        if let (Some(i), false) = (m.ix(Block::GlobalEmbed), fused) {
            let g = &mut self.glob[..em * nodes];
            m.mlp(i).forward(
                th,
                &self.xn[..nf * nodes],
                &[],
                nodes,
                &mut self.tapes[i],
                g,
            );
            squareplus_in_place(g);
        }
        // Decode.
        let (hr_, her_) = (
            &self.h[a.rounds][..em * nodes],
            &self.he[a.rounds][..em * edges],
        );
        let out = &mut self.out[..d * nodes];
        match a.decoder {
            Decoder::Pairwise { body } => {
                // Newton's third law: F_ab = (f_ab − f_ba)/2 on a, −F_ab on b.
                out.fill(0.0);
                let i = m.ix(Block::EdgeDecoder).expect("pairwise decoder");
                let fe = &mut self.f_edge[..d * edges];
                if !fused {
                    let tape = &mut self.tapes[i];
                    (self.split).forward(m.mlp(i), th, (her_, &[]), edges, tape, fe, false);
                }
                let half = edges / 2;
                for c in 0..d {
                    let (oc, fc) = (&mut out[c * nodes..(c + 1) * nodes], &fe[c * edges..]);
                    for e in 0..half {
                        let f = (fc[e] - fc[e + half]) * 0.5;
                        oc[self.recv[e]] += f;
                        oc[self.send[e]] -= f;
                    }
                }
                if body {
                    let i = m.ix(Block::BodyDecoder).expect("body decoder");
                    let fb = &mut self.f_body[..d * nodes];
                    if !fused {
                        let g = &self.glob[..em * nodes];
                        m.mlp(i).forward(th, g, &[], nodes, &mut self.tapes[i], fb);
                    }
                    for (o, f) in out.iter_mut().zip(fb.iter()) {
                        *o += f;
                    }
                }
            }
            Decoder::Node { global } => {
                let i = m.ix(Block::NodeDecoder).expect("node decoder");
                let g: &[f64] = if global {
                    &self.glob[..em * nodes]
                } else {
                    &[]
                };
                m.mlp(i).forward(th, hr_, g, nodes, &mut self.tapes[i], out);
            }
        }
        let k = a.norm.out_scale;
        self.out[..d * nodes].iter_mut().for_each(|o| *o *= k);
    }

    /// Round 0's edge update on the types² pairs' inputs (each edge reads its
    /// pair's row): kept from the pass before when `kept`.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside forward_graph's vector copies
    fn pair_outputs(&mut self, m: &Model, th: &[f64], kept: bool) {
        let a = &m.arch;
        let (t, em) = (a.types, a.embed);
        let i = m.ix(Block::EdgeUpdate(0)).expect("round");
        let (tt, emb) = (t * t, &self.type_embed[..em * t]);
        let (pr, rest) = self.pair_in[..3 * em * tt].split_at_mut(em * tt);
        let (ps, pp) = rest.split_at_mut(em * tt);
        for k in 0..em {
            for p in 0..tt {
                let (r, s) = (emb[k * t + p / t], emb[k * t + p % t]);
                (pr[k * tt + p], ps[k * tt + p], pp[k * tt + p]) = (r, s, r * s);
            }
        }
        let (x, c): (&[f64], &[f64]) = match a.edge_input {
            EdgeInput::Concat => (pr, ps),
            EdgeInput::Product => (pp, &[]),
        };
        let po = &mut self.pair_out[..em * tt];
        if !kept {
            m.mlp(i).forward(th, x, c, tt, &mut self.tapes[i], po);
        }
    }

    /// [`Chunk::edge_stages`] and the edge decoder fused over blocks of edge
    /// rows ([`super::fused`]): inference of MCGNODE's one round by type.
    fn edge_blocks(&mut self, m: &Model, th: &[f64]) {
        let a = &m.arch;
        let (d, t, em) = (m.plan.dim, a.types, a.embed);
        let nodes = self.laid * m.plan.n;
        let edges = self.edges;
        let (Some(ie), Some(id)) = (m.ix(Block::EdgeEmbed), m.ix(Block::EdgeDecoder)) else {
            unreachable!("a pairwise graph model has both edge MLPs")
        };
        let features = a.edge_features();
        let work = EdgeBlocks {
            mlps: Branch {
                embed: m.mlp(ie),
                decoder: m.mlp(id),
                th,
                embed_width: em,
            },
            q: &self.x[t * nodes..(t + d) * nodes],
            nodes,
            dim: d,
            w_scale: a.norm.w_scale,
            recv: &self.recv[..edges],
            send: &self.send[..edges],
            w_in: &self.w_in[..features * edges],
            features,
            edges,
            pair_out: &self.pair_out[..em * t * t],
            pairs: t * t,
            pair: &self.pair[..edges],
        };
        let body = match (m.ix(Block::GlobalEmbed), m.ix(Block::BodyDecoder)) {
            (Some(ig), Some(ib)) => Some(BodyBlocks {
                mlps: Branch {
                    embed: m.mlp(ig),
                    decoder: m.mlp(ib),
                    th,
                    embed_width: em,
                },
                xn: &self.xn[..a.node_features() * nodes],
                features: a.node_features(),
                nodes,
            }),
            _ => None,
        };
        // Edge blocks first, then the particles' from the next whole block.
        let span = edges.next_multiple_of(EDGE_BLOCK);
        let rows = span + if body.is_some() { nodes } else { 0 };
        let f_edge = Out::new(&mut self.f_edge[..d * edges], edges);
        let f_body = Out::new(&mut self.f_body[..d * nodes], nodes);
        let run = |r: std::ops::Range<usize>, s: &mut Scratch| match &body {
            Some(b) if r.start >= span => {
                // SAFETY: `blocks` hands each block of rows to one thread.
                unsafe { b.run(r.start - span..r.end - span, s, f_body) }
            }
            // SAFETY: as above.
            _ => unsafe { work.run(r.start..r.end.min(edges), s, f_edge) },
        };
        (self.split).blocks(rows, EDGE_BLOCK, &mut self.scratch, &run);
    }

    /// q̈ = M⁻¹(N − Aᵀλ), λ = (A M⁻¹ Aᵀ)⁻¹(A M⁻¹ N + Ȧq̇), per state, on the
    /// sparse bar incidence. K and λ are kept for the reverse pass.
    fn constrain(&mut self, m: &Model, th: &[f64], bs: usize, kept: bool) {
        let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
        let nodes = bs * n;
        let k = m.plan.bars.len();
        let lm = m.log_mass.expect("constrained model has masses");
        // 1/m per type, once per call (not in the per-bar loops), or kept
        // with the by-type values (the parameters have not changed).
        if !kept {
            for (t, x) in self.inv_m.iter_mut().enumerate() {
                *x = (-th[lm + t]).exp();
            }
        }
        let inv_m = &self.inv_m;
        if k == 0 {
            self.no_bars(d, bs, nodes);
            return;
        }
        let minv = |p: usize| inv_m[m.plan.types[p]];
        let (x, out) = (&self.x, &self.out);
        let q = |row: usize, c: usize| x[(t + c) * nodes + row];
        let v = |row: usize, c: usize| x[(t + d + c) * nodes + row];
        let f = |row: usize, c: usize| out[c * nodes + row];
        for s in 0..bs {
            let base = s * n;
            let (dq, lam) = (
                &mut self.dq[s * k * d..(s + 1) * k * d],
                &mut self.lam[s * k..(s + 1) * k],
            );
            let kmat = &mut self.kmat[s * k * k..(s + 1) * k * k];
            let mut ok = true;
            if k > 0 {
                for (r, bar) in m.plan.bars.iter().enumerate() {
                    let (mut vv, mut rhs) = (0.0, 0.0);
                    let a = base + bar.a;
                    for c in 0..d {
                        let (qb, vb, fb) = match &bar.b {
                            BarEnd::Particle(bp) => {
                                let b = base + bp;
                                (q(b, c), v(b, c), minv(*bp) * f(b, c))
                            }
                            BarEnd::Fixed(p) => (p[c], 0.0, 0.0),
                        };
                        let (dqc, dvc) = (q(a, c) - qb, v(a, c) - vb);
                        dq[r * d + c] = dqc;
                        vv += dvc * dvc;
                        rhs += dqc * (minv(bar.a) * f(a, c) - fb);
                    }
                    lam[r] = rhs + vv;
                }
                kmat.fill(0.0);
                for p in 0..n {
                    let mi = minv(p);
                    for &(r, sr) in &m.incid[p] {
                        for &(r2, s2) in &m.incid[p] {
                            let dot: f64 = (0..d).map(|c| dq[r * d + c] * dq[r2 * d + c]).sum();
                            kmat[r * k + r2] += mi * sr * s2 * dot;
                        }
                    }
                }
                // Factored in place and kept: the reverse pass solves with
                // the same K again.
                let piv = &mut self.piv[s * k..(s + 1) * k];
                ok = lu_factor_in_place(kmat, piv, k).is_ok();
                if ok {
                    lu_solve_one(kmat, piv, lam, k);
                }
            }
            self.solved[s] = ok;
            for p in 0..n {
                let mi = minv(p);
                for c in 0..d {
                    let mut g = f(base + p, c);
                    if ok {
                        for &(r, sr) in &m.incid[p] {
                            g -= sr * dq[r * d + c] * lam[r];
                        }
                    } else {
                        g = f64::NAN;
                    }
                    self.geq[c * nodes + base + p] = g;
                    self.acc[c * nodes + base + p] = mi * g;
                }
            }
        }
    }

    /// [`Chunk::constrain`] without bars (springs, contacts): G = N and
    /// q̈ = M⁻¹N, in row order.
    fn no_bars(&mut self, d: usize, bs: usize, nodes: usize) {
        let (ty, inv_m) = (&self.node_ty[..nodes], &self.inv_m);
        for c in 0..d {
            let range = c * nodes..(c + 1) * nodes;
            let (f, g) = (&self.out[range.clone()], &mut self.geq[range.clone()]);
            g.copy_from_slice(f);
            for ((a, f), &y) in self.acc[range].iter_mut().zip(f).zip(ty) {
                *a = inv_m[y] * f;
            }
        }
        self.solved[..bs].fill(true);
    }

    /// Reverse pass of [`Chunk::constrain`]: ∂L/∂N into `gout`, ∂L/∂log m into `grad`.
    fn constrain_backward(&mut self, m: &Model, th: &[f64], bs: usize) {
        let (n, d) = (m.plan.n, m.plan.dim);
        let nodes = bs * n;
        let k = m.plan.bars.len();
        let lm = m.log_mass.expect("constrained model has masses");
        // 1/m per type, once per call (not in the per-bar loops).
        for (t, x) in self.inv_m.iter_mut().enumerate() {
            *x = (-th[lm + t]).exp();
        }
        let inv_m = &self.inv_m;
        let minv = |p: usize| inv_m[m.plan.types[p]];
        for s in 0..bs {
            let base = s * n;
            for p in 0..n {
                let (mi, row) = (minv(p), base + p);
                let mut gm = 0.0;
                for c in 0..d {
                    let ga = self.gacc[c * nodes + row];
                    self.gout[c * nodes + row] = mi * ga;
                    gm += self.geq[c * nodes + row] * ga;
                }
                self.gminv[row] = gm;
            }
            if k > 0 && self.solved[s] {
                let dq = &self.dq[s * k * d..(s + 1) * k * d];
                let lam = &self.lam[s * k..(s + 1) * k];
                // λ̄ = −A ḡ_G; r̄hs = K⁻ᵀ λ̄ (K is symmetric); K̄ = −r̄hs λᵀ.
                let rbar = &mut self.rhs[..k];
                for (r, bar) in m.plan.bars.iter().enumerate() {
                    let mut x = 0.0;
                    for c in 0..d {
                        let mut gg = self.gout[c * nodes + base + bar.a];
                        if let BarEnd::Particle(b) = bar.b {
                            gg -= self.gout[c * nodes + base + b];
                        }
                        x -= dq[r * d + c] * gg;
                        if self.inputs {
                            // G = N − Aᵀλ: ∂/∂(q_a − q_b) = −λ_r ḡ_G.
                            self.gdq[(s * k + r) * d + c] = -lam[r] * gg;
                        }
                    }
                    rbar[r] = x;
                }
                // K's factors from the forward pass (it solved, so they are).
                let (kf, piv) = (
                    &self.kmat[s * k * k..(s + 1) * k * k],
                    &self.piv[s * k..(s + 1) * k],
                );
                lu_solve_one(kf, piv, rbar, k);
                if self.inputs {
                    let into = (&mut self.gdq[s * k * d..(s + 1) * k * d], &mut self.gqv[..]);
                    constraint_input_grads(
                        m,
                        s,
                        nodes,
                        inv_m,
                        (dq, lam, rbar),
                        (&self.x, &self.out),
                        into,
                    );
                }
                for p in 0..n {
                    let (mi, row) = (minv(p), base + p);
                    let mut gm = 0.0;
                    for &(r, sr) in &m.incid[p] {
                        let mut dot_f = 0.0;
                        for c in 0..d {
                            let dqc = dq[r * d + c];
                            self.gout[c * nodes + row] += rbar[r] * sr * mi * dqc;
                            dot_f += dqc * self.out[c * nodes + row];
                        }
                        gm += rbar[r] * sr * dot_f;
                        for &(r2, s2) in &m.incid[p] {
                            let dot: f64 = (0..d).map(|c| dq[r * d + c] * dq[r2 * d + c]).sum();
                            gm -= rbar[r] * lam[r2] * sr * s2 * dot;
                        }
                    }
                    self.gminv[row] += gm;
                }
            }
            // None to add without parameter gradients (planning's pass).
            for p in 0..n * usize::from(!self.grad.is_empty()) {
                let mi = minv(p);
                self.grad[lm + m.plan.types[p]] -= self.gminv[base + p] * mi;
            }
        }
    }

    /// [`Chunk::constrain_backward`] without bars, row by row in vectors
    /// where the general loop went particle by particle: the same products
    /// and sums in the same order (each row's mass term summed over the
    /// coordinates in turn, the log-mass gradients row by row), so the same
    /// bits.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside backward_graph's vector copies
    fn no_bars_backward(&mut self, m: &Model, th: &[f64], bs: usize) {
        let (d, nodes) = (m.plan.dim, bs * m.plan.n);
        let lm = m.log_mass.expect("constrained model has masses");
        for (t, x) in self.inv_m.iter_mut().enumerate() {
            *x = (-th[lm + t]).exp();
        }
        let (ty, inv_m) = (&self.node_ty[..nodes], &self.inv_m);
        let gm = &mut self.gminv[..nodes];
        gm.fill(0.0);
        for c in 0..d {
            let range = c * nodes..(c + 1) * nodes;
            let (ga, eq) = (&self.gacc[range.clone()], &self.geq[range.clone()]);
            for ((o, &g), &y) in self.gout[range].iter_mut().zip(ga).zip(ty) {
                *o = inv_m[y] * g;
            }
            for ((x, &e), &g) in gm.iter_mut().zip(eq).zip(ga) {
                *x += e * g;
            }
        }
        // None to add without parameter gradients (planning's pass). One
        // running sum per type, in row order, apart from `grad`.
        if self.grad.is_empty() {
            return;
        }
        if let [mi] = inv_m[..] {
            let mut sum = self.grad[lm];
            for &g in gm.iter() {
                sum -= g * mi;
            }
            self.grad[lm] = sum;
            return;
        }
        let sums = &mut self.g_mass;
        sums.clear();
        sums.extend_from_slice(&self.grad[lm..lm + inv_m.len()]);
        for (&g, &y) in gm.iter().zip(ty) {
            sums[y] -= g * inv_m[y];
        }
        self.grad[lm..lm + inv_m.len()].copy_from_slice(sums);
    }

    widest! {
        /// The reverse of [`Chunk::forward_graph`], compiled for the widest
        /// vectors the CPU has (its activation derivatives, a division each,
        /// were a tenth of a 5-spring epoch as two-lane SSE2); the same bits on
        /// every path.
        fn backward_graph => backward_graph_any(m: &Model, th: &[f64], bs: usize)
    }

    // The reverse of forward_graph_any stage by stage, in one place so that
    // the two read side by side.
    #[allow(clippy::too_many_lines, clippy::inline_always)]
    #[inline(always)]
    fn backward_graph_any(&mut self, m: &Model, th: &[f64], bs: usize) {
        let a = &m.arch;
        let (d, t, em) = (m.plan.dim, a.types, a.embed);
        let nodes = bs * m.plan.n;
        let edges = self.edges;
        let nf = a.node_features();
        if self.inputs {
            self.gxn[..nf * nodes].fill(0.0);
            self.gw[..a.edge_features() * edges].fill(0.0);
            self.gqv[..2 * d * nodes].fill(0.0);
        }
        if a.constrained {
            if m.plan.bars.is_empty() {
                self.no_bars_backward(m, th, bs);
            } else {
                self.constrain_backward(m, th, bs);
            }
        } else {
            self.gout[..d * nodes].copy_from_slice(&self.gacc[..d * nodes]);
        }
        let k = a.norm.out_scale;
        self.gout[..d * nodes].iter_mut().for_each(|g| *g *= k);
        let (gh, ghe, gglob) = (
            &mut self.gh[..em * nodes],
            &mut self.ghe[..em * edges],
            &mut self.gglob[..em * nodes],
        );
        gh.fill(0.0);
        ghe.fill(0.0);
        gglob.fill(0.0);
        self.g_type.fill(0.0);
        let gout = &self.gout[..d * nodes];
        let (hr_, her_) = (
            &self.h[a.rounds][..em * nodes],
            &self.he[a.rounds][..em * edges],
        );
        let glob = &self.glob[..em * nodes];
        let (s1, s2) = (&mut self.s1, &mut self.s2);
        match a.decoder {
            Decoder::Pairwise { body } => {
                let half = edges / 2;
                let gfe = &mut self.gf_edge[..d * edges];
                for c in 0..d {
                    let go = &gout[c * nodes..(c + 1) * nodes];
                    for e in 0..half {
                        let g = 0.5 * (go[self.recv[e]] - go[self.send[e]]);
                        gfe[c * edges + e] = g;
                        gfe[c * edges + e + half] = -g;
                    }
                }
                let i = m.ix(Block::EdgeDecoder).expect("pairwise decoder");
                let gx = Some((&mut ghe[..], &mut [][..]));
                m.mlp(i).backward(
                    th,
                    &mut self.grad,
                    her_,
                    &[],
                    edges,
                    &self.tapes[i],
                    gfe,
                    gx,
                    s1,
                    s2,
                );
                if body {
                    let i = m.ix(Block::BodyDecoder).expect("body decoder");
                    let gx = Some((&mut gglob[..], &mut [][..]));
                    m.mlp(i).backward(
                        th,
                        &mut self.grad,
                        glob,
                        &[],
                        nodes,
                        &self.tapes[i],
                        gout,
                        gx,
                        s1,
                        s2,
                    );
                }
            }
            Decoder::Node { global } => {
                let i = m.ix(Block::NodeDecoder).expect("node decoder");
                let (g, gg): (&[f64], &mut [f64]) = if global {
                    (glob, &mut gglob[..])
                } else {
                    (&[], &mut [])
                };
                let gx = Some((&mut gh[..], gg));
                m.mlp(i).backward(
                    th,
                    &mut self.grad,
                    hr_,
                    g,
                    nodes,
                    &self.tapes[i],
                    gout,
                    gx,
                    s1,
                    s2,
                );
            }
        }
        if let Some(i) = m.ix(Block::GlobalEmbed) {
            times_squareplus_grad(gglob, glob);
            let (x, tape) = (&self.xn[..nf * nodes], &self.tapes[i]);
            let gx = self
                .inputs
                .then(|| (&mut self.gxn[..nf * nodes], &mut [][..]));
            m.mlp(i)
                .backward(th, &mut self.grad, x, &[], nodes, tape, gglob, gx, s1, s2);
        }
        // Message passing, last round first.
        for l in (0..a.rounds).rev() {
            let (gh, ghe) = (&mut self.gh[..em * nodes], &mut self.ghe[..em * edges]);
            let (ghp, ghep) = (
                &mut self.gh_prev[..em * nodes],
                &mut self.ghe_prev[..em * edges],
            );
            let (hs, hr) = (&self.hs[l][..em * edges], &self.hr[l][..em * edges]);
            let (hl1, hel, hel1) = (
                &self.h[l + 1][..em * nodes],
                &self.he[l][..em * edges],
                &self.he[l + 1][..em * edges],
            );
            ghp.fill(0.0);
            ghep.fill(0.0);
            let (gs, gr) = (&mut self.gs[..em * edges], &mut self.gr[..em * edges]);
            if a.updates_edges(l) {
                let gz = &mut self.gz[..em * edges];
                gz.copy_from_slice(ghe);
                times_squareplus_grad(gz, hel1);
                for (x, g) in ghep.iter_mut().zip(gz.iter()) {
                    *x += g;
                }
                let i = m.ix(Block::EdgeUpdate(l)).expect("round");
                let (tape, grad) = (&self.tapes[i], &mut self.grad);
                if m.by_type && l == 0 {
                    // By type pair: each pair's ∂L/∂output is its edges' sum.
                    let tt = t * t;
                    let (gpo, sums) = (&mut self.g_pair_out[..em * tt], &mut self.sums);
                    gpo.fill(0.0);
                    for k in 0..em {
                        let (gk, zk) = (&mut gpo[k * tt..(k + 1) * tt], &gz[k * edges..]);
                        sum_by_index(gk, &zk[..edges], &self.pair[..edges], sums);
                    }
                    let (pr, rest) = self.pair_in[..3 * em * tt].split_at(em * tt);
                    let (ps, pp) = rest.split_at(em * tt);
                    let (gpr, rest) = self.g_pair_in[..3 * em * tt].split_at_mut(em * tt);
                    let (gps, gpp) = rest.split_at_mut(em * tt);
                    let ends = (&mut gpr[..], &mut gps[..], &mut gpp[..]);
                    let mlp = (m.mlp(i), a.edge_input);
                    let x = (pr, ps, pp, tt);
                    edge_update_backward(mlp, th, grad, x, tape, gpo, ends, (s1, s2));
                    let gty = &mut self.g_type[..em * t];
                    for k in 0..em {
                        for p in 0..tt {
                            gty[k * t + p / t] += gpr[k * tt + p];
                            gty[k * t + p % t] += gps[k * tt + p];
                        }
                    }
                } else {
                    let hp = &self.hp[l][..em * edges];
                    let ends = (&mut gr[..], &mut gs[..], &mut self.gp[..em * edges]);
                    let mlp = (m.mlp(i), a.edge_input);
                    let x = (hr, hs, hp, edges);
                    edge_update_backward(mlp, th, grad, x, tape, gz, ends, (s1, s2));
                    // Both ends in one pass, edge by edge: two scatter_add_rows
                    // would sum each node's terms in another order.
                    for k in 0..em {
                        for e in 0..edges {
                            ghp[k * nodes + self.recv[e]] += gr[k * edges + e];
                            ghp[k * nodes + self.send[e]] += gs[k * edges + e];
                        }
                    }
                }
            } else {
                for (x, g) in ghep.iter_mut().zip(ghe.iter()) {
                    *x += g;
                }
            }
            if a.updates_nodes(l) {
                let gz = &mut self.gz[..em * nodes];
                gz.copy_from_slice(gh);
                times_squareplus_grad(gz, hl1);
                for (x, g) in ghp.iter_mut().zip(gz.iter()) {
                    *x += g;
                }
                let gmsg = &mut self.gmsg[..em * edges];
                gather_rows(gmsg, gz, &self.recv[..edges], Gather::Set);
                gs.fill(0.0);
                let i = m.ix(Block::Message(l)).expect("round");
                let gx = Some((&mut gs[..], &mut ghep[..]));
                m.mlp(i).backward(
                    th,
                    &mut self.grad,
                    hs,
                    hel,
                    edges,
                    &self.tapes[i],
                    gmsg,
                    gx,
                    s1,
                    s2,
                );
                scatter_add_rows(ghp, gs, &self.send[..edges]);
            } else {
                for (x, g) in ghp.iter_mut().zip(gh.iter()) {
                    *x += g;
                }
            }
            std::mem::swap(&mut self.gh, &mut self.gh_prev);
            std::mem::swap(&mut self.ghe, &mut self.ghe_prev);
        }
        // Embeddings.
        let gh = &mut self.gh[..em * nodes];
        let i = m.ix(Block::NodeEmbed).expect("graph model");
        if m.by_type {
            // Per type: the sum over its nodes, through the embedding once.
            let gty = &mut self.g_type[..em * t];
            if m.nodes_read {
                let ty = &self.node_ty[..nodes];
                for k in 0..em {
                    let gk = &mut gty[k * t..(k + 1) * t];
                    sum_by_index(gk, &gh[k * nodes..(k + 1) * nodes], ty, &mut self.sums);
                }
            }
            times_squareplus_grad(gty, &self.type_embed[..em * t]);
            let (eye, tape) = (&self.eye[..t * t], &self.tapes[i]);
            m.mlp(i)
                .backward(th, &mut self.grad, eye, &[], t, tape, gty, None, s1, s2);
        } else {
            // (One-hot node inputs went by type above: these carry q and q̇.)
            times_squareplus_grad(gh, &self.h[0][..em * nodes]);
            let (x, tape) = (&self.xn[..nf * nodes], &self.tapes[i]);
            let gx = self
                .inputs
                .then(|| (&mut self.gxn[..nf * nodes], &mut [][..]));
            m.mlp(i)
                .backward(th, &mut self.grad, x, &[], nodes, tape, gh, gx, s1, s2);
        }
        let ghe = &mut self.ghe[..em * edges];
        times_squareplus_grad(ghe, &self.he[0][..em * edges]);
        let i = m.ix(Block::EdgeEmbed).expect("graph model");
        let ef = a.edge_features();
        let w = &self.w_in[..ef * edges];
        let gx = self
            .inputs
            .then(|| (&mut self.gw[..ef * edges], &mut [][..]));
        m.mlp(i).backward(
            th,
            &mut self.grad,
            w,
            &[],
            edges,
            &self.tapes[i],
            ghe,
            gx,
            s1,
            s2,
        );
    }
}

/// The reverse pass of an edge update W_E over rows whose end states are
/// `hr`, `hs` (and `hp` = hr ⊙ hs): W_E(h_i ‖ h_j) or W_E(h_i ⊙ h_j) as the
/// architecture's edge input says. ∂L/∂θ is added into `grad`; ∂L/∂h_i and
/// ∂L/∂h_j are written into `gr`, `gs` (`gp`: the product's, scratch).
#[allow(clippy::too_many_arguments)]
fn edge_update_backward(
    (mlp, input): (&Mlp, EdgeInput),
    th: &[f64],
    grad: &mut [f64],
    (hr, hs, hp, r): (&[f64], &[f64], &[f64], usize),
    tape: &Tape,
    gz: &[f64],
    (gr, gs, gp): (&mut [f64], &mut [f64], &mut [f64]),
    (s1, s2): (&mut [f64], &mut [f64]),
) {
    match input {
        EdgeInput::Concat => {
            gr.fill(0.0);
            gs.fill(0.0);
            mlp.backward(th, grad, hr, hs, r, tape, gz, Some((gr, gs)), s1, s2);
        }
        EdgeInput::Product => {
            // ∂(h_i ⊙ h_j): ḡ_i = ḡ ⊙ h_j, ḡ_j = ḡ ⊙ h_i.
            gp.fill(0.0);
            mlp.backward(th, grad, hp, &[], r, tape, gz, Some((gp, &mut [])), s1, s2);
            for (((g, r), s), (x, y)) in gp
                .iter()
                .zip(gr.iter_mut())
                .zip(gs.iter_mut())
                .zip(hs.iter().zip(hr))
            {
                (*r, *s) = (g * x, g * y);
            }
        }
    }
}

/// The constraint's part of ∂L/∂(q, q̇) for state `s`, once `rbar` holds
/// r̄hs = K⁻¹λ̄ and `gdq` the G term: through rhs = A M⁻¹N + Ȧq̇ and
/// K = A M⁻¹Aᵀ (K̄ = −r̄hs λᵀ), then each bar's q_a − q_b and q̇_a − q̇_b
/// onto its ends, into `gqv` (feature-major `2d × nodes`).
fn constraint_input_grads(
    m: &Model,
    s: usize,
    nodes: usize,
    inv_m: &[f64],
    (dq, lam, rbar): (&[f64], &[f64], &[f64]),
    (x, out): (&[f64], &[f64]),
    (gdq, gqv): (&mut [f64], &mut [f64]),
) {
    let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
    let base = s * n;
    let minv = |p: usize| inv_m[m.plan.types[p]];
    let v = |row: usize, c: usize| x[(t + d + c) * nodes + row];
    for (r, bar) in m.plan.bars.iter().enumerate() {
        let a = base + bar.a;
        for c in 0..d {
            let (fb, vb) = match bar.b {
                BarEnd::Particle(b) => (minv(b) * out[c * nodes + base + b], v(base + b, c)),
                BarEnd::Fixed(_) => (0.0, 0.0),
            };
            gdq[r * d + c] += rbar[r] * (minv(bar.a) * out[c * nodes + a] - fb);
            let gdv = 2.0 * rbar[r] * (v(a, c) - vb);
            gqv[(d + c) * nodes + a] += gdv;
            if let BarEnd::Particle(b) = bar.b {
                gqv[(d + c) * nodes + base + b] -= gdv;
            }
        }
    }
    for p in 0..n {
        let mi = minv(p);
        for &(r, sr) in &m.incid[p] {
            for &(r2, s2) in &m.incid[p] {
                let coef = -mi * sr * s2 * rbar[r] * lam[r2];
                for c in 0..d {
                    gdq[r * d + c] += coef * dq[r2 * d + c];
                    gdq[r2 * d + c] += coef * dq[r * d + c];
                }
            }
        }
    }
    for (r, bar) in m.plan.bars.iter().enumerate() {
        for c in 0..d {
            gqv[c * nodes + base + bar.a] += gdq[r * d + c];
            if let BarEnd::Particle(b) = bar.b {
                gqv[c * nodes + base + b] -= gdq[r * d + c];
            }
        }
    }
}
