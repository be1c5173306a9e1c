//! A batch of states of one graph, as candle tensors.

use super::graph_plan::{GraphPlan, EDGE_PHYSICS};
use crate::error::{bail, Result};
use crate::system::{PeriodicBox, State};
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
    /// 1 for a contact edge, 0 for a fixed one, `(2·B·E, 1)`.
    pub contact: Tensor,
    /// With kinematic particles: 1 for a free particle's coordinates, 0 for a
    /// kinematic one's, `(B·n, d)` (losses average over the free ones).
    pub free: Option<Tensor>,
    /// Constraint rows when the graph has bars: A `(B, k, D)`, Aᵀ `(B, D, k)`, Ȧq̇ `(B, k, 1)`.
    pub constraint: Option<(Tensor, Tensor, Tensor)>,
    /// Target accelerations `(B·n, d)`, when training.
    pub target: Option<Tensor>,
    /// In a periodic box: what turns each directed edge's q_recv − q_send
    /// into its minimum image, `(2·B·E, d)` (a constant: no gradient).
    pub image_shift: Option<Tensor>,
}

impl Batch {
    /// Mean squared error of `pred` against the targets over the free
    /// particles (kinematic ones are given, not predicted): the training
    /// loss of every model that predicts accelerations.
    pub fn mse(&self, pred: &Tensor) -> Result<Tensor> {
        let Some(t) = &self.target else {
            bail!("batch has no targets");
        };
        let err = (pred - t)?.sqr()?;
        Ok(match &self.free {
            None => err.mean_all()?,
            Some(free) => {
                let count = free.sum_all()?.to_scalar::<f64>()?.max(1.0);
                ((err * free)?.sum_all()? / count)?
            }
        })
    }

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
        let Edges {
            recv,
            send,
            params,
            contact,
        } = Edges::of(plan, states);
        let free = free_mask(plan, b)?;
        let constraint = constraint(plan, states)?;
        let target = match targets {
            Some(ts) => Some(target_tensor(ts, b, n, d)?),
            None => None,
        };
        let n_directed = recv.len();
        let image_shift = match &plan.periodic {
            Some(bx) => {
                let shift = image_shifts(bx, &q, d, (&recv, &send));
                Some(Tensor::from_vec(shift, (n_directed, d), dev)?)
            }
            None => None,
        };
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
            contact: Tensor::from_vec(contact, (n_directed, 1), dev)?,
            free,
            constraint,
            target,
            image_shift,
        })
    }
}

/// Per directed edge and axis: minimum image of q_recv − q_send minus the
/// difference itself (`q` flat over the batch's rows).
fn image_shifts(bx: &PeriodicBox, q: &[f64], d: usize, (recv, send): (&[u32], &[u32])) -> Vec<f64> {
    let mut out = Vec::with_capacity(recv.len() * d);
    for (&r, &s) in recv.iter().zip(send) {
        for c in 0..d {
            let w = q[r as usize * d + c] - q[s as usize * d + c];
            let mut img = [w];
            if let Some(l) = bx.period(c) {
                img[0] = crate::periodic::min_image_axis(w, l);
            }
            out.push(img[0] - w);
        }
    }
    out
}

/// Every directed edge of a batch in the plan's order (each state's contacts
/// found at its positions): receivers, senders, rest length and stiffness,
/// and the contact flag.
struct Edges {
    recv: Vec<u32>,
    send: Vec<u32>,
    params: Vec<f64>,
    contact: Vec<f64>,
}

impl Edges {
    fn of(plan: &GraphPlan, states: &[&State]) -> Self {
        let (mut pairs, mut starts) = (vec![], vec![]);
        if plan.has_contacts() {
            let mut search = plan.contact_search();
            starts.push(0);
            for st in states {
                plan.contacts(&mut search, &st.q, &mut pairs);
                starts.push(pairs.len());
            }
        }
        let mut e = Edges {
            recv: vec![],
            send: vec![],
            params: vec![],
            contact: vec![],
        };
        plan.directed_edges(states.len(), &pairs, &starts, |_, d| {
            e.recv.push(d.recv as u32);
            e.send.push(d.send as u32);
            match d.fixed {
                Some(k) => e.params.extend(plan.edge_physics(k)),
                None => e.params.extend(plan.contact_physics()),
            }
            e.contact.push(if d.fixed.is_some() { 0.0 } else { 1.0 });
        });
        e
    }
}

/// With kinematic particles: 1 for a free particle's coordinates, 0 for a
/// kinematic one's, `(B·n, d)`.
fn free_mask(plan: &GraphPlan, b: usize) -> Result<Option<Tensor>> {
    if !plan.kinematic.iter().any(|k| *k) {
        return Ok(None);
    }
    let (n, d) = (plan.n, plan.dim);
    let one = (0..b * n)
        .flat_map(|r| {
            let x = if plan.is_kinematic(r % n) { 0.0 } else { 1.0 };
            std::iter::repeat_n(x, d)
        })
        .collect();
    Ok(Some(Tensor::from_vec(one, (b * n, d), &Device::Cpu)?))
}

/// The bar constraint's rows of each state: A `(B, k, D)`, Aᵀ `(B, D, k)`,
/// Ȧq̇ `(B, k, 1)`; `None` without bars.
fn constraint(plan: &GraphPlan, states: &[&State]) -> Result<Option<(Tensor, Tensor, Tensor)>> {
    let (b, k, nd) = (states.len(), plan.bars.len(), plan.n * plan.dim);
    if k == 0 {
        return Ok(None);
    }
    let dev = &Device::Cpu;
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
    Ok(Some((
        Tensor::from_vec(a, (b, k, nd), dev)?,
        Tensor::from_vec(at, (b, nd, k), dev)?,
        Tensor::from_vec(adq, (b, k, 1), dev)?,
    )))
}

/// Target accelerations of `b` states as one `(B·n, d)` tensor.
fn target_tensor(ts: &[&[f64]], b: usize, n: usize, d: usize) -> Result<Tensor> {
    if ts.len() != b {
        bail!("{} targets for {b} states", ts.len());
    }
    let mut t = Vec::with_capacity(b * n * d);
    for x in ts {
        if x.len() != n * d {
            bail!("target accelerations have the wrong size");
        }
        t.extend_from_slice(x);
    }
    Ok(Tensor::from_vec(t, (b * n, d), &Device::Cpu)?)
}
