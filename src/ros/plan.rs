//! The Plan service: [`crate::plan`] on the served model from a received
//! state, at the node's own step (control steps of `dt`, integration steps
//! of `dt / substeps`), so that a Rollout given the plan's kinematic motion
//! replays its prediction exactly.

use super::predict;
use super::wire::{PlanRequest, PlanResponse};
use crate::data::msg::{Point, Vector3};
use crate::dynamics::{Dynamics, Timing};
use crate::physics::Drive;
use crate::plan::{plan, refine, Controls, Cost, CostKind, Iteration, Plan, Problem, Sampler};
use crate::system::{Graph, State};

/// Why a Plan or Rollout request is refused: the message names the fix.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct Refused(pub String);

/// What the node lends a plan: its step, substeps, horizon and limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanSettings {
    /// The node's timing: control step `dt`, integration steps per control
    /// step `substeps`, control steps when the request gives 0 `horizon`.
    pub timing: Timing,
    /// `max_rollout_steps`: the longest horizon accepted.
    pub max_steps: u32,
    /// `max_particles`.
    pub max_particles: u32,
    /// `plan_risk`: the weight of the risk term ([`Cost::risk_of`]; 0: none).
    pub risk: f64,
}

/// The flat rows of a drive as Points and Vector3s, step-major.
fn motion(drive: &Drive) -> (Vec<Point>, Vec<Vector3>) {
    let d = drive.dim;
    let points = drive
        .q
        .iter()
        .flat_map(|r| r.chunks(d).map(Point::from_coords))
        .collect();
    let vectors = drive
        .v
        .iter()
        .flat_map(|r| r.chunks(d).map(Vector3::from_coords))
        .collect();
    (points, vectors)
}

/// The most candidates per round and rounds a request may ask for: a
/// client's typo must not make the node allocate or search for ever.
pub const MAX_CANDIDATES: u32 = 65_536;
/// See [`MAX_CANDIDATES`].
pub const MAX_ITERATIONS: u32 = 100;

/// Rounds the search of `req` runs, its defaults resolved (0 for a request
/// that will be refused): what the Plan action's feedback counts against.
pub fn rounds(req: &PlanRequest) -> usize {
    sampler(req).map_or(0, Sampler::iterations)
}

/// The sampler a request asks for, with the defaults of `mcgnode plan`.
fn sampler(req: &PlanRequest) -> Result<Sampler, Refused> {
    if req.candidates > MAX_CANDIDATES || req.iterations > MAX_ITERATIONS {
        return Err(Refused(format!(
            "{} candidates x {} rounds: at most {MAX_CANDIDATES} candidates and \
             {MAX_ITERATIONS} rounds per request",
            req.candidates, req.iterations
        )));
    }
    let or = |x: u32, d: usize| if x == 0 { d } else { x as usize };
    let orf = |x: f64, d: f64| if x == 0.0 { d } else { x };
    let (candidates, sigma) = (or(req.candidates, 256), orf(req.sigma, 0.5));
    Ok(match req.sampler.as_str() {
        "" | "cem" => Sampler::Cem {
            candidates,
            iterations: or(req.iterations, 4),
            elites: or(req.elites, 16),
            sigma,
        },
        "random" => Sampler::Random { candidates, sigma },
        "mppi" => Sampler::Mppi {
            candidates,
            iterations: or(req.iterations, 4),
            sigma,
            temperature: orf(req.temperature, 0.1),
        },
        other => {
            return Err(Refused(format!(
                "sampler {other:?} is unknown: use random, cem or mppi (empty: cem)"
            )))
        }
    })
}

/// The most gradient steps a request may ask for (see [`MAX_CANDIDATES`]).
pub const MAX_REFINE: u32 = 1_000;

/// The Plan service's work: checks the request, plans, and answers with the
/// best sequence, its kinematic motion and its predicted trajectory.
pub fn plan_response(model: &dyn Dynamics, req: &PlanRequest, s: &PlanSettings) -> PlanResponse {
    plan_response_with(model, req, s, &mut |_| true)
}

/// [`plan_response`] with `on_round` told each round of the search
/// (feedback); it returns false to stop the search there (cancel), which
/// keeps the best sequence so far.
pub fn plan_response_with(
    model: &dyn Dynamics,
    req: &PlanRequest,
    s: &PlanSettings,
    on_round: &mut dyn FnMut(&Iteration) -> bool,
) -> PlanResponse {
    match answer(model, req, s, on_round) {
        Ok(r) => r,
        Err(Refused(message)) => PlanResponse {
            success: false,
            message,
            ..PlanResponse::default()
        },
    }
}

fn answer(
    model: &dyn Dynamics,
    req: &PlanRequest,
    s: &PlanSettings,
    on_round: &mut dyn FnMut(&Iteration) -> bool,
) -> Result<PlanResponse, Refused> {
    let (graph, start, horizon, kind) = checked(model, req, s)?;
    let d = graph.dim;
    let started = std::time::Instant::now();
    let problem = Problem {
        model,
        graph: &graph,
        start: &start,
        timing: s.timing.with_horizon(horizon),
        cost: cost(req, kind, d, s.risk),
        max_speed: if req.max_speed == 0.0 {
            2.0
        } else {
            req.max_speed
        },
    };
    let (p, refined) = search(&problem, req, on_round)?;
    let seconds = if refined.is_empty() {
        p.seconds
    } else {
        started.elapsed().as_secs_f64()
    };
    respond(&problem, req, s, p, (&refined, seconds))
}

/// The request checked before any work, in this order: refine steps, state
/// size, the model taking its graph, horizon, one target per particle, cost
/// kind. Gives the graph, the start, the horizon and the cost kind.
fn checked(
    model: &dyn Dynamics,
    req: &PlanRequest,
    s: &PlanSettings,
) -> Result<(Graph, State, usize, CostKind), Refused> {
    let no = |e: &dyn std::fmt::Display| Refused(e.to_string());
    if req.refine > MAX_REFINE {
        return Err(Refused(format!(
            "refine = {}: at most {MAX_REFINE} gradient steps per request",
            req.refine
        )));
    }
    predict::check_size(&req.initial, s.max_particles).map_err(|e| no(&e))?;
    let (graph, start) = predict::accept(model, &req.initial).map_err(|e| no(&e))?;
    let horizon = if req.horizon == 0 {
        s.timing.horizon
    } else {
        req.horizon as usize
    };
    if horizon > s.max_steps as usize {
        return Err(Refused(format!(
            "horizon = {horizon} exceeds max_rollout_steps = {}",
            s.max_steps
        )));
    }
    if req.particles.len() != req.targets.len() {
        return Err(Refused(format!(
            "{} particles but {} targets: give one target per particle",
            req.particles.len(),
            req.targets.len()
        )));
    }
    let kind = match req.cost.as_str() {
        "" | "final" => CostKind::Final,
        "along" => CostKind::Along,
        other => {
            return Err(Refused(format!(
                "cost {other:?} is unknown: use final or along"
            )))
        }
    };
    Ok((graph, start, horizon, kind))
}

/// The cost a request asks for, its targets in `d` dimensions, with the
/// node's risk weight (`plan_risk`: the message has no field for it, so
/// that clients built before it keep working).
fn cost(req: &PlanRequest, kind: CostKind, d: usize, risk: f64) -> Cost {
    Cost {
        kind,
        particles: req.particles.iter().map(|&p| p as usize).collect(),
        targets: req
            .targets
            .iter()
            .flat_map(|p| [p.x, p.y, p.z].into_iter().take(d))
            .collect(),
        effort: req.effort,
        speed: req.speed,
        risk,
    }
}

/// The search the request asks for, then its gradient refinement when it
/// asks for one (and the search found a finite cost); with what the
/// refinement says for the message ("" without one).
fn search(
    problem: &Problem,
    req: &PlanRequest,
    on_round: &mut dyn FnMut(&Iteration) -> bool,
) -> Result<(Plan, String), Refused> {
    let no = |e: &dyn std::fmt::Display| Refused(e.to_string());
    let mut p = plan(problem, sampler(req)?, None, req.seed, on_round).map_err(|e| no(&e))?;
    let mut refined = String::new();
    if req.refine > 0 && p.cost.is_finite() {
        let r = refine(problem, &p.best, req.refine as usize).map_err(|e| no(&e))?;
        refined = format!(
            "; refined by {} gradient steps from {:.4e}",
            r.steps.len(),
            r.start_cost
        );
        (p.best, p.cost, p.predicted) = (r.best, r.cost, r.predicted);
    }
    Ok((p, refined))
}

/// The answer for plan `p`: its best sequence, the kinematic motion it
/// gives, its predicted trajectory and the cost of holding still.
fn respond(
    problem: &Problem,
    req: &PlanRequest,
    s: &PlanSettings,
    p: Plan,
    (refined, seconds): (&str, f64),
) -> Result<PlanResponse, Refused> {
    let no = |e: &dyn std::fmt::Display| Refused(e.to_string());
    let d = problem.graph.dim;
    let still = problem
        .cost_of(&Controls::zeros(problem.timing.horizon, problem.width()))
        .map_err(|e| no(&e))?;
    let driven = problem.driven();
    let drive = p.best.drive(&driven, d, problem.start, problem.timing);
    let (kinematic_positions, kinematic_velocities) = motion(&drive);
    let best = p.best.u.chunks(d).map(Vector3::from_coords).collect();
    // An ensemble's plan carries its spread along the best rollout.
    let (states, spread) = match problem.model.members() {
        1 => (p.predicted, Vec::new()),
        _ => problem.rollout_spread(&p.best).map_err(|e| no(&e))?,
    };
    Ok(PlanResponse {
        success: true,
        message: format!(
            "{} candidates in {seconds:.3} s: cost {:.4e} (holding still {still:.4e}){refined}",
            p.evaluated, p.cost
        ),
        cost: p.cost,
        hold_still_cost: still,
        driven: driven.iter().map(|&i| i as u32).collect(),
        best,
        kinematic_positions,
        kinematic_velocities,
        trajectory: predict::trajectory_of(
            &req.initial,
            problem.graph,
            s.timing.dt,
            (&states, &spread),
        ),
        costs: p.costs,
        seconds,
    })
}

/// The kinematic motion a Rollout request gives: `rows` rows (integration
/// steps + 1) of every kinematic particle of `graph`, velocities derived
/// when absent; `None` when the request gives none.
pub fn requested_drive(
    graph: &crate::system::Graph,
    positions: &[Point],
    velocities: &[Vector3],
    rows: usize,
    fine_dt: f64,
) -> Result<Option<Drive>, Refused> {
    if positions.is_empty() {
        if !velocities.is_empty() {
            return Err(Refused(
                "kinematic_velocities given without kinematic_positions".into(),
            ));
        }
        return Ok(None);
    }
    let d = graph.dim;
    let driven: Vec<usize> = (0..graph.n()).filter(|&i| graph.is_kinematic(i)).collect();
    let need = rows * driven.len();
    if driven.is_empty() || positions.len() != need {
        return Err(Refused(format!(
            "kinematic_positions has {} points; the system's {} kinematic particles over \
             steps x substeps + 1 = {rows} integration steps need {need}",
            positions.len(),
            driven.len()
        )));
    }
    if !velocities.is_empty() && velocities.len() != need {
        return Err(Refused(format!(
            "kinematic_velocities has {} vectors, {need} needed (or none: derived from the positions)",
            velocities.len()
        )));
    }
    let flat = |x: f64, y: f64, z: f64| [x, y, z].into_iter().take(d);
    let q: Vec<Vec<f64>> = positions
        .chunks(driven.len())
        .map(|r| r.iter().flat_map(|p| flat(p.x, p.y, p.z)).collect())
        .collect();
    let drive = if velocities.is_empty() {
        Drive::from_positions(driven, d, fine_dt, q)
    } else {
        let v = velocities
            .chunks(driven.len())
            .map(|r| r.iter().flat_map(|p| flat(p.x, p.y, p.z)).collect())
            .collect();
        Drive {
            particles: driven,
            dim: d,
            q,
            v,
        }
    };
    Ok(Some(drive))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Requests a node must not try to serve are refused with the reason;
    /// a good one plans.
    #[test]
    fn requests_are_checked_before_planning() {
        let cfg = crate::physics::SystemConfig::new(crate::physics::SystemKind::HeldChain, 3);
        let g = cfg.graph();
        let sample = crate::system::Sample {
            t: 0.0,
            state: cfg.start_for(&g, 1, 0),
            acc: None,
        };
        let initial = crate::data::msg::ParticleState::from_sample(0, 0, "", &g, &sample);
        let model = crate::models::truth::truth(crate::physics::SystemKind::HeldChain);
        let s = PlanSettings {
            timing: Timing::new(0.1, 10, 5),
            max_steps: 50,
            max_particles: 100,
            risk: 0.0,
        };
        let good = PlanRequest {
            initial,
            particles: vec![2],
            targets: vec![Point {
                x: 0.5,
                y: -3.0,
                z: 0.0,
            }],
            candidates: 8,
            iterations: 2,
            elites: 2,
            ..PlanRequest::default()
        };
        let r = plan_response(model.as_ref(), &good, &s);
        assert!(r.success, "{}", r.message);
        assert_eq!((r.best.len(), r.kinematic_positions.len()), (5, 51));
        let refused = |edit: fn(&mut PlanRequest), want: &str| {
            let mut req = good.clone();
            edit(&mut req);
            let r = plan_response(model.as_ref(), &req, &s);
            assert!(
                !r.success && r.message.contains(want),
                "{want}: {}",
                r.message
            );
        };
        refused(|r| r.candidates = u32::MAX, "at most 65536 candidates");
        refused(|r| r.horizon = 51, "exceeds max_rollout_steps = 50");
        refused(|r| r.targets.clear(), "give one target per particle");
        refused(|r| r.sampler = "grid".into(), "use random, cem or mppi");
        refused(|r| r.cost = "best".into(), "use final or along");
        refused(
            |r| r.particles = vec![9],
            "target particle 9 does not exist",
        );
        refused(|r| r.refine = 1_001, "at most 1000 gradient steps");
        refused(|r| r.refine = 3, "has no gradient");
        // A model file of the GNODE family refines; a cancel after the first
        // round keeps that round's best.
        let (_, learned) =
            crate::testing::random_model(crate::gnode::Variant::Mcgnode, &g, 1).unwrap();
        let req = PlanRequest {
            refine: 3,
            ..good.clone()
        };
        let r = plan_response(&learned, &req, &s);
        assert!(
            r.success && r.message.contains("refined by"),
            "{}",
            r.message
        );
        let mut rounds = 0;
        let r = plan_response_with(&learned, &good, &s, &mut |_| {
            rounds += 1;
            false
        });
        assert!(r.success, "{}", r.message);
        assert_eq!((rounds, r.best.len()), (1, 5));
    }

    /// The action's feedback counts the rounds the search runs, defaults
    /// resolved: CEM's 4 when 0 is asked, random shooting's one.
    #[test]
    fn rounds_resolve_the_defaults() {
        let with = |iterations: u32, sampler: &str| PlanRequest {
            iterations,
            sampler: sampler.into(),
            ..PlanRequest::default()
        };
        assert_eq!(rounds(&with(2, "cem")), 2);
        assert_eq!(rounds(&with(0, "")), 4);
        assert_eq!(rounds(&with(3, "mppi")), 3);
        assert_eq!(rounds(&with(7, "random")), 1);
        assert_eq!(rounds(&with(0, "grid")), 0);
    }
}
