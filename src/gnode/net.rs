//! The candle model: the paper's equations, one bias per piece.

use super::arch::{Arch, Block, Decoder, NodeInput, EDGE_PHYSICS, LOG_MASS};
use super::batch::Batch;
use super::mlp::{squareplus, Mlp};
use super::params::ParamStore;
use super::solve::solve;
use super::variant::{EdgeInput, Hyper, Variant};
use crate::error::{bail, Result};
use candle_core::{DType, Device, Tensor};
use rand::Rng;

/// The MLPs of a model, built from its [`Arch`].
#[derive(Clone, Debug)]
pub struct Parts {
    /// The architecture they realise.
    pub arch: Arch,
    mlps: Vec<(Block, Mlp)>,
}

impl Parts {
    /// Declares the parameters of a model in `store` (in the architecture's
    /// definition order, which fixes what a seed draws).
    pub fn build(h: &Hyper, store: &mut ParamStore, rng: &mut impl Rng) -> Result<Self> {
        let arch = Arch::new(h);
        let mut mlps = vec![];
        for (block, sizes) in &arch.mlps {
            mlps.push((*block, Mlp::new(store, &block.prefix(), sizes, rng)?));
        }
        if arch.constrained {
            store.insert(LOG_MASS, &[arch.types], vec![0.0; arch.types])?;
        }
        Ok(Parts { arch, mlps })
    }

    /// The MLP of a block, if the architecture has it.
    pub fn mlp(&self, block: Block) -> Option<&Mlp> {
        self.mlps.iter().find(|(b, _)| *b == block).map(|(_, m)| m)
    }

    fn need(&self, block: Block) -> Result<&Mlp> {
        self.mlp(block)
            .ok_or_else(|| crate::error::err!("architecture has no {block} block"))
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

    /// Sets the input and output scales (they do not change the parameters).
    pub fn set_norm(&mut self, norm: Option<super::variant::Norm>) {
        self.hyper.norm = norm;
        self.parts.arch = Arch::new(&self.hyper);
    }

    /// Forward pass on a batch: the paper's equations, stage by stage as the
    /// architecture describes them.
    pub fn forward(&self, b: &Batch) -> Result<Output> {
        if let Some(mlp) = self.parts.mlp(Block::Flat) {
            return self.forward_flat(mlp, b);
        }
        let arch = &self.parts.arch;
        let (q, v) = self.scaled_state(b)?;
        let full = Tensor::cat(&[&b.onehot, &q, &v], 1)?;
        let (h, he) = self.encode(b, &full)?;
        let (h, he) = self.message_passing(b, h, he)?;
        let glob = match self.parts.mlp(Block::GlobalEmbed) {
            Some(g) => Some(squareplus(&g.forward(&self.store, &full)?)?),
            None => None,
        };
        let out = (self.decode(b, h, he.as_ref(), glob.as_ref())? * arch.norm.out_scale)?;
        // Constrain.
        if !arch.constrained {
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

    /// NODE: one MLP from the whole scaled state to every acceleration.
    fn forward_flat(&self, mlp: &Mlp, b: &Batch) -> Result<Output> {
        let arch = &self.parts.arch;
        if b.n != arch.particles {
            bail!(
                "NODE was built for {} particles, got {} (NODE is not inductive)",
                arch.particles,
                b.n
            );
        }
        let nd = b.n * b.dim;
        let (q, v) = self.scaled_state(b)?;
        let x = Tensor::cat(&[q.reshape((b.b, nd))?, v.reshape((b.b, nd))?], 1)?;
        let acc =
            (mlp.forward(&self.store, &x)?.reshape((b.b * b.n, b.dim))? * arch.norm.out_scale)?;
        Ok(Output { acc, force: None })
    }

    /// Encode: node states from (one-hot[, q, q̇]), edge states from
    /// w_ij = q_i − q_j (and the edge's physics, the contact flag).
    fn encode(&self, b: &Batch, full: &Tensor) -> Result<(Tensor, Option<Tensor>)> {
        let (s, p) = (&self.store, &self.parts);
        let arch = &p.arch;
        let node_in = match arch.node_input {
            NodeInput::TypeOnly => &b.onehot,
            NodeInput::Full => full,
        };
        let h = squareplus(&p.need(Block::NodeEmbed)?.forward(s, node_in)?)?;
        if b.n_directed == 0 {
            return Ok((h, None));
        }
        let mut w = (gather(&b.q, &b.recv)? - gather(&b.q, &b.send)?)?;
        if let Some(shift) = &b.image_shift {
            w = (w + shift)?;
        }
        let mut w = (w / arch.norm.w_scale)?;
        if arch.edge_physics {
            let scale = arch.edge_physics_scale().map(|s| 1.0 / s);
            let scale = Tensor::from_slice(&scale, (1, EDGE_PHYSICS), &Device::Cpu)?;
            w = Tensor::cat(&[&w, &b.edge_params.broadcast_mul(&scale)?], 1)?;
        }
        if arch.contacts() {
            w = Tensor::cat(&[&w, &b.contact], 1)?;
        }
        let he = squareplus(&p.need(Block::EdgeEmbed)?.forward(s, &w)?)?;
        Ok((h, Some(he)))
    }

    /// The rounds of message passing: h_i ← sqp(h_i + Σ_j W_V(h_j ‖ h_ij)),
    /// h_ij ← sqp(h_ij + W_E(h_i, h_j)) from the node states before the round.
    fn message_passing(
        &self,
        b: &Batch,
        mut h: Tensor,
        mut he: Option<Tensor>,
    ) -> Result<(Tensor, Option<Tensor>)> {
        let (s, p) = (&self.store, &self.parts);
        let arch = &p.arch;
        for l in 0..arch.rounds {
            let (wv, we) = (p.need(Block::Message(l))?, p.need(Block::EdgeUpdate(l))?);
            let Some(e) = &he else {
                h = squareplus(&h)?;
                continue;
            };
            let hs = gather(&h, &b.send)?;
            let hr = gather(&h, &b.recv)?;
            let msg = wv.forward(s, &Tensor::cat(&[&hs, e], 1)?)?;
            let agg = Tensor::zeros((b.b * b.n, arch.embed), DType::F64, &Device::Cpu)?
                .index_add(&b.recv, &msg, 0)?;
            let ends = match arch.edge_input {
                EdgeInput::Concat => Tensor::cat(&[&hr, &hs], 1)?,
                EdgeInput::Product => (&hr * &hs)?,
            };
            let e_new = squareplus(&(e + we.forward(s, &ends)?)?)?;
            h = squareplus(&(h + agg)?)?;
            he = Some(e_new);
        }
        Ok((h, he))
    }

    /// Decode: pairwise forces F_ab = (f_ab − f_ba)/2 on a and −F_ab on b
    /// (Newton's third law) plus body forces, or a per-node output.
    fn decode(
        &self,
        b: &Batch,
        h: Tensor,
        he: Option<&Tensor>,
        glob: Option<&Tensor>,
    ) -> Result<Tensor> {
        let (s, p) = (&self.store, &self.parts);
        match p.arch.decoder {
            Decoder::Pairwise { .. } => {
                let mut n_int = Tensor::zeros((b.b * b.n, b.dim), DType::F64, &Device::Cpu)?;
                if let Some(e) = he {
                    let f = p.need(Block::EdgeDecoder)?.forward(s, e)?;
                    let half = b.n_directed / 2;
                    let fa = ((f.narrow(0, 0, half)? - f.narrow(0, half, half)?)? * 0.5)?;
                    let full_f = Tensor::cat(&[&fa, &fa.neg()?], 0)?;
                    n_int = n_int.index_add(&b.recv, &full_f, 0)?;
                }
                Ok(match (p.mlp(Block::BodyDecoder), glob) {
                    (Some(bo), Some(g)) => (n_int + bo.forward(s, g)?)?,
                    _ => n_int,
                })
            }
            Decoder::Node { .. } => {
                let inp = match glob {
                    Some(g) => Tensor::cat(&[&h, g], 1)?,
                    None => h,
                };
                p.need(Block::NodeDecoder)?.forward(s, &inp)
            }
        }
    }

    /// Scaled node inputs ((q − μ_q)/σ_q, q̇/σ_v).
    fn scaled_state(&self, b: &Batch) -> Result<(Tensor, Tensor)> {
        let n = &self.parts.arch.norm;
        let mu = Tensor::from_slice(&n.q_mean, (1, b.dim), &Device::Cpu)?;
        let q = (b.q.broadcast_sub(&mu)? / n.q_scale)?;
        let v = (&b.v / n.v_scale)?;
        Ok((q, v))
    }

    /// q̈ = M⁻¹(N − Aᵀλ), λ = (A M⁻¹ Aᵀ)⁻¹(A M⁻¹ N + Ȧq̇) (paper eq. for q̈; Π = C = 0).
    fn constrained_acc(&self, b: &Batch, force: &Tensor) -> Result<Tensor> {
        let nd = b.n * b.dim;
        let inv_m = self.store.get(LOG_MASS)?.as_tensor().neg()?.exp()?;
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

    /// Mean squared error of predicted accelerations against the batch
    /// targets, over the free particles (kinematic ones are given).
    pub fn loss(&self, b: &Batch) -> Result<Tensor> {
        b.mse(&self.forward(b)?.acc)
    }

    /// The variant.
    pub fn variant(&self) -> Variant {
        self.hyper.variant
    }
}
