//! Measurement, not a check: a short training of each baseline and of
//! MCGNODE on 10 trajectories of the 5-spring (200 epochs, `MEASURE_EPOCHS`
//! to change), then the test acceleration MSE and the time-averaged rollout
//! errors on 3 trajectories from another seed, with each training's seconds.
//! Run with `cargo bench --bench short_training` (minutes). `mcgnode
//! reproduce` makes the full comparison; this is the quick look.

use mcgnode::baselines::{train_baseline, BaselineHyper, Kind};
use mcgnode::data::dataset::Dataset;
use mcgnode::dynamics::{Dynamics, DynamicsError};
use mcgnode::model::batch::Batch;
use mcgnode::model::plan::GraphPlan;
use mcgnode::physics::rk4::rk4_trajectories;
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::system::{Graph, State};
use mcgnode::train::TrainConfig;

/// MCGNODE's candle net behind `Dynamics`, for the comparison below.
struct NetDyn(mcgnode::model::Net);

impl Dynamics for NetDyn {
    fn describe(&self) -> String {
        "mcgnode (candle)".into()
    }
    fn supports(&self, _: &Graph) -> Result<(), DynamicsError> {
        Ok(())
    }
    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        let plan = GraphPlan::new(graph);
        let model = |e: mcgnode::Error| DynamicsError::Model(e.to_string());
        let b = Batch::new(&plan, &[state], None, 1).map_err(model)?;
        let a = self.0.forward(&b).map_err(model)?.acc;
        out.copy_from_slice(&a.flatten_all().unwrap().to_vec1::<f64>().unwrap());
        Ok(())
    }
    fn forces(&self, _: &Graph, _: &State) -> Result<mcgnode::dynamics::Forces, DynamicsError> {
        Err(DynamicsError::Model("not needed".into()))
    }
}

fn main() {
    mcgnode::alloc::prepare_for_candle();
    let epochs: usize = std::env::var("MEASURE_EPOCHS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200);
    let c = SystemConfig::new(SystemKind::Spring, 5);
    let ds = Dataset::from_trajectories(&c.simulate(10, 1)).expect("a training set");
    let (g, s, a) = (ds.graph, ds.states, ds.acc);
    let rk: Vec<_> = rk4_trajectories(&c, 10, 1).unwrap();
    let (rs, ra): (Vec<State>, Vec<Vec<f64>>) = rk
        .iter()
        .flat_map(|t| {
            t.samples
                .iter()
                .map(|x| (x.state.clone(), x.acc.clone().unwrap()))
        })
        .unzip();
    let test = c.simulate(3, 99);
    let cfg = TrainConfig {
        epochs,
        patience: epochs,
        ..TrainConfig::default()
    };
    let mut models: Vec<(String, Box<dyn Dynamics>, f64)> = vec![];
    for kind in Kind::ALL {
        let (ds, da) = if kind == Kind::Hgn {
            (&rs, &ra)
        } else {
            (&s, &a)
        };
        let t0 = std::time::Instant::now();
        let m = train_baseline(BaselineHyper::new(kind, 2, 1), &g, ds, da, &cfg, |_| true).unwrap();
        models.push((kind.to_string(), Box::new(m), t0.elapsed().as_secs_f64()));
    }
    let mut h = mcgnode::model::Hyper::new(mcgnode::model::Variant::Mcgnode, 2, 1, 5);
    h.body_force = false;
    let t0 = std::time::Instant::now();
    let m = mcgnode::train::train(h, &g, &s, &a, &cfg, |_| true).unwrap();
    models.push((
        "mcgnode".into(),
        Box::new(NetDyn(m.net)),
        t0.elapsed().as_secs_f64(),
    ));
    for (name, m, secs) in &models {
        let mut se = 0.0;
        let mut cnt = 0.0;
        let mut curves = vec![];
        for t in &test {
            for x in &t.samples {
                let mut out = vec![0.0; g.ndof()];
                m.acceleration(&g, &x.state, &mut out).unwrap();
                se += out
                    .iter()
                    .zip(x.acc.as_ref().unwrap())
                    .map(|(p, q)| (p - q).powi(2))
                    .sum::<f64>();
                cnt += out.len() as f64;
            }
            let roll = m.rollout(&g, &t.samples[0].state, 0.01, 990);
            let Ok(roll) = roll else {
                println!("{name}: rollout diverged");
                continue;
            };
            let pred: Vec<State> = roll.into_iter().step_by(10).collect();
            let truth: Vec<State> = t.samples.iter().map(|x| x.state.clone()).collect();
            let times: Vec<f64> = t.samples.iter().map(|x| x.t).collect();
            curves
                .push(mcgnode::metrics::error_curves(&g, &c.field, &truth, &pred, &times).unwrap());
        }
        let av = mcgnode::metrics::summarize(&curves).unwrap().time_average();
        println!(
            "{name}: train {secs:.1} s; test acc MSE {:.3e}; time-avg RE {:.3e} EE {:.3e} ME {:.3e}",
            se / cnt,
            av.re,
            av.ee,
            av.me
        );
    }
}
