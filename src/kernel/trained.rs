//! A trained model, loaded from its file, running on the inference kernel.

use super::{Kernel, Workspace};
use crate::dynamics::{Dynamics, DynamicsError, EdgeForce, Forces, Rollout};
use crate::error::Result;
use crate::model::file::ModelFile;
use crate::physics::verlet;
use crate::system::{Graph, State};
use std::convert::Infallible;
use std::path::Path;

/// A trained model ready for rollouts and serving.
#[derive(Clone, Debug)]
pub struct TrainedModel {
    /// The file it came from (metadata and weights).
    pub file: ModelFile,
    /// The forward kernel built from its weights.
    pub kernel: Kernel,
}

impl TrainedModel {
    /// Loads a model file and builds its kernel.
    pub fn load(path: &Path) -> Result<Self> {
        Self::from_file(ModelFile::load(path)?)
    }

    /// Builds the kernel of an in-memory model file.
    pub fn from_file(file: ModelFile) -> Result<Self> {
        let kernel = Kernel::new(&file.hyper, &file.weights)?;
        Ok(Self { file, kernel })
    }

    /// Velocity-Verlet rollout on the kernel (with SHAKE/RATTLE onto the bars,
    /// using the learned masses, for constrained models), calling `visit(step, q, v)` for the
    /// start and every `every`-th step. Nothing is allocated inside the loop.
    pub fn rollout_with(
        &self,
        ws: &mut Workspace,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
        visit: impl FnMut(usize, &[f64], &[f64]),
    ) -> Result<(), DynamicsError> {
        match self.verlet(ws, start, dt, steps, every, visit) {
            None => Ok(()),
            Some(step) => Err(DynamicsError::Diverged(step)),
        }
    }

    /// The loop of [`TrainedModel::rollout_with`]; returns the step at which
    /// the state became non-finite, if it did.
    fn verlet(
        &self,
        ws: &mut Workspace,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
        mut visit: impl FnMut(usize, &[f64], &[f64]),
    ) -> Option<usize> {
        let d = start.q.len();
        let mut q = start.q.clone();
        let mut v = start.v.clone();
        let mut a = vec![0.0; d];
        self.kernel.acceleration(ws, &q, &v, &mut a);
        visit(0, &q, &v);
        let every = every.max(1);
        for step in 1..=steps {
            // The projector and the forward pass borrow the workspace apart.
            let mut projector = ws.projector.take();
            let Ok(()) = verlet::step(&mut q, &mut v, &mut a, dt, projector.as_mut(), |q, v, a| {
                self.kernel.acceleration(ws, q, v, a);
                Ok::<(), Infallible>(())
            });
            ws.projector = projector;
            if q.iter().chain(&v).any(|x| !x.is_finite()) {
                return Some(step);
            }
            if step % every == 0 {
                visit(step, &q, &v);
            }
        }
        None
    }
}

impl Dynamics for TrainedModel {
    fn describe(&self) -> String {
        let t = &self.file.trained_on;
        format!(
            "{} trained on {}-particle {} ({} epochs, validation MSE {:.3e})",
            self.file.hyper.variant,
            t.particles,
            if t.system.is_empty() {
                "system"
            } else {
                &t.system
            },
            self.file.training.epochs_run,
            self.file.training.validation_loss
        )
    }

    fn supports(&self, graph: &Graph) -> Result<(), DynamicsError> {
        Ok(self.kernel.supports(graph)?)
    }

    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        let mut ws = self.kernel.workspace(graph)?;
        state.validate(graph)?;
        if out.len() != graph.ndof() {
            return Err(DynamicsError::OutputSize {
                got: out.len(),
                need: graph.ndof(),
            });
        }
        self.kernel.acceleration(&mut ws, &state.q, &state.v, out);
        Ok(())
    }

    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError> {
        let mut ws = self.kernel.workspace(graph)?;
        state.validate(graph)?;
        let mut acc = vec![0.0; graph.ndof()];
        self.kernel
            .acceleration(&mut ws, &state.q, &state.v, &mut acc);
        self.kernel.read_forces(&mut ws);
        let b = self.file.hyper.variant.biases();
        let total = if b.constrained {
            ws.force.clone()
        } else {
            // Acceleration-predicting models: force = m q̈ with the true masses.
            acc.iter()
                .enumerate()
                .map(|(i, a)| a * graph.masses[i / graph.dim])
                .collect()
        };
        let d = graph.dim;
        let edges = if b.pairwise {
            (0..ws.plan().n_edges())
                .map(|e| EdgeForce {
                    a: ws.plan().recv[e],
                    b: ws.plan().send[e],
                    force: ws.edge_force[e * d..(e + 1) * d].to_vec(),
                })
                .collect()
        } else {
            vec![]
        };
        Ok(Forces { total, edges })
    }

    fn rollout_every(
        &self,
        graph: &Graph,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<Vec<State>, DynamicsError> {
        let mut ws = self.kernel.workspace(graph)?;
        start.validate(graph)?;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(DynamicsError::TimeStep(dt));
        }
        let mut out = Vec::with_capacity(steps / every.max(1) + 1);
        self.rollout_with(&mut ws, start, dt, steps, every, |_, q, v| {
            out.push(State {
                q: q.to_vec(),
                v: v.to_vec(),
            })
        })?;
        Ok(out)
    }

    /// One kernel rollout per start (no batching needed: the kernel has no
    /// per-call overhead), spread over the cores (each thread has its own
    /// workspace; a rollout does not depend on which thread runs it), keeping
    /// the states of a diverged one.
    fn rollout_many(
        &self,
        graph: &Graph,
        starts: &[State],
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<Vec<Rollout>, DynamicsError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(DynamicsError::TimeStep(dt));
        }
        let ws = self.kernel.workspace(graph)?;
        for start in starts {
            start.validate(graph)?;
        }
        let threads = crate::engine::all_cores().min(starts.len()).max(1);
        let per = starts.len().div_ceil(threads).max(1);
        let run = |group: &[State]| -> Vec<Rollout> {
            let mut ws = ws.clone();
            group
                .iter()
                .map(|start| {
                    let mut states = Vec::with_capacity(steps / every.max(1) + 1);
                    let diverged_at = self.verlet(&mut ws, start, dt, steps, every, |_, q, v| {
                        states.push(State {
                            q: q.to_vec(),
                            v: v.to_vec(),
                        })
                    });
                    Rollout {
                        states,
                        diverged_at,
                    }
                })
                .collect()
        };
        if threads == 1 {
            return Ok(run(starts));
        }
        let groups: Vec<Vec<Rollout>> = std::thread::scope(|s| {
            let handles: Vec<_> = starts
                .chunks(per)
                .map(|g| s.spawn(move || run(g)))
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().map_err(|_| DynamicsError::ThreadPanicked))
                .collect::<Result<_, DynamicsError>>()
        })?;
        Ok(groups.into_iter().flatten().collect())
    }
}
