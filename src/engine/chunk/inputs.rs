//! What the passes read: the node inputs of each state (one-hot, q, q̇,
//! raw and scaled) and the targets, from node-major slices or from the
//! packed records of [`Samples`].

use super::{widest, Chunk, Model};
use crate::engine::dense::{simd, Simd};
use crate::engine::gather::copy_row;
use crate::engine::samples::Samples;

impl Chunk {
    pub(super) fn fill_flat_inputs(&mut self, m: &Model, samples: &Samples, idx: &[usize]) {
        let bs = idx.len();
        let nd = m.plan.n * m.plan.dim;
        let (states, targets) = (samples.states(), samples.targets());
        samples.ask_for(idx);
        for (s, &k) in idx.iter().enumerate() {
            self.put_flat_state(m, s, bs, &states[k].q, &states[k].v);
            if let Some(t) = targets.get(k) {
                for (f, x) in t[..nd].iter().enumerate() {
                    self.tgt[f * bs + s] = *x;
                }
            }
        }
    }

    /// NODE's scaled (q, q̇) of state `s` of `bs`.
    pub(super) fn put_flat_state(&mut self, m: &Model, s: usize, bs: usize, q: &[f64], v: &[f64]) {
        let nd = m.plan.n * m.plan.dim;
        let nm = &m.arch.norm;
        for f in 0..nd {
            self.x[f * bs + s] = (q[f] - nm.q_mean[f % m.plan.dim]) / nm.q_scale;
            self.x[(nd + f) * bs + s] = v[f] / nm.v_scale;
        }
    }

    /// Node inputs and targets of the states `idx`, from their records
    /// ([`Samples`] packs every graph model's states).
    pub(super) fn fill_graph_inputs(&mut self, m: &Model, samples: &Samples, idx: &[usize]) {
        self.clear_one_hot(m, idx.len() * m.plan.n);
        self.put_graph_records(m, samples, idx);
    }

    pub(super) fn clear_one_hot(&mut self, m: &Model, nodes: usize) {
        let t = m.arch.types;
        self.x[..t * nodes].fill(0.0);
        self.xn[..t * nodes].fill(0.0);
    }

    widest! {
        /// Node inputs of state `s` (one-hot, q, q̇ raw in `x`, scaled in `xn`)
        /// from node-major `q`, `v`; the one-hot rows must have been cleared.
        pub(super) fn put_graph_state => put_graph_state_any(
            m: &Model, s: usize, nodes: usize, q: &[f64], v: &[f64]
        )
    }

    #[inline(always)]
    #[allow(clippy::inline_always)]
    pub(super) fn put_graph_state_any(
        &mut self,
        m: &Model,
        s: usize,
        nodes: usize,
        q: &[f64],
        v: &[f64],
    ) {
        let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
        let at = |f: usize| f * nodes + s * n..f * nodes + (s + 1) * n;
        // Transposed first, then scaled a feature row at a time: the
        // divisions run in vectors (one by one they were a sixteenth of a
        // 50-spring rollout step).
        for c in 0..d {
            for (x, y) in self.x[at(t + c)].iter_mut().zip(q.chunks_exact(d)) {
                *x = y[c];
            }
            for (x, y) in self.x[at(t + d + c)].iter_mut().zip(v.chunks_exact(d)) {
                *x = y[c];
            }
        }
        self.finish_graph_state(m, s, nodes);
    }

    widest! {
        /// [`Chunk::put_graph_state`] and the targets for the states `idx`
        /// from their packed records: rows copied, no transposing.
        pub(super) fn put_graph_records => put_graph_records_any(m: &Model, samples: &Samples, idx: &[usize])
    }

    #[inline(always)]
    #[allow(clippy::inline_always)]
    pub(super) fn put_graph_records_any(&mut self, m: &Model, samples: &Samples, idx: &[usize]) {
        let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
        let nodes = idx.len() * n;
        for (s, r) in samples.records(idx).enumerate() {
            for (f, row) in r.chunks_exact(n).enumerate() {
                let to = if f < 2 * d {
                    &mut self.x[(t + f) * nodes + s * n..]
                } else {
                    &mut self.tgt[(f - 2 * d) * nodes + s * n..]
                };
                copy_row(&mut to[..n], row);
            }
            self.finish_graph_state(m, s, nodes);
        }
    }

    /// State `s`'s one-hot rows, and its inputs scaled into `xn` from the
    /// raw rows of `x`.
    #[inline(always)]
    #[allow(clippy::inline_always)]
    pub(super) fn finish_graph_state(&mut self, m: &Model, s: usize, nodes: usize) {
        let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
        let nm = &m.arch.norm;
        let at = |f: usize| f * nodes + s * n..f * nodes + (s + 1) * n;
        for (i, &ty) in m.plan.types.iter().enumerate() {
            self.x[ty * nodes + s * n + i] = 1.0;
            if m.xn_read {
                self.xn[ty * nodes + s * n + i] = 1.0;
            }
        }
        if !m.xn_read {
            return;
        }
        for c in 0..d {
            let (mean, qs, vs) = (nm.q_mean[c], nm.q_scale, nm.v_scale);
            for (z, &y) in self.xn[at(t + c)].iter_mut().zip(&self.x[at(t + c)]) {
                *z = (y - mean) / qs;
            }
            for (z, &y) in self.xn[at(t + d + c)]
                .iter_mut()
                .zip(&self.x[at(t + d + c)])
            {
                *z = y / vs;
            }
        }
    }
}
