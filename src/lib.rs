//! mcgnode: learned particle dynamics (GNODE, CGNODE, CDGNODE, MCGNODE and the
//! NODE baseline of Bishnoi et al.), trained from trajectories stored as MCAP bags
//! of ROS 2 `ParticleState` messages, rolled out on a hand-written kernel, and
//! served as a ROS 2 node.
//!
//! Data flows one way: [`physics`] → [`simulate`] → [`data`] (bags) →
//! [`train`] (on the [`engine`], or candle via [`gnode`]) → model file
//! ([`models`] loads and trains any kind) →
//! [`kernel`] rollouts ([`dynamics`], [`ros`]) and plans ([`plan`]) →
//! [`data`] → [`evaluate`](mod@evaluate) / [`replay`](mod@replay) → [`metrics`].
//!
//! What a library user needs is re-exported here: naming and loading a
//! model ([`ModelRef`], [`load_model`], [`load_any_model`]), rolling it out
//! ([`Dynamics`]), training one from bags ([`train_any_from_bags`]),
//! reading bags ([`read_trajectories`], [`read_bags`], [`ParticleState`])
//! and the systems ([`Graph`], [`State`], [`SystemKind`], [`SystemConfig`],
//! [`Field`]). The modules stay public for the command line's edge, the
//! Python package and the tests.

#![deny(missing_docs)]

pub mod alloc;
pub mod baselines;
pub mod bench;
pub mod calibration;
pub mod cli;
pub mod compat;
pub mod data;
pub mod dynamics;
pub mod engine;
pub mod error;
pub mod estimate;
pub mod evaluate;
pub mod gnode;
pub mod kernel;
pub mod lagrange_metrics;
pub mod metrics;
pub mod models;
pub mod names;
pub mod periodic;
pub mod physics;
pub mod plan;
pub mod plot;
pub mod replay;
pub mod reproduce;
pub mod ros;
pub mod simulate;
pub mod system;
#[doc(hidden)]
pub mod testing;
pub mod train;

pub use data::{read_bags, read_trajectories, Bag, ParticleState, ReadOptions};
pub use dynamics::{Dynamics, DynamicsError, Forces, Predicted, Rollout, Timing};
pub use error::{Error, Result};
pub use evaluate::{evaluate, EvalOptions, Evaluation};
pub use models::{
    load_any_model, load_model, train_any_from_bags, trained_for, LoadedModel, ModelKind, ModelRef,
};
pub use physics::{Field, SystemConfig, SystemKind};
pub use replay::{replay, ReplayOptions, ReplayReport};
pub use ros::{NodeParams, Recorder};
pub use system::{Graph, State, Trajectory};
pub use train::{ModelOptions, TrainConfig};
