//! A rollout's timing in one value, so that no caller passes an integration
//! step, a step count and a stride as positional numbers (once written in two
//! orders, `(dt, horizon, substeps)` and `(dt, substeps, horizon)`).

use serde::{Deserialize, Serialize};

use super::DynamicsError;

/// How a rollout is timed: `horizon` steps of `dt` seconds after the start,
/// each integrated as `substeps` velocity-Verlet steps of `dt / substeps`,
/// keeping the start and every `keep_every`-th of the `dt` steps.
///
/// The node's prediction is [`Timing::new`]`(dt, substeps, horizon)`: one
/// state per `dt`. An integrator's own terms (`steps` steps of `h`, keeping
/// every `every`-th) are [`Timing::integration`]. A planner's control step is
/// `dt`, its horizon counted in control steps.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Seconds between the steps counted by `horizon` (a prediction or
    /// control step).
    pub dt: f64,
    /// Integration steps per `dt` (at least 1; 0 reads as 1).
    pub substeps: usize,
    /// Steps of `dt` after the start.
    pub horizon: usize,
    /// Keep one state every this many steps of `dt` (0 reads as 1).
    pub keep_every: usize,
}

impl Timing {
    /// One state per `dt` for `horizon` steps, integrated with `dt / substeps`.
    pub fn new(dt: f64, substeps: usize, horizon: usize) -> Self {
        Timing {
            dt,
            substeps,
            horizon,
            keep_every: 1,
        }
    }

    /// `steps` integration steps of `step` seconds, keeping the start and
    /// every `every`-th state.
    pub fn integration(step: f64, steps: usize, every: usize) -> Self {
        Timing {
            dt: step,
            substeps: 1,
            horizon: steps,
            keep_every: every,
        }
    }

    /// `horizon` steps of `substeps` integration steps of `step` seconds
    /// (so `dt = step · substeps`), one state kept per `dt`: a planner's
    /// terms, whose users give the integration step.
    pub fn of_step(step: f64, substeps: usize, horizon: usize) -> Self {
        Timing::new(step * substeps.max(1) as f64, substeps, horizon)
    }

    /// The same timing with another horizon.
    #[must_use]
    pub fn with_horizon(self, horizon: usize) -> Self {
        Timing { horizon, ..self }
    }

    /// The integration step, `dt / substeps`, seconds.
    pub fn step(&self) -> f64 {
        // As a float division of dt, so a node's step is bit for bit the one
        // a caller computing `dt / substeps` gets.
        self.dt / self.substeps() as f64
    }

    /// Integration steps per `dt`, at least 1.
    pub fn substeps(&self) -> usize {
        self.substeps.max(1)
    }

    /// Integration steps in all: `horizon · substeps`.
    pub fn steps(&self) -> usize {
        self.horizon.saturating_mul(self.substeps())
    }

    /// Integration steps between kept states: `keep_every · substeps`.
    pub fn stride(&self) -> usize {
        self.keep_every.max(1).saturating_mul(self.substeps())
    }

    /// States a rollout keeps, the start included.
    pub fn kept(&self) -> usize {
        self.steps() / self.stride() + 1
    }

    /// Seconds between kept states.
    pub fn kept_dt(&self) -> f64 {
        self.dt * self.keep_every.max(1) as f64
    }

    /// Whether integration step `k` (from 1) is kept.
    pub fn keeps(&self, k: usize) -> bool {
        k % self.stride() == 0
    }

    /// Refuses a step that is not positive and finite.
    pub fn check(&self) -> Result<(), DynamicsError> {
        let h = self.step();
        if self.dt.is_finite() && self.dt > 0.0 && h > 0.0 {
            Ok(())
        } else {
            Err(DynamicsError::TimeStep(self.dt))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_node_and_the_integrator_count_alike() {
        let node = Timing::new(0.1, 10, 20);
        assert_eq!((node.steps(), node.stride(), node.kept()), (200, 10, 21));
        assert_eq!(node.step().to_bits(), (0.1_f64 / 10.0).to_bits());
        let fine = Timing::integration(1e-3, 2001, 100);
        assert_eq!((fine.steps(), fine.stride(), fine.kept()), (2001, 100, 21));
        assert_eq!(fine.step().to_bits(), 1e-3_f64.to_bits());
        assert!(fine.keeps(2000) && !fine.keeps(2001));
        assert!((Timing::integration(0.5, 10, 4).kept_dt() - 2.0).abs() < 1e-15);
    }

    #[test]
    fn zero_counts_read_as_one_and_bad_steps_are_refused() {
        let t = Timing {
            dt: 0.01,
            substeps: 0,
            horizon: 3,
            keep_every: 0,
        };
        assert_eq!((t.steps(), t.stride()), (3, 1));
        for dt in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(Timing::new(dt, 1, 1).check().is_err(), "{dt}");
        }
        assert!(Timing::new(1e-3, 7, 1).check().is_ok());
    }
}
