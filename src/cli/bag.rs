//! `mcgnode bag info` and `mcgnode bag repair`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::data::bag::{read_bags, scan_input, ReadOptions};
use crate::data::source::{bag_parts, Storage};

/// Options of `bag`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    #[command(subcommand)]
    command: BagCommand,
}

#[derive(clap::Subcommand, Debug, Clone)]
enum BagCommand {
    /// Print each bag's files, topics with message counts, and its
    /// ParticleState trajectories: systems, particles, states, duration and
    /// the field the messages state.
    Info(InfoArgs),
    /// Rewrite a bag cut short by a crash (no summary, footer or end magic, a
    /// torn last record) as a complete, indexed MCAP: every message up to the
    /// last whole record is kept, in order. Like `ros2 bag reindex`.
    Repair(RepairArgs),
}

/// Options of `bag info`.
#[derive(clap::Args, Debug, Clone)]
pub struct InfoArgs {
    /// Bags: MCAP files, rosbag2 directories or .db3 files.
    #[arg(required = true)]
    pub paths: Vec<PathBuf>,
    /// The ParticleState topic to describe, when a bag holds several.
    #[arg(long)]
    pub topic: Option<String>,
}

/// Options of `bag repair`.
#[derive(clap::Args, Debug, Clone)]
pub struct RepairArgs {
    /// The damaged MCAP file.
    pub input: PathBuf,
    /// Where to write the repaired MCAP (must differ from the input).
    pub output: PathBuf,
}

/// Runs `bag`.
pub fn run(a: Args) -> Result<()> {
    match a.command {
        BagCommand::Info(a) => info(a),
        BagCommand::Repair(a) => repair(a),
    }
}

/// Per system name: trajectories, particle counts, dimensions, states,
/// longest span in seconds.
type SystemSummary = (usize, Vec<usize>, Vec<usize>, usize, f64);

fn info(a: InfoArgs) -> Result<()> {
    for path in &a.paths {
        println!("{}", path.display());
        for part in bag_parts(path)? {
            let storage = match part.storage {
                Storage::Mcap => "mcap",
                Storage::Sqlite3 => "sqlite3",
            };
            let mut how = vec![storage.to_string()];
            if let Some(c) = part.file_compression {
                how.push(format!("file compression {}", c.name()));
            }
            if let Some(c) = part.message_compression {
                how.push(format!("message compression {}", c.name()));
            }
            println!("  file: {} ({})", part.path.display(), how.join(", "));
        }
        // topic -> (type, count, first, last log time)
        let mut topics: BTreeMap<String, (String, usize, u64, u64)> = BTreeMap::new();
        scan_input(path, |m| {
            let e = topics
                .entry(m.topic.to_string())
                .or_insert_with(|| (m.schema_name.to_string(), 0, u64::MAX, 0));
            e.1 += 1;
            e.2 = e.2.min(m.log_time);
            e.3 = e.3.max(m.log_time);
            Ok(())
        })
        .with_context(|| format!("reading {}", path.display()))?;
        let (first, last) = topics
            .values()
            .fold((u64::MAX, 0), |(a, b), t| (a.min(t.2), b.max(t.3)));
        let total: usize = topics.values().map(|t| t.1).sum();
        println!(
            "  messages: {total}, duration: {:.3} s",
            if total == 0 {
                0.0
            } else {
                (last - first) as f64 * 1e-9
            }
        );
        println!("  topics:");
        for (t, (ty, n, _, _)) in &topics {
            println!("    {t}  {ty}  {n} messages");
        }
        let bag = read_bags(
            std::slice::from_ref(path),
            &ReadOptions {
                topic: a.topic.clone(),
            },
        )?;
        if bag.trajectories.is_empty() {
            println!("  no ParticleState trajectories");
            continue;
        }
        println!("  ParticleState topic: {}", bag.topic);
        let mut systems: BTreeMap<String, SystemSummary> = BTreeMap::new();
        for tr in &bag.trajectories {
            let name = if tr.system.is_empty() {
                "(unnamed)".to_string()
            } else {
                tr.system.clone()
            };
            let e = systems.entry(name).or_default();
            e.0 += 1;
            if !e.1.contains(&tr.graph.n()) {
                e.1.push(tr.graph.n());
            }
            if !e.2.contains(&tr.graph.dim) {
                e.2.push(tr.graph.dim);
            }
            e.3 += tr.samples.len();
            e.4 = e.4.max(tr.samples.last().map_or(0.0, |s| s.t));
        }
        println!("  systems:");
        for (name, (n, parts, dims, states, span)) in &systems {
            let list = |v: &[usize]| {
                v.iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join("/")
            };
            println!(
                "    {name}: {n} trajectories, {} particles, {}D, {states} states, longest {span:.3} s",
                list(parts),
                list(dims)
            );
        }
        let field = match &bag.field {
            None => "unknown (the messages do not state it)".to_string(),
            Some(f) if f.is_free() => "none (closed when there are no anchors)".to_string(),
            Some(f) => format!(
                "gravity {} along -y, drag {}, force {:?}",
                f.gravity, f.drag, f.force
            ),
        };
        println!("  field: {field}");
        if !bag.derived_velocities.is_empty() {
            println!(
                "  velocities: derived from positions and stamps (position-only) in {} trajectories",
                bag.derived_velocities.len()
            );
        }
        if !bag.metadata.is_empty() {
            let keys: Vec<&str> = bag.metadata.keys().map(String::as_str).collect();
            println!("  mcgnode metadata: {}", keys.join(", "));
        }
    }
    Ok(())
}

fn repair(a: RepairArgs) -> Result<()> {
    let r = crate::data::repair::repair(&a.input, &a.output)?;
    println!(
        "kept {} messages on {} channels and {} metadata records; wrote {}",
        r.messages,
        r.channels,
        r.metadata,
        a.output.display()
    );
    if r.stopped.is_empty() {
        println!("the input was complete");
    } else {
        println!("reading stopped {}", r.stopped);
    }
    Ok(())
}
