//! Criterion benches of the two hot paths: one training step of the native
//! engine (forward + backward, batch 100) and one kernel step of a rollout.

use criterion::{criterion_group, criterion_main, Criterion};
use mcgnode::bench::{rollout_seconds, training_set};
use mcgnode::engine::{all_cores, Engine};
use mcgnode::gnode::Variant;
use mcgnode::gnode::{Hyper, Net};
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::testing::random_model;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn training_step(c: &mut Criterion) {
    for (name, kind) in [
        ("spring", SystemKind::Spring),
        ("pendulum", SystemKind::Pendulum),
    ] {
        let (g, s, a) = training_set(kind, 5, 1);
        let mut h = Hyper::new(Variant::Mcgnode, 2, 1, 5);
        h.body_force = !g.anchors.is_empty();
        let net = Net::new(h.clone(), &mut ChaCha8Rng::seed_from_u64(0)).unwrap();
        let mut eng = Engine::new(&h, &g, all_cores()).unwrap();
        let theta = eng.layout().flatten(&net.store.weights().unwrap()).unwrap();
        let idx: Vec<usize> = (0..100).collect();
        let mut grad = vec![0.0; theta.len()];
        let samples = eng.samples(&s, &a);
        c.bench_function(&format!("engine step 5-{name} mcgnode b100"), |b| {
            b.iter(|| eng.loss_grad(&theta, &samples, &idx, &mut grad))
        });
    }
}

fn kernel_step(c: &mut Criterion) {
    for n in [5usize, 50, 500] {
        let cfg = SystemConfig::new(SystemKind::Spring, n);
        let g = cfg.graph();
        let (_, m) = random_model(Variant::Mcgnode, &g, 0).unwrap();
        let mut ws = m.kernel.workspace(&g).unwrap();
        let s = cfg.start_for(&g, 1, 0);
        let mut a = vec![0.0; g.ndof()];
        c.bench_function(&format!("kernel step {n}-spring mcgnode"), |b| {
            b.iter(|| m.kernel.acceleration(&mut ws, &s.q, &s.v, &mut a))
        });
    }
    c.bench_function("rollout 5-spring 1000 steps", |b| {
        b.iter(|| rollout_seconds(SystemKind::Spring, 5, Variant::Mcgnode, 1000, 1).unwrap())
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = training_step, kernel_step
}
criterion_main!(benches);
