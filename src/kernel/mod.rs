//! The hand-written, forward-only inference kernel: the same equations as
//! [`crate::model::net`], on plain slices (feature-major, see [`dense`]), with
//! every buffer allocated once per graph in a [`Workspace`]. Rollouts and the ROS node run on this; candle is
//! only for training. Tested against candle's forward to 1e-12.

mod dense;
pub mod trained;

use crate::error::{bail, Context, Result};
use crate::model::arch::{Arch, ArchError, Block, LOG_MASS};
use crate::model::mlp::squareplus_f64;
use crate::model::params::Weights;
use crate::model::plan::{BarEnd, GraphPlan};
use crate::model::solve::lu_solve_in_place;
use crate::model::variant::{EdgeInput, Hyper};
use crate::physics::Projector;
use crate::system::Graph;
use dense::Mlp as KMlp;
use rand::SeedableRng;
pub use trained::TrainedModel;

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
    arch: Arch,
    project_bars: bool,
}

/// Buffers for one graph; reused across steps so that the loop allocates nothing.
/// Activations are feature-major: `buf[feature · rows + row]`.
#[derive(Clone, Debug)]
pub struct Workspace {
    /// The graph as the kernel sees it.
    pub plan: GraphPlan,
    /// Node inputs (one-hot type, q, q̇), or NODE's flat (q, q̇).
    x: Vec<f64>,
    h: Vec<f64>,
    agg: Vec<f64>,
    glob: Vec<f64>,
    w_in: Vec<f64>,
    he: Vec<f64>,
    he_new: Vec<f64>,
    hs: Vec<f64>,
    hr: Vec<f64>,
    msg: Vec<f64>,
    f_edge: Vec<f64>,
    f_node: Vec<f64>,
    t1: Vec<f64>,
    t2: Vec<f64>,
    /// Forces of the last evaluation, `n·d` (force-predicting variants).
    pub force: Vec<f64>,
    /// Antisymmetric pairwise forces of the last evaluation, `E·d`, on
    /// `plan.recv[e]` due to `plan.send[e]` (MCGNODE).
    pub edge_force: Vec<f64>,
    incid: Vec<Vec<(usize, f64)>>,
    dq: Vec<f64>,
    kmat: Vec<f64>,
    lambda: Vec<f64>,
    /// SHAKE/RATTLE onto the bars with the learned masses, for rollouts of
    /// constrained models on graphs with bars (see [`Kernel::set_project_bars`]).
    pub projector: Option<Projector>,
}

/// Checks, before anything is allocated for them, that a file's
/// hyperparameters can describe the weights stored with them: no more layers
/// than (weight, bias) pairs, no more parameters than the file holds, scales
/// that can be used. A corrupt width or count (10^15) would
/// otherwise abort on allocation or build for ever, and a short `q_mean`
/// would index out of bounds in every forward pass.
fn check_sizes(hyper: &Hyper, w: &Weights) -> Result<()> {
    if hyper.dim != 2 && hyper.dim != 3 {
        bail!("model dimension must be 2 or 3, got {}", hyper.dim);
    }
    let Some(arch) = Arch::within(hyper, w.len() / 2) else {
        bail!(
            "the model's hyperparameters define more layers than its {} weight arrays can hold",
            w.len()
        );
    };
    // With no width 0, every size is at least one parameter of some layer,
    // so the count below bounds them all (and the buffers sized by them).
    if let Some((block, _)) = arch.mlps.iter().find(|(_, s)| s.contains(&0)) {
        bail!("the model's hyperparameters give block {block} a layer of width 0");
    }
    let stored: usize = w.values().map(|a| a.data.len()).sum();
    match arch.param_count() {
        Some(n) if n <= stored => {}
        n => bail!(
            "the model's hyperparameters define {} parameters, more than the {stored} its file holds",
            n.map_or_else(|| "over 2^64".to_string(), |n| n.to_string())
        ),
    }
    if let Some(nm) = &hyper.norm {
        if nm.q_mean.len() != hyper.dim {
            bail!(
                "the model's norm.q_mean has {} entries for dimension {}",
                nm.q_mean.len(),
                hyper.dim
            );
        }
        let scales = [
            ("q_scale", nm.q_scale),
            ("v_scale", nm.v_scale),
            ("w_scale", nm.w_scale),
            ("out_scale", nm.out_scale),
            ("k_scale", nm.k_scale),
        ];
        if let Some((name, x)) = scales.iter().find(|(_, x)| !(x.is_finite() && *x > 0.0)) {
            bail!("the model's norm.{name} = {x} is not a finite number > 0");
        }
        if nm.q_mean.iter().any(|x| !x.is_finite()) {
            bail!("the model's norm.q_mean is not finite");
        }
    }
    Ok(())
}

impl Kernel {
    /// Builds the kernel from a model's hyperparameters and weights.
    pub fn new(hyper: &Hyper, w: &Weights) -> Result<Self> {
        check_sizes(hyper, w)?;
        // Names, shapes and finiteness are checked against the architecture that
        // `hyper` defines, so the loops below can trust every size.
        let reference = crate::model::Net::new(
            hyper.clone(),
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(0),
        )?;
        reference.store.load(w)?;
        let arch = Arch::new(hyper);
        let ld = |b: Block| KMlp::load(w, &b.prefix());
        let mut rounds = vec![];
        for l in 0..arch.rounds {
            let v = ld(Block::Message(l))?.with_context(|| format!("missing round {l}"))?;
            let e = ld(Block::EdgeUpdate(l))?.with_context(|| format!("missing round {l}"))?;
            rounds.push((v, e));
        }
        let inv_mass = w
            .get(LOG_MASS)
            .map(|a| a.data.iter().map(|x| (-x).exp()).collect());
        let k = Self {
            hyper: hyper.clone(),
            node_mlp: ld(Block::Flat)?,
            node_em: ld(Block::NodeEmbed)?,
            edge_em: ld(Block::EdgeEmbed)?,
            rounds,
            node_out: ld(Block::NodeDecoder)?,
            glob_em: ld(Block::GlobalEmbed)?,
            edge_out: ld(Block::EdgeDecoder)?,
            body_out: ld(Block::BodyDecoder)?,
            inv_mass,
            arch,
            project_bars: true,
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

    /// Whether rollouts project positions and velocities back onto the bars
    /// every step (RATTLE with the learned masses; on by default). Without it
    /// a learned rollout lets bar lengths drift by the integrator's error.
    pub fn set_project_bars(&mut self, on: bool) {
        self.project_bars = on;
    }

    /// Learned masses per particle type (constrained models).
    pub fn learned_masses(&self) -> Option<Vec<f64>> {
        self.inv_mass
            .as_ref()
            .map(|im| im.iter().map(|x| 1.0 / x).collect())
    }

    /// The hyperparameters.
    pub fn hyper(&self) -> &Hyper {
        &self.hyper
    }

    /// Whether the kernel can run on this graph.
    pub fn supports(&self, graph: &Graph) -> Result<(), ArchError> {
        self.arch.supports(graph)
    }

    /// Allocates the buffers for a graph.
    pub fn workspace(&self, graph: &Graph) -> Result<Workspace, ArchError> {
        self.supports(graph)?;
        let plan = GraphPlan::new(graph);
        let (n, d, t) = (plan.n, plan.dim, self.arch.types);
        // NODE has no embeddings (and its file's `embed` sizes no weight).
        let em = if self.node_mlp.is_some() {
            0
        } else {
            self.arch.embed
        };
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
            .map(dense::Mlp::width)
            .max()
            .unwrap_or(1);
        for (a, b) in &self.rounds {
            width = width.max(a.width()).max(b.width());
        }
        let rows = n.max(ne).max(1);
        let x_len = if self.node_mlp.is_some() {
            2 * n * d
        } else {
            (t + 2 * d) * n
        };
        let mut incid = vec![vec![]; n];
        for (r, bar) in plan.bars.iter().enumerate() {
            incid[bar.a].push((r, 1.0));
            if let BarEnd::Particle(b) = bar.b {
                incid[b].push((r, -1.0));
            }
        }
        let k = plan.bars.len();
        // Edge inputs: q_i − q_j (filled each step), then constant edge physics.
        let arch = &self.arch;
        let mut w_in_init = vec![0.0; arch.edge_features() * ne];
        if arch.edge_physics {
            for e in 0..ne {
                for (f, x) in arch.edge_physics_of(&plan, e).iter().enumerate() {
                    w_in_init[(d + f) * ne + e] = *x;
                }
            }
        }
        let projector = match self.learned_masses() {
            Some(m) if self.project_bars && k > 0 => {
                let mut g = graph.clone();
                g.masses = g.types.iter().map(|&t| m[t as usize]).collect();
                Some(Projector::new(&g))
            }
            _ => None,
        };
        Ok(Workspace {
            x: vec![0.0; x_len],
            h: vec![0.0; em * n],
            agg: vec![0.0; em * n],
            glob: vec![0.0; em * n],
            w_in: w_in_init,
            he: vec![0.0; em * ne],
            he_new: vec![0.0; em * ne],
            hs: vec![0.0; em * ne],
            hr: vec![0.0; em * ne],
            msg: vec![0.0; em * ne],
            f_edge: vec![0.0; d * ne],
            f_node: vec![0.0; d * n],
            t1: vec![0.0; width * rows],
            t2: vec![0.0; width * rows],
            force: vec![0.0; n * d],
            edge_force: vec![0.0; ne / 2 * d],
            incid,
            dq: vec![0.0; k * d],
            kmat: vec![0.0; k * k],
            lambda: vec![0.0; k],
            projector,
            plan,
        })
    }

    /// Accelerations at (q, v), written to `acc` (`n·d`). Forces (and pairwise
    /// forces for MCGNODE) are left in `ws.force` / `ws.edge_force`.
    pub fn acceleration(&self, ws: &mut Workspace, q: &[f64], v: &[f64], acc: &mut [f64]) {
        let (n, d, em, t) = (ws.plan.n, ws.plan.dim, self.arch.embed, self.arch.types);
        let bias = self.hyper.variant.biases();
        if let Some(m) = &self.node_mlp {
            let nd = n * d;
            let nm = &self.arch.norm;
            for i in 0..nd {
                ws.x[i] = (q[i] - nm.q_mean[i % d]) / nm.q_scale;
                ws.x[nd + i] = v[i] / nm.v_scale;
            }
            m.forward(&ws.x[..2 * nd], &[], 1, acc, &mut ws.t1, &mut ws.t2);
            acc.iter_mut().for_each(|a| *a *= nm.out_scale);
            return;
        }
        let ne = ws.plan.recv.len();
        let sqp = |x: &mut [f64]| x.iter_mut().for_each(|v| *v = squareplus_f64(*v));
        // Node inputs (one-hot, q, q̇), feature-major.
        ws.x[..t * n].fill(0.0);
        for (i, &ty) in ws.plan.types.iter().enumerate() {
            ws.x[ty * n + i] = 1.0;
            for c in 0..d {
                ws.x[(t + c) * n + i] =
                    (q[i * d + c] - self.arch.norm.q_mean[c]) / self.arch.norm.q_scale;
                ws.x[(t + d + c) * n + i] = v[i * d + c] / self.arch.norm.v_scale;
            }
        }
        // Node embeddings: of the type alone when decoupled.
        let node_in = if bias.decoupled {
            t * n
        } else {
            (t + 2 * d) * n
        };
        let node_em = self.node_em.as_ref().expect("checked in new");
        node_em.forward(&ws.x[..node_in], &[], n, &mut ws.h, &mut ws.t1, &mut ws.t2);
        sqp(&mut ws.h);
        // Edge embeddings of w_ij = q_i − q_j.
        for (e, (&r, &s)) in ws.plan.recv.iter().zip(&ws.plan.send).enumerate() {
            for c in 0..d {
                ws.w_in[c * ne + e] = (q[r * d + c] - q[s * d + c]) / self.arch.norm.w_scale;
            }
        }
        let edge_em = self.edge_em.as_ref().expect("checked in new");
        edge_em.forward(&ws.w_in, &[], ne, &mut ws.he, &mut ws.t1, &mut ws.t2);
        sqp(&mut ws.he);
        // Message passing. In the last round, skip what no decoder reads: node
        // updates when forces come from edges, edge updates when they come from nodes.
        let rounds = self.rounds.len();
        for (l, (wv, we)) in self.rounds.iter().enumerate() {
            let last = l + 1 == rounds;
            let nodes_needed = !(last && bias.pairwise);
            let edges_needed = !last || bias.pairwise;
            for k in 0..em {
                let (hk, base) = (&ws.h[k * n..(k + 1) * n], k * ne);
                for (e, (&r, &s)) in ws.plan.recv.iter().zip(&ws.plan.send).enumerate() {
                    ws.hs[base + e] = hk[s];
                    ws.hr[base + e] = hk[r];
                }
            }
            if nodes_needed {
                // h_i ← sqp(h_i + Σ_j W_V (h_j ‖ h_ij)).
                wv.forward(&ws.hs, &ws.he, ne, &mut ws.msg, &mut ws.t1, &mut ws.t2);
                ws.agg.fill(0.0);
                for k in 0..em {
                    let m = &ws.msg[k * ne..(k + 1) * ne];
                    let a = &mut ws.agg[k * n..(k + 1) * n];
                    for (&r, mv) in ws.plan.recv.iter().zip(m) {
                        a[r] += mv;
                    }
                }
                for (h, a) in ws.h.iter_mut().zip(&ws.agg) {
                    *h = squareplus_f64(*h + a);
                }
            }
            if edges_needed {
                // h_ij ← sqp(h_ij + W_E (h_i ‖ h_j)), from the node states before this round.
                match self.arch.edge_input {
                    EdgeInput::Concat => {
                        we.forward(&ws.hr, &ws.hs, ne, &mut ws.he_new, &mut ws.t1, &mut ws.t2)
                    }
                    EdgeInput::Product => {
                        // h_i ⊙ h_j into `msg`, free at this point of the round.
                        for ((p, r), s) in ws.msg.iter_mut().zip(&ws.hr).zip(&ws.hs) {
                            *p = r * s;
                        }
                        we.forward(&ws.msg, &[], ne, &mut ws.he_new, &mut ws.t1, &mut ws.t2)
                    }
                }
                for (x, old) in ws.he_new.iter_mut().zip(&ws.he) {
                    *x = squareplus_f64(*x + old);
                }
                std::mem::swap(&mut ws.he, &mut ws.he_new);
            }
        }
        // Global (body) embedding of (one-hot, q, q̇).
        if let Some(g) = &self.glob_em {
            g.forward(&ws.x, &[], n, &mut ws.glob, &mut ws.t1, &mut ws.t2);
            sqp(&mut ws.glob);
        }
        // Decoders, into node-major forces (or accelerations for GNODE).
        let out: &mut [f64] = if bias.constrained {
            &mut ws.force
        } else {
            &mut acc[..]
        };
        if let Some(eo) = &self.edge_out {
            // Newton's third law: F_ab = (f_ab − f_ba)/2 on a, −F_ab on b.
            out.fill(0.0);
            eo.forward(&ws.he, &[], ne, &mut ws.f_edge, &mut ws.t1, &mut ws.t2);
            let half = ne / 2;
            for e in 0..half {
                let (a, b) = (ws.plan.recv[e], ws.plan.send[e]);
                for c in 0..d {
                    let f = (ws.f_edge[c * ne + e] - ws.f_edge[c * ne + e + half])
                        * (0.5 * self.arch.norm.out_scale);
                    ws.edge_force[e * d + c] = f;
                    out[a * d + c] += f;
                    out[b * d + c] -= f;
                }
            }
            if let Some(bo) = &self.body_out {
                bo.forward(&ws.glob, &[], n, &mut ws.f_node, &mut ws.t1, &mut ws.t2);
                for i in 0..n {
                    for c in 0..d {
                        out[i * d + c] += ws.f_node[c * n + i] * self.arch.norm.out_scale;
                    }
                }
            }
        } else if let Some(no) = &self.node_out {
            let g: &[f64] = if self.glob_em.is_some() {
                &ws.glob
            } else {
                &[]
            };
            no.forward(&ws.h, g, n, &mut ws.f_node, &mut ws.t1, &mut ws.t2);
            for i in 0..n {
                for c in 0..d {
                    out[i * d + c] = ws.f_node[c * n + i] * self.arch.norm.out_scale;
                }
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
                    let (dq, dv) = bar.delta(q, v, d, c);
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

#[cfg(test)]
mod tests {
    use super::TrainedModel;
    use crate::dynamics::Dynamics;
    use crate::model::{ModelFile, Norm, Variant};
    use crate::physics::{SystemConfig, SystemKind};

    /// Builds a kernel from a random model's file after `edit`, as loading
    /// an edited file does; on success runs one acceleration on the
    /// 3-spring ring the model was made for.
    fn load_edited(
        variant: Variant,
        edit: impl FnOnce(&mut ModelFile),
    ) -> Result<Vec<f64>, String> {
        let c = SystemConfig::new(SystemKind::Spring, 3);
        let g = c.graph();
        let s = c.start_for(&g, 1, 0);
        let (_, m) = crate::testing::random_model(variant, &g, 3).expect("model");
        let mut file = m.file;
        edit(&mut file);
        let m = TrainedModel::from_file(file).map_err(|e| e.to_string())?;
        let mut out = vec![0.0; g.ndof()];
        m.acceleration(&g, &s, &mut out)
            .map_err(|e| e.to_string())?;
        Ok(out)
    }

    /// Settings a corrupt model file can hold (tests/fuzz_readers.rs edits
    /// them; each was checked to fail this way before `check_sizes`): they
    /// allocated terabytes (an abort), panicked on a capacity overflow or an
    /// index out of bounds, or never finished loading.
    #[test]
    fn corrupt_sizes_are_errors_not_aborts() {
        type Edit = fn(&mut ModelFile);
        let cases: [(Variant, Edit, &str); 12] = [
            (
                Variant::Mcgnode,
                |f| f.hyper.hidden = 1_000_000,
                "5000055000023 parameters, more than the 423",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.hidden = usize::MAX,
                "over 2^64 parameters",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.embed = 1 << 32,
                "parameters, more than the 423",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.types = usize::MAX,
                "over 2^64 parameters",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.rounds = 1_000_000_000_000_000,
                "more layers than its 31 weight arrays",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.hidden_layers = 1_000_000_000_000_000,
                "more layers than its 31",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.hidden = 0,
                "block node_em a layer of width 0",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.dim = 1_000_000_000_000_000,
                "dimension must be 2 or 3",
            ),
            (
                Variant::Node,
                |f| f.hyper.node_hidden = 1_000_000,
                "parameters, more than the 582",
            ),
            (
                Variant::Node,
                |f| f.hyper.node_layers = 1_000_000_000_000_000,
                "more layers than its 6",
            ),
            (
                Variant::Node,
                |f| f.hyper.particles = usize::MAX,
                "over 2^64 parameters",
            ),
            (
                Variant::Gnode,
                |f| {
                    let mut n = Norm::identity(2);
                    n.q_mean = vec![0.0];
                    f.hyper.norm = Some(n);
                },
                "norm.q_mean has 1 entries for dimension 2",
            ),
        ];
        for (variant, edit, want) in cases {
            let e = load_edited(variant, edit).expect_err(want);
            assert!(e.contains(want), "{variant}: {e:?} does not say {want:?}");
        }
        let e = load_edited(Variant::Gnode, |f| {
            let mut n = Norm::identity(2);
            n.q_scale = 0.0;
            f.hyper.norm = Some(n);
        })
        .expect_err("a zero scale makes every output NaN");
        assert!(
            e.contains("norm.q_scale = 0 is not a finite number > 0"),
            "{e}"
        );
    }

    /// Settings that size no weight do not size buffers either: NODE's
    /// `embed` and `types` (tests/fuzz_readers.rs met a NODE file whose
    /// `embed` of 2^32 made the workspace ask for 100 GB, an abort), and a
    /// `types` of 0, which the architecture reads as 1 (the kernel indexed
    /// out of bounds).
    #[test]
    fn settings_that_size_no_weight_are_harmless() {
        let plain = load_edited(Variant::Node, |_| {}).expect("node");
        let odd = load_edited(Variant::Node, |f| {
            f.hyper.embed = 1 << 32;
            f.hyper.types = 1 << 40;
        })
        .expect("NODE ignores embed and types");
        assert_eq!(plain, odd);
        for v in [Variant::Gnode, Variant::Mcgnode] {
            let one = load_edited(v, |_| {}).expect("model");
            let zero = load_edited(v, |f| f.hyper.types = 0).expect("types 0 reads as 1");
            assert_eq!(one, zero, "{v}");
        }
    }
}
