//! A trained model, loaded from its file, running on the inference kernel.

use super::{Kernel, Workspace};
use crate::dynamics::{Dynamics, DynamicsError, FlatForces, Forces, Predicted, Rollout, Timing};
use crate::error::Result;
use crate::gnode::file::ModelFile;
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

/// The workspaces of the last few graphs, kept between calls: a call on one
/// of them takes its workspace (no allocation), another graph builds its own
/// (and the least recently used beyond [`Cache::GRAPHS`] is dropped); calls
/// at the same time each get one. A node serving several streams (or a large
/// system between small ones) thus keeps each warm. These serve one rollout
/// at a time (the node's), so a large graph's edge MLPs run on two cores
/// ([`Workspace::split_rows`]).
#[derive(Debug, Default)]
struct Cache(Mutex<Vec<(Graph, Workspace)>>);

impl Clone for Cache {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl Cache {
    /// Graphs whose workspaces are kept.
    const GRAPHS: usize = 4;

    /// The workspace for `graph`: a kept one if it was made for it.
    fn take(&self, kernel: &Kernel, graph: &Graph) -> Result<(Graph, Workspace), DynamicsError> {
        let kept = self.0.lock().ok().and_then(|mut c| {
            let i = c.iter().position(|(g, _)| g == graph)?;
            Some(c.remove(i))
        });
        if let Some(kept) = kept {
            return Ok(kept);
        }
        let mut ws = kernel.workspace(graph)?;
        ws.split_rows();
        Ok((graph.clone(), ws))
    }

    /// Keeps a workspace, most recent first.
    fn put(&self, kept: (Graph, Workspace)) {
        if let Ok(mut c) = self.0.lock() {
            c.insert(0, kept);
            c.truncate(Self::GRAPHS);
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
    /// start and every state `timing` keeps. Nothing is allocated inside the loop.
    pub fn rollout_with(
        &self,
        ws: &mut Workspace,
        start: &State,
        timing: Timing,
        visit: impl FnMut(usize, &[f64], &[f64]),
    ) -> Result<(), DynamicsError> {
        match self.verlet(ws, start, timing, None, |_, _| {}, visit) {
            None => Ok(()),
            Some(step) => Err(DynamicsError::Diverged(step)),
        }
    }

    /// The loop of [`TrainedModel::rollout_with`]; `first(ws, q̈)` sees the
    /// workspace after the evaluation at the start (its forces). Returns the
    /// step at which the state became non-finite, if it did.
    fn verlet(
        &self,
        ws: &mut Workspace,
        start: &State,
        timing: Timing,
        drive: Option<&Drive>,
        first: impl FnOnce(&mut Workspace, &[f64]),
        mut visit: impl FnMut(usize, &[f64], &[f64]),
    ) -> Option<usize> {
        // The workspace's buffers, taken so that the forward pass can
        // borrow the workspace beside them.
        let [mut q, mut v, mut a] = std::mem::take(&mut ws.rollout);
        let reset = |x: &mut Vec<f64>, from: &[f64]| {
            x.clear();
            x.extend_from_slice(from);
        };
        reset(&mut q, &start.q);
        reset(&mut v, &start.v);
        a.resize(q.len(), 0.0);
        if let Some(drive) = drive {
            drive.place(0, &mut q, &mut v);
        }
        self.kernel.acceleration(ws, &q, &v, &mut a);
        first(ws, &a);
        visit(0, &q, &v);
        let diverged = self.steps(ws, (&mut q, &mut v, &mut a), timing, drive, visit);
        ws.rollout = [q, v, a];
        diverged
    }

    /// Steps 1 to `steps` of [`TrainedModel::verlet`] from (q, q̇, q̈).
    fn steps(
        &self,
        ws: &mut Workspace,
        (q, v, a): (&mut [f64], &mut [f64], &mut [f64]),
        timing: Timing,
        drive: Option<&Drive>,
        mut visit: impl FnMut(usize, &[f64], &[f64]),
    ) -> Option<usize> {
        let dt = timing.step();
        for step in 1..=timing.steps() {
            // The projector and the forward pass borrow the workspace apart
            // (taking the projector out and back copied it twice a step, 3 %
            // of a 5-spring rollout).
            let Workspace {
                forward,
                projector,
                periodic,
                ..
            } = &mut *ws;
            let place = |q: &mut [f64], v: &mut [f64]| {
                if let Some(b) = periodic {
                    b.wrap(q);
                }
                if let Some(drive) = drive {
                    drive.place(step, q, v);
                }
            };
            let accel = |q: &[f64], v: &[f64], a: &mut [f64]| {
                forward.run(&self.kernel.theta, q, v, a);
                Ok::<(), Infallible>(())
            };
            let Ok(()) = verlet::step_placed(q, v, a, dt, projector.as_mut(), place, accel);
            if q.iter().chain(v.iter()).any(|x| !x.is_finite()) {
                return Some(step);
            }
            if timing.keeps(step) {
                visit(step, q, v);
            }
        }
        None
    }
}

impl TrainedModel {
    /// The states [`TrainedModel::verlet`] visits, kept (up to the
    /// divergence, whose step comes with them).
    fn states(
        &self,
        ws: &mut Workspace,
        start: &State,
        timing: Timing,
        drive: Option<&Drive>,
        first: impl FnOnce(&mut Workspace, &[f64]),
    ) -> (Vec<State>, Option<usize>) {
        let mut out = Vec::with_capacity(timing.kept());
        let diverged = self.verlet(ws, start, timing, drive, first, |_, q, v| {
            out.push(State {
                q: q.to_vec(),
                v: v.to_vec(),
            });
        });
        (out, diverged)
    }

    /// Forces of the workspace's last evaluation, whose accelerations are
    /// `acc`, into `out` (its memory reused).
    fn forces_of(&self, ws: &mut Workspace, graph: &Graph, acc: &[f64], out: &mut FlatForces) {
        self.kernel.read_forces(ws);
        let b = self.file.hyper.variant.biases();
        out.clear();
        if b.constrained {
            out.total.extend_from_slice(&ws.force);
        } else {
            // Acceleration-predicting models: force = m q̈ with the true masses.
            let m = |i: usize| graph.masses[i / graph.dim];
            out.total
                .extend(acc.iter().enumerate().map(|(i, a)| a * m(i)));
        }
        if b.pairwise {
            out.pairs.extend(ws.edge_pairs());
            out.pair_force.extend_from_slice(&ws.edge_force);
        }
    }

    /// Checks a rollout's start, drive and step before it runs.
    fn check_rollout(
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: Option<&Drive>,
    ) -> Result<(), DynamicsError> {
        start.validate(graph)?;
        if let Some(drive) = drive {
            drive.check(graph, timing.steps())?;
        }
        timing.check()
    }

    /// A rollout on the kept workspace, its states returned.
    fn kept_rollout(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: Option<&Drive>,
    ) -> Result<Vec<State>, DynamicsError> {
        Self::check_rollout(graph, start, timing, drive)?;
        let mut kept = self.cache.take(&self.kernel, graph)?;
        let (out, diverged) = self.states(&mut kept.1, start, timing, drive, |_, _| {});
        self.cache.put(kept);
        match diverged {
            None => Ok(out),
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

    /// Message passing over the edges (bars excepted: [`crate::plan`]'s
    /// lanes leave them out).
    fn steps_copies_together(&self) -> bool {
        true
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
        let mut f = FlatForces::default();
        self.forces_of(&mut kept.1, graph, &acc, &mut f);
        self.cache.put(kept);
        Ok(f.to_forces(graph.dim))
    }

    fn rollout(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
    ) -> Result<Vec<State>, DynamicsError> {
        self.kept_rollout(graph, start, timing, None)
    }

    /// On the kept workspace, the driven particles placed before every
    /// evaluation (no allocation in the loop).
    fn rollout_driven(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: &Drive,
    ) -> Result<Vec<State>, DynamicsError> {
        self.kept_rollout(graph, start, timing, Some(drive))
    }

    /// The forces come from the rollout's first evaluation, in the same
    /// workspace: one forward pass fewer per prediction. On the graph of the
    /// last call, nothing is allocated (`out` and the workspace are reused).
    fn predict_into(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        out: &mut Predicted,
    ) -> Result<(), DynamicsError> {
        Self::check_rollout(graph, start, timing, None)?;
        let mut kept = self.cache.take(&self.kernel, graph)?;
        out.states.clear(graph.ndof());
        let (kept_states, forces) = (&mut out.states, &mut out.forces);
        let first = |ws: &mut Workspace, acc: &[f64]| self.forces_of(ws, graph, acc, forces);
        let visit = |_, q: &[f64], v: &[f64]| kept_states.push(q, v);
        let diverged = self.verlet(&mut kept.1, start, timing, None, first, visit);
        self.cache.put(kept);
        match diverged {
            None => Ok(()),
            Some(step) => Err(DynamicsError::Diverged(step)),
        }
    }

    /// One kernel rollout per start (no batching needed: the kernel has no
    /// per-call overhead), spread over the cores (each thread has its own
    /// workspace; a rollout does not depend on which thread runs it), keeping
    /// the states of a diverged one.
    fn rollout_many(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: Timing,
    ) -> Result<Vec<Rollout>, DynamicsError> {
        timing.check()?;
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
                        self.states(&mut ws, start, timing, None, |_, _| {});
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
