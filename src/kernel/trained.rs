//! A trained model, loaded from its file, running on the inference kernel.

use super::{Kernel, Workspace};
use crate::dynamics::{Dynamics, DynamicsError, EdgeForce, Forces, Rollout};
use crate::error::Result;
use crate::model::file::ModelFile;
use crate::physics::{verlet, Drive};
use crate::system::{Graph, State};
use std::convert::Infallible;
use std::path::Path;
use std::sync::Mutex;

/// A trained model ready for rollouts and serving.
#[derive(Clone, Debug)]
pub struct TrainedModel {
    /// The file it came from (metadata and weights).
    pub file: ModelFile,
    /// The forward kernel built from its weights.
    pub kernel: Kernel,
    /// The last graph's workspace, for the next call on the same graph (the
    /// node predicts state after state of one system).
    cache: Cache,
}

/// A graph and its workspace, kept between calls: a call on the same graph
/// takes it (no allocation), another graph builds its own; calls at the same
/// time each get one.
#[derive(Debug, Default)]
struct Cache(Mutex<Option<(Graph, Workspace)>>);

impl Clone for Cache {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl Cache {
    /// The workspace for `graph`: the kept one if it was made for it.
    fn take(&self, kernel: &Kernel, graph: &Graph) -> Result<(Graph, Workspace), DynamicsError> {
        let kept = self.0.lock().ok().and_then(|mut c| c.take());
        match kept {
            Some((g, ws)) if g == *graph => Ok((g, ws)),
            _ => Ok((graph.clone(), kernel.workspace(graph)?)),
        }
    }

    fn put(&self, kept: (Graph, Workspace)) {
        if let Ok(mut c) = self.0.lock() {
            *c = Some(kept);
        }
    }
}

impl TrainedModel {
    /// Loads a model file and builds its kernel.
    pub fn load(path: &Path) -> Result<Self> {
        Self::from_file(ModelFile::load(path)?)
    }

    /// Builds the kernel of an in-memory model file.
    pub fn from_file(file: ModelFile) -> Result<Self> {
        let kernel = Kernel::new(&file.hyper, &file.weights)?;
        Ok(Self {
            file,
            kernel,
            cache: Cache::default(),
        })
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
        match self.verlet(ws, start, dt, steps, every, None, |_, _| {}, visit) {
            None => Ok(()),
            Some(step) => Err(DynamicsError::Diverged(step)),
        }
    }

    /// The loop of [`TrainedModel::rollout_with`]; `first(ws, q̈)` sees the
    /// workspace after the evaluation at the start (its forces). Returns the
    /// step at which the state became non-finite, if it did.
    #[allow(clippy::too_many_arguments)]
    fn verlet(
        &self,
        ws: &mut Workspace,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
        drive: Option<&Drive>,
        first: impl FnOnce(&mut Workspace, &[f64]),
        mut visit: impl FnMut(usize, &[f64], &[f64]),
    ) -> Option<usize> {
        let d = start.q.len();
        let mut q = start.q.clone();
        let mut v = start.v.clone();
        if let Some(drive) = drive {
            drive.place(0, &mut q, &mut v);
        }
        let mut a = vec![0.0; d];
        self.kernel.acceleration(ws, &q, &v, &mut a);
        first(ws, &a);
        visit(0, &q, &v);
        let every = every.max(1);
        for step in 1..=steps {
            // The projector and the forward pass borrow the workspace apart.
            let mut projector = ws.projector.take();
            let place = |q: &mut [f64], v: &mut [f64]| {
                if let Some(drive) = drive {
                    drive.place(step, q, v);
                }
            };
            let accel = |q: &[f64], v: &[f64], a: &mut [f64]| {
                self.kernel.acceleration(ws, q, v, a);
                Ok::<(), Infallible>(())
            };
            let Ok(()) =
                verlet::step_placed(&mut q, &mut v, &mut a, dt, projector.as_mut(), place, accel);
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

impl TrainedModel {
    /// The states [`TrainedModel::verlet`] visits, kept (up to the
    /// divergence, whose step comes with them).
    #[allow(clippy::too_many_arguments)]
    fn states(
        &self,
        ws: &mut Workspace,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
        drive: Option<&Drive>,
        first: impl FnOnce(&mut Workspace, &[f64]),
    ) -> (Vec<State>, Option<usize>) {
        let mut out = Vec::with_capacity(steps / every.max(1) + 1);
        let diverged = self.verlet(ws, start, dt, steps, every, drive, first, |_, q, v| {
            out.push(State {
                q: q.to_vec(),
                v: v.to_vec(),
            });
        });
        (out, diverged)
    }

    /// Forces of the workspace's last evaluation, whose accelerations are `acc`.
    fn forces_of(&self, ws: &mut Workspace, graph: &Graph, acc: &[f64]) -> Forces {
        self.kernel.read_forces(ws);
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
            ws.edge_pairs()
                .zip(ws.edge_force.chunks(d))
                .map(|((a, b), f)| EdgeForce {
                    a,
                    b,
                    force: f.to_vec(),
                })
                .collect()
        } else {
            vec![]
        };
        Forces { total, edges }
    }

    /// A rollout on the kept workspace, with the forces of its first
    /// evaluation when `forces` is set.
    #[allow(clippy::too_many_arguments)]
    fn rollout_and_forces(
        &self,
        graph: &Graph,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
        drive: Option<&Drive>,
        forces: bool,
    ) -> Result<(Vec<State>, Option<Forces>), DynamicsError> {
        start.validate(graph)?;
        if let Some(drive) = drive {
            drive.check(graph, steps)?;
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(DynamicsError::TimeStep(dt));
        }
        let mut kept = self.cache.take(&self.kernel, graph)?;
        let mut f = None;
        let first = |ws: &mut Workspace, acc: &[f64]| {
            if forces {
                f = Some(self.forces_of(ws, graph, acc));
            }
        };
        let (out, diverged) = self.states(&mut kept.1, start, dt, steps, every, drive, first);
        self.cache.put(kept);
        match diverged {
            None => Ok((out, f)),
            Some(step) => Err(DynamicsError::Diverged(step)),
        }
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

    fn state_gradient(
        &self,
        graph: &Graph,
    ) -> Result<Option<Box<dyn crate::dynamics::StateGradient>>, DynamicsError> {
        Ok(Some(Box::new(self.kernel.gradient(graph)?)))
    }

    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        state.validate(graph)?;
        if out.len() != graph.ndof() {
            return Err(DynamicsError::OutputSize {
                got: out.len(),
                need: graph.ndof(),
            });
        }
        let mut kept = self.cache.take(&self.kernel, graph)?;
        self.kernel
            .acceleration(&mut kept.1, &state.q, &state.v, out);
        self.cache.put(kept);
        Ok(())
    }

    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError> {
        state.validate(graph)?;
        let mut kept = self.cache.take(&self.kernel, graph)?;
        let mut acc = vec![0.0; graph.ndof()];
        self.kernel
            .acceleration(&mut kept.1, &state.q, &state.v, &mut acc);
        let f = self.forces_of(&mut kept.1, graph, &acc);
        self.cache.put(kept);
        Ok(f)
    }

    fn rollout_every(
        &self,
        graph: &Graph,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<Vec<State>, DynamicsError> {
        Ok(self
            .rollout_and_forces(graph, start, dt, steps, every, None, false)?
            .0)
    }

    /// On the kept workspace, the driven particles placed before every
    /// evaluation (no allocation in the loop).
    fn rollout_driven(
        &self,
        graph: &Graph,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
        drive: &Drive,
    ) -> Result<Vec<State>, DynamicsError> {
        Ok(self
            .rollout_and_forces(graph, start, dt, steps, every, Some(drive), false)?
            .0)
    }

    /// The forces come from the rollout's first evaluation, in the same
    /// workspace: one forward pass fewer per prediction.
    fn rollout_with_forces(
        &self,
        graph: &Graph,
        start: &State,
        dt: f64,
        steps: usize,
        every: usize,
    ) -> Result<(Vec<State>, Forces), DynamicsError> {
        let (states, forces) =
            self.rollout_and_forces(graph, start, dt, steps, every, None, true)?;
        Ok((states, forces.unwrap_or_default()))
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
                    let (states, diverged_at) =
                        self.states(&mut ws, start, dt, steps, every, None, |_, _| {});
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
