//! How well an ensemble's spread predicts its error (`evaluate --json`'s
//! `calibration`): the mean spread and error at a few leads, the Spearman
//! rank correlation between spread and realised error at lead 1 s over the
//! evaluated starts, and the fraction of states whose error lies within two
//! spreads.
//!
//! Per particle and kept state, the spread is the members' standard
//! deviation of position (√ of the mean over axes of the variance,
//! [`crate::dynamics::Spread`]) and the error is in the same units: √ of the
//! mean over axes of the squared position error of the mean prediction.

use crate::system::State;
use serde::Serialize;

/// Leads (seconds after the start) at which spread and error are reported,
/// those the trajectories reach.
pub const LEADS: [f64; 6] = [0.1, 0.5, 1.0, 2.0, 5.0, 10.0];

/// The lead of the Spearman correlation, seconds.
pub const SPEARMAN_LEAD: f64 = 1.0;

/// One evaluated start: per kept state its time after the start, and per
/// particle the error and the spread.
#[derive(Clone, Debug, Default)]
pub struct Sample {
    lead: Vec<f64>,
    error: Vec<Vec<f64>>,
    spread: Vec<Vec<f64>>,
}

impl Sample {
    /// The errors of `pred` against `truth` (kept states at `times`, the
    /// start first) beside `spread`, for particles of `dim` coordinates.
    pub fn new(
        dim: usize,
        times: &[f64],
        truth: &[State],
        pred: &[State],
        spread: &[Vec<f64>],
    ) -> Self {
        let d = dim.max(1);
        let k = times
            .len()
            .min(truth.len())
            .min(pred.len())
            .min(spread.len());
        let t0 = times.first().copied().unwrap_or(0.0);
        let error = (0..k)
            .map(|s| {
                truth[s]
                    .q
                    .chunks(d)
                    .zip(pred[s].q.chunks(d))
                    .map(|(a, b)| {
                        let sq: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
                        (sq / d as f64).sqrt()
                    })
                    .collect()
            })
            .collect();
        Self {
            lead: times[..k].iter().map(|t| t - t0).collect(),
            error,
            spread: spread[..k].to_vec(),
        }
    }

    /// The kept state nearest `lead` seconds, if the sample reaches it
    /// (within half a kept interval).
    fn at(&self, lead: f64) -> Option<usize> {
        let step = self.lead.get(1).copied().unwrap_or(0.0);
        let (i, t) = self
            .lead
            .iter()
            .enumerate()
            .min_by(|a, b| (a.1 - lead).abs().total_cmp(&(b.1 - lead).abs()))?;
        (i > 0 && (t - lead).abs() <= 0.5 * step + 1e-9).then_some(i)
    }
}

/// Mean spread and mean error at one lead, over starts and particles.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct LeadSpread {
    /// Seconds after the start.
    pub lead: f64,
    /// The members' mean spread.
    pub mean_spread: f64,
    /// The mean error of the mean prediction.
    pub mean_error: f64,
}

/// The calibration figures of an evaluation.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Calibration {
    /// Ensemble members (1: a single model, whose spread is 0).
    pub members: usize,
    /// Starts whose rollouts enter these figures (driven and diverged ones
    /// do not).
    pub starts: usize,
    /// Mean spread and error at the [`LEADS`] the trajectories reach.
    pub spread_at_leads: Vec<LeadSpread>,
    /// Spearman rank correlation over the starts between the mean spread at
    /// lead 1 s and the error there (root mean square over particles);
    /// `None` with fewer than 3 starts reaching 1 s, or when either side is
    /// constant (a single model's spread).
    pub spearman_spread_error_1s: Option<f64>,
    /// Per start reaching 1 s, its mean spread and error there (what the
    /// Spearman correlation ranks), so that evaluations can be pooled.
    pub spread_error_1s: Vec<[f64; 2]>,
    /// Fraction of (kept state after the start, particle) whose error is at
    /// most two spreads.
    pub within_2_spreads: Option<f64>,
}

impl Calibration {
    /// The figures of `samples` from a model of `members` members.
    pub fn new(members: usize, samples: &[Sample]) -> Self {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let spread_at_leads = LEADS
            .iter()
            .filter_map(|&lead| {
                let (mut s, mut e) = (vec![], vec![]);
                for x in samples {
                    if let Some(i) = x.at(lead) {
                        s.extend_from_slice(&x.spread[i]);
                        e.extend_from_slice(&x.error[i]);
                    }
                }
                (!s.is_empty()).then(|| LeadSpread {
                    lead,
                    mean_spread: mean(&s),
                    mean_error: mean(&e),
                })
            })
            .collect();
        let (mut s1, mut e1) = (vec![], vec![]);
        for x in samples {
            if let Some(i) = x.at(SPEARMAN_LEAD) {
                s1.push(mean(&x.spread[i]));
                let sq: Vec<f64> = x.error[i].iter().map(|e| e * e).collect();
                e1.push(mean(&sq).sqrt());
            }
        }
        let spearman_spread_error_1s = (s1.len() >= 3).then(|| spearman(&s1, &e1)).flatten();
        let spread_error_1s = s1.iter().zip(&e1).map(|(s, e)| [*s, *e]).collect();
        let (mut within, mut all) = (0usize, 0usize);
        for x in samples {
            for (e, s) in x.error.iter().zip(&x.spread).skip(1) {
                all += e.len();
                within += e.iter().zip(s).filter(|(e, s)| **e <= 2.0 * **s).count();
            }
        }
        Self {
            members,
            starts: samples.len(),
            spread_at_leads,
            spearman_spread_error_1s,
            spread_error_1s,
            within_2_spreads: (all > 0).then(|| within as f64 / all as f64),
        }
    }
}

/// Ranks from 1, ties given the average of the ranks they span.
pub fn ranks(x: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..x.len()).collect();
    order.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    let mut out = vec![0.0; x.len()];
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && x[order[j + 1]] == x[order[i]] {
            j += 1;
        }
        let rank = (i + j) as f64 / 2.0 + 1.0;
        for &k in &order[i..=j] {
            out[k] = rank;
        }
        i = j + 1;
    }
    out
}

/// Spearman's rank correlation: Pearson's correlation of the ranks (ties by
/// average rank). `None` when the lengths differ, there are fewer than two
/// values, or either side is constant.
pub fn spearman(x: &[f64], y: &[f64]) -> Option<f64> {
    if x.len() != y.len() || x.len() < 2 {
        return None;
    }
    let (rx, ry) = (ranks(x), ranks(y));
    let n = x.len() as f64;
    let (mx, my) = (rx.iter().sum::<f64>() / n, ry.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in rx.iter().zip(&ry) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    (sxx > 0.0 && syy > 0.0).then(|| sxy / (sxx * syy).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ties_get_the_average_rank() {
        assert_eq!(ranks(&[10.0, 20.0, 10.0, 5.0]), vec![2.5, 4.0, 2.5, 1.0]);
    }

    #[test]
    fn spearman_of_monotone_and_reversed_orders() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        let up = [1.0, 4.0, 9.0, 16.0, 100.0];
        let down = [5.0, 3.0, 2.0, 1.0, 0.0];
        assert!((spearman(&x, &up).unwrap() - 1.0).abs() < 1e-12);
        assert!((spearman(&x, &down).unwrap() + 1.0).abs() < 1e-12);
        assert_eq!(spearman(&x, &[1.0; 5]), None, "constant side");
        assert_eq!(spearman(&x, &up[..3]), None, "lengths differ");
    }

    #[test]
    fn spearman_with_ties_matches_the_textbook_value() {
        // Ranks x: 1, 2.5, 2.5, 4; y: 1, 2, 3, 4. Pearson of the ranks:
        // Σ dx·dy = 4.5, Σ dx² = 4.5, Σ dy² = 5, so 4.5 / √22.5 = 0.94868...
        let r = spearman(&[1.0, 2.0, 2.0, 3.0], &[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert!((r - 4.5 / 22.5f64.sqrt()).abs() < 1e-12, "{r}");
    }

    #[test]
    fn calibration_counts_errors_within_two_spreads() {
        let st = |x: f64| State {
            q: vec![x, 0.0],
            v: vec![0.0, 0.0],
        };
        // One particle in 2D, errors 0.1·i/√2 at lead i·0.5 s; spread 0.1.
        let samples: Vec<Sample> = (1..=4)
            .map(|k| {
                let times: Vec<f64> = (0..4).map(|i| 0.5 * f64::from(i)).collect();
                let truth: Vec<State> = (0..4).map(|_| st(0.0)).collect();
                let pred: Vec<State> = (0..4).map(|i| st(0.1 * f64::from(i * k))).collect();
                let spread = vec![vec![0.05 * f64::from(k)]; 4];
                Sample::new(2, &times, &truth, &pred, &spread)
            })
            .collect();
        let c = Calibration::new(3, &samples);
        assert_eq!(c.starts, 4);
        assert_eq!(c.spread_at_leads.len(), 2, "0.5 s and 1 s are reached");
        assert_eq!(c.spread_error_1s.len(), 4, "one pair per start");
        assert!((c.spearman_spread_error_1s.unwrap() - 1.0).abs() < 1e-12);
        // error i·k·0.1/√2 <= 2·0.05·k ⇔ i <= √2: only i = 1 of 1..=3.
        assert!((c.within_2_spreads.unwrap() - 1.0 / 3.0).abs() < 1e-12);
    }
}
