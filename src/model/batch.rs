//! A batch of states of one graph, as candle tensors.

use super::plan::{GraphPlan, EDGE_PHYSICS};
use crate::error::{bail, Result};
use crate::system::State;
use candle_core::{Device, Tensor};

/// Inputs (and optionally targets) for `B` states of one graph.
pub struct Batch {
    /// Number of states.
    pub b: usize,
    /// Particles per state.
    pub n: usize,
    /// Dimension.
    pub dim: usize,
    /// One-hot particle types, `(B·n, T)`.
    pub onehot: Tensor,
    /// Particle types, `(B·n)` u32.
    pub types: Tensor,
    /// Positions, `(B·n, d)`.
    pub q: Tensor,
    /// Velocities, `(B·n, d)`.
    pub v: Tensor,
    /// Directed-edge receivers over the whole batch, `(2·B·E)` u32: first all
    /// forward edges (sample-major), then all reversed ones.
    pub recv: Tensor,
    /// Directed-edge senders, same layout.
    pub send: Tensor,
    /// Number of directed edges, 2·B·E.
    pub n_directed: usize,
    /// Rest length and stiffness of each directed edge, `(2·B·E, 2)`.
    pub edge_params: Tensor,
    /// Constraint rows when the graph has bars: A `(B, k, D)`, Aᵀ `(B, D, k)`, Ȧq̇ `(B, k, 1)`.
    pub constraint: Option<(Tensor, Tensor, Tensor)>,
    /// Target accelerations `(B·n, d)`, when training.
    pub target: Option<Tensor>,
}

impl Batch {
    /// Builds a batch; `types` is the model's one-hot width.
    pub fn new(
        plan: &GraphPlan,
        states: &[&State],
        targets: Option<&[&[f64]]>,
        types: usize,
    ) -> Result<Self> {
        let dev = &Device::Cpu;
        let (b, n, d) = (states.len(), plan.n, plan.dim);
        let nd = n * d;
        if b == 0 {
            bail!("empty batch");
        }
        if let Some(t) = plan.types.iter().find(|&&t| t >= types) {
            bail!("particle type {t} is unknown to the model (it knows {types} types)");
        }
        let mut onehot = vec![0.0; b * n * types];
        let mut ty = Vec::with_capacity(b * n);
        let mut q = Vec::with_capacity(b * nd);
        let mut v = Vec::with_capacity(b * nd);
        for (s, st) in states.iter().enumerate() {
            if st.q.len() != nd || st.v.len() != nd {
                bail!("state {s} has the wrong size for a {n}-particle {d}D graph");
            }
            for (i, &t) in plan.types.iter().enumerate() {
                onehot[(s * n + i) * types + t] = 1.0;
                ty.push(t as u32);
            }
            q.extend_from_slice(&st.q);
            v.extend_from_slice(&st.v);
        }
        let e = plan.n_edges();
        let mut recv = Vec::with_capacity(2 * b * e);
        let mut send = Vec::with_capacity(2 * b * e);
        let mut params = Vec::with_capacity(4 * b * e);
        for half in 0..2 {
            for s in 0..b {
                for k in half * e..(half + 1) * e {
                    recv.push((s * n + plan.recv[k]) as u32);
                    send.push((s * n + plan.send[k]) as u32);
                    params.extend(plan.edge_physics(k));
                }
            }
        }
        let k = plan.bars.len();
        let constraint = if k > 0 {
            let mut a = vec![0.0; b * k * nd];
            let mut at = vec![0.0; b * nd * k];
            let mut adq = vec![0.0; b * k];
            for (s, st) in states.iter().enumerate() {
                plan.constraint_rows(
                    &st.q,
                    &st.v,
                    &mut a[s * k * nd..(s + 1) * k * nd],
                    &mut adq[s * k..(s + 1) * k],
                );
                for r in 0..k {
                    for c in 0..nd {
                        at[s * nd * k + c * k + r] = a[s * k * nd + r * nd + c];
                    }
                }
            }
            Some((
                Tensor::from_vec(a, (b, k, nd), dev)?,
                Tensor::from_vec(at, (b, nd, k), dev)?,
                Tensor::from_vec(adq, (b, k, 1), dev)?,
            ))
        } else {
            None
        };
        let target = match targets {
            Some(ts) => {
                if ts.len() != b {
                    bail!("{} targets for {b} states", ts.len());
                }
                let mut t = Vec::with_capacity(b * nd);
                for x in ts {
                    if x.len() != nd {
                        bail!("target accelerations have the wrong size");
                    }
                    t.extend_from_slice(x);
                }
                Some(Tensor::from_vec(t, (b * n, d), dev)?)
            }
            None => None,
        };
        let n_directed = recv.len();
        Ok(Self {
            b,
            n,
            dim: d,
            onehot: Tensor::from_vec(onehot, (b * n, types), dev)?,
            types: Tensor::from_vec(ty, b * n, dev)?,
            q: Tensor::from_vec(q, (b * n, d), dev)?,
            v: Tensor::from_vec(v, (b * n, d), dev)?,
            recv: Tensor::from_vec(recv, n_directed, dev)?,
            send: Tensor::from_vec(send, n_directed, dev)?,
            n_directed,
            edge_params: Tensor::from_vec(params, (n_directed, EDGE_PHYSICS), dev)?,
            constraint,
            target,
        })
    }
}
