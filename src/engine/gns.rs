//! GNS (the baseline of `baselines::gns`) on the executor: its graph
//! network's forward pass and reverse-mode gradient written by hand on the
//! feature-major layout, with the GNODE family's MLP, so that GNS trains at
//! its best speed and comparisons at equal wall-clock time are fair.
//!
//! The equations, as the candle reference (`baselines::graphnet`, residual
//! rounds with the distance as an edge feature) writes them:
//! - encode: h = sqp(φ_v([onehot, q, q̇])), e = sqp(φ_e([w_ij, |w_ij|]));
//! - each round: e ← e + φ_E([e, h_recv, h_send]); h ← h + φ_V([h, Σ_recv e]);
//! - decode: q̈ = φ_out(h).
//!
//! Loss: the mean squared error of q̈ over the free particles' coordinates.
//! Checked against candle's autodiff and finite differences
//! (`tests/gns_engine.rs`).

use super::dense::{squareplus_in_place, times_squareplus_grad, Mlp, Tape};
use super::gather::{copy_row, gather_rows, scatter_add_rows, Gather};
use super::model::ExecutorModel;
use super::samples::Samples;
use super::EngineError;
use crate::gnode::graph_plan::GraphPlan;
use crate::physics::neighbors::NeighborSearch;
use crate::system::{Graph, State};

/// Sizes of a GNS network (as `baselines::net::BaselineHyper` sets them).
#[derive(Clone, Copy, Debug)]
pub struct GnsSpec {
    /// Spatial dimension.
    pub dim: usize,
    /// One-hot width.
    pub types: usize,
    /// Hidden units of every MLP (one hidden layer).
    pub hidden: usize,
    /// Latent width.
    pub latent: usize,
    /// Processor rounds.
    pub rounds: usize,
}

/// The MLPs of a GNS at their offsets in the flat parameter vector.
#[derive(Clone, Debug)]
struct Net {
    spec: GnsSpec,
    node_em: Mlp,
    edge_em: Mlp,
    /// Per round: edge update, node update.
    rounds: Vec<(Mlp, Mlp)>,
    node_out: Mlp,
}

impl Net {
    /// The MLPs, their parameters found in `params` (name, scalar count, in
    /// the flat vector's order) under candle's names (`node_em.l0.w`, …).
    fn new(spec: GnsSpec, params: &[(String, usize)]) -> Result<Self, EngineError> {
        let named = super::named::Named::new(params);
        let (h, l, d) = (spec.hidden, spec.latent, spec.dim);
        let mlp = |name: &str, sizes: &[usize]| named.mlp("GNS", name, sizes);
        let rounds = (0..spec.rounds)
            .map(|r| {
                Ok((
                    mlp(&format!("gn{r}.e"), &[3 * l, h, l])?,
                    mlp(&format!("gn{r}.v"), &[2 * l, h, l])?,
                ))
            })
            .collect::<Result<_, EngineError>>()?;
        Ok(Self {
            spec,
            node_em: mlp("node_em", &[spec.types + 2 * d, h, l])?,
            edge_em: mlp("edge_em", &[d + 1, h, l])?,
            rounds,
            node_out: mlp("node_out", &[l, h, d])?,
        })
    }

    /// Every MLP, for sizing scratch.
    fn mlps(&self) -> impl Iterator<Item = &Mlp> {
        [&self.node_em, &self.edge_em, &self.node_out]
            .into_iter()
            .chain(self.rounds.iter().flat_map(|(e, v)| [e, v]))
    }
}

/// GNS's loss and gradient on states of one graph (contacts found at each
/// state when it has a radius), over `threads` threads; the result does not
/// depend on the thread count.
pub struct Gns {
    net: Net,
    plan: GraphPlan,
    chunks: Vec<Chunk>,
    crew: Option<super::crew::Crew>,
}

impl Gns {
    /// A GNS of `spec` for `graph`, its parameters laid out as `params`
    /// (name and scalar count in the flat vector's order).
    pub fn new(
        spec: GnsSpec,
        params: &[(String, usize)],
        graph: &Graph,
        threads: usize,
    ) -> Result<Self, EngineError> {
        let types = graph.type_count();
        if graph.dim != spec.dim || types > spec.types {
            return Err(EngineError::Parameters(format!(
                "a GNS of {}D and {} particle types cannot take a {}D graph with {types}",
                spec.dim, spec.types, graph.dim
            )));
        }
        Ok(Self {
            net: Net::new(spec, params)?,
            plan: GraphPlan::new(graph),
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
        let (net, plan) = (&self.net, &self.plan);
        let work = |c: &mut Chunk, (a, b): (usize, usize)| {
            c.run(net, plan, theta, (samples, &idx[a..b]), scale);
        };
        super::in_waves(&mut self.chunks, self.crew.as_ref(), &parts, work, fold);
    }
}

impl ExecutorModel for Gns {
    /// `states` and their target accelerations (one per state, or none)
    /// packed for this network ([`Samples`]), as [`super::Engine::samples`]
    /// packs them. Build them once per data set, not per batch.
    ///
    /// # Panics
    /// If a state or target does not fit the graph, or there are targets but
    /// not one per state.
    fn samples<'a>(&self, states: &'a [State], targets: &'a [Vec<f64>]) -> Samples<'a> {
        Samples::new(self.plan.n, self.plan.dim, true, states, targets)
    }

    /// Mean squared error of the free particles' accelerations of the
    /// states `idx` of `samples` against their targets, and its gradient
    /// into `grad`.
    ///
    /// # Panics
    /// If `samples` were not made by [`Gns::samples`] for this graph.
    fn loss_grad(
        &mut self,
        theta: &[f64],
        samples: &Samples,
        idx: &[usize],
        grad: &mut [f64],
    ) -> f64 {
        let count = (idx.len() * self.plan.free_ndof()).max(1) as f64;
        super::mean_loss(count, Some(grad), |fold| {
            self.run(theta, samples, idx, Some(1.0 / count), fold);
        })
    }

    /// [`Gns::loss_grad`]'s loss alone.
    fn loss(&mut self, theta: &[f64], samples: &Samples, idx: &[usize]) -> f64 {
        let count = (idx.len() * self.plan.free_ndof()).max(1) as f64;
        super::mean_loss(count, None, |fold| {
            self.run(theta, samples, idx, None, fold)
        })
    }

    /// Predicted accelerations of `states` (node-major, one vector each):
    /// the forward pass alone, for rollouts.
    fn accelerations(&mut self, theta: &[f64], states: &[State]) -> Vec<Vec<f64>> {
        let (n, d) = (self.plan.n, self.plan.dim);
        let samples = self.samples(states, &[]);
        let per_state = n + self.plan.recv.len();
        super::node_major_all(states.len(), (n, d), per_state, |idx, put| {
            self.run(theta, &samples, idx, None, |c| put(&c.out));
        })
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
    search: Option<NeighborSearch>,
    pairs: Vec<(usize, usize)>,
    starts: Vec<usize>,
    recv: Vec<usize>,
    send: Vec<usize>,
    /// Node inputs `(T + 2d) × N` and edge inputs `(d + 1) × E`.
    x: Vec<f64>,
    feat: Vec<f64>,
    /// Node latents before each round and after the last, `L × N` each.
    h: Vec<Vec<f64>>,
    /// Edge latents likewise, `L × E` each.
    e: Vec<Vec<f64>>,
    /// Per round: `[h_recv; h_send]` (`2L × E`) and Σ_recv e (`L × N`).
    hrs: Vec<Vec<f64>>,
    agg: Vec<Vec<f64>>,
    out: Vec<f64>,
    /// Tapes: node encoder, edge encoder, per round (edge, node), decoder.
    tapes: Vec<Tape>,
    /// Rows the tapes were made for (nodes, edges).
    taped: (usize, usize),
    /// Reverse-pass buffers.
    gh: Vec<f64>,
    gh2: Vec<f64>,
    ge: Vec<f64>,
    ge2: Vec<f64>,
    ghrs: Vec<f64>,
    gagg: Vec<f64>,
    gout: Vec<f64>,
    s1: Vec<f64>,
    s2: Vec<f64>,
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

impl Chunk {
    /// Loss (and with `scale`, its gradient times `scale`) of the states
    /// `sel` of `samples` against their targets.
    fn run(
        &mut self,
        net: &Net,
        plan: &GraphPlan,
        theta: &[f64],
        (samples, sel): (&Samples, &[usize]),
        scale: Option<f64>,
    ) {
        let nodes = sel.len() * plan.n;
        let edges = self.lay_out(net, plan, samples, sel);
        self.forward(net, theta, nodes, edges, scale.is_some());
        if samples.targets().is_empty() {
            // Inference: the accelerations are in `out`.
            self.sse = 0.0;
            return;
        }
        // The loss, and ∂L/∂q̈ into `gout`.
        let (n, d) = (plan.n, plan.dim);
        let gout = room(&mut self.gout, d * nodes);
        self.sse = 0.0;
        for (s, &i) in sel.iter().enumerate() {
            // The target's rows follow q's and q̇'s in the record.
            let target = &samples.record(i).expect("packed samples")[2 * d * n..];
            for p in 0..plan.n {
                if plan.is_kinematic(p) {
                    for c in 0..d {
                        gout[c * nodes + s * plan.n + p] = 0.0;
                    }
                    continue;
                }
                for c in 0..d {
                    let row = s * plan.n + p;
                    let r = self.out[c * nodes + row] - target[c * n + p];
                    self.sse += r * r;
                    gout[c * nodes + row] = 2.0 * r * scale.unwrap_or(0.0);
                }
            }
        }
        if scale.is_some() {
            self.backward(net, theta, nodes, edges);
        }
    }

    /// Edges and inputs of the selected states; returns the directed edges.
    fn lay_out(&mut self, net: &Net, plan: &GraphPlan, samples: &Samples, sel: &[usize]) -> usize {
        let (n, d, t) = (plan.n, plan.dim, net.spec.types);
        let nodes = sel.len() * n;
        self.pairs.clear();
        self.starts.clear();
        if plan.has_contacts() {
            let search = self.search.get_or_insert_with(|| plan.contact_search());
            for &i in sel {
                self.starts.push(self.pairs.len());
                plan.contacts(search, &samples.states()[i].q, &mut self.pairs);
            }
            self.starts.push(self.pairs.len());
        }
        self.recv.clear();
        self.send.clear();
        let (recv, send) = (&mut self.recv, &mut self.send);
        plan.directed_edges(sel.len(), &self.pairs, &self.starts, |_, e| {
            recv.push(e.recv);
            send.push(e.send);
        });
        let edges = self.recv.len();
        let x = room(&mut self.x, (t + 2 * d) * nodes);
        x.fill(0.0);
        for (s, r) in samples.records(sel).enumerate() {
            for (p, &ty) in plan.types.iter().enumerate() {
                x[ty * nodes + s * n + p] = 1.0;
            }
            // q's then q̇'s rows, the record's first 2d rows.
            for (f, row) in r[..2 * d * n].chunks_exact(n).enumerate() {
                copy_row(&mut x[(t + f) * nodes + s * n..][..n], row);
            }
        }
        let feat = room(&mut self.feat, (d + 1) * edges);
        for k in 0..edges {
            let (r, s) = (self.recv[k], self.send[k]);
            let mut sq = 0.0;
            for c in 0..d {
                let q = &self.x[(t + c) * nodes..(t + c + 1) * nodes];
                let w = q[r] - q[s];
                feat[c * edges + k] = w;
                sq += w * w;
            }
            feat[d * edges + k] = sq.sqrt();
        }
        edges
    }

    /// The forward pass, keeping what the reverse pass needs when `record`.
    fn forward(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize, record: bool) {
        let (l, rounds) = (net.spec.latent, net.rounds.len());
        self.ready_tapes(net, nodes, edges, record);
        if self.h.len() < rounds + 1 {
            self.h.resize_with(rounds + 1, Vec::new);
            self.e.resize_with(rounds + 1, Vec::new);
        }
        if self.hrs.len() < rounds {
            self.hrs.resize_with(rounds, Vec::new);
            self.agg.resize_with(rounds, Vec::new);
        }
        let x_len = (net.spec.types + 2 * net.spec.dim) * nodes;
        let h0 = room(&mut self.h[0], l * nodes);
        net.node_em
            .forward(th, &self.x[..x_len], &[], nodes, &mut self.tapes[0], h0);
        squareplus_in_place(h0);
        let e0 = room(&mut self.e[0], l * edges);
        let feat = &self.feat[..(net.spec.dim + 1) * edges];
        net.edge_em
            .forward(th, feat, &[], edges, &mut self.tapes[1], e0);
        squareplus_in_place(e0);
        for (r, (we, wv)) in net.rounds.iter().enumerate() {
            let (h_prev, h_next) = self.h.split_at_mut(r + 1);
            let (e_prev, e_next) = self.e.split_at_mut(r + 1);
            let (h, e) = (&h_prev[r][..l * nodes], &e_prev[r][..l * edges]);
            let hrs = room(&mut self.hrs[r], 2 * l * edges);
            let (hr, hs) = hrs.split_at_mut(l * edges);
            gather_rows(hr, h, &self.recv, Gather::Set);
            gather_rows(hs, h, &self.send, Gather::Set);
            let e_new = room(&mut e_next[0], l * edges);
            we.forward(th, e, hrs, edges, &mut self.tapes[2 + 2 * r], e_new);
            for (x, old) in e_new.iter_mut().zip(e) {
                *x += old;
            }
            let agg = room(&mut self.agg[r], l * nodes);
            agg.fill(0.0);
            scatter_add_rows(agg, e_new, &self.recv);
            let h_new = room(&mut h_next[0], l * nodes);
            wv.forward(th, h, agg, nodes, &mut self.tapes[3 + 2 * r], h_new);
            for (x, old) in h_new.iter_mut().zip(h) {
                *x += old;
            }
        }
        let out = room(&mut self.out, net.spec.dim * nodes);
        let last = 2 + 2 * rounds;
        net.node_out.forward(
            th,
            &self.h[rounds][..l * nodes],
            &[],
            nodes,
            &mut self.tapes[last],
            out,
        );
    }

    /// Tapes that record (training) or only hold a tile (loss alone), for
    /// `nodes` and `edges` rows.
    fn ready_tapes(&mut self, net: &Net, nodes: usize, edges: usize, record: bool) {
        // Recording tapes of enough rows serve both; tapes that only hold a
        // tile serve the loss alone.
        let built = self.tapes.len() == 3 + 2 * net.rounds.len();
        let cover = self.taped.0 >= nodes && self.taped.1 >= edges;
        if built && (cover || (!record && self.taped == (0, 0))) {
            return;
        }
        let (nr, er) = if record {
            (nodes.max(self.taped.0), edges.max(self.taped.1))
        } else {
            (0, 0)
        };
        let tape = |m: &Mlp, rows: usize| {
            if record {
                m.tape(rows)
            } else {
                m.inference_tape()
            }
        };
        self.tapes = vec![tape(&net.node_em, nr), tape(&net.edge_em, er)];
        for (we, wv) in &net.rounds {
            self.tapes.push(tape(we, er));
            self.tapes.push(tape(wv, nr));
        }
        self.tapes.push(tape(&net.node_out, nr));
        self.taped = (nr, er);
    }

    /// The reverse pass from ∂L/∂q̈ (`gout`) to every parameter (`grad`).
    fn backward(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, rounds) = (net.spec.latent, net.spec.dim, net.rounds.len());
        let width = net.mlps().map(Mlp::width).max().unwrap_or(0);
        let rows = nodes.max(edges);
        let grad = room(&mut self.grad, th.len());
        grad.fill(0.0);
        let (s1, s2) = (
            room(&mut self.s1, width * rows),
            room(&mut self.s2, width * rows),
        );
        let gh = room(&mut self.gh, l * nodes);
        gh.fill(0.0);
        let last = 2 + 2 * rounds;
        net.node_out.backward(
            th,
            grad,
            &self.h[rounds][..l * nodes],
            &[],
            nodes,
            &self.tapes[last],
            &self.gout[..d * nodes],
            Some((gh, &mut [])),
            s1,
            s2,
        );
        room(&mut self.ge, l * edges).fill(0.0);
        room(&mut self.gh2, l * nodes);
        room(&mut self.ge2, l * edges);
        for (r, (we, wv)) in net.rounds.iter().enumerate().rev() {
            let (gh, gh2) = (&self.gh[..l * nodes], &mut self.gh2[..l * nodes]);
            // h_{r+1} = h_r + φ_V([h_r; agg]): the residual passes ∂L/∂h on.
            gh2.copy_from_slice(gh);
            let gagg = room(&mut self.gagg, l * nodes);
            gagg.fill(0.0);
            let (h, agg) = (&self.h[r][..l * nodes], &self.agg[r][..l * nodes]);
            let tape = &self.tapes[3 + 2 * r];
            wv.backward(th, grad, h, agg, nodes, tape, gh, Some((gh2, gagg)), s1, s2);
            // agg = Σ_recv e_{r+1}.
            let ge = &mut self.ge[..l * edges];
            gather_rows(ge, gagg, &self.recv, Gather::Add);
            // e_{r+1} = e_r + φ_E([e_r; h_recv; h_send]).
            let ge2 = &mut self.ge2[..l * edges];
            ge2.copy_from_slice(ge);
            let ghrs = room(&mut self.ghrs, 2 * l * edges);
            ghrs.fill(0.0);
            let (e, hrs) = (&self.e[r][..l * edges], &self.hrs[r][..2 * l * edges]);
            let tape = &self.tapes[2 + 2 * r];
            we.backward(th, grad, e, hrs, edges, tape, ge, Some((ge2, ghrs)), s1, s2);
            let (ghr, ghs) = ghrs.split_at(l * edges);
            scatter_add_rows(gh2, ghr, &self.recv);
            scatter_add_rows(gh2, ghs, &self.send);
            // The round's input gradients become the next (earlier) round's
            // output gradients: swapped, not copied.
            std::mem::swap(&mut self.gh, &mut self.gh2);
            std::mem::swap(&mut self.ge, &mut self.ge2);
        }
        let (gh, ge) = (&mut self.gh[..l * nodes], &mut self.ge[..l * edges]);
        // Through the encoders' squareplus to their weights.
        times_squareplus_grad(gh, &self.h[0][..l * nodes]);
        let x_len = (net.spec.types + 2 * d) * nodes;
        let x = &self.x[..x_len];
        net.node_em
            .backward(th, grad, x, &[], nodes, &self.tapes[0], gh, None, s1, s2);
        times_squareplus_grad(ge, &self.e[0][..l * edges]);
        let feat = &self.feat[..(d + 1) * edges];
        net.edge_em
            .backward(th, grad, feat, &[], edges, &self.tapes[1], ge, None, s1, s2);
    }
}
