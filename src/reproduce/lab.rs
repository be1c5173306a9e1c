//! The bench every experiment works on: bags in `data/`, model files in
//! `models/`, figures in the output folder; jobs spread over a few threads.
//! Each step goes through the same public path as the command line:
//! simulate → bag → train → model file → evaluate. Trainings save checkpoints
//! in `checkpoints/`, so a stopped run can be resumed.

use crate::data::bag::read_trajectories;
use crate::error::{Context, Result};
use crate::evaluate::{evaluate, EvalOptions, Evaluation};
use crate::gnode::file::TrainingReport;
use crate::models::{load_any_model, train_any_from_bags, ModelKind, ModelRef};
use crate::physics::SystemConfig;
use crate::simulate::{simulate_with, DataIntegrator};
use crate::train::{Checkpointing, ModelOptions, TrainConfig};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

/// Where and how experiments run.
pub struct Lab<'a> {
    /// Output folder.
    pub dir: PathBuf,
    /// Worker threads for independent jobs.
    pub threads: usize,
    /// Progress lines.
    pub log: &'a (dyn Fn(&str) + Sync),
    /// Start of the run.
    pub t0: Instant,
    /// Take up trainings from their checkpoints (`checkpoints/<label>.json`);
    /// when false, a checkpoint left by an earlier run is removed first.
    pub resume: bool,
}

/// Seconds between checkpoint saves of a training.
const CHECKPOINT_EVERY: f64 = 120.0;

/// A job for [`Lab::pool`].
pub type Job<'s, T> = Box<dyn FnOnce() -> Result<T> + Send + 's>;

/// A trained model on disk.
#[derive(Clone, Debug)]
pub struct Trained {
    /// Label in tables and figures.
    pub label: String,
    /// The model file.
    pub path: PathBuf,
    /// Its training figures.
    pub report: TrainingReport,
}

/// What to train.
#[derive(Clone, Debug)]
pub struct TrainSpec {
    /// Label, also the model file's stem.
    pub label: String,
    /// Model.
    pub kind: ModelKind,
    /// Training bags.
    pub bags: Vec<PathBuf>,
    /// Training settings.
    pub cfg: TrainConfig,
    /// Architecture options (GNODE family).
    pub opts: ModelOptions,
}

impl Lab<'_> {
    /// Prints a progress line with the elapsed time.
    pub fn say(&self, m: &str) {
        (self.log)(&format!("[{:6.0} s] {m}", self.t0.elapsed().as_secs_f64()));
    }

    /// Simulates `trajectories` trajectories into `data/<name>.mcap` (RK4 on
    /// (q, p) when `rk4`, for HGN), with the configuration in the metadata.
    pub fn bag(
        &self,
        name: &str,
        cfg: &SystemConfig,
        trajectories: usize,
        seed: u64,
        rk4: bool,
    ) -> Result<PathBuf> {
        let dir = self.dir.join("data");
        std::fs::create_dir_all(&dir)?;
        let path = dir.join(format!("{name}.mcap"));
        let integrator = if rk4 {
            DataIntegrator::Rk4
        } else {
            DataIntegrator::Verlet
        };
        simulate_with(cfg, integrator, trajectories, seed, &path)?;
        Ok(path)
    }

    /// Trains one model into `models/<label>.json`.
    pub fn train(&self, spec: &TrainSpec) -> Result<Trained> {
        let dir = self.dir.join("models");
        std::fs::create_dir_all(&dir)?;
        let path = dir.join(format!("{}.json", spec.label));
        let every = (spec.cfg.epochs / 4).max(1);
        let checkpoint = self
            .dir
            .join("checkpoints")
            .join(format!("{}.json", spec.label));
        if !self.resume {
            match std::fs::remove_file(&checkpoint) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(e).with_context(|| {
                        format!("removing the old checkpoint {}", checkpoint.display())
                    })
                }
                _ => {}
            }
        }
        // An ensemble's members are trained one after another without
        // checkpoints (a checkpoint holds one run).
        let cfg = TrainConfig {
            checkpoint: (spec.cfg.ensemble <= 1).then_some(Checkpointing {
                path: checkpoint,
                every: CHECKPOINT_EVERY,
            }),
            ..spec.cfg.clone()
        };
        let report = train_any_from_bags(
            spec.kind,
            &spec.bags,
            &spec.opts,
            &cfg,
            |_| {},
            |r| {
                if r.epoch % every == 0 {
                    self.say(&format!(
                        "{}: epoch {}/{}, validation MSE {:.3e}",
                        spec.label, r.epoch, r.epochs, r.validation_loss
                    ));
                }
                true
            },
            &path,
        )
        .with_context(|| format!("training {}", spec.label))?;
        Ok(Trained {
            label: spec.label.clone(),
            path,
            report,
        })
    }

    /// Trains all specs on the pool; a failure is kept per model.
    pub fn train_all(&self, specs: &[TrainSpec]) -> Vec<Result<Trained>> {
        let jobs: Vec<Job<'_, Trained>> = specs
            .iter()
            .map(|s| Box::new(move || self.train(s)) as Job<'_, Trained>)
            .collect();
        self.pool(jobs)
    }

    /// Evaluates a model file on a bag (at most `max` trajectories, step `dt`
    /// when given, else the bag's).
    pub fn evaluate(
        &self,
        model: &Path,
        bag: &Path,
        dt: Option<f64>,
        max: usize,
    ) -> Result<Evaluation> {
        let m = load_any_model(&ModelRef::from_path(model)?)?;
        let b = read_trajectories(bag)?;
        evaluate(
            m.dynamics.as_ref(),
            &m.start_fingerprints,
            &b,
            &EvalOptions {
                dt,
                max_trajectories: Some(max),
                // The tables here report RE/EE/ME only: keep Sinkhorn cheap.
                sinkhorn_particles: Some(256),
                ..EvalOptions::default()
            },
        )
        .with_context(|| format!("evaluating {} on {}", model.display(), bag.display()))
    }

    /// Runs jobs on [`Lab::threads`] threads (in order of submission), one
    /// result per job in the same order. A panicking job becomes an error.
    pub fn pool<T: Send>(&self, jobs: Vec<Job<'_, T>>) -> Vec<Result<T>> {
        let n = jobs.len();
        let queue = Mutex::new(jobs.into_iter().enumerate().collect::<Vec<_>>());
        let results: Mutex<Vec<Option<Result<T>>>> = Mutex::new((0..n).map(|_| None).collect());
        std::thread::scope(|s| {
            for _ in 0..self.threads.clamp(1, n.max(1)) {
                s.spawn(|| loop {
                    let next = {
                        let mut q = queue
                            .lock()
                            .unwrap_or_else(std::sync::PoisonError::into_inner);
                        if q.is_empty() {
                            None
                        } else {
                            Some(q.remove(0))
                        }
                    };
                    let Some((i, job)) = next else { break };
                    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(job))
                        .unwrap_or_else(|_| Err(crate::error::err!("job panicked")));
                    results
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)[i] = Some(r);
                });
            }
        });
        results
            .into_inner()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .into_iter()
            .map(|r| r.unwrap_or_else(|| Err(crate::error::err!("job did not run"))))
            .collect()
    }
}
