//! The full graph network shared by the baselines (Battaglia et al. 2018;
//! Cranmer et al. 2020; Sanchez-Gonzalez et al. 2020): node and edge encoders,
//! then rounds in which every edge is updated from (edge, receiver, sender) and
//! every node from (node, sum of incoming edges).
//!
//! Unlike the GNODE network (where the edge update sees only the two node
//! embeddings and the node update sees sender + edge), the full GN's edge
//! update reads its own edge state, and node updates aggregate updated edges.

use crate::model::batch::Batch;
use crate::model::mlp::{squareplus, Mlp};
use crate::model::params::ParamStore;
use anyhow::Result;
use candle_core::{DType, Device, Tensor};
use rand::Rng;

/// Encoders and message-passing rounds.
#[derive(Clone, Debug)]
pub struct GraphNet {
    /// Node encoder.
    pub node_em: Mlp,
    /// Edge encoder.
    pub edge_em: Mlp,
    /// Per round: (edge update over e‖h_recv‖h_send, node update over h‖Σe).
    pub rounds: Vec<(Mlp, Mlp)>,
    /// GNS-style residual updates (h ← h + φ(…)); otherwise h ← squareplus(φ(…)).
    pub residual: bool,
    /// Edge features include the distance |w_ij| (GNS) besides w_ij = q_i − q_j.
    pub edge_distance: bool,
    /// Latent (embedding) width.
    pub latent: usize,
}

/// Settings of a [`GraphNet`].
#[derive(Clone, Copy, Debug)]
pub struct GraphNetSpec {
    /// Width of the node input features.
    pub node_in: usize,
    /// Spatial dimension.
    pub dim: usize,
    /// Hidden units of each MLP.
    pub hidden: usize,
    /// Latent width.
    pub latent: usize,
    /// Message-passing rounds.
    pub rounds: usize,
    /// Residual updates.
    pub residual: bool,
    /// Distance as an edge feature.
    pub edge_distance: bool,
}

impl GraphNet {
    /// Declares the parameters (`node_em`, `edge_em`, `gn{l}.e`, `gn{l}.v`).
    pub fn new(store: &mut ParamStore, s: GraphNetSpec, rng: &mut impl Rng) -> Result<Self> {
        let (h, l) = (s.hidden, s.latent);
        let edge_in = s.dim + usize::from(s.edge_distance);
        let node_em = Mlp::new(store, "node_em", &[s.node_in, h, l], rng)?;
        let edge_em = Mlp::new(store, "edge_em", &[edge_in, h, l], rng)?;
        let mut rounds = vec![];
        for r in 0..s.rounds {
            let e = Mlp::new(store, &format!("gn{r}.e"), &[3 * l, h, l], rng)?;
            let v = Mlp::new(store, &format!("gn{r}.v"), &[2 * l, h, l], rng)?;
            rounds.push((e, v));
        }
        Ok(Self {
            node_em,
            edge_em,
            rounds,
            residual: s.residual,
            edge_distance: s.edge_distance,
            latent: l,
        })
    }

    /// Node latents `(B·n, L)` and directed-edge latents `(2·B·E, L)` (None
    /// without edges). `q` are the positions (a variable when differentiating)
    /// and `node_x` the node input features.
    pub fn run(
        &self,
        store: &ParamStore,
        b: &Batch,
        q: &Tensor,
        node_x: &Tensor,
    ) -> Result<(Tensor, Option<Tensor>)> {
        let act = |x: Tensor| -> Result<Tensor> { Ok(squareplus(&x)?) };
        let mut h = act(self.node_em.forward(store, node_x)?)?;
        let mut e = if b.n_directed > 0 {
            let w = (q.index_select(&b.recv, 0)? - q.index_select(&b.send, 0)?)?;
            let feat = if self.edge_distance {
                let r = w.sqr()?.sum_keepdim(1)?.sqrt()?;
                Tensor::cat(&[&w, &r], 1)?
            } else {
                w
            };
            Some(act(self.edge_em.forward(store, &feat)?)?)
        } else {
            None
        };
        let nodes = h.dim(0)?;
        for (we, wv) in &self.rounds {
            let mut agg = Tensor::zeros((nodes, self.latent), DType::F64, &Device::Cpu)?;
            if let Some(ev) = &e {
                let hr = h.index_select(&b.recv, 0)?;
                let hs = h.index_select(&b.send, 0)?;
                let de = we.forward(store, &Tensor::cat(&[ev, &hr, &hs], 1)?)?;
                let e_new = if self.residual { (ev + de)? } else { act(de)? };
                agg = agg.index_add(&b.recv, &e_new, 0)?;
                e = Some(e_new);
            }
            let dh = wv.forward(store, &Tensor::cat(&[&h, &agg], 1)?)?;
            h = if self.residual { (h + dh)? } else { act(dh)? };
        }
        Ok((h, e))
    }
}
