//! `mcgnode bench`.

use anyhow::Result;

/// Options of `bench`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Fewer repeats and steps (seconds instead of a minute).
    #[arg(long)]
    pub quick: bool,
    /// Print one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
    /// Only the figures whose name contains this text (case-insensitive),
    /// e.g. `hgn`, `cube`, `rollout`.
    #[arg(long, value_name = "TEXT")]
    pub only: Option<String>,
}

/// Runs `bench`.
pub fn run(a: Args) -> Result<()> {
    let figs = crate::bench::run_all(a.quick, a.only.as_deref())?;
    if figs.is_empty() {
        anyhow::bail!(
            "no figure's name contains {:?}; run `mcgnode bench` without --only to list them",
            a.only.unwrap_or_default()
        );
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&figs)?);
        return Ok(());
    }
    println!("{:<50} {:>14}  unit", "measure (median)", "mcgnode");
    for f in figs {
        println!("{:<50} {:>14.4}  {}", f.name, f.value, f.unit);
    }
    // The authors' JAX code is timed beside these only by the harness, in the
    // same run: a figure from another hour or machine compares nothing.
    println!("against the authors' JAX code: scripts/bench_vs_reference.sh REF_DIR");
    Ok(())
}
