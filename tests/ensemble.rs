//! Ensembles (`train --ensemble K`): one model file of K members whose
//! mean is the prediction and whose spread `evaluate --json` reports;
//! single-model files load and predict as before.

mod common;

use common::cli::{evaluate_json, mcgnode, ok};
use mcgnode::dynamics::{Dynamics, Timing};
use mcgnode::gnode::{Member, ModelFile};
use mcgnode::kernel::{Ensemble, TrainedModel};
use mcgnode::models::{load_any_model, ModelRef};
use mcgnode::physics::{SystemConfig, SystemKind};
use std::path::Path;

const SHIPPED: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/bags/models/spring5-mcgnode.json"
);

fn spreads(e: &serde_json::Value) -> Vec<f64> {
    e["calibration"]["spread_at_leads"]
        .as_array()
        .expect("spread_at_leads")
        .iter()
        .map(|l| l["mean_spread"].as_f64().expect("mean_spread"))
        .collect()
}

#[test]
fn an_ensemble_reports_its_spread_and_a_single_model_none() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sim = |seed: &str, n: &str, states: &str, out: &str| {
        ok(&mcgnode(
            &[
                "simulate",
                "--system",
                "spring",
                "--particles",
                "5",
                "--trajectories",
                n,
                "--seed",
                seed,
                "--states",
                states,
                "--out",
                out,
            ],
            d,
        ))
    };
    sim("1", "8", "30", "train.mcap");
    sim("2", "6", "21", "test.mcap");
    let train = |k: &str, out: &str| {
        ok(&mcgnode(
            &[
                "train",
                "--model",
                "mcgnode",
                "--data",
                "train.mcap",
                "--epochs",
                "5",
                "--ensemble",
                k,
                "--out",
                out,
                "--quiet",
            ],
            d,
        ))
    };
    train("2", "k2.json");
    train("1", "k1.json");
    let file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("k2.json")).unwrap()).unwrap();
    let members = file["members"].as_array().expect("members of a K = 2 file");
    assert_eq!(
        members.len(),
        1,
        "the file's own weights are the first member"
    );
    assert_ne!(members[0]["weights"], file["weights"], "members differ");
    assert_ne!(members[0]["training"]["seed"], file["training"]["seed"]);

    let e2 = evaluate_json(d, &["--model", "k2.json", "--bag", "test.mcap"]);
    let c = &e2["calibration"];
    assert_eq!(c["members"], 2);
    let keys: Vec<&String> = c.as_object().unwrap().keys().collect();
    assert!(keys.iter().any(|k| k.contains("spearman")), "{keys:?}");
    assert!(keys.iter().any(|k| k.contains("spread")), "{keys:?}");
    let s2 = spreads(&e2);
    assert!(!s2.is_empty(), "leads reached by 2 s trajectories: {c}");
    assert!(s2.iter().all(|s| *s > 0.0), "spread of two members: {s2:?}");
    assert!(c["spearman_spread_error_1s"].is_number(), "{c}");
    let f = c["within_2_spreads"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&f));

    let e1 = evaluate_json(d, &["--model", "k1.json", "--bag", "test.mcap"]);
    assert_eq!(e1["calibration"]["members"], 1);
    let s1 = spreads(&e1);
    assert!(!s1.is_empty() && s1.iter().all(|s| *s == 0.0), "{s1:?}");
    assert!(e1["calibration"]["spearman_spread_error_1s"].is_null());
}

#[test]
fn a_baseline_ensemble_is_refused_with_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&mcgnode(
        &[
            "simulate",
            "--particles",
            "3",
            "--trajectories",
            "2",
            "--states",
            "5",
            "--out",
            "t.mcap",
        ],
        d,
    ));
    let o = mcgnode(
        &[
            "train",
            "--model",
            "gns",
            "--data",
            "t.mcap",
            "--epochs",
            "1",
            "--ensemble",
            "2",
            "--out",
            "m.json",
        ],
        d,
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("GNODE family") && err.contains("without it"),
        "{err}"
    );
}

fn positions(model: &dyn Dynamics) -> Vec<f64> {
    let c = SystemConfig::new(SystemKind::Spring, 5);
    let g = c.graph();
    let start = c.start_for(&g, 11, 0);
    model
        .rollout(&g, &start, Timing::integration(1e-3, 500, 50))
        .unwrap()
        .iter()
        .flat_map(|s| s.q.clone())
        .collect()
}

#[test]
fn a_model_file_from_before_ensembles_loads_and_predicts_as_before() {
    let text = std::fs::read_to_string(SHIPPED).unwrap();
    assert!(
        !text.contains("\"members\""),
        "the shipped file predates ensembles"
    );
    let single = TrainedModel::from_file(ModelFile::load(Path::new(SHIPPED)).unwrap()).unwrap();
    let loaded = load_any_model(&ModelRef::from_path(Path::new(SHIPPED)).unwrap()).unwrap();
    assert_eq!(loaded.dynamics.members(), 1);
    assert_eq!(positions(loaded.dynamics.as_ref()), positions(&single));
    // Saved again, it is the same document: no members field appears.
    let dir = tempfile::tempdir().unwrap();
    let again = dir.path().join("again.json");
    single.file.save(&again).unwrap();
    let parse = |p: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let (mut before, mut after) = (parse(Path::new(SHIPPED)), parse(&again));
    before.as_object_mut().unwrap().remove("crate_version");
    after.as_object_mut().unwrap().remove("crate_version");
    assert_eq!(before, after);
}

#[test]
fn identical_members_predict_the_single_model_with_no_spread() {
    let file = ModelFile::load(Path::new(SHIPPED)).unwrap();
    let single = TrainedModel::from_file(file.clone()).unwrap();
    let mut twice = file.clone();
    twice.members.push(Member {
        training: file.training.clone(),
        weights: file.weights.clone(),
    });
    let ens = Ensemble::from_file(&twice).unwrap();
    assert_eq!(ens.members(), 2);
    let (a, b) = (positions(&ens), positions(&single));
    assert!(a
        .iter()
        .zip(&b)
        .all(|(x, y)| (x - y).abs() <= 1e-12 * y.abs().max(1.0)));
    let c = SystemConfig::new(SystemKind::Spring, 5);
    let g = c.graph();
    let starts = [c.start_for(&g, 11, 0), c.start_for(&g, 11, 1)];
    let out = ens
        .rollout_many_spread(&g, &starts, Timing::integration(1e-3, 200, 50))
        .unwrap();
    assert_eq!(out.len(), 2);
    for (r, s) in &out {
        assert_eq!(r.states.len(), s.len());
        assert!(s.iter().flatten().all(|x| *x == 0.0));
    }
    // Members that differ spread apart.
    let mut other = twice.clone();
    for w in other.members[0].weights.values_mut() {
        w.data.iter_mut().for_each(|x| *x *= 1.05);
    }
    let ens = Ensemble::from_file(&other).unwrap();
    let out = ens
        .rollout_many_spread(&g, &starts, Timing::integration(1e-3, 200, 50))
        .unwrap();
    assert!(out[0].1.last().unwrap().iter().all(|x| *x > 0.0));
}

#[test]
fn the_node_s_prediction_the_rollout_and_the_batch_agree_on_the_spread() {
    // What the node publishes (predict_into), what the Rollout service and
    // Python answer (rollout_spread) and what evaluate uses
    // (rollout_many_spread) are one mean and one spread.
    let file = ModelFile::load(Path::new(SHIPPED)).unwrap();
    let mut other = file.clone();
    let mut weights = file.weights.clone();
    for w in weights.values_mut() {
        w.data.iter_mut().for_each(|x| *x *= 0.97);
    }
    other.members.push(Member {
        training: file.training.clone(),
        weights,
    });
    let ens = Ensemble::from_file(&other).unwrap();
    let c = SystemConfig::new(SystemKind::Spring, 5);
    let g = c.graph();
    let start = c.start_for(&g, 11, 0);
    let timing = Timing::integration(1e-3, 200, 50);
    let (states, spread) = ens.rollout_spread(&g, &start, timing, None).unwrap();
    let mut p = mcgnode::dynamics::Predicted::default();
    ens.predict_into(&g, &start, timing, &mut p).unwrap();
    assert_eq!(p.states.to_states(), states);
    assert_eq!(p.spread, spread.concat());
    assert_eq!(spread.len(), states.len());
    assert!(spread.last().unwrap().iter().all(|x| *x > 0.0));
    let many = ens
        .rollout_many_spread(&g, std::slice::from_ref(&start), timing)
        .unwrap();
    assert_eq!(many[0].0.states, states);
    assert_eq!(many[0].1, spread);
    // A single model has none.
    let single = TrainedModel::from_file(file).unwrap();
    assert!(single
        .rollout_spread(&g, &start, timing, None)
        .unwrap()
        .1
        .is_empty());
}

#[test]
fn members_shared_among_the_cores_predict_as_one_by_one() {
    // Long enough (5 particles × 5,000 steps) for the members to run on all
    // cores: the same mean and spread as the members rolled out one by one.
    let file = ModelFile::load(Path::new(SHIPPED)).unwrap();
    let mut three = file.clone();
    for scale in [0.98, 1.03] {
        let mut weights = file.weights.clone();
        weights
            .values_mut()
            .for_each(|w| w.data.iter_mut().for_each(|x| *x *= scale));
        three.members.push(Member {
            training: file.training.clone(),
            weights,
        });
    }
    let ens = Ensemble::from_file(&three).unwrap();
    let c = SystemConfig::new(SystemKind::Spring, 5);
    let g = c.graph();
    let start = c.start_for(&g, 11, 0);
    let timing = Timing::integration(1e-3, 5_000, 500);
    assert!(g.n() * timing.steps() >= mcgnode::kernel::ensemble::PARALLEL_WORK);
    let (states, spread) = ens.rollout_spread(&g, &start, timing, None).unwrap();
    let alone: Vec<Vec<mcgnode::system::State>> = ens
        .members
        .iter()
        .map(|m| m.rollout(&g, &start, timing).unwrap())
        .collect();
    let refs: Vec<&[mcgnode::system::State]> = alone.iter().map(Vec::as_slice).collect();
    let (want_states, want_spread) = mcgnode::kernel::ensemble::mean_and_spread(2, &refs);
    assert_eq!(states, want_states);
    assert_eq!(spread, want_spread);
}

/// Every number in a JSON value, in order.
fn numbers(v: &serde_json::Value, out: &mut Vec<f64>) {
    match v {
        serde_json::Value::Number(n) => out.extend(n.as_f64()),
        serde_json::Value::Array(a) => a.iter().for_each(|x| numbers(x, out)),
        serde_json::Value::Object(o) => o.values().for_each(|x| numbers(x, out)),
        _ => {}
    }
}

/// Each member's weights, as flat numbers: the file's own first.
fn member_weights(file: &Path) -> Vec<Vec<f64>> {
    let f: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
    let mut out = vec![f["weights"].clone()];
    for m in f["members"].as_array().cloned().unwrap_or_default() {
        out.push(m["weights"].clone());
    }
    out.iter()
        .map(|w| {
            let mut x = Vec::new();
            numbers(w, &mut x);
            x
        })
        .collect()
}

#[test]
fn an_ensemble_warm_starts_member_by_member() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--particles",
            "5",
            "--trajectories",
            "6",
            "--states",
            "30",
            "--out",
            "train.mcap",
        ],
        d,
    ));
    let train = |extra: &[&str], out: &str| {
        let mut args = vec![
            "train",
            "--model",
            "mcgnode",
            "--data",
            "train.mcap",
            "--quiet",
            "--out",
            out,
        ];
        args.extend_from_slice(extra);
        mcgnode(&args, d)
    };
    ok(&train(&["--epochs", "20", "--ensemble", "3"], "k3.json"));
    // Without --ensemble: as many members as the --init model, each from its own.
    ok(&train(&["--epochs", "1", "--init", "k3.json"], "warm.json"));
    let (before, after) = (
        member_weights(&d.join("k3.json")),
        member_weights(&d.join("warm.json")),
    );
    assert_eq!(after.len(), 3, "the warm start keeps the ensemble");
    let dist = |a: &[f64], b: &[f64]| -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    for (i, w) in after.iter().enumerate() {
        let own = dist(w, &before[i]);
        for (j, b) in before.iter().enumerate().filter(|(j, _)| *j != i) {
            assert!(
                own < dist(w, b),
                "member {i} after one epoch is {own:.3e} from its own start, {:.3e} from member {j}'s",
                dist(w, b)
            );
        }
        assert!(own > 0.0, "member {i} trained");
    }
    // Another member count is refused, naming the one that works.
    let o = train(
        &["--epochs", "1", "--init", "k3.json", "--ensemble", "2"],
        "bad.json",
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--ensemble 3"), "{err}");
}
