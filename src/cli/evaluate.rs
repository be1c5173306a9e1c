//! `mcgnode evaluate`.

use super::field::{check_fits, FieldArgs};
use crate::data::bag::{read_bags, ReadOptions};
use crate::evaluate::{evaluate, table, EvalOptions};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// Options of `evaluate`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Trained model file (GNODE family or baseline).
    #[arg(long)]
    pub model: PathBuf,
    /// Test bag(s): each an MCAP file, a rosbag2 directory or a .db3 file
    /// (several: `--bag A B` or repeated). Each trajectory's first state is the
    /// rollout's start, the rest the truth.
    #[arg(long, required = true, num_args = 1..)]
    pub bag: Vec<PathBuf>,
    /// The ParticleState topic to read, when a bag holds several.
    #[arg(long)]
    pub topic: Option<String>,
    #[command(flatten)]
    pub field: FieldArgs,
    /// Print one JSON document on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write a PNG of RE, EE and ME against time (geometric mean, 95% band).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Integration step (default: the bag's simulator step, else the interval
    /// of its header stamps).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Evaluate at most this many trajectories.
    #[arg(long)]
    pub trajectories: Option<usize>,
    /// Rows of the printed table.
    #[arg(long, default_value_t = 11)]
    pub rows: usize,
    /// Evaluate even if test trajectories start where training ones did.
    #[arg(long)]
    pub allow_overlap: bool,
    /// Particle spacing of the E_kin metric (volume dx^d per particle, as
    /// LagrangeBench); default: the bag metadata's `dx`, else 1.
    #[arg(long)]
    pub dx: Option<f64>,
    /// Compute the Sinkhorn metric on this many evenly strided particles
    /// (the same ones in truth and prediction) instead of all: it costs
    /// O(N²) per iteration. Default: all particles.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub sinkhorn_particles: Option<u64>,
}

/// Runs `evaluate`.
pub fn run(a: Args) -> Result<()> {
    let reference = crate::models::ModelRef::from_path(&a.model)?;
    let model = crate::models::load_any_model(&reference)?;
    let bag = read_bags(
        &a.bag,
        &ReadOptions {
            topic: a.topic.clone(),
        },
    )
    .context("reading the test bag")?;
    let flag_field = a.field.field()?;
    // Refuse data the model was not trained for (dimension, edges, field).
    let trained = crate::models::trained_for(&reference)?;
    check_fits(&trained, &bag, flag_field.as_ref())?;
    super::field::warn_out_of_range(&trained, &bag, "test");
    let opts = EvalOptions {
        dt: a.dt,
        field: flag_field,
        max_trajectories: a.trajectories,
        allow_overlap: a.allow_overlap,
        dx: a.dx,
        sinkhorn_particles: a.sinkhorn_particles.map(|k| k as usize),
    };
    let e = evaluate(
        model.dynamics.as_ref(),
        &model.start_fingerprints,
        &bag,
        &opts,
    )?;
    if let Some(p) = &a.plot {
        let title = format!("{}-particle {}", e.particles, e.system);
        crate::plot::plot_summaries(p, &[(title, vec![(model.name.clone(), e.summary.clone())])])?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&e)?);
    } else {
        print!("{}", table(&e, a.rows.max(2)));
        if let Some(p) = &a.plot {
            println!("plot: {}", p.display());
        }
    }
    Ok(())
}
