//! From an incoming `ParticleState` to the node's outputs: checks the message,
//! asks the model for a rollout and forces, and builds the reply messages.
//! Pure functions, no ROS: the node and the Rollout service both call these.
//!
//! The prediction itself ([`predict_into`]) fills buffers the caller keeps:
//! the node predicts state after state of one system without allocating;
//! only the wire messages it then publishes are new ([`messages`]).

use crate::compat::{OutOfRange, Passed};
use crate::data::msg::{Header, ParticleState, Vector3};
use crate::data::DataError;
use crate::dynamics::{Dynamics, DynamicsError, FlatForces, KeptStates, Predicted, Spread, Timing};
use crate::system::{Graph, State};

use super::input::Input;
use super::params::NodeParams;
use super::wire::{ParticleForces, PredictedTrajectory};

/// Why a state gets no prediction; each message says what to change.
#[derive(Debug, thiserror::Error)]
pub enum PredictError {
    /// The node is not active (managed lifecycle).
    #[error("{0}")]
    Inactive(String),
    /// More particles than `max_particles` allows.
    #[error(
        "state too large: {particles} particles, above max_particles = {max} (raise it with \
         --set max_particles=N if the subscribers can take predictions that large)"
    )]
    TooLarge {
        /// Particles in the state.
        particles: usize,
        /// The `max_particles` parameter.
        max: u32,
    },
    /// The message does not describe a valid state.
    #[error("malformed input: {0}")]
    Malformed(#[from] DataError),
    /// The state is not what the model was trained for (dimension, edge
    /// kinds or parameters, field).
    #[error(transparent)]
    NotTrainedFor(#[from] crate::compat::Mismatch),
    /// An input outside the model's training range, refused because
    /// `out_of_range_refuse` is set.
    #[error("refused (out_of_range_refuse): {0}")]
    OutOfRange(crate::compat::OutOfRange),
    /// A state no model can meaningfully predict (a coordinate above
    /// [`crate::compat::ABSURD_MAGNITUDE`], an input
    /// [`crate::compat::ABSURD_SIGMAS`] training scales out), or a prediction
    /// that is not finite: refused whatever `out_of_range_refuse` says.
    #[error("refused (absurd state): {0}")]
    Absurd(String),
    /// A momentum-conserving model's prediction whose total momentum drifts
    /// from the input's by more than [`crate::compat::CONSERVATION_TOLERANCE`]
    /// of the momentum scale: refused and counted as rejected, like
    /// [`PredictError::Absurd`].
    #[error("refused (broke conservation): {0}")]
    BrokeConservation(String),
    /// The model cannot run this graph.
    #[error("unsupported system: {0}")]
    Unsupported(#[source] DynamicsError),
    /// A step that is not a positive number.
    #[error("dt = {0} must be finite and > 0")]
    BadStep(f64),
    /// The model's rollout failed.
    #[error("rollout failed: {0}")]
    Rollout(#[source] DynamicsError),
    /// The model's forces failed.
    #[error("forces failed: {0}")]
    Forces(#[source] DynamicsError),
    /// The model's forces do not fit the message.
    #[error("{0}")]
    ForceShape(String),
}

crate::error::typed_errors!(PredictError);

/// The wire messages of a prediction for one state.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// `horizon` states after the input.
    pub trajectory: PredictedTrajectory,
    /// Forces at the input state.
    pub forces: ParticleForces,
}

/// Refuses a state with more than `max_particles` particles (counted as the
/// longest per-particle array, so a malformed message cannot slip past),
/// naming the parameter that allows it.
pub fn check_size(input: &ParticleState, max_particles: u32) -> Result<(), PredictError> {
    let n = [
        input.types.len(),
        input.masses.len(),
        input.positions.len(),
        input.velocities.len(),
        input.accelerations.len(),
    ]
    .into_iter()
    .max()
    .unwrap_or(0);
    if n > max_particles as usize {
        return Err(PredictError::TooLarge {
            particles: n,
            max: max_particles,
        });
    }
    Ok(())
}

/// Checks an input message and converts it for the model; the error says
/// what is wrong with the message or why the model cannot take it.
pub fn accept(model: &dyn Dynamics, input: &ParticleState) -> Result<(Graph, State), PredictError> {
    let (graph, sample) = input.to_parts()?;
    model.supports(&graph).map_err(PredictError::Unsupported)?;
    Ok((graph, sample.state))
}

/// Rolls the model out from `input` (already accepted as `graph` +
/// `start`) as `timing` says; state `k` is `(k + 1)·dt` after the input
/// ([`PredictedTrajectory::state`]).
pub fn trajectory(
    model: &dyn Dynamics,
    input: &ParticleState,
    graph: &Graph,
    start: &State,
    timing: Timing,
) -> Result<PredictedTrajectory, PredictError> {
    let (states, spread) = integrate(timing, |t| model.rollout_spread(graph, start, t, None))?;
    Ok(trajectory_of(
        input,
        graph,
        timing.kept_dt(),
        (&states, &spread),
    ))
}

/// [`trajectory`] with the kinematic particles moved along `drive` (one row
/// per integration step of [`Timing::step`]).
pub fn trajectory_driven(
    model: &dyn Dynamics,
    (input, graph, start): (&ParticleState, &Graph, &State),
    timing: Timing,
    drive: &crate::physics::Drive,
) -> Result<PredictedTrajectory, PredictError> {
    let (states, spread) = integrate(timing, |t| {
        model.rollout_spread(graph, start, t, Some(drive))
    })?;
    Ok(trajectory_of(
        input,
        graph,
        timing.kept_dt(),
        (&states, &spread),
    ))
}

/// The wire message of a rollout from `input` (its kept states, the start
/// first, and their [`crate::dynamics::Spread`], empty for a single model),
/// `dt` apart: the start is not repeated.
pub fn trajectory_of(
    input: &ParticleState,
    graph: &Graph,
    dt: f64,
    (states, spread): (&[State], &[Vec<f64>]),
) -> PredictedTrajectory {
    let mut kept = KeptStates::default();
    kept.fill(graph.ndof(), states);
    let flat: Vec<f64> = spread.iter().flatten().copied().collect();
    trajectory_msg(input, dt, (&kept, &flat), 1)
}

/// The model's states as `timing` keeps them from `start` (the first is
/// `start` itself), and the forces at `start`, into `out`: on the graph of
/// the last call, a model with a forward pass allocates nothing. The model
/// is asked whether it supports the graph.
pub fn predict_into(
    model: &dyn Dynamics,
    graph: &Graph,
    start: &State,
    timing: Timing,
    out: &mut Predicted,
) -> Result<(), PredictError> {
    model.supports(graph).map_err(PredictError::Unsupported)?;
    // Only an ensemble fills it.
    out.spread.clear();
    model
        .predict_into(graph, start, checked(timing)?, out)
        .map_err(|e| match e {
            DynamicsError::Forces(e) => PredictError::Forces(*e),
            e => PredictError::Rollout(e),
        })?;
    if out.states.is_empty() {
        return Err(no_states());
    }
    Ok(())
}

/// The node's prediction for a parsed input, into `out`: the served model
/// (`model`, swap `generation`) checked against the input's system once per
/// system (`passed`), the input against the training range (refused when
/// `out_of_range_refuse` is set), then [`predict_into`]. Returns what was out
/// of range when it predicted anyway. On the system of the last call this
/// allocates nothing (`tests/alloc_free.rs` counts).
pub fn predict_served(
    (model, generation): (&dyn Dynamics, u64),
    passed: &Passed,
    input: &Input,
    params: &NodeParams,
    out: &mut Predicted,
) -> Result<Option<OutOfRange>, PredictError> {
    let mut outside = None;
    // A state the model was not trained for (another dimension, edge kinds
    // or field) is refused with the reason, not predicted.
    if let Some(t) = model.trained_for() {
        // Keyed by the model served: a swap checks again.
        passed.check(generation, t, &input.graph, input.field.as_ref())?;
        let sigmas = params.out_of_range_sigmas;
        outside = (t.range.as_ref()).and_then(|r| r.check(&input.graph, &input.state, sigmas));
        if let (Some(o), true) = (&outside, params.out_of_range_refuse) {
            return Err(PredictError::OutOfRange(o.clone()));
        }
    }
    refuse_absurd(model, input)?;
    predict_into(model, &input.graph, &input.state, params.timing(), out)?;
    let finite = |x: &[f64]| x.iter().all(|v| v.is_finite());
    let states_finite =
        (0..out.states.len()).all(|k| finite(out.states.q(k)) && finite(out.states.v(k)));
    if !(states_finite && finite(&out.forces.total)) {
        return Err(PredictError::Absurd(
            "the model's prediction is not finite (it overflowed): nothing published".into(),
        ));
    }
    if conserves_momentum(model, input) {
        check_momentum(&input.graph, &input.state.v, &out.states)?;
    }
    Ok(outside)
}

/// Whether the served model conserves total momentum on this input: an
/// MCGNODE without its body-force branch (pairwise forces only), on a graph
/// without anchors or kinematic particles, in a free field.
fn conserves_momentum(model: &dyn Dynamics, input: &Input) -> bool {
    let closed = model.trained_for().is_some_and(|t| t.closed == Some(true));
    closed
        && input.graph.anchors.is_empty()
        && !input.graph.kinematic.iter().any(|&k| k)
        && input
            .field
            .as_ref()
            .is_none_or(crate::physics::Field::is_free)
}

/// Refuses `states` (the prediction, its first the input itself) when a
/// state's total momentum differs from the input's (`v0`) by more than
/// [`crate::compat::CONSERVATION_TOLERANCE`] of the momentum scale: the
/// larger of the input's and that state's sum of |m v|.
pub fn check_momentum(graph: &Graph, v0: &[f64], states: &KeptStates) -> Result<(), PredictError> {
    use crate::compat::CONSERVATION_TOLERANCE;
    let d = graph.dim.max(1);
    // Total momentum (d components) and the sum of |m v| of velocities `v`.
    let momentum = |v: &[f64]| {
        let mut p = [0.0; 3];
        let mut scale = 0.0;
        for (m, vi) in graph.masses.iter().zip(v.chunks(d)) {
            for (pc, x) in p.iter_mut().zip(vi) {
                *pc += m * x;
            }
            scale += m.abs() * vi.iter().map(|x| x * x).sum::<f64>().sqrt();
        }
        (p, scale)
    };
    let (p0, s0) = momentum(v0);
    for k in 0..states.len() {
        let (p, s) = momentum(states.v(k));
        let drift = p0
            .iter()
            .zip(&p)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        let scale = s0.max(s);
        if drift > CONSERVATION_TOLERANCE * scale {
            return Err(PredictError::BrokeConservation(format!(
                "the model conserves momentum, but predicted state {k}'s total momentum drifts \
                 {drift:.3e} from the input's, {:.1e} of its scale {scale:.3e} (tolerance \
                 {CONSERVATION_TOLERANCE:e}): nothing published; send states in the range the \
                 model was trained on",
                drift / scale
            )));
        }
    }
    Ok(())
}

/// Refuses a state whose coordinates are beyond
/// [`crate::compat::ABSURD_MAGNITUDE`] or, for a model that states its
/// training range, an input [`crate::compat::ABSURD_SIGMAS`] training scales
/// out.
fn refuse_absurd(model: &dyn Dynamics, input: &Input) -> Result<(), PredictError> {
    use crate::compat::{ABSURD_MAGNITUDE, ABSURD_SIGMAS};
    let s = &input.state;
    let big = |x: &[f64]| x.iter().position(|v| v.abs() > ABSURD_MAGNITUDE);
    let d = input.graph.dim.max(1);
    for (what, xs) in [("position", &s.q), ("velocity", &s.v)] {
        if let Some(i) = big(xs) {
            return Err(PredictError::Absurd(format!(
                "{what} component {} of particle {} is {:.3e}, beyond {ABSURD_MAGNITUDE:e}: \
                 send states in the model's units",
                i % d,
                i / d,
                xs[i]
            )));
        }
    }
    let range = model.trained_for().and_then(|t| t.range.as_ref());
    if let Some(o) = range.and_then(|r| r.check(&input.graph, s, ABSURD_SIGMAS)) {
        return Err(PredictError::Absurd(o.to_string()));
    }
    Ok(())
}

/// The wire messages of `p`, predicted from `input` (parsed as `graph`)
/// every `dt`.
pub fn messages(
    input: &ParticleState,
    graph: &Graph,
    dt: f64,
    p: &Predicted,
) -> Result<Prediction, PredictError> {
    Ok(Prediction {
        trajectory: trajectory_msg(input, dt, (&p.states, &p.spread), 1),
        forces: forces_msg(&input.header, graph.dim, &p.forces)?,
    })
}

/// `timing`, refused as a bad step unless its `dt` is positive and finite.
fn checked(timing: Timing) -> Result<Timing, PredictError> {
    timing
        .check()
        .map_err(|_| PredictError::BadStep(timing.dt))?;
    Ok(timing)
}

/// A model that answered with no state at all.
fn no_states() -> PredictError {
    PredictError::Rollout(DynamicsError::Model("the model returned no states".into()))
}

/// Runs `roll(timing)` after checking its step, refusing an empty answer
/// (its states and their spread).
fn integrate(
    timing: Timing,
    roll: impl FnOnce(Timing) -> Result<(Vec<State>, Spread), DynamicsError>,
) -> Result<(Vec<State>, Spread), PredictError> {
    let (states, spread) = roll(checked(timing)?).map_err(PredictError::Rollout)?;
    if states.is_empty() {
        return Err(no_states());
    }
    Ok((states, spread))
}

/// The wire message of the predicted `states` (and their flat spread, `n`
/// numbers a state, or none) from the `skip`-th on, after `input`, `dt` apart.
fn trajectory_msg(
    input: &ParticleState,
    dt: f64,
    (states, spread): (&KeptStates, &[f64]),
    skip: usize,
) -> PredictedTrajectory {
    // The wire's layout is the kept states' own: n·d numbers a state.
    let kept = states.len().saturating_sub(skip);
    let (positions, velocities) = (states.q_from(skip).to_vec(), states.v_from(skip).to_vec());
    let n = input.positions.len();
    let spread = spread.get(skip * n..).unwrap_or_default().to_vec();
    PredictedTrajectory {
        header: input.header.clone(),
        initial: input.clone(),
        dt,
        steps: u32::try_from(kept).unwrap_or(u32::MAX),
        positions,
        velocities,
        spread,
    }
}

/// Converts forces to the wire message (2D forces get z = 0).
pub fn forces_msg(
    header: &Header,
    dim: usize,
    f: &FlatForces,
) -> Result<ParticleForces, PredictError> {
    let shape = PredictError::ForceShape;
    let vec3 = |c: &[f64]| -> Result<Vector3, PredictError> {
        if c.len() != dim {
            return Err(shape(format!(
                "model gave a {}-component force in {dim}D",
                c.len()
            )));
        }
        Ok(Vector3::from_coords(c))
    };
    if f.total.len() % dim != 0 {
        let len = f.total.len();
        return Err(shape(format!(
            "model gave {len} total-force numbers in {dim}D"
        )));
    }
    if f.pair_force.len() != f.pairs.len() * dim {
        return Err(shape(format!(
            "model gave {} pair-force numbers for {} pairs in {dim}D",
            f.pair_force.len(),
            f.pairs.len()
        )));
    }
    let idx =
        |i: usize| u32::try_from(i).map_err(|_| shape(format!("particle index {i} too large")));
    Ok(ParticleForces {
        header: header.clone(),
        total: f.total.chunks(dim).map(vec3).collect::<Result<_, _>>()?,
        edge_a: f.pairs.iter().map(|e| idx(e.0)).collect::<Result<_, _>>()?,
        edge_b: f.pairs.iter().map(|e| idx(e.1)).collect::<Result<_, _>>()?,
        edge_force: f
            .pair_force
            .chunks(dim)
            .map(vec3)
            .collect::<Result<_, _>>()?,
    })
}

/// Everything the node publishes for one incoming state (into buffers of
/// its own; the node keeps them from state to state with [`predict_into`]).
pub fn predict(
    model: &dyn Dynamics,
    input: &ParticleState,
    timing: Timing,
) -> Result<Prediction, PredictError> {
    let (graph, start) = accept(model, input)?;
    let mut p = Predicted::default();
    predict_into(model, &graph, &start, timing, &mut p)?;
    messages(input, &graph, timing.kept_dt(), &p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_prediction_that_breaks_momentum_conservation_is_refused() {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("bags/models/spring5-mcgnode.json");
        let model = crate::kernel::TrainedModel::load(&p).expect("shipped model");
        let (graph, start) = accept(&model, &spring_state()).expect("accepted");
        let mut out = Predicted::default();
        let timing = Timing::integration(1e-3, 100, 10);
        predict_into(&model, &graph, &start, timing, &mut out).expect("prediction");
        assert!(out.states.len() > 5);
        // The shipped MCGNODE conserves momentum: its real prediction passes.
        check_momentum(&graph, &start.v, &out.states).expect("a real prediction conserves");
        // One particle's velocity in one state corrupted by 1e-4 of the speed.
        let mut states: Vec<State> = (0..out.states.len())
            .map(|k| State {
                q: out.states.q(k).to_vec(),
                v: out.states.v(k).to_vec(),
            })
            .collect();
        let speed = start.v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        states[5].v[2] += 1e-4 * speed;
        let mut bad = KeptStates::default();
        bad.fill(graph.ndof(), &states);
        let e = check_momentum(&graph, &start.v, &bad).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("refused (broke conservation): "), "{msg}");
        assert!(msg.contains("predicted state 5"), "{msg}");
    }
    use crate::data::msg::{to_vec3, Time};
    use crate::models::truth::load_truth;
    use crate::physics::{SystemConfig, SystemKind};
    use crate::system::Sample;

    fn spring_state() -> ParticleState {
        let cfg = SystemConfig::new(SystemKind::Spring, 5);
        let graph = cfg.graph();
        let state = cfg.start_for(&graph, 3, 0);
        let mut msg = ParticleState::from_sample(
            4,
            10,
            "spring",
            &graph,
            &Sample {
                t: 0.0,
                state,
                acc: None,
            },
        );
        msg.header = Header {
            stamp: Time {
                sec: 1_700_000_000,
                nanosec: 999_999_000,
            },
            frame_id: "lab".into(),
        };
        msg
    }

    #[test]
    fn prediction_is_stamped_from_the_input() {
        let model = load_truth("truth:spring").unwrap();
        let input = spring_state();
        let p = predict(model.as_ref(), &input, Timing::new(0.001, 1, 7)).unwrap();
        assert_eq!(p.trajectory.header, input.header);
        assert_eq!(p.forces.header, input.header);
        assert_eq!(p.trajectory.initial, input);
        assert_eq!(p.trajectory.steps, 7);
        assert_eq!(p.trajectory.positions.len(), 7 * 5 * 2);
        assert_eq!(p.trajectory.velocities.len(), 7 * 5 * 2);
        assert!(p.trajectory.state(7).is_none());
        let s3 = &p.trajectory.state(2).unwrap();
        assert_eq!(s3.positions, to_vec3(p.trajectory.positions_at(2), 2));
        assert_eq!(s3.velocities, to_vec3(p.trajectory.velocities_at(2), 2));
        assert!(s3.positions.iter().all(|v| v.z == 0.0));
        assert_eq!(s3.edge_a, input.edge_a);
        assert_eq!(s3.step, 13);
        assert_eq!(s3.trajectory_id, 4);
        assert_eq!(s3.header.frame_id, "lab");
        assert_eq!(
            s3.header.stamp.as_nanos() - input.header.stamp.as_nanos(),
            3_000_000
        );
        // The states moved, and the forces of a 5-ring: 5 totals, 5 pairs.
        assert_ne!(s3.positions, input.positions);
        assert_eq!(p.forces.total.len(), 5);
        assert_eq!(p.forces.edge_a.len(), 5);
        assert_eq!(p.forces.edge_force.len(), 5);
        // Newton's third law: internal spring forces sum to zero.
        let sx: f64 = p.forces.total.iter().map(|v| v.x).sum();
        assert!(sx.abs() < 1e-9, "{sx}");
    }

    #[test]
    fn predicted_states_carry_the_inputs_field() {
        let model = load_truth("truth:spring").unwrap();
        let input = spring_state().with_field(Some(&crate::physics::Field::default()));
        let p = predict(model.as_ref(), &input, Timing::new(0.001, 1, 3)).unwrap();
        for s in (0..3).filter_map(|k| p.trajectory.state(k)) {
            assert_eq!(s.field_status, crate::data::msg::FIELD_KNOWN);
            assert_eq!(s.field().unwrap(), Some(crate::physics::Field::default()));
        }
        // Without a field stated, the predictions do not invent one.
        let p = predict(model.as_ref(), &spring_state(), Timing::new(0.001, 1, 3)).unwrap();
        assert!((0..3).all(|k| p.trajectory.state(k).unwrap().field_status == 0));
    }

    /// The 1e300-scaled state of the issue is refused with the reason (by
    /// default, `out_of_range_refuse` off); the same state unscaled is
    /// predicted.
    #[test]
    fn absurd_states_are_refused_with_the_reason() {
        use crate::ros::input::{Accepted, Inputs};
        let model = load_truth("truth:spring").unwrap();
        let params = NodeParams::default();
        let served = |msg: ParticleState| {
            let Accepted::Ready(input) = Inputs::default().accept(&params, msg).unwrap() else {
                panic!("a state with velocities is ready at once");
            };
            let mut out = Predicted::default();
            predict_served(
                (model.as_ref(), 1),
                &Passed::default(),
                &input,
                &params,
                &mut out,
            )
        };
        assert!(served(spring_state()).is_ok());
        let mut huge = spring_state();
        for p in &mut huge.positions {
            (p.x, p.y) = (p.x * 1e300, p.y * 1e300);
        }
        let e = served(huge).unwrap_err();
        assert!(matches!(e, PredictError::Absurd(_)), "{e}");
        assert!(e.to_string().contains("beyond 1e100"), "{e}");
        let mut fast = spring_state();
        fast.velocities[2].y = -1e200;
        let e = served(fast).unwrap_err();
        assert!(
            e.to_string().contains("velocity component 1 of particle 2"),
            "{e}"
        );
    }

    #[test]
    fn malformed_input_is_an_error_not_a_panic() {
        let model = load_truth("truth:spring").unwrap();
        let mut nan = spring_state();
        nan.positions[1].x = f64::NAN;
        let mut short = spring_state();
        short.masses.pop();
        let mut edge = spring_state();
        edge.edge_a[0] = 99;
        let mut dim = spring_state();
        dim.dimension = 7;
        for (bad, want) in [
            (nan, "not finite"),
            (short, "masses has 4 entries"),
            (edge, "out of range"),
            (dim, "dimension"),
        ] {
            let e = predict(model.as_ref(), &bad, Timing::new(0.001, 1, 3)).unwrap_err();
            assert!(matches!(e, PredictError::Malformed(_)), "{e}");
            let e = e.to_string();
            assert!(e.contains("malformed") && e.contains(want), "{e}");
        }
        let e = predict(model.as_ref(), &spring_state(), Timing::new(f64::NAN, 1, 3)).unwrap_err();
        assert!(matches!(e, PredictError::BadStep(_)), "{e}");
        assert!(e.to_string().contains("dt"), "{e}");
    }

    /// Truth for its rollout, but forces that fail: the error must say
    /// forces, not rollout.
    struct NoForces(std::sync::Arc<dyn Dynamics>);

    impl Dynamics for NoForces {
        fn describe(&self) -> String {
            "no forces".into()
        }
        fn supports(&self, graph: &Graph) -> Result<(), DynamicsError> {
            self.0.supports(graph)
        }
        fn acceleration(
            &self,
            graph: &Graph,
            state: &State,
            out: &mut [f64],
        ) -> Result<(), DynamicsError> {
            self.0.acceleration(graph, state, out)
        }
        fn forces(&self, _: &Graph, _: &State) -> Result<crate::dynamics::Forces, DynamicsError> {
            Err(DynamicsError::Model("this model has no forces".into()))
        }
    }

    #[test]
    fn failed_forces_are_reported_as_forces() {
        let model = NoForces(load_truth("truth:spring").unwrap());
        let e = predict(&model, &spring_state(), Timing::new(0.001, 1, 3)).unwrap_err();
        assert!(matches!(e, PredictError::Forces(_)), "{e:?}");
        assert_eq!(e.to_string(), "forces failed: this model has no forces");
    }
}
