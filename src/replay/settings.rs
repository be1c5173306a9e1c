//! The first stage: the settings a replay runs with (step, horizon, lead-time
//! grid, energy field), resolved from the options and the bag.

use crate::data::bag::Bag;
use crate::data::field::bag_system;
use crate::error::{bail, Result};
use crate::physics::Field;
use crate::system::Trajectory;

use super::options::{ReplayOptions, DEFAULT_HORIZON_INTERVALS, DEFAULT_IRREGULAR_BINS, MAX_BINS};

/// The settings a replay runs with, resolved from the options and the bag.
pub(super) struct Settings {
    pub(super) dt: f64,
    pub(super) dt_source: String,
    pub(super) horizon: f64,
    pub(super) horizon_source: String,
    pub(super) bin_width: f64,
    pub(super) bins: usize,
    pub(super) regular: bool,
    pub(super) field: Field,
    pub(super) field_source: String,
}

fn positive(x: f64, what: &str) -> Result<f64> {
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        bail!("{what} must be a positive finite number, got {x}")
    }
}

pub(super) fn resolve(bag: &Bag, trajs: &[&Trajectory], opts: &ReplayOptions) -> Result<Settings> {
    let sys = bag_system(bag)?;
    let meta = bag.meta()?;
    let node_dt = meta.node_dt;
    let (dt, dt_source) = match (opts.dt, &sys, node_dt) {
        (Some(dt), _, _) => (dt, "option"),
        (None, Some(s), _) => (s.dt, "bag system_config (simulator step)"),
        (None, None, Some(dt)) => (dt, "bag metadata dt (the recording node's step)"),
        (None, None, None) => match crate::data::field::stamp_interval(bag) {
            Some(d) => (d, "the header stamps (their interval)"),
            None => bail!(
                "the bag does not say its integration step (no system_config or dt metadata, \
                 and its stamps are not evenly spaced); pass --dt"
            ),
        },
    };
    let dt = positive(dt, "dt")?;
    let mut intervals: Vec<f64> = trajs
        .iter()
        .flat_map(|t| t.samples.windows(2).map(|w| w[1].t - w[0].t))
        .collect();
    if intervals.is_empty() {
        bail!("no trajectory has two recorded states: nothing to compare a prediction with");
    }
    intervals.sort_by(f64::total_cmp);
    let median = intervals[intervals.len() / 2];
    let (lo, hi) = (intervals[0], intervals[intervals.len() - 1]);
    let regular = hi - lo <= 1e-6 * median;
    let node_horizon = meta.node_horizon.map(f64::from);
    let (horizon, horizon_source) = match (opts.horizon, node_horizon, node_dt) {
        (Some(h), _, _) => (h, "option".to_string()),
        (None, Some(h), Some(d)) => (h * d, "the recording node's horizon × dt".to_string()),
        _ => (
            DEFAULT_HORIZON_INTERVALS * median,
            format!("{DEFAULT_HORIZON_INTERVALS} median recorded intervals"),
        ),
    };
    let horizon = positive(horizon, "horizon")?;
    let (bins, bin_width) = match opts.bins {
        Some(b) if b == 0 || b > MAX_BINS => bail!("bins must be in 1..={MAX_BINS}, got {b}"),
        Some(b) => (b, horizon / b as f64),
        None if regular => {
            // Leads are whole intervals: one grid point each, nothing binned.
            let b = (horizon / median + 1e-6).floor() as usize;
            if b == 0 {
                bail!(
                    "horizon {horizon} s is shorter than the recorded interval {median} s: \
                     no recorded state to compare with"
                );
            }
            (b.min(MAX_BINS), median)
        }
        None => (
            DEFAULT_IRREGULAR_BINS,
            horizon / DEFAULT_IRREGULAR_BINS as f64,
        ),
    };
    let origin = crate::data::field::bag_field(bag, opts.field.as_ref())?
        .ok_or_else(|| crate::data::field::unknown_field_error("the energy error"))?;
    let (field, field_source) = (origin.field, origin.source);
    Ok(Settings {
        dt,
        dt_source: dt_source.into(),
        horizon,
        horizon_source,
        bin_width,
        bins,
        regular,
        field,
        field_source,
    })
}
