//! The hand-written, forward-only inference kernel: the same equations as
//! [`crate::model::net`], on plain slices, with every buffer allocated once per
//! graph in a [`Workspace`]. Rollouts and the ROS node run on this; candle is
//! only for training. Tested against candle's forward to 1e-12.

use crate::model::mlp::squareplus_f64;
use crate::model::params::Weights;
use crate::model::plan::{BarEnd, GraphPlan};
use crate::model::solve::lu_solve_in_place;
use crate::model::variant::Hyper;
use crate::system::Graph;
use anyhow::{bail, Context, Result};
use rand::SeedableRng;

/// One linear layer, weights `[inputs, outputs]` row-major.
#[derive(Clone, Debug)]
struct Dense {
    w: Vec<f64>,
    b: Vec<f64>,
    inp: usize,
    out: usize,
}

/// An MLP with squareplus between layers.
#[derive(Clone, Debug)]
struct KMlp {
    layers: Vec<Dense>,
}

impl KMlp {
    fn load(w: &Weights, name: &str) -> Result<Option<Self>> {
        let mut layers = vec![];
        loop {
            let i = layers.len();
            let (Some(wt), Some(bs)) = (
                w.get(&format!("{name}.l{i}.w")),
                w.get(&format!("{name}.l{i}.b")),
            ) else {
                break;
            };
            if wt.shape.len() != 2 || bs.shape != [wt.shape[1]] {
                bail!("parameter {name}.l{i} has inconsistent shapes");
            }
            layers.push(Dense {
                w: wt.data.clone(),
                b: bs.data.clone(),
                inp: wt.shape[0],
                out: wt.shape[1],
            });
        }
        if layers.is_empty() {
            return Ok(None);
        }
        for p in layers.windows(2) {
            if p[0].out != p[1].inp {
                bail!("MLP {name}: layer sizes do not chain");
            }
        }
        Ok(Some(Self { layers }))
    }

    fn inp(&self) -> usize {
        self.layers[0].inp
    }

    fn width(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.out.max(l.inp))
            .max()
            .unwrap_or(0)
    }

    /// `y = mlp(x)`; `t1`, `t2` are scratch of at least `width()`.
    #[inline]
    fn forward(&self, x: &[f64], y: &mut [f64], t1: &mut [f64], t2: &mut [f64]) {
        let nl = self.layers.len();
        t1[..x.len()].copy_from_slice(x);
        for (li, l) in self.layers.iter().enumerate() {
            let dst: &mut [f64] = if li + 1 == nl {
                &mut y[..l.out]
            } else {
                &mut t2[..l.out]
            };
            dst.copy_from_slice(&l.b);
            for (i, &xi) in t1[..l.inp].iter().enumerate() {
                if xi == 0.0 {
                    continue; // one-hot inputs are mostly zero
                }
                let row = &l.w[i * l.out..(i + 1) * l.out];
                for (d, w) in dst.iter_mut().zip(row) {
                    *d += xi * w;
                }
            }
            if li + 1 < nl {
                for d in dst.iter_mut() {
                    *d = squareplus_f64(*d);
                }
                t1[..l.out].copy_from_slice(dst);
            }
        }
    }
}

/// A trained model's forward pass, ready to run.
#[derive(Clone, Debug)]
pub struct Kernel {
    hyper: Hyper,
    node_mlp: Option<KMlp>,
    node_em: Option<KMlp>,
    edge_em: Option<KMlp>,
    rounds: Vec<(KMlp, KMlp)>,
    node_out: Option<KMlp>,
    glob_em: Option<KMlp>,
    edge_out: Option<KMlp>,
    body_out: Option<KMlp>,
    inv_mass: Option<Vec<f64>>,
}

/// Buffers for one graph; reused across steps so that the loop allocates nothing.
#[derive(Clone, Debug)]
pub struct Workspace {
    /// The graph as the kernel sees it.
    pub plan: GraphPlan,
    x: Vec<f64>,
    h: Vec<f64>,
    agg: Vec<f64>,
    he: Vec<f64>,
    he_new: Vec<f64>,
    glob: Vec<f64>,
    cat: Vec<f64>,
    t1: Vec<f64>,
    t2: Vec<f64>,
    /// Forces of the last evaluation, `n·d` (force-predicting variants).
    pub force: Vec<f64>,
    /// Antisymmetric pairwise forces of the last evaluation, `E·d`, on
    /// `plan.recv[e]` due to `plan.send[e]` (MCGNODE).
    pub edge_force: Vec<f64>,
    fpair: Vec<f64>,
    type_em: Vec<f64>,
    incid: Vec<Vec<(usize, f64)>>,
    dq: Vec<f64>,
    kmat: Vec<f64>,
    lambda: Vec<f64>,
}

impl Kernel {
    /// Builds the kernel from a model's hyperparameters and weights.
    pub fn new(hyper: &Hyper, w: &Weights) -> Result<Self> {
        // Names, shapes and finiteness are checked against the architecture that
        // `hyper` defines, so the loops below can trust every size.
        let mut reference = crate::model::Net::new(
            hyper.clone(),
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(0),
        )?;
        reference.store.load(w)?;
        let ld = |n: &str| KMlp::load(w, n);
        let mut rounds = vec![];
        let graph_rounds = if hyper.variant.biases().graph {
            hyper.rounds
        } else {
            0
        };
        for l in 0..graph_rounds {
            let v = ld(&format!("mp{l}.v"))?.with_context(|| format!("missing round {l}"))?;
            let e = ld(&format!("mp{l}.e"))?.with_context(|| format!("missing round {l}"))?;
            rounds.push((v, e));
        }
        let inv_mass = w
            .get("log_mass")
            .map(|a| a.data.iter().map(|x| (-x).exp()).collect());
        let k = Self {
            hyper: hyper.clone(),
            node_mlp: ld("node")?,
            node_em: ld("node_em")?,
            edge_em: ld("edge_em")?,
            rounds,
            node_out: ld("node_out")?,
            glob_em: ld("glob_em")?,
            edge_out: ld("edge_out")?,
            body_out: ld("body_out")?,
            inv_mass,
        };
        let b = hyper.variant.biases();
        let ok = if b.graph {
            k.node_em.is_some()
                && k.edge_em.is_some()
                && (k.node_out.is_some() || k.edge_out.is_some())
                && (k.inv_mass.is_some() == b.constrained)
        } else {
            k.node_mlp.is_some()
        };
        if !ok {
            bail!("weights do not match a {} model", hyper.variant);
        }
        Ok(k)
    }

    /// The hyperparameters.
    pub fn hyper(&self) -> &Hyper {
        &self.hyper
    }

    /// Whether the kernel can run on this graph.
    pub fn supports(&self, graph: &Graph) -> Result<(), String> {
        graph.validate()?;
        if graph.dim != self.hyper.dim {
            return Err(format!(
                "model is {}D, system is {}D",
                self.hyper.dim, graph.dim
            ));
        }
        if let Some(t) = graph
            .types
            .iter()
            .find(|&&t| t as usize >= self.hyper.types)
        {
            return Err(format!(
                "particle type {t} is unknown to the model (it knows {} types)",
                self.hyper.types
            ));
        }
        if self.node_mlp.is_some() && graph.n() != self.hyper.particles {
            return Err(format!(
                "NODE model is built for {} particles, system has {} (NODE is not inductive)",
                self.hyper.particles,
                graph.n()
            ));
        }
        Ok(())
    }

    /// Allocates the buffers for a graph.
    pub fn workspace(&self, graph: &Graph) -> Result<Workspace, String> {
        self.supports(graph)?;
        let plan = GraphPlan::new(graph);
        let (n, d, em) = (plan.n, plan.dim, self.hyper.embed);
        let ne = plan.recv.len();
        let mlps = [
            &self.node_mlp,
            &self.node_em,
            &self.edge_em,
            &self.node_out,
            &self.glob_em,
            &self.edge_out,
            &self.body_out,
        ];
        let mut width = mlps
            .iter()
            .filter_map(|m| m.as_ref())
            .map(|m| m.width())
            .max()
            .unwrap_or(0);
        for (a, b) in &self.rounds {
            width = width.max(a.width()).max(b.width());
        }
        let xin = self
            .node_em
            .as_ref()
            .map(|m| m.inp())
            .unwrap_or(0)
            .max(self.hyper.types + 2 * d);
        let x_len = if self.node_mlp.is_some() {
            2 * n * d
        } else {
            n * xin
        };
        let width = width.max(2 * n * d).max(2 * em + 1);
        let mut incid = vec![vec![]; n];
        for (r, bar) in plan.bars.iter().enumerate() {
            incid[bar.a].push((r, 1.0));
            if let BarEnd::Particle(b) = bar.b {
                incid[b].push((r, -1.0));
            }
        }
        let k = plan.bars.len();
        Ok(Workspace {
            x: vec![0.0; x_len],
            h: vec![0.0; n * em],
            agg: vec![0.0; n * em],
            he: vec![0.0; ne * em],
            he_new: vec![0.0; ne * em],
            glob: vec![0.0; n * em],
            cat: vec![0.0; 2 * em + xin],
            t1: vec![0.0; width],
            t2: vec![0.0; width],
            force: vec![0.0; n * d],
            edge_force: vec![0.0; ne / 2 * d],
            fpair: vec![0.0; 2 * d],
            type_em: vec![0.0; self.hyper.types * em],
            incid,
            dq: vec![0.0; k * d],
            kmat: vec![0.0; k * k],
            lambda: vec![0.0; k],
            plan,
        })
    }

    /// Writes (one-hot type, q_i, q̇_i) into `ws.cat`; returns its length.
    fn node_features(&self, ws: &mut Workspace, q: &[f64], v: &[f64], i: usize) -> usize {
        let (d, t) = (ws.plan.dim, self.hyper.types);
        let c = &mut ws.cat;
        c[..t].iter_mut().for_each(|x| *x = 0.0);
        c[ws.plan.types[i]] = 1.0;
        c[t..t + d].copy_from_slice(&q[i * d..(i + 1) * d]);
        c[t + d..t + 2 * d].copy_from_slice(&v[i * d..(i + 1) * d]);
        t + 2 * d
    }

    /// Accelerations at (q, v), written to `acc` (`n·d`). Forces (and pairwise
    /// forces for MCGNODE) are left in `ws.force` / `ws.edge_force`.
    pub fn acceleration(&self, ws: &mut Workspace, q: &[f64], v: &[f64], acc: &mut [f64]) {
        let (n, d, em) = (ws.plan.n, ws.plan.dim, self.hyper.embed);
        let bias = self.hyper.variant.biases();
        if let Some(m) = &self.node_mlp {
            let nd = n * d;
            ws.x[..nd].copy_from_slice(q);
            ws.x[nd..2 * nd].copy_from_slice(v);
            m.forward(&ws.x[..2 * nd], acc, &mut ws.t1, &mut ws.t2);
            return;
        }
        // Node embeddings. Decoupled variants embed the type alone: one per type.
        let node_em = self.node_em.as_ref().expect("checked in new");
        if bias.decoupled {
            let t = self.hyper.types;
            for ty in 0..t {
                ws.cat[..t].iter_mut().for_each(|x| *x = 0.0);
                ws.cat[ty] = 1.0;
                let h = &mut ws.type_em[ty * em..(ty + 1) * em];
                node_em.forward(&ws.cat[..t], h, &mut ws.t1, &mut ws.t2);
                h.iter_mut().for_each(|x| *x = squareplus_f64(*x));
            }
            for i in 0..n {
                let ty = ws.plan.types[i];
                ws.h[i * em..(i + 1) * em].copy_from_slice(&ws.type_em[ty * em..(ty + 1) * em]);
            }
        } else {
            for i in 0..n {
                let len = self.node_features(ws, q, v, i);
                let (cat, h) = (&ws.cat[..len], &mut ws.h[i * em..(i + 1) * em]);
                node_em.forward(cat, h, &mut ws.t1, &mut ws.t2);
                h.iter_mut().for_each(|x| *x = squareplus_f64(*x));
            }
        }
        // Edge embeddings of w_ij = q_i − q_j.
        let ne = ws.plan.recv.len();
        let edge_em = self.edge_em.as_ref().expect("checked in new");
        for e in 0..ne {
            let (r, s) = (ws.plan.recv[e], ws.plan.send[e]);
            for c in 0..d {
                ws.cat[c] = q[r * d + c] - q[s * d + c];
            }
            let he = &mut ws.he[e * em..(e + 1) * em];
            edge_em.forward(&ws.cat[..d], he, &mut ws.t1, &mut ws.t2);
            he.iter_mut().for_each(|x| *x = squareplus_f64(*x));
        }
        // Message passing. In the last round, skip what no decoder reads: node
        // updates when forces come from edges, edge updates when they come from nodes.
        let rounds = self.rounds.len();
        for (l, (wv, we)) in self.rounds.iter().enumerate() {
            let last = l + 1 == rounds;
            let nodes_needed = !(last && bias.pairwise);
            let edges_needed = !last || bias.pairwise;
            ws.agg.iter_mut().for_each(|x| *x = 0.0);
            for e in 0..ne {
                let (r, s) = (ws.plan.recv[e], ws.plan.send[e]);
                if nodes_needed {
                    ws.cat[..em].copy_from_slice(&ws.h[s * em..(s + 1) * em]);
                    ws.cat[em..2 * em].copy_from_slice(&ws.he[e * em..(e + 1) * em]);
                    let (cat, rest) = ws.cat.split_at_mut(2 * em);
                    let msg = &mut rest[..em];
                    wv.forward(cat, msg, &mut ws.t1, &mut ws.t2);
                    for (a, m) in ws.agg[r * em..(r + 1) * em].iter_mut().zip(msg.iter()) {
                        *a += m;
                    }
                }
                if edges_needed {
                    ws.cat[..em].copy_from_slice(&ws.h[r * em..(r + 1) * em]);
                    ws.cat[em..2 * em].copy_from_slice(&ws.h[s * em..(s + 1) * em]);
                    let hn = &mut ws.he_new[e * em..(e + 1) * em];
                    we.forward(&ws.cat[..2 * em], hn, &mut ws.t1, &mut ws.t2);
                    for (x, old) in hn.iter_mut().zip(&ws.he[e * em..(e + 1) * em]) {
                        *x = squareplus_f64(*x + old);
                    }
                }
            }
            if nodes_needed {
                for (h, a) in ws.h.iter_mut().zip(&ws.agg) {
                    *h = squareplus_f64(*h + a);
                }
            }
            if edges_needed {
                std::mem::swap(&mut ws.he, &mut ws.he_new);
            }
        }
        // Global (body) embedding.
        if let Some(g) = &self.glob_em {
            for i in 0..n {
                let len = self.node_features(ws, q, v, i);
                let out = &mut ws.glob[i * em..(i + 1) * em];
                g.forward(&ws.cat[..len], out, &mut ws.t1, &mut ws.t2);
                out.iter_mut().for_each(|x| *x = squareplus_f64(*x));
            }
        }
        // Decoders.
        let out: &mut [f64] = if bias.constrained {
            &mut ws.force
        } else {
            &mut acc[..]
        };
        if let Some(eo) = &self.edge_out {
            // Newton's third law: F_ab = (f_ab − f_ba)/2 on a, −F_ab on b.
            out.iter_mut().for_each(|x| *x = 0.0);
            let half = ne / 2;
            for e in 0..half {
                let (fab, fba) = ws.fpair.split_at_mut(d);
                eo.forward(&ws.he[e * em..(e + 1) * em], fab, &mut ws.t1, &mut ws.t2);
                let p = e + half;
                eo.forward(&ws.he[p * em..(p + 1) * em], fba, &mut ws.t1, &mut ws.t2);
                let (a, b) = (ws.plan.recv[e], ws.plan.send[e]);
                for c in 0..d {
                    let f = (fab[c] - fba[c]) * 0.5;
                    ws.edge_force[e * d + c] = f;
                    out[a * d + c] += f;
                    out[b * d + c] -= f;
                }
            }
            if let Some(bo) = &self.body_out {
                for i in 0..n {
                    let fb = &mut ws.fpair[..d];
                    bo.forward(&ws.glob[i * em..(i + 1) * em], fb, &mut ws.t1, &mut ws.t2);
                    for c in 0..d {
                        out[i * d + c] += fb[c];
                    }
                }
            }
        } else if let Some(no) = &self.node_out {
            for i in 0..n {
                let len = if self.glob_em.is_some() {
                    ws.cat[..em].copy_from_slice(&ws.h[i * em..(i + 1) * em]);
                    ws.cat[em..2 * em].copy_from_slice(&ws.glob[i * em..(i + 1) * em]);
                    2 * em
                } else {
                    ws.cat[..em].copy_from_slice(&ws.h[i * em..(i + 1) * em]);
                    em
                };
                no.forward(
                    &ws.cat[..len],
                    &mut out[i * d..(i + 1) * d],
                    &mut ws.t1,
                    &mut ws.t2,
                );
            }
        }
        if bias.constrained {
            self.constrained_acc(ws, q, v, acc);
        }
    }

    /// q̈ = M⁻¹(N − Aᵀλ) with λ = (A M⁻¹ Aᵀ)⁻¹(A M⁻¹ N + Ȧq̇), on the sparse bar
    /// incidence: K_rs gathers only bars that share a particle.
    fn constrained_acc(&self, ws: &mut Workspace, q: &[f64], v: &[f64], acc: &mut [f64]) {
        let (n, d) = (ws.plan.n, ws.plan.dim);
        let inv_m = self
            .inv_mass
            .as_ref()
            .expect("constrained model has masses");
        let k = ws.plan.bars.len();
        let mut ok = true;
        if k > 0 {
            for (r, bar) in ws.plan.bars.iter().enumerate() {
                let mut s = 0.0;
                let mut rhs = 0.0;
                for c in 0..d {
                    let (qb, vb) = match &bar.b {
                        BarEnd::Particle(b) => (q[b * d + c], v[b * d + c]),
                        BarEnd::Fixed(p) => (p[c], 0.0),
                    };
                    let dq = q[bar.a * d + c] - qb;
                    let dv = v[bar.a * d + c] - vb;
                    ws.dq[r * d + c] = dq;
                    s += dv * dv;
                    rhs += dq * inv_m[ws.plan.types[bar.a]] * ws.force[bar.a * d + c];
                    if let BarEnd::Particle(b) = bar.b {
                        rhs -= dq * inv_m[ws.plan.types[b]] * ws.force[b * d + c];
                    }
                }
                ws.lambda[r] = rhs + s;
            }
            ws.kmat.iter_mut().for_each(|x| *x = 0.0);
            for p in 0..n {
                let mi = inv_m[ws.plan.types[p]];
                for &(r, sr) in &ws.incid[p] {
                    for &(s, ss) in &ws.incid[p] {
                        let mut dot = 0.0;
                        for c in 0..d {
                            dot += ws.dq[r * d + c] * ws.dq[s * d + c];
                        }
                        ws.kmat[r * k + s] += mi * sr * ss * dot;
                    }
                }
            }
            ok = lu_solve_in_place(&mut ws.kmat, &mut ws.lambda, k, 1).is_ok();
        }
        for p in 0..n {
            let mi = inv_m[ws.plan.types[p]];
            for c in 0..d {
                let mut f = ws.force[p * d + c];
                if ok {
                    for &(r, sr) in &ws.incid[p] {
                        f -= sr * ws.dq[r * d + c] * ws.lambda[r];
                    }
                } else {
                    f = f64::NAN;
                }
                acc[p * d + c] = mi * f;
            }
        }
    }
}
