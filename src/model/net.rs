//! The candle model: the paper's equations, one bias per piece.

use super::batch::Batch;
use super::mlp::{squareplus, Mlp};
use super::params::ParamStore;
use super::solve::solve;
use super::variant::{Biases, Hyper, Variant};
use anyhow::{bail, Result};
use candle_core::{DType, Device, Tensor};
use rand::Rng;

/// The MLPs of a variant. Which ones exist is decided by its biases alone.
#[derive(Clone, Debug)]
pub struct Parts {
    /// NODE: the one MLP over the flattened state.
    pub node_mlp: Option<Mlp>,
    /// Node embedding: (one-hot, q, q̇), or one-hot only when decoupled.
    pub node_em: Option<Mlp>,
    /// Edge embedding of w_ij = q_i − q_j.
    pub edge_em: Option<Mlp>,
    /// Per round: node update W_V over (h_j ‖ h_ij), edge update W_E over (h_i ‖ h_j).
    pub rounds: Vec<(Mlp, Mlp)>,
    /// Node decoder (acceleration, or force; over (z_i ‖ g_i) when decoupled).
    pub node_out: Option<Mlp>,
    /// Global (body) embedding of (one-hot, q, q̇), when decoupled.
    pub glob_em: Option<Mlp>,
    /// Pairwise edge-force decoder (MCGNODE).
    pub edge_out: Option<Mlp>,
    /// Body-force decoder of the global embedding (MCGNODE with external fields).
    pub body_out: Option<Mlp>,
    /// Learnable log-masses, one per type (constrained variants): `"log_mass"`.
    pub masses: bool,
}

impl Parts {
    /// Declares the parameters of a model in `store`.
    pub fn build(h: &Hyper, store: &mut ParamStore, rng: &mut impl Rng) -> Result<Self> {
        let (d, t, hid, em) = (h.dim, h.types, h.hidden, h.embed);
        let b: Biases = h.variant.biases();
        let mut p = Parts {
            node_mlp: None,
            node_em: None,
            edge_em: None,
            rounds: vec![],
            node_out: None,
            glob_em: None,
            edge_out: None,
            body_out: None,
            masses: b.constrained,
        };
        if !b.graph {
            let io = h.particles * d;
            let mut sizes = vec![2 * io];
            sizes.extend(std::iter::repeat_n(h.node_hidden, h.node_layers));
            sizes.push(io);
            p.node_mlp = Some(Mlp::new(store, "node", &sizes, rng)?);
            return Ok(p);
        }
        let node_in = if b.decoupled { t } else { t + 2 * d };
        p.node_em = Some(Mlp::new(store, "node_em", &[node_in, hid, em], rng)?);
        p.edge_em = Some(Mlp::new(store, "edge_em", &[d, hid, em], rng)?);
        for l in 0..h.rounds {
            let wv = Mlp::new(store, &format!("mp{l}.v"), &[2 * em, em], rng)?;
            let we = Mlp::new(store, &format!("mp{l}.e"), &[2 * em, em], rng)?;
            p.rounds.push((wv, we));
        }
        let body = b.decoupled && (!b.pairwise || h.body_force);
        if body {
            p.glob_em = Some(Mlp::new(store, "glob_em", &[t + 2 * d, hid, em], rng)?);
        }
        if b.pairwise {
            p.edge_out = Some(Mlp::new(store, "edge_out", &[em, hid, d], rng)?);
            if body {
                p.body_out = Some(Mlp::new(store, "body_out", &[em, hid, d], rng)?);
            }
        } else {
            let inp = if b.decoupled { 2 * em } else { em };
            p.node_out = Some(Mlp::new(store, "node_out", &[inp, hid, d], rng)?);
        }
        if b.constrained {
            store.insert("log_mass", &[t], vec![0.0; t])?;
        }
        Ok(p)
    }
}

/// A trainable model: hyperparameters, parameters, parts.
#[derive(Clone, Debug)]
pub struct Net {
    /// Hyperparameters.
    pub hyper: Hyper,
    /// Parameters.
    pub store: ParamStore,
    /// Which MLPs exist.
    pub parts: Parts,
}

/// What a forward pass yields.
pub struct Output {
    /// Accelerations `(B·n, d)`.
    pub acc: Tensor,
    /// Forces `(B·n, d)` for force-predicting variants.
    pub force: Option<Tensor>,
}

fn gather(x: &Tensor, idx: &Tensor) -> candle_core::Result<Tensor> {
    x.index_select(idx, 0)
}

impl Net {
    /// A freshly initialised model (seeded).
    pub fn new(hyper: Hyper, rng: &mut impl Rng) -> Result<Self> {
        if hyper.dim != 2 && hyper.dim != 3 {
            bail!("model dimension must be 2 or 3");
        }
        let mut store = ParamStore::new();
        let parts = Parts::build(&hyper, &mut store, rng)?;
        Ok(Self {
            hyper,
            store,
            parts,
        })
    }

    /// Forward pass on a batch.
    pub fn forward(&self, b: &Batch) -> Result<Output> {
        let s = &self.store;
        let p = &self.parts;
        let bias = self.hyper.variant.biases();
        if let Some(mlp) = &p.node_mlp {
            if b.n != self.hyper.particles {
                bail!(
                    "NODE was built for {} particles, got {} (NODE is not inductive)",
                    self.hyper.particles,
                    b.n
                );
            }
            let nd = b.n * b.dim;
            let x = Tensor::cat(&[b.q.reshape((b.b, nd))?, b.v.reshape((b.b, nd))?], 1)?;
            let acc = mlp.forward(s, &x)?.reshape((b.b * b.n, b.dim))?;
            return Ok(Output { acc, force: None });
        }
        let (node_em, edge_em) = (p.node_em.as_ref().unwrap(), p.edge_em.as_ref().unwrap());
        let full = Tensor::cat(&[&b.onehot, &b.q, &b.v], 1)?;
        let node_in = if bias.decoupled {
            b.onehot.clone()
        } else {
            full.clone()
        };
        let mut h = squareplus(&node_em.forward(s, &node_in)?)?;
        let nodes = b.b * b.n;
        let em = self.hyper.embed;
        let mut he = if b.n_directed > 0 {
            let w = (gather(&b.q, &b.recv)? - gather(&b.q, &b.send)?)?;
            Some(squareplus(&edge_em.forward(s, &w)?)?)
        } else {
            None
        };
        for (wv, we) in &p.rounds {
            if let Some(e) = &he {
                let hs = gather(&h, &b.send)?;
                let hr = gather(&h, &b.recv)?;
                let msg = wv.forward(s, &Tensor::cat(&[&hs, e], 1)?)?;
                let agg = Tensor::zeros((nodes, em), DType::F64, &Device::Cpu)?
                    .index_add(&b.recv, &msg, 0)?;
                let e_new = squareplus(&(e + we.forward(s, &Tensor::cat(&[&hr, &hs], 1)?)?)?)?;
                h = squareplus(&(h + agg)?)?;
                he = Some(e_new);
            } else {
                h = squareplus(&h)?;
            }
        }
        let glob = match &p.glob_em {
            Some(g) => Some(squareplus(&g.forward(s, &full)?)?),
            None => None,
        };
        let out = if let Some(eo) = &p.edge_out {
            // Newton's third law: F_ab = (f_ab − f_ba)/2 on a, −F_ab on b.
            let mut n_int = Tensor::zeros((nodes, b.dim), DType::F64, &Device::Cpu)?;
            if let Some(e) = &he {
                let f = eo.forward(s, e)?;
                let half = b.n_directed / 2;
                let fa = ((f.narrow(0, 0, half)? - f.narrow(0, half, half)?)? * 0.5)?;
                let full_f = Tensor::cat(&[&fa, &fa.neg()?], 0)?;
                n_int = n_int.index_add(&b.recv, &full_f, 0)?;
            }
            match (&p.body_out, &glob) {
                (Some(bo), Some(g)) => (n_int + bo.forward(s, g)?)?,
                _ => n_int,
            }
        } else {
            let inp = match &glob {
                Some(g) => Tensor::cat(&[&h, g], 1)?,
                None => h,
            };
            p.node_out.as_ref().unwrap().forward(s, &inp)?
        };
        if !bias.constrained {
            return Ok(Output {
                acc: out,
                force: None,
            });
        }
        let acc = self.constrained_acc(b, &out)?;
        Ok(Output {
            acc,
            force: Some(out),
        })
    }

    /// q̈ = M⁻¹(N − Aᵀλ), λ = (A M⁻¹ Aᵀ)⁻¹(A M⁻¹ N + Ȧq̇) (paper eq. for q̈; Π = C = 0).
    fn constrained_acc(&self, b: &Batch, force: &Tensor) -> Result<Tensor> {
        let nd = b.n * b.dim;
        let inv_m = self.store.get("log_mass")?.as_tensor().neg()?.exp()?;
        let minv = gather(&inv_m, &b.types)?
            .unsqueeze(1)?
            .broadcast_as((b.b * b.n, b.dim))?
            .contiguous()?;
        let Some((a, at, adq)) = &b.constraint else {
            return Ok((force * &minv)?);
        };
        let minv3 = minv.reshape((b.b, 1, nd))?;
        let f3 = force.reshape((b.b, nd, 1))?;
        let am = a.broadcast_mul(&minv3)?;
        let k = am.matmul(at)?;
        let rhs = (am.matmul(&f3)? + adq)?;
        let lambda = solve(&k, &rhs)?;
        let acc = ((f3 - at.matmul(&lambda)?)?.reshape((b.b * b.n, b.dim))? * &minv)?;
        Ok(acc)
    }

    /// Mean squared error of predicted accelerations against the batch targets.
    pub fn loss(&self, b: &Batch) -> Result<Tensor> {
        let Some(t) = &b.target else {
            bail!("batch has no targets");
        };
        Ok((self.forward(b)?.acc - t)?.sqr()?.mean_all()?)
    }

    /// The variant.
    pub fn variant(&self) -> Variant {
        self.hyper.variant
    }
}
