//! Replay: feed every recorded state of a bag through a model, as the node
//! would receive it, and score the predictions against the states recorded
//! after it: RE, EE and ME (the paper's metrics, [`crate::metrics`]) as a
//! function of *lead time* (how far ahead the prediction looks).
//!
//! For each start state k the model is rolled out from the recorded state to
//! the times of the following recorded states up to `horizon` seconds later.
//! Each gap between recorded times is cut into equal steps no longer than
//! `dt`, so the rollout lands exactly on every recorded time: irregular stamps
//! work. Bags recorded by the node (inputs plus prediction topics) and
//! simulated bags both work: only `ParticleState` messages are read.
//!
//! Summary over start states: every (start, lead) pair goes to the nearest
//! point of a lead-time grid (spacing `bin_width`), and each grid point gets
//! the geometric mean and 95% band of its errors, exactly as
//! [`crate::metrics::summarize`] defines them, computed streaming (a long node
//! recording can have millions of pairs). Grid points no pair fell on are
//! left out. The grid starts with lead 0 (errors exactly 0), as
//! [`evaluate`](mod@crate::evaluate)'s curves start with t = 0, so
//! `Summary::time_average` skips it the same way.

//!
//! The stages, one file each: [`ReplayOptions`] (`options.rs`), the settings
//! resolved from them and the bag (`settings.rs`), each trajectory's starts
//! rolled out and their errors binned (`trajectory.rs`, into `bins.rs`), the
//! [`ReplayReport`] built from the bins (`report.rs`), and its text
//! [`table`] (`table.rs`).

mod bins;
mod options;
mod report;
mod settings;
mod table;
mod trajectory;

pub use options::{ReplayOptions, DEFAULT_HORIZON_INTERVALS, DEFAULT_IRREGULAR_BINS, MAX_BINS};
pub use report::{ReplayReport, Worst};
pub use table::table;

use std::time::Instant;

use crate::data::bag::Bag;
use crate::data::stream::Smoother;
use crate::data::stream::StreamOptions;
use crate::dynamics::{Dynamics, Timing};
use crate::error::{bail, Context as _, Result};
use crate::metrics::StillReference;
use crate::system::Trajectory;

use bins::Bin;
use settings::resolve;
use trajectory::{reference_for, replay_trajectory};

/// Replays `bag` through `model`: every recorded state (every `stride`-th) is
/// a start, every later recorded state within the horizon a comparison.
///
/// Errors (never panics) on a bag without `ParticleState` trajectories, a
/// graph the model cannot take, bad options, or when no state has a later
/// one within the horizon.
pub fn replay(model: &dyn Dynamics, bag: &Bag, opts: &ReplayOptions) -> Result<ReplayReport> {
    let mut report = replay_model(model, bag, opts)?;
    let reference = crate::dynamics::Still;
    if model.describe() != reference.describe() {
        // Standing still has no rollout to fit through: with the model
        // smoother it starts from the window's degree-2 fit, the positions
        // the model's fit starts from (it predicts no motion, so velocities
        // do not matter).
        let mut still_opts = opts.clone();
        if let Smoother::Model { window } = opts.stream.smoother {
            still_opts.stream.smoother = Smoother::Poly { window, order: 2 };
        }
        let still = replay_model(&reference, bag, &still_opts)?;
        report.still = Some(StillReference::new(&still.summary, report.averages.re));
    }
    Ok(report)
}

/// [`replay`] without the reference.
fn replay_model(model: &dyn Dynamics, bag: &Bag, opts: &ReplayOptions) -> Result<ReplayReport> {
    let started = Instant::now();
    let trajs: Vec<&Trajectory> = bag
        .trajectories
        .iter()
        .take(opts.max_trajectories.unwrap_or(usize::MAX))
        .collect();
    if trajs.is_empty() {
        bail!("the bag has no ParticleState messages (no trajectories to replay)");
    }
    let p = resolve(bag, &trajs, opts)?;
    let mut bins = vec![Bin::default(); p.bins + 1];
    let mut report = ReplayReport::new(model.describe(), bag, &trajs, &p, opts);
    for tr in &trajs {
        let truth = opts
            .reference
            .as_ref()
            .map(|r| reference_for(r, tr))
            .transpose()?;
        let causal = opts.positions_only || bag.derived_velocities.contains(&tr.id);
        replay_trajectory(
            model,
            tr,
            truth,
            (causal, &opts.stream),
            &p,
            opts.stride.max(1),
            &mut bins,
            &mut report,
        )?;
    }
    if report.starts == 0 {
        bail!(
            "no recorded state has a later one within the horizon ({} s): nothing to compare",
            p.horizon
        );
    }
    report.summarize(&bins, p.bin_width);
    report.seconds = started.elapsed().as_secs_f64();
    Ok(report)
}

/// Reads the bag at `path` and replays it (what the node's Replay service
/// does with its current model); the error names the file.
pub fn replay_bag(
    model: &dyn Dynamics,
    path: &std::path::Path,
    opts: &ReplayOptions,
) -> Result<ReplayReport> {
    let bag = crate::data::read_trajectories(path)
        .with_context(|| format!("reading bag {}", path.display()))?;
    replay(model, &bag, opts)
}

/// What the node's Replay service does: replays the bag at `path` through
/// `model` the way the node predicts (integration steps of
/// [`Timing::step`], its horizon of steps of `dt` ahead) and returns the
/// report with its JSON encoding.
pub fn replay_as_node(
    model: &dyn Dynamics,
    path: &str,
    timing: Timing,
) -> Result<(ReplayReport, String)> {
    replay_as_node_with(model, path, timing, StreamOptions::default())
}

/// [`replay_as_node`] with the node's stream settings (how it estimates
/// the velocities of position-only states).
pub fn replay_as_node_with(
    model: &dyn Dynamics,
    path: &str,
    timing: Timing,
    stream: StreamOptions,
) -> Result<(ReplayReport, String)> {
    if path.trim().is_empty() {
        bail!("no bag given: set `bag` to the path of an MCAP file");
    }
    let opts = ReplayOptions {
        dt: Some(timing.step()),
        horizon: Some(timing.horizon as f64 * timing.dt),
        stream,
        ..ReplayOptions::default()
    };
    let report = replay_bag(model, std::path::Path::new(path), &opts)?;
    let json = serde_json::to_string(&report).context("encoding the replay report")?;
    Ok((report, json))
}
