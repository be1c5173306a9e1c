//! Stored frames (positions only) as samples: what both importers do with
//! datasets that keep no velocities.

use crate::periodic::PeriodicBox;
use crate::system::{Sample, State};

/// Samples `dt` apart from position frames (flat, `dim` per particle), each
/// with the backward-difference velocity (q_t − q_{t−1}) / dt (the first
/// takes the forward one, (q_1 − q_0) / dt), each difference the minimum
/// image in `periodic`. Needs at least two frames.
pub fn samples_from_frames<F: AsRef<[f64]>>(
    frames: &[F],
    dim: usize,
    dt: f64,
    periodic: Option<&PeriodicBox>,
) -> Vec<Sample> {
    (0..frames.len())
        .map(|t| {
            let (a, b) = if t == 0 { (0, 1) } else { (t - 1, t) };
            let (qa, qb) = (frames[a].as_ref(), frames[b].as_ref());
            let mut v: Vec<f64> = qb.iter().zip(qa).map(|(x, y)| x - y).collect();
            if let Some(pb) = periodic {
                v.chunks_mut(dim.max(1)).for_each(|c| pb.min_image(c));
            }
            v.iter_mut().for_each(|x| *x /= dt);
            Sample {
                t: t as f64 * dt,
                state: State {
                    q: frames[t].as_ref().to_vec(),
                    v,
                },
                acc: None,
            }
        })
        .collect()
}
