//! LGN: a full graph network gives the potential V_θ(q); the Lagrangian is
//! L = ½ q̇ᵀ M q̇ − V_θ(q) with a learnable diagonal mass M (one mass per
//! particle type), as the paper does "since Cartesian coordinates are used"
//! (following Finzi et al. 2020). Accelerations come from the generic
//! Euler–Lagrange code ([`super::mechanics::euler_lagrange`]) with the bar
//! constraints, so the Hessian ∇_q̇∇_q̇L and the mixed term are computed by
//! autodiff even though this L makes them M and 0; training differentiates
//! ∇_q L once more (grad-of-grad).

use super::mechanics::euler_lagrange;
use super::net::BaselineNet;
use crate::model::batch::Batch;
use anyhow::Result;
use candle_core::{Tensor, Var};

/// The learned Lagrangian summed over the batch.
pub fn lagrangian(net: &BaselineNet, b: &Batch, q: &Tensor, v: &Tensor) -> Result<Tensor> {
    let m = net.row_masses(b)?;
    let t = (v.sqr()?.broadcast_mul(&m)?.sum_all()? * 0.5)?;
    Ok((t - net.potential(b, q)?)?)
}

/// Accelerations `(B·n, d)` from Euler–Lagrange.
pub fn acceleration(net: &BaselineNet, b: &Batch) -> Result<Tensor> {
    let q = Var::from_tensor(&b.q)?;
    let v = Var::from_tensor(&b.v)?;
    euler_lagrange(
        |q, v| lagrangian(net, b, q, v),
        &q,
        &v,
        b.b,
        b.constraint.as_ref(),
    )
}
