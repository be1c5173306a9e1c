//! The metrics of LagrangeBench (Toshev et al. 2023), as its
//! `lagrangebench/evaluate/metrics.py` (`MetricsComputer`, version 0.2.0)
//! computes them at inference, on the first [`HORIZON`] predicted frames of a
//! rollout (its `n_rollout_steps = 20`, `metrics_stride = 1`):
//!
//! * **MSE5, MSE10, MSE20**: the position error of each predicted frame,
//!   squared and averaged over particles and dimensions, then averaged over
//!   the first 5, 10 and 20 predicted frames (the start, frame 0, is not
//!   scored: it is given);
//! * **Sinkhorn**: the Sinkhorn divergence between the predicted and the true
//!   particle positions of each predicted frame, averaged over the frames:
//!   uniform weights, squared Euclidean cost, entropic regularisation
//!   ε = mean(C_xy) / 20 shared by the three terms (what ott-jax's `Geometry`
//!   and `sinkhorn_divergence`, which LagrangeBench calls, default to),
//!   S = OT_ε(x, y) − ½ OT_ε(x, x) − ½ OT_ε(y, y), each OT_ε the dual
//!   objective of log-domain Sinkhorn iterations (see [`sinkhorn_divergence`]);
//! * **E_kin MSE**: E_kin of a frame pair = dx^dim Σ_i |v_i|², v_i the finite
//!   difference of consecutive predicted frames over the frame interval (no
//!   ½, no mass: LagrangeBench's particles all have the volume dx^dim), and
//!   the mean over frame pairs of (E_kin predicted − E_kin true)².
//!
//! Every particle counts, kinematic ones (walls) included, as in
//! LagrangeBench. Over trajectories, each metric is the plain mean of the
//! per-trajectory values (its `averaged_metrics`). Differences from
//! LagrangeBench: we compute in f64 (it casts the cost matrices to f32) and
//! iterate Sinkhorn to a marginal error of [`SINKHORN_TOLERANCE`] (it stops
//! at 1e-4; after [`SINKHORN_MAX_ITERATIONS`] we accept up to that, too); `scripts/check_lagrangebench_metrics.sh` compares the two.

use crate::periodic::PeriodicBox;
use serde::{Deserialize, Serialize};

/// Predicted frames scored (LagrangeBench's default `n_rollout_steps`).
pub const HORIZON: usize = 20;

/// Sinkhorn iterations stop when the L1 error of the coupling's marginal is
/// below this (ott-jax's `norm_error = 1`).
pub const SINKHORN_TOLERANCE: f64 = 1e-8;

/// At most this many Sinkhorn iterations per transport problem.
pub const SINKHORN_MAX_ITERATIONS: usize = 20_000;

/// After [`SINKHORN_MAX_ITERATIONS`], a marginal error below this is still
/// accepted: it is LagrangeBench's own stopping threshold (ott-jax's
/// `threshold` as LagrangeBench sets it). A few well-separated particles at
/// small ε converge slowly and stall between the two.
pub const SINKHORN_ACCEPTED: f64 = 1e-4;

/// ε as a fraction of the mean cost (ott-jax's default relative epsilon).
pub const RELATIVE_EPSILON: f64 = 0.05;

/// Why the metrics cannot be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LagrangeError {
    /// Truth and prediction disagree in frames or sizes.
    #[error("{what}: {got}, expected {expected}")]
    Shape {
        /// What disagrees.
        what: &'static str,
        /// Found.
        got: usize,
        /// Expected.
        expected: usize,
    },
    /// Nothing to score.
    #[error(
        "no predicted frames to score (a trajectory needs its start and at least one more state)"
    )]
    NoFrames,
    /// A non-finite position, or a bad interval or spacing.
    #[error("{0} is not finite and positive (or a position is not finite)")]
    Value(&'static str),
    /// Sinkhorn did not converge.
    #[error(
        "Sinkhorn did not reach a marginal error of {SINKHORN_ACCEPTED:e} in \
         {SINKHORN_MAX_ITERATIONS} iterations (error {0:e})"
    )]
    NotConverged(f64),
}

crate::error::typed_errors!(LagrangeError);

/// LagrangeBench's metrics of one trajectory, or their means over many.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LagrangeMetrics {
    /// Mean position MSE over the first 5 predicted frames (`None`: fewer).
    pub mse5: Option<f64>,
    /// Over the first 10.
    pub mse10: Option<f64>,
    /// Over the first 20.
    pub mse20: Option<f64>,
    /// Mean Sinkhorn divergence over the scored frames.
    pub sinkhorn: f64,
    /// MSE of the kinetic energy over the scored frame pairs (`None`: fewer
    /// than two predicted frames). JSON key `ekin_mse`.
    #[serde(rename = "ekin_mse")]
    pub e_kin_mse: Option<f64>,
    /// Predicted frames scored (at most [`HORIZON`]).
    pub frames: usize,
}

/// One trajectory's frames: flat positions (N·d each), frame 0 the start.
pub struct Frames<'a> {
    /// Positions of each frame.
    pub q: Vec<&'a [f64]>,
}

/// The metrics of `pred` against `truth` (frame 0 of both is the start and is
/// not scored; up to [`HORIZON`] frames after it are), `d` dimensions,
/// `frame_dt` the time between frames, `dx` the particle spacing.
pub fn trajectory_metrics(
    truth: &Frames,
    pred: &Frames,
    d: usize,
    frame_dt: f64,
    dx: f64,
) -> Result<LagrangeMetrics, LagrangeError> {
    trajectory_metrics_sampled(truth, pred, d, frame_dt, dx, None, None)
}

/// [`trajectory_metrics`] with Sinkhorn computed on at most
/// `sinkhorn_particles` particles (the same evenly strided particles of the
/// truth and the prediction, [`subsample`]; `None`: all). Sinkhorn costs
/// O(N²) per iteration; the other metrics always use every particle. In a
/// periodic box (`periodic`) MSE and the velocities of E_kin take the
/// minimum image of each difference, so a particle wrapped across a face is
/// not an error of a box length; Sinkhorn compares the wrapped positions.
pub fn trajectory_metrics_sampled(
    truth: &Frames,
    pred: &Frames,
    d: usize,
    frame_dt: f64,
    dx: f64,
    sinkhorn_particles: Option<usize>,
    periodic: Option<&PeriodicBox>,
) -> Result<LagrangeMetrics, LagrangeError> {
    if pred.q.len() != truth.q.len() {
        return Err(LagrangeError::Shape {
            what: "predicted frames",
            got: pred.q.len(),
            expected: truth.q.len(),
        });
    }
    let frames = truth.q.len().saturating_sub(1).min(HORIZON);
    if frames == 0 {
        return Err(LagrangeError::NoFrames);
    }
    check_frames(truth, pred, d, frames)?;
    if !(frame_dt.is_finite() && frame_dt > 0.0) {
        return Err(LagrangeError::Value("the frame interval"));
    }
    if !(dx.is_finite() && dx > 0.0) {
        return Err(LagrangeError::Value("the particle spacing dx"));
    }
    let (t, p) = (&truth.q[1..=frames], &pred.q[1..=frames]);
    let mse: Vec<f64> = t
        .iter()
        .zip(p)
        .map(|(a, b)| mse(a, b, d, periodic))
        .collect();
    let mean_of = |k: usize| (frames >= k).then(|| mean(&mse[..k]));
    let mut sinkhorn = Vec::with_capacity(frames);
    for (a, b) in t.iter().zip(p) {
        let s = match sinkhorn_particles {
            Some(k) if k < a.len() / d => {
                sinkhorn_divergence(&subsample(b, d, k), &subsample(a, d, k), d)?
            }
            _ => sinkhorn_divergence(b, a, d)?,
        };
        sinkhorn.push(s);
    }
    let e_kin_mse = (frames >= 2).then(|| {
        let (et, ep) = (
            e_kin(t, frame_dt, dx, d, periodic),
            e_kin(p, frame_dt, dx, d, periodic),
        );
        mean(
            &et.iter()
                .zip(&ep)
                .map(|(a, b)| (b - a) * (b - a))
                .collect::<Vec<_>>(),
        )
    });
    Ok(LagrangeMetrics {
        mse5: mean_of(5),
        mse10: mean_of(10),
        mse20: mean_of(20),
        sinkhorn: mean(&sinkhorn),
        e_kin_mse,
        frames,
    })
}

/// Sizes and finiteness of the scored frames.
fn check_frames(
    truth: &Frames,
    pred: &Frames,
    d: usize,
    frames: usize,
) -> Result<(), LagrangeError> {
    let len = truth.q[0].len();
    if d == 0 || len == 0 || len % d != 0 {
        return Err(LagrangeError::Shape {
            what: "positions per frame (a positive multiple of the dimension)",
            got: len,
            expected: d.max(1),
        });
    }
    for q in truth.q[..=frames].iter().chain(&pred.q[..=frames]) {
        if q.len() != len {
            return Err(LagrangeError::Shape {
                what: "positions in a frame",
                got: q.len(),
                expected: len,
            });
        }
        if q.iter().any(|x| !x.is_finite()) {
            return Err(LagrangeError::Value("a position"));
        }
    }
    Ok(())
}

/// The plain mean of each metric over trajectories (a metric absent from
/// any trajectory is absent from the mean).
pub fn average(per_trajectory: &[LagrangeMetrics]) -> Option<LagrangeMetrics> {
    if per_trajectory.is_empty() {
        return None;
    }
    let opt = |f: fn(&LagrangeMetrics) -> Option<f64>| {
        per_trajectory
            .iter()
            .map(f)
            .collect::<Option<Vec<f64>>>()
            .map(|v| mean(&v))
    };
    Some(LagrangeMetrics {
        mse5: opt(|m| m.mse5),
        mse10: opt(|m| m.mse10),
        mse20: opt(|m| m.mse20),
        sinkhorn: mean(
            &per_trajectory
                .iter()
                .map(|m| m.sinkhorn)
                .collect::<Vec<_>>(),
        ),
        e_kin_mse: opt(|m| m.e_kin_mse),
        frames: per_trajectory.iter().map(|m| m.frames).min().unwrap_or(0),
    })
}

/// The metrics a diverged rollout scores: the worst value, everywhere
/// ([`crate::metrics::DIVERGED`]).
pub fn diverged(frames: usize) -> LagrangeMetrics {
    let w = crate::metrics::DIVERGED;
    let some = |k: usize| (frames >= k).then_some(w);
    LagrangeMetrics {
        mse5: some(5),
        mse10: some(10),
        mse20: some(20),
        sinkhorn: w,
        e_kin_mse: some(2),
        frames,
    }
}

/// `k` of the points of `q` (flat, `d` per point), evenly strided: point
/// ⌊i·n/k⌋ for i in 0..k (all of them when k ≥ n; at least one).
pub fn subsample(q: &[f64], d: usize, k: usize) -> Vec<f64> {
    let n = q.len() / d;
    let k = k.clamp(1, n.max(1));
    (0..k)
        .flat_map(|i| {
            let p = i * n / k;
            q[p * d..(p + 1) * d].iter().copied()
        })
        .collect()
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// Squared position error averaged over particles and dimensions.
/// `a − b` particle by particle, each difference the minimum image in a
/// periodic box.
fn differences(a: &[f64], b: &[f64], d: usize, periodic: Option<&PeriodicBox>) -> Vec<f64> {
    let mut out: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    if let Some(pb) = periodic {
        out.chunks_mut(d.max(1)).for_each(|c| pb.min_image(c));
    }
    out
}

fn mse(a: &[f64], b: &[f64], d: usize, periodic: Option<&PeriodicBox>) -> f64 {
    let diff = differences(a, b, d, periodic);
    mean(&diff.iter().map(|x| x * x).collect::<Vec<_>>())
}

/// dx^d Σ |v|² of each consecutive pair of `frames`, v by finite differences.
fn e_kin(
    frames: &[&[f64]],
    frame_dt: f64,
    dx: f64,
    d: usize,
    periodic: Option<&PeriodicBox>,
) -> Vec<f64> {
    let volume = dx.powi(d as i32);
    frames
        .windows(2)
        .map(|w| {
            let s: f64 = differences(w[1], w[0], d, periodic)
                .iter()
                .map(|x| (x / frame_dt).powi(2))
                .sum();
            s * volume
        })
        .collect()
}

/// Squared Euclidean distance of particle `i` of `x` and `j` of `y`.
fn cost(x: &[f64], y: &[f64], d: usize, i: usize, j: usize) -> f64 {
    let (a, b) = (&x[i * d..(i + 1) * d], &y[j * d..(j + 1) * d]);
    a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum()
}

/// The Sinkhorn divergence of point clouds `x` and `y` (flat, `d` per point)
/// with uniform weights: OT_ε(x, y) − ½ (OT_ε(x, x) + OT_ε(y, y)),
/// ε = [`RELATIVE_EPSILON`] · mean cost of x against y, for all three terms.
/// Each OT_ε is ott-jax's `reg_ot_cost`: with potentials f, g after
/// log-domain iterations, ⟨a, f − ε log a⟩ + ⟨b, g − ε log b⟩ + ε (1 − Σ P),
/// P_ij = exp((f_i + g_j − C_ij) / ε). Costs are computed as needed, never
/// stored (memory stays linear in the particles).
pub fn sinkhorn_divergence(x: &[f64], y: &[f64], d: usize) -> Result<f64, LagrangeError> {
    let (n, m) = (x.len() / d, y.len() / d);
    let mut total = 0.0;
    for i in 0..n {
        for j in 0..m {
            total += cost(x, y, d, i, j);
        }
    }
    let eps = RELATIVE_EPSILON * total / (n * m) as f64;
    if eps == 0.0 {
        // Every point of x sits on every point of y: nothing to transport.
        return Ok(0.0);
    }
    let xy = transport(x, y, d, eps, false)?;
    let xx = transport(x, x, d, eps, true)?;
    let yy = transport(y, y, d, eps, true)?;
    Ok(xy - 0.5 * (xx + yy))
}

/// Rows of [`soft_min`] per parallel task: large enough that a task
/// outweighs its scheduling, small enough to spread 2,500 rows over cores.
const ROWS_PER_TASK: usize = 64;

/// Sinkhorn's own pool, one thread per core: the process-wide rayon pool
/// is kept at one thread for candle (`crate::alloc`). `None` if it cannot
/// be built (then rows run on the calling thread).
fn pool() -> Option<&'static rayon::ThreadPool> {
    static POOL: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(crate::engine::all_cores())
            .thread_name(|i| format!("sinkhorn-{i}"))
            .build()
            .ok()
    })
    .as_ref()
}

/// −ε log Σ_j exp((h_j − C_ij) / ε) for each i (rows of x against the
/// points of y with their potentials h). Rows are independent: above
/// [`ROWS_PER_TASK`] rows, chunks of that many run on [`pool`], each with
/// its own scratch row, so the result does not depend on the threads.
fn soft_min(x: &[f64], y: &[f64], d: usize, h: &[f64], eps: f64, out: &mut [f64]) {
    use rayon::prelude::*;
    let m = h.len();
    let chunk = |(c, rows): (usize, &mut [f64])| {
        let mut z = vec![0.0; m];
        for (k, o) in rows.iter_mut().enumerate() {
            let i = c * ROWS_PER_TASK + k;
            let mut top = f64::NEG_INFINITY;
            for (j, zj) in z.iter_mut().enumerate() {
                *zj = (h[j] - cost(x, y, d, i, j)) / eps;
                top = top.max(*zj);
            }
            let s: f64 = z.iter().map(|v| (v - top).exp()).sum();
            *o = -eps * (top + s.ln());
        }
    };
    match pool() {
        Some(p) if out.len() > ROWS_PER_TASK => p.install(|| {
            out.par_chunks_mut(ROWS_PER_TASK)
                .enumerate()
                .for_each(chunk)
        }),
        _ => out.chunks_mut(ROWS_PER_TASK).enumerate().for_each(chunk),
    }
}

/// ott-jax's `reg_ot_cost` of uniform weights on `x` and `y` after Sinkhorn
/// iterations in the log domain: alternating g then f updates, or for
/// `symmetric` (x is y) the averaged update f ← ½ (f + T(f)) of Feydy et al.
/// 2019, eq. 25, as `sinkhorn_divergence` runs for OT(x, x).
fn transport(
    x: &[f64],
    y: &[f64],
    d: usize,
    eps: f64,
    symmetric: bool,
) -> Result<f64, LagrangeError> {
    let (n, m) = (x.len() / d, y.len() / d);
    let (la, lb) = ((1.0 / n as f64).ln(), (1.0 / m as f64).ln());
    let (mut f, mut g) = (vec![0.0; n], vec![0.0; m]);
    let mut t = vec![0.0; n.max(m)];
    let mut error = f64::INFINITY;
    let mut last = None;
    for it in 0..SINKHORN_MAX_ITERATIONS {
        if symmetric {
            soft_min(x, x, d, &f, eps, &mut t[..n]);
            for (fi, ti) in f.iter_mut().zip(&t) {
                *fi = 0.5 * (*fi + eps * la + ti);
            }
            g.copy_from_slice(&f);
        } else {
            soft_min(y, x, d, &f, eps, &mut t[..m]);
            for (gj, tj) in g.iter_mut().zip(&t) {
                *gj = eps * lb + tj;
            }
            soft_min(x, y, d, &g, eps, &mut t[..n]);
            for (fi, ti) in f.iter_mut().zip(&t) {
                *fi = eps * la + ti;
            }
        }
        if it % 10 == 9 {
            // Column marginals: after the f update the rows are exact.
            soft_min(y, x, d, &f, eps, &mut t[..m]);
            let col: Vec<f64> = g
                .iter()
                .zip(&t)
                .map(|(gj, tj)| ((gj - tj) / eps).exp())
                .collect();
            error = col.iter().map(|c| (c - 1.0 / m as f64).abs()).sum();
            let fa: f64 = f.iter().map(|fi| fi - eps * la).sum::<f64>() / n as f64;
            let gb: f64 = g.iter().map(|gj| gj - eps * lb).sum::<f64>() / m as f64;
            let cost = fa + gb + eps * (1.0 - col.iter().sum::<f64>());
            if error < SINKHORN_TOLERANCE {
                return Ok(cost);
            }
            last = Some(cost);
        }
    }
    match last {
        Some(cost) if error < SINKHORN_ACCEPTED => Ok(cost),
        _ => Err(LagrangeError::NotConverged(error)),
    }
}

#[cfg(test)]
#[path = "lagrange_metrics_tests.rs"]
mod tests;
