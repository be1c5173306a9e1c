//! GNS (Sanchez-Gonzalez et al. 2020): encode-process-decode predicting
//! accelerations, trained on accelerations like GNODE.
//!
//! Differences from GNODE as implemented here: edge features include the
//! distance |w_ij| besides w_ij; the processor runs several rounds (default 2)
//! of full-GN blocks whose edge update reads the edge's own latent, with
//! residual updates and no activation on the residual stream; a separate
//! decoder maps node latents to accelerations. Smaller than the original
//! (latent 16, one hidden layer of 16, no LayerNorm; the original has 128,
//! two hidden layers, LayerNorm, 10 steps) to match this project's scale.

use super::net::BaselineNet;
use crate::error::Result;
use crate::gnode::batch::Batch;
use candle_core::Tensor;

/// Accelerations `(B·n, d)`.
pub fn acceleration(net: &BaselineNet, b: &Batch) -> Result<Tensor> {
    let x = Tensor::cat(&[&b.onehot, &b.q, &b.v], 1)?;
    let (h, _) = net.graph.run(&net.store, b, &b.q, &x)?;
    net.node_out.forward(&net.store, &h)
}
