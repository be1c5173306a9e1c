//! `mcgnode train`.

use super::choices::{ArchArg, BodyForceArg, EdgeInputArg, EngineArg, MessageFnArg, RecipeArg};
use crate::gnode::file::TrainingReport;
use crate::gnode::ArchPreset;
use crate::models::{train_any_from_bags, ModelKind};
use crate::train::recipe::{self, paper};
use crate::train::{
    BodyForce, Checkpointing, EngineKind, EpochReport, ModelOptions, Recipe, TrainConfig,
};
use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Options of `train`. Their defaults are the library's
/// ([`ModelOptions::default`] and [`TrainConfig::for_recipe`] of the default
/// [`Recipe`], constants in [`recipe`]): [`Args::settings`] of no option
/// gives exactly those (a test below checks it).
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Model: node, gnode, cgnode, cdgnode, mcgnode, or a baseline: lgn, hgn, gns.
    #[arg(long)]
    pub model: ModelKind,
    /// Training bag(s) of ParticleState messages, each an MCAP file, a rosbag2
    /// directory or a .db3 file (repeat or comma-separate).
    #[arg(long, required = true, value_delimiter = ',')]
    pub data: Vec<PathBuf>,
    /// The ParticleState topic to train on, when a bag holds several.
    #[arg(long)]
    pub topic: Option<String>,
    /// How settings left out are chosen: auto (from the data: batch by
    /// edges, lr 1e-2 stepped to 1e-3 after two thirds of the epochs, epochs
    /// for 22,500 Adam steps, edge MLPs of 16,16; learns solids and chains
    /// alike) or paper (the paper's appendix: batch 100, lr 1e-3, 10,000
    /// epochs, width 5). Options given here override either. Baselines
    /// (lgn, hgn, gns) keep their papers' settings under both.
    #[arg(long, value_enum, default_value_t = RecipeArg::from(Recipe::default()))]
    pub recipe: RecipeArg,
    /// Maximum epochs (auto: for 22,500 Adam steps, at most 10,000; paper: 10,000).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Output model file (JSON).
    #[arg(long)]
    pub out: PathBuf,
    /// Seed for initialisation, the 75:25 split and shuffling.
    #[arg(long, default_value_t = recipe::SEED)]
    pub seed: u64,
    /// Adam learning rate (auto: 1e-2, or 1e-3 for a warm start; paper: 1e-3).
    #[arg(long)]
    pub lr: Option<f64>,
    /// Learning-rate step: after EPOCH, use LR (repeatable), e.g. `300:1e-3`
    /// (auto: a tenth of the rate after two thirds of the epochs; paper: none).
    /// Given, it replaces the recipe's step.
    #[arg(long, value_name = "EPOCH:LR", value_parser = parse_drop)]
    pub lr_drop: Vec<(usize, f64)>,
    /// Batch size in states (auto: 16,000 directed edges' worth, at most 100;
    /// paper: 100).
    #[arg(long)]
    pub batch: Option<usize>,
    /// Wall-clock budget: stop after the first epoch that ends this many
    /// seconds into training, keeping the best weights so far.
    #[arg(long, value_name = "SECONDS")]
    pub max_seconds: Option<f64>,
    /// Stop when the validation loss has not improved for this many epochs.
    #[arg(long, default_value_t = recipe::PATIENCE)]
    pub patience: usize,
    /// Hidden units of the graph MLPs (paper: 5).
    #[arg(long, default_value_t = paper::HIDDEN)]
    pub hidden: usize,
    /// Node/edge embedding width (paper: 5).
    #[arg(long, default_value_t = paper::EMBED)]
    pub embed: usize,
    /// Message-passing rounds (paper: 1).
    #[arg(long, default_value_t = paper::ROUNDS)]
    pub rounds: usize,
    /// Architecture: authors (their code, behind the paper's numbers: two
    /// hidden layers per MLP, MLP messages, h_i ⊙ h_j edge updates) or paper
    /// (the paper's text: one hidden layer, linear messages, h_i ‖ h_j).
    #[arg(long, value_enum, default_value_t = ArchArg::from(ArchPreset::default()))]
    pub arch: ArchArg,
    /// Hidden layers per graph MLP (overrides --arch).
    #[arg(long)]
    pub hidden_layers: Option<usize>,
    /// Message and edge-update functions (overrides --arch).
    #[arg(long, value_enum)]
    pub messages: Option<MessageFnArg>,
    /// Edge-update input (overrides --arch).
    #[arg(long, value_enum)]
    pub edge_update: Option<EdgeInputArg>,
    /// Hidden sizes of one block, e.g. `edge_out=16,16` (repeatable; blocks:
    /// node_em, edge_em, mp0.v, mp0.e, glob_em, node_out, edge_out, body_out).
    #[arg(long, value_name = "BLOCK=SIZES", value_parser = parse_block)]
    pub block_hidden: Vec<(String, Vec<usize>)>,
    /// Gaussian noise added to the target accelerations, in percent of their
    /// standard deviation (the paper's noise experiments use 0, 1, 5 and 10).
    #[arg(long, default_value_t = TrainConfig::default().noise, value_name = "PERCENT")]
    pub noise: f64,
    /// Train on a seeded random subset of N states (train + validation) instead
    /// of all of them (the paper's data-efficiency experiments use 100 to 10000).
    #[arg(long, value_name = "N")]
    pub points: Option<usize>,
    /// MCGNODE body-force branch: auto (off for a closed system, as the bag's
    /// messages or metadata state or its data show; refused when none tells),
    /// on, off.
    #[arg(long, value_enum, default_value_t = BodyForceArg::from(BodyForce::default()))]
    pub body_force: BodyForceArg,
    /// Gradient engine of the GNODE family and GNS: native (hand-written,
    /// all cores) or candle (the autodiff reference). LGN and HGN always use
    /// candle.
    #[arg(long, value_enum, default_value_t = EngineArg::from(EngineKind::default()))]
    pub engine: EngineArg,
    /// Training threads of the native engine (default: all cores). The
    /// trained weights do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Edges also read their rest length and stiffness, so one model serves
    /// springs of several kinds (without it, a model refuses graphs whose
    /// edges differ from those it was trained on).
    #[arg(long)]
    pub edge_physics: bool,
    /// Contacts: every pair of particles closer than R interacts through a
    /// contact edge found at each state (an edge input marks it), overriding
    /// the bags' interaction_radius; 0 trains on fixed edges only. Recorded
    /// in the model file, which then serves only systems of this radius.
    #[arg(long, value_name = "R")]
    pub radius: Option<f64>,
    /// Train on unscaled inputs and outputs (by default they are scaled by
    /// statistics of the training split, stored in the model file).
    #[arg(long)]
    pub no_normalize: bool,
    /// Warm start: continue from this model file's weights (and its Adam
    /// state, when the file has one); its architecture is kept.
    #[arg(long, value_name = "MODEL")]
    pub init: Option<PathBuf>,
    /// Save the run's state to FILE as it goes (every --checkpoint-every
    /// seconds and at the end); when FILE exists, training resumes from it
    /// and ends where an uninterrupted run would. A checkpoint of another
    /// run (other data, seed or settings) is refused.
    #[arg(long, value_name = "FILE")]
    pub checkpoint: Option<PathBuf>,
    /// Seconds between checkpoint saves.
    #[arg(
        long,
        value_name = "SECONDS",
        default_value_t = Checkpointing::EVERY,
        requires = "checkpoint"
    )]
    pub checkpoint_every: f64,
    /// Train an ensemble of K members of the GNODE family into one model
    /// file: the same recipe, seeds --seed, --seed + 1, … (initialisation,
    /// split and data order). Consumers predict the members' mean and report
    /// their spread.
    #[arg(long, value_name = "K", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..=64))]
    pub ensemble: u32,
    /// Print nothing but errors.
    #[arg(long)]
    pub quiet: bool,
}

/// `EPOCH:LR` (also the Python package's string form of an `lr_drop`).
pub fn parse_drop(s: &str) -> Result<(usize, f64)> {
    let bad = || anyhow::anyhow!("expected EPOCH:LR such as 300:1e-3, got {s:?}");
    let (e, lr) = s.split_once(':').ok_or_else(bad)?;
    let e = e.trim().parse::<usize>().map_err(|_| bad())?;
    match lr.trim().parse::<f64>() {
        Ok(lr) if lr.is_finite() && lr > 0.0 => Ok((e, lr)),
        _ => Err(bad()),
    }
}

/// `BLOCK=SIZES`, sizes comma-separated (empty: no hidden layer) (also the
/// Python package's string form of a `block_hidden` item).
pub fn parse_block(s: &str) -> Result<(String, Vec<usize>)> {
    let (block, sizes) = s
        .split_once('=')
        .ok_or_else(|| anyhow::anyhow!("expected BLOCK=SIZES such as edge_out=16,16, got {s:?}"))?;
    let sizes = sizes
        .split(',')
        .filter(|x| !x.is_empty())
        .map(|x| match x.trim().parse::<usize>() {
            Ok(n) if n > 0 => Ok(n),
            _ => Err(anyhow::anyhow!(
                "hidden size {x:?} in {s:?} is not a positive integer"
            )),
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((block.trim().to_string(), sizes))
}

/// Progress: a bar on a terminal, plain lines otherwise.
pub fn progress(quiet: bool) -> impl FnMut(&EpochReport) -> bool {
    // The recipe may choose the epoch count from the data: the bar takes it
    // from the first report.
    let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
        let b = ProgressBar::new(0);
        b.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} epochs  {msg}  ETA {eta}")
                .expect("valid template"),
        );
        b
    });
    move |r: &EpochReport| {
        let every = (r.epochs / 20).max(1);
        let msg = format!(
            "train {:.3e}  val {:.3e}  best {:.3e}",
            r.train_loss, r.validation_loss, r.best
        );
        match &bar {
            Some(b) => {
                b.set_length(r.epochs as u64);
                b.set_position(r.epoch as u64);
                b.set_message(msg);
                if r.epoch == r.epochs {
                    b.finish();
                }
            }
            None if !quiet && (r.epoch % every == 0 || r.epoch == 1) => {
                eprintln!(
                    "epoch {}/{}  {msg}  ({:.1} s)",
                    r.epoch, r.epochs, r.elapsed
                )
            }
            None => {}
        }
        true
    }
}

impl Args {
    /// The model options and training config these arguments stand for
    /// (loading the `--init` model file): the library's defaults with each
    /// option given here set, so that one given setting takes it from the
    /// recipe and the others stay the recipe's.
    pub fn settings(&self) -> Result<(ModelOptions, TrainConfig)> {
        let a = self;
        let recipe = Recipe::from(a.recipe);
        let mut cfg = TrainConfig {
            patience: a.patience,
            seed: a.seed,
            noise: a.noise,
            points: a.points,
            engine: a.engine.into(),
            time_budget: a.max_seconds,
            checkpoint: a.checkpoint.clone().map(|path| Checkpointing {
                path,
                every: a.checkpoint_every,
            }),
            threads: a.threads.unwrap_or_else(crate::engine::all_cores),
            ensemble: a.ensemble as usize,
            normalize: !a.no_normalize,
            init: a
                .init
                .as_deref()
                .map(crate::gnode::ModelFile::load)
                .transpose()?
                .map(Box::new),
            ..TrainConfig::for_recipe(recipe)
        };
        if let Some(e) = a.epochs {
            cfg.set_epochs(e);
        }
        if let Some(lr) = a.lr {
            cfg.set_lr(lr);
        }
        if let Some(b) = a.batch {
            cfg.set_batch(b);
        }
        if !a.lr_drop.is_empty() {
            cfg.set_lr_drops(a.lr_drop.clone());
        }
        let opts = ModelOptions {
            hidden: a.hidden,
            embed: a.embed,
            rounds: a.rounds,
            body_force: a.body_force.into(),
            types: None,
            topic: a.topic.clone(),
            arch: a.arch.into(),
            hidden_layers: a.hidden_layers,
            message: a.messages.map(Into::into),
            edge_input: a.edge_update.map(Into::into),
            block_hidden: a.block_hidden.iter().cloned().collect(),
            edge_physics: a.edge_physics,
            radius: a.radius,
            recipe,
        };
        Ok((opts, cfg))
    }
}

/// Trains as `a` says and writes the model file `a.out`: what `run` does,
/// without its printing. `log` gets training's messages and `on_epoch` each
/// epoch's figures (returning false cancels).
pub fn train(
    a: &Args,
    log: impl FnMut(&str),
    on_epoch: impl FnMut(&EpochReport) -> bool,
) -> Result<TrainingReport> {
    let (opts, cfg) = a.settings()?;
    Ok(train_any_from_bags(
        a.model, &a.data, &opts, &cfg, log, on_epoch, &a.out,
    )?)
}

/// The line `run` prints when training has written `out`.
pub fn summary(out: &Path, t: &TrainingReport) -> String {
    format!(
        "wrote {}: {} epochs{}{} in {:.1} s, best epoch {}, train MSE {:.3e}, validation MSE {:.3e}",
        out.display(),
        t.epochs_run,
        t.resumed_at
            .map(|e| format!(" (resumed from the checkpoint of epoch {e})"))
            .unwrap_or_default(),
        match (t.stopped_early, t.out_of_time) {
            (true, _) => " (early stop)",
            (_, true) => " (time budget reached)",
            _ => "",
        },
        t.seconds,
        t.best_epoch,
        t.train_loss,
        t.validation_loss
    )
}

/// Runs `train`.
pub fn run(a: Args) -> Result<()> {
    let quiet = a.quiet;
    let log = |m: &str| {
        if !quiet {
            eprintln!("{m}")
        }
    };
    let t = &train(&a, log, progress(a.quiet))?;
    if !a.quiet {
        eprintln!("{}", summary(&a.out, t));
        eprintln!("{}", t.explained_line());
    }
    // Even --quiet says when a model learned little: a plausible wrong
    // answer is the worst outcome.
    if let Some(w) = t.explained_warning() {
        eprintln!("{w}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{Args as _, FromArgMatches as _};

    /// `train` with `argv` after `--model mcgnode --data d.mcap --out m.json`.
    fn parse(argv: &[&str]) -> Args {
        let cmd = Args::augment_args(clap::Command::new("train")).no_binary_name(true);
        let base = ["--model", "mcgnode", "--data", "d.mcap", "--out", "m.json"];
        let m = cmd
            .try_get_matches_from(base.iter().chain(argv))
            .expect("valid arguments");
        Args::from_arg_matches(&m).expect("matches")
    }

    #[test]
    fn the_command_line_defaults_are_the_library_defaults() {
        let (opts, cfg) = parse(&[]).settings().unwrap();
        assert_eq!(opts, ModelOptions::default());
        assert_eq!(opts.recipe, Recipe::Auto);
        // TrainConfig holds a model file (no PartialEq): compared as printed.
        assert_eq!(
            format!("{cfg:?}"),
            format!("{:?}", TrainConfig::for_recipe(Recipe::default()))
        );
        assert_eq!(cfg.auto, crate::train::Auto::ALL);
        assert_eq!(cfg.patience, recipe::PATIENCE);
    }

    #[test]
    fn the_help_states_the_recipe_s_numbers() {
        // `--help` spells out what the recipe chooses; it must say the
        // constants the recipe uses.
        let help = Args::augment_args(clap::Command::new("train"))
            .render_long_help()
            .to_string();
        let thousands = |n: usize| {
            let s = n.to_string();
            let head = s.len() % 3;
            let mut out = s[..head].to_string();
            for (i, c) in s[head..].chars().enumerate() {
                if i % 3 == 0 && !out.is_empty() {
                    out.push(',');
                }
                out.push(c);
            }
            out
        };
        assert_eq!(thousands(22_500), "22,500");
        for needle in [
            thousands(recipe::STEPS),
            thousands(recipe::BATCH_EDGES),
            thousands(paper::EPOCHS),
            format!("{0},{0}", recipe::EDGE_WIDTH),
            format!("{:e}", recipe::LR),
            format!("{:e}", paper::LR),
            format!("paper: {}", paper::BATCH),
            format!("paper: {}", paper::HIDDEN),
        ] {
            assert!(help.contains(&needle), "--help does not say {needle:?}");
        }
    }

    #[test]
    fn the_paper_recipe_is_one_flag_away() {
        let (opts, cfg) = parse(&["--recipe", "paper"]).settings().unwrap();
        assert_eq!(opts, ModelOptions::for_recipe(Recipe::Paper));
        assert_eq!(format!("{cfg:?}"), format!("{:?}", TrainConfig::default()));
        assert_eq!(
            (cfg.epochs, cfg.batch, cfg.lr, opts.hidden),
            (paper::EPOCHS, paper::BATCH, paper::LR, paper::HIDDEN)
        );
    }

    #[test]
    fn a_given_setting_leaves_the_others_to_the_recipe() {
        let (opts, cfg) = parse(&["--epochs", "7", "--lr-drop", "3:1e-4", "--hidden", "9"])
            .settings()
            .unwrap();
        assert_eq!((cfg.epochs, cfg.lr_drops.clone()), (7, vec![(3, 1e-4)]));
        let auto = cfg.auto;
        assert!(
            !auto.epochs && !auto.lr_drops && auto.batch && auto.lr,
            "{auto:?}"
        );
        assert_eq!(
            opts,
            ModelOptions {
                hidden: 9,
                ..ModelOptions::default()
            }
        );
    }
}
