//! An incoming `ParticleState`, parsed once into what the model, the checks
//! and live accuracy need ([`Input`]), with the velocities of position-only
//! messages estimated from the stream's history ([`crate::data::stream`]):
//! one history per trajectory id, at most `input_max_streams` of them.

use std::sync::{Mutex, PoisonError};
use std::time::Instant;

use crate::data::msg::{to_vec3, ParticleState};
use crate::data::stream::{Estimate, History, Nanos, Reset, Smoother, StreamOptions, Streams};
use crate::data::DataError;
use crate::dynamics::Dynamics;
use crate::physics::Field;
use crate::system::{Graph, State};

use super::params::NodeParams;
use super::smoother::{fit_newest, CostSummary, Costs, StreamFit};

/// One incoming state, checked and typed.
#[derive(Clone, Debug)]
pub struct Input {
    /// The message as predicted from: a position-only message gets the
    /// estimated velocities (and, with a poly smoother, the fitted positions).
    pub message: ParticleState,
    /// Its graph.
    pub graph: Graph,
    /// Its state.
    pub state: State,
    /// Its field (`None`: unknown).
    pub field: Option<Field>,
    /// Its stamp.
    pub stamp: Nanos,
    /// Its trajectory id (the stream).
    pub trajectory_id: u32,
    /// Whether its velocities were estimated from the history.
    pub derived: bool,
    /// Why the stream started over at this state, if it did.
    pub reset: Option<Reset>,
}

/// What became of an incoming state.
#[derive(Clone, Debug)]
pub enum Accepted {
    /// Ready to predict from.
    Ready(Box<Input>),
    /// Position-only, and its stream has too little history yet.
    WarmingUp {
        /// States held.
        have: usize,
        /// States needed.
        needs: usize,
        /// Why the stream started over at this state, if it did.
        reset: Option<Reset>,
    },
}

/// The stream settings the parameters give; the error names the parameters.
pub fn stream_options(p: &NodeParams) -> Result<StreamOptions, DataError> {
    let smoother = Smoother::new(
        &p.velocity_smoother,
        p.smoother_window as usize,
        p.smoother_order as usize,
    )
    .map_err(|e| {
        DataError::Invalid(format!(
            "velocity_smoother, smoother_window, smoother_order: {e}"
        ))
    })?;
    Ok(StreamOptions {
        smoother,
        max_gap: p.input_max_gap,
    })
}

/// One input stream: its history, and with the model smoother its fitter.
#[derive(Debug, Default)]
struct Stream {
    history: History,
    fit: Option<StreamFit>,
}

/// The node's input streams.
#[derive(Debug)]
pub struct Inputs {
    state: Mutex<(StreamOptions, Streams<Stream>)>,
    costs: Mutex<Costs>,
}

impl Default for Inputs {
    fn default() -> Self {
        Inputs {
            state: Mutex::new((StreamOptions::default(), Streams::new(1))),
            costs: Mutex::default(),
        }
    }
}

impl Inputs {
    /// [`Inputs::accept_with`] without a model (the model smoother refuses).
    pub fn accept(&self, p: &NodeParams, msg: ParticleState) -> Result<Accepted, DataError> {
        self.accept_with(p, msg, None)
    }

    /// Median and p99 of the model smoother's last fits (per state), `None`
    /// before its first.
    pub fn smoother_cost(&self) -> Option<CostSummary> {
        self.costs
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .summary()
    }

    /// Parses `msg` once and, for a position-only one, estimates its
    /// velocities from its stream's history; with `velocity_smoother: model`
    /// through `model` (the served one and its generation). Streams start
    /// over when the stream settings change.
    pub fn accept_with(
        &self,
        p: &NodeParams,
        mut msg: ParticleState,
        model: Option<(&dyn Dynamics, u64)>,
    ) -> Result<Accepted, DataError> {
        let (graph, sample, no_v) = msg.to_parts_positions_only()?;
        let field = msg.field()?;
        let opts = stream_options(p)?;
        let stamp = msg.header.stamp.as_nanos();
        let id = msg.trajectory_id;
        let estimate = {
            let mut guard = self.state.lock().unwrap_or_else(PoisonError::into_inner);
            let (current, streams) = &mut *guard;
            if *current != opts || streams.capacity() != p.input_max_streams as usize {
                *guard = (opts, Streams::new(p.input_max_streams as usize));
            }
            let stream = guard.1.get_or_insert_with(id, Stream::default);
            let (reset, estimate) = stream.history.push(&opts, &graph, stamp, &sample.state.q);
            match (estimate, opts.smoother) {
                (Estimate::Ready(poly), Smoother::Model { .. }) if no_v => {
                    let model = model.ok_or_else(|| {
                        DataError::Invalid(
                            "velocity_smoother model needs the served model (use none or poly)"
                                .into(),
                        )
                    })?;
                    let t0 = Instant::now();
                    let fitted = fit_newest(
                        &mut stream.fit,
                        model,
                        &graph,
                        p.fit_options(),
                        &stream.history,
                        reset.is_some(),
                        poly,
                    )?;
                    self.costs
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .note(t0);
                    (reset, Estimate::Ready(fitted))
                }
                (estimate, _) => (reset, estimate),
            }
        };
        let (reset, estimate) = estimate;
        let state = if no_v {
            match estimate {
                Estimate::WarmingUp { have, needs } => {
                    return Ok(Accepted::WarmingUp { have, needs, reset })
                }
                Estimate::Ready(s) => {
                    msg.positions = to_vec3(&s.q, graph.dim);
                    msg.velocities = to_vec3(&s.v, graph.dim);
                    s
                }
            }
        } else {
            sample.state
        };
        Ok(Accepted::Ready(Box::new(Input {
            message: msg,
            graph,
            state,
            field,
            stamp,
            trajectory_id: id,
            derived: no_v,
            reset,
        })))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{SystemConfig, SystemKind};
    use crate::system::Sample;

    fn message(k: u32, t: f64, cfg: &SystemConfig) -> ParticleState {
        let graph = cfg.graph();
        let mut state = cfg.start_for(&graph, 3, 0);
        state.q.iter_mut().for_each(|x| *x += 0.1 * t);
        let mut m = ParticleState::from_sample(
            7,
            k,
            "spring",
            &graph,
            &Sample {
                t,
                state,
                acc: None,
            },
        );
        m.header.stamp = crate::data::msg::Time {
            sec: 100,
            nanosec: (t * 1e9) as u32,
        };
        m.velocities.clear();
        m
    }

    #[test]
    fn position_only_messages_warm_up_then_get_velocities() {
        let cfg = SystemConfig::new(SystemKind::Spring, 5);
        let inputs = Inputs::default();
        let p = NodeParams::default();
        for k in 0..2 {
            let a = inputs
                .accept(&p, message(k, 0.01 * f64::from(k), &cfg))
                .unwrap();
            assert!(matches!(a, Accepted::WarmingUp { needs: 3, .. }), "{a:?}");
        }
        let Accepted::Ready(i) = inputs.accept(&p, message(2, 0.02, &cfg)).unwrap() else {
            panic!("not ready after 3 states");
        };
        assert!(i.derived);
        // Every position moves at 0.1 per second.
        assert!(
            i.state.v.iter().all(|v| (v - 0.1).abs() < 1e-6),
            "{:?}",
            i.state.v
        );
        assert_eq!(i.message.velocities.len(), 5);
        assert!((i.message.velocities[0].x - 0.1).abs() < 1e-6);
        // A stamp going back starts over.
        let a = inputs.accept(&p, message(3, 0.0, &cfg)).unwrap();
        assert!(
            matches!(
                a,
                Accepted::WarmingUp {
                    reset: Some(Reset::Earlier { .. }),
                    ..
                }
            ),
            "{a:?}"
        );
        // Full states pass through.
        let mut full = message(4, 0.05, &cfg);
        full.velocities = full.positions.clone();
        let Accepted::Ready(i) = inputs.accept(&p, full.clone()).unwrap() else {
            panic!("a full state is ready at once");
        };
        assert!(!i.derived);
        assert_eq!(i.message, full);
    }

    /// With `velocity_smoother: model` the node fits each position-only
    /// state through the served model: on the model's own motion the
    /// estimate is its state; without a model of the GNODE family the state
    /// is refused with the fix, never served as a poly fit.
    #[test]
    fn the_model_smoother_fits_through_the_served_model() {
        use crate::dynamics::{Dynamics, Timing};
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("bags/models/spring5-mcgnode.json");
        let model = crate::kernel::TrainedModel::load(&path).expect("shipped model");
        let cfg = SystemConfig::new(SystemKind::Spring, 5);
        let graph = cfg.graph();
        let start = cfg.start_for(&graph, 3, 0);
        let traj = model
            .rollout(&graph, &start, Timing::integration(1e-3, 300, 10))
            .expect("rollout");
        let p = NodeParams {
            velocity_smoother: "model".into(),
            smoother_window: 10,
            // Bound by iterations, not by a loaded machine's clock.
            smoother_budget: 10.0,
            dt: 0.01,
            substeps: 10,
            ..NodeParams::default()
        };
        let inputs = Inputs::default();
        let mut worst = 0.0_f64;
        for (k, s) in traj.iter().enumerate() {
            let mut m = message(k as u32, 0.0, &cfg);
            m.header.stamp = crate::data::msg::Time {
                sec: 100,
                nanosec: k as u32 * 10_000_000,
            };
            m.positions = crate::data::msg::to_vec3(&s.q, graph.dim);
            match inputs.accept_with(&p, m, Some((&model, 1))).unwrap() {
                Accepted::WarmingUp { needs, .. } => assert!(k < 9 && needs == 10, "{k}"),
                Accepted::Ready(i) => {
                    assert!(k >= 9);
                    let e = i.state.v.iter().zip(&s.v).map(|(a, b)| (a - b).abs());
                    worst = e.fold(worst, f64::max);
                }
            }
        }
        let speed = start.v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        assert!(worst < 1e-6 * speed.max(1.0), "velocity off by {worst}");
        let cost = inputs.smoother_cost().expect("fits were timed");
        assert_eq!(cost.fits, traj.len() as u64 - 9);
        assert!(cost.median_ms.is_finite() && cost.p99_ms >= cost.median_ms);
        // Without a model, or with one that has no accelerations to fit
        // through, the warm stream's state is refused with the fix.
        let refused = |model: Option<(&dyn Dynamics, u64)>| {
            let inputs = Inputs::default();
            let mut last = None;
            for (k, s) in traj.iter().take(10).enumerate() {
                let mut m = message(k as u32, 0.0, &cfg);
                m.header.stamp.nanosec = k as u32 * 10_000_000;
                m.positions = crate::data::msg::to_vec3(&s.q, graph.dim);
                last = Some(inputs.accept_with(&p, m, model));
            }
            last.unwrap().unwrap_err().to_string()
        };
        let e = refused(None);
        assert!(
            e.contains("velocity_smoother model") && e.contains("poly"),
            "{e}"
        );
        let e = refused(Some((&crate::dynamics::Still, 1)));
        assert!(e.contains("GNODE family") && e.contains("poly"), "{e}");
    }

    #[test]
    fn bad_smoother_settings_name_the_parameters() {
        let p = NodeParams {
            velocity_smoother: "poly".into(),
            smoother_window: 3,
            ..NodeParams::default()
        };
        let e = stream_options(&p).unwrap_err().to_string();
        assert!(
            e.contains("smoother_window") && e.contains("window 3"),
            "{e}"
        );
    }
}
