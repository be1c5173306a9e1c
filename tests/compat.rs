//! Models refuse data they were not trained for (dimension, edge kinds, field,
//! closed or not), in the library check and in `evaluate`, `replay` and
//! `rollout`.

use std::path::Path;
use std::process::{Command, Output};

use mcgnode::compat::TrainedFor;
use mcgnode::physics::{Field, SystemConfig, SystemKind};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn mcgnode(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mcgnode"))
        .args(args)
        .current_dir(ROOT)
        .output()
        .expect("run mcgnode")
}

fn refused(o: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "expected a refusal: {err}");
    assert_ne!(o.status.code(), Some(101), "panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr should mention {n:?}: {err}");
    }
}

fn graph(kind: SystemKind, n: usize) -> mcgnode::system::Graph {
    SystemConfig::new(kind, n).graph()
}

#[test]
fn the_shipped_spring_model_knows_what_it_was_trained_on() {
    let t = TrainedFor::from_model_file(Path::new(&format!(
        "{ROOT}/bags/models/spring5-mcgnode.json"
    )))
    .unwrap();
    assert_eq!(t.dim, Some(2));
    assert_eq!(t.closed, Some(true), "MCGNODE without body force");
    assert_eq!(t.field, Some(Field::default()));
    // Inductive: any number of springs is fine.
    t.check(&graph(SystemKind::Spring, 20), Some(&Field::default()))
        .unwrap();
    t.check(&graph(SystemKind::Spring, 3), None).unwrap();
    // A pendulum: bars and an anchor.
    let e = t
        .check(&graph(SystemKind::Pendulum, 5), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("springs") && e.contains("rigid bars, anchors"),
        "{e}"
    );
    // 3D.
    let mut g3 = SystemConfig::new(SystemKind::Spring, 5);
    g3.dim = 3;
    let e = t.check(&g3.graph(), None).unwrap_err().to_string();
    assert!(e.contains("2D") && e.contains("3D"), "{e}");
    // Gravity on a closed-system model.
    let g = Field {
        gravity: 9.81,
        ..Field::default()
    };
    let e = t
        .check(&graph(SystemKind::Spring, 5), Some(&g))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("closed system") && e.contains("gravity 9.81"),
        "{e}"
    );
}

#[test]
fn truth_models_check_the_field_and_refuse_through_supports() {
    let m = mcgnode::models::load_model("truth:pendulum").unwrap();
    let t = m.trained_for().expect("truth models say what they are");
    assert_eq!(t.field.as_ref().map(|f| f.gravity), Some(10.0));
    t.check(
        &graph(SystemKind::Pendulum, 3),
        Some(&SystemConfig::new(SystemKind::Pendulum, 3).field),
    )
    .unwrap();
    let e = t
        .check(&graph(SystemKind::Spring, 5), Some(&Field::default()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("gravity 10") && e.contains("no field"), "{e}");
    // A file model wrapped by load_model refuses a foreign graph in supports.
    let m =
        mcgnode::models::load_model(&format!("{ROOT}/bags/models/pendulum5-mcgnode.json")).unwrap();
    let e = m
        .supports(&graph(SystemKind::Spring, 5))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("rigid bars") && e.contains("these data have springs"),
        "{e}"
    );
    m.supports(&graph(SystemKind::Pendulum, 5)).unwrap();
}

#[test]
fn evaluate_replay_and_rollout_refuse_a_pendulum_for_a_spring_model() {
    let spring = "bags/models/spring5-mcgnode.json";
    refused(
        &mcgnode(&[
            "evaluate",
            "--model",
            spring,
            "--bag",
            "bags/pendulum5-sample.mcap",
        ]),
        &[
            "trajectory",
            "trained on a system with springs",
            "rigid bars",
        ],
    );
    refused(
        &mcgnode(&[
            "replay",
            "--model",
            spring,
            "--bag",
            "bags/pendulum5-sample.mcap",
        ]),
        &["trained on a system with springs"],
    );
    refused(
        &mcgnode(&[
            "replay",
            "--model",
            "truth:pendulum",
            "--bag",
            "bags/spring5-sample.mcap",
        ]),
        &["trained with gravity 10", "no field"],
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r.mcap");
    refused(
        &mcgnode(&[
            "rollout",
            "--model",
            spring,
            "--system",
            "pendulum",
            "--duration",
            "0.1",
            "--out",
            out.to_str().unwrap(),
        ]),
        &["rigid bars"],
    );
    // The matching pairs still work.
    let o = mcgnode(&[
        "rollout",
        "--model",
        spring,
        "--system",
        "spring",
        "--duration",
        "0.1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
