//! `mcgnode replay`.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::data::bag::{read_bags, ReadOptions};
use crate::evaluate::field_from_flags;
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
    /// Gravity for the energy error (with --drag, replaces the bag's field;
    /// the one not given is 0). Default: what the bag's messages or
    /// system_config state, else a closed system when the data show one, else
    /// refused.
    #[arg(long)]
    pub gravity: Option<f64>,
    /// Linear drag for the energy error (see --gravity).
    #[arg(long)]
    pub drag: Option<f64>,
    /// The system is closed (no gravity, drag or force): for bags that do
    /// not state their field.
    #[arg(long)]
    pub closed: bool,
    /// Replay at most this many trajectories.
    #[arg(long)]
    pub trajectories: Option<usize>,
    /// Use every N-th recorded state as a start (long recordings).
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Rows of the printed table.
    #[arg(long, default_value_t = 11)]
    pub rows: usize,
}

/// Runs `replay`.
pub fn run(a: Args) -> Result<()> {
    let model = crate::models::load_model(&a.model)?;
    let bag = read_bags(
        &a.bag,
        &ReadOptions {
            topic: a.topic.clone(),
        },
    )
    .context("reading the bag")?;
    let field = field_from_flags(a.gravity, a.drag, a.closed)?;
    if let Some(t) = model.trained_for() {
        let data_field = crate::data::field::bag_field(&bag, field.as_ref())?.map(|o| o.field);
        crate::compat::check_bag(t, &bag, data_field.as_ref())?;
    }
    let opts = ReplayOptions {
        dt: a.dt,
        horizon: a.horizon,
        bins: a.bins,
        field,
        max_trajectories: a.trajectories,
        stride: a.stride,
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
