//! `mcgnode demo`: the embedded default, no ROS needed. A small scale of
//! reproduce's zero-shot experiment, on the same [`Lab`]: simulates 5-spring
//! training data, trains GNODE and MCGNODE side by side, and evaluates both
//! on held-out 5-, 20- and 50-spring bags.

use crate::evaluate::table;
use crate::gnode::Variant;
use crate::models::ModelKind;
use crate::physics::{SystemConfig, SystemKind};
use crate::reproduce::lab::{Lab, TrainSpec, Trained};
use crate::train::{ModelOptions, Recipe, TrainConfig};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Options of `demo`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Small and fast (about 20 s): fewer trajectories and epochs.
    #[arg(long)]
    pub quick: bool,
    /// Output folder: demo.png, demo.json, data/ (bags), models/.
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// Training epochs (default: 1500, quick: 60).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Seed of the training data (test data uses seed + 1000).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Instead: closed-loop control of a chain held by a gripper (the
    /// ground truth is the world, a model trained on random gripper motions
    /// plans): success rate, final distance and planning time per control
    /// step of MCGNODE, GNODE, the true physics and doing nothing, over 20
    /// seeded targets (4 with --quick), into DIR/mpc.json and DIR/mpc.png.
    #[arg(long)]
    pub mpc: bool,
    /// With --mpc: the world's springs get this stiffness instead of the
    /// training data's 500; the learned planners still plan as if it were
    /// 500 (the true physics knows the world's).
    #[arg(long, requires = "mpc")]
    pub held_out_stiffness: Option<f64>,
    /// With --mpc: also train an MCGNODE ensemble (--ensemble members) and
    /// plan on its mean without (`mcgnode_ensemble`) and with this risk
    /// weight on its spread (`mcgnode_risk`; see `plan --risk`); several
    /// weights, comma-separated, give one planner each (`mcgnode_risk_<w>`).
    #[arg(long, value_delimiter = ',', requires = "mpc")]
    pub risk: Vec<f64>,
    /// Members of the --risk ensemble.
    #[arg(long, default_value_t = 5, requires = "mpc")]
    pub ensemble: usize,
}

/// Test sizes: the training size and two zero-shot ones.
const SIZES: [usize; 3] = [5, 20, 50];
const VARIANTS: [Variant; 2] = [Variant::Gnode, Variant::Mcgnode];

/// Runs `demo`.
pub fn run(a: Args) -> Result<()> {
    let lab = Lab {
        dir: a.out.clone(),
        threads: VARIANTS.len(),
        log: &|m| eprintln!("{m}"),
        t0: std::time::Instant::now(),
        resume: false,
    };
    if a.mpc {
        return mpc(&lab, &a);
    }
    let (n_train, n_test, epochs) = if a.quick {
        (20, 10, 60)
    } else {
        (100, 100, 1500)
    };
    let epochs = a.epochs.unwrap_or(epochs);
    let (train, tests) = simulate(&lab, a.seed, n_train, n_test)?;
    let models = train_models(&lab, &train, epochs, a.seed)?;
    let (mut panels, mut json) = (vec![], vec![]);
    for (n, bag) in SIZES.iter().zip(&tests) {
        let mut curves = vec![];
        for (v, m) in VARIANTS.iter().zip(&models) {
            let e = lab.evaluate(&m.path, bag, None, n_test)?;
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
    let summary = a.out.join("demo.json");
    std::fs::write(&summary, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", summary.display()))?;
    println!(
        "demo done in {:.0} s: plot {}, summary {}",
        lab.t0.elapsed().as_secs_f64(),
        plot.display(),
        summary.display()
    );
    Ok(())
}

/// `demo --mpc`: runs the closed-loop experiment and prints its table.
fn mpc(lab: &Lab, a: &Args) -> Result<()> {
    let o = crate::reproduce::mpc::MpcOptions {
        held_out_stiffness: a.held_out_stiffness,
        risk: a.risk.clone(),
        ensemble: a.ensemble,
        ..crate::reproduce::mpc::MpcOptions::plain(a.quick, a.seed)
    };
    let r = crate::reproduce::mpc::run(lab, &o)?;
    println!(
        "{:<16} {:>8} {:>15} {:>18}",
        "planner", "success", "final distance", "ms per step"
    );
    for (name, p) in &r.planners {
        println!(
            "{name:<16} {:>7.0}% {:>15.3} {:>18.1}",
            100.0 * p.success_rate,
            p.final_distance,
            1e3 * p.seconds_per_step
        );
    }
    println!(
        "wrote {} and {}",
        a.out.join("mpc.json").display(),
        a.out.join("mpc.png").display()
    );
    Ok(())
}

/// Simulates the training bag (`n_train` trajectories of 5 springs) and one
/// test bag per size in [`SIZES`] (`n_test` trajectories of 20 s each).
fn simulate(
    lab: &Lab,
    seed: u64,
    n_train: usize,
    n_test: usize,
) -> Result<(PathBuf, Vec<PathBuf>)> {
    let train = lab.bag(
        "train-5-spring",
        &SystemConfig::new(SystemKind::Spring, 5),
        n_train,
        seed,
        false,
    )?;
    let mut tests = vec![];
    for n in SIZES {
        let mut c = SystemConfig::new(SystemKind::Spring, n);
        c.states = 201; // 20 s, the paper's spring evaluation horizon
        tests.push(lab.bag(&format!("test-{n}-spring"), &c, n_test, seed + 1000, false)?);
    }
    lab.say(&format!(
        "simulated {n_train} training trajectories of 5 springs and {n_test} test trajectories \
         of 5, 20 and 50 springs (20 s each)"
    ));
    Ok((train, tests))
}

/// Trains the [`VARIANTS`] side by side on `train`.
fn train_models(lab: &Lab, train: &Path, epochs: usize, seed: u64) -> Result<Vec<Trained>> {
    let specs: Vec<TrainSpec> = VARIANTS
        .iter()
        .map(|&v| TrainSpec {
            label: format!("{v}-5-spring"),
            kind: ModelKind::Family(v),
            bags: vec![train.to_path_buf()],
            cfg: TrainConfig {
                epochs,
                patience: epochs,
                seed,
                // The trainings run side by side.
                threads: (crate::engine::all_cores() / VARIANTS.len()).max(1),
                ..TrainConfig::default()
            },
            opts: ModelOptions::for_recipe(Recipe::Paper),
        })
        .collect();
    let models = lab
        .train_all(&specs)
        .into_iter()
        .collect::<crate::Result<Vec<_>>>()?;
    lab.say(&format!("trained GNODE and MCGNODE ({epochs} epochs each)"));
    Ok(models)
}
