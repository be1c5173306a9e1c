//! Where a rollout or a plan starts: the first state of a bag's trajectory,
//! or a state drawn as `simulate` draws them (shared by `rollout` and `plan`).

use crate::data::bag::{read_bags, ReadOptions};
use crate::data::field::bag_system;
use crate::physics::{Field, SystemConfig, SystemKind};
use crate::system::{Graph, State};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// Where to start, as `rollout` and `plan` take it.
#[derive(clap::Args, Debug, Clone)]
pub(crate) struct StartArgs {
    /// Free particles of the drawn start (any: graph models are inductive).
    #[arg(long, default_value_t = 5)]
    pub particles: usize,
    /// Seed of the drawn start.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Start from the first state of this bag instead (its trajectory
    /// `--trajectory`): an MCAP file, a rosbag2 directory or a .db3 file
    /// (several: the first trajectory with that id).
    #[arg(long, num_args = 1..)]
    pub initial: Option<Vec<PathBuf>>,
    /// The ParticleState topic of `--initial`, when it holds several.
    #[arg(long)]
    pub topic: Option<String>,
    /// Trajectory id within `--initial`.
    #[arg(long, default_value_t = 0)]
    pub trajectory: u32,
}

impl StartArgs {
    /// The start: `--initial`'s, else one of `system` drawn as `simulate` does.
    pub fn start(&self, system: SystemKind) -> Result<Start> {
        match &self.initial {
            Some(paths) => from_bag(paths, self.topic.clone(), self.trajectory),
            None => drawn(system, self.particles, self.seed),
        }
    }
}

/// A start and what is known about its system.
pub(crate) struct Start {
    /// The system.
    pub graph: Graph,
    /// The state.
    pub state: State,
    /// The system's name ("" when a bag does not say).
    pub system: String,
    /// The simulator's configuration, when known.
    pub cfg: Option<SystemConfig>,
    /// The field, when known.
    pub field: Option<Field>,
    /// The bag's first recorded interval, when read from a bag.
    pub stamp_dt: Option<f64>,
    /// The recorded samples, when read from a bag (what its kinematic
    /// particles did, for rollouts that follow them).
    pub recorded: Vec<crate::system::Sample>,
}

/// The first state of trajectory `trajectory` of the bags `paths`.
fn from_bag(paths: &[PathBuf], topic: Option<String>, trajectory: u32) -> Result<Start> {
    let bag = read_bags(paths, &ReadOptions { topic }).context("reading --initial")?;
    let cfg = bag_system(&bag)?;
    let field = bag.field.clone().or(cfg.as_ref().map(|c| c.field.clone()));
    let tr = bag
        .trajectories
        .into_iter()
        .find(|t| t.id == trajectory)
        .with_context(|| format!("--initial has no trajectory {trajectory}"))?;
    let stamp_dt = tr.samples.get(1).map(|s| s.t - tr.samples[0].t);
    Ok(Start {
        state: tr.samples[0].state.clone(),
        graph: tr.graph,
        system: tr.system,
        cfg,
        field,
        stamp_dt,
        recorded: tr.samples,
    })
}

/// A start of `system` with `particles` particles drawn with `seed`.
fn drawn(system: SystemKind, particles: usize, seed: u64) -> Result<Start> {
    let cfg = SystemConfig::new(system, particles);
    cfg.validate()?;
    let graph = cfg.graph();
    let state = cfg.start_for(&graph, seed, 0);
    Ok(Start {
        graph,
        state,
        system: system.name().to_string(),
        field: Some(cfg.field.clone()),
        cfg: Some(cfg),
        stamp_dt: None,
        recorded: vec![],
    })
}
