//! `mcgnode rollout`.

use crate::data::bag::write_trajectories_with_field;
use crate::dynamics::{Dynamics, Timing};
use crate::models::{load_any_model, ModelRef};
use crate::physics::SystemKind;
use crate::system::{Graph, Sample, State, Trajectory};
use anyhow::{bail, Result};
use std::path::PathBuf;

/// Options of `rollout`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Trained model file (GNODE family or a baseline).
    #[arg(long)]
    pub model: PathBuf,
    /// System whose initial state to draw (as `simulate` draws them).
    #[arg(long, default_value = "spring")]
    pub system: SystemKind,
    /// Where to start.
    #[command(flatten)]
    pub start: super::start::StartArgs,
    /// Simulated time [s].
    #[arg(long, default_value_t = 20.0)]
    pub duration: f64,
    /// Integration step [s] (default: the system's; with --initial, the bag's
    /// system_config, else the interval of its header stamps).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Save every this many steps (default: the system's; with --initial from
    /// a bag without system_config, 1).
    #[arg(long)]
    pub save_every: Option<usize>,
    /// Output bag.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `rollout`.
pub fn run(a: Args) -> Result<()> {
    let reference = ModelRef::from_path(&a.model)?;
    let model = load_any_model(&reference)?.dynamics;
    let trained = crate::models::trained_for(&reference)?;
    let from = a.start.start(a.system)?;
    let super::start::Start {
        graph,
        state: start,
        system,
        mut cfg,
        field,
        stamp_dt,
        recorded,
    } = from;
    trained.check(&graph, field.as_ref())?;
    if let Some(o) = trained
        .range
        .as_ref()
        .and_then(|r| r.check(&graph, &start, crate::compat::OUT_OF_RANGE_SIGMAS))
    {
        eprintln!("warning: the initial state is out of the model's training range: {o}; the rollout is an extrapolation");
    }
    // Without a flag or a system_config, the step is the recorded interval and
    // every step is saved.
    let (dt, default_every) = match (a.dt, &cfg, stamp_dt) {
        (Some(dt), Some(c), _) => (dt, c.save_every),
        (Some(dt), None, _) => (dt, 1),
        (None, Some(c), _) => (c.dt, c.save_every),
        (None, None, Some(d)) => (d, 1),
        (None, None, None) => {
            bail!("--initial does not say its step (no system_config, one state): pass --dt")
        }
    };
    let every = a.save_every.unwrap_or(default_every).max(1);
    if !(a.duration.is_finite() && a.duration > 0.0 && dt > 0.0) {
        bail!("duration and dt must be positive");
    }
    let steps = (a.duration / dt).round() as usize;
    let t0 = std::time::Instant::now();
    let moving = Trajectory {
        id: a.start.trajectory,
        system: system.clone(),
        graph: graph.clone(),
        samples: recorded,
    };
    let timing = Timing::integration(dt, steps, every);
    let states = roll_out(model.as_ref(), &moving, &start, timing)?;
    let secs = t0.elapsed().as_secs_f64();
    let samples = with_accelerations(model.as_ref(), &graph, states, dt, every)?;
    let n = samples.len();
    let tr = Trajectory {
        id: 0,
        system,
        graph,
        samples,
    };
    if let Some(c) = cfg.as_mut() {
        c.dt = dt;
        c.save_every = every;
        c.states = n;
        c.particles = tr.graph.n();
    }
    let meta = crate::data::BagMetadata {
        system_config: cfg,
        generator: Some(format!("mcgnode rollout of {}", a.model.display())),
        model: Some(a.model.display().to_string()),
        ..Default::default()
    }
    .to_map()?;
    write_trajectories_with_field(&a.out, &[tr], &meta, field.as_ref())?;
    eprintln!(
        "{steps} steps ({:.3} s simulated) in {secs:.3} s; wrote {n} states to {}",
        steps as f64 * dt,
        a.out.display()
    );
    Ok(())
}

/// Rolls `model` out from `start` as `timing` says. The GNODE family integrates on the allocation-free
/// kernel, baselines on candle. Kinematic particles that move in the
/// recording `moving` follow it (cubic Hermite between its states);
/// otherwise they are held.
fn roll_out(
    model: &dyn Dynamics,
    moving: &Trajectory,
    start: &State,
    timing: Timing,
) -> Result<Vec<State>> {
    let graph = &moving.graph;
    let (dt, steps) = (timing.step(), timing.steps());
    Ok(if crate::evaluate::kinematic_moves(moving) {
        let drive = crate::physics::Drive::from_samples(graph, &moving.samples, dt, steps)?;
        let have = moving
            .samples
            .last()
            .map_or(0.0, |s| s.t - moving.samples[0].t);
        if have + 0.5 * dt < steps as f64 * dt {
            bail!(
                "--initial records its kinematic particles' motion for {have} s only: give \
                 --duration {have} or less"
            );
        }
        model.rollout_driven(graph, start, timing, &drive)?
    } else {
        model.rollout(graph, start, timing)?
    })
}

/// The rolled-out states as samples stamped from 0, each with the model's
/// acceleration.
fn with_accelerations(
    model: &dyn Dynamics,
    graph: &Graph,
    states: Vec<State>,
    dt: f64,
    every: usize,
) -> Result<Vec<Sample>> {
    let mut acc = vec![0.0; graph.ndof()];
    let mut samples = Vec::with_capacity(states.len());
    for (k, state) in states.into_iter().enumerate() {
        model.acceleration(graph, &state, &mut acc)?;
        samples.push(Sample {
            t: (k * every) as f64 * dt,
            state,
            acc: Some(acc.clone()),
        });
    }
    Ok(samples)
}
