//! Ground-truth trajectories of a [`SystemConfig`]: its starts integrated
//! by the exact simulator, one trajectory or a set on all cores.

use super::config::SystemConfig;
use super::drive::Drive;
use super::integrator::Integrator;
use super::PhysicsError;
use crate::system::{Graph, Sample, State, Trajectory};

impl SystemConfig {
    /// One trajectory from `start`: `states` samples, `save_every` steps of
    /// `dt` apart (t = k·save_every·dt), each with its exact constrained
    /// acceleration.
    ///
    /// # Panics
    /// If the configuration, graph or start is invalid; use
    /// [`SystemConfig::try_simulate_one`] for a `Result`.
    pub fn simulate_one(&self, graph: &Graph, start: State, id: u32) -> Trajectory {
        self.try_simulate_one(graph, start, id)
            .unwrap_or_else(|e| panic!("simulate_one: {e}"))
    }

    /// [`SystemConfig::simulate_one`], returning invalid input as an error.
    pub fn try_simulate_one(
        &self,
        graph: &Graph,
        start: State,
        id: u32,
    ) -> Result<Trajectory, PhysicsError> {
        self.try_simulate_driven(graph, start, None, id)
    }

    /// [`SystemConfig::try_simulate_one`] with the kinematic particles moved
    /// along `drive` (which must cover the trajectory's steps).
    pub fn try_simulate_driven(
        &self,
        graph: &Graph,
        start: State,
        drive: Option<Drive>,
        id: u32,
    ) -> Result<Trajectory, PhysicsError> {
        self.validate()?;
        let k_c = self.contact_stiffness;
        let mut it = match drive {
            Some(d) => {
                let steps = self.save_every * self.states.saturating_sub(1);
                d.check(graph, steps)
                    .map_err(|e| PhysicsError::Drive(e.to_string()))?;
                Integrator::driven(graph, &self.field, k_c, self.dt, start, d)?
            }
            None => Integrator::with_contacts(graph, &self.field, k_c, self.dt, start)?,
        };
        let mut samples = Vec::with_capacity(self.states);
        for k in 0..self.states {
            if k > 0 {
                it.advance(self.save_every);
            }
            let state = it.state().clone();
            samples.push(Sample {
                t: (k * self.save_every) as f64 * self.dt,
                acc: Some(it.exact_acceleration()),
                state,
            });
        }
        if let Some(bad) = samples
            .iter()
            .position(|s| s.state.validate(graph).is_err())
        {
            return Err(PhysicsError::Diverged { id, sample: bad });
        }
        Ok(Trajectory {
            id,
            system: self.kind.name().to_string(),
            graph: graph.clone(),
            samples,
        })
    }

    /// `trajectories` trajectories with ids 0.., trajectory i starting from
    /// [`SystemConfig::start_for`]`(graph, seed, i)`. Runs on all cores; the
    /// result does not depend on how many.
    ///
    /// # Panics
    /// If the configuration is invalid; use [`SystemConfig::try_simulate`].
    pub fn simulate(&self, trajectories: usize, seed: u64) -> Vec<Trajectory> {
        self.try_simulate(trajectories, seed)
            .unwrap_or_else(|e| panic!("simulate: {e}"))
    }

    /// [`SystemConfig::simulate`], returning invalid input as an error.
    pub fn try_simulate(
        &self,
        trajectories: usize,
        seed: u64,
    ) -> Result<Vec<Trajectory>, PhysicsError> {
        self.validate()?;
        if trajectories > u32::MAX as usize {
            return Err(PhysicsError::TooManyTrajectories(trajectories));
        }
        let graph = self.graph();
        let threads = std::thread::available_parallelism()
            .map_or(1, std::num::NonZero::get)
            .min(trajectories.max(1));
        let run = |i: usize| {
            let start = self.start_for(&graph, seed, i);
            self.try_simulate_driven(&graph, start, self.drive_for(seed, i), i as u32)
        };
        let mut out: Vec<Option<Result<Trajectory, PhysicsError>>> = vec![None; trajectories];
        std::thread::scope(|s| {
            // Strided split: trajectory i goes to thread i % threads.
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    let run = &run;
                    s.spawn(move || {
                        (t..trajectories)
                            .step_by(threads)
                            .map(|i| (i, run(i)))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            for h in handles {
                // A panicked worker is reported below as missing trajectories.
                if let Ok(v) = h.join() {
                    for (i, r) in v {
                        out[i] = Some(r);
                    }
                }
            }
        });
        out.into_iter()
            .enumerate()
            .map(|(i, r)| r.unwrap_or(Err(PhysicsError::WorkerPanicked(i))))
            .collect()
    }
}
