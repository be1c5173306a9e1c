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

use super::bars::BarForce;
use super::dense::{dot, dots, squareplus_in_place, sum, times_squareplus_grad, Linear, Mlp};
use super::gather::{copy_row, gather_rows, scatter_add_rows, Gather};
use super::named::Named;
use super::samples::Samples;
use super::EngineError;
use crate::gnode::plan::GraphPlan;
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

    /// `states` and their target accelerations (one per state, or none)
    /// packed for this network ([`Samples`]). Build them once per data set.
    ///
    /// # Panics
    /// If a state or target does not fit the graph, or there are targets but
    /// not one per state.
    pub fn samples<'a>(&self, states: &'a [State], targets: &'a [Vec<f64>]) -> Samples<'a> {
        Samples::new(self.plan.n, self.plan.dim, true, states, targets)
    }

    /// The loss of the states `idx` of `samples` against their targets, and
    /// its gradient into `grad`.
    ///
    /// # Panics
    /// If `samples` were not made by [`Potential::samples`] for this graph
    /// with targets.
    pub fn loss_grad(
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
    pub fn loss(&mut self, theta: &[f64], samples: &Samples, idx: &[usize]) -> f64 {
        let count = (idx.len() * self.plan.ndof()).max(1) as f64;
        super::mean_loss(count, None, |fold| {
            self.run(theta, samples, idx, None, fold)
        })
    }

    /// Predicted accelerations f / m of `states` (node-major, one vector
    /// each): the forward pass and the force, for rollouts.
    pub fn accelerations(&mut self, theta: &[f64], states: &[State]) -> Vec<Vec<f64>> {
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

    /// The forward pass, keeping every MLP's hidden activations.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    fn forward(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, t, rounds) = net.sizes();
        slots(&mut self.apps, net.mlps.len());
        slots(&mut self.h, rounds + 1);
        slots(&mut self.e, rounds + 1);
        slots(&mut self.ein, rounds);
        slots(&mut self.nin, rounds);
        let x = &self.x.v[..(t + d) * nodes];
        let h0 = room(&mut self.h[0].v, l * nodes);
        mlp_forward(net.node_em(), th, x, nodes, &mut self.apps[0], h0);
        squareplus_in_place(h0);
        let e0 = room(&mut self.e[0].v, l * edges);
        mlp_forward(
            net.edge_em(),
            th,
            &self.w.v[..d * edges],
            edges,
            &mut self.apps[1],
            e0,
        );
        squareplus_in_place(e0);
        for r in 0..rounds {
            let (we, wv) = net.round(r);
            let ein = room(&mut self.ein[r].v, 3 * l * edges);
            let (e, h) = (&self.e[r].v[..l * edges], &self.h[r].v[..l * nodes]);
            edge_update_inputs(ein, e, h, (&self.recv, &self.send));
            let e_new = room(&mut self.e[r + 1].v, l * edges);
            mlp_forward(we, th, ein, edges, &mut self.apps[2 + 2 * r], e_new);
            squareplus_in_place(e_new);
            let nin = room(&mut self.nin[r].v, 2 * l * nodes);
            node_update_inputs(nin, &self.h[r].v[..l * nodes], e_new, &self.recv);
            let h_new = room(&mut self.h[r + 1].v, l * nodes);
            mlp_forward(wv, th, nin, nodes, &mut self.apps[3 + 2 * r], h_new);
            squareplus_in_place(h_new);
        }
        let k = net.readout();
        let energy = room(&mut self.energy, nodes.max(edges));
        let h = &self.h[rounds].v[..l * nodes];
        mlp_forward(
            &net.mlps[k],
            th,
            h,
            nodes,
            &mut self.apps[k],
            &mut energy[..nodes],
        );
        let e = &self.e[rounds].v[..l * edges];
        mlp_forward(
            &net.mlps[k + 1],
            th,
            e,
            edges,
            &mut self.apps[k + 1],
            &mut energy[..edges],
        );
    }

    /// The force f = −∂V/∂q into `f` (`d × N`): the reverse pass of V with
    /// respect to the inputs only.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    fn force(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, t, rounds) = net.sizes();
        let ones = room(&mut self.ones, nodes.max(edges));
        ones.fill(1.0);
        let k = net.readout();
        let s = &mut self.s;
        let gh = room(&mut self.gh.v, l * nodes);
        mlp_input_grad(
            &net.mlps[k],
            th,
            &self.apps[k],
            &ones[..nodes],
            nodes,
            gh,
            s,
        );
        let ge = room(&mut self.ge.v, l * edges);
        mlp_input_grad(
            &net.mlps[k + 1],
            th,
            &self.apps[k + 1],
            &ones[..edges],
            edges,
            ge,
            s,
        );
        for r in (0..rounds).rev() {
            let (we, wv) = net.round(r);
            times_squareplus_grad(gh, &self.h[r + 1].v[..l * nodes]);
            let gnin = room(&mut self.gin.v, 2 * l * nodes);
            mlp_input_grad(wv, th, &self.apps[3 + 2 * r], gh, nodes, gnin, s);
            let (gh_part, gagg) = gnin.split_at(l * nodes);
            gh.copy_from_slice(gh_part);
            gather_rows(ge, gagg, &self.recv, Gather::Add);
            times_squareplus_grad(ge, &self.e[r + 1].v[..l * edges]);
            let gein = room(&mut self.gin.v, 3 * l * edges);
            mlp_input_grad(we, th, &self.apps[2 + 2 * r], ge, edges, gein, s);
            let (ge_part, ghrs) = gein.split_at(l * edges);
            ge.copy_from_slice(ge_part);
            let (ghr, ghs) = ghrs.split_at(l * edges);
            scatter_add_rows(gh, ghr, &self.recv);
            scatter_add_rows(gh, ghs, &self.send);
        }
        times_squareplus_grad(gh, &self.h[0].v[..l * nodes]);
        let gx = room(&mut self.gin.t, (t + d) * nodes);
        mlp_input_grad(net.node_em(), th, &self.apps[0], gh, nodes, gx, s);
        times_squareplus_grad(ge, &self.e[0].v[..l * edges]);
        let gw = room(&mut self.gin.v, d * edges);
        mlp_input_grad(net.edge_em(), th, &self.apps[1], ge, edges, gw, s);
        // ∂V/∂q through the node inputs' q rows and the edges' w = q_recv − q_send.
        let f = room(&mut self.f, d * nodes);
        f.copy_from_slice(&gx[t * nodes..(t + d) * nodes]);
        scatter_add_rows(f, gw, &self.recv);
        gw.iter_mut().for_each(|g| *g = -*g);
        scatter_add_rows(f, gw, &self.send);
        f.iter_mut().for_each(|g| *g = -*g);
    }

    /// The loss of the forces in `f` against the targets, ∂L/∂(∂V/∂q) into
    /// `u` (times `scale`) and the log-masses' gradients into `grad` (zeroed
    /// first).
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    fn seed(
        &mut self,
        net: &Net,
        (plan, masses): (&GraphPlan, &[f64]),
        th: &[f64],
        (samples, sel): (&Samples, &[usize]),
        scale: Option<f64>,
    ) {
        let (n, d) = (plan.n, plan.dim);
        let nodes = sel.len() * n;
        let sc = scale.unwrap_or(0.0);
        let grad = room(&mut self.grad, th.len());
        grad.fill(0.0);
        let u = room(&mut self.u, d * nodes);
        let mut sse = 0.0;
        for (s, &i) in sel.iter().enumerate() {
            // A record's rows: q, q̇, the target.
            let rec = samples.record(i).expect("packed samples");
            let (v, target) = (&rec[d * n..2 * d * n], &rec[2 * d * n..3 * d * n]);
            for (p, &ty) in plan.types.iter().enumerate() {
                let (lm, m) = (net.log_mass + ty, net.mass(th, ty));
                for c in 0..d {
                    let at = c * nodes + s * n + p;
                    let (f, tv, vv) = (self.f[at], target[c * n + p], v[c * n + p]);
                    match net.spec.loss {
                        PotentialLoss::Acceleration => {
                            let a = f / m;
                            let r = a - tv;
                            sse += r * r;
                            let ga = 2.0 * r * sc;
                            u[at] = ga / m;
                            // ∂a/∂log m = −a.
                            grad[lm] -= ga * a;
                        }
                        PotentialLoss::Hamilton => {
                            let mt = masses[p];
                            let qd = mt * vv / m;
                            let (rq, rp) = (qd - vv, f - mt * tv);
                            sse += 0.5 * (rq * rq + rp * rp);
                            u[at] = rp * sc;
                            grad[lm] -= rq * sc * qd;
                        }
                    }
                }
            }
        }
        self.sse = sse;
        // ∂L/∂f → ∂L/∂g, g = ∂V/∂q: f = −g, or through the bars' multipliers
        // (which depend on the masses too: ∂M⁻¹/∂log m = −M⁻¹).
        if plan.bars.is_empty() {
            u.iter_mut().for_each(|x| *x = -*x);
            return;
        }
        let gminv = room(&mut self.gminv, d * nodes);
        gminv.fill(0.0);
        self.bars
            .reverse(plan, &self.minv, &self.f[..d * nodes], u, gminv);
        for s in 0..sel.len() {
            for (p, &ty) in plan.types.iter().enumerate() {
                for c in 0..d {
                    grad[net.log_mass + ty] -= gminv[c * nodes + s * n + p] * self.minv[p];
                }
            }
        }
    }

    /// The tangent of the forward pass along q̇ = u (= ∂L/∂(∂V/∂q)): every
    /// latent's tangent and every MLP's hidden tangents.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    fn tangent(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, t, rounds) = net.sizes();
        let xt = &mut self.x.t[..(t + d) * nodes];
        xt[t * nodes..].copy_from_slice(&self.u[..d * nodes]);
        let wt = room(&mut self.w.t, d * edges);
        differences(wt, &self.u[..d * nodes], &self.recv, &self.send);
        let (h, ht) = self.h[0].tangents(l * nodes);
        mlp_tangent(net.node_em(), th, xt, nodes, &mut self.apps[0], ht);
        times_squareplus_grad(ht, h);
        let (e, et) = self.e[0].tangents(l * edges);
        mlp_tangent(net.edge_em(), th, wt, edges, &mut self.apps[1], et);
        times_squareplus_grad(et, e);
        for r in 0..rounds {
            let (we, wv) = net.round(r);
            let eint = room(&mut self.ein[r].t, 3 * l * edges);
            let (et, ht) = (&self.e[r].t[..l * edges], &self.h[r].t[..l * nodes]);
            edge_update_inputs(eint, et, ht, (&self.recv, &self.send));
            let (e_new, et_new) = self.e[r + 1].tangents(l * edges);
            mlp_tangent(we, th, eint, edges, &mut self.apps[2 + 2 * r], et_new);
            times_squareplus_grad(et_new, e_new);
            let nint = room(&mut self.nin[r].t, 2 * l * nodes);
            node_update_inputs(nint, &self.h[r].t[..l * nodes], et_new, &self.recv);
            let (h_new, ht_new) = self.h[r + 1].tangents(l * nodes);
            mlp_tangent(wv, th, nint, nodes, &mut self.apps[3 + 2 * r], ht_new);
            times_squareplus_grad(ht_new, h_new);
        }
        // The readouts' hidden tangents (their output tangent, u·∂V/∂q, is
        // what the reverse pass starts from, and is not needed itself).
        let k = net.readout();
        let out = room(&mut self.energy, nodes.max(edges));
        let ht = &self.h[rounds].t[..l * nodes];
        mlp_tangent(
            &net.mlps[k],
            th,
            ht,
            nodes,
            &mut self.apps[k],
            &mut out[..nodes],
        );
        let et = &self.e[rounds].t[..l * edges];
        mlp_tangent(
            &net.mlps[k + 1],
            th,
            et,
            edges,
            &mut self.apps[k + 1],
            &mut out[..edges],
        );
    }

    /// The reverse pass of (values, tangents) from the readouts' output
    /// tangents (seeded 1: ∂L/∂θ = ∂(u·∂V/∂q)/∂θ) to every weight,
    /// accumulated into `grad`.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    fn reverse(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, t, rounds) = net.sizes();
        let rows = nodes.max(edges);
        room(&mut self.zeros, rows).fill(0.0);
        let seed = room(&mut self.ones, rows);
        seed.fill(1.0);
        let (seed, zeros) = (&self.ones[..rows], &self.zeros[..rows]);
        let (grad, s) = (&mut self.grad[..th.len()], &mut self.s);
        let k = net.readout();
        let (gh, ght) = self.gh.both(l * nodes);
        let (h, e) = (&self.h[rounds], &self.e[rounds]);
        mlp_dual_reverse(
            &net.mlps[k],
            (th, &mut *grad),
            (&h.v[..l * nodes], &h.t[..l * nodes]),
            &self.apps[k],
            (&zeros[..nodes], &seed[..nodes], nodes),
            Some((&mut *gh, &mut *ght)),
            s,
        );
        let (ge, get) = self.ge.both(l * edges);
        mlp_dual_reverse(
            &net.mlps[k + 1],
            (th, &mut *grad),
            (&e.v[..l * edges], &e.t[..l * edges]),
            &self.apps[k + 1],
            (&zeros[..edges], &seed[..edges], edges),
            Some((&mut *ge, &mut *get)),
            s,
        );
        for r in (0..rounds).rev() {
            self.reverse_round(net, th, r, (nodes, edges));
        }
        let (gh, ght) = self.gh.both(l * nodes);
        let (ge, get) = self.ge.both(l * edges);
        let (grad, s) = (&mut self.grad[..th.len()], &mut self.s);
        let h0 = &self.h[0];
        act_reverse(&h0.v[..l * nodes], &h0.t[..l * nodes], gh, ght);
        mlp_dual_reverse(
            net.node_em(),
            (th, &mut *grad),
            (&self.x.v[..(t + d) * nodes], &self.x.t[..(t + d) * nodes]),
            &self.apps[0],
            (gh, ght, nodes),
            None,
            s,
        );
        let e0 = &self.e[0];
        act_reverse(&e0.v[..l * edges], &e0.t[..l * edges], ge, get);
        mlp_dual_reverse(
            net.edge_em(),
            (th, &mut *grad),
            (&self.w.v[..d * edges], &self.w.t[..d * edges]),
            &self.apps[1],
            (ge, get, edges),
            None,
            s,
        );
    }
    /// [`Chunk::reverse`] through round `r`: from the adjoints of its output
    /// latents (in `gh`, `ge`) to those of its inputs.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    fn reverse_round(&mut self, net: &Net, th: &[f64], r: usize, (nodes, edges): (usize, usize)) {
        let l = net.spec.latent;
        let (gh, ght) = self.gh.both(l * nodes);
        let (ge, get) = self.ge.both(l * edges);
        let (grad, s) = (&mut self.grad[..th.len()], &mut self.s);
        let (we, wv) = net.round(r);
        let h1 = &self.h[r + 1];
        act_reverse(&h1.v[..l * nodes], &h1.t[..l * nodes], gh, ght);
        let nin = &self.nin[r];
        let (gn, gnt) = (
            room(&mut self.gin.v, 2 * l * nodes),
            room(&mut self.gin.t, 2 * l * nodes),
        );
        mlp_dual_reverse(
            wv,
            (th, &mut *grad),
            (&nin.v[..2 * l * nodes], &nin.t[..2 * l * nodes]),
            &self.apps[3 + 2 * r],
            (gh, ght, nodes),
            Some((&mut *gn, &mut *gnt)),
            s,
        );
        gh.copy_from_slice(&gn[..l * nodes]);
        ght.copy_from_slice(&gnt[..l * nodes]);
        gather_rows(ge, &gn[l * nodes..], &self.recv, Gather::Add);
        gather_rows(get, &gnt[l * nodes..], &self.recv, Gather::Add);
        let e1 = &self.e[r + 1];
        act_reverse(&e1.v[..l * edges], &e1.t[..l * edges], ge, get);
        let ein = &self.ein[r];
        let (gn, gnt) = (
            room(&mut self.gin.v, 3 * l * edges),
            room(&mut self.gin.t, 3 * l * edges),
        );
        mlp_dual_reverse(
            we,
            (th, &mut *grad),
            (&ein.v[..3 * l * edges], &ein.t[..3 * l * edges]),
            &self.apps[2 + 2 * r],
            (ge, get, edges),
            Some((&mut *gn, &mut *gnt)),
            s,
        );
        ge.copy_from_slice(&gn[..l * edges]);
        get.copy_from_slice(&gnt[..l * edges]);
        let (ghr, ghs) = gn[l * edges..].split_at(l * edges);
        scatter_add_rows(gh, ghr, &self.recv);
        scatter_add_rows(gh, ghs, &self.send);
        let (ghr, ghs) = gnt[l * edges..].split_at(l * edges);
        scatter_add_rows(ght, ghr, &self.recv);
        scatter_add_rows(ght, ghs, &self.send);
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

/// `y` (`out × r`) = Wᵀx, plus the bias when `bias`; `x` is `inp × r`.
#[inline(always)]
#[allow(clippy::inline_always)]
fn affine(th: &[f64], l: &Linear, x: &[f64], r: usize, y: &mut [f64], bias: bool) {
    let y = &mut y[..l.out * r];
    for (j, yj) in y.chunks_exact_mut(r).enumerate() {
        yj.fill(if bias { th[l.b + j] } else { 0.0 });
    }
    for (i, xi) in x[..l.inp * r].chunks_exact(r).enumerate() {
        let wi = &th[l.w + i * l.out..][..l.out];
        for (yj, &wv) in y.chunks_exact_mut(r).zip(wi) {
            for (yv, xv) in yj.iter_mut().zip(xi) {
                *yv += wv * xv;
            }
        }
    }
}

/// `gx` (`inp × r`) = W gy.
#[inline(always)]
#[allow(clippy::inline_always)]
fn affine_t(th: &[f64], l: &Linear, gy: &[f64], r: usize, gx: &mut [f64]) {
    for (i, gxi) in gx[..l.inp * r].chunks_exact_mut(r).enumerate() {
        gxi.fill(0.0);
        let wi = &th[l.w + i * l.out..][..l.out];
        for (gyj, &wv) in gy[..l.out * r].chunks_exact(r).zip(wi) {
            for (gv, yv) in gxi.iter_mut().zip(gyj) {
                *gv += wv * yv;
            }
        }
    }
}

/// ∂W += x gyᵀ, and ∂b += Σ_rows gy when `bias`.
#[inline(always)]
#[allow(clippy::inline_always)]
fn affine_w(g: &mut [f64], l: &Linear, x: &[f64], gy: &[f64], r: usize, bias: bool) {
    let gy = &gy[..l.out * r];
    if bias {
        for (j, gyj) in gy.chunks_exact(r).enumerate() {
            g[l.b + j] += sum(gyj);
        }
    }
    let gyj = |j: usize| &gy[j * r..(j + 1) * r];
    for (i, xi) in x[..l.inp * r].chunks_exact(r).enumerate() {
        let gw = &mut g[l.w + i * l.out..][..l.out];
        // Eight, then four outputs per pass over x_i (the AVX2 dots).
        let mut j = 0;
        while j + 8 <= l.out {
            let d: [f64; 8] = dots(xi, std::array::from_fn(|o| gyj(j + o)));
            gw[j..j + 8].iter_mut().zip(d).for_each(|(g, d)| *g += d);
            j += 8;
        }
        while j + 4 <= l.out {
            let d: [f64; 4] = dots(xi, std::array::from_fn(|o| gyj(j + o)));
            gw[j..j + 4].iter_mut().zip(d).for_each(|(g, d)| *g += d);
            j += 4;
        }
        for (o, gv) in gw.iter_mut().enumerate().skip(j) {
            *gv += dot(xi, gyj(o));
        }
    }
}

/// Through y = sqp(z) in reverse for a (value, tangent) pair: from the
/// adjoints (ȳ, ẏ̄) in `(g, gt)` to (z̄, ż̄) in place, given y and ẏ:
/// ż̄ = s'·ẏ̄ and z̄ = s'·ȳ + s''·ż·ẏ̄, where ż = ẏ / s' and, from y alone,
/// s' = y²/(1 + y²) and s''/s' = 2y/(1 + y²)².
#[inline(always)]
#[allow(clippy::inline_always)]
fn act_reverse(y: &[f64], yt: &[f64], g: &mut [f64], gt: &mut [f64]) {
    for (((&y, &yt), gv), gtv) in y.iter().zip(yt).zip(g.iter_mut()).zip(gt.iter_mut()) {
        let q = 1.0 / (1.0 + y * y);
        let s1 = y * y * q;
        *gv = s1 * *gv + 2.0 * y * q * q * yt * *gtv;
        *gtv *= s1;
    }
}

/// `y = mlp(x)` over `r` rows (none: nothing to do), keeping the hidden
/// activations in `app`.
#[inline(always)]
#[allow(clippy::inline_always)]
fn mlp_forward(m: &Mlp, th: &[f64], x: &[f64], r: usize, app: &mut App, y: &mut [f64]) {
    if r == 0 {
        return;
    }
    let k = m.layers.len();
    slots(&mut app.a, k - 1);
    slots(&mut app.at, k - 1);
    for (li, l) in m.layers.iter().enumerate() {
        let (done, rest) = app.a.split_at_mut(li);
        let inp = if li == 0 { x } else { &done[li - 1][..] };
        if li + 1 == k {
            affine(th, l, inp, r, y, true);
        } else {
            let out = room(&mut rest[0], l.out * r);
            affine(th, l, inp, r, out, true);
            squareplus_in_place(out);
        }
    }
}

/// `gx = (∂y/∂x)ᵀ gy` from the activations [`mlp_forward`] kept (inputs
/// only: no parameter gradients). `s` is scratch.
#[inline(always)]
#[allow(clippy::inline_always)]
fn mlp_input_grad(
    m: &Mlp,
    th: &[f64],
    app: &App,
    gy: &[f64],
    r: usize,
    gx: &mut [f64],
    s: &mut [Vec<f64>; 4],
) {
    if r == 0 {
        return;
    }
    let [cur, next, ..] = s;
    let mut first = true;
    for li in (1..m.layers.len()).rev() {
        let l = &m.layers[li];
        let g: &[f64] = if first { gy } else { &cur[..l.out * r] };
        let n = room(next, l.inp * r);
        affine_t(th, l, g, r, n);
        times_squareplus_grad(n, &app.a[li - 1][..l.inp * r]);
        std::mem::swap(cur, next);
        first = false;
    }
    let g: &[f64] = if first { gy } else { cur };
    affine_t(th, &m.layers[0], g, r, gx);
}

/// The tangent `ẏ = (∂y/∂x) ẋ`, keeping the hidden tangents in `app`.
#[inline(always)]
#[allow(clippy::inline_always)]
fn mlp_tangent(m: &Mlp, th: &[f64], xt: &[f64], r: usize, app: &mut App, yt: &mut [f64]) {
    if r == 0 {
        return;
    }
    let k = m.layers.len();
    for (li, l) in m.layers.iter().enumerate() {
        let (done, rest) = app.at.split_at_mut(li);
        let inp = if li == 0 { xt } else { &done[li - 1][..] };
        if li + 1 == k {
            affine(th, l, inp, r, yt, false);
        } else {
            let out = room(&mut rest[0], l.out * r);
            affine(th, l, inp, r, out, false);
            times_squareplus_grad(out, &app.a[li][..l.out * r]);
        }
    }
}

/// The reverse pass of the pair (y, ẏ) = (mlp(x), (∂y/∂x) ẋ): from the
/// adjoints (ȳ, ẏ̄) over `r` rows, accumulates every weight's gradient into
/// `g` and, when `gx` is given, writes (x̄, ẋ̄) there. `s` is scratch.
#[inline(always)]
#[allow(clippy::inline_always)]
fn mlp_dual_reverse(
    m: &Mlp,
    (th, g): (&[f64], &mut [f64]),
    (x, xt): (&[f64], &[f64]),
    app: &App,
    (gy, gyt, r): (&[f64], &[f64], usize),
    gx: Option<(&mut [f64], &mut [f64])>,
    s: &mut [Vec<f64>; 4],
) {
    if r == 0 {
        // No rows (a graph without edges): nothing flows.
        return;
    }
    let [c, ct, n, nt] = s;
    let mut first = true;
    for li in (0..m.layers.len()).rev() {
        let l = &m.layers[li];
        let (gv, gt): (&[f64], &[f64]) = if first {
            (gy, gyt)
        } else {
            (&c[..l.out * r], &ct[..l.out * r])
        };
        let (xi, xti) = if li == 0 {
            (x, xt)
        } else {
            (&app.a[li - 1][..l.inp * r], &app.at[li - 1][..l.inp * r])
        };
        affine_w(g, l, xi, gv, r, true);
        affine_w(g, l, xti, gt, r, false);
        if li > 0 {
            let (nv, ntv) = (room(n, l.inp * r), room(nt, l.inp * r));
            affine_t(th, l, gv, r, nv);
            affine_t(th, l, gt, r, ntv);
            act_reverse(xi, xti, nv, ntv);
            std::mem::swap(c, n);
            std::mem::swap(ct, nt);
            first = false;
        } else if let Some((gxv, gxt)) = gx {
            affine_t(th, l, gv, r, gxv);
            affine_t(th, l, gt, r, gxt);
            return;
        }
    }
}
