//! Models refuse data they were not trained for (dimension, edge kinds, field,
//! closed or not), in the library check and in `evaluate`, `replay` and
//! `rollout`.

use std::path::Path;
use std::process::{Command, Output};

use mcgnode::compat::TrainedFor;
use mcgnode::models::ModelRef;
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
    let m = mcgnode::models::load_model(&"truth:pendulum".parse().unwrap()).unwrap();
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
    let m = mcgnode::models::load_model(&ModelRef::File(
        format!("{ROOT}/bags/models/pendulum5-mcgnode.json").into(),
    ))
    .unwrap();
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

/// The first shipped spring model, kept as written before model files
/// recorded their training edges or input scales.
const LEGACY: &str = "tests/fixtures/legacy-spring5-mcgnode.json";

fn with_edge(g: &mut mcgnode::system::Graph, k: f64, r0: f64) {
    g.edges[0].stiffness = k;
    g.edges[0].rest_length = r0;
}

/// A file that does not record its training edges takes them from the
/// simulator's system it records (k = r0 = 1), so another stiffness or rest
/// length, or a negative stiffness, is refused, not predicted as if it were
/// k = 1; with neither record, any graph with edges is refused, naming the fix.
#[test]
fn legacy_model_files_refuse_edges_they_cannot_see() {
    let path = Path::new(ROOT).join(LEGACY);
    let t = TrainedFor::from_model_file(&path).unwrap();
    assert!(!t.edges_unrecorded);
    t.check(&graph(SystemKind::Spring, 5), None).unwrap();
    for (k, r0) in [(5.0, 1.0), (1.0, 2.0), (-1.0, 1.0)] {
        let mut g = graph(SystemKind::Spring, 5);
        with_edge(&mut g, k, r0);
        let e = t.check(&g, None).unwrap_err().to_string();
        assert!(
            e.contains("--edge-physics") && e.contains(&format!("stiffness {k}")),
            "k {k}, r0 {r0}: {e}"
        );
    }
    // Through the CLI too: a bag with one stiff spring is refused.
    let dir = tempfile::tempdir().unwrap();
    let mut bag =
        mcgnode::data::read_trajectories(format!("{ROOT}/bags/spring5-sample.mcap")).unwrap();
    for tr in &mut bag.trajectories {
        with_edge(&mut tr.graph, 5.0, 1.0);
    }
    let stiff = dir.path().join("stiff.mcap");
    mcgnode::data::write_trajectories_with_field(
        &stiff,
        &bag.trajectories,
        &Default::default(),
        Some(&Field::default()),
    )
    .unwrap();
    refused(
        &mcgnode(&[
            "evaluate",
            "--model",
            LEGACY,
            "--bag",
            stiff.to_str().unwrap(),
        ]),
        &["stiffness 5", "--edge-physics"],
    );

    // Neither edges nor a system: refused with the fix.
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    v["trained_on"]["system_config"] = serde_json::Value::Null;
    let bare = TrainedFor::from_model_json("bare", &v);
    assert!(bare.edges_unrecorded);
    let e = bare
        .check(&graph(SystemKind::Spring, 5), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("does not record the edges") && e.contains("retrain"),
        "{e}"
    );
    // An edge-physics model reads its edges: nothing to refuse.
    v["hyper"]["edge_physics"] = serde_json::Value::Bool(true);
    let reads = TrainedFor::from_model_json("reads", &v);
    assert!(!reads.edges_unrecorded && reads.edge_params.is_none());
}

/// The scales a model file stores bound what it saw in training: a state
/// many scales beyond them (velocities of 1e300, a stretched bond, a
/// negative stiffness for an edge-physics model) is out of range; the
/// training states are not.
#[test]
fn inputs_far_outside_the_training_scales_are_out_of_range() {
    use mcgnode::compat::{InputRange, OUT_OF_RANGE_SIGMAS};
    let norm = mcgnode::gnode::Norm {
        q_mean: vec![0.0, 0.0],
        q_scale: 1.0,
        v_scale: 0.5,
        w_scale: 1.0,
        out_scale: 1.0,
        k_scale: 1.0,
    };
    let r = InputRange {
        norm,
        reads_positions: false,
        edge_physics: true,
    };
    let cfg = SystemConfig::new(SystemKind::Spring, 5);
    let g = cfg.graph();
    let s = cfg.start_for(&g, 1, 0);
    assert_eq!(r.check(&g, &s, OUT_OF_RANGE_SIGMAS), None);
    let mut fast = s.clone();
    fast.v.iter_mut().for_each(|v| *v = 1e300);
    let o = r.check(&g, &fast, OUT_OF_RANGE_SIGMAS).unwrap();
    assert!(o.what.contains("velocity") && o.times > 1e299, "{o}");
    // Just under and just over the limit.
    let mut edge = s.clone();
    edge.v.iter_mut().for_each(|v| *v = 0.0);
    edge.v[0] = 0.5 * 9.99;
    assert_eq!(r.check(&g, &edge, OUT_OF_RANGE_SIGMAS), None);
    edge.v[0] = 0.5 * 10.01;
    assert!(r.check(&g, &edge, OUT_OF_RANGE_SIGMAS).is_some());
    // NaN is never in range; a limit of 0 checks nothing.
    edge.v[0] = f64::NAN;
    assert!(r.check(&g, &edge, OUT_OF_RANGE_SIGMAS).is_some());
    assert_eq!(r.check(&g, &edge, 0.0), None);
    // Positions are checked only for models that read them.
    let mut far = s.clone();
    far.q.iter_mut().for_each(|q| *q += 100.0);
    assert_eq!(r.check(&g, &far, OUT_OF_RANGE_SIGMAS), None);
    let reads = InputRange {
        reads_positions: true,
        ..r.clone()
    };
    assert!(reads
        .check(&g, &far, OUT_OF_RANGE_SIGMAS)
        .unwrap()
        .what
        .contains("position"));
    // Edge physics: a negative stiffness is outside anything trained on.
    let mut neg = g.clone();
    with_edge(&mut neg, -1.0, 1.0);
    let o = r.check(&neg, &s, OUT_OF_RANGE_SIGMAS).unwrap();
    assert!(
        o.what.contains("stiffness") && o.what.contains("not positive"),
        "{o}"
    );
}

/// A stream of states of one system is checked once: the next state of the
/// same graph, field and model costs a comparison; another graph, field or
/// model (a swap) is checked in full, and a refusal is never remembered.
#[test]
fn one_full_check_per_system_in_a_row() {
    let t = TrainedFor::from_model_file(Path::new(&format!(
        "{ROOT}/bags/models/spring5-mcgnode.json"
    )))
    .unwrap();
    let p = mcgnode::compat::Passed::default();
    let (five, seven) = (graph(SystemKind::Spring, 5), graph(SystemKind::Spring, 7));
    let calm = Field::default();
    for _ in 0..100 {
        p.check(0, &t, &five, Some(&calm)).unwrap();
    }
    assert_eq!(p.full_checks(), 1);
    p.check(0, &t, &seven, Some(&calm)).unwrap();
    p.check(0, &t, &five, None).unwrap();
    p.check(1, &t, &five, None).unwrap();
    assert_eq!(p.full_checks(), 4);
    let pendulum = graph(SystemKind::Pendulum, 5);
    for k in 0..3 {
        assert!(p.check(1, &t, &pendulum, None).is_err());
        assert_eq!(p.full_checks(), 5 + k);
    }
}
