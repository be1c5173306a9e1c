//! Training: reproducible, learns, conserves momentum exactly (MCGNODE), inductive.

use mcgnode::dynamics::Dynamics;
use mcgnode::model::{Hyper, ModelFile, TrainedModel, Variant};
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
    let (_, m) = mcgnode::bench::random_model(
        t.net.hyper.variant,
        &SystemConfig::new(SystemKind::Spring, 5).graph(),
        0,
    )
    .unwrap();
    let mut f: ModelFile = m.file;
    f.hyper = t.net.hyper.clone();
    f.weights = t.net.store.weights().unwrap();
    f.training = t.report;
    TrainedModel::from_file(f).unwrap()
}

#[test]
fn training_is_reproducible_and_learns() {
    let (g, s, a) = data(SystemKind::Spring, 5, 10, 1);
    let cfg = TrainConfig {
        epochs: 40,
        seed: 3,
        ..TrainConfig::default()
    };
    let hy = Hyper::new(Variant::Gnode, 2, 1, 5);
    let mut first_val = f64::NAN;
    let t1 = train(hy.clone(), &g, &s, &a, &cfg, |r| {
        if r.epoch == 1 {
            first_val = r.validation_loss;
        }
        true
    })
    .unwrap();
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
        let traj = m.rollout(&bg, &s0, 1e-3, 20_000).unwrap();
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
        let tr = mc.rollout(&gg, &c.start_for(&gg, 5, 0), 1e-3, 100).unwrap();
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
