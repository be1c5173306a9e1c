//! The full graph network shared by the baselines (Battaglia et al. 2018;
//! Cranmer et al. 2020; Sanchez-Gonzalez et al. 2020): node and edge encoders,
//! then rounds in which every edge is updated from (edge, receiver, sender) and
//! every node from (node, sum of incoming edges).
//!
//! Unlike the GNODE network (where the edge update sees only the two node
//! embeddings and the node update sees sender + edge), the full GN's edge
//! update reads its own edge state, and node updates aggregate updated edges.

use crate::error::Result;
use crate::gnode::batch::Batch;
use crate::gnode::mlp::{squareplus, squareplus_grad, Mlp};
use crate::gnode::params::ParamStore;
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
        let t = self.run_traced(store, b, q, node_x)?;
        Ok((t.h, t.e))
    }

    /// [`GraphNet::run`], keeping what [`GraphNet::input_grads`] needs.
    pub fn run_traced(
        &self,
        store: &ParamStore,
        b: &Batch,
        q: &Tensor,
        node_x: &Tensor,
    ) -> Result<Trace> {
        let (node_out, node_pre) = self.node_em.forward_keep(store, node_x)?;
        let mut h = squareplus(&node_out)?;
        let mut edge = None;
        let mut e = if b.n_directed > 0 {
            let w = (q.index_select(&b.recv, 0)? - q.index_select(&b.send, 0)?)?;
            let (feat, r) = if self.edge_distance {
                let r = w.sqr()?.sum_keepdim(1)?.sqrt()?;
                (Tensor::cat(&[&w, &r], 1)?, Some(r))
            } else {
                (w.clone(), None)
            };
            let (out, pre) = self.edge_em.forward_keep(store, &feat)?;
            let e = squareplus(&out)?;
            edge = Some(EdgeTrace { w, r, out, pre });
            Some(e)
        } else {
            None
        };
        let nodes = h.dim(0)?;
        let mut rounds = Vec::with_capacity(self.rounds.len());
        for (we, wv) in &self.rounds {
            let mut agg = Tensor::zeros((nodes, self.latent), DType::F64, &Device::Cpu)?;
            let mut edge_step = None;
            if let Some(ev) = &e {
                let hr = h.index_select(&b.recv, 0)?;
                let hs = h.index_select(&b.send, 0)?;
                let (de, pre) = we.forward_keep(store, &Tensor::cat(&[ev, &hr, &hs], 1)?)?;
                let e_new = if self.residual {
                    (ev + &de)?
                } else {
                    squareplus(&de)?
                };
                agg = agg.index_add(&b.recv, &e_new, 0)?;
                e = Some(e_new);
                edge_step = Some((de, pre));
            }
            let (dh, node_pre) = wv.forward_keep(store, &Tensor::cat(&[&h, &agg], 1)?)?;
            h = if self.residual {
                (h + &dh)?
            } else {
                squareplus(&dh)?
            };
            rounds.push(RoundTrace {
                edge: edge_step,
                node: (dh, node_pre),
            });
        }
        Ok(Trace {
            node: (node_out, node_pre),
            edge,
            rounds,
            h,
            e,
        })
    }

    /// The backward pass of [`GraphNet::run_traced`] with respect to its
    /// inputs, written as candle ops (so that candle can differentiate it in
    /// the weights): given ∂s/∂h and ∂s/∂e of the outputs for a scalar s,
    /// returns (∂s/∂node_x, the part of ∂s/∂q that flows through the edge
    /// features). LGN and HGN train on ∂V/∂q; computing it this way, rather
    /// than by a first autodiff pass, lets candle differentiate only once.
    pub fn input_grads(
        &self,
        store: &ParamStore,
        b: &Batch,
        t: &Trace,
        dh: &Tensor,
        de: Option<&Tensor>,
    ) -> Result<(Tensor, Option<Tensor>)> {
        let l = self.latent;
        let mut gh = dh.clone();
        let mut ge = de.cloned();
        for ((we, wv), r) in self.rounds.iter().zip(&t.rounds).rev() {
            let gdh = self.through_update(&gh, &r.node.0)?;
            let gcat = wv.input_grad(store, &r.node.1, &gdh)?;
            let mut gh_prev = gcat.narrow(1, 0, l)?;
            if self.residual {
                gh_prev = (gh_prev + &gh)?;
            }
            if let Some((de_out, pre)) = &r.edge {
                // agg = Σ_recv e_new, so e_new also receives ∂s/∂agg[recv].
                let from_agg = gcat
                    .narrow(1, l, l)?
                    .contiguous()?
                    .index_select(&b.recv, 0)?;
                let ge_new = match &ge {
                    Some(g) => (g + from_agg)?,
                    None => from_agg,
                };
                let gde = self.through_update(&ge_new, de_out)?;
                let gcat_e = we.input_grad(store, pre, &gde)?;
                let mut ge_prev = gcat_e.narrow(1, 0, l)?;
                if self.residual {
                    ge_prev = (ge_prev + &ge_new)?;
                }
                gh_prev = gh_prev
                    .index_add(&b.recv, &gcat_e.narrow(1, l, l)?.contiguous()?, 0)?
                    .index_add(&b.send, &gcat_e.narrow(1, 2 * l, l)?.contiguous()?, 0)?;
                ge = Some(ge_prev);
            }
            gh = gh_prev;
        }
        let (node_out, node_pre) = &t.node;
        let gx = self
            .node_em
            .input_grad(store, node_pre, &(gh * squareplus_grad(node_out)?)?)?;
        let gq = match (&t.edge, ge) {
            (Some(et), Some(ge)) => {
                let gfeat =
                    self.edge_em
                        .input_grad(store, &et.pre, &(ge * squareplus_grad(&et.out)?)?)?;
                let d = et.w.dim(1)?;
                let mut gw = gfeat.narrow(1, 0, d)?.contiguous()?;
                if let Some(r) = &et.r {
                    // ∂|w|/∂w = w / |w|.
                    gw = (gw
                        + gfeat
                            .narrow(1, d, 1)?
                            .broadcast_mul(&et.w.broadcast_div(r)?)?)?;
                }
                let zeros = Tensor::zeros((gx.dim(0)?, d), DType::F64, &Device::Cpu)?;
                Some(
                    zeros
                        .index_add(&b.recv, &gw, 0)?
                        .index_add(&b.send, &gw.neg()?, 0)?,
                )
            }
            _ => None,
        };
        Ok((gx, gq))
    }

    /// ∂s/∂(update output) from ∂s/∂(new latent): the identity for residual
    /// updates, squareplus' otherwise.
    fn through_update(&self, g: &Tensor, out: &Tensor) -> Result<Tensor> {
        Ok(if self.residual {
            g.clone()
        } else {
            (g * squareplus_grad(out)?)?
        })
    }
}

/// What a forward pass keeps for [`GraphNet::input_grads`].
#[derive(Clone, Debug)]
pub struct Trace {
    /// Node encoder: output before the activation, hidden pre-activations.
    node: (Tensor, Vec<Tensor>),
    /// Edge encoder, when the batch has edges.
    edge: Option<EdgeTrace>,
    /// Per round.
    rounds: Vec<RoundTrace>,
    /// Final node latents.
    pub h: Tensor,
    /// Final directed-edge latents.
    pub e: Option<Tensor>,
}

#[derive(Clone, Debug)]
struct EdgeTrace {
    /// w_ij = q_i − q_j.
    w: Tensor,
    /// |w_ij| when it is a feature.
    r: Option<Tensor>,
    /// Encoder output before the activation.
    out: Tensor,
    /// Encoder hidden pre-activations.
    pre: Vec<Tensor>,
}

#[derive(Clone, Debug)]
struct RoundTrace {
    /// Edge update output and hidden pre-activations.
    edge: Option<(Tensor, Vec<Tensor>)>,
    /// Node update output and hidden pre-activations.
    node: (Tensor, Vec<Tensor>),
}
