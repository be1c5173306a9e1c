//! Baselines of the paper: LGN and HGN (graph networks that output a
//! Lagrangian / Hamiltonian, differentiated into accelerations) and GNS
//! (encode-process-decode graph network simulator predicting accelerations).
//! They use the same data, splits, metrics and rollout (the
//! [`crate::dynamics::Dynamics`] trait) as the GNODE family.
//!
//! Choices (the paper gives few details):
//! * LGN/HGN use a full graph network (`graphnet`; embeddings 8, MLPs with
//!   one hidden layer of 16, squareplus, one round, as the paper's table). It
//!   outputs a potential V_θ(q) as a sum of node and edge energies; the kinetic
//!   energy is ½ q̇ᵀMq̇ (LGN) or ½ pᵀM⁻¹p (HGN) with a learnable diagonal mass
//!   per particle type, "since Cartesian coordinates are used" (paper, after
//!   Finzi et al. 2020).
//! * Derivatives: with a diagonal learned mass, LGN and HGN need only ∂V/∂q
//!   of the learned potential, written as a backward pass in candle ops
//!   (`graphnet::GraphNet::input_grads`, `net::BaselineNet::potential_grad`),
//!   so training differentiates once. Generic code (`mechanics`) that works
//!   for any scalar L(q, q̇) or H(q, p) and handles rigid bars is the
//!   reference: tested against hand-written Lagrangians and Hamiltonians of
//!   the true systems, and the baselines' shortcuts against it. It needs
//!   candle's grad-of-grad (`autodiff`), which it switches on itself.
//! * HGN trains on (q̇, ṗ); its data come from RK4 on (q, p)
//!   ([`crate::physics::rk4::rk4_trajectories`]). LGN and GNS train on accelerations.

pub(crate) mod autodiff;
pub(crate) mod forward;
pub(crate) mod gns;
pub(crate) mod graphnet;
pub mod hgn;
pub mod lgn;
pub(crate) mod mechanics;
pub(crate) mod net;

pub use net::{BaselineHyper, BaselineNet, Kind};
pub(crate) mod file;
pub(crate) mod train;
pub(crate) mod trained;

pub use autodiff::{ensure_second_order, probe_second_derivative, DO_NOT_DETACH};
pub use file::{BaselineFile, FORMAT};
pub use graphnet::{GraphNet, GraphNetSpec};
pub use mechanics::{euler_lagrange, hamilton};
pub use train::train_baseline;
pub(crate) use train::train_baseline_from_bags;
pub use trained::TrainedBaseline;
