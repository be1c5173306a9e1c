//! HGN: a full graph network gives the potential V_θ(q); the Hamiltonian is
//! H = ½ pᵀ M⁻¹ p + V_θ(q) with a learnable diagonal mass M (one per type).
//! Dynamics from the generic Hamilton code ([`super::mechanics::hamilton`]):
//! q̇ = ∂H/∂p, ṗ = −∂H/∂q − Aᵀλ for pendulum bars, λ keeping A q̈ + Ȧq̇ = 0.
//! Trained on (q̇, ṗ) targets; the data come from RK4 integration of the true
//! Hamiltonian system ([`crate::physics::rk4::rk4_trajectories`]), as the paper
//! says.

use super::mechanics::hamilton;
use super::net::BaselineNet;
use crate::error::{bail, Result};
use crate::gnode::batch::Batch;
use crate::system::State;
use candle_core::{Device, Tensor, Var};

/// The learned Hamiltonian summed over the batch.
pub fn hamiltonian(net: &BaselineNet, b: &Batch, q: &Tensor, p: &Tensor) -> Result<Tensor> {
    let m = net.row_masses(b)?;
    let t = (p.sqr()?.broadcast_div(&m)?.sum_all()? * 0.5)?;
    Ok((t + net.potential(b, q)?)?)
}

/// (q̇, ṗ) at the batch positions and momenta `p` `(B·n, d)`.
///
/// This H is separable with a diagonal learned mass, so ∂H/∂p = M⁻¹p,
/// H_pp = M⁻¹ and H_pq = 0 exactly, and ṗ is the force
/// [`BaselineNet::bar_constrained_force`] (Hamilton's multipliers with those
/// terms). [`derivatives_generic`] (autodiff twice) is the reference it is
/// tested against.
pub fn derivatives(net: &BaselineNet, b: &Batch, p: &Tensor) -> Result<(Tensor, Tensor)> {
    let qdot = p.broadcast_div(&net.row_masses(b)?)?;
    Ok((qdot, net.bar_constrained_force(b)?))
}

/// The same derivatives through the generic Hamilton code (all derivatives
/// of H by autodiff, twice in training), for checking [`derivatives`].
pub fn derivatives_generic(net: &BaselineNet, b: &Batch, p: &Tensor) -> Result<(Tensor, Tensor)> {
    super::autodiff::ensure_second_order()?;
    let q = Var::from_tensor(&b.q)?;
    let p = Var::from_tensor(p)?;
    hamilton(
        |q, p| hamiltonian(net, b, q, p),
        &q,
        &p,
        b.b,
        b.constraint.as_ref(),
    )
}

/// Accelerations for rollouts: p = M q̇ with the learned masses, then
/// q̈ = M⁻¹ ṗ (exact for this separable H, where ∂H/∂p = M⁻¹p).
pub fn acceleration(net: &BaselineNet, b: &Batch) -> Result<Tensor> {
    let m = net.row_masses(b)?;
    let p = b.v.broadcast_mul(&m)?;
    let (_, pdot) = derivatives(net, b, &p)?;
    Ok(pdot.broadcast_div(&m)?)
}

/// MSE over (q̇, ṗ) against (v, m∘a) with the true masses: the momenta fed to
/// the network are p = m∘v, as recorded by a Hamiltonian simulation.
pub fn loss(net: &BaselineNet, b: &Batch, masses: &[f64]) -> Result<Tensor> {
    loss_with(derivatives, net, b, masses)
}

/// The loss of predicting q̇ = 0 and ṗ = 0 on the samples `idx`:
/// ½ (mean v² + mean (m a)²), in [`loss`]'s units.
pub fn trivial_loss(states: &[State], acc: &[Vec<f64>], masses: &[f64], idx: &[usize]) -> f64 {
    let (mut v2, mut p2, mut count) = (0.0, 0.0, 0usize);
    for &i in idx {
        let d = acc[i].len() / masses.len().max(1);
        v2 += states[i].v.iter().map(|x| x * x).sum::<f64>();
        p2 += acc[i]
            .iter()
            .enumerate()
            .map(|(k, a)| (masses[k / d.max(1)] * a).powi(2))
            .sum::<f64>();
        count += acc[i].len();
    }
    if count == 0 {
        0.0
    } else {
        0.5 * (v2 + p2) / count as f64
    }
}

/// [`loss`] through [`derivatives_generic`], for checking its gradients.
pub fn loss_generic(net: &BaselineNet, b: &Batch, masses: &[f64]) -> Result<Tensor> {
    loss_with(derivatives_generic, net, b, masses)
}

type Derivatives = fn(&BaselineNet, &Batch, &Tensor) -> Result<(Tensor, Tensor)>;

fn loss_with(derivs: Derivatives, net: &BaselineNet, b: &Batch, masses: &[f64]) -> Result<Tensor> {
    let Some(acc) = &b.target else {
        bail!("batch has no targets");
    };
    if masses.len() != b.n {
        bail!("{} masses for {} particles", masses.len(), b.n);
    }
    let m: Vec<f64> = (0..b.b).flat_map(|_| masses.iter().copied()).collect();
    let m = Tensor::from_vec(m, (b.b * b.n, 1), &Device::Cpu)?;
    let p = b.v.broadcast_mul(&m)?;
    let (qd, pd) = derivs(net, b, &p)?;
    let lq = (qd - &b.v)?.sqr()?.mean_all()?;
    let lp = (pd - acc.broadcast_mul(&m)?)?.sqr()?.mean_all()?;
    Ok(((lq + lp)? * 0.5)?)
}
