//! What [`fit`](mod@super::fit) minimises: the [`Objective`] trait, with candle's
//! autodiff and the hand-written engine behind it.

use crate::engine::{BaselineExecutor, Engine, ExecutorModel, Samples};
use crate::error::{bail, Result};
use crate::gnode::params::ParamStore;
use crate::system::State;
use candle_core::Tensor;
use rayon::prelude::*;

/// What [`fit`](mod@super::fit) minimises: a mean loss over samples, with its gradient, as a
/// function of one flat parameter vector.
pub trait Objective {
    /// Mean loss over the samples `idx` at `theta`, its gradient written to `grad`.
    fn loss_grad(&mut self, theta: &[f64], idx: &[usize], grad: &mut [f64]) -> Result<f64>;
    /// Mean loss over the samples `idx` at `theta`.
    fn loss(&mut self, theta: &[f64], idx: &[usize]) -> Result<f64>;
}

/// The parameters of a candle store as one flat vector, in definition order.
pub fn flat_params(store: &ParamStore) -> Result<Vec<f64>> {
    let mut out = vec![];
    for v in store.vars() {
        out.extend(v.as_tensor().flatten_all()?.to_vec1::<f64>()?);
    }
    Ok(out)
}

/// Sets a candle store's parameters from a flat vector (definition order).
pub fn set_flat_params(store: &ParamStore, theta: &[f64]) -> Result<()> {
    let mut at = 0;
    for v in store.vars() {
        let n = v.elem_count();
        v.set(&Tensor::from_vec(
            theta[at..at + n].to_vec(),
            v.shape(),
            v.device(),
        )?)?;
        at += n;
    }
    if at != theta.len() {
        bail!("{} parameters given, the model has {at}", theta.len());
    }
    Ok(())
}

/// A candle loss `loss(indices)` over a store, differentiated by candle's
/// autodiff: the reference engine, and the one the baselines use. With more
/// than one thread, a batch is cut into one chunk per thread whose gradients
/// are summed in order (so results depend on the thread count only through
/// rounding); candle itself runs each chunk on one thread.
pub struct CandleObjective<'a, F> {
    store: &'a ParamStore,
    loss: F,
    pool: Option<rayon::ThreadPool>,
    threads: usize,
}

impl<'a, F: Fn(&[usize]) -> Result<Tensor> + Sync> CandleObjective<'a, F> {
    /// The objective of `loss` on `store`'s parameters, on one thread.
    pub fn new(store: &'a ParamStore, loss: F) -> Self {
        Self {
            store,
            loss,
            pool: None,
            threads: 1,
        }
    }

    /// The same, with batches cut over `threads` threads.
    pub fn with_threads(store: &'a ParamStore, loss: F, threads: usize) -> Result<Self> {
        let threads = threads.max(1);
        let pool = if threads > 1 {
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()?,
            )
        } else {
            None
        };
        Ok(Self {
            store,
            loss,
            pool,
            threads,
        })
    }

    /// Mean loss and its gradient over one chunk.
    fn chunk(&self, idx: &[usize], with_grad: bool) -> Result<(f64, Vec<f64>)> {
        let l = (self.loss)(idx)?;
        let value = l.to_scalar::<f64>()?;
        let mut out = vec![];
        if with_grad {
            let grads = l.backward()?;
            for var in self.store.vars() {
                match grads.get(&var) {
                    Some(g) => out.extend(g.flatten_all()?.to_vec1::<f64>()?),
                    // Parameters the loss does not read have no gradient.
                    None => out.extend(std::iter::repeat_n(0.0, var.elem_count())),
                }
            }
        }
        Ok((value, out))
    }

    /// The chunks of `idx` (at most `max` samples each, at least one per
    /// thread when there are enough), evaluated in order.
    fn chunks(
        &self,
        idx: &[usize],
        max: usize,
        with_grad: bool,
    ) -> Result<Vec<(usize, f64, Vec<f64>)>> {
        let size = idx.len().div_ceil(self.threads).clamp(1, max);
        let parts: Vec<&[usize]> = idx.chunks(size).collect();
        let run = |c: &&[usize]| -> Result<(usize, f64, Vec<f64>)> {
            let (l, g) = self.chunk(c, with_grad)?;
            Ok((c.len(), l, g))
        };
        match &self.pool {
            Some(pool) if parts.len() > 1 => pool.install(|| parts.par_iter().map(run).collect()),
            _ => parts.iter().map(run).collect(),
        }
    }
}

impl<F: Fn(&[usize]) -> Result<Tensor> + Sync> Objective for CandleObjective<'_, F> {
    fn loss_grad(&mut self, theta: &[f64], idx: &[usize], grad: &mut [f64]) -> Result<f64> {
        set_flat_params(self.store, theta)?;
        let n = idx.len() as f64;
        let parts = self.chunks(idx, usize::MAX, true)?;
        if let [(_, l, g)] = parts.as_slice() {
            grad.copy_from_slice(g);
            return Ok(*l);
        }
        grad.fill(0.0);
        let mut total = 0.0;
        for (len, l, g) in parts {
            let w = len as f64 / n;
            total += l * w;
            for (x, y) in grad.iter_mut().zip(&g) {
                *x += y * w;
            }
        }
        Ok(total)
    }

    fn loss(&mut self, theta: &[f64], idx: &[usize]) -> Result<f64> {
        set_flat_params(self.store, theta)?;
        let total: f64 = self
            .chunks(idx, 1000, false)?
            .iter()
            .map(|(len, l, _)| l * *len as f64)
            .sum();
        Ok(total / idx.len() as f64)
    }
}

/// The hand-written engine on one graph's states and target accelerations.
pub struct EngineObjective<'a> {
    engine: &'a mut Engine,
    samples: Samples<'a>,
}

impl<'a> EngineObjective<'a> {
    /// The objective of `engine` on these states and targets (one per
    /// state), laid out for it once.
    pub fn new(engine: &'a mut Engine, states: &'a [State], targets: &'a [Vec<f64>]) -> Self {
        let samples = engine.samples(states, targets);
        Self { engine, samples }
    }
}

impl Objective for EngineObjective<'_> {
    fn loss_grad(&mut self, theta: &[f64], idx: &[usize], grad: &mut [f64]) -> Result<f64> {
        Ok(self.engine.loss_grad(theta, &self.samples, idx, grad))
    }

    fn loss(&mut self, theta: &[f64], idx: &[usize]) -> Result<f64> {
        Ok(self.engine.loss(theta, &self.samples, idx))
    }
}

/// A baseline on the executor ([`BaselineExecutor`]) on one graph's states
/// and target accelerations.
pub struct BaselineObjective<'a> {
    exec: BaselineExecutor,
    samples: Samples<'a>,
}

impl<'a> BaselineObjective<'a> {
    /// The objective of `exec` on these states and targets (one per state),
    /// laid out for it once.
    pub fn new(exec: BaselineExecutor, states: &'a [State], targets: &'a [Vec<f64>]) -> Self {
        let samples = exec.samples(states, targets);
        Self { exec, samples }
    }
}

impl Objective for BaselineObjective<'_> {
    fn loss_grad(&mut self, theta: &[f64], idx: &[usize], grad: &mut [f64]) -> Result<f64> {
        Ok(self.exec.loss_grad(theta, &self.samples, idx, grad))
    }

    fn loss(&mut self, theta: &[f64], idx: &[usize]) -> Result<f64> {
        Ok(self.exec.loss(theta, &self.samples, idx))
    }
}
