//! Inference on the engine: the training engine's forward pass over one
//! state (no gradient record beyond the activations the forward keeps, every
//! buffer allocated once per graph), with its results read off node-major.
//! This is what rollouts, the node and the bench run, so the GNODE family's
//! equations exist once outside candle.

use super::chunk::{Chunk, Model};
use crate::gnode::arch::{Arch, Decoder};
use crate::gnode::graph_plan::GraphPlan;
use std::sync::Arc;

/// One graph's forward pass and its buffers.
#[derive(Clone, Debug)]
pub struct Forward {
    model: Model,
    chunk: Chunk,
    /// The parameters of the last run, kept alive so that their address
    /// names them: values that read the parameters alone are kept while
    /// the same ones come back.
    params: Option<Arc<[f64]>>,
}

impl Forward {
    /// Buffers for `plan` under `arch` (whose support of the graph the caller
    /// has checked).
    pub fn new(arch: Arch, plan: GraphPlan) -> Self {
        let model = Model::new(arch, plan);
        let mut chunk = Chunk::default();
        // Sizes every buffer now, so that the first step allocates nothing.
        chunk.reserve_one(&model);
        Self {
            model,
            chunk,
            params: None,
        }
    }

    /// From now on, runs the edge MLPs of large graphs (over 1,024 directed
    /// edges) on two cores: a helper thread, started on first need and kept
    /// with these buffers, takes half of each one's rows (the same bits).
    /// For one rollout at a time; a clone does not split.
    pub fn split_rows(&mut self) {
        self.chunk.split.enable();
    }

    /// The graph as the engine sees it.
    pub fn plan(&self) -> &GraphPlan {
        &self.model.plan
    }

    /// Accelerations at (q, v) under the parameters `theta`, node-major into
    /// `acc`; kinematic particles' are 0 (their motion is given, not
    /// predicted: held at their velocity unless a caller moves them).
    pub fn run(&mut self, theta: &Arc<[f64]>, q: &[f64], v: &[f64], acc: &mut [f64]) {
        let same = self.params.as_ref().is_some_and(|p| Arc::ptr_eq(p, theta));
        if !same {
            self.params = Some(Arc::clone(theta));
        }
        self.chunk.forward_one(&self.model, theta, q, v, same);
        self.chunk.acceleration(self.model.shape(), 1, 0, acc);
        let plan = &self.model.plan;
        if !plan.kinematic.is_empty() {
            for (i, a) in acc.chunks_mut(plan.dim).enumerate() {
                if plan.is_kinematic(i) {
                    a.fill(0.0);
                }
            }
        }
    }

    /// The decoded forces of the last [`Forward::run`] (constrained models:
    /// the N of q̈ = M⁻¹(N − Aᵀλ)), node-major into `out` (`n·d`).
    pub fn forces(&self, out: &mut [f64]) {
        let (n, d) = (self.model.plan.n, self.model.plan.dim);
        let f = self.chunk.decoded();
        for i in 0..n {
            for c in 0..d {
                out[i * d + c] = f[c * n + i];
            }
        }
    }

    /// The undirected edges of the last [`Forward::run`], fixed then contact,
    /// as (a, b) particle pairs: what [`Forward::edge_forces`] is indexed by.
    pub fn edge_pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let (recv, send) = self.chunk.laid_edges();
        let half = recv.len() / 2;
        recv[..half]
            .iter()
            .copied()
            .zip(send[..half].iter().copied())
    }

    /// Pairwise forces of the last [`Forward::run`] (pairwise decoders; else
    /// `out` is emptied): `out[e·d + c]` on `a` due to `b` of the `e`-th of
    /// [`Forward::edge_pairs`]. These are the terms the decoder sums into
    /// [`Forward::forces`]. `out` is resized (it allocates only when a state
    /// has more edges than any before).
    pub fn edge_forces(&self, out: &mut Vec<f64>) {
        out.clear();
        if !matches!(self.model.arch.decoder, Decoder::Pairwise { .. }) {
            return;
        }
        let (d, ne) = (self.model.plan.dim, self.chunk.laid_edges().0.len());
        let (half, k) = (ne / 2, self.model.arch.norm.out_scale);
        out.resize(half * d, 0.0);
        let fe = self.chunk.edge_outputs();
        for e in 0..half {
            for c in 0..d {
                out[e * d + c] = (fe[c * ne + e] - fe[c * ne + e + half]) * 0.5 * k;
            }
        }
    }
}
