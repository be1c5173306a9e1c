//! `mcgnode plan`: the motion of the kinematic particles (a gripper) that
//! brings chosen particles to targets, searched through a model.

use super::choices::{CostArg, SamplerArg};
use super::{parse_vector, Vector};
use crate::dynamics::Timing;
use crate::models::{load_any_model, ModelRef};
use crate::physics::SystemKind;
use crate::plan::{plan, refine, Controls, Cost, Plan, Problem, Refined, Sampler};
use crate::system::State;
use anyhow::{bail, Result};
use serde_json::json;
use std::path::PathBuf;

/// Options of `plan`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// The model that predicts the free particles: a model file, `still`, or
    /// `truth:<system>` (the ground truth as planner).
    #[arg(long)]
    pub model: PathBuf,
    /// Without --initial: the system whose start to draw, as `simulate` does.
    #[arg(long, default_value = "held-chain")]
    pub system: SystemKind,
    /// Where to start.
    #[command(flatten)]
    pub start: super::start::StartArgs,
    /// The particle to bring to the target (default: the last free one, the
    /// held chain's free end).
    #[arg(long)]
    pub particle: Option<usize>,
    /// Its target, "x,y[,z]".
    #[arg(long, value_parser = parse_vector)]
    pub target: Vector,
    /// When the distance counts: at the end of the horizon, or along it.
    #[arg(long, value_enum, default_value_t = CostArg::Final)]
    pub cost: CostArg,
    /// Weight of the control effort Σ|u|²·T.
    #[arg(long, default_value_t = 1e-3)]
    pub effort: f64,
    /// Weight of the particle's squared speed, counted where its distance
    /// is (bring it there at rest).
    #[arg(long, default_value_t = 0.0)]
    pub speed: f64,
    /// Weight of the risk term: this × the sum over control steps of the
    /// free particles' mean spread (the ensemble members' standard
    /// deviation of position) along each candidate's mean rollout. Needs an
    /// ensemble (`train --ensemble K`); 0 plans as without it.
    #[arg(long, default_value_t = 0.0)]
    pub risk: f64,
    /// Control steps ahead.
    #[arg(long, default_value_t = 10)]
    pub horizon: usize,
    /// Integration step of the planner's rollouts [s] (default: the bag's or
    /// the system's).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Integration steps per control step (the driven particles' velocity
    /// ramps to each control's value over dt·substeps).
    #[arg(long, default_value_t = 10)]
    pub substeps: usize,
    /// How candidates are drawn.
    #[arg(long, value_enum, default_value_t = SamplerArg::Cem)]
    pub sampler: SamplerArg,
    /// Candidate sequences per round.
    #[arg(long, default_value_t = 256)]
    pub candidates: usize,
    /// Rounds (CEM, MPPI).
    #[arg(long, default_value_t = 4)]
    pub iterations: usize,
    /// CEM: sequences refitted to.
    #[arg(long, default_value_t = 16)]
    pub elites: usize,
    /// Spread of the sampled velocities [m/s] (CEM: the first round's).
    #[arg(long, default_value_t = 0.5)]
    pub sigma: f64,
    /// MPPI temperature λ, in cost units.
    #[arg(long, default_value_t = 0.1)]
    pub temperature: f64,
    /// Largest speed of a driven particle along each axis [m/s].
    #[arg(long, default_value_t = 2.0)]
    pub max_speed: f64,
    /// Seed of the sampling.
    #[arg(long, default_value_t = 1)]
    pub sample_seed: u64,
    /// Gradient steps after the search: ∂cost/∂controls by reverse mode
    /// through the model's rollout refines the best candidate (model files
    /// of the GNODE family). The plan printed is the refined one.
    #[arg(long, default_value_t = 0)]
    pub refine: usize,
    /// Print one JSON document: the cost, the best sequence, its predicted
    /// trajectory, every candidate's cost of the last round, the rounds.
    #[arg(long)]
    pub json: bool,
}

/// Runs `plan`.
pub fn run(a: Args) -> Result<()> {
    let reference = ModelRef::from_path(&a.model)?;
    let model = load_any_model(&reference)?.dynamics;
    let from = a.start.start(a.system)?;
    let (g, d) = (&from.graph, from.graph.dim);
    let dt = match (a.dt, &from.cfg, from.stamp_dt) {
        (Some(dt), _, _) => dt,
        (None, Some(c), _) => c.dt,
        (None, None, Some(s)) => s,
        (None, None, None) => bail!("the start does not say its step: pass --dt"),
    };
    let particle = match a.particle {
        Some(p) => p,
        None => (0..g.n())
            .rev()
            .find(|&i| !g.is_kinematic(i))
            .ok_or_else(|| {
                anyhow::anyhow!("every particle is kinematic: nothing to bring anywhere")
            })?,
    };
    if a.target.0.len() != d {
        bail!(
            "--target has {} numbers for a {d}D system",
            a.target.0.len()
        );
    }
    let problem = Problem {
        model: model.as_ref(),
        graph: g,
        start: &from.state,
        timing: Timing::of_step(dt, a.substeps, a.horizon),
        cost: Cost {
            kind: a.cost.into(),
            particles: vec![particle],
            targets: a.target.0.clone(),
            effort: a.effort,
            speed: a.speed,
            risk: a.risk,
        },
        max_speed: a.max_speed,
    };
    let quiet = a.json;
    let p = plan(&problem, sampler(&a), None, a.sample_seed, |it| {
        if !quiet {
            eprintln!(
                "round {}: best cost {:.4e}, mean {:.4e}, {} diverged",
                it.iteration, it.best, it.mean, it.diverged
            );
        }
        true
    })?;
    let refined = refine_plan(&problem, &p, a.refine, quiet)?;
    let still = problem.cost_of(&Controls::zeros(a.horizon, problem.width()))?;
    if a.json {
        print_json(&a, &problem, particle, &p, refined.as_ref(), still)
    } else {
        print_text(&a, particle, d, &p, refined.as_ref(), still);
        Ok(())
    }
}

/// The sampler the options choose.
fn sampler(a: &Args) -> Sampler {
    match a.sampler {
        SamplerArg::Random => Sampler::Random {
            candidates: a.candidates,
            sigma: a.sigma,
        },
        SamplerArg::Cem => Sampler::Cem {
            candidates: a.candidates,
            iterations: a.iterations,
            elites: a.elites,
            sigma: a.sigma,
        },
        SamplerArg::Mppi => Sampler::Mppi {
            candidates: a.candidates,
            iterations: a.iterations,
            sigma: a.sigma,
            temperature: a.temperature,
        },
    }
}

/// `steps` gradient steps from the search's best (none when 0), said on
/// stderr unless `quiet`.
fn refine_plan(problem: &Problem, p: &Plan, steps: usize, quiet: bool) -> Result<Option<Refined>> {
    if steps == 0 {
        return Ok(None);
    }
    let r = refine(problem, &p.best, steps)?;
    if !quiet {
        eprintln!(
            "refined by {} gradient steps: cost {:.4e} → {:.4e}",
            r.steps.len(),
            r.start_cost,
            r.cost
        );
    }
    Ok(Some(r))
}

/// The plan printed: the refined one when there is one, else the search's
/// best, as (controls, cost, predicted trajectory).
fn chosen<'a>(p: &'a Plan, refined: Option<&'a Refined>) -> (&'a Controls, f64, &'a [State]) {
    match refined {
        Some(r) => (&r.best, r.cost, &r.predicted),
        None => (&p.best, p.cost, &p.predicted),
    }
}

/// `plan --json`: one JSON document on stdout.
fn print_json(
    a: &Args,
    problem: &Problem,
    particle: usize,
    p: &Plan,
    refined: Option<&Refined>,
    still: f64,
) -> Result<()> {
    let (best, cost, predicted) = chosen(p, refined);
    let rows: Vec<&[f64]> = (0..best.steps).map(|k| best.row(k)).collect();
    let doc = json!({
        "model": problem.model.describe(),
        "particle": particle,
        "target": a.target.0,
        "driven": problem.driven(),
        "dt": problem.timing.step(),
        "substeps": a.substeps,
        "control_step": problem.timing.dt,
        "cost": cost,
        "search_cost": p.cost,
        "hold_still_cost": still,
        "best": rows,
        "predicted": predicted.iter().map(|s| &s.q).collect::<Vec<_>>(),
        "predicted_velocities": predicted.iter().map(|s| &s.v).collect::<Vec<_>>(),
        "refine": refined.map(|r| json!({
            "start_cost": r.start_cost,
            "steps": r.steps,
            "gradient": r.grad,
        })),
        "costs": p.costs,
        "iterations": p.iterations,
        "evaluated": p.evaluated,
        "seconds": p.seconds,
    });
    println!("{}", serde_json::to_string_pretty(&doc)?);
    Ok(())
}

/// `plan` without --json: the cost, where the particle ends, and the plan's
/// velocities step by step.
fn print_text(
    a: &Args,
    particle: usize,
    d: usize,
    p: &Plan,
    refined: Option<&Refined>,
    still: f64,
) {
    let (best, cost, predicted) = chosen(p, refined);
    let rows: Vec<&[f64]> = (0..best.steps).map(|k| best.row(k)).collect();
    let end = predicted
        .last()
        .map(|s| s.q[particle * d..(particle + 1) * d].to_vec());
    println!(
        "{} candidates in {:.3} s: best cost {:.4e} (holding still: {:.4e}); particle {particle} predicted at {:?}, target {:?}",
        p.evaluated, p.seconds, cost, still, end.unwrap_or_default(), a.target.0
    );
    for (k, r) in rows.iter().enumerate() {
        println!("  step {k}: velocity {r:?}");
    }
}
