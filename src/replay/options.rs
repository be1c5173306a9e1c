//! What a replay is asked for: [`ReplayOptions`] and their limits.

use crate::data::bag::Bag;
use crate::data::stream::StreamOptions;
use crate::physics::Field;

/// Grid points used when the bag's stamps are irregular and no `bins` is given.
pub const DEFAULT_IRREGULAR_BINS: usize = 20;
/// Default horizon, in recorded intervals, for bags that do not say the node's.
pub const DEFAULT_HORIZON_INTERVALS: f64 = 10.0;
/// Largest number of grid points accepted.
pub const MAX_BINS: usize = 100_000;
/// Replay settings; `Default` takes everything from the bag.
#[derive(Clone, Debug, Default)]
pub struct ReplayOptions {
    /// Largest integration step, seconds. Default: the bag's simulator step
    /// (`system_config`), else the recording node's `dt` metadata, else the
    /// interval of evenly spaced header stamps.
    pub dt: Option<f64>,
    /// Longest lead time, seconds. Default: the recording node's horizon × dt
    /// (its metadata), else [`DEFAULT_HORIZON_INTERVALS`] median recorded
    /// intervals.
    pub horizon: Option<f64>,
    /// Lead-time grid points after lead 0 (spacing horizon / bins). Default:
    /// one per recorded interval when the stamps are regular (no binning at
    /// all), else [`DEFAULT_IRREGULAR_BINS`].
    pub bins: Option<usize>,
    /// Field for the energy error. Default: the bag's
    /// ([`crate::data::field::bag_field`]); refused when it cannot be known.
    pub field: Option<Field>,
    /// Replay at most this many trajectories (the first ones, by id).
    pub max_trajectories: Option<usize>,
    /// Use every `stride`-th recorded state as a start (0 and 1: all).
    pub stride: usize,
    /// Start from positions only, with velocities estimated causally from
    /// the states before (the node's rule for position-only streams,
    /// [`crate::data::stream`]), even where the bag records velocities.
    /// Position-only trajectories are always started this way.
    pub positions_only: bool,
    /// How those velocities are estimated.
    pub stream: StreamOptions,
    /// Score against this bag's states (same trajectory ids and stamps, e.g.
    /// the noise-free recording of a noisy one) instead of the replayed
    /// bag's own.
    pub reference: Option<Bag>,
}
