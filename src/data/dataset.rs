//! Trajectories to training samples (state → acceleration), and bag digests.

use std::io::Read;
use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sha2::{Digest, Sha256};

use super::DataError;
use crate::system::{Graph, State, Trajectory};

/// Relative tolerance on the spread of time steps within a trajectory for finite
/// differences (stamps are stored at 1 ns, so Δ = 1 ms already jitters by 1e-6).
pub const DT_REL_TOL: f64 = 1e-4;

/// Where a dataset's accelerations come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AccSource {
    /// Recorded in every sample (exact, from the simulator).
    Recorded,
    /// Verlet finite difference of consecutive positions (interior states only).
    FiniteDifference,
}

/// Training pairs: states and the accelerations to learn, all on one graph.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// The graph shared by every state.
    pub graph: Graph,
    /// Inputs.
    pub states: Vec<State>,
    /// Targets, `graph.ndof()` each, one per state.
    pub acc: Vec<Vec<f64>>,
    /// Where `acc` comes from.
    pub source: AccSource,
}

impl Dataset {
    /// Number of training pairs.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// True when there are no pairs.
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// Keeps a random subset of `points` training pairs, in their original
    /// order (the paper's data-efficiency experiments train on 100 to 10,000
    /// points). The subset depends only on `seed` and the dataset's size.
    /// Errors when `points` is below 2 (nothing to split for validation) or
    /// above [`Dataset::len`].
    pub fn subsample(&mut self, points: usize, seed: u64) -> Result<(), DataError> {
        let n = self.len();
        if points < 2 || points > n {
            return Err(DataError::Trajectory(format!(
                "cannot train on {points} data points: the data have {n} states (use 2..={n})"
            )));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut keep = rand::seq::index::sample(&mut rng, n, points).into_vec();
        keep.sort_unstable();
        self.states = keep.iter().map(|&i| self.states[i].clone()).collect();
        self.acc = keep.iter().map(|&i| self.acc[i].clone()).collect();
        Ok(())
    }

    /// Adds Gaussian noise N(0, σ²) to every acceleration component, with
    /// σ = `percent`/100 · the population standard deviation of all
    /// acceleration components of the dataset (the paper gives noise as a
    /// percentage of the spread of the outputs). Returns σ. `percent` = 0
    /// leaves the data bit-identical; negative or non-finite `percent` is an
    /// error. The noise depends only on `seed` and the data.
    pub fn add_noise(&mut self, percent: f64, seed: u64) -> Result<f64, DataError> {
        if !(percent.is_finite() && percent >= 0.0) {
            return Err(DataError::Trajectory(format!(
                "noise must be a finite percentage ≥ 0, got {percent}"
            )));
        }
        let count = self.acc.iter().map(Vec::len).sum::<usize>();
        if percent == 0.0 || count == 0 {
            return Ok(0.0);
        }
        let all = || self.acc.iter().flatten();
        let mean = all().sum::<f64>() / count as f64;
        let var = all().map(|x| (x - mean).powi(2)).sum::<f64>() / count as f64;
        let sigma = percent / 100.0 * var.sqrt();
        if sigma == 0.0 {
            return Ok(0.0);
        }
        let normal = Normal::new(0.0, sigma)
            .map_err(|e| DataError::Trajectory(format!("noise σ = {sigma}: {e}")))?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for x in self.acc.iter_mut().flatten() {
            *x += normal.sample(&mut rng);
        }
        Ok(sigma)
    }

    /// Builds the training set. Uses the recorded accelerations when every sample of
    /// every trajectory has them; otherwise finite differences of the positions
    /// over interior states ([`finite_difference`]: the Verlet difference for a
    /// uniform Δ, the three-point difference for uneven stamps), which need at
    /// least 3 samples per trajectory.
    /// All trajectories must share one graph.
    pub fn from_trajectories(trajectories: &[Trajectory]) -> Result<Dataset, DataError> {
        let err = |m: String| Err(DataError::Trajectory(m));
        let Some(first) = trajectories.first() else {
            return err("no trajectories to build a dataset from".into());
        };
        let graph = first.graph.clone();
        if let Err(e) = graph.validate() {
            return err(format!("trajectory {}: {e}", first.id));
        }
        for tr in trajectories {
            if tr.graph != graph {
                return err(format!(
                    "trajectory {} has a different graph from trajectory {} (one dataset needs one system)",
                    tr.id, first.id
                ));
            }
            if tr.samples.is_empty() {
                return err(format!("trajectory {} has no samples", tr.id));
            }
            for (k, s) in tr.samples.iter().enumerate() {
                if let Err(e) = s.state.validate(&graph) {
                    return err(format!("trajectory {} sample {k}: {e}", tr.id));
                }
            }
        }
        let recorded = trajectories
            .iter()
            .all(|tr| tr.samples.iter().all(|s| s.acc.is_some()));
        let (mut states, mut acc) = (Vec::new(), Vec::new());
        if recorded {
            for tr in trajectories {
                for (k, s) in tr.samples.iter().enumerate() {
                    let a = s.acc.clone().unwrap_or_default();
                    if a.len() != graph.ndof() || a.iter().any(|x| !x.is_finite()) {
                        return err(format!(
                            "trajectory {} sample {k}: accelerations are not {} finite numbers",
                            tr.id,
                            graph.ndof()
                        ));
                    }
                    states.push(s.state.clone());
                    acc.push(a);
                }
            }
        } else {
            for tr in trajectories {
                let a = finite_difference(tr)?;
                for (k, a) in a.into_iter().enumerate() {
                    states.push(tr.samples[k + 1].state.clone());
                    acc.push(a);
                }
            }
        }
        Ok(Dataset {
            graph,
            states,
            acc,
            source: if recorded {
                AccSource::Recorded
            } else {
                AccSource::FiniteDifference
            },
        })
    }
}

/// Accelerations of a trajectory's interior samples 1..m−1 by finite
/// differences of the positions: the Verlet difference
/// (q(t+Δ) + q(t−Δ) − 2 q(t)) / Δ² with Δ the mean step when the steps are
/// uniform (within [`DT_REL_TOL`]; error O(Δ²)); otherwise the three-point
/// difference for uneven steps h₁, h₂,
/// 2 [(q₊ − q)/h₂ − (q − q₋)/h₁] / (h₁ + h₂) (error O(h₂ − h₁) + O(h²)).
pub fn finite_difference(tr: &Trajectory) -> Result<Vec<Vec<f64>>, DataError> {
    let s = &tr.samples;
    let m = s.len();
    if m >= 3 {
        let dt = (s[m - 1].t - s[0].t) / (m - 1) as f64;
        let uneven = (1..m).any(|k| {
            let d = s[k].t - s[k - 1].t;
            (d - dt).abs() > DT_REL_TOL * dt
        });
        let increasing = (1..m).all(|k| s[k].t > s[k - 1].t);
        if uneven && increasing && dt.is_finite() {
            return Ok((1..m - 1)
                .map(|k| {
                    let (h1, h2) = (s[k].t - s[k - 1].t, s[k + 1].t - s[k].t);
                    let (qp, q, qn) = (&s[k - 1].state.q, &s[k].state.q, &s[k + 1].state.q);
                    (0..q.len())
                        .map(|i| 2.0 * ((qn[i] - q[i]) / h2 - (q[i] - qp[i]) / h1) / (h1 + h2))
                        .collect()
                })
                .collect());
        }
    }
    uniform_difference(tr)
}

/// Velocities of every sample of a trajectory from its positions and stamps
/// (for position-only recordings): the three-point difference for uneven
/// steps, central inside and one-sided at both ends, exact for quadratics so
/// the error is O(h²) (h the local step): for a sine of angular frequency ω,
/// about (ωh)²/6 of the amplitude of the velocity inside and (ωh)²/3 at the
/// ends (7e-4 and 1.3e-3 for 1 Hz sampled at 100 Hz). Two samples give the
/// one-step difference (O(h)); one sample is an error.
pub fn finite_difference_velocities(tr: &Trajectory) -> Result<Vec<Vec<f64>>, DataError> {
    let err = |m: String| Err(DataError::Trajectory(format!("trajectory {}: {m}", tr.id)));
    let s = &tr.samples;
    let m = s.len();
    if m < 2 {
        return err(
            "one state without velocities: velocities need at least two stamped positions".into(),
        );
    }
    for k in 1..m {
        if s[k].t.partial_cmp(&s[k - 1].t) != Some(std::cmp::Ordering::Greater) {
            return err(format!("sample {k} is not stamped after sample {}", k - 1));
        }
    }
    let q = |k: usize| &s[k].state.q;
    let n = q(0).len();
    if m == 2 {
        let h = s[1].t - s[0].t;
        let v: Vec<f64> = (0..n).map(|i| (q(1)[i] - q(0)[i]) / h).collect();
        return Ok(vec![v.clone(), v]);
    }
    // Weights of q at three consecutive points for the derivative at one of them.
    let combine = |k0: usize, w: [f64; 3]| -> Vec<f64> {
        (0..n)
            .map(|i| w[0] * q(k0)[i] + w[1] * q(k0 + 1)[i] + w[2] * q(k0 + 2)[i])
            .collect()
    };
    let h = |k: usize| s[k].t - s[k - 1].t;
    let mut out = Vec::with_capacity(m);
    out.push(combine(0, three_point(h(1), h(2), At::First)));
    for k in 1..m - 1 {
        out.push(combine(k - 1, three_point(h(k), h(k + 1), At::Middle)));
    }
    out.push(combine(m - 3, three_point(h(m - 2), h(m - 1), At::Last)));
    Ok(out)
}

/// Which of three consecutive points a derivative is taken at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum At {
    /// The first (one-sided, forward).
    First,
    /// The middle (central).
    Middle,
    /// The last (one-sided, backward): what a live stream has for its newest state.
    Last,
}

/// Weights of the positions at three points with steps `h1`, `h2` between
/// them for the first derivative at one of them: the derivative of the
/// quadratic through the three points, so exact for quadratics (error O(h²)).
/// The bag reader and the node's live streams both use it.
pub fn three_point(h1: f64, h2: f64, at: At) -> [f64; 3] {
    let h = h1 + h2;
    match at {
        At::First => [-(2.0 * h1 + h2) / (h1 * h), h / (h1 * h2), -h1 / (h2 * h)],
        At::Middle => [-h2 / (h1 * h), (h2 - h1) / (h1 * h2), h1 / (h2 * h)],
        At::Last => [h2 / (h1 * h), -h / (h1 * h2), (2.0 * h2 + h1) / (h2 * h)],
    }
}

/// The Verlet difference with the mean step, after checking the steps are
/// uniform (the errors name what is wrong).
fn uniform_difference(tr: &Trajectory) -> Result<Vec<Vec<f64>>, DataError> {
    let err = |m: String| Err(DataError::Trajectory(format!("trajectory {}: {m}", tr.id)));
    let s = &tr.samples;
    let m = s.len();
    if m < 3 {
        return err(format!(
            "{m} samples without recorded accelerations; finite differences need at least 3"
        ));
    }
    let dt = (s[m - 1].t - s[0].t) / (m - 1) as f64;
    if !(dt.is_finite() && dt > 0.0) {
        return err(format!("time step {dt} is not positive"));
    }
    for k in 1..m {
        let d = s[k].t - s[k - 1].t;
        if !d.is_finite() || (d - dt).abs() > DT_REL_TOL * dt {
            return err(format!(
                "time step between samples {} and {k} is {d}, but the mean step is {dt}: finite differences need a uniform step",
                k - 1
            ));
        }
    }
    Ok((1..m - 1)
        .map(|k| {
            let (qp, q, qn) = (&s[k - 1].state.q, &s[k].state.q, &s[k + 1].state.q);
            (0..q.len())
                .map(|i| (qn[i] + qp[i] - 2.0 * q[i]) / (dt * dt))
                .collect()
        })
        .collect())
}

/// SHA-256 of a file's bytes, lower-case hex (identifies the bag a model was trained on).
pub fn digest(path: impl AsRef<Path>) -> Result<String, DataError> {
    let path = path.as_ref();
    let mut file = std::fs::File::open(path).map_err(|e| DataError::io(path, "opening", e))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = match file.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(DataError::io(path, "reading", e)),
        };
        hasher.update(&buf[..n]);
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}
