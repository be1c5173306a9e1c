//! Trajectories as a tracker reports them: Gaussian noise on the positions,
//! an uneven rate and dropped states (`mcgnode bag observe`), to measure how
//! predictions from live position-only streams degrade.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::DataError;
use crate::system::{Endpoint, Graph, State, Trajectory};

/// How a trajectory is observed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// Standard deviation of the position noise, as a fraction of the
    /// particle spacing ([`spacing`]); 0: exact positions.
    pub noise: f64,
    /// Keep about every `thin`-th state (1: all).
    pub thin: usize,
    /// Spread of the kept states' spacing: each next one is `thin · (1 ± u)`
    /// states on, u uniform in [0, `uneven`] (0: regular). Positions stay
    /// those of their stamps, so the rate is uneven, not the clock wrong.
    pub uneven: f64,
    /// Probability that a kept state is dropped (a gap).
    pub drop: f64,
    /// Seed of the noise and the choices.
    pub seed: u64,
}

impl Default for Observation {
    fn default() -> Self {
        Observation {
            noise: 0.0,
            thin: 1,
            uneven: 0.0,
            drop: 0.0,
            seed: 1,
        }
    }
}

/// The particle spacing of `graph` at `state`: the median length of its
/// edges between particles, or the median nearest-neighbour distance when it
/// has none (0 for a single particle).
pub fn spacing(graph: &Graph, state: &State) -> f64 {
    let d = graph.dim;
    let at = |i: usize| &state.q[i * d..(i + 1) * d];
    let dist = |a: usize, b: usize| -> f64 {
        at(a)
            .iter()
            .zip(at(b))
            .map(|(x, y)| (x - y) * (x - y))
            .sum::<f64>()
            .sqrt()
    };
    // Edges between particles; a bar to an anchor says nothing of the spacing.
    let mut lengths: Vec<f64> = graph
        .edges
        .iter()
        .filter_map(|e| match e.b {
            Endpoint::Particle(b) => Some(dist(e.a, b)),
            Endpoint::Anchor(_) => None,
        })
        .collect();
    if lengths.is_empty() {
        lengths = (0..graph.n())
            .filter_map(|a| {
                (0..graph.n())
                    .filter(|&b| b != a)
                    .map(|b| dist(a, b))
                    .min_by(f64::total_cmp)
            })
            .collect();
    }
    lengths.sort_by(f64::total_cmp);
    lengths.get(lengths.len() / 2).copied().unwrap_or(0.0)
}

/// `trajectories` as observed by `o`, with the noise's standard deviation in
/// length units (the first trajectory's spacing times `o.noise`).
pub fn observe(
    trajectories: &[Trajectory],
    o: &Observation,
) -> Result<(Vec<Trajectory>, f64), DataError> {
    let bad = |m: String| Err(DataError::Invalid(m));
    if !(o.noise.is_finite() && o.noise >= 0.0) {
        return bad(format!("noise {} must be a finite fraction >= 0", o.noise));
    }
    if o.thin == 0 {
        return bad("thin must be at least 1".into());
    }
    if !(0.0..1.0).contains(&o.uneven) {
        return bad(format!("uneven {} must be in [0, 1)", o.uneven));
    }
    if !(0.0..1.0).contains(&o.drop) {
        return bad(format!("drop {} must be in [0, 1)", o.drop));
    }
    let Some(first) = trajectories
        .first()
        .and_then(|t| Some((t, t.samples.first()?)))
    else {
        return bad("no states to observe".into());
    };
    let sigma = o.noise * spacing(&first.0.graph, &first.1.state);
    let normal = Normal::new(0.0, sigma.max(f64::MIN_POSITIVE))
        .map_err(|e| DataError::Invalid(format!("noise σ = {sigma}: {e}")))?;
    let mut rng = ChaCha8Rng::seed_from_u64(o.seed);
    let mut out = Vec::with_capacity(trajectories.len());
    for tr in trajectories {
        let mut samples = Vec::new();
        let mut k = 0usize;
        while k < tr.samples.len() {
            if o.drop == 0.0 || rng.random::<f64>() >= o.drop {
                let mut s = tr.samples[k].clone();
                if sigma > 0.0 {
                    s.state
                        .q
                        .iter_mut()
                        .for_each(|x| *x += normal.sample(&mut rng));
                }
                s.acc = None;
                samples.push(s);
            }
            let u = if o.uneven > 0.0 {
                rng.random_range(-o.uneven..=o.uneven)
            } else {
                0.0
            };
            k += ((o.thin as f64 * (1.0 + u)).round() as usize).max(1);
        }
        out.push(Trajectory {
            samples,
            ..tr.clone()
        });
    }
    Ok((out, sigma))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{SystemConfig, SystemKind};

    #[test]
    fn noise_thinning_and_drops_are_what_was_asked() {
        let mut cfg = SystemConfig::new(SystemKind::Spring, 5);
        cfg.states = 2001;
        cfg.save_every = 1;
        let g = cfg.graph();
        let tr = cfg.simulate_one(&g, cfg.start_for(&g, 2, 0), 0);
        let space = spacing(&g, &tr.samples[0].state);
        assert!(space > 0.1 && space < 10.0, "{space}");
        let o = Observation {
            noise: 0.01,
            thin: 10,
            uneven: 0.3,
            drop: 0.1,
            seed: 4,
        };
        let (seen, sigma) = observe(std::slice::from_ref(&tr), &o).unwrap();
        assert!((sigma - 0.01 * space).abs() < 1e-15);
        let s = &seen[0].samples;
        // About 2000 / 10 states, 10 % of them dropped.
        assert!((150..200).contains(&s.len()), "{}", s.len());
        let steps: Vec<f64> = s.windows(2).map(|w| w[1].t - w[0].t).collect();
        let (lo, hi) = steps
            .iter()
            .fold((f64::MAX, 0.0f64), |(l, h), &d| (l.min(d), h.max(d)));
        assert!(lo < 0.009 && hi > 0.015, "uneven steps {lo}..{hi}");
        // The noise has the asked spread around the true positions.
        let mut sq = (0.0, 0usize);
        for x in s {
            let k = (x.t / 0.001).round() as usize;
            for (a, b) in x.state.q.iter().zip(&tr.samples[k].state.q) {
                sq = (sq.0 + (a - b).powi(2), sq.1 + 1);
            }
        }
        let rms = (sq.0 / sq.1 as f64).sqrt();
        assert!((rms / sigma - 1.0).abs() < 0.1, "{rms} vs {sigma}");
        let e = observe(&[tr], &Observation { drop: 1.0, ..o }).unwrap_err();
        assert!(e.to_string().contains("drop"), "{e}");
    }
}
