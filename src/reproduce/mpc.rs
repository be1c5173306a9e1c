//! `demo --mpc`: closed-loop control of a chain held by a gripper. The
//! ground-truth simulator is the world; the planner is a model trained on
//! bags of random gripper motions (MCGNODE, GNODE), the true physics (the
//! upper bound) or nothing (the gripper stays). The task: bring the chain's
//! free end to a target by moving the held end. Reported per planner over
//! seeded targets: success rate, mean final distance and planning time per
//! control step (`mpc.json`), and a picture of one episode (`mpc.png`).
//!
//! Two variants ([`MpcOptions`]): a world whose springs have a stiffness the
//! models never saw (`--held-out-stiffness`; the learned planners still
//! believe the training system, the true physics knows the world's), and an
//! MCGNODE ensemble planning on its mean with and without a risk term on its
//! spread (`--risk`).

use super::lab::{Lab, TrainSpec, Trained};
use crate::dynamics::{Dynamics, Timing};
use crate::error::{Context, Result};
use crate::gnode::Variant;
use crate::models::{load_any_model, ModelKind, ModelRef};
use crate::physics::{SystemConfig, SystemKind};
use crate::plan::{mpc, Cost, CostKind, EpisodeReport, Sampler};
use crate::system::{Graph, State};
use crate::train::recipe::Auto;
use crate::train::{ModelOptions, TrainConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::sync::Arc;

/// Links of the chain.
const LINKS: usize = 5;
/// A target counts as reached when the free end ends closer than this (the
/// links are 1 apart).
pub const SUCCESS_DISTANCE: f64 = 0.3;
/// The gripper's speed bound along each axis, m/s: about the speeds of the
/// training motions (faster, jerkier candidates take a learned model out of
/// what it has seen).
const MAX_SPEED: f64 = 1.0;
/// Weight of the free end's squared speed in the cost: with a horizon far
/// shorter than the chain's swing (about 4.7 s), distance alone drives the
/// end through the target and leaves it swinging.
const SPEED_WEIGHT: f64 = 0.1;
/// Gradient steps after each of `mcgnode_refined`'s searches.
const REFINE_STEPS: usize = 5;

/// A planner: its name, its model (none: hold still), the gradient steps
/// after each of its searches, its risk weight, and whether it plans on the
/// world's system (the true physics) rather than the training one.
struct Planner {
    name: String,
    model: Option<Arc<dyn Dynamics>>,
    refine: usize,
    risk: f64,
    knows_world: bool,
}

/// The experiment's options (`demo --mpc`'s flags).
#[derive(Clone, Debug, PartialEq)]
pub struct MpcOptions {
    /// 4 targets, shorter episodes, fewer candidates and less training.
    pub quick: bool,
    /// Seed of the data, the trainings and the targets.
    pub seed: u64,
    /// The world's spring stiffness instead of the training data's (500):
    /// the learned planners keep planning on the system they were trained on.
    pub held_out_stiffness: Option<f64>,
    /// Risk weights: when given, an MCGNODE ensemble of `ensemble` members
    /// is trained and plans on its mean without (`mcgnode_ensemble`) and
    /// with each weight (`mcgnode_risk`, `mcgnode_risk_<w>` for several);
    /// `mcgnode` is then its first member alone.
    pub risk: Vec<f64>,
    /// Members of that ensemble.
    pub ensemble: usize,
}

impl MpcOptions {
    /// Today's experiment: no held-out stiffness, no ensemble.
    pub fn plain(quick: bool, seed: u64) -> Self {
        MpcOptions {
            quick,
            seed,
            held_out_stiffness: None,
            risk: vec![],
            ensemble: 5,
        }
    }
}

/// One planner's results over every target.
#[derive(Clone, Debug, Serialize)]
pub struct PlannerResult {
    /// Fraction of targets reached (0..1).
    pub success_rate: f64,
    /// Mean distance of the free end to its target at the end.
    pub final_distance: f64,
    /// Mean planning wall time per control step, seconds.
    pub seconds_per_step: f64,
    /// Each target's final distance.
    pub distances: Vec<f64>,
    /// A learned planner's fraction of its validation targets explained
    /// (1 − MSE / MSE of predicting zero acceleration); none for the others.
    pub explained: Option<f64>,
}

/// What `demo --mpc` measured.
#[derive(Clone, Debug, Serialize)]
pub struct MpcReport {
    /// Per planner: `mcgnode`, `mcgnode_refined` (its searches refined by
    /// gradient steps), `gnode`, `truth`, `none`.
    pub planners: std::collections::BTreeMap<String, PlannerResult>,
    /// The targets (x, y), one per episode.
    pub targets: Vec<Vec<f64>>,
    /// The settings, in words.
    pub settings: String,
}

/// Runs the closed-loop experiment into `lab.dir`.
pub fn run(lab: &Lab, o: &MpcOptions) -> Result<MpcReport> {
    let (quick, seed) = (o.quick, o.seed);
    let mut cfg = SystemConfig::new(SystemKind::HeldChain, LINKS);
    cfg.states = 31;
    let (n_train, epochs, n_targets, steps, candidates) = if quick {
        (30, 300, 4, 20, 32)
    } else {
        (100, 1000, 20, 60, 64)
    };
    let bad_weight = o.risk.iter().any(|w| !(w.is_finite() && *w > 0.0));
    if bad_weight || (!o.risk.is_empty() && o.ensemble < 2) {
        crate::error::bail!("--risk needs finite weights > 0 and an --ensemble of at least 2");
    }
    let members = if o.risk.is_empty() { 1 } else { o.ensemble };
    let trained = train_models(lab, &cfg, (n_train, epochs, members), seed)?;
    let explained = |k: usize| trained[k].report.explained;
    let planners = planners(&trained, o)?;
    let mut world = cfg.clone();
    if let Some(k) = o.held_out_stiffness {
        if !(k.is_finite() && k > 0.0) {
            crate::error::bail!("--held-out-stiffness must be positive, got {k}");
        }
        world.stiffness = k;
    }
    let (graph, world_graph) = (cfg.graph(), world.graph());
    let episodes = episodes(&world, &world_graph, n_targets, seed);
    let setup = Setup {
        cfg: &world,
        graph: &world_graph,
        trained_graph: &graph,
        timing: Timing::of_step(0.005, 20, 10),
        sampler: Sampler::Cem {
            candidates,
            iterations: 3,
            elites: 8,
            sigma: 0.5,
        },
        steps,
        seed,
    };
    let mut report = MpcReport {
        planners: Default::default(),
        targets: episodes.iter().map(|e| e.1.clone()).collect(),
        settings: setup.settings(candidates) + &variant(o, cfg.stiffness),
    };
    // The picture shows the episode whose target is farthest from the start.
    let shown = farthest(&episodes);
    let mut first: Vec<(String, EpisodeReport)> = vec![];
    for pl in &planners {
        let name = pl.name.as_str();
        let results = setup.episodes(&episodes, pl)?;
        if let Some(r) = results.get(shown) {
            first.push((name.to_string(), r.clone()));
        }
        let explained = match name {
            "mcgnode" => explained(0),
            "gnode" => explained(1),
            _ => None,
        };
        let res = planner_result(&results, explained);
        lab.say(&format!(
            "{name}: success {:.0} %, mean final distance {:.3}, {:.1} ms per control step",
            100.0 * res.success_rate,
            res.final_distance,
            1e3 * res.seconds_per_step
        ));
        report.planners.insert(name.to_string(), res);
    }
    let json = lab.dir.join("mpc.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("writing {}", json.display()))?;
    picture(lab, &episodes[shown], &first)?;
    Ok(report)
}

/// The variant's settings, in words ("" for today's experiment).
fn variant(o: &MpcOptions, trained_stiffness: f64) -> String {
    let mut out = String::new();
    if o.held_out_stiffness.is_some() {
        out += &format!(
            "; held-out stiffness: the models were trained at k = {trained_stiffness} and plan \
             as if the world had it (the true physics plans on the world's)"
        );
    }
    if !o.risk.is_empty() {
        out += &format!(
            "; MCGNODE ensemble of {} members (mcgnode: the first alone), planning on its mean \
             (mcgnode_ensemble) and with risk weight {:?} x the sum over the horizon of the free \
             particles' mean spread (mcgnode_risk)",
            o.ensemble, o.risk
        );
    }
    out
}

/// One episode: the chain's start and the free end's target (x, y).
type Target = (State, Vec<f64>);

/// Simulates `n_train` trajectories of the held chain with random gripper
/// motions and trains MCGNODE (an ensemble of `members` when above 1) and
/// GNODE on them, side by side, for `epochs` epochs each.
fn train_models(
    lab: &Lab,
    cfg: &SystemConfig,
    (n_train, epochs, members): (usize, usize, usize),
    seed: u64,
) -> Result<Vec<Trained>> {
    let train = lab.bag("held-chain-train", cfg, n_train, seed, false)?;
    lab.say(&format!(
        "simulated {n_train} trajectories of a {LINKS}-link chain whose gripper moves at random"
    ));
    let specs: Vec<TrainSpec> = [Variant::Mcgnode, Variant::Gnode]
        .iter()
        .map(|&v| TrainSpec {
            label: format!("{v}-held-chain"),
            kind: ModelKind::Family(v),
            bags: vec![train.clone()],
            cfg: TrainConfig {
                epochs,
                patience: epochs,
                seed,
                threads: (crate::engine::all_cores() / 2).max(1),
                auto: Auto::GIVEN_EPOCHS,
                ensemble: if v == Variant::Mcgnode { members } else { 1 },
                ..TrainConfig::default()
            },
            // The default recipe's options (`mcgnode train`'s).
            opts: ModelOptions::default(),
        })
        .collect();
    let trained = lab
        .train_all(&specs)
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let explained = |k: usize| trained[k].report.explained;
    let pct = |x: Option<f64>| x.map_or_else(|| "?".into(), |x| format!("{:.2} %", 100.0 * x));
    lab.say(&format!(
        "trained MCGNODE and GNODE ({epochs} epochs each; they explain {} and {} of their \
         validation targets)",
        pct(explained(0)),
        pct(explained(1))
    ));
    Ok(trained)
}

/// The planners compared: the trained MCGNODE (with and without gradient
/// steps; with a held-out stiffness without them) and GNODE, the true
/// physics, and holding still; with a risk weight, the MCGNODE ensemble's
/// mean without and with the risk term, and `mcgnode` its first member.
fn planners(trained: &[Trained], o: &MpcOptions) -> Result<Vec<Planner>> {
    let load = |p: &std::path::Path| -> Result<Arc<dyn Dynamics>> {
        Ok(load_any_model(&ModelRef::File(p.to_path_buf()))?.dynamics)
    };
    let plain = |name: &str, model: Option<Arc<dyn Dynamics>>| Planner {
        name: name.to_string(),
        model,
        refine: 0,
        risk: 0.0,
        knows_world: false,
    };
    let file = load(&trained[0].path)?;
    let mcgnode = if o.risk.is_empty() {
        file.clone()
    } else {
        let f = crate::gnode::file::ModelFile::load(&trained[0].path)?;
        let first = f.member_files().into_iter().next();
        let first = first.ok_or_else(|| crate::error::err!("the ensemble has no member"))?;
        Arc::new(crate::kernel::TrainedModel::from_file(first)?) as Arc<dyn Dynamics>
    };
    let mut out = vec![plain("mcgnode", Some(mcgnode.clone()))];
    if o.held_out_stiffness.is_none() {
        out.push(Planner {
            refine: REFINE_STEPS,
            ..plain("mcgnode_refined", Some(mcgnode))
        });
    }
    if !o.risk.is_empty() {
        out.push(plain("mcgnode_ensemble", Some(file.clone())));
    }
    for &w in &o.risk {
        let name = match o.risk.len() {
            1 => "mcgnode_risk".to_string(),
            _ => format!("mcgnode_risk_{w}"),
        };
        out.push(Planner {
            risk: w,
            name,
            ..plain("", Some(file.clone()))
        });
    }
    out.push(plain("gnode", Some(load(&trained[1].path)?)));
    out.push(Planner {
        knows_world: true,
        ..plain(
            "truth",
            Some(crate::models::truth::truth(SystemKind::HeldChain)),
        )
    });
    out.push(plain("none", None));
    Ok(out)
}

/// `n_targets` seeded episodes: a start of the chain and a target near its
/// free end.
fn episodes(cfg: &SystemConfig, graph: &Graph, n_targets: usize, seed: u64) -> Vec<Target> {
    let end = LINKS - 1;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x006d_7063);
    (0..n_targets)
        .map(|i| {
            let start = cfg.start_for(graph, seed + 7000, i);
            let (x, y) = (start.q[end * 2], start.q[end * 2 + 1]);
            let target = vec![
                x + rng.random_range(-1.5..1.5),
                y + rng.random_range(-0.5..0.5),
            ];
            (start, target)
        })
        .collect()
}

/// The episode whose target is farthest from the free end's start.
fn farthest(episodes: &[Target]) -> usize {
    let end = LINKS - 1;
    let far = |(s, t): &Target| (s.q[end * 2] - t[0]).hypot(s.q[end * 2 + 1] - t[1]);
    (0..episodes.len())
        .max_by(|&a, &b| far(&episodes[a]).total_cmp(&far(&episodes[b])))
        .unwrap_or(0)
}

/// What every episode shares: the world, the planner's search and the
/// episode length.
struct Setup<'a> {
    /// The world's system and its graph.
    cfg: &'a SystemConfig,
    graph: &'a Graph,
    /// The system the models were trained on (the world's unless its
    /// stiffness is held out).
    trained_graph: &'a Graph,
    timing: Timing,
    sampler: Sampler,
    /// Control steps per episode.
    steps: usize,
    seed: u64,
}

impl Setup<'_> {
    /// The settings, in words.
    fn settings(&self, candidates: usize) -> String {
        let (cfg, timing, steps) = (self.cfg, self.timing, self.steps);
        format!(
            "{LINKS}-link held chain (springs k = {}, g = {}), world dt {}; planner CEM {candidates} \
             candidates x 3 rounds (8 elites, sigma 0.5 m/s), horizon 10 control steps of {} s \
             (rollouts at dt {}), speed bound {MAX_SPEED} m/s, cost: mean squared distance of the free end \
             over the horizon + {SPEED_WEIGHT} × its squared speed + 1e-3 effort; {steps} control steps per episode; success: final \
             distance < {SUCCESS_DISTANCE}",
            cfg.stiffness,
            cfg.field.gravity,
            cfg.dt,
            timing.dt,
            timing.step()
        )
    }

    /// Runs every episode with the planner `pl`.
    fn episodes(&self, episodes: &[Target], pl: &Planner) -> Result<Vec<EpisodeReport>> {
        let (name, refine) = (pl.name.as_str(), pl.refine);
        let end = LINKS - 1;
        let mut results = vec![];
        for (i, (start, target)) in episodes.iter().enumerate() {
            let ep = mpc::Episode {
                graph: self.graph,
                field: &self.cfg.field,
                world_dt: self.cfg.dt,
                start: start.clone(),
                planner: pl.model.as_deref(),
                planner_graph: (!pl.knows_world).then_some(self.trained_graph),
                sampler: self.sampler,
                timing: self.timing,
                steps: self.steps,
                cost: Cost {
                    kind: CostKind::Along,
                    particles: vec![end],
                    targets: target.clone(),
                    effort: 1e-3,
                    speed: SPEED_WEIGHT,
                    risk: pl.risk,
                },
                max_speed: MAX_SPEED,
                seed: self.seed + 100 * i as u64,
                refine,
            };
            let r = mpc::run(&ep).with_context(|| format!("{name}, target {i}"))?;
            results.push(r);
        }
        Ok(results)
    }
}

/// One planner's results over its episodes.
fn planner_result(results: &[EpisodeReport], explained: Option<f64>) -> PlannerResult {
    let m = results.len() as f64;
    let distances: Vec<f64> = results.iter().map(|r| r.final_distance).collect();
    PlannerResult {
        success_rate: distances.iter().filter(|d| **d < SUCCESS_DISTANCE).count() as f64 / m,
        final_distance: distances.iter().sum::<f64>() / m,
        seconds_per_step: results.iter().map(|r| r.seconds_per_step).sum::<f64>() / m,
        distances,
        explained,
    }
}

/// `mpc.png`: one episode's target, each planner's executed path of the free
/// end, and MCGNODE's first predicted path; widths a fraction of the picture's
/// span.
fn picture(lab: &Lab, episode: &Target, runs: &[(String, EpisodeReport)]) -> Result<()> {
    use plotters::style::RGBColor;
    let colour = |name: &str| match name {
        "mcgnode" => RGBColor(220, 90, 20),
        "gnode" => RGBColor(40, 120, 200),
        "truth" => RGBColor(40, 160, 60),
        _ => RGBColor(120, 120, 120),
    };
    let p3 = |p: &[f64]| [p[0], p[1], 0.0];
    let (lo, hi) = runs.iter().flat_map(|(_, r)| r.executed.iter()).fold(
        ([f64::MAX; 2], [f64::MIN; 2]),
        |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        },
    );
    let w = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(0.5) / 200.0;
    let mut scene = crate::plot::Scene {
        title: "free end: executed paths (mcgnode orange, gnode blue, truth green, none grey), \
                mcgnode's first plan (light), target (square)"
            .into(),
        ..Default::default()
    };
    for (name, r) in runs {
        for seg in r.executed.windows(2) {
            scene
                .segments
                .push((p3(&seg[0]), p3(&seg[1]), colour(name), w));
        }
        if let Some(last) = r.executed.last() {
            scene.discs.push((p3(last), colour(name), 5.0 * w));
        }
        if name == "mcgnode" {
            let mut prev = r.executed[0].clone();
            for q in &r.predicted {
                scene
                    .segments
                    .push((p3(&prev), p3(q), RGBColor(250, 190, 150), 0.7 * w));
                prev.clone_from(q);
            }
        }
    }
    let (start, target) = episode;
    let end = LINKS - 1;
    scene.discs.push((
        p3(&start.q[end * 2..end * 2 + 2]),
        RGBColor(0, 0, 0),
        4.0 * w,
    ));
    scene
        .squares
        .push((p3(target), RGBColor(200, 30, 30), 6.0 * w));
    crate::plot::draw_scene(&lab.dir.join("mpc.png"), &scene)
}
