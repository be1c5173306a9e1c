//! The model smoother in the node (`velocity_smoother: model`): per stream,
//! the newest state of each incoming position-only state fitted through the
//! served model's rollout over the last `smoother_window` positions
//! ([`crate::estimate`]), warm-started from the stream's previous fit and
//! bounded in iterations and time; and what each fit cost, for
//! `/diagnostics`.

use std::collections::VecDeque;
use std::time::Instant;

use crate::data::stream::History;
use crate::data::DataError;
use crate::dynamics::Dynamics;
use crate::estimate::{FitOptions, ModelFit};
use crate::system::{Graph, State};

/// One stream's fitter, for the model generation and graph it was made for.
pub(super) struct StreamFit {
    generation: u64,
    graph: Graph,
    opts: FitOptions,
    fit: ModelFit,
}

impl std::fmt::Debug for StreamFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamFit")
            .field("generation", &self.generation)
            .field("opts", &self.opts)
            .finish_non_exhaustive()
    }
}

/// The newest state of `history`'s window fitted through `model` (served as
/// `generation`) within `opts` (its step, iterations and time budget); `slot`
/// keeps the stream's fitter (made again when the model, graph or `opts`
/// changed, its
/// warm start forgotten on `reset`). Where the rollout diverges from every
/// start tried, `fallback` (the window's degree-2 fit) stands, as in
/// `replay`. `Err`: the model or graph cannot be fitted through, with the
/// fix.
pub(super) fn fit_newest(
    slot: &mut Option<StreamFit>,
    (model, generation): (&dyn Dynamics, u64),
    graph: &Graph,
    opts: FitOptions,
    history: &History,
    reset: bool,
    fallback: State,
) -> Result<State, DataError> {
    let stale = slot
        .as_ref()
        .is_none_or(|s| s.generation != generation || s.graph != *graph || s.opts != opts);
    if stale {
        let fit = ModelFit::new(model, graph, opts)
            .map_err(|e| DataError::Invalid(format!("velocity_smoother model: {e}")))?;
        *slot = Some(StreamFit {
            generation,
            graph: graph.clone(),
            opts,
            fit,
        });
    }
    let Some(s) = slot.as_mut() else {
        return Ok(fallback);
    };
    if reset {
        s.fit.reset();
    }
    let (stamps, positions) = history.window();
    Ok(s.fit.fit(&stamps, &positions).map_or(fallback, |f| f.state))
}

/// The last fits' costs (wall time per state, milliseconds).
#[derive(Debug, Default)]
pub(super) struct Costs {
    recent: VecDeque<f64>,
    total: u64,
}

/// Fits whose cost is kept for the median and p99 (10 s at 100 Hz).
const KEPT: usize = 1000;

/// Median and p99 of the kept fits' costs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostSummary {
    /// Median, milliseconds.
    pub median_ms: f64,
    /// 99th percentile, milliseconds.
    pub p99_ms: f64,
    /// Fits since the node started.
    pub fits: u64,
}

impl Costs {
    /// Notes a fit that started at `t0`.
    pub(super) fn note(&mut self, t0: Instant) {
        if self.recent.len() >= KEPT {
            self.recent.pop_front();
        }
        self.recent.push_back(t0.elapsed().as_secs_f64() * 1e3);
        self.total += 1;
    }

    /// Over the last fits (up to 1,000); `None` before the first.
    pub(super) fn summary(&self) -> Option<CostSummary> {
        let mut v: Vec<f64> = self.recent.iter().copied().collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Some(CostSummary {
            median_ms: at(0.5),
            p99_ms: at(0.99),
            fits: self.total,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cost_summary_is_the_median_and_p99_of_the_kept_fits() {
        let mut c = Costs::default();
        assert_eq!(c.summary(), None);
        for k in 0..1500 {
            // Older fits than the last 1,000 are forgotten.
            c.recent
                .push_back(if k < 500 { 1e6 } else { f64::from(k - 500) });
            if c.recent.len() > KEPT {
                c.recent.pop_front();
            }
            c.total += 1;
        }
        let s = c.summary().unwrap();
        assert_eq!(s.fits, 1500);
        assert!((s.median_ms - 500.0).abs() <= 1.0, "{s:?}");
        assert!((s.p99_ms - 989.0).abs() <= 1.0, "{s:?}");
        c.note(Instant::now());
        assert_eq!(c.recent.len(), KEPT);
        assert!(c.recent.back().is_some_and(|ms| (0.0..1e3).contains(ms)));
    }
}
