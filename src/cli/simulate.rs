//! `mcgnode simulate`.

use super::choices::IntegratorArg;
use crate::physics::{SystemConfig, SystemKind};
use crate::simulate::{simulate_with, DataIntegrator};
use anyhow::Result;
use std::path::PathBuf;

/// Options of `simulate`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// System: spring (ring of springs), pendulum (chain of rigid bars),
    /// peridynamic (3D elastic cube of k³ particles, e.g. 125, compressed and
    /// released), or one whose particles touch: soft-spheres (balls in a box of
    /// kinematic walls, under gravity), colliding-lattices (two spring lattices
    /// thrown at each other, no field), falling-chain (bars falling onto a
    /// kinematic floor); or held-chain (springs hanging from a kinematic
    /// gripper that moves along a random smooth path, under gravity).
    #[arg(long, default_value = "spring")]
    pub system: SystemKind,
    /// Number of particles (default: 125 for peridynamic, which needs a cube
    /// number such as 8, 27, 64, 125; 100 soft spheres; colliding lattices
    /// 2·k^dim, default 32 in 2D and 54 in 3D; 10 chain links, falling or
    /// held; 5 otherwise). Walls, floors and grippers come on top of these.
    #[arg(long)]
    pub particles: Option<usize>,
    /// Interaction radius R: pairs closer than it touch (default: soft
    /// spheres and colliding lattices 1, falling chain 0.5; others 0, none).
    #[arg(long)]
    pub radius: Option<f64>,
    /// Contact stiffness k_c of the potential ½ k_c (R − r)² (default: soft
    /// spheres 1000, colliding lattices 100, falling chain 1e4).
    #[arg(long)]
    pub contact_stiffness: Option<f64>,
    /// Spring stiffness k (default: held chain 500, colliding lattices 10,
    /// others 1); e.g. 2x the training data's for held-out data outside its
    /// range.
    #[arg(long)]
    pub stiffness: Option<f64>,
    /// Factor on every start's velocities (e.g. 3 for held-out data faster
    /// than the training data).
    #[arg(long, default_value_t = 1.0)]
    pub velocity_scale: f64,
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
    pub force: Option<super::Vector>,
    /// Integration step [s] (default: pendulum 1e-5, falling chain 1e-4, others 1e-3).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Integration steps between saved states (default: pendulum 1000, others 100).
    #[arg(long)]
    pub save_every: Option<usize>,
    /// Saved states per trajectory, including the first (default 100).
    #[arg(long)]
    pub states: Option<usize>,
    /// Gravity along −y (default: pendulum and falling chain 10, soft spheres 1, others 0).
    #[arg(long)]
    pub gravity: Option<f64>,
    /// Spatial dimension, 2 or 3 (default: 3 for peridynamic, which must be 3D; 2 otherwise).
    #[arg(long)]
    pub dim: Option<usize>,
    /// Integrator: verlet (velocity Verlet + RATTLE, the default) or rk4
    /// (Hamiltonian RK4 on (q, p), the paper's data for HGN).
    #[arg(long, value_enum, default_value_t = IntegratorArg::Verlet)]
    pub integrator: IntegratorArg,
}

/// Builds the simulator configuration from the options.
pub fn config(a: &Args) -> Result<SystemConfig> {
    let dim = a.dim.unwrap_or(a.system.default_dim());
    let particles = a.particles.unwrap_or(match a.system {
        SystemKind::Peridynamic => 125,
        SystemKind::SoftSpheres => 100,
        SystemKind::PeriodicSpheres => 64,
        SystemKind::CollidingLattices if dim == 3 => 54,
        SystemKind::CollidingLattices => 32,
        SystemKind::FallingChain | SystemKind::HeldChain => 10,
        _ => 5,
    });
    let mut c = SystemConfig::new(a.system, particles);
    c.dim = dim;
    if let Some(r) = a.radius {
        c.interaction_radius = r;
    }
    if let Some(k) = a.contact_stiffness {
        c.contact_stiffness = k;
    }
    if let Some(k) = a.stiffness {
        c.stiffness = k;
    }
    c.velocity_scale = a.velocity_scale;
    if let Some(d) = a.drag {
        c.field.drag = d;
    }
    if let Some(f) = &a.force {
        c.field.force.clone_from(&f.0);
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
    c.validate()?;
    Ok(c)
}

/// Runs `simulate`.
pub fn run(a: Args) -> Result<()> {
    let cfg = config(&a)?;
    let integrator = DataIntegrator::from(a.integrator);
    let t0 = std::time::Instant::now();
    simulate_with(&cfg, integrator, a.trajectories, a.seed, &a.out)?;
    eprintln!(
        "wrote {} trajectories of a {}-particle {}D {}{} ({} states every {} s, dt {}, {}) to {} in {:.1} s",
        a.trajectories,
        cfg.particles,
        cfg.dim,
        cfg.kind.name(),
        contacts(&cfg),
        cfg.states,
        cfg.dt * cfg.save_every as f64,
        cfg.dt,
        integrator.name(),
        a.out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// ", contact radius R, k_c K, W walls/floor" for the systems that touch.
fn contacts(cfg: &SystemConfig) -> String {
    if cfg.interaction_radius == 0.0 {
        return String::new();
    }
    let walls = cfg.graph().n_kinematic();
    format!(
        ", contact radius {}, k_c {}, {walls} kinematic particles",
        cfg.interaction_radius, cfg.contact_stiffness
    )
}
