//! `mcgnode demo`: the embedded default, no ROS needed. Simulates 5-spring
//! training data, trains GNODE and MCGNODE side by side (one per core), and
//! evaluates both on held-out 5-, 20- and 50-spring bags.

use super::simulate::simulate_to;
use crate::data::bag::read_trajectories;
use crate::evaluate::{evaluate, table, EvalOptions};
use crate::kernel::TrainedModel;
use crate::model::Variant;
use crate::physics::{SystemConfig, SystemKind};
use crate::train::{train_from_bags, ModelOptions, TrainConfig};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// Options of `demo`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Small and fast (about a minute): fewer trajectories and epochs.
    #[arg(long)]
    pub quick: bool,
    /// Output folder for bags, models, plots and the JSON summary.
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// Training epochs (default: 1500, quick: 60).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Seed of the training data (test data uses seed + 1000).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs `demo`.
pub fn run(a: Args) -> Result<()> {
    let t0 = std::time::Instant::now();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let (n_train, n_test, epochs) = if a.quick {
        (20, 10, 60)
    } else {
        (100, 100, 1500)
    };
    let epochs = a.epochs.unwrap_or(epochs);
    let train_bag = a.out.join("train-5-spring.mcap");
    let cfg = SystemConfig::new(SystemKind::Spring, 5);
    simulate_to(&cfg, n_train, a.seed, &train_bag)?;
    eprintln!(
        "[{:5.1} s] simulated {n_train} training trajectories: {}",
        t0.elapsed().as_secs_f64(),
        train_bag.display()
    );
    let sizes = [5usize, 20, 50];
    let mut tests = vec![];
    for &n in &sizes {
        let mut c = SystemConfig::new(SystemKind::Spring, n);
        c.states = 201; // 20 s, the paper's spring evaluation horizon
        let p = a.out.join(format!("test-{n}-spring.mcap"));
        simulate_to(&c, n_test, a.seed + 1000, &p)?;
        tests.push((n, p));
    }
    eprintln!(
        "[{:5.1} s] simulated {n_test} test trajectories of 5, 20 and 50 springs (20 s each)",
        t0.elapsed().as_secs_f64()
    );
    let cfg = TrainConfig {
        epochs,
        patience: epochs,
        seed: a.seed,
        // The two trainings run side by side.
        threads: (crate::engine::all_cores() / 2).max(1),
        ..TrainConfig::default()
    };
    let variants = [Variant::Gnode, Variant::Mcgnode];
    let results: Vec<Result<PathBuf>> = std::thread::scope(|s| {
        let handles: Vec<_> = variants
            .iter()
            .map(|&v| {
                let (cfg, train_bag, out) = (cfg.clone(), train_bag.clone(), a.out.clone());
                s.spawn(move || -> Result<PathBuf> {
                    let every = (cfg.epochs / 5).max(1);
                    let f = train_from_bags(
                        v,
                        &[train_bag],
                        &ModelOptions::default(),
                        &cfg,
                        |m| eprintln!("[{v}] {m}"),
                        |r| {
                            if r.epoch % every == 0 {
                                eprintln!(
                                    "[{v}] epoch {}/{}  train {:.3e}  val {:.3e}  ({:.0} s)",
                                    r.epoch, r.epochs, r.train_loss, r.validation_loss, r.elapsed
                                );
                            }
                            true
                        },
                    )?;
                    let p = out.join(format!("{v}-5-spring.json"));
                    f.save(&p)?;
                    Ok(p)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("training thread panicked"))
            .collect()
    });
    let mut models = vec![];
    for (v, r) in variants.iter().zip(results) {
        let p = r?;
        models.push((*v, TrainedModel::load(&p)?));
    }
    eprintln!(
        "[{:5.1} s] trained GNODE and MCGNODE ({epochs} epochs each)",
        t0.elapsed().as_secs_f64()
    );
    let mut panels = vec![];
    let mut json = vec![];
    for (n, p) in &tests {
        let bag = read_trajectories(p)?;
        let mut curves = vec![];
        for (v, m) in &models {
            let e = evaluate(
                m,
                &m.file.trained_on.start_fingerprints,
                &bag,
                &EvalOptions::default(),
            )?;
            println!("{}", table(&e, 6));
            json.push(serde_json::json!({
                "model": v.name(), "particles": n,
                "averages": e.averages,
                "rollout_seconds": e.rollout_seconds,
            }));
            curves.push((v.name().to_string(), e.summary));
        }
        panels.push((format!("{n}-spring"), curves));
    }
    let plot = a.out.join("demo.png");
    crate::plot::plot_summaries(&plot, &panels)?;
    std::fs::write(
        a.out.join("demo.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    println!(
        "demo done in {:.0} s: plot {}, summary {}",
        t0.elapsed().as_secs_f64(),
        plot.display(),
        a.out.join("demo.json").display()
    );
    Ok(())
}
