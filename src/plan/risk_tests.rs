//! The risk term: nothing changes at weight 0, it reorders candidates when
//! the ensemble's spread differs between them, the lanes give the same risk
//! as candidates run one by one, it equals the members' spread computed
//! apart, and a single model refuses a weight.

use super::*;
use crate::dynamics::Forces;
use crate::kernel::Ensemble;
use crate::physics::{Drive, SystemConfig, SystemKind};
use crate::plan::CostKind;
use std::sync::Arc;

/// The held chain's true physics with a made-up disagreement: its
/// "members" agree except to the right of where each free particle started
/// (by more than 1 mm), where their spread is how far right of it the
/// particle is.
struct Disagree {
    truth: Arc<dyn Dynamics>,
    start: State,
}

impl Dynamics for Disagree {
    fn describe(&self) -> String {
        "an ensemble that disagrees to the right".into()
    }
    fn supports(&self, graph: &Graph) -> Result<(), DynamicsError> {
        self.truth.supports(graph)
    }
    fn acceleration(&self, g: &Graph, s: &State, out: &mut [f64]) -> Result<(), DynamicsError> {
        self.truth.acceleration(g, s, out)
    }
    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError> {
        self.truth.forces(graph, state)
    }
    fn rollout_driven(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: &Drive,
    ) -> Result<Vec<State>, DynamicsError> {
        self.truth.rollout_driven(graph, start, timing, drive)
    }
    fn members(&self) -> usize {
        2
    }
    fn rollout_spread(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: Option<&Drive>,
    ) -> Result<(Vec<State>, Spread), DynamicsError> {
        let states = self.rollout_driven(graph, start, timing, drive.expect("driven"))?;
        let d = graph.dim;
        let right = |s: &State, i: usize| (s.q[i * d] - self.start.q[i * d] - 1e-3).max(0.0);
        let spread = states
            .iter()
            .map(|s| (0..graph.n()).map(|i| right(s, i)).collect())
            .collect();
        Ok((states, spread))
    }
}

fn chain() -> (SystemConfig, Graph, State) {
    let cfg = SystemConfig::new(SystemKind::HeldChain, 3);
    let g = cfg.graph();
    let mut start = cfg.start_for(&g, 3, 0);
    start.v.iter_mut().for_each(|v| *v = 0.0);
    (cfg, g, start)
}

fn problem<'a>(model: &'a dyn Dynamics, g: &'a Graph, start: &'a State, risk: f64) -> Problem<'a> {
    let end = 2;
    Problem {
        model,
        graph: g,
        start,
        timing: Timing::of_step(0.005, 20, 5),
        cost: Cost {
            kind: CostKind::Along,
            particles: vec![end],
            targets: vec![start.q[2 * end] + 0.05, start.q[2 * end + 1]],
            effort: 1e-3,
            speed: 0.0,
            risk,
        },
        max_speed: 1.0,
    }
}

/// The gripper moving along x at `vx` for the whole horizon.
fn moving(p: &Problem, vx: f64) -> Controls {
    let w = p.width();
    let u = (0..p.timing.horizon * w)
        .map(|j| if j % w == 0 { vx } else { 0.0 })
        .collect();
    Controls {
        steps: p.timing.horizon,
        width: w,
        u,
    }
}

/// Toward the target (right) is cheaper without risk; with a weight, the
/// members' disagreement on the right makes the left the cheaper.
#[test]
fn the_risk_term_reorders_candidates_by_spread() {
    let (_, g, start) = chain();
    let model = Disagree {
        truth: crate::models::truth::truth(SystemKind::HeldChain),
        start: start.clone(),
    };
    let plain = problem(&model, &g, &start, 0.0);
    let (right, left) = (moving(&plain, 0.5), moving(&plain, -0.5));
    let c0 = plain.costs(&[right.clone(), left.clone()]).unwrap();
    assert!(c0[0] < c0[1], "without risk the target's side wins: {c0:?}");
    let risky = problem(&model, &g, &start, 10.0);
    let c1 = risky.costs(&[right.clone(), left.clone()]).unwrap();
    assert!(c1[0] > c1[1], "with risk the agreed side wins: {c1:?}");
    // Only the disagreeing candidate's cost moved, by its weighted spread.
    assert_eq!(c1[1].to_bits(), c0[1].to_bits());
    let (_, spread) = risky.rollout_spread(&right).unwrap();
    let sum: f64 = spread[1..].iter().map(|s| (s[0] + s[1] + s[2]) / 3.0).sum();
    assert!(sum > 0.0);
    assert!((c1[0] - c0[0] - 10.0 * sum).abs() <= 1e-12 * c1[0].abs());
    let best = plan(
        &risky,
        Sampler::Random {
            candidates: 16,
            sigma: 0.5,
        },
        None,
        1,
        |_| true,
    );
    assert!(best.unwrap().cost.is_finite());
}

/// A two-member MCGNODE ensemble on the lanes: at weight 0 every cost is,
/// bit for bit, the plain cost of the mean rollout (the planner as before
/// the risk term); at weight 1 the lanes' costs equal the candidates' run
/// one by one, and exceed the plain ones by the weighted spread.
#[test]
fn weight_zero_is_the_plain_cost_and_lanes_agree() {
    let (_, g, start) = chain();
    let member = |seed| crate::testing::random_model(crate::gnode::Variant::Mcgnode, &g, seed);
    let ensemble = Ensemble {
        members: vec![member(1).unwrap().1, member(2).unwrap().1],
    };
    let plain = problem(&ensemble, &g, &start, 0.0);
    assert!(super::super::lanes::Lanes::new(&ensemble, &g, &start).is_some());
    let candidates: Vec<Controls> = (0..90)
        .map(|k| moving(&plain, 0.02 * (f64::from(k) - 45.0)))
        .collect();
    let c0 = plain.costs(&candidates).unwrap();
    for (c, cost) in candidates.iter().zip(&c0) {
        let states = plain.rollout(c).unwrap();
        let want = plain.cost.of(&states, g.dim, c, plain.timing);
        assert_eq!(cost.to_bits(), want.to_bits());
    }
    let risky = problem(&ensemble, &g, &start, 1.0);
    let c1 = risky.costs(&candidates).unwrap();
    let mut moved = 0;
    for ((c, lane), before) in candidates.iter().zip(&c1).zip(&c0) {
        let alone = risky.cost_of(c).unwrap();
        assert!(
            (lane - alone).abs() <= 1e-10 * alone.abs(),
            "{lane} vs {alone}"
        );
        assert!(lane >= before);
        moved += usize::from(lane > before);
    }
    assert!(
        2 * moved > candidates.len(),
        "the spread moved only {moved} costs"
    );
}

/// A weight above 0 on a single model is refused, naming `train --ensemble`.
#[test]
fn a_single_model_refuses_a_risk_weight() {
    let (_, g, start) = chain();
    let truth = crate::models::truth::truth(SystemKind::HeldChain);
    assert!(problem(truth.as_ref(), &g, &start, 0.0).check().is_ok());
    let e = problem(truth.as_ref(), &g, &start, 0.5)
        .check()
        .unwrap_err();
    assert!(e.to_string().contains("train --ensemble K"), "{e}");
    let e = problem(truth.as_ref(), &g, &start, -1.0)
        .check()
        .unwrap_err();
    assert!(e.to_string().contains("risk weights finite and ≥ 0"), "{e}");
}

/// The risk term against a computation that shares nothing with the
/// ensemble's: each member rolled out alone under the same controls, and
/// for two members the spread in closed form, |x₁ − x₂| / (2√d) per
/// particle (the members' standard deviation, RMS over the axes). The cost
/// at weight w exceeds the cost at 0 by w × Σₖ the free particles' mean of
/// it, and the mean rollout is the members' average.
#[test]
fn the_risk_term_equals_the_members_spread_computed_apart() {
    let (_, g, start) = chain();
    let member = |seed| crate::testing::random_model(crate::gnode::Variant::Mcgnode, &g, seed);
    let (a, b) = (member(4).unwrap().1, member(5).unwrap().1);
    let ensemble = Ensemble {
        members: vec![a.clone(), b.clone()],
    };
    let w = 2.5;
    let (plain, risky) = (
        problem(&ensemble, &g, &start, 0.0),
        problem(&ensemble, &g, &start, w),
    );
    let free = plain.free();
    assert!(!free.is_empty() && free.len() < g.n(), "{free:?}");
    let d = g.dim as f64;
    for vx in [-0.3, 0.0, 0.2, 0.5] {
        let c = moving(&plain, vx);
        let ra = problem(&a, &g, &start, 0.0).rollout(&c).unwrap();
        let rb = problem(&b, &g, &start, 0.0).rollout(&c).unwrap();
        let mean = plain.rollout(&c).unwrap();
        let risk: f64 = (1..ra.len())
            .map(|k| {
                let spread = |i: usize| {
                    let sq: f64 = (0..g.dim)
                        .map(|c| (ra[k].q[i * g.dim + c] - rb[k].q[i * g.dim + c]).powi(2))
                        .sum();
                    sq.sqrt() / (2.0 * d.sqrt())
                };
                free.iter().map(|&i| spread(i)).sum::<f64>() / free.len() as f64
            })
            .sum();
        for (k, m) in mean.iter().enumerate() {
            for (j, q) in m.q.iter().enumerate() {
                let avg = 0.5 * (ra[k].q[j] + rb[k].q[j]);
                assert!(
                    (q - avg).abs() <= 1e-12 * (1.0 + avg.abs()),
                    "step {k}: {q} vs {avg}"
                );
            }
        }
        assert!(risk > 0.0, "random members agree exactly at vx {vx}");
        let extra = risky.cost_of(&c).unwrap() - plain.cost_of(&c).unwrap();
        assert!(
            (extra - w * risk).abs() <= 1e-9 * w * risk,
            "vx {vx}: cost grew by {extra}, independent w × risk {}",
            w * risk
        );
    }
}
