//! The services' work: Rollout, Plan and Replay, each a function of the
//! node's handles (current parameters and model) and the request, run on
//! the blocking pool by [`super::service::serve`].

use super::handles::Handles;
use super::predict;
use super::wire::{
    PlanRequest, PlanResponse, ReplayRequest, ReplayResponse, RolloutRequest, RolloutResponse,
};
use crate::dynamics::{Dynamics, Timing};

/// The Rollout service's work with the node's current parameters.
pub(crate) fn rollout_call(h: &Handles, req: RolloutRequest) -> RolloutResponse {
    if let Some(why) = h.lifecycle.refusal() {
        return RolloutResponse {
            success: false,
            message: why,
            ..RolloutResponse::default()
        };
    }
    let p = h.params.get();
    let limits = RolloutLimits {
        default_dt: p.dt,
        fine_dt: p.timing().step(),
        max_steps: p.max_rollout_steps,
        max_particles: p.max_particles,
    };
    rollout_response(h.model.get().as_ref(), &req, &limits)
}

/// The Plan service's work with the node's current parameters and model.
pub(crate) fn plan_call(h: &Handles, req: PlanRequest) -> PlanResponse {
    plan_call_with(h, &req, &mut |_| true)
}

/// [`plan_call`] telling `on_round` each round of the search (the Plan
/// action's feedback); false from it stops the search (cancel).
pub(crate) fn plan_call_with(
    h: &Handles,
    req: &PlanRequest,
    on_round: &mut dyn FnMut(&crate::plan::Iteration) -> bool,
) -> PlanResponse {
    if let Some(why) = h.lifecycle.refusal() {
        return PlanResponse {
            message: why,
            ..PlanResponse::default()
        };
    }
    let p = h.params.get();
    let settings = super::plan::PlanSettings {
        timing: p.timing(),
        max_steps: p.max_rollout_steps,
        max_particles: p.max_particles,
        risk: p.plan_risk,
    };
    super::plan::plan_response_with(h.model.get().as_ref(), req, &settings, on_round)
}

/// What the Rollout service accepts and how it integrates, from the node's
/// parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RolloutLimits {
    /// Step of a request with `dt = 0` (the `dt` parameter).
    pub default_dt: f64,
    /// Longest integration step (`dt / substeps`).
    pub fine_dt: f64,
    /// `max_rollout_steps`.
    pub max_steps: u32,
    /// `max_particles`.
    pub max_particles: u32,
}

/// The Rollout service's work: checks the request, then predicts. `dt = 0` in
/// the request means `default_dt`; the model is integrated with steps no
/// longer than `fine_dt` and sampled every `dt`.
pub fn rollout_response(
    model: &dyn Dynamics,
    req: &RolloutRequest,
    limits: &RolloutLimits,
) -> RolloutResponse {
    let fail = |message: String| RolloutResponse {
        success: false,
        message,
        ..RolloutResponse::default()
    };
    let RolloutLimits {
        default_dt,
        fine_dt,
        max_steps,
        max_particles,
    } = *limits;
    if req.steps > max_steps {
        return fail(format!(
            "steps = {} exceeds max_rollout_steps = {max_steps}",
            req.steps
        ));
    }
    if let Err(e) = predict::check_size(&req.initial, max_particles) {
        return fail(e.to_string());
    }
    let dt = if req.dt == 0.0 { default_dt } else { req.dt };
    let (graph, start) = match predict::accept(model, &req.initial) {
        Ok(x) => x,
        Err(e) => return fail(e.to_string()),
    };
    let substeps = if dt.is_finite() && dt > 0.0 {
        ((dt / fine_dt).round() as usize).max(1)
    } else {
        1
    };
    let timing = Timing::new(dt, substeps, req.steps as usize);
    let given = super::plan::requested_drive(
        &graph,
        &req.kinematic_positions,
        &req.kinematic_velocities,
        timing.steps() + 1,
        timing.step(),
    );
    let predicted = match given {
        Err(e) => return fail(e.0),
        Ok(None) => predict::trajectory(model, &req.initial, &graph, &start, timing),
        Ok(Some(drive)) => {
            predict::trajectory_driven(model, (&req.initial, &graph, &start), timing, &drive)
        }
    };
    match predicted {
        Ok(trajectory) => RolloutResponse {
            success: true,
            message: format!("{} states, dt = {dt}", trajectory.steps),
            trajectory,
        },
        Err(e) => fail(e.to_string()),
    }
}

/// The Replay service's work: the bag through the model served now, with the
/// node's dt and horizon (see [`crate::replay::replay_as_node`]).
pub(crate) fn replay_call(h: &Handles, req: ReplayRequest) -> ReplayResponse {
    let p = h.params.get();
    let stream = match super::input::stream_options(&p) {
        Ok(s) => s,
        Err(e) => {
            return ReplayResponse {
                message: e.to_string(),
                ..ReplayResponse::default()
            }
        }
    };
    match crate::replay::replay_as_node_with(h.model.get().as_ref(), &req.bag, p.timing(), stream) {
        Ok((r, json)) => ReplayResponse {
            success: true,
            message: format!(
                "{} starts, {} comparisons, mean RE {:.3e}",
                r.starts, r.comparisons, r.averages.re
            ),
            report_json: json,
        },
        Err(e) => ReplayResponse {
            message: format!("{e:#}"),
            ..ReplayResponse::default()
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rollout_service_checks_its_request() {
        let model = crate::models::truth::load_truth("truth:spring").unwrap();
        let req = RolloutRequest {
            steps: 50,
            ..RolloutRequest::default()
        };
        let limits = |max_steps| RolloutLimits {
            default_dt: 0.01,
            fine_dt: 0.01,
            max_steps,
            max_particles: 100,
        };
        let r = rollout_response(model.as_ref(), &req, &limits(10));
        assert!(
            !r.success && r.message.contains("max_rollout_steps"),
            "{}",
            r.message
        );
        let r = rollout_response(model.as_ref(), &req, &limits(100));
        assert!(
            !r.success && r.message.contains("malformed"),
            "{}",
            r.message
        );
        let mut big = req.clone();
        big.initial.masses = vec![1.0; 101];
        let r = rollout_response(model.as_ref(), &big, &limits(100));
        assert!(
            !r.success && r.message.contains("max_particles = 100") && r.message.contains("101"),
            "{}",
            r.message
        );
    }
}
