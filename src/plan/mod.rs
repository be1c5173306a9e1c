//! Planning with a learned model: "what happens if I move like this?"
//! Candidate motions of the kinematic particles (a gripper, a pusher) are
//! rolled out through any [`crate::dynamics::Dynamics`] with the free
//! particles predicted under them ([`crate::dynamics::Dynamics::rollout_driven`]),
//! scored by a cost against targets, and searched by random shooting, CEM or
//! MPPI over all cores; [`mpc`] closes the loop against the ground truth.
//!
//! * [`controls`]: a candidate (the driven particles' velocity at the end of
//!   each control step) and the smooth motion it gives them;
//! * [`cost`]: distance of chosen particles to targets, at the end or along
//!   the horizon, plus control effort;
//! * [`search`]: the samplers and the parallel evaluation of candidates,
//!   small systems stepped several candidates at a time (`lanes`);
//! * [`gradient`]: ∂cost/∂controls by reverse mode through the rollout, and
//!   gradient steps that refine a search's best candidate;
//! * [`mpc`]: closed-loop episodes (plan, execute the first control, repeat).

pub mod controls;
pub mod cost;
pub mod gradient;
mod lanes;
pub mod mpc;
pub mod search;

pub use controls::Controls;
pub use cost::{Cost, CostKind};
pub use gradient::{refine, Gradient, RefineStep, Refined};
pub use mpc::{Episode, EpisodeReport};
pub use search::{plan, Iteration, Plan, PlanError, Problem, Sampler};
