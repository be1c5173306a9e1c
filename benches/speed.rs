//! Criterion benches of the two hot paths: one candle training step (forward +
//! backward, batch 100) and one kernel step of a rollout.

use criterion::{criterion_group, criterion_main, Criterion};
use mcgnode::bench::{random_model, rollout_seconds, train_step_seconds};
use mcgnode::model::Variant;
use mcgnode::physics::{SystemConfig, SystemKind};

fn training_step(c: &mut Criterion) {
    for (name, kind) in [
        ("spring", SystemKind::Spring),
        ("pendulum", SystemKind::Pendulum),
    ] {
        c.bench_function(&format!("train step 5-{name} mcgnode b100"), |b| {
            b.iter(|| train_step_seconds(kind, Variant::Mcgnode, 100, 1).unwrap())
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
