//! `mcgnode reproduce --quick`: every experiment runs end to end through the
//! binary and writes a complete report with finite numbers. Run with
//! `cargo test --release --test reproduce`.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

mod common;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

fn is_png(p: &Path) -> bool {
    std::fs::read(p)
        .map(|b| b.len() > 1000 && b.starts_with(b"\x89PNG\r\n\x1a\n"))
        .unwrap_or(false)
}

#[test]
fn quick_reproduce_writes_a_complete_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("repro");
    // Bounded: a hang fails the test with what the run printed (~20 s normally).
    let o = common::run_bounded(
        Command::new(common::BIN)
            .args(["reproduce", "--quick", "--out"])
            .arg(&out),
        Duration::from_secs(600),
        dir.path(),
    );
    assert!(o.status.success(), "reproduce failed:\n{}", o.stderr);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    for heading in [
        "## What the paper claims, and what we measured",
        "## spring: inductive biases, baselines, zero-shot sizes",
        "## pendulum: inductive biases, baselines, zero-shot sizes",
        "### Zero-shot to large rings",
        "### MCGNODE against LGN, HGN and GNS at equal wall-clock time",
        "### The architecture: the authors' code against the paper's text",
        "### Training and forward-simulation time (spring",
        "### Training and forward-simulation time (pendulum",
        "## 3D peridynamic solid",
        "## Drag and external force",
        "## Robustness to noise",
        "## Data efficiency",
        "## Systems that touch (not in the paper)",
        "## Settings",
    ] {
        assert!(report.contains(heading), "report lacks {heading:?}");
    }
    assert!(!report.contains("failed"), "a model failed:\n{report}");
    assert!(!report.contains("could not be drawn"), "{report}");
    // Every figure the report links exists and is a PNG.
    let mut figures = 0;
    for line in report.lines().filter(|l| l.starts_with("![")) {
        let name = &line[line.find("](").unwrap() + 2..line.len() - 1];
        assert!(is_png(&out.join(name)), "{name} is not a PNG");
        figures += 1;
    }
    assert_eq!(
        figures, 10,
        "biases, baselines and wall-clock per system, peridynamic, drag/force, noise, data"
    );
    // Every evaluation succeeded with finite metrics; every experiment and
    // every model of the paper is there.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let evals = json["evaluations"].as_array().unwrap();
    for e in evals {
        assert!(e["error"].is_null(), "{e}");
        for k in ["re", "ee", "me", "me_scaled", "re_abs", "me_abs"] {
            let x = e["averages"][k].as_f64();
            assert!(x.is_some_and(|x| x.is_finite() && x >= 0.0), "{k} of {e}");
        }
        // Relative errors are at most 1 by definition.
        for k in ["re", "ee", "me", "me_scaled"] {
            assert!(e["averages"][k].as_f64().unwrap() <= 1.0, "{k} of {e}");
        }
    }
    let has = |exp: &str, model: &str| {
        evals
            .iter()
            .any(|e| e["experiment"] == exp && e["model"] == model)
    };
    for m in ["node", "gnode", "cgnode", "cdgnode", "mcgnode"] {
        assert!(has("biases", m), "no bias-ladder row for {m}");
    }
    for m in ["mcgnode", "lgn", "hgn", "gns"] {
        assert!(has("baselines", m), "no baseline-comparison row for {m}");
        assert!(has("wallclock", m), "no wall-clock-comparison row for {m}");
    }
    for (exp, m) in [
        ("large", "mcgnode"),
        ("architecture", "gnode"),
        ("architecture", "mcgnode"),
        ("peridynamic", "mcgnode"),
        ("peridynamic", "gnode"),
        ("peridynamic", "gns"),
        ("drag-force", "node"),
        ("noise", "lgn"),
        ("noise", "hgn"),
        ("points", "hgn"),
        ("points", "node"),
        ("contacts", "mcgnode"),
        ("contacts", "gnode"),
        ("contacts", "gns"),
        ("contacts", "gns-equal-time"),
    ] {
        assert!(has(exp, m), "no {exp} row for {m}");
    }
    // Noise and data-size rows carry their setting; the models record it.
    assert!(evals
        .iter()
        .any(|e| e["experiment"] == "noise" && e["x"].as_f64() == Some(10.0)));
    let training = json["training"].as_array().unwrap();
    assert!(training
        .iter()
        .any(|t| t["training"]["noise"].as_f64() == Some(10.0)));
    assert!(training
        .iter()
        .any(|t| t["training"]["points"].as_u64() == Some(100)));
    // The wall-clock baselines trained on a time budget and ran out of it.
    let budgeted: Vec<&serde_json::Value> = training
        .iter()
        .filter(|t| t["training"]["time_budget"].as_f64().is_some())
        .collect();
    assert_eq!(
        budgeted.len(),
        9,
        "LGN, HGN, GNS per system; GNS on the cube and on each contact system"
    );
    assert!(budgeted
        .iter()
        .all(|t| t["training"]["out_of_time"] == true
            && t["training"]["epochs_run"].as_u64() >= Some(1)));
    // GNS on the cube gets the seconds MCGNODE's cube training took.
    let seconds = |model: &str| {
        let t = training.iter().find(|t| t["model"] == model).unwrap();
        (
            t["training"]["seconds"].as_f64(),
            t["training"]["time_budget"].as_f64(),
        )
    };
    assert_eq!(
        seconds("gns-peridynamic").1,
        seconds("mcgnode-peridynamic").0
    );
    assert_eq!(
        seconds("gns-equal-time-soft-spheres").1,
        seconds("mcgnode-soft-spheres").0
    );
    // MCGNODE conserves the closed colliding lattices' momentum, contacts
    // and all.
    let lat = evals
        .iter()
        .find(|e| {
            e["experiment"] == "contacts"
                && e["model"] == "mcgnode"
                && e["system"] == "colliding-lattices"
        })
        .unwrap();
    assert!(
        lat["averages"]["me_scaled"].as_f64().unwrap() < 1e-12,
        "{lat}"
    );
    // MCGNODE without body forces conserves the peridynamic cube's momentum.
    let peri = evals
        .iter()
        .find(|e| e["experiment"] == "peridynamic" && e["model"] == "mcgnode")
        .unwrap();
    assert!(
        peri["averages"]["me_abs"].as_f64().unwrap() < 1e-9,
        "{peri}"
    );
}

#[test]
fn only_runs_the_named_parts_and_names_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("repro");
    // The noise part at toy scale, with `extra` options.
    let noise = |extra: &[&str]| {
        common::run_bounded(
            Command::new(common::BIN)
                .args(["reproduce", "--quick", "--only", "noise"])
                .args(["--comparison-epochs", "3"])
                .args(extra)
                .arg("--out")
                .arg(&out),
            Duration::from_secs(300),
            dir.path(),
        )
    };
    let o = noise(&[]);
    assert!(o.status.success(), "reproduce failed:\n{}", o.stderr);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("## Robustness to noise"), "{report}");
    assert!(!report.contains("## Data efficiency"), "{report}");
    assert!(
        report.contains(
            "Not run (`--only`): springs, pendulums, peridynamic, drag-force, data-efficiency"
        ),
        "{report}"
    );
    // Only the noise claim is checked: the claims of parts not run are left
    // out, not reported as failed or missing.
    let claims = report
        .split("## What the paper claims")
        .nth(1)
        .and_then(|c| c.split("\n## ").next())
        .unwrap();
    assert!(
        claims.contains("Noise (paper: MCGNODE the most robust)"),
        "{claims}"
    );
    for absent in [
        "a model failed",
        "No result",
        "Energy error",
        "Each bias",
        "Peridynamic",
    ] {
        assert!(
            !claims.contains(absent),
            "{absent:?} in the claims of a noise run:\n{claims}"
        );
    }
    // The command is shown without the machine's folders.
    assert!(
        report.contains(
            "Command: `mcgnode reproduce --quick --only noise --comparison-epochs 3 --out repro`"
        ),
        "{report}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(json["scale"]["epochs"], 3);
    assert_eq!(json["parts"], serde_json::json!(["noise"]));
    assert_eq!(json["pending"], serde_json::json!([]));
    // --resume takes every training up from its checkpoint: finished ones
    // are not trained again, and the results are the same.
    let resumed = noise(&["--resume"]);
    assert!(
        resumed.status.success(),
        "resume failed:\n{}",
        resumed.stderr
    );
    let again: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let trainings = again["training"].as_array().unwrap();
    assert!(!trainings.is_empty());
    for t in trainings {
        assert_eq!(
            t["training"]["resumed_at"], t["training"]["epochs_run"],
            "{t}"
        );
    }
    let scores = |j: &serde_json::Value| -> Vec<serde_json::Value> {
        j["evaluations"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| serde_json::json!([e["model"], e["x"], e["averages"]]))
            .collect()
    };
    assert_eq!(scores(&again), scores(&json));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("**Resumed** (`--resume`)"), "{report}");
    // A misspelt part is refused with the valid names.
    let bad = Command::new(common::BIN)
        .args(["reproduce", "--quick", "--only", "spring", "--out"])
        .arg(dir.path().join("bad"))
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("springs, pendulums, peridynamic"), "{err}");
}
