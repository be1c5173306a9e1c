//! One chunk of a batch: the forward pass of the GNODE family over several
//! states of one graph at once (the states side by side as one disjoint
//! graph, feature-major), the squared error against the targets, and the
//! hand-written reverse pass. Every buffer lives here and is reused.
//!
//! This file holds the model, the buffers and the entry points (a batch
//! chunk's [`Chunk::run`], inference's [`Chunk::forward_one`], planning's
//! [`Chunk::input_vjp`]); the passes live beside it, one file each:
//! [`buffers`] sizes and lays out (with [`contacts`]' pairs), [`inputs`] fills the node inputs,
//! [`forward`] runs the encoder, message passing and decoder, [`constraints`]
//! applies the bars (both directions), and [`reverse`] is the hand-written
//! reverse pass. The graph passes run inside one AVX-512/AVX2 copy each
//! ([`widest!`]): their stages are `#[inline(always)]` to stay inside it.

mod buffers;
mod constraints;
mod contacts;
mod forward;
mod inputs;
mod reverse;

use contacts::Contacts;

use super::dense::{Mlp, Tape};
use super::gather::IndexSums;
use super::layout::Layout;
use super::samples::Samples;
use super::split::{Scratch, Split};
use crate::gnode::arch::{Arch, Block, Decoder, NodeInput};
use crate::gnode::graph_plan::{BarEnd, GraphPlan};

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
    ($(#[$doc:meta])* $vis:vis fn $name:ident => $any:ident($($arg:ident: $ty:ty),* $(,)?)) => {
        $(#[$doc])*
        $vis fn $name(&mut self, $($arg: $ty),*) {
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
pub(super) use widest;

impl Chunk {
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
}
