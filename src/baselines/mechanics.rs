//! Equations of motion from a scalar: Euler–Lagrange for LGN, Hamilton for HGN,
//! both with the rigid-bar constraints A(q) q̇ = 0 of the batch. Generic in the
//! scalar (any closure of candle ops), so the same code is tested against
//! hand-written Lagrangians and Hamiltonians and then used for the networks.

use super::autodiff::{grads, hessian};
use crate::error::Result;
use crate::gnode::solve::solve;
use candle_core::{Tensor, Var};

/// Constraint rows of a batch: A `(B, k, D)`, Aᵀ `(B, D, k)`, Ȧq̇ `(B, k, 1)`.
pub type Constraint = (Tensor, Tensor, Tensor);

/// Accelerations `(B·n, d)` from a Lagrangian.
///
/// `lag(q, q̇)` returns the Lagrangian summed over the batch (a scalar; samples
/// are independent, so its gradients are per-sample). Euler–Lagrange with
/// constraint forces −Aᵀλ:
/// K q̈ = N − Aᵀλ, K = ∇_q̇∇_q̇ L, N = ∇_q L − (∇_q̇∇_q L) q̇, and λ from
/// A q̈ + Ȧq̇ = 0: λ = (A K⁻¹ Aᵀ)⁻¹ (A K⁻¹ N + Ȧq̇).
pub fn euler_lagrange(
    lag: impl Fn(&Tensor, &Tensor) -> Result<Tensor>,
    q: &Var,
    v: &Var,
    b: usize,
    constraint: Option<&Constraint>,
) -> Result<Tensor> {
    let shape = q.as_tensor().dims().to_vec();
    let dd = q.elem_count() / b;
    let l = lag(q.as_tensor(), v.as_tensor())?;
    let mut g = grads(&l, &[q, v])?;
    let (gq, gv) = (g.remove(0), g.remove(0));
    let k = hessian(&gv, v, b)?;
    // (∇_q̇∇_q L) q̇ = ∇_q̇ (∇_q L · q̇) with q̇ held fixed: one backward pass.
    let vfix = v.as_tensor().detach();
    let mixed = grads(&(&gq * &vfix)?.sum_all()?, &[v])?.remove(0);
    let n = (gq - mixed)?.reshape((b, dd, 1))?;
    Ok(solve_constrained(&k, &n, constraint)?.reshape(shape)?)
}

/// x = K⁻¹(N − Aᵀλ) with the constraint force, or K⁻¹N without bars; all batched.
pub fn solve_constrained(
    k: &Tensor,
    n: &Tensor,
    constraint: Option<&Constraint>,
) -> Result<Tensor> {
    match constraint {
        None => Ok(solve(k, n)?),
        Some((a, at, adq)) => constrained(k, n, a, at, adq),
    }
}

/// x = K⁻¹(N − Aᵀλ) with λ = (A K⁻¹ Aᵀ)⁻¹(A K⁻¹ N + Ȧq̇); all batched.
fn constrained(k: &Tensor, n: &Tensor, a: &Tensor, at: &Tensor, adq: &Tensor) -> Result<Tensor> {
    let kc = at.dim(2)?;
    let x = solve(k, &Tensor::cat(&[n, at], 2)?)?;
    let (xn, xa) = (x.narrow(2, 0, 1)?, x.narrow(2, 1, kc)?);
    let s = a.matmul(&xa)?;
    let lambda = solve(&s, &(a.matmul(&xn)? + adq)?)?;
    Ok((xn - xa.matmul(&lambda)?)?)
}

/// Hamilton's equations `(q̇, ṗ)`, each `(B·n, d)`.
///
/// `ham(q, p)` returns the Hamiltonian summed over the batch. q̇ = ∂H/∂p,
/// ṗ = −∂H/∂q − Aᵀλ, with λ keeping A q̈ + Ȧq̇ = 0 where q̈ = H_pq q̇ + H_pp ṗ:
/// λ = (A H_pp Aᵀ)⁻¹ (A H_pq q̇ − A H_pp ∂H/∂q + Ȧq̇). Ȧq̇ comes from the
/// batch (built from the state's velocities).
pub fn hamilton(
    ham: impl Fn(&Tensor, &Tensor) -> Result<Tensor>,
    q: &Var,
    p: &Var,
    b: usize,
    constraint: Option<&Constraint>,
) -> Result<(Tensor, Tensor)> {
    let shape = q.as_tensor().dims().to_vec();
    let dd = q.elem_count() / b;
    let h = ham(q.as_tensor(), p.as_tensor())?;
    let mut g = grads(&h, &[q, p])?;
    let (gq, gp) = (g.remove(0), g.remove(0));
    let Some((a, at, adq)) = constraint else {
        return Ok((gp, gq.neg()?));
    };
    let hpp = hessian(&gp, p, b)?;
    // H_pq q̇ = ∇_p(∇_q H · q̇) with q̇ = ∂H/∂p held fixed.
    let qdot_fix = gp.detach();
    let hpq_qdot = grads(&(&gq * &qdot_fix)?.sum_all()?, &[p])?.remove(0);
    let gq3 = gq.reshape((b, dd, 1))?;
    let rhs = ((a.matmul(&hpq_qdot.reshape((b, dd, 1))?)? - a.matmul(&hpp.matmul(&gq3)?)?)? + adq)?;
    let s = a.matmul(&hpp)?.matmul(at)?;
    let lambda = solve(&s, &rhs)?;
    let pdot = (gq3.neg()? - at.matmul(&lambda)?)?.reshape(shape)?;
    Ok((gp, pdot))
}
