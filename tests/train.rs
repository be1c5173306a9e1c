//! Training: reproducible, learns, conserves momentum exactly (MCGNODE), inductive.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use mcgnode::dynamics::Dynamics;
use mcgnode::gnode::{Hyper, ModelFile, Variant};
use mcgnode::kernel::TrainedModel;
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::system::State;
use mcgnode::train::{train, TrainConfig};

fn data(
    kind: SystemKind,
    n: usize,
    trajectories: usize,
    seed: u64,
) -> (mcgnode::system::Graph, Vec<State>, Vec<Vec<f64>>) {
    let c = SystemConfig::new(kind, n);
    let trajs = c.simulate(trajectories, seed);
    let g = trajs[0].graph.clone();
    let mut s = vec![];
    let mut a = vec![];
    for t in &trajs {
        for x in &t.samples {
            s.push(x.state.clone());
            a.push(
                x.acc
                    .clone()
                    .expect("simulated samples carry accelerations"),
            );
        }
    }
    (g, s, a)
}

fn to_model(t: mcgnode::train::Trained) -> TrainedModel {
    let (_, m) = mcgnode::testing::random_model(
        t.net.hyper.variant,
        &SystemConfig::new(SystemKind::Spring, 5).graph(),
        0,
    )
    .unwrap();
    let mut f: ModelFile = m.file;
    f.hyper = t.net.hyper.clone();
    f.weights = t.net.store.weights().unwrap();
    f.training = t.report;
    f.optimizer = Some(t.optimizer);
    TrainedModel::from_file(f).unwrap()
}

/// Trains and returns the result with the validation loss of its first epoch.
fn train_first(
    hy: &Hyper,
    g: &mcgnode::system::Graph,
    s: &[State],
    a: &[Vec<f64>],
    cfg: &TrainConfig,
) -> (mcgnode::train::Trained, f64) {
    let mut first = f64::NAN;
    let t = train(hy.clone(), g, s, a, cfg, |r| {
        if r.epoch == 1 {
            first = r.validation_loss;
        }
        true
    })
    .unwrap();
    (t, first)
}

#[test]
fn training_is_reproducible_and_learns() {
    let (g, s, a) = data(SystemKind::Spring, 5, 10, 1);
    // Unscaled, so that the first epoch starts far from the data (the scaled
    // model starts near "predict the mean"; see `normalisation_is_recorded`).
    let cfg = TrainConfig {
        epochs: 40,
        seed: 3,
        normalize: false,
        ..TrainConfig::default()
    };
    let hy = Hyper::new(Variant::Gnode, 2, 1, 5);
    let (t1, first_val) = train_first(&hy, &g, &s, &a, &cfg);
    let t2 = train(hy.clone(), &g, &s, &a, &cfg, |_| true).unwrap();
    assert_eq!(
        t1.net.store.weights().unwrap(),
        t2.net.store.weights().unwrap(),
        "same seed, same weights"
    );
    assert!(
        t1.report.validation_loss < 0.5 * first_val,
        "validation loss should fall: epoch 1 {first_val}, best {}",
        t1.report.validation_loss
    );
    let t3 = train(
        hy,
        &g,
        &s,
        &a,
        &TrainConfig {
            seed: 4,
            ..cfg.clone()
        },
        |_| true,
    )
    .unwrap();
    assert_ne!(
        t1.net.store.weights().unwrap(),
        t3.net.store.weights().unwrap()
    );
    // Cancelling from the callback stops training with an error that says so.
    let hy = Hyper::new(Variant::Mcgnode, 2, 1, 5);
    let err = train(hy, &g, &s, &a, &cfg, |r| r.epoch < 3).err().unwrap();
    assert!(format!("{err}").contains("cancelled"));
}

/// The paper's theorem, as a test: MCGNODE without a body-force branch, trained
/// on 5 springs and rolled out for 20 s on 50 springs, keeps total momentum to
/// round-off; GNODE trained the same way does not.
#[test]
fn mcgnode_conserves_momentum_on_unseen_sizes() {
    let (g, s, a) = data(SystemKind::Spring, 5, 10, 1);
    let cfg = TrainConfig {
        epochs: 15,
        seed: 1,
        ..TrainConfig::default()
    };
    let mut hy = Hyper::new(Variant::Mcgnode, 2, 1, 5);
    hy.body_force = false;
    let mc = to_model(train(hy, &g, &s, &a, &cfg, |_| true).unwrap());
    let gn = to_model(
        train(
            Hyper::new(Variant::Gnode, 2, 1, 5),
            &g,
            &s,
            &a,
            &cfg,
            |_| true,
        )
        .unwrap(),
    );
    let big = SystemConfig::new(SystemKind::Spring, 50);
    let bg = big.graph();
    // Start with non-zero momentum so that the relative change is well defined.
    let mut s0 = big.start_for(&bg, 77, 0);
    for i in 0..50 {
        s0.v[2 * i] += 0.3;
    }
    let p0 = s0.momentum(&bg);
    let scale: f64 = p0.iter().map(|x| x * x).sum::<f64>().sqrt();
    let drift = |m: &TrainedModel| {
        let traj = m
            .rollout(
                &bg,
                &s0,
                mcgnode::dynamics::Timing::integration(1e-3, 20_000, 1),
            )
            .unwrap();
        let p = traj.last().unwrap().momentum(&bg);
        p.iter()
            .zip(&p0)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt()
            / scale
    };
    let d_mc = drift(&mc);
    let d_gn = drift(&gn);
    assert!(d_mc < 1e-12, "MCGNODE momentum drift {d_mc}");
    assert!(
        d_gn > 1e-6,
        "GNODE should not conserve momentum exactly (drift {d_gn})"
    );
    // Inductive: the same model runs on 3 and 20 springs.
    for n in [3usize, 20] {
        let c = SystemConfig::new(SystemKind::Spring, n);
        let gg = c.graph();
        let tr = mc
            .rollout(
                &gg,
                &c.start_for(&gg, 5, 0),
                mcgnode::dynamics::Timing::integration(1e-3, 100, 1),
            )
            .unwrap();
        assert_eq!(tr.len(), 101);
    }
}

/// The pendulum path: CGNODE (constrained solve inside) trains and its
/// accelerations satisfy the bars.
#[test]
fn constrained_training_on_pendulum() {
    let mut c = SystemConfig::new(SystemKind::Pendulum, 3);
    c.states = 20;
    let trajs = c.simulate(5, 1);
    let g = trajs[0].graph.clone();
    let s: Vec<State> = trajs
        .iter()
        .flat_map(|t| t.samples.iter().map(|x| x.state.clone()))
        .collect();
    let a: Vec<Vec<f64>> = trajs
        .iter()
        .flat_map(|t| t.samples.iter().map(|x| x.acc.clone().unwrap()))
        .collect();
    let mut first = f64::NAN;
    let t = train(
        Hyper::new(Variant::Cgnode, 2, 1, 3),
        &g,
        &s,
        &a,
        &TrainConfig {
            epochs: 30,
            batch: 20,
            ..TrainConfig::default()
        },
        |r| {
            if r.epoch == 1 {
                first = r.validation_loss
            }
            true
        },
    )
    .unwrap();
    assert!(
        t.report.validation_loss < first,
        "loss should fall ({first} → {})",
        t.report.validation_loss
    );
}

fn spring_dataset(trajectories: usize) -> mcgnode::data::dataset::Dataset {
    let trajs = SystemConfig::new(SystemKind::Spring, 5).simulate(trajectories, 1);
    mcgnode::data::dataset::Dataset::from_trajectories(&trajs).unwrap()
}

#[test]
fn subsample_keeps_a_seeded_ordered_subset() {
    let full = spring_dataset(5);
    assert_eq!(full.len(), 500);
    let mut a = full.clone();
    a.subsample(120, 7).unwrap();
    assert_eq!((a.len(), a.acc.len()), (120, 120));
    let mut b = full.clone();
    b.subsample(120, 7).unwrap();
    assert_eq!(a, b, "same seed, same subset");
    let mut c = full.clone();
    c.subsample(120, 8).unwrap();
    assert_ne!(a.states, c.states, "another seed, another subset");
    // Kept pairs are the original ones, in their original order.
    let pos: Vec<usize> = a
        .states
        .iter()
        .map(|s| full.states.iter().position(|x| x == s).unwrap())
        .collect();
    assert!(pos.windows(2).all(|w| w[0] < w[1]), "order not kept");
    for (k, &i) in pos.iter().enumerate() {
        assert_eq!(a.acc[k], full.acc[i], "state and target separated");
    }
    let mut all = full.clone();
    all.subsample(500, 1).unwrap();
    assert_eq!(all, full);
    for bad in [501, 1, 0] {
        let err = full.clone().subsample(bad, 1).unwrap_err().to_string();
        assert!(
            err.contains(&bad.to_string()) && err.contains("500"),
            "{err}"
        );
    }
}

#[test]
fn add_noise_has_the_requested_spread() {
    let clean = spring_dataset(10);
    let values: Vec<f64> = clean.acc.iter().flatten().copied().collect();
    assert!(values.len() >= 10_000, "{} components", values.len());
    let std = |x: &[f64]| {
        let m = x.iter().sum::<f64>() / x.len() as f64;
        (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / x.len() as f64).sqrt()
    };
    let mut zero = clean.clone();
    assert_eq!(zero.add_noise(0.0, 3).unwrap(), 0.0);
    assert_eq!(zero, clean, "0 % noise must leave the data bit-identical");

    let mut noisy = clean.clone();
    let sigma = noisy.add_noise(10.0, 3).unwrap();
    assert!((sigma - 0.1 * std(&values)).abs() < 1e-12 * sigma);
    assert_eq!(noisy.states, clean.states, "noise only on the targets");
    let diff: Vec<f64> = noisy
        .acc
        .iter()
        .flatten()
        .zip(&values)
        .map(|(a, b)| a - b)
        .collect();
    let got = std(&diff);
    println!(
        "10 % noise: σ = {sigma:.4e}, empirical {got:.4e} over {} components",
        diff.len()
    );
    assert!(
        (got / sigma - 1.0).abs() < 0.05,
        "σ {sigma}, empirical {got}"
    );
    let mut again = clean.clone();
    again.add_noise(10.0, 3).unwrap();
    assert_eq!(again, noisy, "same seed, same noise");
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        assert!(clean.clone().add_noise(bad, 3).is_err(), "{bad}");
    }
}

#[test]
fn training_on_a_subset_reports_it() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("train.mcap");
    let trajs = SystemConfig::new(SystemKind::Spring, 5).simulate(4, 1);
    mcgnode::data::bag::write_trajectories(&bag, &trajs, &Default::default()).unwrap();
    let cfg = TrainConfig {
        epochs: 2,
        points: Some(200),
        noise: 5.0,
        seed: 4,
        ..TrainConfig::default()
    };
    let mut lines = vec![];
    let file = mcgnode::models::train_from_bags(
        mcgnode::models::ModelKind::Family(Variant::Gnode),
        &[bag],
        &mcgnode::train::ModelOptions::for_recipe(mcgnode::train::Recipe::Paper),
        &cfg,
        |m| lines.push(m.to_string()),
        |_| true,
    )
    .unwrap()
    .into_family()
    .expect("a GNODE-family file");
    assert_eq!(file.training.points, Some(200));
    assert_eq!(file.training.noise, 5.0);
    assert_eq!(file.trained_on.states, 200);
    assert_eq!(file.trained_on.trajectories, 4);
    assert!(
        lines.iter().any(|l| l == "using 200 of 400 states"),
        "{lines:?}"
    );
    assert!(
        lines.iter().any(|l| l.starts_with("added 5% noise: σ = ")),
        "{lines:?}"
    );
    let too_many = TrainConfig {
        points: Some(401),
        ..cfg
    };
    let err = mcgnode::models::train_from_bags(
        mcgnode::models::ModelKind::Family(Variant::Gnode),
        &[dir.path().join("train.mcap")],
        &mcgnode::train::ModelOptions::for_recipe(mcgnode::train::Recipe::Paper),
        &too_many,
        |_| {},
        |_| true,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("401"), "{err}");
}

/// Model files written before the noise and points fields still load, as
/// trained on all clean data.
#[test]
fn old_model_files_load_without_noise_and_points() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    // The models shipped before the default recipe, kept as they were written.
    for name in [
        "legacy-spring5-mcgnode.json",
        "legacy-pendulum5-mcgnode.json",
    ] {
        let path = root.join("tests/fixtures").join(name);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains("\"points\""), "{name} is not an old file");
        let m = ModelFile::load(&path).unwrap();
        assert_eq!(m.training.noise, 0.0);
        assert_eq!(m.training.points, None);
    }
}

/// `init` continues from a model's weights and Adam state: the first epoch
/// starts where the earlier training ended (not where a fresh one starts),
/// and a model of another architecture is refused.
#[test]
fn warm_start_continues_training() {
    let (g, s, a) = data(SystemKind::Spring, 5, 6, 1);
    // Unscaled, so that a fresh start is far from where training ends.
    let cfg = TrainConfig {
        epochs: 25,
        seed: 2,
        normalize: false,
        ..TrainConfig::default()
    };
    let hy = Hyper::new(Variant::Mcgnode, 2, 1, 5);
    let (first, fresh_first) = train_first(&hy, &g, &s, &a, &cfg);
    let file = to_model(first).file;
    let steps = file.optimizer.as_ref().expect("Adam state kept").step;
    assert!(steps > 0);
    let best = file.training.validation_loss;
    let warm = TrainConfig {
        init: Some(Box::new(file.clone())),
        ..cfg.clone()
    };
    let (second, warm_first) = train_first(&file.hyper, &g, &s, &a, &warm);
    assert!(
        warm_first < 0.5 * fresh_first && warm_first < 2.0 * best,
        "warm start's first epoch {warm_first:.3e}: fresh {fresh_first:.3e}, earlier best {best:.3e}"
    );
    assert!(second.report.validation_loss <= warm_first);
    assert!(second.optimizer.step > steps, "Adam's step count continues");
    let mut other = file.hyper.clone();
    other.hidden = 7;
    let err = train(other, &g, &s, &a, &warm, |_| true).err().unwrap();
    assert!(err.to_string().contains("architecture"), "{err}");
}

/// Training scales inputs and outputs by statistics of its training split and
/// records them; the trained model's kernel applies them (its accelerations
/// equal candle's on the trained net, which does too).
#[test]
fn normalisation_is_recorded_and_applied() {
    let (g, s, a) = data(SystemKind::Spring, 5, 4, 3);
    let cfg = TrainConfig {
        epochs: 3,
        ..TrainConfig::default()
    };
    let t = train(
        Hyper::new(Variant::Mcgnode, 2, 1, 5),
        &g,
        &s,
        &a,
        &cfg,
        |_| true,
    )
    .unwrap();
    let norm = t.net.hyper.norm.clone().expect("normalised by default");
    let rms = |xs: &mut dyn Iterator<Item = f64>| {
        let v: Vec<f64> = xs.collect();
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    };
    // The split keeps 75 % of the states: the scales are near the full data's.
    let acc_rms = rms(&mut a.iter().flatten().copied());
    let v_rms = rms(&mut s.iter().flat_map(|x| x.v.iter().copied()));
    assert!(
        (norm.out_scale / acc_rms - 1.0).abs() < 0.1,
        "{} vs {acc_rms}",
        norm.out_scale
    );
    assert!(
        (norm.v_scale / v_rms - 1.0).abs() < 0.1,
        "{} vs {v_rms}",
        norm.v_scale
    );
    assert!(norm.w_scale > 0.1 && norm.q_scale > 0.1);
    let unscaled = TrainConfig {
        normalize: false,
        ..cfg.clone()
    };
    let u = train(
        Hyper::new(Variant::Mcgnode, 2, 1, 5),
        &g,
        &s,
        &a,
        &unscaled,
        |_| true,
    )
    .unwrap();
    assert!(u.net.hyper.norm.is_none());
    // Same weights, different scales: different accelerations.
    let m = to_model(t);
    let mut other = m.file.clone();
    other.hyper.norm = None;
    let other = TrainedModel::from_file(other).unwrap();
    let (mut x, mut y) = (vec![0.0; 10], vec![0.0; 10]);
    m.acceleration(&g, &s[7], &mut x).unwrap();
    other.acceleration(&g, &s[7], &mut y).unwrap();
    assert!(x.iter().zip(&y).any(|(p, q)| (p - q).abs() > 1e-6));
}

/// With `edge_physics` a model reads each edge's stiffness (a stiffer ring
/// gets other accelerations); without it, a model refuses edges it was not
/// trained on and names the flag.
#[test]
fn edge_physics_reads_stiffness_and_plain_models_refuse_other_edges() {
    use mcgnode::compat::TrainedFor;
    use mcgnode::gnode::EdgeParams;
    let (g, s, a) = data(SystemKind::Spring, 5, 3, 1);
    let mut stiff = g.clone();
    stiff.edges.iter_mut().for_each(|e| e.stiffness = 5.0);
    let cfg = TrainConfig {
        epochs: 2,
        ..TrainConfig::default()
    };
    let trained_for = |m: &TrainedModel| {
        let mut f = m.file.clone();
        f.trained_on.edge_params = EdgeParams::of(&g);
        TrainedFor::from_model_json("m", &serde_json::to_value(&f).unwrap())
    };
    let plain = to_model(
        train(
            Hyper::new(Variant::Mcgnode, 2, 1, 5),
            &g,
            &s,
            &a,
            &cfg,
            |_| true,
        )
        .unwrap(),
    );
    let tf = trained_for(&plain);
    assert!(tf.check(&g, None).is_ok());
    let err = tf.check(&stiff, None).unwrap_err().to_string();
    assert!(
        err.contains("--edge-physics") && err.contains("stiffness 5"),
        "{err}"
    );
    let mut h = Hyper::new(Variant::Mcgnode, 2, 1, 5);
    h.edge_physics = true;
    let phys = to_model(train(h, &g, &s, &a, &cfg, |_| true).unwrap());
    assert!(trained_for(&phys).check(&stiff, None).is_ok());
    let (mut x, mut y) = (vec![0.0; 10], vec![0.0; 10]);
    phys.acceleration(&g, &s[5], &mut x).unwrap();
    phys.acceleration(&stiff, &s[5], &mut y).unwrap();
    assert!(
        x.iter().zip(&y).any(|(p, q)| (p - q).abs() > 1e-9),
        "stiffness is read"
    );
    plain.acceleration(&g, &s[5], &mut x).unwrap();
    plain.acceleration(&stiff, &s[5], &mut y).unwrap();
    assert_eq!(
        x, y,
        "a plain model cannot see stiffness (hence the refusal)"
    );
}

/// A learning-rate step applies from the epoch after it (a step to a
/// vanishing rate freezes the weights) and is recorded in the report.
#[test]
fn learning_rate_steps_apply_and_are_recorded() {
    let cfg = TrainConfig {
        lr: 1e-2,
        lr_drops: vec![(300, 1e-4), (200, 1e-3)],
        ..TrainConfig::default()
    };
    assert_eq!(
        [cfg.lr_at(1), cfg.lr_at(200), cfg.lr_at(201), cfg.lr_at(301)],
        [1e-2, 1e-2, 1e-3, 1e-4]
    );
    let (g, s, a) = data(SystemKind::Spring, 5, 3, 1);
    let cfg = TrainConfig {
        epochs: 4,
        lr_drops: vec![(2, 1e-300)],
        ..TrainConfig::default()
    };
    let mut val = vec![];
    let t = train(Hyper::new(Variant::Gnode, 2, 1, 5), &g, &s, &a, &cfg, |r| {
        val.push(r.validation_loss);
        true
    })
    .unwrap();
    assert_ne!(val[0], val[1], "epochs 1-2 train at the base rate");
    assert_eq!(val[2], val[3], "after the step nothing moves");
    assert_eq!(t.report.lr_drops, vec![(2, 1e-300)]);
}

/// A wall-clock budget ends training after the first epoch that passes it,
/// keeps the best weights so far and is recorded; a budget that is not a
/// positive number of seconds is refused.
#[test]
fn time_budget_stops_training_and_is_recorded() {
    let (g, s, a) = data(SystemKind::Spring, 5, 3, 1);
    let budget = 0.4;
    let cfg = TrainConfig {
        epochs: 1_000_000,
        patience: 1_000_000,
        time_budget: Some(budget),
        threads: 1,
        ..TrainConfig::default()
    };
    let mut seen = vec![];
    let t = train(Hyper::new(Variant::Gnode, 2, 1, 5), &g, &s, &a, &cfg, |r| {
        seen.push((r.elapsed, r.validation_loss));
        true
    })
    .unwrap();
    let r = &t.report;
    assert!(r.out_of_time && !r.stopped_early);
    assert_eq!(r.time_budget, Some(budget));
    assert_eq!(r.epochs_run, seen.len());
    assert!(seen.len() >= 2 && seen.len() < 1_000_000);
    let last = seen.len() - 1;
    assert!(seen[last].0 >= budget, "stopped before the budget");
    assert!(
        seen[last - 1].0 < budget,
        "ran past the first epoch over budget"
    );
    let best = seen.iter().map(|x| x.1).fold(f64::INFINITY, f64::min);
    assert_eq!(r.validation_loss, best, "best weights kept");
    let json = serde_json::to_string(r).unwrap();
    assert!(json.contains("\"out_of_time\":true"), "{json}");
    for bad in [0.0, -1.0, f64::NAN] {
        let cfg = TrainConfig {
            epochs: 2,
            time_budget: Some(bad),
            ..TrainConfig::default()
        };
        let e = train(
            Hyper::new(Variant::Gnode, 2, 1, 5),
            &g,
            &s,
            &a,
            &cfg,
            |_| true,
        );
        let msg = format!("{:#}", e.err().expect("refused"));
        assert!(msg.contains("time budget"), "{msg}");
    }
}

/// A run stopped part-way (here by a cancel, as a crash or the end of a
/// session would stop it) and started again on the same checkpoint ends bit
/// for bit where an uninterrupted run ends: weights, Adam's state, best
/// epoch and losses. A finished run is not trained again, a longer one goes
/// on from it, and a checkpoint of another run is refused with its fix.
#[test]
fn checkpointed_training_resumes_exactly() {
    use mcgnode::train::{Checkpoint, Checkpointing};
    let (g, s, a) = data(SystemKind::Spring, 5, 4, 1);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.ckpt.json");
    let cfg = TrainConfig {
        epochs: 10,
        seed: 5,
        threads: 2,
        lr: 3e-3,
        lr_drops: vec![(6, 1e-3)],
        ..TrainConfig::default()
    };
    let hy = Hyper::new(Variant::Mcgnode, 2, 1, 5);
    let weights = |t: &mcgnode::train::Trained| t.net.store.weights().unwrap();
    let straight = train(hy.clone(), &g, &s, &a, &cfg, |_| true).unwrap();
    let ck = TrainConfig {
        checkpoint: Some(Checkpointing {
            path: path.clone(),
            every: 0.0,
        }),
        ..cfg.clone()
    };
    let err = train(hy.clone(), &g, &s, &a, &ck, |r| r.epoch < 4)
        .err()
        .expect("cancelled");
    assert!(format!("{err}").contains("cancelled at epoch 4"), "{err}");
    let saved: Checkpoint = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(saved.progress.epoch, 4);
    // The file is flat: the progress fields sit beside the parameters (as
    // in checkpoints written before they were grouped).
    let raw: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(raw["epoch"], 4);
    assert!(raw["best_theta"].is_array() && raw.get("progress").is_none());
    let mut epochs = vec![];
    let resumed = train(hy.clone(), &g, &s, &a, &ck, |r| {
        epochs.push(r.epoch);
        true
    })
    .unwrap();
    assert_eq!(
        epochs,
        (5..=10).collect::<Vec<_>>(),
        "went on after epoch 4"
    );
    assert_eq!(weights(&resumed), weights(&straight), "same weights");
    assert_eq!(resumed.optimizer, straight.optimizer, "same Adam state");
    let (r, q) = (&resumed.report, &straight.report);
    assert_eq!(
        (r.epochs_run, r.best_epoch, r.validation_loss, r.train_loss),
        (q.epochs_run, q.best_epoch, q.validation_loss, q.train_loss)
    );
    assert_eq!(r.resumed_at, Some(4));
    assert!(
        r.seconds >= saved.progress.seconds,
        "seconds count every session"
    );
    // Finished: nothing is trained again, the result is the same.
    let again = train(hy.clone(), &g, &s, &a, &ck, |_| {
        panic!("a finished run trained again")
    })
    .unwrap();
    assert_eq!(weights(&again), weights(&straight));
    assert_eq!(
        again.report.seconds, resumed.report.seconds,
        "a finished run states the seconds it had (budgets derived from them match)"
    );
    // Longer: goes on from epoch 10 to where a straight 14-epoch run ends.
    let longer = |c: &TrainConfig| TrainConfig {
        epochs: 14,
        ..c.clone()
    };
    let straight14 = train(hy.clone(), &g, &s, &a, &longer(&cfg), |_| true).unwrap();
    let went_on = train(hy.clone(), &g, &s, &a, &longer(&ck), |_| true).unwrap();
    assert_eq!(weights(&went_on), weights(&straight14));
    assert_eq!(went_on.report.resumed_at, Some(10));
    // Another seed, or other data: refused, naming what differs and the fix.
    for (other, what) in [
        (
            TrainConfig {
                seed: 6,
                ..ck.clone()
            },
            "seed",
        ),
        (
            TrainConfig {
                batch: 50,
                ..ck.clone()
            },
            "batch",
        ),
    ] {
        let e = train(hy.clone(), &g, &s, &a, &other, |_| true)
            .err()
            .expect("refused");
        let msg = format!("{e}");
        assert!(
            msg.contains("another training run") && msg.contains(what) && msg.contains("remove it"),
            "{msg}"
        );
    }
    let half = s.len() / 2;
    let e = train(hy, &g, &s[..half], &a[..half], &ck, |_| true)
        .err()
        .expect("refused");
    assert!(format!("{e}").contains("training samples"), "{e}");
}
