use super::*;
use crate::data::stream::{Estimate, History, Smoother, StreamOptions};
use crate::dynamics::Timing;
use crate::kernel::TrainedModel;
use crate::physics::{SystemConfig, SystemKind};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

fn shipped(name: &str) -> TrainedModel {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("bags/models")
        .join(name);
    TrainedModel::load(&p).expect("shipped model")
}

/// 100 Hz stamps in nanoseconds.
fn stamps(m: usize) -> Vec<Nanos> {
    (0..m as i64)
        .map(|k| 5_000_000_000 + k * 10_000_000)
        .collect()
}

fn max_err(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn positions_from_the_model_itself_give_back_its_state() {
    let model = shipped("spring5-mcgnode.json");
    let cfg = SystemConfig::new(SystemKind::Spring, 5);
    let graph = cfg.graph();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let start = cfg.initial_state(&graph, &mut rng);
    // 12 states 10 ms apart, 10 integration steps of 1 ms each.
    let traj = model
        .rollout(&graph, &start, Timing::integration(1e-3, 110, 10))
        .expect("rollout");
    assert_eq!(traj.len(), 12);
    let qs: Vec<&[f64]> = traj.iter().map(|s| s.q.as_slice()).collect();
    let mut fit = ModelFit::new(&model, &graph, FitOptions::with_dt(1e-3)).expect("fitter");
    let opts = FitOptions {
        iterations: 20,
        budget: Duration::from_secs(5),
        ..FitOptions::with_dt(1e-3)
    };
    fit.opts = opts;
    let f = fit.fit(&stamps(12), &qs).expect("fit");
    let last = traj.last().unwrap();
    let speed = last.v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    assert!(
        f.rms < 1e-9,
        "rms {} after {} iterations",
        f.rms,
        f.iterations
    );
    assert!(
        max_err(&f.state.q, &last.q) < 1e-8,
        "{:?} {:?}",
        f.state.q,
        last.q
    );
    assert!(
        max_err(&f.state.v, &last.v) < 1e-6 * speed.max(1.0),
        "{f:?}"
    );
    assert!(!f.warm);
    // The next window (one state on) starts from this fit: at its answer at once.
    let more = model
        .rollout(&graph, &start, Timing::integration(1e-3, 120, 10))
        .expect("rollout");
    let qs: Vec<&[f64]> = more[1..].iter().map(|s| s.q.as_slice()).collect();
    let g = fit.fit(&stamps(13)[1..], &qs).expect("fit");
    assert!(g.warm && g.rms_start < 1e-8, "{g:?}");
    assert!(max_err(&g.state.q, &more.last().unwrap().q) < 1e-8);
    // A window 5 states on (the ones between not fitted, as replay skips
    // them): the previous fit rolled on to its oldest stamp starts it.
    let later = model
        .rollout(&graph, &start, Timing::integration(1e-3, 170, 10))
        .expect("rollout");
    let qs: Vec<&[f64]> = later[6..].iter().map(|s| s.q.as_slice()).collect();
    let h = fit.fit(&stamps(18)[6..], &qs).expect("fit");
    assert!(h.warm && h.rms_start < 1e-8, "{h:?}");
    // With no previous fit before the window, it starts cold.
    fit.reset();
    let c = fit.fit(&stamps(18)[6..], &qs).expect("fit");
    assert!(!c.warm && c.rms_start > 1e-6, "{c:?}");
}

/// Truth from the simulator (not the model), positions with Gaussian noise
/// of `noise` times the spacing: the fit's velocity error at the newest
/// state against a poly smoother's on the same window.
fn velocity_errors(kind: SystemKind, model: &str, every: usize, dt: f64, noise: f64) -> (f64, f64) {
    let model = shipped(model);
    let mut cfg = SystemConfig::new(kind, 5);
    cfg.save_every = every;
    cfg.states = 120;
    let tr = cfg.simulate(1, 5).remove(0);
    let graph = tr.graph.clone();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let normal = Normal::new(0.0, noise).unwrap();
    let noisy: Vec<Vec<f64>> = tr
        .samples
        .iter()
        .map(|s| {
            s.state
                .q
                .iter()
                .map(|x| x + normal.sample(&mut rng))
                .collect()
        })
        .collect();
    let window = 15;
    let t: Vec<Nanos> = tr
        .samples
        .iter()
        .map(|s| (s.t * 1e9).round() as Nanos)
        .collect();
    let mut fit = ModelFit::new(&model, &graph, FitOptions::with_dt(dt)).expect("fitter");
    fit.opts.budget = Duration::from_secs(5);
    let poly = StreamOptions {
        smoother: Smoother::Poly { window, order: 2 },
        max_gap: 0.0,
    };
    let mut h = History::default();
    let (mut e_fit, mut e_poly) = (0.0, 0.0);
    for k in 0..tr.samples.len() {
        let est = h.push(&poly, &graph, t[k], &noisy[k]).1;
        let Estimate::Ready(p) = est else { continue };
        let w: Vec<&[f64]> = noisy[k + 1 - window..=k]
            .iter()
            .map(Vec::as_slice)
            .collect();
        let f = fit.fit(&t[k + 1 - window..=k], &w).expect("fit");
        let truth = &tr.samples[k].state;
        e_fit += max_err(&f.state.v, &truth.v).powi(2);
        e_poly += max_err(&p.v, &truth.v).powi(2);
    }
    (e_fit.sqrt(), e_poly.sqrt())
}

#[test]
fn through_the_model_noisy_springs_give_better_velocities_than_a_polynomial() {
    let (fit, poly) = velocity_errors(SystemKind::Spring, "spring5-mcgnode.json", 10, 1e-3, 1e-3);
    eprintln!("springs: velocity error, model fit {fit:.3e}, poly {poly:.3e}");
    assert!(fit < poly / 3.0, "model fit {fit:.3e}, poly {poly:.3e}");
}

#[test]
fn through_the_model_a_noisy_pendulum_gives_better_velocities_than_a_polynomial() {
    let (fit, poly) = velocity_errors(
        SystemKind::Pendulum,
        "pendulum5-mcgnode.json",
        1000,
        1e-4,
        1e-3,
    );
    eprintln!("pendulum: velocity error, model fit {fit:.3e}, poly {poly:.3e}");
    assert!(fit < poly / 3.0, "model fit {fit:.3e}, poly {poly:.3e}");
}

#[test]
fn a_model_without_accelerations_or_a_kinematic_graph_is_refused_with_the_fix() {
    let cfg = SystemConfig::new(SystemKind::Spring, 5);
    let mut graph = cfg.graph();
    let truth = crate::models::truth::truth(SystemKind::Spring);
    let e = ModelFit::new(truth.as_ref(), &graph, FitOptions::with_dt(1e-3))
        .err()
        .expect("refused");
    assert!(e.to_string().contains("poly"), "{e}");
    graph.kinematic = vec![false; 5];
    graph.kinematic[0] = true;
    let model = shipped("spring5-mcgnode.json");
    let e = ModelFit::new(&model, &graph, FitOptions::with_dt(1e-3))
        .err()
        .expect("refused");
    assert!(e.to_string().contains("kinematic"), "{e}");
    let mut fit = ModelFit::new(&model, &cfg.graph(), FitOptions::with_dt(1e-3)).unwrap();
    let q = vec![0.0; 10];
    let e = fit.fit(&stamps(2), &[&q, &q]).unwrap_err();
    assert!(e.to_string().contains("at least 3"), "{e}");
}
