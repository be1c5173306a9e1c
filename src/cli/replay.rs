//! `mcgnode replay`.

use std::path::PathBuf;

use anyhow::{Context, Result};

use super::field::{check_fits, FieldArgs};
use crate::data::bag::{read_bags, ReadOptions};
use crate::data::stream::{Smoother, StreamOptions, SMOOTHERS};
use crate::replay::{replay, table, ReplayOptions};

/// Options of `replay`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Bag(s) of ParticleState messages, each an MCAP file, a rosbag2
    /// directory or a .db3 file: simulated, or recorded by the node (its
    /// prediction topics are ignored).
    #[arg(long, required = true, num_args = 1..)]
    pub bag: Vec<PathBuf>,
    /// The ParticleState topic to read, when a bag holds several.
    #[arg(long)]
    pub topic: Option<String>,
    /// Model: a trained model file, or truth:spring / truth:pendulum.
    #[arg(long)]
    pub model: String,
    /// Print one JSON document on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write a PNG of RE, EE and ME against lead time (geometric mean, 95% band).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Longest lead time, seconds (default: the recording node's horizon × dt,
    /// else 10 recorded intervals).
    #[arg(long)]
    pub horizon: Option<f64>,
    /// Largest integration step, seconds (default: the bag's simulator step,
    /// else the recording node's dt, else the interval of the header stamps).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Lead-time grid points (default: one per recorded interval when stamps
    /// are regular, else 20); each comparison goes to the nearest.
    #[arg(long)]
    pub bins: Option<usize>,
    #[command(flatten)]
    pub field: FieldArgs,
    /// Replay at most this many trajectories.
    #[arg(long)]
    pub trajectories: Option<usize>,
    /// Use every N-th recorded state as a start (long recordings).
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Rows of the printed table.
    #[arg(long, default_value_t = 11)]
    pub rows: usize,
    /// Start from positions only, velocities estimated from the states
    /// before as the node estimates them for a position-only stream (the
    /// bag's velocities ignored); position-only bags are always replayed so.
    #[arg(long)]
    pub positions_only: bool,
    /// Velocity estimate for those starts, as the node's velocity_smoother:
    /// none (three-point difference at the newest state), poly (fit over
    /// the last --smoother-window states) or model (the start of those
    /// states fitted through the model's own rollout; GNODE-family models).
    #[arg(long, default_value = "none", value_parser = clap::builder::PossibleValuesParser::new(SMOOTHERS))]
    pub smoother: String,
    /// States in a poly or model smoother's fit.
    #[arg(long, default_value_t = 15)]
    pub smoother_window: usize,
    /// Degree of a poly smoother's polynomial.
    #[arg(long, default_value_t = 2)]
    pub smoother_order: usize,
    /// Score against this bag's states instead (same trajectories and
    /// stamps): e.g. the noise-free recording a noisy bag was made from.
    #[arg(long)]
    pub reference: Option<PathBuf>,
}

/// Runs `replay`.
pub fn run(a: Args) -> Result<()> {
    let model = crate::models::load_model(&a.model.parse()?)?;
    let bag = read_bags(
        &a.bag,
        &ReadOptions {
            topic: a.topic.clone(),
        },
    )
    .context("reading the bag")?;
    let field = a.field.field()?;
    if let Some(t) = model.trained_for() {
        check_fits(t, &bag, field.as_ref())?;
        super::field::warn_out_of_range(t, &bag, "recorded");
    }
    let opts = ReplayOptions {
        dt: a.dt,
        horizon: a.horizon,
        bins: a.bins,
        field,
        max_trajectories: a.trajectories,
        stride: a.stride,
        positions_only: a.positions_only,
        stream: StreamOptions {
            smoother: Smoother::new(&a.smoother, a.smoother_window, a.smoother_order)?,
            max_gap: 0.0,
        },
        reference: match &a.reference {
            Some(p) => Some(
                crate::data::read_trajectories(p)
                    .with_context(|| format!("reading the reference bag {}", p.display()))?,
            ),
            None => None,
        },
    };
    let r = replay(model.as_ref(), &bag, &opts)?;
    if let Some(p) = &a.plot {
        let title = format!(
            "{}-particle {} replay (x: lead time)",
            r.particles,
            if r.system.is_empty() {
                "system"
            } else {
                &r.system
            }
        );
        let name = model.describe();
        let name = name.split(" (").next().unwrap_or("model").to_string();
        crate::plot::plot_summaries(p, &[(title, vec![(name, r.summary.clone())])])?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", table(&r, a.rows));
        if let Some(p) = &a.plot {
            println!("plot: {}", p.display());
        }
    }
    Ok(())
}
