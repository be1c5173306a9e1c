//! `mcgnode simulate`.

use crate::data::bag::write_trajectories;
use crate::evaluate::META_SYSTEM;
use crate::physics::{SystemConfig, SystemKind};
use anyhow::{Context, Result};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Options of `simulate`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// System: spring (ring of springs) or pendulum (chain of rigid bars).
    #[arg(long, default_value = "spring")]
    pub system: SystemKind,
    /// Number of particles.
    #[arg(long, default_value_t = 5)]
    pub particles: usize,
    /// Number of trajectories (random initial conditions).
    #[arg(long, default_value_t = 100)]
    pub trajectories: usize,
    /// Seed; different seeds give disjoint initial conditions (use one for training, another for testing).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output bag (MCAP, ROS 2 ParticleState messages).
    #[arg(long)]
    pub out: PathBuf,
    /// Linear drag −c·q̇ on every particle; `--drag` alone means c = 0.1 (paper).
    #[arg(long, num_args = 0..=1, default_missing_value = "0.1")]
    pub drag: Option<f64>,
    /// Constant external force on every particle, "fx,fy[,fz]".
    #[arg(long, value_parser = super::parse_vector)]
    pub force: Option<Vec<f64>>,
    /// Integration step [s] (default: pendulum 1e-5, spring 1e-3).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Integration steps between saved states (default: pendulum 1000, spring 100).
    #[arg(long)]
    pub save_every: Option<usize>,
    /// Saved states per trajectory, including the first (default 100).
    #[arg(long)]
    pub states: Option<usize>,
    /// Gravity along −y (default: pendulum 10, spring 0).
    #[arg(long)]
    pub gravity: Option<f64>,
    /// Spatial dimension (2 or 3).
    #[arg(long, default_value_t = 2)]
    pub dim: usize,
}

/// Builds the simulator configuration from the options.
pub fn config(a: &Args) -> Result<SystemConfig> {
    let mut c = SystemConfig::new(a.system, a.particles);
    c.dim = a.dim;
    if let Some(d) = a.drag {
        c.field.drag = d;
    }
    if let Some(f) = &a.force {
        c.field.force = f.clone();
    }
    if let Some(g) = a.gravity {
        c.field.gravity = g;
    }
    if let Some(dt) = a.dt {
        c.dt = dt;
    }
    if let Some(s) = a.save_every {
        c.save_every = s;
    }
    if let Some(s) = a.states {
        c.states = s;
    }
    c.validate().map_err(anyhow::Error::msg)?;
    Ok(c)
}

/// Simulates and writes a bag; returns the configuration used.
pub fn simulate_to(
    cfg: &SystemConfig,
    trajectories: usize,
    seed: u64,
    out: &PathBuf,
) -> Result<()> {
    let trajs = cfg
        .try_simulate(trajectories, seed)
        .map_err(anyhow::Error::msg)?;
    let mut meta = BTreeMap::new();
    meta.insert(META_SYSTEM.to_string(), serde_json::to_string(cfg)?);
    meta.insert("seed".to_string(), seed.to_string());
    meta.insert(
        "generator".to_string(),
        format!("mcgnode {} simulate", env!("CARGO_PKG_VERSION")),
    );
    write_trajectories(out, &trajs, &meta).with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}

/// Runs `simulate`.
pub fn run(a: Args) -> Result<()> {
    let cfg = config(&a)?;
    let t0 = std::time::Instant::now();
    simulate_to(&cfg, a.trajectories, a.seed, &a.out)?;
    eprintln!(
        "wrote {} trajectories of a {}-particle {} ({} states every {} s, dt {}) to {} in {:.1} s",
        a.trajectories,
        cfg.particles,
        cfg.kind.name(),
        cfg.states,
        cfg.dt * cfg.save_every as f64,
        cfg.dt,
        a.out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
