//! The one f64 executor of the GNODE family: the forward pass on the
//! feature-major layout, for inference ([`Forward`], one state, no loss) and
//! for training, with hand-written reverse-mode gradients (squared error on
//! accelerations → every weight and log-mass) over all cores, and
//! ([`Reverse`]) down to a state's positions and velocities for planning.
//!
//! A batch is cut into chunks by a rule that depends only on the batch size
//! and the graph, never on the thread count; each chunk's gradient is
//! computed on its own buffers and the chunks are summed in a fixed order, so
//! a seeded training gives bit-identical weights with any `--threads`.
//! Nothing is allocated per step once the buffers have grown to the largest
//! chunk. Checked against candle and finite differences (tests/engine.rs).

mod bars;
mod baseline;
mod chunk;
mod cores;
mod crew;
mod dense;
mod fused;
mod gather;
mod gns;
mod infer;
mod layout;
mod model;
mod named;
mod potential;
mod reverse;
mod samples;
mod split;

pub use baseline::BaselineExecutor;
pub use cores::all_cores;
pub use gns::{Gns, GnsSpec};
pub use infer::Forward;
pub use layout::{Layout, LayoutError};
pub use model::ExecutorModel;
pub use potential::{Potential, PotentialLoss, PotentialSpec};
pub use reverse::Reverse;
pub use samples::Samples;
pub use split::SPLIT_ROWS;

use crate::gnode::arch::Arch;
use crate::gnode::graph_plan::GraphPlan;
use crate::gnode::variant::Hyper;
use crate::system::{Graph, State};
use chunk::{Chunk, Model};
use crew::Crew;
use thiserror::Error;

/// Rows (particles + directed edges, or NODE states) a chunk aims at: enough
/// to amortise the per-layer loops, few enough to spread a batch of 100
/// small graphs over the cores.
const CHUNK_ROWS: usize = 1024;

/// Why an engine cannot be built.
#[derive(Debug, Error)]
pub enum EngineError {
    /// The graph does not suit the model.
    #[error(transparent)]
    Graph(#[from] crate::gnode::arch::ArchError),
    /// Parameters that do not fit the network.
    #[error("{0}")]
    Parameters(String),
    /// Training threads could not be started.
    #[error("cannot start {threads} training threads: {reason}")]
    Threads {
        /// Threads asked for.
        threads: usize,
        /// The system's error.
        reason: String,
    },
}

crate::error::typed_errors!(EngineError);

/// Loss and gradients of one model on states of one graph.
pub struct Engine {
    model: Model,
    /// Buffers of training's chunks, and apart from them those of the
    /// passes without gradients (validation), which record no tapes and
    /// take the inference path: a chunk would reallocate at every switch.
    chunks: Vec<Chunk>,
    eval_chunks: Vec<Chunk>,
    crew: Option<Crew>,
}

/// How a selection of `len` states of `rows` rows each (particles and
/// directed edges) is cut into chunks: a function of `len` and the graph
/// only, never of the thread count. The count is 1, 2 or a multiple of 4, so
/// that 1 and 2 threads (and 4, from 4 chunks up) share the chunks evenly.
/// Two stay two: a batch of 100 5-spring states in four chunks instead of two
/// trained about a tenth slower on two threads (each chunk zeroes and folds
/// a whole gradient, and moves its buffers between the cores).
fn split(len: usize, rows: usize) -> Vec<(usize, usize)> {
    let mut k = (len * rows).div_ceil(CHUNK_ROWS).max(1);
    if k > 2 {
        k = k.div_ceil(4) * 4;
    }
    let k = k.min(len).max(1);
    let (base, extra) = (len / k, len % k);
    let mut out = Vec::with_capacity(k);
    let mut start = 0;
    for i in 0..k {
        let size = base + usize::from(i < extra);
        out.push((start, start + size));
        start += size;
    }
    out
}

/// Runs `work` on the chunks `parts` (a chunk's buffers each), wave by wave
/// across the crew's threads, and folds the results in chunk order with
/// `fold`: the order, and so the sums, do not depend on the threads.
fn in_waves<C: Default + Send>(
    chunks: &mut Vec<C>,
    crew: Option<&Crew>,
    parts: &[(usize, usize)],
    work: impl Fn(&mut C, (usize, usize)) + Sync,
    mut fold: impl FnMut(&C),
) {
    let wave = 4 * crew.map_or(1, Crew::threads);
    for group in parts.chunks(wave) {
        if chunks.len() < group.len() {
            chunks.resize_with(group.len(), C::default);
        }
        let these = &mut chunks[..group.len()];
        match crew {
            Some(crew) => crew.for_each(these, |c, i| work(c, group[i])),
            None => these.iter_mut().zip(group).for_each(|(c, &p)| work(c, p)),
        }
        chunks[..group.len()].iter().for_each(&mut fold);
    }
}

/// A chunk's squared error and gradient, as [`mean_loss`] sums them.
trait ChunkLoss {
    fn sse(&self) -> f64;
    fn grad(&self) -> &[f64];
}

impl ChunkLoss for Chunk {
    fn sse(&self) -> f64 {
        self.sse
    }

    fn grad(&self) -> &[f64] {
        &self.grad
    }
}

/// The mean of `count` squared errors and, with `grad` (zeroed first), its
/// gradient: the chunks that `run` hands its fold, summed in their order.
fn mean_loss<C: ChunkLoss>(
    count: f64,
    mut grad: Option<&mut [f64]>,
    run: impl FnOnce(&mut dyn FnMut(&C)),
) -> f64 {
    if let Some(g) = grad.as_deref_mut() {
        g.fill(0.0);
    }
    let mut sse = 0.0;
    run(&mut |c: &C| {
        sse += c.sse();
        if let Some(g) = grad.as_deref_mut() {
            for (x, y) in g.iter_mut().zip(c.grad()) {
                *x += y;
            }
        }
    });
    sse / count
}

/// Node-major outputs (`n · d` each) of `states` states from a run over
/// all of them: `run(idx, put)` runs the states `idx` in the chunks
/// [`split`] cuts for `per_state` rows a state and hands each chunk's
/// feature-major rows (`d × nodes`) to `put`, in chunk order.
fn node_major_all(
    states: usize,
    (n, d): (usize, usize),
    per_state: usize,
    run: impl FnOnce(&[usize], &mut dyn FnMut(&[f64])),
) -> Vec<Vec<f64>> {
    let mut out = vec![vec![0.0; n * d]; states];
    let idx: Vec<usize> = (0..states).collect();
    let parts = split(states, per_state);
    let mut at = parts.iter();
    run(&idx, &mut |rows| {
        let &part = at.next().expect("one fold per chunk");
        node_major(&mut out, part, (n, d), rows);
    });
    out
}

/// The states `a..b` of `out` (node-major, `n · d` each) from a chunk's
/// feature-major rows (`d × nodes`).
fn node_major(out: &mut [Vec<f64>], (a, b): (usize, usize), (n, d): (usize, usize), rows: &[f64]) {
    let nodes = (b - a) * n;
    for (s, o) in out[a..b].iter_mut().enumerate() {
        for p in 0..n {
            for k in 0..d {
                o[p * d + k] = rows[k * nodes + s * n + p];
            }
        }
    }
}

/// The threads of an engine running on `threads` threads (none beside the
/// caller for one).
fn crew(threads: usize) -> Result<Option<Crew>, EngineError> {
    Crew::new(threads).map_err(|e| EngineError::Threads {
        threads,
        reason: e.to_string(),
    })
}

impl Engine {
    /// An engine for `hyper` on `graph`, running on `threads` threads.
    pub fn new(hyper: &Hyper, graph: &Graph, threads: usize) -> Result<Self, EngineError> {
        let arch = Arch::new(hyper);
        arch.supports(graph)?;
        let crew = crew(threads)?;
        Ok(Self {
            model: Model::new(arch, GraphPlan::new(graph)),
            chunks: vec![],
            eval_chunks: vec![],
            crew,
        })
    }

    /// Where each parameter sits in the flat vector.
    pub fn layout(&self) -> &Layout {
        &self.model.layout
    }

    /// The architecture.
    pub fn arch(&self) -> &Arch {
        &self.model.arch
    }

    /// `states` and their target accelerations (one per state, or none) as
    /// this engine reads them: packed into one record per state for graph
    /// models ([`Samples`]). Build them once per data set, not per batch.
    ///
    /// # Panics
    /// If a state or target does not fit the graph, or there are targets but
    /// not one per state.
    pub fn samples<'a>(&self, states: &'a [State], targets: &'a [Vec<f64>]) -> Samples<'a> {
        let (n, d) = (self.model.plan.n, self.model.plan.dim);
        Samples::new(n, d, self.model.arch.biases.graph, states, targets)
    }

    /// How a selection of `len` states is cut into chunks ([`split`]).
    fn split(&self, len: usize) -> Vec<(usize, usize)> {
        split(len, self.model.rows_per_state())
    }

    /// Runs the chunks of `idx` (wave by wave, each wave across the threads)
    /// and folds each chunk's results, in chunk order, with `fold`.
    fn run(
        &mut self,
        theta: &[f64],
        samples: &Samples,
        idx: &[usize],
        scale: Option<f64>,
        fold: impl FnMut(&Chunk),
    ) {
        let (n, d) = (self.model.plan.n, self.model.plan.dim);
        assert!(
            samples.laid_out_for(n, d, self.model.arch.biases.graph),
            "samples laid out for another model: make them with this engine's `samples`"
        );
        let parts = self.split(idx.len());
        let model = &self.model;
        let work = |c: &mut Chunk, (a, b): (usize, usize)| {
            c.run(model, theta, samples, &idx[a..b], scale);
        };
        let chunks = if scale.is_some() {
            &mut self.chunks
        } else {
            &mut self.eval_chunks
        };
        in_waves(chunks, self.crew.as_ref(), &parts, work, fold);
    }

    /// Mean squared error of the accelerations of states `idx` against their
    /// targets, and its gradient with respect to `theta` written to `grad`.
    ///
    /// # Panics
    /// If `samples` were not made by [`Engine::samples`] of an engine of this
    /// graph and model kind.
    pub fn loss_grad(
        &mut self,
        theta: &[f64],
        samples: &Samples,
        idx: &[usize],
        grad: &mut [f64],
    ) -> f64 {
        let count = (idx.len() * self.model.plan.free_ndof()) as f64;
        mean_loss(count, Some(grad), |fold| {
            self.run(theta, samples, idx, Some(1.0 / count), fold);
        })
    }

    /// Mean squared error of the accelerations of states `idx` (no gradient).
    pub fn loss(&mut self, theta: &[f64], samples: &Samples, idx: &[usize]) -> f64 {
        let count = (idx.len() * self.model.plan.free_ndof()) as f64;
        mean_loss(count, None, |fold| {
            self.run(theta, samples, idx, None, fold)
        })
    }

    /// Predicted accelerations of `states` (node-major, one vector each).
    pub fn accelerations(&mut self, theta: &[f64], states: &[State]) -> Vec<Vec<f64>> {
        let nd = self.model.plan.ndof();
        let mut out = vec![vec![0.0; nd]; states.len()];
        let idx: Vec<usize> = (0..states.len()).collect();
        let parts = self.split(idx.len());
        let mut at = parts.iter();
        let shape = self.model.shape();
        let samples = self.samples(states, &[]);
        self.run(theta, &samples, &idx, None, |c| {
            let &(a, b) = at.next().expect("one fold per chunk");
            for (s, o) in out[a..b].iter_mut().enumerate() {
                c.acceleration(shape, b - a, s, o);
            }
        });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Chunks cover the selection in order, differ in size by at most one
    /// state, number 1, 2 or a multiple of 4 (never more than the states)
    /// and hold about `CHUNK_ROWS` rows at most; a 100-state batch of 5 springs (15 rows each) is two chunks.
    #[test]
    fn chunks_cover_the_selection_evenly() {
        for rows in [1, 7, 15, 25, 160, 3000] {
            for len in [1, 2, 3, 5, 40, 99, 100, 512, 1000] {
                let parts = split(len, rows);
                let k = parts.len();
                assert!(
                    k == 1 || k == 2 || k % 4 == 0 || k == len,
                    "{len}×{rows}: {k}"
                );
                let at_least = (len * rows).div_ceil(CHUNK_ROWS).min(len);
                assert!(k <= len && k >= at_least, "{len}×{rows}: {k}");
                assert_eq!(parts[0].0, 0);
                assert_eq!(parts[k - 1].1, len);
                assert!(parts.windows(2).all(|w| w[0].1 == w[1].0));
                let sizes: Vec<usize> = parts.iter().map(|(a, b)| b - a).collect();
                let (lo, hi) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
                assert!(hi - lo <= 1 && *lo >= 1, "{len}×{rows}: {sizes:?}");
            }
        }
        assert_eq!(split(100, 15).len(), 2);
        assert_eq!(split(100, 25).len(), 4);
        assert_eq!(split(50, 15).len(), 1);
    }
}
