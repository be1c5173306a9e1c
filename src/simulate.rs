//! Simulate → bag, the first step of the pipeline: ground-truth trajectories
//! of a [`SystemConfig`] written as an MCAP bag whose metadata say how they
//! were made. Used by `mcgnode simulate`, `demo` and `reproduce`.

use crate::data::bag::write_trajectories_with_field;
use crate::error::{bail, Context, Result};
use crate::physics::{constraint_residual, SystemConfig};
use std::path::Path;

/// Largest bar-length residual |r − l| accepted in RK4 data. RK4 integrates the
/// constrained flow without projecting back onto the bars, so the bars drift
/// slowly; past this the data no longer describe a rigid pendulum.
pub const RK4_MAX_BAR_RESIDUAL: f64 = 1e-6;

/// How ground-truth trajectories are integrated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataIntegrator {
    /// Velocity Verlet (+ SHAKE/RATTLE for bars): symplectic, bars exact.
    Verlet,
    /// Classical RK4 on (q, p) with the exact constrained acceleration
    /// ([`crate::physics::rk4::rk4_trajectories`]): the paper's HGN data.
    Rk4,
}

impl DataIntegrator {
    /// The name on the command line and in the bag metadata.
    pub fn name(self) -> &'static str {
        match self {
            DataIntegrator::Verlet => "verlet",
            DataIntegrator::Rk4 => "rk4",
        }
    }
}

impl crate::names::Named for DataIntegrator {
    const ALL: &'static [Self] = &[DataIntegrator::Verlet, DataIntegrator::Rk4];
    const WHAT: &'static str = "integrator";

    fn name(self) -> &'static str {
        DataIntegrator::name(self)
    }
}

crate::impl_named!(DataIntegrator);

/// Simulates with velocity Verlet and writes a bag
/// ([`simulate_with`] with [`DataIntegrator::Verlet`]).
pub fn simulate_to(cfg: &SystemConfig, trajectories: usize, seed: u64, out: &Path) -> Result<()> {
    simulate_with(cfg, DataIntegrator::Verlet, trajectories, seed, out)
}

/// Simulates `trajectories` trajectories (starts from `seed`, as
/// [`SystemConfig::start_for`]) with `integrator` and writes a bag whose
/// metadata record the configuration, seed and integrator.
///
/// RK4 does not hold bars at their length; RK4 data of a system with bars is
/// refused when a bar drifts by more than [`RK4_MAX_BAR_RESIDUAL`].
pub fn simulate_with(
    cfg: &SystemConfig,
    integrator: DataIntegrator,
    trajectories: usize,
    seed: u64,
    out: &Path,
) -> Result<()> {
    let trajs = match integrator {
        DataIntegrator::Verlet => cfg.try_simulate(trajectories, seed)?,
        DataIntegrator::Rk4 => {
            let trajs = crate::physics::rk4::rk4_trajectories(cfg, trajectories, seed)?;
            let worst = trajs
                .iter()
                .flat_map(|t| {
                    t.samples
                        .iter()
                        .map(|s| constraint_residual(&t.graph, &s.state))
                })
                .fold(0.0_f64, f64::max);
            if worst > RK4_MAX_BAR_RESIDUAL {
                bail!(
                    "RK4 does not keep the bars rigid: a bar's length drifted by {worst:.2e} \
                     (limit {RK4_MAX_BAR_RESIDUAL:e}); use a smaller --dt or --integrator verlet"
                );
            }
            trajs
        }
    };
    let meta = crate::data::BagMetadata {
        system_config: Some(cfg.clone()),
        seed: Some(seed),
        integrator: Some(integrator.name().to_string()),
        generator: Some(format!("mcgnode {}", env!("CARGO_PKG_VERSION"))),
        ..Default::default()
    }
    .to_map()?;
    // Every message states the field, so the bag describes its system without
    // the metadata record.
    write_trajectories_with_field(out, &trajs, &meta, Some(&cfg.field))
        .with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}
