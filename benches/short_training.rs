//! Measurement, not a check: a short training of each baseline and of
//! MCGNODE on 10 trajectories of the 5-spring (200 epochs, `MEASURE_EPOCHS`
//! to change), through the same path as the command line (simulate → bag →
//! train → model file → evaluate on 3 trajectories from another seed), with
//! each training's seconds. Run with `cargo bench --bench short_training`
//! (minutes). `mcgnode reproduce` makes the full comparison; this is the
//! quick look.

use mcgnode::baselines::Kind;
use mcgnode::data::bag::read_trajectories;
use mcgnode::evaluate::{evaluate, EvalOptions};
use mcgnode::gnode::Variant;
use mcgnode::models::{load_any_model, train_any_from_bags, ModelKind, ModelRef};
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::simulate::{simulate_with, DataIntegrator};
use mcgnode::train::{ModelOptions, Recipe, TrainConfig};

fn main() -> mcgnode::Result<()> {
    mcgnode::alloc::prepare_for_candle();
    let epochs: usize = std::env::var("MEASURE_EPOCHS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200);
    let dir = tempfile::tempdir()?;
    let bag = |name: &str, integrator, trajectories, seed| {
        let path = dir.path().join(name);
        let c = SystemConfig::new(SystemKind::Spring, 5);
        simulate_with(&c, integrator, trajectories, seed, &path).map(|()| path)
    };
    let verlet = bag("train.mcap", DataIntegrator::Verlet, 10, 1)?;
    // HGN learns (q̇, ṗ) from RK4 data, as in `reproduce`.
    let rk4 = bag("train-rk4.mcap", DataIntegrator::Rk4, 10, 1)?;
    let test = read_trajectories(&bag("test.mcap", DataIntegrator::Verlet, 3, 99)?)?;
    let cfg = TrainConfig {
        epochs,
        patience: epochs,
        ..TrainConfig::default()
    };
    let kinds = Kind::ALL
        .map(ModelKind::Baseline)
        .into_iter()
        .chain([ModelKind::Family(Variant::Mcgnode)]);
    for kind in kinds {
        let data = if kind == ModelKind::Baseline(Kind::Hgn) {
            &rk4
        } else {
            &verlet
        };
        let out = dir.path().join(format!("{kind}.json"));
        let opts = ModelOptions::for_recipe(Recipe::Paper);
        let t = train_any_from_bags(
            kind,
            std::slice::from_ref(data),
            &opts,
            &cfg,
            |_| {},
            |_| true,
            &out,
        )?;
        let m = load_any_model(&ModelRef::File(out.clone()))?;
        let e = evaluate(
            m.dynamics.as_ref(),
            &m.start_fingerprints,
            &test,
            &EvalOptions::default(),
        )?;
        let av = e.averages;
        println!(
            "{kind}: train {:.1} s, validation MSE {:.3e}; time-averaged RE {:.3e}, EE {:.3e}, \
             ME scaled {:.3e}, diverged {}/{}",
            t.seconds, t.validation_loss, av.re, av.ee, av.me_scaled, e.diverged, e.trajectories
        );
    }
    Ok(())
}
