//! The `mcgnode` binary end to end: simulate → train → rollout → evaluate, and
//! clear errors (never a panic) on bad input.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::path::Path;
use std::process::{Command, Output};

fn mcgnode(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mcgnode"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run mcgnode")
}

fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "mcgnode failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Fails with exit code 1 (not a panic's 101) and says `want` on stderr.
fn fails_with(o: &Output, want: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "expected failure, got success; stderr {err}"
    );
    assert_ne!(o.status.code(), Some(101), "panicked: {err}");
    assert!(!err.contains("panicked"), "panicked: {err}");
    assert!(
        err.to_lowercase().contains(&want.to_lowercase()),
        "stderr should mention {want:?}: {err}"
    );
}

#[test]
fn pipeline_and_bad_input() {
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
            "8",
            "--seed",
            "1",
            "--out",
            "train.mcap",
        ],
        d,
    ));
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--particles",
            "7",
            "--trajectories",
            "3",
            "--seed",
            "2",
            "--states",
            "21",
            "--out",
            "test.mcap",
        ],
        d,
    ));
    ok(&mcgnode(
        &[
            "train",
            "--model",
            "mcgnode",
            "--data",
            "train.mcap",
            "--epochs",
            "5",
            "--out",
            "m.json",
        ],
        d,
    ));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("m.json")).unwrap()).unwrap();
    assert_eq!(m["hyper"]["variant"], "mcgnode");
    assert_eq!(m["trained_on"]["particles"], 5);
    assert_eq!(m["trained_on"]["accelerations"], "recorded");
    assert_eq!(
        m["trained_on"]["start_fingerprints"]
            .as_array()
            .unwrap()
            .len(),
        8
    );
    assert_eq!(m["training"]["epochs_run"], 5);

    // Evaluate on 7 springs (inductive), JSON on stdout, PNG written.
    let out = ok(&mcgnode(
        &[
            "evaluate",
            "--model",
            "m.json",
            "--bag",
            "test.mcap",
            "--json",
            "--plot",
            "e.png",
        ],
        d,
    ));
    let e: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(e["particles"], 7);
    assert_eq!(e["trajectories"], 3);
    let re = e["summary"]["re"]["gmean"].as_array().unwrap();
    assert_eq!(re.len(), 21);
    assert!(re.iter().all(|x| x.as_f64().unwrap().is_finite()));
    assert!(std::fs::read(d.join("e.png"))
        .unwrap()
        .starts_with(b"\x89PNG"));
    // Evaluating on the training bag is refused: its starts are the training starts.
    fails_with(
        &mcgnode(&["evaluate", "--model", "m.json", "--bag", "train.mcap"], d),
        "start where training",
    );

    // Rollout from a bag's first state and from a drawn state, both written as bags.
    ok(&mcgnode(
        &[
            "rollout",
            "--model",
            "m.json",
            "--initial",
            "test.mcap",
            "--duration",
            "1",
            "--out",
            "r1.mcap",
        ],
        d,
    ));
    ok(&mcgnode(
        &[
            "rollout",
            "--model",
            "m.json",
            "--system",
            "spring",
            "--particles",
            "50",
            "--duration",
            "0.5",
            "--out",
            "r2.mcap",
        ],
        d,
    ));
    let r = mcgnode::data::bag::read_trajectories(d.join("r2.mcap")).unwrap();
    assert_eq!(r.trajectories[0].graph.n(), 50);
    assert_eq!(r.trajectories[0].samples.len(), 6); // 0.5 s saved every 0.1 s, plus the start

    // Baselines train on the same bags and evaluate through the same code.
    for kind in ["gns", "lgn"] {
        let out = format!("{kind}.json");
        ok(&mcgnode(
            &[
                "train",
                "--model",
                kind,
                "--data",
                "train.mcap",
                "--epochs",
                "2",
                "--out",
                &out,
            ],
            d,
        ));
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join(&out)).unwrap()).unwrap();
        assert_eq!(m["hyper"]["kind"], kind);
        assert_eq!(
            m["trained_on"]["start_fingerprints"]
                .as_array()
                .unwrap()
                .len(),
            8
        );
        let e: serde_json::Value = serde_json::from_str(&ok(&mcgnode(
            &[
                "evaluate",
                "--model",
                &out,
                "--bag",
                "test.mcap",
                "--trajectories",
                "1",
                "--json",
            ],
            d,
        )))
        .unwrap();
        assert!(e["averages"]["re"].as_f64().unwrap().is_finite());
        fails_with(
            &mcgnode(&["evaluate", "--model", &out, "--bag", "train.mcap"], d),
            "start where training",
        );
        // `rollout` takes baseline files too.
        let bag = format!("{kind}-rollout.mcap");
        ok(&mcgnode(
            &[
                "rollout",
                "--model",
                &out,
                "--particles",
                "7",
                "--duration",
                "0.3",
                "--out",
                &bag,
            ],
            d,
        ));
        let r = mcgnode::data::bag::read_trajectories(d.join(&bag)).unwrap();
        assert_eq!(r.trajectories[0].graph.n(), 7);
        assert_eq!(r.trajectories[0].samples.len(), 4);
    }

    // Bad input: unknown system/model, missing or corrupt files.
    fails_with(
        &mcgnode(&["simulate", "--system", "galaxy", "--out", "x.mcap"], d),
        "galaxy",
    );
    fails_with(
        &mcgnode(
            &[
                "train",
                "--model",
                "transformer",
                "--data",
                "train.mcap",
                "--out",
                "x.json",
            ],
            d,
        ),
        "transformer",
    );
    fails_with(
        &mcgnode(
            &[
                "train",
                "--model",
                "gnode",
                "--data",
                "nope.mcap",
                "--out",
                "x.json",
            ],
            d,
        ),
        "nope.mcap",
    );
    fails_with(
        &mcgnode(
            &["evaluate", "--model", "nope.json", "--bag", "test.mcap"],
            d,
        ),
        "cannot read model file",
    );
    std::fs::write(d.join("bad.json"), "{\"format\": 3}").unwrap();
    fails_with(
        &mcgnode(
            &["evaluate", "--model", "bad.json", "--bag", "test.mcap"],
            d,
        ),
        "not a valid mcgnode model file",
    );
    let bytes = std::fs::read(d.join("test.mcap")).unwrap();
    std::fs::write(d.join("cut.mcap"), &bytes[..bytes.len() / 3]).unwrap();
    let o = mcgnode(&["evaluate", "--model", "m.json", "--bag", "cut.mcap"], d);
    assert!(
        !o.status.success() && o.status.code() != Some(101),
        "corrupt bag must fail cleanly"
    );
    // A NODE model is not inductive: a clear error on another particle count.
    ok(&mcgnode(
        &[
            "train",
            "--model",
            "node",
            "--data",
            "train.mcap",
            "--epochs",
            "2",
            "--out",
            "n.json",
        ],
        d,
    ));
    fails_with(
        &mcgnode(&["evaluate", "--model", "n.json", "--bag", "test.mcap"], d),
        "not inductive",
    );
    // Model and system of different dimension.
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--dim",
            "3",
            "--particles",
            "4",
            "--trajectories",
            "2",
            "--seed",
            "9",
            "--states",
            "5",
            "--out",
            "s3.mcap",
        ],
        d,
    ));
    fails_with(
        &mcgnode(&["evaluate", "--model", "m.json", "--bag", "s3.mcap"], d),
        "2D",
    );
}

#[test]
fn help_documents_every_subcommand() {
    let dir = tempfile::tempdir().unwrap();
    let top = ok(&mcgnode(&["--help"], dir.path()));
    for sub in [
        "simulate",
        "train",
        "rollout",
        "evaluate",
        "demo",
        "bench",
        "serve",
        "reproduce",
    ] {
        assert!(top.contains(sub), "top-level help lacks {sub}");
        let h = ok(&mcgnode(&[sub, "--help"], dir.path()));
        assert!(
            h.lines()
                .filter(|l| l.trim_start().starts_with("--"))
                .count()
                >= 1,
            "{sub} --help lists no options"
        );
    }
}

#[test]
fn simulate_peridynamic_solid_defaults_to_3d() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let base = ["simulate", "--system", "peridynamic", "--trajectories", "2"];
    ok(&mcgnode(
        &[&base[..], &["--particles", "125", "--out", "p.mcap"]].concat(),
        d,
    ));
    let bag = mcgnode::data::bag::read_trajectories(d.join("p.mcap")).unwrap();
    assert_eq!(bag.trajectories.len(), 2);
    let t = &bag.trajectories[0];
    assert_eq!(t.system, "peridynamic");
    assert_eq!(
        (t.graph.dim, t.graph.n(), t.graph.edges.len()),
        (3, 125, 780)
    );
    assert_eq!(t.samples.len(), 100);
    assert_eq!(bag.metadata["integrator"], "verlet");
    ok(&mcgnode(
        &[
            &base[..],
            &["--particles", "8", "--dim", "3", "--out", "q.mcap"],
        ]
        .concat(),
        d,
    ));
    fails_with(
        &mcgnode(
            &[&base[..], &["--particles", "100", "--out", "x.mcap"]].concat(),
            d,
        ),
        "cube number",
    );
    fails_with(
        &mcgnode(
            &[
                &base[..],
                &["--particles", "125", "--dim", "2", "--out", "x.mcap"],
            ]
            .concat(),
            d,
        ),
        "3-dimensional",
    );
}

#[test]
fn simulate_rk4_matches_verlet() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |integrator: &str, out: &str| {
        ok(&mcgnode(
            &[
                "simulate",
                "--system",
                "spring",
                "--particles",
                "5",
                "--trajectories",
                "3",
                "--states",
                "20",
                "--seed",
                "4",
                "--integrator",
                integrator,
                "--out",
                out,
            ],
            d,
        ));
        mcgnode::data::bag::read_trajectories(d.join(out)).unwrap()
    };
    let (rk4, verlet) = (run("rk4", "rk4.mcap"), run("verlet", "verlet.mcap"));
    assert_eq!(rk4.metadata["integrator"], "rk4");
    assert_eq!(verlet.metadata["integrator"], "verlet");
    assert_eq!(rk4.trajectories.len(), 3);
    let mut worst = 0.0_f64;
    for (a, b) in rk4.trajectories.iter().zip(&verlet.trajectories) {
        assert_eq!(a.samples.len(), 20);
        assert_eq!(a.samples[0].state, b.samples[0].state, "same starts");
        for (x, y) in a.samples.iter().zip(&b.samples) {
            for (p, q) in x.state.q.iter().zip(&y.state.q) {
                worst = worst.max((p - q).abs());
            }
        }
    }
    println!("RK4 vs Verlet, 5 springs, 1.9 s at dt 1e-3: max position difference {worst:.3e}");
    assert!(worst > 0.0, "the two integrators gave identical data");
    assert!(worst < 1e-6, "RK4 and Verlet differ by {worst}");
    assert!(!ok(&mcgnode(&["simulate", "--help"], d)).is_empty());
    fails_with(
        &mcgnode(&["simulate", "--integrator", "euler", "--out", "x.mcap"], d),
        "euler",
    );
}

/// `train` engine, architecture and warm-start options through the binary:
/// both engines write the same architecture, `--arch paper` the paper-text one,
/// `--init` continues (and refuses another model kind), `--block-hidden`
/// checks its block names.
#[test]
fn train_engine_arch_and_warm_start_options() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let args = |extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = ["train", "--data", "t.mcap", "--epochs", "4", "--quiet"]
            .iter()
            .map(std::string::ToString::to_string)
            .collect();
        v.extend(extra.iter().map(std::string::ToString::to_string));
        v
    };
    let run = |extra: &[&str]| {
        let a = args(extra);
        mcgnode(&a.iter().map(String::as_str).collect::<Vec<_>>(), d)
    };
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--trajectories",
            "4",
            "--out",
            "t.mcap",
        ],
        d,
    ));
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join(f)).unwrap()).unwrap()
    };
    ok(&run(&["--model", "mcgnode", "--out", "native.json"]));
    ok(&run(&[
        "--model",
        "mcgnode",
        "--engine",
        "candle",
        "--out",
        "candle.json",
    ]));
    let (n, c) = (read("native.json"), read("candle.json"));
    assert_eq!(n["hyper"], c["hyper"]);
    assert_eq!(n["hyper"]["hidden_layers"], 2);
    assert_eq!(n["hyper"]["message"], "mlp");
    assert_eq!(n["hyper"]["edge_input"], "product");
    let (ln, lc) = (
        n["training"]["validation_loss"].as_f64().unwrap(),
        c["training"]["validation_loss"].as_f64().unwrap(),
    );
    assert!((ln - lc).abs() <= 1e-6 * lc, "native {ln} vs candle {lc}");
    assert!(n["optimizer"]["step"].as_i64().unwrap() > 0);
    // A checkpointed run gives the same model; run again, it resumes from
    // the finished checkpoint; another seed's run is refused with the fix.
    let ck = ["--model", "mcgnode", "--checkpoint", "ck.json"];
    ok(&run(&[&ck[..], &["--out", "ck1.json"]].concat()));
    ok(&run(&[&ck[..], &["--out", "ck2.json"]].concat()));
    let (c1, c2) = (read("ck1.json"), read("ck2.json"));
    assert_eq!(c1["weights"], n["weights"]);
    assert_eq!(c2["weights"], n["weights"]);
    assert!(c1["training"].get("resumed_at").is_none());
    assert_eq!(c2["training"]["resumed_at"], 4);
    fails_with(
        &run(&[&ck[..], &["--seed", "1", "--out", "x.json"]].concat()),
        "remove it to train afresh",
    );
    ok(&run(&[
        "--model",
        "gnode",
        "--arch",
        "paper",
        "--out",
        "paper.json",
    ]));
    let p = read("paper.json");
    assert_eq!(p["hyper"]["hidden_layers"], 1);
    assert_eq!(p["hyper"]["message"], "linear");
    assert_eq!(
        p["weights"]["mp0.v.l0.w"]["shape"],
        serde_json::json!([10, 5])
    );
    ok(&run(&[
        "--model",
        "mcgnode",
        "--init",
        "native.json",
        "--out",
        "warm.json",
    ]));
    let w = read("warm.json");
    assert_eq!(
        w["optimizer"]["step"].as_i64().unwrap(),
        2 * n["optimizer"]["step"].as_i64().unwrap()
    );
    fails_with(
        &run(&[
            "--model",
            "gnode",
            "--init",
            "native.json",
            "--out",
            "x.json",
        ]),
        "--init model is a mcgnode model",
    );
    fails_with(
        &run(&[
            "--model",
            "mcgnode",
            "--block-hidden",
            "node_out=8",
            "--out",
            "x.json",
        ]),
        "edge_out",
    );
}

/// The README's peridynamic example, as written: 125 particles by default.
#[test]
fn readme_peridynamic_example_uses_125_particles() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "peridynamic",
            "--trajectories",
            "10",
            "--out",
            "solid.mcap",
        ],
        d,
    ));
    let bag = mcgnode::data::read_trajectories(d.join("solid.mcap")).unwrap();
    assert_eq!(bag.trajectories.len(), 10);
    assert!(bag
        .trajectories
        .iter()
        .all(|t| t.graph.n() == 125 && t.graph.dim == 3));
    // A closed solid: the messages say so, and `bag info` prints it.
    assert_eq!(bag.field, Some(Default::default()));
    let info = ok(&mcgnode(&["bag", "info", "solid.mcap"], d));
    assert!(
        info.contains("peridynamic: 10 trajectories, 125 particles, 3D, 1000 states"),
        "{info}"
    );
    assert!(info.contains("field: none"), "{info}");
    // Other systems keep 5 particles, and a non-cube count is still refused.
    ok(&mcgnode(
        &["simulate", "--trajectories", "1", "--out", "s.mcap"],
        d,
    ));
    let bag = mcgnode::data::read_trajectories(d.join("s.mcap")).unwrap();
    assert_eq!(bag.trajectories[0].graph.n(), 5);
    fails_with(
        &mcgnode(
            &[
                "simulate",
                "--system",
                "peridynamic",
                "--particles",
                "5",
                "--out",
                "bad.mcap",
            ],
            d,
        ),
        "cube",
    );
}

/// `evaluate --model still` scores the "nothing moves" reference: its RE(t)
/// equals a direct computation of ‖q(0) − q(t)‖/(‖q(0)‖ + ‖q(t)‖) from the
/// bag (geometric mean over trajectories).
#[test]
fn evaluate_still_is_the_standing_still_reference() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--trajectories",
            "3",
            "--states",
            "21",
            "--out",
            "t.mcap",
        ],
        d,
    ));
    let e: serde_json::Value = serde_json::from_str(&ok(&mcgnode(
        &["evaluate", "--model", "still", "--bag", "t.mcap", "--json"],
        d,
    )))
    .unwrap();
    let re: Vec<f64> = e["summary"]["re"]["gmean"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let bag = mcgnode::data::bag::read_trajectories(d.join("t.mcap")).unwrap();
    let norm = |x: &[f64]| x.iter().map(|v| v * v).sum::<f64>().sqrt();
    for k in [1, 10, 20] {
        let logs: Vec<f64> = bag
            .trajectories
            .iter()
            .map(|t| {
                let (q0, q) = (&t.samples[0].state.q, &t.samples[k].state.q);
                let diff: Vec<f64> = q0.iter().zip(q).map(|(a, b)| a - b).collect();
                (norm(&diff) / (norm(q0) + norm(q))).ln()
            })
            .collect();
        let want = (logs.iter().sum::<f64>() / logs.len() as f64).exp();
        assert!(
            (re[k] - want).abs() <= 1e-12 * want,
            "RE at sample {k}: evaluate {} vs direct {want}",
            re[k]
        );
    }
}

/// `evaluate --model truth:<system>` rolls the simulator itself out: at the
/// bag's own step it reproduces the bag (the evaluation adds no error of its
/// own), and at a coarser `--dt` its error is the floor that step puts under
/// every model evaluated with it; a truth of another system is refused.
#[test]
fn evaluate_truth_reproduces_its_bag_and_measures_a_step_floor() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "pendulum",
            "--particles",
            "3",
            "--trajectories",
            "2",
            "--states",
            "11",
            "--out",
            "p.mcap",
        ],
        d,
    ));
    let re = |extra: &[&str]| -> f64 {
        let mut args = vec![
            "evaluate",
            "--model",
            "truth:pendulum",
            "--bag",
            "p.mcap",
            "--json",
        ];
        args.extend_from_slice(extra);
        let e: serde_json::Value = serde_json::from_str(&ok(&mcgnode(&args, d))).unwrap();
        e["averages"]["re"].as_f64().unwrap()
    };
    let own = re(&[]);
    assert!(own < 1e-12, "truth at the bag's step: RE {own}");
    let coarse = re(&["--dt", "1e-4"]);
    assert!(
        coarse > 1e-14 && coarse < 1e-5,
        "truth at 10x the bag's step: RE {coarse}"
    );
    fails_with(
        &mcgnode(
            &["evaluate", "--model", "truth:spring", "--bag", "p.mcap"],
            d,
        ),
        "spring",
    );
}

/// The README's first command, at its quick scale with few epochs: bags,
/// models, the plot and a summary of finite errors for both models on every
/// size; MCGNODE conserves the rings' momentum where GNODE does not.
#[test]
fn demo_quick_runs_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = ok(&mcgnode(
        &["demo", "--quick", "--epochs", "5", "--out", "demo-out"],
        d,
    ));
    assert!(out.contains("demo done in"), "{out}");
    let o = d.join("demo-out");
    for f in [
        "demo.png",
        "data/train-5-spring.mcap",
        "data/test-50-spring.mcap",
        "models/gnode-5-spring.json",
        "models/mcgnode-5-spring.json",
    ] {
        assert!(o.join(f).is_file(), "demo wrote no {f}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(o.join("demo.json")).unwrap()).unwrap();
    let rows = json.as_array().unwrap();
    assert_eq!(rows.len(), 6, "2 models x 3 sizes: {json}");
    for n in [5, 20, 50] {
        let me = |m: &str| {
            let r = rows
                .iter()
                .find(|r| r["model"] == m && r["particles"] == n)
                .unwrap_or_else(|| panic!("no {m} on {n}: {json}"));
            let re = r["averages"]["re"].as_f64().unwrap();
            assert!(re.is_finite() && (0.0..=1.0).contains(&re), "{r}");
            r["averages"]["me_scaled"].as_f64().unwrap()
        };
        let (m, g) = (me("mcgnode"), me("gnode"));
        assert!(
            m < 1e-10 && m < g,
            "momentum error on {n}: MCGNODE {m}, GNODE {g}"
        );
    }
}

/// `bag draw` on a bag without markers says so and how to get them.
#[test]
fn bag_draw_names_the_fix_when_a_bag_has_no_markers() {
    let dir = tempfile::tempdir().unwrap();
    let bag = Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/spring5-sample.mcap");
    let o = mcgnode(
        &["bag", "draw", bag.to_str().unwrap(), "--png", "x.png"],
        dir.path(),
    );
    fails_with(
        &o,
        "holds 0 MarkerArray messages; record with `serve` (markers: true)",
    );
    assert!(!dir.path().join("x.png").exists());
}

#[test]
fn errors_state_each_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let o = mcgnode(
        &[
            "train",
            "--model",
            "mcgnode",
            "--data",
            &format!("{}/bags/spring5-sample.mcap", env!("CARGO_MANIFEST_DIR")),
            "--init",
            "/nonexistent/m.json",
            "--epochs",
            "1",
            "--out",
            "m.json",
        ],
        dir.path(),
    );
    fails_with(&o, "cannot read model file /nonexistent/m.json");
    let err = String::from_utf8_lossy(&o.stderr);
    // The io error's text (it names the OS error) appears once, not twice.
    let cause = "(os error 2)";
    assert_eq!(err.matches(cause).count(), 1, "{err}");
    // A context added at the edge still shows with the library's message.
    let o = mcgnode(&["bag", "info", "/nonexistent/b.mcap"], dir.path());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("/nonexistent/b.mcap"), "{err}");
    assert!(err.matches(cause).count() <= 1, "{err}");
}

/// `train`'s default recipe sizes batch, rate and widths by the data and
/// records them; `--recipe paper` is the paper's settings exactly; every
/// training reports how much of its targets it explains against predicting
/// zero acceleration; `evaluate` and `replay` show the standing-still
/// reference beside the model.
#[test]
fn train_recipes_explained_fraction_and_the_still_reference() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (seed, traj, out) in [("1", "2", "train.mcap"), ("2", "2", "test.mcap")] {
        ok(&mcgnode(
            &[
                "simulate",
                "--system",
                "peridynamic",
                "--particles",
                "27",
                "--trajectories",
                traj,
                "--states",
                "21",
                "--seed",
                seed,
                "--out",
                out,
            ],
            d,
        ));
    }
    let train = |extra: &[&str], out: &str| {
        let mut args = vec![
            "train",
            "--model",
            "mcgnode",
            "--data",
            "train.mcap",
            "--epochs",
            "3",
            "--out",
            out,
        ];
        args.extend_from_slice(extra);
        let o = mcgnode(&args, d);
        ok(&o);
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join(out)).unwrap()).unwrap();
        (m, String::from_utf8_lossy(&o.stderr).into_owned())
    };
    // 27 particles, 126 bonds: 252 directed edges, 16,000 / 252 = 63 states.
    let (auto, log) = train(&[], "auto.json");
    let t = &auto["training"];
    assert_eq!(t["batch"], 63);
    assert_eq!(t["lr"], 1e-2);
    assert_eq!(t["lr_drops"], serde_json::json!([[2, 1e-3]]));
    assert_eq!(
        auto["hyper"]["block_hidden"],
        serde_json::json!({"edge_em": [16, 16], "edge_out": [16, 16]})
    );
    assert!(
        log.contains("recipe: batch 63 states (252 directed edges each)"),
        "{log}"
    );
    let (val, trivial, explained) = (
        t["validation_loss"].as_f64().unwrap(),
        t["trivial_loss"].as_f64().unwrap(),
        t["explained"].as_f64().unwrap(),
    );
    assert!(trivial > 0.0 && val > 0.0);
    assert!((explained - (1.0 - val / trivial)).abs() <= 1e-15);
    assert!(log.contains("explains"), "{log}");
    // Three epochs learn little: the warning names what to try.
    assert!(
        explained < 0.99 && log.contains("--epochs"),
        "{explained}: {log}"
    );

    // The recipe chooses exactly what its flags spell out: the same weights.
    let (spelled, _) = train(
        &[
            "--batch",
            "63",
            "--lr",
            "1e-2",
            "--lr-drop",
            "2:1e-3",
            "--block-hidden",
            "edge_em=16,16",
            "--block-hidden",
            "edge_out=16,16",
        ],
        "spelled.json",
    );
    assert_eq!(spelled["weights"], auto["weights"]);
    assert_eq!(spelled["hyper"], auto["hyper"]);

    let (paper, log) = train(&["--recipe", "paper"], "paper.json");
    let t = &paper["training"];
    assert_eq!(
        (t["batch"].as_u64(), t["lr"].as_f64()),
        (Some(100), Some(1e-3))
    );
    assert!(t.get("lr_drops").is_none(), "{t}");
    assert!(paper["hyper"]["block_hidden"]
        .as_object()
        .is_none_or(serde_json::Map::is_empty));
    assert!(!log.contains("recipe:"), "{log}");
    // ... and is what the library's paper settings (reproduce's) train: the
    // same weights.
    let lib = mcgnode::models::train_from_bags(
        mcgnode::models::ModelKind::Family(mcgnode::gnode::Variant::Mcgnode),
        &[d.join("train.mcap")],
        &mcgnode::train::ModelOptions::for_recipe(mcgnode::train::Recipe::Paper),
        &mcgnode::train::TrainConfig {
            epochs: 3,
            ..Default::default()
        },
        |_| {},
        |_| true,
    )
    .unwrap()
    .into_family()
    .expect("a GNODE-family file");
    assert_eq!(
        serde_json::to_value(&lib.weights).unwrap(),
        paper["weights"]
    );
    // The library's defaults (ModelOptions::default(), the default recipe's
    // TrainConfig: what the node and the Python package start from) train
    // what `train` with no option trains.
    let mut cfg = mcgnode::train::TrainConfig::for_recipe(mcgnode::train::Recipe::default());
    cfg.set_epochs(3);
    let lib = mcgnode::models::train_from_bags(
        mcgnode::models::ModelKind::Family(mcgnode::gnode::Variant::Mcgnode),
        &[d.join("train.mcap")],
        &mcgnode::train::ModelOptions::default(),
        &cfg,
        |_| {},
        |_| true,
    )
    .unwrap()
    .into_family()
    .expect("a GNODE-family file");
    assert_eq!(serde_json::to_value(&lib.weights).unwrap(), auto["weights"]);
    assert_eq!(serde_json::to_value(&lib.hyper).unwrap(), auto["hyper"]);
    // Given options override the recipe.
    let (given, _) = train(&["--batch", "7", "--lr", "3e-3"], "given.json");
    assert_eq!(given["training"]["batch"], 7);
    assert_eq!(given["training"]["lr"], 3e-3);
    let drop = &given["training"]["lr_drops"][0];
    assert_eq!(drop[0], 2);
    assert!((drop[1].as_f64().unwrap() - 3e-4).abs() < 1e-18, "{drop}");

    // The reference beside the model is `evaluate --model still` itself.
    let still: serde_json::Value = serde_json::from_str(&ok(&mcgnode(
        &[
            "evaluate",
            "--model",
            "still",
            "--bag",
            "test.mcap",
            "--json",
        ],
        d,
    )))
    .unwrap();
    assert!(still["still"].is_null());
    let e: serde_json::Value = serde_json::from_str(&ok(&mcgnode(
        &[
            "evaluate",
            "--model",
            "auto.json",
            "--bag",
            "test.mcap",
            "--json",
        ],
        d,
    )))
    .unwrap();
    let (ref_re, model_re) = (
        e["still"]["re_mean"].as_f64().unwrap(),
        e["averages"]["re"].as_f64().unwrap(),
    );
    assert_eq!(ref_re, still["averages"]["re"].as_f64().unwrap());
    assert_eq!(e["still"]["re"], still["summary"]["re"]["gmean"]);
    assert_eq!(e["still"]["worse"].as_bool().unwrap(), model_re > ref_re);
    let table = ok(&mcgnode(
        &["evaluate", "--model", "auto.json", "--bag", "test.mcap"],
        d,
    ));
    assert!(table.contains("RE still"), "{table}");
    assert!(
        if model_re > ref_re {
            table.contains("WARNING: the model is worse than predicting that nothing moves")
        } else {
            table.contains("below standing still")
        },
        "{table}"
    );
    // States far outside the training scales are evaluated with a warning
    // that counts them and names the first.
    let mut bag = mcgnode::data::read_trajectories(d.join("test.mcap")).unwrap();
    bag.trajectories[0].samples[3]
        .state
        .v
        .iter_mut()
        .for_each(|v| *v = 1e3);
    mcgnode::data::write_trajectories_with_field(
        d.join("wild.mcap"),
        &bag.trajectories,
        &bag.metadata,
        bag.field.as_ref(),
    )
    .unwrap();
    let o = mcgnode(
        &["evaluate", "--model", "auto.json", "--bag", "wild.mcap"],
        d,
    );
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("1 of 42 test states lie outside the model's training range")
            && err.contains("trajectory 0, state 3: velocity"),
        "{err}"
    );
    let replay = ok(&mcgnode(
        &[
            "replay",
            "--model",
            "auto.json",
            "--bag",
            "test.mcap",
            "--json",
        ],
        d,
    ));
    let r: serde_json::Value = serde_json::from_str(&replay).unwrap();
    let still_replay: serde_json::Value = serde_json::from_str(&ok(&mcgnode(
        &["replay", "--model", "still", "--bag", "test.mcap", "--json"],
        d,
    )))
    .unwrap();
    assert_eq!(r["still"]["re_mean"], still_replay["averages"]["re"]);
}

/// `scripts/bench_vs_reference.sh` (the side-by-side harness against the
/// authors' JAX code) refuses a missing or wrong REF_DIR (or --baselines
/// checkout) with a clear message and exit code 2, before it makes a venv or
/// times anything.
#[test]
fn bench_vs_reference_refuses_a_missing_ref_dir() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let script = root.join("scripts/bench_vs_reference.sh");
    let dir = tempfile::tempdir().unwrap();
    // Looks like their GNODE checkout (what the script checks), so that the
    // check of --baselines comes next.
    let gnode = dir.path().join("gnode");
    std::fs::create_dir_all(gnode.join("scripts/psystems")).unwrap();
    std::fs::write(gnode.join("scripts/Spring-4MCGNODE.py"), "").unwrap();
    for (args, want) in [
        (vec![], "no REF_DIR given"),
        (
            vec![dir.path().join("nowhere").display().to_string()],
            "is not a checkout of M3RG-IITD/graph_neural_ODE",
        ),
        (vec!["--bogus".to_string()], "unknown option --bogus"),
        (
            vec![
                "--baselines".to_string(),
                dir.path().join("nowhere").display().to_string(),
                gnode.display().to_string(),
            ],
            "is not a checkout of M3RG-IITD/benchmarking_graph",
        ),
    ] {
        let o = Command::new("bash")
            .arg(script.as_path())
            .args(&args)
            .output()
            .expect("run bash");
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(want),
            "{args:?}: stderr should say {want:?}: {err}"
        );
        assert!(err.contains("Usage") || err.contains("git clone"), "{err}");
    }
}

/// A reader that goes away (`| head`) ends a command quietly, as Unix tools
/// end, not with a panic from `println!`.
#[test]
fn a_closed_pipe_ends_a_command_without_a_panic() {
    let o = Command::new("bash")
        .arg("-c")
        .arg(
            r#""$BIN" plan --model truth:held-chain --target 1,-6 --horizon 100 --candidates 8 \
                --iterations 1 --elites 2 --json | head -c 100 >/dev/null; echo "status ${PIPESTATUS[0]}""#,
        )
        .env("BIN", env!("CARGO_BIN_EXE_mcgnode"))
        .output()
        .unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(!err.contains("panicked"), "{err}");
    // 141 = 128 + SIGPIPE: killed by the signal, as `yes | head` is.
    assert!(out.contains("status 141"), "{out} / {err}");
}

/// Every vector path (`MCGNODE_SIMD`) trains to the same bits: the graph
/// passes forward and backward, the input scaling and the constraint, on
/// springs (no bars) and pendulums (bars), against the portable build of
/// the same code.
#[test]
fn every_vector_path_trains_the_same_bits() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for system in ["spring", "pendulum"] {
        let bag = format!("{system}.mcap");
        ok(&mcgnode(
            &[
                "simulate",
                "--system",
                system,
                "--particles",
                "4",
                "--trajectories",
                "3",
                "--seed",
                "3",
                "--out",
                &bag,
            ],
            d,
        ));
        let mut trained = vec![];
        for path in ["", "avx2", "portable"] {
            let out = format!("{system}-{path}.json");
            let o = Command::new(env!("CARGO_BIN_EXE_mcgnode"))
                .args([
                    "train",
                    "--model",
                    "mcgnode",
                    "--recipe",
                    "paper",
                    "--data",
                    &bag,
                    "--epochs",
                    "3",
                    "--threads",
                    "2",
                    "--out",
                    &out,
                    "--quiet",
                ])
                .env("MCGNODE_SIMD", path)
                .current_dir(d)
                .output()
                .expect("run mcgnode");
            ok(&o);
            let file: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(d.join(&out)).unwrap()).unwrap();
            let losses = &file["training"]["validation_loss"];
            assert!(
                losses.as_f64().is_some_and(f64::is_finite),
                "{system}: {losses}"
            );
            trained.push((file["weights"].to_string(), losses.to_string()));
        }
        assert!(
            trained.iter().all(|t| *t == trained[0]),
            "{system}: the vector paths trained different weights"
        );
    }
}
