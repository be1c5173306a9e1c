//! The binned statistics: every (start, lead) pair's errors streamed into
//! the nearest grid point, as the log-scale mean and band
//! [`crate::metrics::summarize`] defines, without keeping the pairs.

use crate::metrics::{floored_ln, log_band};

/// Streaming mean and variance (Welford) of the log of one metric.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct LogStats {
    n: usize,
    mean: f64,
    m2: f64,
    pub(super) max: f64,
}

impl LogStats {
    pub(super) fn push(&mut self, x: f64) {
        self.max = self.max.max(x);
        let l = floored_ln(x);
        self.n += 1;
        let d = l - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (l - self.mean);
    }

    /// (geometric mean, lo, hi) as [`crate::metrics::summarize`] defines them.
    pub(super) fn band(&self) -> (f64, f64, f64) {
        let var = if self.n > 1 {
            self.m2 / (self.n - 1) as f64
        } else {
            0.0
        };
        log_band(self.mean, var)
    }
}

/// Everything that fell on one grid point.
#[derive(Clone, Debug, Default)]
pub(super) struct Bin {
    /// RE, EE, ME, ME scaled.
    pub(super) stats: [LogStats; 4],
    pub(super) lead_sum: f64,
}

impl Bin {
    pub(super) fn push(&mut self, lead: f64, errors: [f64; 4]) {
        self.lead_sum += lead;
        for (s, e) in self.stats.iter_mut().zip(errors) {
            // A non-finite error (an overflowing prediction) counts at its limit, 1.
            s.push(if e.is_finite() { e } else { 1.0 });
        }
    }

    pub(super) fn count(&self) -> usize {
        self.stats[0].n
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::{summarize, ErrorCurves};

    /// The streaming band must be what `summarize` computes from whole curves.
    #[test]
    fn streaming_band_matches_summarize() {
        let vals = [
            [0.1, 0.2, 0.0, 3e-5],
            [0.5, 1e-7, 0.3, 2e-4],
            [0.02, 0.7, 0.9, 1.0],
        ];
        let curves: Vec<ErrorCurves> = vals
            .iter()
            .map(|v| ErrorCurves {
                t: vec![1.0],
                re: vec![v[0]],
                ee: vec![v[1]],
                me: vec![v[2]],
                me_scaled: vec![v[3]],
                re_abs: vec![0.0],
                me_abs: vec![0.0],
            })
            .collect();
        let want = summarize(&curves).unwrap();
        let mut bin = Bin::default();
        for v in vals {
            bin.push(1.0, v);
        }
        let bands = [&want.re, &want.ee, &want.me, &want.me_scaled];
        for (b, stats) in bands.iter().zip(&bin.stats) {
            let (g, lo, hi) = stats.band();
            for (x, y) in [(g, b.gmean[0]), (lo, b.lo[0]), (hi, b.hi[0])] {
                assert!((x - y).abs() <= 1e-12 * y.abs(), "{x} vs {y}");
            }
        }
        let mut one = LogStats::default();
        one.push(0.25);
        assert_eq!(
            one.band(),
            (0.25f64.ln().exp(), 0.25f64.ln().exp(), 0.25f64.ln().exp())
        );
    }
}
