//! `mcgnode reproduce`: every experiment of the paper, one report.

use crate::names::Named;
use crate::reproduce::{run as run_all, scale::Scale, shown_command, Options, Part};
use anyhow::Result;
use std::path::PathBuf;

/// Options of `reproduce`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Output folder: report.md, PNG figures, results.json, data/ (bags), models/.
    #[arg(long)]
    pub out: PathBuf,
    /// Toy scale (about 20 s on 2 cores, against 74 min for the full run): tiny data and epochs, same experiments and report.
    #[arg(long)]
    pub quick: bool,
    /// Epochs of every model (full defaults: 2000 for the GNODE family, 200 for the baseline comparison, noise and data efficiency, 300 for the peridynamic solid; paper: 10000).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Epochs of MCGNODE, LGN, HGN and GNS in the equal-epoch comparison only, after --epochs (LGN and HGN cost 20x MCGNODE per epoch; the equal-wall-clock comparison gives them MCGNODE's time).
    #[arg(long)]
    pub comparison_epochs: Option<usize>,
    /// Epochs of the peridynamic cube's models, after --epochs (a cube epoch of MCGNODE costs about 0.4 s on 2 cores, 50x a 5-spring epoch; GNS trains for the seconds MCGNODE took).
    #[arg(long)]
    pub peridynamic_epochs: Option<usize>,
    /// Parts to run, comma-separated, in this order (default: all): springs, pendulums, peridynamic, drag-force, noise, data-efficiency, contacts.
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<Part>,
    /// Go on with a run stopped part-way in the same --out folder, with the
    /// same options: every training resumes from its checkpoint in
    /// checkpoints/ (finished ones are not repeated; training seconds count
    /// every session). Without it, old checkpoints are removed.
    #[arg(long)]
    pub resume: bool,
    /// Trainings and evaluations run side by side (default: the number of cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Runs `reproduce`.
pub fn run(a: Args) -> Result<()> {
    let mut scale = if a.quick {
        Scale::quick()
    } else {
        Scale::full()
    };
    if let Some(e) = a.epochs {
        if e == 0 {
            anyhow::bail!("--epochs must be at least 1");
        }
        scale = scale.with_epochs(e);
    }
    if let Some(e) = a.comparison_epochs {
        if e == 0 {
            anyhow::bail!("--comparison-epochs must be at least 1");
        }
        scale.epochs = e;
    }
    if let Some(e) = a.peridynamic_epochs {
        if e == 0 {
            anyhow::bail!("--peridynamic-epochs must be at least 1");
        }
        scale.peri_epochs = e;
    }
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, std::num::NonZero::get));
    let opts = Options {
        out: a.out.clone(),
        scale,
        threads,
        resume: a.resume,
        command: shown_command(&std::env::args().collect::<Vec<_>>()),
        parts: if a.only.is_empty() {
            Part::ALL.to_vec()
        } else {
            let mut parts: Vec<Part> = vec![];
            for p in a.only {
                if !parts.contains(&p) {
                    parts.push(p);
                }
            }
            parts
        },
    };
    let outcome = run_all(&opts, &|m| eprintln!("{m}"))?;
    let failed = outcome.rows.iter().filter(|r| r.error.is_some()).count();
    println!(
        "reproduce done in {:.0} s: {} ({} evaluations{})",
        outcome.seconds,
        outcome.report.display(),
        outcome.rows.len(),
        if failed > 0 {
            format!(", {failed} failed: see the report")
        } else {
            String::new()
        }
    );
    Ok(())
}
