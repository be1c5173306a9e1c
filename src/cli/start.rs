//! Where a rollout or a plan starts: the first state of a bag's trajectory,
//! or a state drawn as `simulate` draws them (shared by `rollout` and `plan`).

use crate::data::bag::{read_bags, ReadOptions};
use crate::data::field::bag_system;
use crate::physics::{Field, SystemConfig, SystemKind};
use crate::system::{Graph, State};
use anyhow::{Context, Result};
use std::path::PathBuf;

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
}

/// The first state of trajectory `trajectory` of the bags `paths`.
pub(crate) fn from_bag(paths: &[PathBuf], topic: Option<String>, trajectory: u32) -> Result<Start> {
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
    })
}

/// A start of `system` with `particles` particles drawn with `seed`.
pub(crate) fn drawn(system: SystemKind, particles: usize, seed: u64) -> Result<Start> {
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
    })
}
