//! LGN: a full graph network gives the potential V_θ(q); the Lagrangian is
//! L = ½ q̇ᵀ M q̇ − V_θ(q) with a learnable diagonal mass M (one mass per
//! particle type), as the paper does "since Cartesian coordinates are used"
//! (following Finzi et al. 2020). For this L the Hessian ∇_q̇∇_q̇L is M and the
//! mixed term is 0, so Euler–Lagrange needs only ∇_q L = −∂V/∂q, which comes
//! from a backward pass written as candle ops
//! ([`BaselineNet::potential_grad`]): training differentiates once. The
//! generic code ([`super::mechanics::euler_lagrange`], autodiff twice) is the
//! reference ([`acceleration_generic`]).

use super::mechanics::{euler_lagrange, solve_constrained};
use super::net::BaselineNet;
use crate::model::batch::Batch;
use anyhow::Result;
use candle_core::{DType, Device, Tensor, Var};

/// The learned Lagrangian summed over the batch.
pub fn lagrangian(net: &BaselineNet, b: &Batch, q: &Tensor, v: &Tensor) -> Result<Tensor> {
    let m = net.row_masses(b)?;
    let t = (v.sqr()?.broadcast_mul(&m)?.sum_all()? * 0.5)?;
    Ok((t - net.potential(b, q)?)?)
}

/// Accelerations `(B·n, d)` from Euler–Lagrange.
///
/// For this Lagrangian the Hessian ∇_q̇∇_q̇L is the learned diagonal mass M
/// and the mixed term ∇_q̇∇_q L is zero, exactly; only ∇_q L is left to
/// autodiff. The generic [`euler_lagrange`] (tested against it, see
/// [`acceleration_generic`]) would spend one backward pass per coordinate on
/// the Hessian and a full one on the mixed term.
pub fn acceleration(net: &BaselineNet, b: &Batch) -> Result<Tensor> {
    // ∇_q L = −∂V/∂q, by the hand-written backward pass (candle then
    // differentiates once in training).
    let gq = net.potential_grad(b, &b.q)?.neg()?;
    let dd = b.n * b.dim;
    let m = net
        .row_masses(b)?
        .broadcast_as((b.b * b.n, b.dim))?
        .reshape((b.b, 1, dd))?;
    let k = Tensor::eye(dd, DType::F64, &Device::Cpu)?
        .unsqueeze(0)?
        .broadcast_mul(&m)?;
    let n = gq.reshape((b.b, dd, 1))?;
    let acc = solve_constrained(&k, &n, b.constraint.as_ref())?;
    Ok(acc.reshape(b.q.dims())?)
}

/// The same accelerations through the generic Euler–Lagrange code (Hessian
/// and mixed term by autodiff), for checking [`acceleration`].
pub fn acceleration_generic(net: &BaselineNet, b: &Batch) -> Result<Tensor> {
    super::autodiff::ensure_second_order()?;
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
