//! Error metrics, their summary, and the plot. Run with
//! `cargo test --release --test metrics`.

use mcgnode::metrics::{error_curves, summarize, ErrorCurves, Summary};
use mcgnode::physics::{Field, SystemConfig, SystemKind};
use mcgnode::plot::plot_summaries;
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, State};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1e-300)
}

#[test]
fn identical_trajectories_have_zero_error() {
    let mut cfg = SystemConfig::new(SystemKind::Spring, 5);
    cfg.states = 20;
    let t = &cfg.simulate(1, 3)[0];
    let states: Vec<State> = t.samples.iter().map(|s| s.state.clone()).collect();
    let times: Vec<f64> = t.samples.iter().map(|s| s.t).collect();
    let c = error_curves(&t.graph, &cfg.field, &states, &states, &times).unwrap();
    assert_eq!(c.t, times);
    for v in [&c.re, &c.ee, &c.me, &c.me_scaled] {
        assert_eq!(v.len(), 20);
        assert!(v.iter().all(|x| *x == 0.0), "{v:?}");
    }
}

/// Two particles joined by a spring (k = 2, r0 = 1), gravity 3 along −y.
fn two_body() -> (Graph, Field) {
    let g = Graph {
        dim: 2,
        types: vec![0, 0],
        masses: vec![1.0, 2.0],
        edges: vec![Edge {
            a: 0,
            b: Endpoint::Particle(1),
            kind: EdgeKind::Spring,
            rest_length: 1.0,
            stiffness: 2.0,
        }],
        anchors: vec![],
        interaction_radius: 0.0,
        kinematic: vec![],
        periodic_box: None,
    };
    (
        g,
        Field {
            gravity: 3.0,
            drag: 0.0,
            force: vec![],
        },
    )
}

#[test]
fn hand_computed_case() {
    let (g, f) = two_body();
    // Truth: particle 0 at (1, 0) moving (1, 0); particle 1 at rest at the origin.
    let truth = State {
        q: vec![1.0, 0.0, 0.0, 0.0],
        v: vec![1.0, 0.0, 0.0, 0.0],
    };
    // Prediction: particle 0 at (1, 1) moving (2, 0).
    let pred = State {
        q: vec![1.0, 1.0, 0.0, 0.0],
        v: vec![2.0, 0.0, 0.0, 0.0],
    };
    let c = error_curves(&g, &f, &[truth], &[pred], &[0.5]).unwrap();
    // RE = |(0, 1)| / (√2 + 1).
    assert!(
        close(c.re[0], 1.0 / (2f64.sqrt() + 1.0), 1e-14),
        "RE {}",
        c.re[0]
    );
    // H = ½·1·1 + 0 (spring at rest length) + 0 (y = 0) = 0.5.
    // Ĥ = ½·1·4 + ½·2·(√2 − 1)² + 1·3·1 = 2 + (√2 − 1)² + 3.
    let h = 0.5;
    let hp = 5.0 + (2f64.sqrt() - 1.0).powi(2);
    assert!(close(c.ee[0], (hp - h) / (hp + h), 1e-14), "EE {}", c.ee[0]);
    // P = (1, 0), P̂ = (2, 0): ME = 1 / 3; momentum scale 1 + 2 as well.
    assert!(close(c.me[0], 1.0 / 3.0, 1e-14), "ME {}", c.me[0]);
    assert!(close(c.me_scaled[0], 1.0 / 3.0, 1e-14));

    // Both momenta zero, positions differ: ME is 0/0, defined as 0.
    let a = State {
        q: vec![1.0, 0.0, 0.0, 0.0],
        v: vec![0.0; 4],
    };
    let b = State {
        q: vec![2.0, 0.0, 0.0, 0.0],
        v: vec![0.0; 4],
    };
    let c = error_curves(&g, &f, &[a], &[b], &[0.0]).unwrap();
    assert_eq!(c.me[0], 0.0);
    assert_eq!(c.me_scaled[0], 0.0);
    assert!(close(c.re[0], 1.0 / 3.0, 1e-14));
}

#[test]
fn bad_input_is_rejected() {
    let (g, f) = two_body();
    let s = State {
        q: vec![0.0; 4],
        v: vec![0.0; 4],
    };
    let err = error_curves(
        &g,
        &f,
        std::slice::from_ref(&s),
        &[s.clone(), s.clone()],
        &[0.0],
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("must match"), "{err}");
    let nan = State {
        q: vec![f64::NAN, 0.0, 0.0, 0.0],
        v: vec![0.0; 4],
    };
    let err = error_curves(&g, &f, std::slice::from_ref(&s), &[nan], &[0.0])
        .unwrap_err()
        .to_string();
    assert!(err.contains("predicted state 0"), "{err}");
    assert!(error_curves(&g, &f, &[], &[], &[]).is_err());
    assert!(summarize(&[]).is_err());
}

fn constant(t: &[f64], re: f64, ee: f64, me: f64) -> ErrorCurves {
    ErrorCurves {
        t: t.to_vec(),
        re: vec![re; t.len()],
        ee: vec![ee; t.len()],
        me: vec![me; t.len()],
        me_scaled: vec![me; t.len()],
        re_abs: vec![re; t.len()],
        me_abs: vec![me; t.len()],
    }
}

#[test]
fn summary_of_constant_curves_is_the_constant() {
    let t = [0.0, 0.1, 0.2, 0.3];
    let curves = vec![constant(&t, 0.1, 2e-5, 0.3); 3];
    let s = summarize(&curves).unwrap();
    assert_eq!(s.n, 3);
    for (band, want) in [(&s.re, 0.1), (&s.ee, 2e-5), (&s.me, 0.3)] {
        for v in band.gmean.iter().chain(&band.lo).chain(&band.hi) {
            assert!(close(*v, want, 1e-12), "{v} vs {want}");
        }
    }
    let avg = s.time_average();
    assert!(close(avg.re, 0.1, 1e-12) && close(avg.ee, 2e-5, 1e-12) && close(avg.me, 0.3, 1e-12));
}

#[test]
fn summary_band_by_hand() {
    let t = [0.0, 1.0];
    let mut a = constant(&t, 1e-2, 1.0, 0.0);
    a.re[1] = 1.0;
    let b = constant(&t, 1e-4, 1.0, 0.0);
    let s = summarize(&[a, b]).unwrap();
    // Logs ln 1e-2 and ln 1e-4: mean ln 1e-3, sample sd √2·ln 10.
    assert!(close(s.re.gmean[0], 1e-3, 1e-12));
    let w = 10f64.powf(1.96 * 2f64.sqrt());
    assert!(close(s.re.hi[0], 1e-3 * w, 1e-12));
    assert!(close(s.re.lo[0], 1e-3 / w, 1e-12));
    // At t = 1: values 1 and 1e-4, geometric mean 1e-2.
    assert!(close(s.at(0.9).0, 1e-2, 1e-12));
    assert!(close(s.at(-5.0).0, 1e-3, 1e-12));
    // Zeros are floored, not NaN.
    assert!(s.me.gmean.iter().all(|x| *x > 0.0 && *x < 1e-290));
    // Time average: the arithmetic mean of the geometric-mean curve after t = 0,
    // here the single value 1e-2.
    assert!(close(s.time_average().re, 1e-2, 1e-12));
    // Curves on different times are refused.
    let c = constant(&[0.0, 2.0], 1.0, 1.0, 1.0);
    let err = summarize(&[constant(&t, 1.0, 1.0, 1.0), c])
        .unwrap_err()
        .to_string();
    assert!(err.contains("time"), "{err}");
}

/// A summary whose errors grow like a·e^{t} with a log-normal spread.
fn growing(t: &[f64], a: f64) -> Summary {
    let curves: Vec<ErrorCurves> = (0..10)
        .map(|i| {
            let f = 1.0 + 0.3 * f64::from(i);
            ErrorCurves {
                t: t.to_vec(),
                re: t.iter().map(|x| f * a * x.exp()).collect(),
                ee: t.iter().map(|x| f * a * 0.1 * (1.0 + x)).collect(),
                me: t.iter().map(|x| f * a * 1e-3 * (2.0 + x.sin())).collect(),
                me_scaled: t.iter().map(|_| 0.0).collect(),
                re_abs: t.iter().map(|x| f * x).collect(),
                me_abs: t.iter().map(|_| 0.0).collect(),
            }
        })
        .collect();
    summarize(&curves).unwrap()
}

#[test]
fn plot_is_written_as_png() {
    let t: Vec<f64> = (0..100).map(|k| f64::from(k) * 0.1).collect();
    let panels = vec![
        (
            "5-spring".to_string(),
            vec![
                ("gnode".to_string(), growing(&t, 1e-3)),
                ("mcgnode".to_string(), growing(&t, 1e-6)),
            ],
        ),
        (
            "5-pendulum".to_string(),
            vec![
                ("gnode".to_string(), growing(&t, 1e-2)),
                ("mcgnode".to_string(), growing(&t, 1e-5)),
            ],
        ),
    ];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("errors.png");
    plot_summaries(&path, &panels).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "not a PNG");
    assert_eq!(&bytes[12..16], b"IHDR");
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!(
        (w, h),
        (2 * 460, 4 * 300),
        "a column per panel, a row per metric"
    );
    assert!(
        bytes.len() > 10_000,
        "suspiciously small PNG ({} bytes)",
        bytes.len()
    );
    if let Ok(keep) = std::env::var("MCGNODE_KEEP_PLOT") {
        std::fs::copy(&path, keep).unwrap();
    }

    assert!(plot_summaries(&path, &[]).is_err());
    assert!(plot_summaries(&path, &[("empty".into(), vec![])]).is_err());
    let missing = dir.path().join("no/such/dir/x.png");
    assert!(plot_summaries(&missing, &panels).is_err());
}

#[test]
fn absolute_errors_and_diverged_rollouts() {
    use mcgnode::metrics::DIVERGED;
    let g = SystemConfig::new(SystemKind::Spring, 3).graph();
    let f = Field::default();
    let truth = State {
        q: vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0],
        v: vec![1.0, 0.0, 0.0, 0.0, -1.0, 0.0],
    };
    let mut pred = truth.clone();
    pred.q[0] += 3.0;
    pred.q[1] += 4.0;
    pred.v[0] += 0.5;
    let c = error_curves(&g, &f, std::slice::from_ref(&truth), &[pred], &[1.0]).unwrap();
    // ‖Δq‖ = 5; ΔP = (0.5, 0) with unit masses.
    assert!(close(c.re_abs[0], 5.0, 1e-15), "{}", c.re_abs[0]);
    assert!(close(c.me_abs[0], 0.5, 1e-15), "{}", c.me_abs[0]);
    // A rollout that diverged after its first state scores the worst values.
    let d = ErrorCurves::diverged(c.clone(), &[1.0, 2.0, 3.0]);
    assert_eq!(d.t, vec![1.0, 2.0, 3.0]);
    assert_eq!(d.re[1..], [1.0, 1.0]);
    assert_eq!(d.me_abs[1..], [DIVERGED, DIVERGED]);
    let s = summarize(&[d.clone(), d]).unwrap();
    assert!(s.re_abs.gmean.iter().all(|x| x.is_finite()));
    assert!(close(s.re_abs.gmean[2], DIVERGED, 1e-9));
}

/// Accelerations that blow up once |q| passes a threshold: a model whose
/// rollouts diverge after a while.
struct Exploding;

impl mcgnode::dynamics::Dynamics for Exploding {
    fn describe(&self) -> String {
        "exploding".into()
    }
    fn supports(&self, _: &Graph) -> Result<(), mcgnode::dynamics::DynamicsError> {
        Ok(())
    }
    fn acceleration(
        &self,
        _: &Graph,
        s: &State,
        out: &mut [f64],
    ) -> Result<(), mcgnode::dynamics::DynamicsError> {
        let r = s.q.iter().map(|x| x * x).sum::<f64>().sqrt();
        for o in out.iter_mut() {
            *o = if r > 3.0 { f64::INFINITY } else { 1.0 };
        }
        Ok(())
    }
    fn forces(
        &self,
        _: &Graph,
        _: &State,
    ) -> Result<mcgnode::dynamics::Forces, mcgnode::dynamics::DynamicsError> {
        Ok(Default::default())
    }
}

/// A diverging rollout keeps its states so far, is counted, and scores the
/// worst values from then on instead of failing the evaluation.
#[test]
fn diverged_rollouts_are_scored_not_fatal() {
    use mcgnode::dynamics::Dynamics;
    let mut c = SystemConfig::new(SystemKind::Spring, 3);
    c.states = 31;
    let trajs = c.simulate(2, 7);
    let g = c.graph();
    let starts: Vec<State> = trajs.iter().map(|t| t.samples[0].state.clone()).collect();
    let r = Exploding
        .rollout_many(
            &g,
            &starts,
            mcgnode::dynamics::Timing::integration(0.01, 3000, 100),
        )
        .unwrap();
    for x in &r {
        let at = x.diverged_at.expect("diverges");
        assert_eq!(
            x.states.len(),
            1 + (at - 1) / 100,
            "states kept up to divergence"
        );
        assert!(x.states.iter().all(|s| s.validate(&g).is_ok()));
    }
    let bag = mcgnode::data::bag::Bag {
        trajectories: trajs,
        metadata: [(
            mcgnode::data::meta::KEY_SYSTEM_CONFIG.to_string(),
            serde_json::to_string(&c).unwrap(),
        )]
        .into_iter()
        .collect(),
        field: None,
        topic: "/particle_state".into(),
        sources: vec![],
        derived_velocities: vec![],
    };
    let e = mcgnode::evaluate::evaluate(&Exploding, &[], &bag, &Default::default()).unwrap();
    assert_eq!(e.diverged, 2);
    assert_eq!(*e.summary.re.gmean.last().unwrap(), 1.0);
    let worst = *e.summary.re_abs.gmean.last().unwrap();
    assert!(close(worst, mcgnode::metrics::DIVERGED, 1e-12), "{worst}");
    assert!(mcgnode::evaluate::table(&e, 4).contains("2 of 2 rollouts diverged"));
}
