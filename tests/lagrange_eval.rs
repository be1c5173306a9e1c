//! LagrangeBench's metrics in `evaluate` (MSE5/10/20, Sinkhorn, E_kin MSE),
//! through the CLI on the shipped model and sample bag. Run with
//! `cargo test --release --test lagrange_eval`.

mod common;

use common::cli::{evaluate_json, mcgnode, ok};
use common::ROOT;
use std::path::Path;

const MODEL: &str = "bags/models/spring5-mcgnode.json";
const BAG: &str = "bags/spring5-sample.mcap";

fn root() -> &'static Path {
    Path::new(ROOT)
}

fn num(v: &serde_json::Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} is not a number in {v}"))
}

/// The keys exist for the model and for standing still, and the shipped
/// model beats standing still on every one of them.
#[test]
fn shipped_model_beats_standing_still_on_the_benchmark_metrics() {
    let e = evaluate_json(root(), &["--model", MODEL, "--bag", BAG]);
    let (m, s) = (&e["lagrange"], &e["still_lagrange"]);
    assert_eq!(m["frames"].as_u64(), Some(20), "{m}");
    for key in ["mse5", "mse10", "mse20", "sinkhorn", "ekin_mse"] {
        let (model, still) = (num(m, key), num(s, key));
        assert!(model.is_finite() && model >= 0.0, "{key}: {model}");
        assert!(
            model < still,
            "{key}: the model ({model:e}) does not beat standing still ({still:e})"
        );
    }
    assert!(e["still"]["times_better"].as_f64().unwrap() > 1.0);
    let table = ok(&mcgnode(
        &["evaluate", "--model", MODEL, "--bag", BAG],
        root(),
    ));
    for needle in ["MSE5", "MSE10", "MSE20", "Sinkhorn", "E_kin MSE", "still"] {
        assert!(table.contains(needle), "{needle} missing from:\n{table}");
    }
}

/// Standing still's MSE20 is the mean over frames 1..=20 of the mean squared
/// displacement from the start, computed here from the bag itself; its
/// E_kin MSE scales as dx^(2d) with `--dx`; a Sinkhorn subsample of all the
/// particles is the full computation.
#[test]
fn still_metrics_match_a_direct_computation() {
    let e = evaluate_json(root(), &["--model", "still", "--bag", BAG]);
    let bag = common::cli::read(&root().join(BAG));
    let mut per_traj = vec![];
    for t in &bag.trajectories {
        let q0 = &t.samples[0].state.q;
        let frames: Vec<f64> = (1..=20)
            .map(|k| {
                let q = &t.samples[k].state.q;
                q.iter().zip(q0).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / q.len() as f64
            })
            .collect();
        per_traj.push(frames.iter().sum::<f64>() / 20.0);
    }
    let want = per_traj.iter().sum::<f64>() / per_traj.len() as f64;
    let got = num(&e["lagrange"], "mse20");
    assert!((got - want).abs() <= 1e-12 * want, "MSE20 {got} vs {want}");
    assert!(e["still_lagrange"].is_null(), "still is its own reference");

    let e2 = evaluate_json(root(), &["--model", "still", "--bag", BAG, "--dx", "2"]);
    let (a, b) = (
        num(&e["lagrange"], "ekin_mse"),
        num(&e2["lagrange"], "ekin_mse"),
    );
    let d = bag.trajectories[0].graph.dim as i32;
    let scale = 2f64.powi(2 * d);
    assert!(
        (b - scale * a).abs() <= 1e-9 * b,
        "E_kin MSE {a} at dx 1, {b} at dx 2"
    );
    assert_eq!(e2["dx_source"], "--dx");

    let all = bag.trajectories[0].graph.n().to_string();
    let e3 = evaluate_json(
        root(),
        &[
            "--model",
            "still",
            "--bag",
            BAG,
            "--sinkhorn-particles",
            &all,
        ],
    );
    assert_eq!(e3["lagrange"]["sinkhorn"], e["lagrange"]["sinkhorn"]);
    let e4 = evaluate_json(
        root(),
        &[
            "--model",
            "still",
            "--bag",
            BAG,
            "--sinkhorn-particles",
            "2",
        ],
    );
    let (full, sub) = (
        num(&e["lagrange"], "sinkhorn"),
        num(&e4["lagrange"], "sinkhorn"),
    );
    assert!(
        sub.is_finite() && sub != full,
        "subsample {sub} vs full {full}"
    );
}

/// Bad values of the new flags are refused, naming the flag.
#[test]
fn bad_metric_flags_are_refused() {
    for (flag, value) in [("--dx", "-1"), ("--dx", "0"), ("--sinkhorn-particles", "0")] {
        let arg = format!("{flag}={value}");
        let o = mcgnode(
            &["evaluate", "--model", "still", "--bag", BAG, &arg],
            root(),
        );
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{flag} {value} was accepted");
        let name = flag.trim_start_matches("--").replace('-', "_");
        assert!(
            err.contains(flag) || err.contains(&name) || err.contains("dx"),
            "{flag} {value}: {err}"
        );
    }
}
