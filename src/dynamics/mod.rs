//! The one interface between "something that knows the dynamics" (a trained
//! model, or the ground-truth physics) and whoever uses it (rollouts, metrics,
//! the ROS node).

use crate::compat::Mismatch;
use crate::gnode::arch::ArchError;
use crate::physics::{verlet, Drive, DriveError, PhysicsError};
use crate::system::{Graph, State, SystemError};

mod predicted;
mod timing;
pub use predicted::{FlatForces, KeptStates, Predicted};
pub use timing::Timing;

/// Forces a model attributes to a state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Forces {
    /// Total force per particle, `n * dim`.
    pub total: Vec<f64>,
    /// Pairwise forces f_ab on particle `a` due to particle `b` (so f_ba = −f_ab),
    /// one entry per particle edge, when the model has them (MCGNODE).
    pub edges: Vec<EdgeForce>,
}

/// A model's accelerations on one graph with reverse mode through them:
/// what a planning gradient chains through a rollout
/// ([`crate::plan::gradient`]). Holds its own buffers.
pub trait StateGradient: Send {
    /// q̈ at (q, q̇) into `acc` (`n·d`), as the model's rollouts evaluate it.
    fn acceleration(&mut self, q: &[f64], v: &[f64], acc: &mut [f64]);

    /// q̈ at (q, q̇) into `acc`, and, with L = Σ ḡ·q̈ for ḡ = `gacc`, ∂L/∂q
    /// into `gq` and ∂L/∂q̇ into `gv`; all `n·d`.
    #[allow(clippy::too_many_arguments)]
    fn vjp(
        &mut self,
        q: &[f64],
        v: &[f64],
        gacc: &[f64],
        acc: &mut [f64],
        gq: &mut [f64],
        gv: &mut [f64],
    );

    /// The projection onto the bars the model's rollouts apply after each
    /// drift and kick (SHAKE/RATTLE with its masses), if any.
    fn projector(&self) -> Option<crate::physics::Projector>;
}

/// The force on particle `a` due to particle `b`.
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeForce {
    /// Particle receiving the force.
    pub a: usize,
    /// Particle exerting it.
    pub b: usize,
    /// The force, `dim` components.
    pub force: Vec<f64>,
}

/// The outcome of one rollout among many ([`Dynamics::rollout_many`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Rollout {
    /// The start and every kept state, up to (not including) divergence.
    pub states: Vec<State>,
    /// The integration step at which the state became non-finite, if it did.
    pub diverged_at: Option<usize>,
}

/// Velocity Verlet for many starts of one graph in lockstep: `accel` gets the
/// still-finite states of a step together, so models with a large per-call
/// cost (the candle baselines) pay it once per step rather than once per
/// trajectory. The arithmetic per trajectory is exactly that of
/// [`Dynamics::rollout`]; a trajectory that turns non-finite is dropped
/// from the batch and reported in [`Rollout::diverged_at`].
pub fn verlet_lockstep(
    graph: &Graph,
    starts: &[State],
    timing: Timing,
    mut accel: impl FnMut(&[State], &mut [Vec<f64>]) -> Result<(), DynamicsError>,
) -> Result<Vec<Rollout>, DynamicsError> {
    timing.check()?;
    for s in starts {
        s.validate(graph)?;
    }
    let (dt, steps) = (timing.step(), timing.steps());
    let mut out: Vec<Rollout> = starts
        .iter()
        .map(|s| Rollout {
            states: vec![s.clone()],
            diverged_at: None,
        })
        .collect();
    // `active[k]` is the trajectory index of `cur[k]`.
    let mut active: Vec<usize> = (0..starts.len()).collect();
    let mut cur: Vec<State> = starts.to_vec();
    let mut acc = vec![vec![0.0; graph.ndof()]; cur.len()];
    if !cur.is_empty() {
        accel(&cur, &mut acc)?;
    }
    for step in 1..=steps {
        if cur.is_empty() {
            break;
        }
        for (s, a) in cur.iter_mut().zip(&acc) {
            verlet::drift(&mut s.q, &mut s.v, a, dt);
            verlet::wrap(graph, &mut s.q);
        }
        accel(&cur, &mut acc)?;
        let mut k = 0;
        while k < cur.len() {
            let s = &mut cur[k];
            verlet::kick(&mut s.v, &acc[k], dt);
            if s.q.iter().chain(&s.v).any(|x| !x.is_finite()) {
                out[active[k]].diverged_at = Some(step);
                cur.remove(k);
                acc.remove(k);
                active.remove(k);
                continue;
            }
            if timing.keeps(step) {
                out[active[k]].states.push(s.clone());
            }
            k += 1;
        }
    }
    Ok(out)
}

/// [`Dynamics::rollout_many`] as one [`Dynamics::rollout`] per start,
/// for models whose rollouts do not diverge (an error fails the call).
pub fn rollout_each(
    model: &(impl Dynamics + ?Sized),
    graph: &Graph,
    starts: &[State],
    timing: Timing,
) -> Result<Vec<Rollout>, DynamicsError> {
    starts
        .iter()
        .map(|s| {
            Ok(Rollout {
                states: model.rollout(graph, s, timing)?,
                diverged_at: None,
            })
        })
        .collect()
}

/// The buffers of [`Dynamics::acceleration_batch`]: one per state.
pub fn check_batch(states: &[State], out: &[Vec<f64>]) -> Result<(), DynamicsError> {
    if states.len() == out.len() {
        Ok(())
    } else {
        Err(DynamicsError::Buffers {
            states: states.len(),
            buffers: out.len(),
        })
    }
}

/// Something that predicts accelerations of a particle system.
pub trait Dynamics: Send + Sync {
    /// A short human-readable description ("mcgnode trained on 5-spring", ...).
    fn describe(&self) -> String;

    /// Whether this graph can be handled (particle types known, dimension, ...).
    fn supports(&self, graph: &Graph) -> Result<(), DynamicsError>;

    /// What the model was trained on, when a caller wrapped it with that
    /// knowledge ([`crate::models::Checked`]); `None` otherwise.
    fn trained_for(&self) -> Option<&crate::compat::TrainedFor> {
        None
    }

    /// Whether a rollout of `L` disjoint copies of a graph costs about `L`
    /// rollouts of one (message passing and per-edge physics do; a dense
    /// mass-matrix solve over the whole system, LGN's or HGN's, costs L³),
    /// so that a planner may step candidates together
    /// ([`crate::plan::Problem::costs`]). Off unless a model says so.
    fn steps_copies_together(&self) -> bool {
        false
    }

    /// Accelerations at a state, written to `out` (`n * dim`).
    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError>;

    /// Forces at a state.
    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError>;

    /// [`Dynamics::rollout`] and the [`Dynamics::forces`] at `start`
    /// into `out` (the start first), what the node publishes for each state.
    /// Models with a forward pass take the forces from the rollout's first
    /// evaluation and, on a graph they saw last, allocate nothing.
    fn predict_into(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        out: &mut Predicted,
    ) -> Result<(), DynamicsError> {
        let states = self.rollout(graph, start, timing)?;
        fill_prediction(self, graph, start, &states, out)
    }

    /// Velocity-Verlet rollout timed by `timing`: its [`Timing::steps`]
    /// steps of [`Timing::step`], keeping `start` and every
    /// [`Timing::stride`]-th state (so a coarse output can come from a fine
    /// integration step).
    ///
    /// The velocity-dependent acceleration at the new position is evaluated at
    /// the half-step velocity, which keeps the scheme explicit.
    fn rollout(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
    ) -> Result<Vec<State>, DynamicsError> {
        self.supports(graph)?;
        start.validate(graph)?;
        let (dt, steps) = (timing.step(), timing.steps());
        let mut out = Vec::with_capacity(timing.kept());
        let mut s = start.clone();
        let mut a = vec![0.0; graph.ndof()];
        self.acceleration(graph, &s, &mut a)?;
        out.push(s.clone());
        for step in 1..=steps {
            verlet::drift(&mut s.q, &mut s.v, &a, dt);
            verlet::wrap(graph, &mut s.q);
            self.acceleration(graph, &s, &mut a)?;
            verlet::kick(&mut s.v, &a, dt);
            if s.q.iter().chain(&s.v).any(|x| !x.is_finite()) {
                return Err(DynamicsError::Diverged(step));
            }
            if timing.keeps(step) {
                out.push(s.clone());
            }
        }
        Ok(out)
    }

    /// Reverse mode through this model's accelerations on `graph`, when it
    /// has one (the GNODE family, on the engine); `None` for the others.
    fn state_gradient(
        &self,
        graph: &Graph,
    ) -> Result<Option<Box<dyn StateGradient>>, DynamicsError> {
        let _ = graph;
        Ok(None)
    }

    /// [`Dynamics::rollout`] with the kinematic particles moved along
    /// `drive` (one row per integration step, at least [`Timing::steps`]):
    /// before each evaluation they are placed where it has them, so the free
    /// particles respond to that motion. The start's driven particles are
    /// placed at row 0 too. The default evaluates [`Dynamics::acceleration`]
    /// per step; models with a forward pass run it on their workspace.
    fn rollout_driven(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: &Drive,
    ) -> Result<Vec<State>, DynamicsError> {
        self.supports(graph)?;
        start.validate(graph)?;
        let (dt, steps) = (timing.step(), timing.steps());
        drive.check(graph, steps)?;
        timing.check()?;
        let mut out = Vec::with_capacity(timing.kept());
        let mut s = start.clone();
        drive.place(0, &mut s.q, &mut s.v);
        let mut a = vec![0.0; graph.ndof()];
        self.acceleration(graph, &s, &mut a)?;
        out.push(s.clone());
        for step in 1..=steps {
            let mut failed = None;
            let State { q, v } = &mut s;
            verlet::step_placed(
                q,
                v,
                &mut a,
                dt,
                None,
                |q, v| {
                    verlet::wrap(graph, q);
                    drive.place(step, q, v);
                },
                |q, v, a| {
                    let st = State {
                        q: q.to_vec(),
                        v: v.to_vec(),
                    };
                    self.acceleration(graph, &st, a)
                        .map_err(|e| failed = Some(e))
                },
            )
            .map_err(|()| failed.take().unwrap_or(DynamicsError::Diverged(step)))?;
            if s.q.iter().chain(&s.v).any(|x| !x.is_finite()) {
                return Err(DynamicsError::Diverged(step));
            }
            if timing.keeps(step) {
                out.push(s.clone());
            }
        }
        Ok(out)
    }

    /// Accelerations of several states of one graph, one `n * dim` vector per
    /// state. The default calls [`Dynamics::acceleration`] per state.
    fn acceleration_batch(
        &self,
        graph: &Graph,
        states: &[State],
        out: &mut [Vec<f64>],
    ) -> Result<(), DynamicsError> {
        check_batch(states, out)?;
        for (s, o) in states.iter().zip(out.iter_mut()) {
            self.acceleration(graph, s, o)?;
        }
        Ok(())
    }

    /// Rollouts of many starts of one graph, each as
    /// [`Dynamics::rollout`] would do it, except that a rollout that
    /// diverges keeps its states so far (see [`Rollout`]) instead of failing
    /// the call. The default steps all starts in lockstep with
    /// [`Dynamics::acceleration_batch`] ([`verlet_lockstep`]).
    fn rollout_many(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: Timing,
    ) -> Result<Vec<Rollout>, DynamicsError> {
        self.supports(graph)?;
        verlet_lockstep(graph, starts, timing, |s, a| {
            self.acceleration_batch(graph, s, a)
        })
    }

    /// [`Dynamics::rollout`] (or [`Dynamics::rollout_driven`] along `drive`)
    /// with each kept state's [`Spread`]; empty for a single model, whose
    /// prediction has none.
    fn rollout_spread(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: Option<&Drive>,
    ) -> Result<(Vec<State>, Spread), DynamicsError> {
        let states = match drive {
            Some(d) => self.rollout_driven(graph, start, timing, d)?,
            None => self.rollout(graph, start, timing)?,
        };
        Ok((states, Vec::new()))
    }

    /// Models whose prediction is the mean of this many (an ensemble,
    /// [`crate::kernel::Ensemble`]); 1 for a single model.
    fn members(&self) -> usize {
        1
    }

    /// [`Dynamics::rollout_many`] with each kept state's [`Spread`]. A
    /// single model's spread is zero; an ensemble's is its members'.
    fn rollout_many_spread(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: Timing,
    ) -> Result<Vec<(Rollout, Spread)>, DynamicsError> {
        let n = graph.n();
        Ok(self
            .rollout_many(graph, starts, timing)?
            .into_iter()
            .map(|r| {
                let zero = vec![vec![0.0; n]; r.states.len()];
                (r, zero)
            })
            .collect())
    }
}

/// `states` (the start first) and `model`'s forces at `start` into `out`.
pub fn fill_prediction<M: Dynamics + ?Sized>(
    model: &M,
    graph: &Graph,
    start: &State,
    states: &[State],
    out: &mut Predicted,
) -> Result<(), DynamicsError> {
    let forces = model
        .forces(graph, start)
        .map_err(|e| DynamicsError::Forces(Box::new(e)))?;
    out.states.fill(graph.ndof(), states);
    out.forces.fill(&forces);
    Ok(())
}

/// Per kept state, each particle's spread: the ensemble members' standard
/// deviation of its position, √(mean over axes of the variance).
pub type Spread = Vec<Vec<f64>>;

/// The name under which [`Still`] is loaded (`--model still`).
pub const STILL: &str = "still";

/// The "nothing moves" reference: every predicted state is the start's
/// positions at rest, q̂(t) = q(0). What a learned model must beat on systems
/// that move little, such as a solid vibrating about its rest shape.
#[derive(Clone, Copy, Debug, Default)]
pub struct Still;

impl Still {
    fn at_rest(start: &State) -> State {
        State {
            q: start.q.clone(),
            v: vec![0.0; start.v.len()],
        }
    }
}

impl Dynamics for Still {
    fn describe(&self) -> String {
        "nothing moves (q̂(t) = q(0), at rest): the reference".into()
    }

    fn supports(&self, graph: &Graph) -> Result<(), DynamicsError> {
        Ok(graph.validate()?)
    }

    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        state.validate(graph)?;
        out.fill(0.0);
        Ok(())
    }

    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError> {
        state.validate(graph)?;
        Ok(Forces {
            total: vec![0.0; graph.ndof()],
            edges: vec![],
        })
    }

    fn rollout(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
    ) -> Result<Vec<State>, DynamicsError> {
        start.validate(graph)?;
        Ok(vec![Self::at_rest(start); timing.kept()])
    }

    /// The free particles stand still; the driven ones follow their motion.
    fn rollout_driven(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: &Drive,
    ) -> Result<Vec<State>, DynamicsError> {
        start.validate(graph)?;
        drive.check(graph, timing.steps())?;
        Ok((0..=timing.steps())
            .step_by(timing.stride())
            .map(|k| {
                let mut s = Self::at_rest(start);
                drive.place(k, &mut s.q, &mut s.v);
                s
            })
            .collect())
    }

    fn rollout_many(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: Timing,
    ) -> Result<Vec<Rollout>, DynamicsError> {
        rollout_each(self, graph, starts, timing)
    }
}

/// Why a model cannot predict: the input is invalid or does not fit the
/// model, or the prediction failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DynamicsError {
    /// The graph or a state is invalid.
    #[error(transparent)]
    System(#[from] SystemError),
    /// The field (or the physics' input) is invalid.
    #[error(transparent)]
    Physics(#[from] PhysicsError),
    /// The graph does not fit a GNODE-family model's architecture.
    #[error(transparent)]
    Arch(#[from] ArchError),
    /// The data are not what the model was trained on ([`crate::compat`]).
    #[error(transparent)]
    NotTrainedFor(#[from] Mismatch),
    /// A baseline meets a graph of another dimension.
    #[error("{model} was trained on {trained}D systems, the graph is {graph}D")]
    Dimension {
        /// The model.
        model: String,
        /// Its dimension.
        trained: usize,
        /// The graph's.
        graph: usize,
    },
    /// The integration step is not positive and finite.
    #[error("time step must be positive and finite, got {0}")]
    TimeStep(f64),
    /// Not one output buffer per state.
    #[error("{states} states but {buffers} output buffers: one per state is needed")]
    Buffers {
        /// States given.
        states: usize,
        /// Buffers given.
        buffers: usize,
    },
    /// An output buffer of the wrong length.
    #[error("output has {got} slots, need {need}")]
    OutputSize {
        /// Its length.
        got: usize,
        /// n · dim.
        need: usize,
    },
    /// The kinematic particles' given motion does not fit the rollout.
    #[error(transparent)]
    Drive(#[from] DriveError),
    /// The rolled-out state turned non-finite at this step.
    #[error("rollout diverged (non-finite state) at step {0}")]
    Diverged(usize),
    /// A thread of a parallel rollout panicked.
    #[error("a rollout thread panicked")]
    ThreadPanicked,
    /// The model's own computation failed (candle), with its causes.
    #[error("{0}")]
    Model(String),
    /// The forces failed although the rollout did not
    /// ([`Dynamics::predict_into`]): callers report it as such.
    #[error("{0}")]
    Forces(Box<DynamicsError>),
}

crate::error::typed_errors!(DynamicsError);
