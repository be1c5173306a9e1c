//! `mcgnode reproduce`: every experiment of the paper (Bishnoi et al.) from
//! one command, written to `DIR/report.md` with PNG figures, `results.json`,
//! and the bags and model files it made (`DIR/data`, `DIR/models`).
//!
//! Each experiment goes the way a user would: simulate → bag → train → model
//! file → evaluate; [`scale::Scale`] sets how big (full or `--quick`).

mod claims;
pub mod experiments;
pub mod lab;
pub mod mpc;
mod part;
pub mod report;
pub mod scale;

pub use part::Part;

use crate::error::{Context, Result};
use crate::names::Named;
use experiments::Section;
use lab::Lab;
use report::Row;
use scale::Scale;
use std::path::PathBuf;
use std::time::Instant;

/// What to run.
#[derive(Clone, Debug)]
pub struct Options {
    /// Output folder.
    pub out: PathBuf,
    /// Sizes and epochs.
    pub scale: Scale,
    /// Worker threads for independent trainings and evaluations.
    pub threads: usize,
    /// The command line that started the run, for the report (absolute
    /// paths are shortened to their last component: [`shown_command`]).
    pub command: String,
    /// The parts to run, in this order (default: [`Part::ALL`]).
    pub parts: Vec<Part>,
    /// Take up every training from its checkpoint in `checkpoints/` (a run
    /// stopped part-way goes on; finished trainings are not repeated);
    /// without it, checkpoints of earlier runs are removed first.
    pub resume: bool,
}

/// A command line as the report shows it: the program as `mcgnode` and
/// every other absolute path by its last component, so that a report names
/// no folder of the machine it ran on.
pub fn shown_command(args: &[String]) -> String {
    let short = |a: &String| {
        let p = std::path::Path::new(a);
        if p.is_absolute() {
            p.file_name()
                .map_or_else(|| a.clone(), |f| f.to_string_lossy().into_owned())
        } else {
            a.clone()
        }
    };
    args.iter()
        .enumerate()
        .map(|(i, a)| {
            if i == 0 {
                "mcgnode".to_string()
            } else {
                short(a)
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// The outcome of a run.
pub struct Outcome {
    /// The report's path.
    pub report: PathBuf,
    /// Every evaluation.
    pub rows: Vec<Row>,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Runs the chosen parts and writes the report, rewritten after each part
/// so that a long run that is stopped keeps what it finished.
pub fn run(opts: &Options, log: &(dyn Fn(&str) + Sync)) -> Result<Outcome> {
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("creating {}", opts.out.display()))?;
    // LGN and HGN need candle's grad-of-grad; candle fixes the setting per
    // thread at its first backward pass, so it is set before any thread starts.
    crate::baselines::autodiff::request_second_order();
    let lab = Lab {
        dir: opts.out.clone(),
        threads: opts.threads.max(1),
        log,
        t0: Instant::now(),
        resume: opts.resume,
    };
    let mut sections: Vec<Section> = vec![];
    let mut report = opts.out.join("report.md");
    for (i, part) in opts.parts.iter().enumerate() {
        lab.say(&format!("experiment: {part}"));
        sections.push(
            part.run(&lab, &opts.scale)
                .with_context(|| format!("experiment {part}"))?,
        );
        report = write_report(opts, &lab, &sections, &opts.parts[i + 1..])?;
    }
    Ok(Outcome {
        report,
        rows: sections.iter().flat_map(|s| s.rows.clone()).collect(),
        seconds: lab.t0.elapsed().as_secs_f64(),
    })
}

/// The report's title, the run's command, scale and duration, and the metrics' definitions.
fn report_header(opts: &Options, lab: &Lab, seconds: f64, pending: &[Part]) -> String {
    let sc = &opts.scale;
    let names = |ps: &[Part]| {
        ps.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut md = String::from("# mcgnode reproduction report\n\n");
    md += &format!(
        "Command: `{}` — scale **{}**, {} worker threads, {} in {:.0} s \
         ({:.1} min) on {} cores. Parts: {}. Every number below was measured in this run; the \
         bags and model files it made are in `data/` and `models/`, every evaluation in \
         `results.json`.\n\n",
        opts.command,
        sc.name,
        lab.threads,
        if pending.is_empty() {
            "finished"
        } else {
            "so far"
        },
        seconds,
        seconds / 60.0,
        std::thread::available_parallelism().map_or(1, std::num::NonZero::get),
        names(&opts.parts),
    );
    if !pending.is_empty() {
        md += &format!("**Partial report**: still to run: {}.\n\n", names(pending));
    }
    if opts.resume {
        md += "**Resumed** (`--resume`): the duration above is this session's; trainings went \
               on from their checkpoints in `checkpoints/`, and their training seconds (and \
               the time budgets derived from them) count every session.\n\n";
    }
    md += "Metrics (paper's definitions): RE = ‖q̂ − q‖/(‖q̂‖ + ‖q‖), EE the same for the \
           Hamiltonian, ME for the total momentum; ME scaled = ‖P̂ − P‖/(Σm|v̂| + Σm|v|) \
           (meaningful when the true momentum is zero, as for our spring starts). \
           Figures: geometric mean over test trajectories with the band where 95 % of them \
           lie. Tables: the time average of the geometric-mean curve (t > 0). A rollout that \
           diverges scores the worst value from then on (relative errors 1).\n\n";
    md
}

/// Writes report.md and results.json from the sections so far; `pending`
/// are the parts still to run (named in the report while it is partial).
fn write_report(
    opts: &Options,
    lab: &Lab,
    sections: &[Section],
    pending: &[Part],
) -> Result<PathBuf> {
    let sc = &opts.scale;
    let seconds = lab.t0.elapsed().as_secs_f64();
    let rows: Vec<Row> = sections.iter().flat_map(|s| s.rows.clone()).collect();
    let names = |ps: &[Part]| {
        ps.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut md = report_header(opts, lab, seconds, pending);
    md += "## What the paper claims, and what we measured\n\n";
    let trained: Vec<&(String, Result<lab::Trained>)> =
        sections.iter().flat_map(|s| s.trained.iter()).collect();
    md += &claims::claims(&opts.parts, &rows, &trained);
    let left_out: Vec<Part> = Part::ALL
        .iter()
        .filter(|p| !opts.parts.contains(p))
        .copied()
        .collect();
    if !left_out.is_empty() {
        md += &format!(
            "- Not run (`--only`): {}; their claims have no result.\n",
            names(&left_out)
        );
    }
    md += "\n";
    for s in sections {
        md += &s.markdown;
        md += "\n";
    }
    md += "## Settings\n\n```json\n";
    md += &serde_json::to_string_pretty(sc)?;
    md += "\n```\n";
    let report = opts.out.join("report.md");
    std::fs::write(&report, md).with_context(|| format!("writing {}", report.display()))?;
    let training: Vec<serde_json::Value> = sections
        .iter()
        .flat_map(|s| s.trained.iter())
        .map(|(label, t)| match t {
            Ok(t) => serde_json::json!({"model": label, "training": t.report}),
            Err(e) => serde_json::json!({"model": label, "error": format!("{e:#}")}),
        })
        .collect();
    let json = serde_json::json!({
        "scale": sc,
        "parts": opts.parts.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "pending": pending.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "seconds": seconds,
        "evaluations": rows,
        "training": training,
    });
    crate::gnode::file::write_json_atomic(&opts.out.join("results.json"), &json)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shown_command_names_no_folder_of_the_machine() {
        let args: Vec<String> = [
            "/work/main/target/release/mcgnode",
            "reproduce",
            "--out",
            "/work/runs/repro",
            "--epochs",
            "10",
            "rel/dir",
        ]
        .iter()
        .map(ToString::to_string)
        .collect();
        assert_eq!(
            shown_command(&args),
            "mcgnode reproduce --out repro --epochs 10 rel/dir"
        );
    }

    #[test]
    fn parts_parse_by_name() {
        assert_eq!("drag-force".parse::<Part>().unwrap(), Part::DragForce);
        let e = "spring".parse::<Part>().unwrap_err().to_string();
        assert!(e.contains("springs, pendulums"), "{e}");
    }
}
