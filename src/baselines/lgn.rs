//! LGN: a full graph network gives the potential V_θ(q); the Lagrangian is
//! L = ½ q̇ᵀ M q̇ − V_θ(q) with a learnable diagonal mass M (one mass per
//! particle type), as the paper does "since Cartesian coordinates are used"
//! (following Finzi et al. 2020). For this L the Hessian ∇_q̇∇_q̇L is M and the
//! mixed term is 0, so Euler–Lagrange needs only ∇_q L = −∂V/∂q, which comes
//! from a backward pass written as candle ops
//! ([`BaselineNet::potential_grad`]): training differentiates once. The
//! generic code ([`super::mechanics::euler_lagrange`], autodiff twice) is the
//! reference ([`acceleration_generic`]).

use super::mechanics::euler_lagrange;
use super::net::BaselineNet;
use crate::error::Result;
use crate::gnode::batch::Batch;
use candle_core::{Tensor, Var};

/// The learned Lagrangian summed over the batch.
pub fn lagrangian(net: &BaselineNet, b: &Batch, q: &Tensor, v: &Tensor) -> Result<Tensor> {
    let m = net.row_masses(b)?;
    let t = (v.sqr()?.broadcast_mul(&m)?.sum_all()? * 0.5)?;
    Ok((t - net.potential(b, q)?)?)
}

/// Accelerations `(B·n, d)` from Euler–Lagrange.
///
/// For this Lagrangian the Hessian ∇_q̇∇_q̇L is the learned diagonal mass M
/// and the mixed term ∇_q̇∇_q L is zero, exactly, so q̈ = M⁻¹ f with f the
/// force [`BaselineNet::bar_constrained_force`] (the same as HGN's ṗ). The
/// generic [`euler_lagrange`] (tested against it, see
/// [`acceleration_generic`]) would spend one backward pass per coordinate on
/// the Hessian and a full one on the mixed term.
pub fn acceleration(net: &BaselineNet, b: &Batch) -> Result<Tensor> {
    Ok(net
        .bar_constrained_force(b)?
        .broadcast_div(&net.row_masses(b)?)?)
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
