//! Closed-loop model-predictive control: the ground-truth simulator is the
//! world, a model is the planner. At every control step the planner plans
//! from the world's true state, the world executes the plan's first control
//! for one control step, and the next plan starts from the rest of this one.

use super::controls::Controls;
use super::cost::Cost;
use super::gradient::refine;
use super::search::{plan, PlanError, Problem, Sampler};
use crate::dynamics::Dynamics;
use crate::dynamics::Timing;
use crate::physics::{Field, Integrator};
use crate::system::{Graph, State};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// One episode's setting.
pub struct Episode<'a> {
    /// The world's system (its kinematic particles are what the robot moves).
    pub graph: &'a Graph,
    /// The world's field.
    pub field: &'a Field,
    /// The world's integration step, seconds.
    pub world_dt: f64,
    /// Where the episode starts.
    pub start: State,
    /// The planner's model; `None` holds still (the do-nothing reference).
    pub planner: Option<&'a dyn Dynamics>,
    /// The system as the planner believes it (a learned model's training
    /// system when the world's differs, e.g. in its stiffness); `None`: the
    /// world's. Same particles, kinematic ones and dimension.
    pub planner_graph: Option<&'a Graph>,
    /// How the planner searches.
    pub sampler: Sampler,
    /// The planner's rollouts: control step, integration steps per control
    /// step, control steps it looks ahead.
    pub timing: Timing,
    /// Control steps the episode lasts.
    pub steps: usize,
    /// The task: particles and their targets, and the effort weight.
    pub cost: Cost,
    /// Speed bound of the driven particles, m/s.
    pub max_speed: f64,
    /// Seed of the planner's sampling (control step k uses seed + k).
    pub seed: u64,
    /// Gradient steps refining each search's best sequence
    /// ([`super::gradient::refine`]; planners with a reverse pass only).
    pub refine: usize,
}

/// What an episode did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeReport {
    /// Distance of the target particles to their targets at the end (the
    /// root of the summed squares).
    pub final_distance: f64,
    /// Planner wall time per control step, seconds (0 for holding still).
    pub seconds_per_step: f64,
    /// The target particles' executed positions: the start, then after each
    /// control step.
    pub executed: Vec<Vec<f64>>,
    /// The first plan's predicted positions of the target particles, one
    /// per control step of its horizon (empty when holding still).
    pub predicted: Vec<Vec<f64>>,
}

/// The chosen particles' positions in `s`.
fn picked(cost: &Cost, s: &State, dim: usize) -> Vec<f64> {
    cost.particles
        .iter()
        .flat_map(|&p| s.q[p * dim..(p + 1) * dim].iter().copied())
        .collect()
}

/// The planner's system, when it is not the world's, must have the world's
/// particles, kinematic ones and dimension.
fn check_planner_graph(ep: &Episode) -> Result<(), PlanError> {
    let g = ep.graph;
    match ep.planner_graph {
        Some(pg) if pg.n() != g.n() || pg.dim != g.dim || pg.kinematic != g.kinematic => {
            Err(PlanError::Problem(
                "the planner's system must have the world's particles, kinematic ones and \
                 dimension"
                    .into(),
            ))
        }
        _ => Ok(()),
    }
}

/// Runs one episode.
pub fn run(ep: &Episode) -> Result<EpisodeReport, PlanError> {
    let (g, d) = (ep.graph, ep.graph.dim);
    check_planner_graph(ep)?;
    let driven: Vec<usize> = (0..g.n()).filter(|&i| g.is_kinematic(i)).collect();
    let width = driven.len() * d;
    let t_control = ep.timing.dt;
    let world_sub = (t_control / ep.world_dt).round().max(1.0) as usize;
    // One control step of the world, integrated with its own step.
    let world_timing = Timing::new(ep.world_dt * world_sub as f64, world_sub, 1);
    let mut state = ep.start.clone();
    let mut executed = vec![picked(&ep.cost, &state, d)];
    let mut predicted = vec![];
    let mut warm: Option<Controls> = None;
    let mut planning = 0.0;
    for k in 0..ep.steps {
        let first = match ep.planner {
            None => Controls::zeros(1, width),
            Some(model) => {
                let problem = Problem {
                    model,
                    graph: ep.planner_graph.unwrap_or(g),
                    start: &state,
                    timing: ep.timing,
                    cost: ep.cost.clone(),
                    max_speed: ep.max_speed,
                };
                let t0 = Instant::now();
                let p = plan(
                    &problem,
                    ep.sampler,
                    warm.as_ref(),
                    ep.seed + k as u64,
                    |_| true,
                )?;
                let (best, path) = if ep.refine > 0 && p.cost.is_finite() {
                    let r = refine(&problem, &p.best, ep.refine)?;
                    (r.best, r.predicted)
                } else {
                    (p.best, p.predicted)
                };
                planning += t0.elapsed().as_secs_f64();
                if k == 0 {
                    predicted = path[1..].iter().map(|s| picked(&ep.cost, s, d)).collect();
                }
                let first = Controls {
                    steps: 1,
                    width,
                    u: best.row(0).to_vec(),
                };
                warm = Some(best.shifted());
                first
            }
        };
        // The world executes the first control for one control step.
        let drive = first.drive(&driven, d, &state, world_timing);
        let mut it = Integrator::driven(g, ep.field, 0.0, ep.world_dt, state.clone(), drive)
            .map_err(crate::dynamics::DynamicsError::from)?;
        it.advance(world_sub);
        state = it.state().clone();
        if state.validate(g).is_err() {
            return Err(PlanError::Problem(format!(
                "the world diverged at control step {k}: lower the speed bound"
            )));
        }
        executed.push(picked(&ep.cost, &state, d));
    }
    Ok(EpisodeReport {
        final_distance: ep.cost.distance2(&state, d).sqrt(),
        seconds_per_step: planning / ep.steps.max(1) as f64,
        executed,
        predicted,
    })
}
