//! Position-only recordings with tracker noise: `mcgnode bag observe`,
//! `replay --positions-only / --smoother / --reference`, and
//! scripts/noise.sh, which makes the README's noise table.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mcgnode");

fn mcgnode(dir: &Path, args: &[&str]) -> std::process::Output {
    Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .output()
        .expect("running mcgnode")
}

fn ok(o: &std::process::Output) -> String {
    assert!(
        o.status.success(),
        "failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Mean RE at lead `lead` of a replay's JSON report.
fn re_at(json: &str, lead: f64) -> f64 {
    let r: serde_json::Value = serde_json::from_str(json).expect("replay JSON");
    let t = r["summary"]["t"].as_array().expect("t");
    let i = (0..t.len())
        .min_by(|&a, &b| {
            let d = |k: usize| (t[k].as_f64().unwrap() - lead).abs();
            d(a).total_cmp(&d(b))
        })
        .expect("leads");
    r["summary"]["re"]["gmean"][i].as_f64().expect("RE")
}

#[test]
fn observed_bags_replay_as_the_node_predicts_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/models/spring5-mcgnode.json");
    let model = model.to_str().unwrap();
    ok(&mcgnode(
        d,
        &[
            "simulate",
            "--save-every",
            "10",
            "--states",
            "201",
            "--trajectories",
            "2",
            "--seed",
            "7",
            "--out",
            "truth.mcap",
        ],
    ));
    let out = ok(&mcgnode(
        d,
        &[
            "bag",
            "observe",
            "truth.mcap",
            "--out",
            "noisy.mcap",
            "--noise",
            "0.001",
        ],
    ));
    assert!(out.contains("402 position-only states"), "{out}");
    // bag info reads it, and says the velocities are derived.
    let info = ok(&mcgnode(d, &["bag", "info", "noisy.mcap"]));
    assert!(info.contains("spring"), "{info}");
    let replay_bag = |bag: &str, extra: &[&str]| {
        let mut args = vec![
            "replay",
            "--bag",
            bag,
            "--model",
            model,
            "--horizon",
            "0.5",
            "--json",
        ];
        args.extend_from_slice(extra);
        ok(&mcgnode(d, &args))
    };
    let replay = |extra: &[&str]| replay_bag("noisy.mcap", extra);
    let plain = replay(&["--reference", "truth.mcap"]);
    let smooth = replay(&[
        "--reference",
        "truth.mcap",
        "--smoother",
        "poly",
        "--smoother-window",
        "25",
    ]);
    let r: serde_json::Value = serde_json::from_str(&smooth).unwrap();
    assert!(
        r["start_velocities"]
            .as_str()
            .unwrap()
            .contains("degree-2 fit over the last 25"),
        "{}",
        r["start_velocities"]
    );
    assert!(r["scored_against"].as_str().unwrap().contains("truth.mcap"));
    // The warm-up: the first 24 states per trajectory are no start (nor the
    // last, which has nothing after it).
    assert_eq!(r["starts"], 2 * (201 - 24 - 1));
    let (p, s) = (re_at(&plain, 0.1), re_at(&smooth, 0.1));
    println!("RE at 0.1 s with 0.1 % noise: three-point {p:.2e}, poly 25 {s:.2e}");
    assert!(s < p / 4.0, "{s} vs {p}");
    // Scored against the noisy bag itself, the noise floor shows.
    let own = replay(&["--smoother", "poly", "--smoother-window", "25"]);
    assert!(re_at(&own, 0.1) > s, "noisy truth should score worse");
    // A full bag replayed from positions only: noise-free, close to full.
    let replay_truth = |extra: &[&str]| replay_bag("truth.mcap", extra);
    let full = replay_truth(&[]);
    let pos = replay_truth(&["--positions-only"]);
    let (f, q) = (re_at(&full, 0.5), re_at(&pos, 0.5));
    assert!(q < 2.0 * f && q > 0.5 * f, "{q} vs {f}");
    // Bad settings and a reference that does not match say what to do.
    let e = mcgnode(
        d,
        &[
            "bag",
            "observe",
            "truth.mcap",
            "--out",
            "x.mcap",
            "--drop",
            "1",
        ],
    );
    assert!(!e.status.success());
    assert!(String::from_utf8_lossy(&e.stderr).contains("drop 1 must be in [0, 1)"));
    ok(&mcgnode(
        d,
        &[
            "simulate",
            "--save-every",
            "10",
            "--states",
            "50",
            "--trajectories",
            "2",
            "--seed",
            "7",
            "--out",
            "short.mcap",
        ],
    ));
    let e = mcgnode(
        d,
        &[
            "replay",
            "--bag",
            "noisy.mcap",
            "--model",
            model,
            "--reference",
            "short.mcap",
        ],
    );
    let err = String::from_utf8_lossy(&e.stderr);
    assert!(
        !e.status.success() && err.contains("pass the recording the replayed bag was made from"),
        "{err}"
    );
    let e = mcgnode(
        d,
        &[
            "replay",
            "--bag",
            "noisy.mcap",
            "--model",
            model,
            "--smoother",
            "poly",
            "--smoother-window",
            "3",
        ],
    );
    let err = String::from_utf8_lossy(&e.stderr);
    assert!(!e.status.success() && err.contains("window 3"), "{err}");
}

/// scripts/noise.sh (smaller: 1 trajectory of 201 states) prints the README's table; what
/// the README says of it holds.
#[test]
fn noise_script_makes_the_readme_table() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new("bash")
        .arg(root.join("scripts/noise.sh"))
        .arg(dir.path())
        .env("MCGNODE", BIN)
        .env("TRAJECTORIES", "1")
        // Shorter than the default 301: the model rows fit through the rollout.
        .env("STATES", "201")
        .output()
        .expect("running scripts/noise.sh");
    let table = ok(&o);
    println!("{table}");
    // (system, input, smoother) -> (RE at 0.1 s, RE at 1 s)
    let rows: Vec<(String, String, String, f64, f64)> = table
        .lines()
        .skip(2)
        .map(|l| {
            let c: Vec<&str> = l.trim_matches('|').split('|').map(str::trim).collect();
            let x = |k: usize| c[k].parse::<f64>().unwrap_or(f64::NAN);
            (c[0].into(), c[1].into(), c[2].into(), x(3), x(4))
        })
        .collect();
    // Per system: full states, and at 3 noise levels none, poly 9, model 9,
    // poly 25, model 25.
    assert_eq!(rows.len(), 32, "{table}");
    for r in &rows {
        assert!(r.3 > 0.0 && r.3 < 1.0 && r.4 > 0.0 && r.4 < 1.0, "{r:?}");
    }
    // Standing still beside each row: the noise-free model beats it.
    let still: Vec<f64> = table
        .lines()
        .skip(2)
        .map(|l| {
            l.trim_matches('|')
                .split('|')
                .nth(6)
                .unwrap_or("")
                .trim()
                .parse()
                .unwrap_or(f64::NAN)
        })
        .collect();
    assert!(
        still.iter().all(|s| *s > 0.0 && *s < 1.0),
        "{still:?}\n{table}"
    );
    for (r, s) in rows.iter().zip(&still) {
        if r.1 == "full states" {
            assert!(
                r.4 < *s / 10.0,
                "{} is not 10x better than still: {r:?}",
                r.0
            );
        }
    }
    let get = |system: &str, input: &str, smoother: &str| {
        rows.iter()
            .find(|r| r.0 == system && r.1 == input && r.2 == smoother)
            .map(|r| (r.3, r.4))
            .unwrap_or_else(|| panic!("no row {system} {input} {smoother}\n{table}"))
    };
    // Noise-free positions only: the spring within 2x of full states.
    let full = get("spring", "full states", "-");
    let pos = get("spring", "positions, noise 0 %", "none");
    assert!(
        pos.0 < 2.0 * full.0 && pos.1 < 2.0 * full.1,
        "{pos:?} vs {full:?}"
    );
    // With 0.1 % noise, a smoother beats none for both systems.
    for system in ["spring", "pendulum"] {
        let none = get(system, "positions, noise 0.1 %", "none").0;
        let best = ["poly 9", "poly 25"]
            .iter()
            .map(|s| get(system, "positions, noise 0.1 %", s).0)
            .fold(f64::MAX, f64::min);
        assert!(best < none, "{system}: {best} vs {none}");
        // The model smoother's best row is below the best poly row.
        let model = ["model 9", "model 25"]
            .iter()
            .map(|s| get(system, "positions, noise 0.1 %", s).0)
            .fold(f64::MAX, f64::min);
        println!(
            "{system}, 0.1 % noise, RE at 0.1 s: best model {model:.2e}, best poly {best:.2e} \
             ({:.1}x below)",
            best / model
        );
        assert!(
            model < best,
            "{system}: model {model} vs poly {best}\n{table}"
        );
    }
}
