//! LGN and HGN (the baselines of `baselines::{lgn, hgn}`) on the executor.
//! Both learn a potential V_θ(q) with a full graph network and one mass per
//! particle type, m = exp(log_mass); the force is f = −∂V/∂q, and
//! - LGN: q̈ = f / m, loss the mean squared error of q̈;
//! - HGN: q̇ = p / m, ṗ = f with p = m_true v, loss
//!   ½ (mean (q̇ − v)² + mean (ṗ − m_true q̈_target)²).
//!
//! The potential, as the candle reference (`baselines::graphnet`:
//! non-residual rounds, w_ij = q_i − q_j the only edge feature) writes it:
//! - encode: h = sqp(φ_v([onehot, q])), e = sqp(φ_e(w_ij));
//! - each round: e ← sqp(φ_E([e, h_recv, h_send])); h ← sqp(φ_V([h, Σ_recv e]));
//! - V = Σ_nodes φ_no(h) + Σ_edges φ_eo(e).
//!
//! A training step is four passes: the forward pass; its reverse pass from
//! V down to q (the force, all a rollout needs, with the bars' multipliers
//! where there are bars); then, with u = ∂L/∂f, the
//! tangent of the forward pass along q̇ = w, w = ∂L/∂(∂V/∂q) (−u, or through
//! the bars' multipliers, [`super::bars`]), whose output is w·∂V/∂q; and the
//! reverse pass of the pair (values, tangents), which gives
//! ∂L/∂θ = ∂(w·∂V/∂q)/∂θ. Each MLP keeps its hidden activations and their
//! tangents; squareplus's first and second derivatives come from its output.
//! Checked against candle's autodiff and finite differences
//! (`tests/potential_engine.rs`).

mod force;
mod gradient;
mod mlp;

use super::bars::BarForce;
use super::dense::Mlp;
use super::gather::{copy_row, gather_rows, scatter_add_rows, Gather};
use super::model::ExecutorModel;
use super::named::Named;
use super::samples::Samples;
use super::EngineError;
use crate::gnode::graph_plan::GraphPlan;
use crate::system::{Graph, State};

/// What the loss compares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PotentialLoss {
    /// LGN: the mean squared error of q̈ = f / m.
    Acceleration,
    /// HGN: ½ (mean (q̇ − v)² + mean (ṗ − m_true q̈)²).
    Hamilton,
}

/// Sizes of an LGN or HGN (as `baselines::net::BaselineHyper` sets them).
#[derive(Clone, Copy, Debug)]
pub struct PotentialSpec {
    /// Spatial dimension.
    pub dim: usize,
    /// One-hot width.
    pub types: usize,
    /// Hidden units of every MLP (one hidden layer).
    pub hidden: usize,
    /// Latent width.
    pub latent: usize,
    /// Message-passing rounds.
    pub rounds: usize,
    /// LGN's loss or HGN's.
    pub loss: PotentialLoss,
}

/// The MLPs at their offsets in the flat parameter vector, in the order of
/// a chunk's [`App`]s: encoders, rounds (edge, node), readouts (node, edge).
#[derive(Clone, Debug)]
struct Net {
    spec: PotentialSpec,
    mlps: Vec<Mlp>,
    /// Offset of the log-masses (one per type).
    log_mass: usize,
}

impl Net {
    fn new(spec: PotentialSpec, params: &[(String, usize)]) -> Result<Self, EngineError> {
        let named = Named::new(params);
        let (h, l, d, t) = (spec.hidden, spec.latent, spec.dim, spec.types);
        let mlp = |name: &str, sizes: &[usize]| named.mlp("LGN/HGN", name, sizes);
        let mut mlps = vec![mlp("node_em", &[t + d, h, l])?, mlp("edge_em", &[d, h, l])?];
        for r in 0..spec.rounds {
            mlps.push(mlp(&format!("gn{r}.e"), &[3 * l, h, l])?);
            mlps.push(mlp(&format!("gn{r}.v"), &[2 * l, h, l])?);
        }
        mlps.push(mlp("node_out", &[l, h, 1])?);
        mlps.push(mlp("edge_out", &[l, h, 1])?);
        Ok(Self {
            spec,
            mlps,
            log_mass: named.find("LGN/HGN", "log_mass", t)?,
        })
    }

    fn node_em(&self) -> &Mlp {
        &self.mlps[0]
    }

    fn edge_em(&self) -> &Mlp {
        &self.mlps[1]
    }

    /// Round `r`'s edge and node updates.
    fn round(&self, r: usize) -> (&Mlp, &Mlp) {
        (&self.mlps[2 + 2 * r], &self.mlps[3 + 2 * r])
    }

    /// Index of the node readout's [`App`]; the edge readout's follows.
    fn readout(&self) -> usize {
        2 + 2 * self.spec.rounds
    }

    /// Latent width, dimension, one-hot width and rounds.
    fn sizes(&self) -> (usize, usize, usize, usize) {
        let s = &self.spec;
        (s.latent, s.dim, s.types, s.rounds)
    }

    /// The learned mass of type `ty`.
    fn mass(&self, th: &[f64], ty: usize) -> f64 {
        th[self.log_mass + ty].exp()
    }
}

/// LGN's or HGN's loss, gradient and accelerations on states of one graph
/// (fixed edges and bars), over `threads` threads; the result does not
/// depend on the thread count.
pub struct Potential {
    net: Net,
    plan: GraphPlan,
    /// The true masses (HGN's momenta p = m v).
    masses: Vec<f64>,
    chunks: Vec<Chunk>,
    crew: Option<super::crew::Crew>,
}

impl Potential {
    /// An LGN or HGN of `spec` for `graph`, its parameters laid out as
    /// `params` (name and scalar count in the flat vector's order). Graphs
    /// with contacts or kinematic particles are refused (LGN and HGN model
    /// closed systems).
    pub fn new(
        spec: PotentialSpec,
        params: &[(String, usize)],
        graph: &Graph,
        threads: usize,
    ) -> Result<Self, EngineError> {
        let types = graph.type_count();
        if graph.dim != spec.dim || types > spec.types {
            return Err(EngineError::Parameters(format!(
                "an LGN/HGN of {}D and {} particle types cannot take a {}D graph with {types}",
                spec.dim, spec.types, graph.dim
            )));
        }
        let plan = GraphPlan::new(graph);
        if plan.has_contacts() || graph.n_kinematic() > 0 {
            return Err(EngineError::Parameters(
                "LGN and HGN do not model contacts or kinematic particles".into(),
            ));
        }
        Ok(Self {
            net: Net::new(spec, params)?,
            plan,
            masses: graph.masses.clone(),
            chunks: vec![],
            crew: super::crew(threads)?,
        })
    }

    /// The chunks of `idx` across the threads, folded in chunk order.
    fn run(
        &mut self,
        theta: &[f64],
        samples: &Samples,
        idx: &[usize],
        scale: Option<f64>,
        fold: impl FnMut(&Chunk),
    ) {
        assert!(
            samples.laid_out_for(self.plan.n, self.plan.dim, true),
            "samples laid out for another model: make them with this network's `samples`"
        );
        let parts = super::split(idx.len(), self.plan.n + self.plan.recv.len());
        let (net, plan, masses) = (&self.net, &self.plan, &self.masses[..]);
        let work = |c: &mut Chunk, (a, b): (usize, usize)| {
            c.run(net, (plan, masses), theta, (samples, &idx[a..b]), scale);
        };
        super::in_waves(&mut self.chunks, self.crew.as_ref(), &parts, work, fold);
    }
}

impl ExecutorModel for Potential {
    /// `states` and their target accelerations (one per state, or none)
    /// packed for this network ([`Samples`]). Build them once per data set.
    ///
    /// # Panics
    /// If a state or target does not fit the graph, or there are targets but
    /// not one per state.
    fn samples<'a>(&self, states: &'a [State], targets: &'a [Vec<f64>]) -> Samples<'a> {
        Samples::new(self.plan.n, self.plan.dim, true, states, targets)
    }

    /// The loss of the states `idx` of `samples` against their targets, and
    /// its gradient into `grad`.
    ///
    /// # Panics
    /// If `samples` were not made by [`Potential::samples`] for this graph
    /// with targets.
    fn loss_grad(
        &mut self,
        theta: &[f64],
        samples: &Samples,
        idx: &[usize],
        grad: &mut [f64],
    ) -> f64 {
        let count = (idx.len() * self.plan.ndof()).max(1) as f64;
        super::mean_loss(count, Some(grad), |fold| {
            self.run(theta, samples, idx, Some(1.0 / count), fold);
        })
    }

    /// [`Potential::loss_grad`]'s loss alone.
    fn loss(&mut self, theta: &[f64], samples: &Samples, idx: &[usize]) -> f64 {
        let count = (idx.len() * self.plan.ndof()).max(1) as f64;
        super::mean_loss(count, None, |fold| {
            self.run(theta, samples, idx, None, fold)
        })
    }

    /// Predicted accelerations f / m of `states` (node-major, one vector
    /// each): the forward pass and the force, for rollouts.
    fn accelerations(&mut self, theta: &[f64], states: &[State]) -> Vec<Vec<f64>> {
        let (n, d) = (self.plan.n, self.plan.dim);
        let samples = self.samples(states, &[]);
        let per_state = n + self.plan.recv.len();
        let mut out = super::node_major_all(states.len(), (n, d), per_state, |idx, put| {
            self.run(theta, &samples, idx, None, |c| put(&c.f));
        });
        // q̈ = f / m.
        let m: Vec<f64> = self
            .plan
            .types
            .iter()
            .map(|&t| self.net.mass(theta, t))
            .collect();
        for o in &mut out {
            for (x, &mp) in o.chunks_exact_mut(d).zip(&m) {
                x.iter_mut().for_each(|v| *v /= mp);
            }
        }
        out
    }
}

/// One MLP application's hidden activations and their tangents (one buffer
/// per hidden layer, `width × rows`).
#[derive(Default)]
struct App {
    a: Vec<Vec<f64>>,
    at: Vec<Vec<f64>>,
}

/// A pair of buffers: values' adjoints and tangents' adjoints (or values
/// and tangents).
#[derive(Default)]
struct Pair {
    v: Vec<f64>,
    t: Vec<f64>,
}

impl Pair {
    /// Both buffers, grown to `len`.
    fn both(&mut self, len: usize) -> (&mut [f64], &mut [f64]) {
        (room(&mut self.v, len), room(&mut self.t, len))
    }

    /// The values (read) and the tangents (to write, grown to `len`).
    fn tangents(&mut self, len: usize) -> (&[f64], &mut [f64]) {
        (&self.v[..len], room(&mut self.t, len))
    }
}

impl super::ChunkLoss for Chunk {
    fn sse(&self) -> f64 {
        self.sse
    }

    fn grad(&self) -> &[f64] {
        &self.grad
    }
}

/// One chunk's buffers (grown to the largest chunk, then reused) and results.
#[derive(Default)]
struct Chunk {
    recv: Vec<usize>,
    send: Vec<usize>,
    /// Node inputs `(T + d) × N` and their tangents (zero but in q's rows).
    x: Pair,
    /// Edge inputs w_ij `d × E` and their tangents.
    w: Pair,
    /// Node latents before each round and after the last, `L × N` each,
    /// with their tangents.
    h: Vec<Pair>,
    /// Edge latents likewise, `L × E` each.
    e: Vec<Pair>,
    /// Per round, the updates' inputs: `[e; h_recv; h_send]` (`3L × E`) and
    /// `[h; Σ_recv e]` (`2L × N`), with their tangents.
    ein: Vec<Pair>,
    nin: Vec<Pair>,
    apps: Vec<App>,
    /// The readouts' energies (unused but by the forward pass).
    energy: Vec<f64>,
    /// Force `d × N`, and ∂L/∂f, then ∂L/∂(∂V/∂q), in `u`.
    f: Vec<f64>,
    u: Vec<f64>,
    /// The bars' multipliers, each particle's inverse learned mass and
    /// ∂L/∂(M⁻¹) per coordinate (`d × N`).
    bars: BarForce,
    minv: Vec<f64>,
    gminv: Vec<f64>,
    /// Reverse passes: adjoints of node and edge latents, of an update's
    /// inputs, and seeds.
    gh: Pair,
    ge: Pair,
    gin: Pair,
    ones: Vec<f64>,
    zeros: Vec<f64>,
    /// MLP scratch: four buffers of `width × rows`.
    s: [Vec<f64>; 4],
    sse: f64,
    grad: Vec<f64>,
}

/// `v` at least `len` long (zeros when it grows).
fn room(v: &mut Vec<f64>, len: usize) -> &mut [f64] {
    if v.len() < len {
        v.resize(len, 0.0);
    }
    &mut v[..len]
}

/// `v` holds at least `len` items.
fn slots<T: Default>(v: &mut Vec<T>, len: usize) {
    if v.len() < len {
        v.resize_with(len, T::default);
    }
}

impl Chunk {
    /// Loss (and with `scale`, its gradient times `scale`) of the states
    /// `sel` of `samples` against their targets; without targets, the
    /// forces alone (in `f`).
    fn run(
        &mut self,
        net: &Net,
        (plan, masses): (&GraphPlan, &[f64]),
        th: &[f64],
        (samples, sel): (&Samples, &[usize]),
        scale: Option<f64>,
    ) {
        #[cfg(target_arch = "x86_64")]
        if super::dense::simd() != super::dense::Simd::Portable {
            // SAFETY: the CPU supports AVX2 and FMA (`simd` checked).
            return unsafe { self.run_avx2(net, (plan, masses), th, (samples, sel), scale) };
        }
        self.run_any(net, (plan, masses), th, (samples, sel), scale);
    }

    /// [`Chunk::run`] compiled for AVX2 and FMA (the passes' loops in
    /// 4-wide vectors, [`dot`]'s fused multiply-adds in one instruction).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn run_avx2(
        &mut self,
        net: &Net,
        plan: (&GraphPlan, &[f64]),
        th: &[f64],
        data: (&Samples, &[usize]),
        scale: Option<f64>,
    ) {
        self.run_any(net, plan, th, data, scale);
    }

    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies above
    fn run_any(
        &mut self,
        net: &Net,
        (plan, masses): (&GraphPlan, &[f64]),
        th: &[f64],
        (samples, sel): (&Samples, &[usize]),
        scale: Option<f64>,
    ) {
        let nodes = sel.len() * plan.n;
        let edges = self.lay_out(net, plan, samples, sel);
        self.forward(net, th, nodes, edges);
        self.force(net, th, nodes, edges);
        if !plan.bars.is_empty() {
            self.minv.clear();
            self.minv
                .extend(plan.types.iter().map(|&ty| 1.0 / net.mass(th, ty)));
            let states = sel.iter().map(|&i| &samples.states()[i]);
            let f = &mut self.f[..plan.dim * nodes];
            self.bars.apply(plan, states, &self.minv, f);
        }
        self.sse = 0.0;
        if samples.targets().is_empty() {
            return;
        }
        self.seed(net, (plan, masses), th, (samples, sel), scale);
        if scale.is_some() {
            self.tangent(net, th, nodes, edges);
            self.reverse(net, th, nodes, edges);
        }
    }

    /// Edges and inputs of the selected states; returns the directed edges.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    fn lay_out(&mut self, net: &Net, plan: &GraphPlan, samples: &Samples, sel: &[usize]) -> usize {
        let (n, d, t) = (plan.n, plan.dim, net.spec.types);
        let nodes = sel.len() * n;
        self.recv.clear();
        self.send.clear();
        let (recv, send) = (&mut self.recv, &mut self.send);
        plan.directed_edges(sel.len(), &[], &[], |_, e| {
            recv.push(e.recv);
            send.push(e.send);
        });
        let edges = self.recv.len();
        let x = room(&mut self.x.v, (t + d) * nodes);
        x.fill(0.0);
        for (s, r) in samples.records(sel).enumerate() {
            for (p, &ty) in plan.types.iter().enumerate() {
                x[ty * nodes + s * n + p] = 1.0;
            }
            // q's rows, the record's first d rows.
            for (f, row) in r[..d * n].chunks_exact(n).enumerate() {
                copy_row(&mut x[(t + f) * nodes + s * n..][..n], row);
            }
        }
        room(&mut self.x.t, (t + d) * nodes).fill(0.0);
        let w = room(&mut self.w.v, d * edges);
        differences(
            w,
            &self.x.v[t * nodes..(t + d) * nodes],
            &self.recv,
            &self.send,
        );
        edges
    }
}

/// A round's edge-update inputs `[e; h_recv; h_send]` (`3L × E`) from the
/// edge and node latents, or from their tangents (the map is linear).
#[inline(always)]
#[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
fn edge_update_inputs(out: &mut [f64], e: &[f64], h: &[f64], (recv, send): (&[usize], &[usize])) {
    let (e_part, hrs) = out.split_at_mut(e.len());
    e_part.copy_from_slice(e);
    let (hr, hs) = hrs.split_at_mut(e.len());
    gather_rows(hr, h, recv, Gather::Set);
    gather_rows(hs, h, send, Gather::Set);
}

/// A round's node-update inputs `[h; Σ_recv e]` (`2L × N`) from the node
/// latents and the updated edge latents, or from their tangents.
#[inline(always)]
#[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
fn node_update_inputs(out: &mut [f64], h: &[f64], e_new: &[f64], recv: &[usize]) {
    let (h_part, agg) = out.split_at_mut(h.len());
    h_part.copy_from_slice(h);
    agg.fill(0.0);
    scatter_add_rows(agg, e_new, recv);
}

/// Per coordinate row: `w[e] = q[recv[e]] − q[send[e]]` (`d × E` from `d × N`).
#[inline(always)]
#[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
fn differences(w: &mut [f64], q: &[f64], recv: &[usize], send: &[usize]) {
    if recv.is_empty() {
        return;
    }
    let nodes = q.len() / (w.len() / recv.len()).max(1);
    for (wr, qr) in w.chunks_exact_mut(recv.len()).zip(q.chunks_exact(nodes)) {
        for ((wv, &i), &j) in wr.iter_mut().zip(recv).zip(send) {
            *wv = qr[i] - qr[j];
        }
    }
}
