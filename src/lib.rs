//! mcgnode: learned particle dynamics (GNODE, CGNODE, CDGNODE, MCGNODE and the
//! NODE baseline of Bishnoi et al.), trained from trajectories stored as MCAP bags
//! of ROS 2 `ParticleState` messages, rolled out on a hand-written kernel, and
//! served as a ROS 2 node.
//!
//! Data flows one way: [`physics`] → [`simulate`] → [`data`] (bags) →
//! [`train`] (on the [`engine`], or candle via [`model`]) → model file
//! ([`models`] loads and trains any kind) →
//! [`kernel`] rollouts ([`dynamics`], [`ros`]) → [`data`] → [`evaluate`] /
//! [`replay`] → [`metrics`].

#![deny(missing_docs)]

pub mod alloc;
pub mod baselines;
pub mod bench;
pub mod cli;
pub mod compat;
pub mod data;
pub mod dynamics;
pub mod engine;
pub mod error;
pub mod evaluate;
pub mod kernel;
pub mod metrics;
pub mod model;
pub mod models;
pub mod names;
pub mod physics;
pub mod plot;
pub mod replay;
pub mod reproduce;
pub mod ros;
pub mod simulate;
pub mod system;
#[doc(hidden)]
pub mod testing;
pub mod train;

pub use error::{Error, Result};
