//! Speed measurements (`mcgnode bench` and the criterion benches): median wall
//! times of training steps and rollouts, next to the authors' JAX figures
//! measured on this same 2-core machine.

use crate::dynamics::Timing;
use crate::error::Result;
use crate::gnode::{Hyper, Variant};
use crate::physics::{SystemConfig, SystemKind};
use crate::system::{Graph, State};
use crate::testing::random_model;
use crate::train::{EngineKind, TrainConfig};
use serde::Serialize;
use std::time::Instant;

/// One measured figure.
#[derive(Clone, Debug, Serialize)]
pub struct Figure {
    /// What was measured.
    pub name: String,
    /// Median over repeats.
    pub value: f64,
    /// Unit of `value`.
    pub unit: String,
    /// Repeats.
    pub repeats: usize,
}

impl Figure {
    /// A rollout speed: `steps` steps in a median of `seconds`, over
    /// `repeats` repeats.
    fn speed(name: String, steps: usize, seconds: f64, repeats: usize) -> Self {
        Self {
            name,
            value: steps as f64 / seconds,
            unit: "steps/s".into(),
            repeats,
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// What a training figure trains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trainee {
    /// A model of the GNODE family on an engine, with this many threads.
    Family(Variant, EngineKind, usize),
    /// A baseline on an engine (LGN and HGN: candle whatever is asked),
    /// with this many threads.
    Baseline(crate::baselines::Kind, EngineKind, usize),
}

/// A data set like the paper's: `trajectories` × 100 states of `n` particles
/// of `system` (independent seeded starts, exact accelerations). Training
/// time depends on sizes, not on where the states lie on a trajectory.
pub fn training_set(
    system: SystemKind,
    n: usize,
    trajectories: usize,
) -> (Graph, Vec<State>, Vec<Vec<f64>>) {
    let cfg = SystemConfig::new(system, n);
    let g = cfg.graph();
    let states: Vec<State> = (0..trajectories * 100)
        .map(|i| cfg.start_for(&g, 99, i))
        .collect();
    let acc = states
        .iter()
        .map(|s| crate::physics::acceleration(&g, &cfg.field, s))
        .collect();
    (g, states, acc)
}

/// Wall time of whole epochs as `train` runs them (shuffled batches of 100,
/// Adam, validation on 25 %): the median over `epochs` epochs of the time
/// between consecutive epoch reports (the first epoch is included, so
/// warm-up counts once).
pub fn epoch_seconds(
    trainee: Trainee,
    data: &(Graph, Vec<State>, Vec<Vec<f64>>),
    epochs: usize,
) -> Result<f64> {
    let (g, states, acc) = data;
    let mut cfg = TrainConfig {
        epochs,
        patience: epochs,
        ..TrainConfig::default()
    };
    let mut times = vec![];
    let mut last = 0.0;
    let on_epoch = |r: &crate::train::EpochReport| {
        times.push(r.elapsed - last);
        last = r.elapsed;
        true
    };
    match trainee {
        Trainee::Family(v, engine, threads) => {
            cfg.engine = engine;
            cfg.threads = threads;
            let mut h = Hyper::new(v, g.dim, 1, g.n());
            h.body_force = !g.anchors.is_empty();
            crate::train::train(h, g, states, acc, &cfg, on_epoch)?;
        }
        Trainee::Baseline(kind, engine, threads) => {
            cfg.engine = engine;
            cfg.threads = threads;
            let types = g.type_count();
            let mut h = crate::baselines::BaselineHyper::new(kind, g.dim, types);
            h.interaction_radius = g.interaction_radius;
            crate::baselines::train_baseline(h, g, states, acc, &cfg, on_epoch)?;
        }
    }
    Ok(median(times))
}

/// Median time of a kernel rollout of `steps` steps.
pub fn rollout_seconds(
    system: SystemKind,
    n: usize,
    variant: Variant,
    steps: usize,
    repeats: usize,
) -> Result<f64> {
    let cfg = SystemConfig::new(system, n);
    let g = cfg.graph();
    let s0 = cfg.start_for(&g, 5, 0);
    graph_rollout_seconds(&g, &s0, cfg.dt, variant, steps, repeats)
}

/// Median time of a `steps`-step rollout of an ensemble of `k` random
/// MCGNODE members on `n` springs over the time of one of them, both through
/// [`crate::dynamics::Dynamics::rollout`] as every consumer calls it.
pub fn ensemble_cost_ratio(n: usize, k: usize, steps: usize, repeats: usize) -> Result<f64> {
    use crate::dynamics::Dynamics;
    let cfg = SystemConfig::new(SystemKind::Spring, n);
    let g = cfg.graph();
    let s0 = cfg.start_for(&g, 5, 0);
    let members = (0..k as u64)
        .map(|seed| Ok(random_model(Variant::Mcgnode, &g, seed)?.1))
        .collect::<Result<Vec<_>>>()?;
    let single = members[0].clone();
    let ensemble = crate::kernel::Ensemble { members };
    let timing = Timing::integration(cfg.dt, steps, steps);
    let time = |m: &dyn Dynamics| -> Result<f64> {
        let mut times = Vec::with_capacity(repeats);
        for _ in 0..repeats.max(1) {
            let t = Instant::now();
            m.rollout(&g, &s0, timing)
                .map_err(crate::error::Error::msg)?;
            times.push(t.elapsed().as_secs_f64());
        }
        Ok(median(times))
    };
    Ok(time(&ensemble)? / time(&single)?)
}

/// `side`² free particles on a triangular lattice 0.8 apart, jittered by
/// 2 %, with contacts within radius 1: six neighbours each inside (a dense
/// granular packing), the graph the contact rollout figure runs on, at rest.
pub fn contact_packing(side: usize) -> (Graph, State) {
    use rand::{Rng, SeedableRng};
    let n = side * side;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let (a, h) = (0.8, 0.8 * 3f64.sqrt() / 2.0);
    let mut q = Vec::with_capacity(2 * n);
    for k in 0..n {
        let (i, j) = ((k % side) as f64, (k / side) as f64);
        let shift = if (k / side) % 2 == 1 { a / 2.0 } else { 0.0 };
        q.push(i * a + shift + rng.random_range(-0.016..0.016));
        q.push(j * h + rng.random_range(-0.016..0.016));
    }
    let g = Graph {
        dim: 2,
        types: vec![0; n],
        masses: vec![1.0; n],
        edges: vec![],
        anchors: vec![],
        interaction_radius: 1.0,
        kinematic: vec![],
        periodic_box: None,
    };
    let v = vec![0.0; 2 * n];
    (g, State { q, v })
}

/// Median time of one round of `candidates` random candidates, each
/// `control_steps` control steps of 10 integration steps, through a random
/// MCGNODE on a chain of 19 links and its gripper (20 particles), on every core.
pub fn plan_seconds(candidates: usize, control_steps: usize, repeats: usize) -> Result<f64> {
    use crate::plan::{plan, Sampler};
    let (cfg, g, start, m) = plan_setup()?;
    let mut problem = plan_problem(&cfg, &g, &start, &m);
    problem.timing = problem.timing.with_horizon(control_steps);
    let sampler = Sampler::Random {
        candidates,
        sigma: 0.5,
    };
    let mut times = vec![];
    for k in 0..repeats {
        let t = Instant::now();
        plan(&problem, sampler, None, k as u64, |_| true).map_err(crate::error::Error::msg)?;
        times.push(t.elapsed().as_secs_f64());
    }
    Ok(median(times))
}

/// Median time of one planning gradient (∂cost/∂controls by reverse mode
/// through the rollout) of the problem [`plan_seconds`] searches.
pub fn plan_gradient_seconds(repeats: usize) -> Result<f64> {
    let (cfg, g, start, m) = plan_setup()?;
    let problem = plan_problem(&cfg, &g, &start, &m);
    let controls = crate::plan::Controls::zeros(problem.timing.horizon, problem.width());
    let mut times = vec![];
    for _ in 0..repeats {
        let t = Instant::now();
        problem
            .gradient(&controls)
            .map_err(crate::error::Error::msg)?;
        times.push(t.elapsed().as_secs_f64());
    }
    Ok(median(times))
}

/// The planning benches' system: a 20-particle held chain and an MCGNODE of
/// random weights.
fn plan_setup() -> Result<(SystemConfig, Graph, State, crate::kernel::TrainedModel)> {
    let cfg = SystemConfig::new(SystemKind::HeldChain, 19);
    let g = cfg.graph();
    let start = cfg.start_for(&g, 5, 0);
    let (_, m) = random_model(Variant::Mcgnode, &g, 0)?;
    Ok((cfg, g, start, m))
}

/// Moving the gripper so that the chain's end reaches a target.
fn plan_problem<'a>(
    cfg: &SystemConfig,
    g: &'a Graph,
    start: &'a State,
    m: &'a crate::kernel::TrainedModel,
) -> crate::plan::Problem<'a> {
    use crate::plan::{Cost, CostKind, Problem};
    Problem {
        model: m,
        graph: g,
        start,
        timing: Timing::of_step(cfg.dt, 10, 5),
        cost: Cost {
            kind: CostKind::Final,
            particles: vec![18],
            targets: vec![1.0, -20.0],
            effort: 1e-3,
            speed: 0.0,
            risk: 0.0,
        },
        max_speed: 1.0,
    }
}

/// Median time of a kernel rollout of `steps` steps of `variant` (random
/// weights) on `g` from `s0`.
pub fn graph_rollout_seconds(
    g: &Graph,
    s0: &State,
    dt: f64,
    variant: Variant,
    steps: usize,
    repeats: usize,
) -> Result<f64> {
    let (_, m) = random_model(variant, g, 0)?;
    model_rollout_seconds(&m, g, s0, dt, steps, repeats, false)
}

/// Median seconds of `steps`-step rollouts of the model `m` from `s0`, with
/// the edge MLPs' rows on two cores when `split` is set (as the node runs).
fn model_rollout_seconds(
    m: &crate::kernel::TrainedModel,
    g: &Graph,
    s0: &State,
    dt: f64,
    steps: usize,
    repeats: usize,
    split: bool,
) -> Result<f64> {
    let mut ws = m.kernel.workspace(g).map_err(crate::error::Error::msg)?;
    if split {
        ws.split_rows();
    }
    let mut times = vec![];
    for _ in 0..repeats {
        let t = Instant::now();
        let r = m.rollout_with(
            &mut ws,
            s0,
            Timing::integration(dt, steps, steps),
            |_, _, _| {},
        );
        times.push(t.elapsed().as_secs_f64());
        r.map_err(crate::error::Error::msg)?;
    }
    Ok(median(times))
}

fn epoch_figure(
    name: String,
    trainee: Trainee,
    data: &(Graph, Vec<State>, Vec<Vec<f64>>),
    epochs: usize,
) -> Result<Figure> {
    Ok(Figure {
        name,
        value: epoch_seconds(trainee, data, epochs)? * 1e3,
        unit: "ms".into(),
        repeats: epochs,
    })
}

/// Runs the benchmark set: every figure, or those whose name contains
/// `only`. `quick` uses fewer repeats, and a tenth of the data for the
/// baselines and the candle engine on the cube.
pub fn run_all(quick: bool, only: Option<&str>) -> Result<Vec<Figure>> {
    let want = |name: &str| only.is_none_or(|o| name.to_lowercase().contains(&o.to_lowercase()));
    let mut out = family_epoch_figures(quick, &want)?;
    out.extend(baseline_epoch_figures(quick, &want)?);
    out.extend(rollout_figures(quick, &want)?);
    out.extend(plan_figures(quick, &want)?);
    out.extend(contact_figures(quick, &want)?);
    Ok(out)
}

/// Repeats of the timed runs: fewer with `quick`.
fn repeats(quick: bool) -> usize {
    if quick {
        5
    } else {
        21
    }
}

/// Timed epochs per training figure: fewer with `quick`.
fn epochs(quick: bool) -> usize {
    if quick {
        2
    } else {
        7
    }
}

/// MCGNODE epochs on the paper's data sets (100 trajectories of 100 states,
/// 75 % trained on) and on the 5×5×5 peridynamic cube (10 trajectories),
/// with each engine.
fn family_epoch_figures(quick: bool, want: &dyn Fn(&str) -> bool) -> Result<Vec<Figure>> {
    let ep = epochs(quick);
    let cores = crate::engine::all_cores();
    let mut out = vec![];
    // The paper's data sets: 100 trajectories of 100 states (75 % trained on).
    for (system, label) in [
        (SystemKind::Spring, "5-spring"),
        (SystemKind::Pendulum, "5-pendulum"),
    ] {
        let data = training_set(system, 5, 100);
        for (engine, threads) in [
            (EngineKind::Native, cores),
            (EngineKind::Native, 1),
            (EngineKind::Candle, 1),
        ] {
            let name = format!(
                "{label} MCGNODE epoch, 10,000 states, {engine:?} engine, {threads} thread(s)"
            )
            .to_lowercase();
            let t = Trainee::Family(Variant::Mcgnode, engine, threads);
            if want(&name) {
                out.push(epoch_figure(name, t, &data, ep)?);
            }
        }
    }
    // The 5×5×5 peridynamic cube, 10 trajectories.
    let cube = training_set(SystemKind::Peridynamic, 125, if quick { 1 } else { 10 });
    let states = cube.1.len();
    for (engine, threads) in [(EngineKind::Native, cores), (EngineKind::Candle, 1)] {
        let name = format!(
            "125-particle cube MCGNODE epoch, {states} states, {engine:?} engine, {threads} thread(s)"
        )
        .to_lowercase();
        let t = Trainee::Family(Variant::Mcgnode, engine, threads);
        if want(&name) {
            out.push(epoch_figure(name, t, &cube, ep.min(3))?);
        }
    }
    Ok(out)
}

/// Baselines' epochs on the 5-spring set (a tenth of it with `quick`).
fn baseline_epoch_figures(quick: bool, want: &dyn Fn(&str) -> bool) -> Result<Vec<Figure>> {
    use crate::baselines::Kind;
    let ep = epochs(quick);
    let mut out = vec![];
    let data = training_set(SystemKind::Spring, 5, if quick { 10 } else { 100 });
    let states = data.1.len();
    let candle = (EngineKind::Candle, 1);
    // LGN and HGN: the native engine on one thread and on every core, and
    // candle (the reference).
    let cores = crate::engine::all_cores();
    for kind in [Kind::Lgn, Kind::Hgn] {
        for (engine, threads) in [(EngineKind::Native, 1), (EngineKind::Native, cores), candle] {
            if engine == EngineKind::Native && threads == cores && cores == 1 {
                continue;
            }
            let name = match engine {
                EngineKind::Candle => format!("5-spring {kind} epoch, {states} states (candle)"),
                EngineKind::Native => format!(
                    "5-spring {kind} epoch, {states} states (native engine, {threads} thread)"
                ),
            };
            if want(&name) {
                let t = Trainee::Baseline(kind, engine, threads);
                out.push(epoch_figure(name, t, &data, ep.min(3))?);
            }
        }
    }
    // GNS on both engines, one thread each: on the springs, and on the
    // soft-sphere box (a radius graph with its walls) that reproduce's
    // contact part trains it on.
    let balls = training_set(SystemKind::SoftSpheres, 100, if quick { 1 } else { 4 });
    let sets = [("5-spring", &data), ("100-ball soft-sphere box", &balls)];
    for ((what, set), (engine, threads)) in sets
        .into_iter()
        .flat_map(|s| [(s, candle), (s, (EngineKind::Native, 1))])
    {
        let name = format!(
            "{what} gns epoch, {} states ({} engine, {threads} thread)",
            set.1.len(),
            format!("{engine:?}").to_lowercase()
        );
        if want(&name) {
            let t = Trainee::Baseline(Kind::Gns, engine, threads);
            out.push(epoch_figure(name, t, set, ep.min(3))?);
        }
    }
    Ok(out)
}

/// MCGNODE rollouts: the paper's spring and pendulum horizons, and steps per
/// second on rings of 5, 50 and 500 springs.
fn rollout_figures(quick: bool, want: &dyn Fn(&str) -> bool) -> Result<Vec<Figure>> {
    let r = repeats(quick);
    let mut out = vec![];
    let name = "5-spring MCGNODE rollout, 20 s (20,000 steps)";
    if want(name) {
        out.push(Figure {
            name: name.into(),
            value: rollout_seconds(SystemKind::Spring, 5, Variant::Mcgnode, 20_000, r)?,
            unit: "s".into(),
            repeats: r,
        });
    }
    let name = "5-pendulum MCGNODE rollout, 1 s (100,000 steps)";
    if want(name) {
        out.push(Figure {
            name: name.into(),
            value: rollout_seconds(SystemKind::Pendulum, 5, Variant::Mcgnode, 100_000, r.min(7))?,
            unit: "s".into(),
            repeats: r.min(7),
        });
    }
    for (n, steps) in [(50usize, 2_000usize), (5, 25)] {
        let name = format!(
            "ensemble: K = 5 MCGNODE members, {n}-spring {steps}-step rollout, cost against one model"
        );
        if want(&name) {
            out.push(Figure {
                name,
                value: ensemble_cost_ratio(n, 5, steps, r.min(5) * if n < 10 { 200 } else { 1 })?,
                unit: "x".into(),
                repeats: r.min(5),
            });
        }
    }
    for n in [5usize, 50, 500] {
        let name = format!("{n}-spring MCGNODE rollout speed");
        if !want(&name) {
            continue;
        }
        let steps = 2_000_000 / n.max(1) / if quick { 10 } else { 1 };
        let s = rollout_seconds(SystemKind::Spring, n, Variant::Mcgnode, steps, r.min(5))?;
        out.push(Figure::speed(name, steps, s, r.min(5)));
    }
    Ok(out)
}

/// One round of planning on a held chain, and one planning gradient.
fn plan_figures(quick: bool, want: &dyn Fn(&str) -> bool) -> Result<Vec<Figure>> {
    let r = repeats(quick);
    let mut out = vec![];
    let name = "plan: 256 candidates x 50 steps of a 20-particle held chain (MCGNODE, one round)";
    if want(name) {
        out.push(Figure {
            name: name.into(),
            value: plan_seconds(256, 5, r.min(5))?,
            unit: "s".into(),
            repeats: r.min(5),
        });
    }
    let name = "plan: 20,000 candidates x 20 steps of the same chain (MCGNODE, one round)";
    if want(name) {
        let repeats = if quick { 1 } else { 3 };
        out.push(Figure {
            name: name.into(),
            value: plan_seconds(20_000, 2, repeats)?,
            unit: "s".into(),
            repeats,
        });
    }
    let name = "plan gradient: d cost / d controls through 50 steps of the same chain (MCGNODE)";
    if want(name) {
        out.push(Figure {
            name: name.into(),
            value: plan_gradient_seconds(r)?,
            unit: "s".into(),
            repeats: r,
        });
    }
    Ok(out)
}

/// Steps per second of a rollout with contact edges, and the share of a
/// step the neighbour search takes.
fn contact_figures(quick: bool, want: &dyn Fn(&str) -> bool) -> Result<Vec<Figure>> {
    let r = repeats(quick);
    let mut out = vec![];
    let (g, s0) = contact_packing(32);
    let steps = if quick { 200 } else { 2_000 };
    let wide = crate::train::recipe::edge_blocks(Variant::Mcgnode);
    let width = wide.first().map_or(0, |(_, w)| w[0]);
    let wide_name = format!(
        "{}-particle contact MCGNODE rollout speed, train's edge blocks ({width} wide)",
        g.n()
    );
    let split_name = format!("{wide_name}, 2 cores (the node's)");
    // A soft-sphere box under gravity gets a body branch too (`train`'s
    // automatic --body-force): the node's benchmark model.
    let body_name = format!("{wide_name} and a body branch, 2 cores (the node's)");
    for (name, split, body) in [
        (wide_name, false, false),
        (split_name, true, false),
        (body_name, true, true),
    ] {
        if want(&name) {
            // What `train` makes by default and the node serves.
            let (_, m) = crate::testing::random_model_with(Variant::Mcgnode, &g, 0, |h| {
                h.block_hidden
                    .extend(wide.iter().map(|(b, w)| ((*b).to_string(), w.clone())));
                h.body_force = body;
            })?;
            let s = model_rollout_seconds(&m, &g, &s0, 1e-3, steps, r.min(5), split)?;
            out.push(Figure::speed(name, steps, s, r.min(5)));
        }
    }
    let name = format!(
        "{}-particle contact MCGNODE rollout speed (6 neighbours each)",
        g.n()
    );
    if want(&name) {
        let (_, m) = random_model(Variant::Mcgnode, &g, 0)?;
        let s = model_rollout_seconds(&m, &g, &s0, 1e-3, steps, r.min(5), false)?;
        out.push(Figure::speed(name, steps, s, r.min(5)));
        // The share of a step the neighbour search takes (one search per
        // evaluation, one evaluation per step), as the rollout searches:
        // the Verlet list along the rollout's own positions.
        let mut ws = m.kernel.workspace(&g).map_err(crate::error::Error::msg)?;
        let mut path = vec![];
        m.rollout_with(
            &mut ws,
            &s0,
            Timing::integration(1e-3, steps, 1),
            |_, q, _| path.push(q.to_vec()),
        )
        .map_err(crate::error::Error::msg)?;
        let times: Vec<f64> = (0..r.min(5))
            .map(|_| {
                let mut search = crate::physics::neighbors::NeighborSearch::new(&g);
                let t = Instant::now();
                for q in &path[..steps] {
                    std::hint::black_box(search.search_moving(q, 2, 1.0).len());
                }
                t.elapsed().as_secs_f64()
            })
            .collect();
        out.push(Figure {
            name: format!("{}-particle contact rollout: neighbour search share", g.n()),
            value: 100.0 * median(times) / s,
            unit: "% of a step".into(),
            repeats: r.min(5),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    /// The contact figure's packing has the six neighbours it claims inside
    /// (fewer on its rim), none bonded.
    #[test]
    fn the_contact_packing_has_six_neighbours_inside() {
        let (g, s) = super::contact_packing(32);
        let pairs = crate::physics::neighbors::brute_force_pairs(&g, &s.q, 1.0);
        let mut count = vec![0usize; g.n()];
        for (a, b) in pairs {
            count[a] += 1;
            count[b] += 1;
        }
        let inside = |k: usize| (2..30).contains(&(k % 32)) && (2..30).contains(&(k / 32));
        assert!((0..g.n()).filter(|&k| inside(k)).all(|k| count[k] == 6));
        let mean = count.iter().sum::<usize>() as f64 / g.n() as f64;
        assert!((5.5..6.0).contains(&mean), "{mean}");
    }
}
