//! Training: MSE on accelerations, Adam, batches of 100, a seeded 75:25 split,
//! early stopping on the validation loss (the best weights are kept).

use crate::data::dataset::Dataset;
use crate::model::batch::Batch;
use crate::model::file::TrainingReport;
use crate::model::params::{ParamStore, Weights};
use crate::model::plan::GraphPlan;
use crate::model::{Hyper, Net};
use crate::system::{Graph, State};
use anyhow::{bail, Result};
use candle_core::Tensor;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

/// Training settings.
#[derive(Clone, Debug)]
pub struct TrainConfig {
    /// Maximum epochs (paper: 10,000).
    pub epochs: usize,
    /// Adam learning rate (paper: 1e-3).
    pub lr: f64,
    /// Batch size (paper: 100).
    pub batch: usize,
    /// Fraction of states held out for validation (paper: 0.25).
    pub validation: f64,
    /// Stop when the validation loss has not improved for this many epochs.
    pub patience: usize,
    /// Seed for initialisation, split and shuffling (and, through distinct
    /// streams, subsampling and noise).
    pub seed: u64,
    /// Gaussian noise on the target accelerations, percent of their standard
    /// deviation (paper's noise experiments: 0, 1, 5, 10). Applied by
    /// [`apply_data_options`].
    pub noise: f64,
    /// Train on a seeded random subset of this many states (paper's
    /// data-efficiency experiments: 100 to 10,000); `None`: all. Applied by
    /// [`apply_data_options`].
    pub points: Option<usize>,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 10_000,
            lr: 1e-3,
            batch: 100,
            validation: 0.25,
            patience: 1_000,
            seed: 0,
            noise: 0.0,
            points: None,
        }
    }
}

/// One epoch's figures, handed to the progress callback.
#[derive(Clone, Debug)]
pub struct EpochReport {
    /// Epoch number, from 1.
    pub epoch: usize,
    /// Epochs asked for.
    pub epochs: usize,
    /// Mean training loss over the epoch's batches.
    pub train_loss: f64,
    /// Validation loss after the epoch.
    pub validation_loss: f64,
    /// Best validation loss so far.
    pub best: f64,
    /// Seconds since training started.
    pub elapsed: f64,
}

/// The result of training.
pub struct Trained {
    /// The model with the best weights.
    pub net: Net,
    /// Figures for the model file.
    pub report: TrainingReport,
}

/// Adam (Kingma & Ba) on flat parameter vectors: cheaper than one candle op per
/// moment update for models with a few hundred parameters.
pub struct Adam {
    lr: f64,
    m: Vec<Vec<f64>>,
    v: Vec<Vec<f64>>,
    t: i32,
}

impl Adam {
    /// Zero moments for the store's parameters.
    pub fn new(lr: f64, store: &ParamStore) -> Self {
        let sizes: Vec<usize> = store.vars().iter().map(|v| v.elem_count()).collect();
        Self {
            lr,
            m: sizes.iter().map(|&n| vec![0.0; n]).collect(),
            v: sizes.iter().map(|&n| vec![0.0; n]).collect(),
            t: 0,
        }
    }

    /// One update from the gradients of a loss (parameters without a gradient
    /// are left alone).
    pub fn step(
        &mut self,
        store: &ParamStore,
        grads: &candle_core::backprop::GradStore,
    ) -> Result<()> {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        const EPS: f64 = 1e-8;
        self.t += 1;
        let c1 = 1.0 - B1.powi(self.t);
        let c2 = 1.0 - B2.powi(self.t);
        for (k, var) in store.vars().iter().enumerate() {
            let Some(g) = grads.get(var) else { continue };
            let g = g.flatten_all()?.to_vec1::<f64>()?;
            let mut p = var.as_tensor().flatten_all()?.to_vec1::<f64>()?;
            let (m, v) = (&mut self.m[k], &mut self.v[k]);
            for i in 0..p.len() {
                m[i] = B1 * m[i] + (1.0 - B1) * g[i];
                v[i] = B2 * v[i] + (1.0 - B2) * g[i] * g[i];
                p[i] -= self.lr * (m[i] / c1) / ((v[i] / c2).sqrt() + EPS);
            }
            var.set(&Tensor::from_vec(p, var.shape(), var.device())?)?;
        }
        Ok(())
    }
}

/// Checks training data against its graph and the settings.
pub fn check_data(
    graph: &Graph,
    states: &[State],
    acc: &[Vec<f64>],
    cfg: &TrainConfig,
) -> Result<()> {
    if states.len() != acc.len() {
        bail!("{} states but {} accelerations", states.len(), acc.len());
    }
    if states.len() < 2 {
        bail!("need at least 2 states to train (got {})", states.len());
    }
    if !(cfg.validation > 0.0 && cfg.validation < 1.0) {
        bail!("validation fraction must be in (0, 1)");
    }
    if cfg.batch == 0 || cfg.epochs == 0 {
        bail!("batch size and epochs must be positive");
    }
    graph.validate().map_err(anyhow::Error::msg)?;
    for (i, (s, a)) in states.iter().zip(acc).enumerate() {
        s.validate(graph)
            .map_err(|e| anyhow::anyhow!("state {i}: {e}"))?;
        if a.len() != graph.ndof() || a.iter().any(|x| !x.is_finite()) {
            bail!("accelerations of state {i} have the wrong size or are not finite");
        }
    }
    Ok(())
}

/// The loop every trainable model shares: a seeded split of `n` samples
/// (validation fraction from `cfg`), shuffled batches, Adam on `store`,
/// validation after every epoch, early stopping; the best weights are loaded
/// back into `store`. `loss(indices)` is the mean loss over those samples;
/// `on_epoch` returns false to cancel.
pub fn fit(
    store: &ParamStore,
    n: usize,
    cfg: &TrainConfig,
    rng: &mut ChaCha8Rng,
    loss: impl Fn(&[usize]) -> Result<Tensor>,
    mut on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<TrainingReport> {
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(rng);
    let n_val = ((n as f64 * cfg.validation).round() as usize).clamp(1, n - 1);
    let (val_idx, train_idx) = order.split_at(n_val);
    let mut train_idx = train_idx.to_vec();
    let validation = |idx: &[usize]| -> Result<f64> {
        let mut total = 0.0;
        for chunk in idx.chunks(1000) {
            total += loss(chunk)?.to_scalar::<f64>()? * chunk.len() as f64;
        }
        Ok(total / idx.len() as f64)
    };
    let mut adam = Adam::new(cfg.lr, store);
    let start = Instant::now();
    let mut best = f64::INFINITY;
    let mut best_weights: Weights = store.weights()?;
    let (mut best_epoch, mut best_train) = (0, f64::NAN);
    let mut epochs_run = 0;
    let mut stopped_early = false;
    for epoch in 1..=cfg.epochs {
        train_idx.shuffle(rng);
        let (mut sum, mut count) = (0.0, 0usize);
        for chunk in train_idx.chunks(cfg.batch) {
            let l = loss(chunk)?;
            let lv = l.to_scalar::<f64>()?;
            if !lv.is_finite() {
                bail!("training diverged at epoch {epoch} (loss {lv})");
            }
            adam.step(store, &l.backward()?)?;
            sum += lv * chunk.len() as f64;
            count += chunk.len();
        }
        let train_loss = sum / count as f64;
        let val = validation(val_idx)?;
        epochs_run = epoch;
        if !val.is_finite() {
            bail!("validation loss is not finite at epoch {epoch}");
        }
        if val < best {
            best = val;
            best_epoch = epoch;
            best_train = train_loss;
            best_weights = store.weights()?;
        }
        let report = EpochReport {
            epoch,
            epochs: cfg.epochs,
            train_loss,
            validation_loss: val,
            best,
            elapsed: start.elapsed().as_secs_f64(),
        };
        if !on_epoch(&report) {
            bail!("training cancelled at epoch {epoch}");
        }
        if epoch - best_epoch >= cfg.patience {
            stopped_early = true;
            break;
        }
    }
    store.load(&best_weights)?;
    Ok(TrainingReport {
        seed: cfg.seed,
        epochs_requested: cfg.epochs,
        epochs_run,
        best_epoch,
        train_loss: best_train,
        validation_loss: best,
        stopped_early,
        seconds: start.elapsed().as_secs_f64(),
        batch: cfg.batch,
        lr: cfg.lr,
        patience: cfg.patience,
        noise: cfg.noise,
        points: cfg.points,
    })
}

/// Mixed into [`TrainConfig::seed`] for the subsample's stream ("points"), so
/// it is independent of initialisation and shuffling.
const POINTS_STREAM: u64 = 0x706f_696e_7473;
/// Mixed into [`TrainConfig::seed`] for the noise stream ("noise").
const NOISE_STREAM: u64 = 0x6e_6f69_7365;

/// Applies the data options of `cfg` to a training set: first the subsample
/// ([`TrainConfig::points`], [`Dataset::subsample`]), then the noise
/// ([`TrainConfig::noise`], [`Dataset::add_noise`]), so the noise scale is
/// that of the data actually trained on. `log` says what was done.
pub fn apply_data_options(
    ds: &mut Dataset,
    cfg: &TrainConfig,
    mut log: impl FnMut(&str),
) -> Result<()> {
    if let Some(points) = cfg.points {
        let total = ds.len();
        ds.subsample(points, cfg.seed ^ POINTS_STREAM)?;
        log(&format!("using {points} of {total} states"));
    }
    let sigma = ds.add_noise(cfg.noise, cfg.seed ^ NOISE_STREAM)?;
    if cfg.noise > 0.0 {
        log(&format!(
            "added {}% noise: σ = {sigma:.3e} to accelerations",
            cfg.noise
        ));
    }
    Ok(())
}

/// Trains a fresh model of `hyper` on states of one graph with their
/// accelerations. `on_epoch` sees every epoch and returns false to cancel.
pub fn train(
    hyper: Hyper,
    graph: &Graph,
    states: &[State],
    acc: &[Vec<f64>],
    cfg: &TrainConfig,
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<Trained> {
    check_data(graph, states, acc, cfg)?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let net = Net::new(hyper, &mut rng)?;
    let plan = GraphPlan::new(graph);
    let loss = |idx: &[usize]| -> Result<Tensor> {
        let s: Vec<&State> = idx.iter().map(|&i| &states[i]).collect();
        let a: Vec<&[f64]> = idx.iter().map(|&i| acc[i].as_slice()).collect();
        net.loss(&Batch::new(&plan, &s, Some(&a), net.hyper.types)?)
    };
    let report = fit(&net.store, states.len(), cfg, &mut rng, loss, on_epoch)?;
    Ok(Trained { net, report })
}

/// Whether MCGNODE learns a body-force branch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BodyForce {
    /// On unless the bag says the system is closed (no field, no anchors).
    Auto,
    /// Always learn body forces.
    On,
    /// Never: internal forces only, momentum conserved exactly.
    Off,
}

/// Architecture choices on top of a variant's paper defaults.
#[derive(Clone, Debug)]
pub struct ModelOptions {
    /// Hidden units of the graph MLPs.
    pub hidden: usize,
    /// Embedding width.
    pub embed: usize,
    /// Message-passing rounds.
    pub rounds: usize,
    /// Body-force branch (MCGNODE).
    pub body_force: BodyForce,
    /// One-hot width; default: largest type in the data + 1.
    pub types: Option<usize>,
    /// The ParticleState topic to train on, when a bag holds several.
    pub topic: Option<String>,
}

impl Default for ModelOptions {
    fn default() -> Self {
        Self {
            hidden: 5,
            embed: 5,
            rounds: 1,
            body_force: BodyForce::Auto,
            types: None,
            topic: None,
        }
    }
}

/// Training data read from bags: the dataset and what a model file records about it.
pub struct TrainingData {
    /// States and target accelerations on one graph.
    pub dataset: crate::data::dataset::Dataset,
    /// What the model file says about its training data.
    pub trained_on: crate::model::file::TrainedOn,
    /// The simulator configuration from the first bag's metadata, if any.
    pub system_config: Option<crate::physics::SystemConfig>,
    /// Whether the data are a closed system (no anchors, no field), and why:
    /// `None` when the bags neither say nor show it.
    pub closed: Option<(bool, String)>,
}

/// Reads training bags (each an MCAP file, a rosbag2 directory or a .db3
/// file) into a dataset ([`load_training_data_from`] on the only
/// ParticleState topic).
pub fn load_training_data(
    bags: &[std::path::PathBuf],
    log: impl FnMut(&str),
) -> Result<TrainingData> {
    load_training_data_from(bags, None, log)
}

/// Reads training bags into a dataset (recorded accelerations, else finite
/// differences; `log` says which) with fingerprints of every trajectory's
/// start, reading `topic` (needed when a bag holds several ParticleState
/// topics).
pub fn load_training_data_from(
    bags: &[std::path::PathBuf],
    topic: Option<&str>,
    mut log: impl FnMut(&str),
) -> Result<TrainingData> {
    use crate::data::bag::{read_bags, ReadOptions};
    use crate::data::dataset::AccSource;
    use crate::evaluate::{bag_field, bag_system, fingerprint};
    if bags.is_empty() {
        bail!("no training bags given");
    }
    let mut trajectories = vec![];
    let mut digests = vec![];
    let mut system_config = None;
    let mut closed: Option<(bool, String)> = None;
    let read = ReadOptions {
        topic: topic.map(str::to_string),
    };
    for p in bags {
        let bag = read_bags(std::slice::from_ref(p), &read)?;
        if system_config.is_none() {
            system_config = bag_system(&bag)?;
        }
        // Closed: no anchors and no field, as the bag states or its data show.
        let this = match bag_field(&bag, None)? {
            _ if bag.trajectories.iter().any(|t| !t.graph.anchors.is_empty()) => {
                Some((false, "anchors".to_string()))
            }
            Some(o) => Some((o.field.is_free(), o.source)),
            None => None,
        };
        closed = match (closed, this) {
            (None, t) if trajectories.is_empty() => t,
            (Some((a, why)), Some((b, _))) if a == b => Some((a, why)),
            _ => None,
        };
        digests.push(bag_digest(p)?);
        trajectories.extend(bag.trajectories);
    }
    let ds = Dataset::from_trajectories(&trajectories)?;
    let source = match ds.source {
        AccSource::Recorded => "recorded",
        AccSource::FiniteDifference => "finite-difference",
    };
    log(&format!(
        "{} states of {} trajectories ({}-particle {}D graph); accelerations: {source}",
        ds.len(),
        trajectories.len(),
        ds.graph.n(),
        ds.graph.dim
    ));
    let first = trajectories.first().expect("dataset is not empty");
    let trained_on = crate::model::file::TrainedOn {
        system: first.system.clone(),
        particles: ds.graph.n(),
        dim: ds.graph.dim,
        bag: bags
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(","),
        bag_sha256: digests.join(","),
        accelerations: source.to_string(),
        trajectories: trajectories.len(),
        states: ds.len(),
        start_fingerprints: trajectories
            .iter()
            .filter_map(|t| t.samples.first())
            .map(|s| fingerprint(&s.state))
            .collect(),
        system_config: system_config
            .as_ref()
            .map(serde_json::to_value)
            .transpose()?,
    };
    Ok(TrainingData {
        dataset: ds,
        trained_on,
        system_config,
        closed,
    })
}

/// SHA-256 of a bag argument: of its file, or of each storage file of a
/// rosbag2 directory joined by `+`.
fn bag_digest(p: &std::path::Path) -> Result<String> {
    let parts = crate::data::source::bag_parts(p)?;
    Ok(parts
        .iter()
        .map(|part| crate::data::dataset::digest(&part.path))
        .collect::<Result<Vec<_>, _>>()?
        .join("+"))
}

/// Trains a model from trajectory bags and returns the model file (not yet saved).
pub fn train_from_bags(
    variant: crate::model::Variant,
    bags: &[std::path::PathBuf],
    opts: &ModelOptions,
    cfg: &TrainConfig,
    mut log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<crate::model::ModelFile> {
    log(&format!("training {variant}"));
    let mut data = load_training_data_from(bags, opts.topic.as_deref(), &mut log)?;
    apply_data_options(&mut data.dataset, cfg, &mut log)?;
    data.trained_on.states = data.dataset.len();
    let ds = &data.dataset;
    let types = opts.types.unwrap_or(
        ds.graph
            .types
            .iter()
            .map(|&t| t as usize + 1)
            .max()
            .unwrap_or(1),
    );
    let mut hyper = Hyper::new(variant, ds.graph.dim, types, ds.graph.n());
    hyper.hidden = opts.hidden;
    hyper.embed = opts.embed;
    hyper.rounds = opts.rounds;
    hyper.body_force = match opts.body_force {
        BodyForce::On => true,
        BodyForce::Off => false,
        BodyForce::Auto => match &data.closed {
            Some((closed, _)) => !closed,
            None if variant == crate::model::Variant::Mcgnode => bail!(
                "the training bags do not say whether the system is closed (their messages \
                 leave the field unknown, there is no system_config metadata, and the data do \
                 not show a closed system): pass --body-force off for a closed system \
                 (momentum conserved exactly) or --body-force on"
            ),
            None => true,
        },
    };
    if variant == crate::model::Variant::Mcgnode {
        let why = match (&opts.body_force, &data.closed) {
            (BodyForce::Auto, Some((_, why))) => format!(", from {why}"),
            (BodyForce::Auto, None) => String::new(),
            _ => ", as asked".to_string(),
        };
        log(&format!(
            "body-force branch: {}{why}",
            if hyper.body_force {
                "on"
            } else {
                "off (closed system: momentum is conserved exactly)"
            }
        ));
    }
    let trained = train(hyper, &ds.graph, &ds.states, &ds.acc, cfg, on_epoch)?;
    Ok(crate::model::ModelFile {
        format: crate::model::file::FORMAT.to_string(),
        crate_version: env!("CARGO_PKG_VERSION").to_string(),
        hyper: trained.net.hyper.clone(),
        trained_on: data.trained_on,
        training: trained.report,
        weights: trained.net.store.weights()?,
    })
}
