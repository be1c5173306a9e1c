//! Candidates stepped together: `L` copies of the system side by side as one
//! graph of `L · n` particles (no edge joins two copies), each copy driven by
//! its own candidate, rolled out in one call. The model sees one larger graph,
//! so its MLPs run on `L` times the rows per call (full SIMD tiles instead of
//! a 20-particle graph's padded ones) and the per-rollout overhead is paid
//! once per `L` candidates.
//!
//! Exact only when the copies cannot interact: no contact radius (contacts
//! would be found between copies lying on top of each other) and no bars (one
//! constraint solve over all copies costs O((L · bars)³)). Otherwise, or when
//! a group diverges or the model refuses the larger graph, its candidates run
//! one by one as before: the costs never depend on the lanes.

use super::controls::Controls;
use super::search::{PlanError, Problem};
use crate::physics::Drive;
use crate::system::{Edge, Endpoint, Graph, State};

/// Particles per lane group the lanes aim at: enough rows for full tiles in
/// every MLP, few enough that a group's edge MLPs stay below the rows at
/// which a workspace hands half of them to the second core (busy already
/// with its own share of the candidates).
const LANE_PARTICLES: usize = 320;

/// A problem's system copied `lanes` times into one graph.
pub(crate) struct Lanes {
    /// Copies per group.
    pub width: usize,
    graph: Graph,
    start: State,
}

impl Lanes {
    /// The lanes for `problem`, or `None` when its candidates must run one
    /// by one (a model whose cost grows faster than its graph, contacts,
    /// bars, or a system already large enough).
    pub fn new(problem: &Problem) -> Option<Self> {
        let g = problem.graph;
        let lanes = LANE_PARTICLES / g.n().max(1);
        let linear = problem.model.steps_copies_together();
        if !linear || lanes < 2 || g.interaction_radius > 0.0 || g.n_bars() > 0 {
            return None;
        }
        Some(Lanes {
            width: lanes,
            graph: copies(g, lanes),
            start: State {
                q: problem.start.q.repeat(lanes),
                v: problem.start.v.repeat(lanes),
            },
        })
    }

    /// The costs of `group` (at most `lanes` candidates of equal steps).
    pub fn costs(&self, problem: &Problem, group: &[Controls]) -> Result<Vec<f64>, PlanError> {
        match self.together(problem, group) {
            Some(costs) => Ok(costs),
            None => group.iter().map(|c| problem.cost_of(c)).collect(),
        }
    }

    /// The costs of a full group of equal steps from one joined rollout;
    /// `None` for a short or mixed group, a diverged copy or a graph the
    /// model refuses at this size (each candidate alone then says which,
    /// and costs +∞ or errs as before).
    fn together(&self, problem: &Problem, group: &[Controls]) -> Option<Vec<f64>> {
        let steps = group.first()?.steps;
        if group.len() != self.width || group.iter().any(|c| c.steps != steps) {
            return None;
        }
        let (driven, g) = (problem.driven(), problem.graph);
        let drives: Vec<Drive> = group
            .iter()
            .map(|c| c.drive(&driven, g.dim, problem.start, problem.timing))
            .collect();
        let timing = problem.timing.with_horizon(steps);
        let states = problem
            .model
            .rollout_driven(&self.graph, &self.start, timing, &joined(&drives, g.n()))
            .ok()?;
        let cost = |(k, c): (usize, &Controls)| {
            let own = lane(&states, k, g.ndof());
            problem.cost.of(&own, g.dim, c, problem.timing)
        };
        Some(group.iter().enumerate().map(cost).collect())
    }
}

/// `copies` copies of `g`: copy `c`'s particle `i` is `c · n + i`, its anchor
/// `k` is `c · anchors + k`.
fn copies(g: &Graph, copies: usize) -> Graph {
    let (n, na) = (g.n(), g.anchors.len());
    let edges = (0..copies)
        .flat_map(|c| {
            g.edges.iter().map(move |e| Edge {
                a: e.a + c * n,
                b: match e.b {
                    Endpoint::Particle(b) => Endpoint::Particle(b + c * n),
                    Endpoint::Anchor(k) => Endpoint::Anchor(k + c * na),
                },
                ..*e
            })
        })
        .collect();
    Graph {
        dim: g.dim,
        types: g.types.repeat(copies),
        masses: g.masses.repeat(copies),
        edges,
        anchors: (0..copies)
            .flat_map(|_| g.anchors.iter().cloned())
            .collect(),
        interaction_radius: g.interaction_radius,
        kinematic: g.kinematic.repeat(copies),
    }
}

/// One drive of every copy's driven particles, copy by copy.
fn joined(drives: &[Drive], n: usize) -> Drive {
    let first = &drives[0];
    let particles = (0..drives.len())
        .flat_map(|c| first.particles.iter().map(move |&i| i + c * n))
        .collect();
    let rows = |pick: fn(&Drive) -> &Vec<Vec<f64>>| -> Vec<Vec<f64>> {
        (0..pick(first).len())
            .map(|k| {
                drives
                    .iter()
                    .flat_map(|d| pick(d)[k].iter().copied())
                    .collect()
            })
            .collect()
    };
    Drive {
        particles,
        dim: first.dim,
        q: rows(|d| &d.q),
        v: rows(|d| &d.v),
    }
}

/// Copy `k`'s states out of the joined rollout's (`ndof` numbers a copy).
fn lane(states: &[State], k: usize, ndof: usize) -> Vec<State> {
    let r = k * ndof..(k + 1) * ndof;
    states
        .iter()
        .map(|s| State {
            q: s.q[r.clone()].to_vec(),
            v: s.v[r.clone()].to_vec(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::Timing;
    use crate::physics::{SystemConfig, SystemKind};
    use crate::plan::{Cost, CostKind};

    /// Copies conserve the graph: counts, and every copy's edges within it.
    #[test]
    fn copies_keep_each_copy_to_itself() {
        let cfg = SystemConfig::new(SystemKind::Pendulum, 4);
        let g = cfg.graph();
        let u = copies(&g, 3);
        assert_eq!(u.n(), 3 * g.n());
        assert_eq!(u.edges.len(), 3 * g.edges.len());
        assert_eq!(u.anchors.len(), 3 * g.anchors.len());
        for (k, e) in u.edges.iter().enumerate() {
            let c = k / g.edges.len();
            assert_eq!(e.a / g.n(), c, "edge {k} leaves its copy");
            match e.b {
                Endpoint::Particle(b) => assert_eq!(b / g.n(), c),
                Endpoint::Anchor(a) => assert_eq!(a / g.anchors.len(), c),
            }
        }
    }

    /// The held chain's candidates cost the same in lanes as one by one (the
    /// copies do not see each other): for the exact simulator and for an
    /// MCGNODE on the kernel.
    #[test]
    fn lanes_cost_what_one_by_one_costs() {
        let cfg = SystemConfig::new(SystemKind::HeldChain, 9);
        let g = cfg.graph();
        let start = cfg.start_for(&g, 5, 0);
        let (_, net) = crate::testing::random_model(crate::gnode::Variant::Mcgnode, &g, 3)
            .expect("a random MCGNODE");
        let truth = crate::models::truth::truth(SystemKind::HeldChain);
        for model in [truth.as_ref(), &net as &dyn crate::dynamics::Dynamics] {
            same_costs(model, &cfg, &g, &start);
        }
    }

    fn same_costs(
        model: &dyn crate::dynamics::Dynamics,
        cfg: &SystemConfig,
        g: &Graph,
        start: &State,
    ) {
        let problem = Problem {
            model,
            graph: g,
            start,
            timing: Timing::of_step(cfg.dt, 4, 3),
            cost: Cost {
                kind: CostKind::Along,
                particles: vec![8],
                targets: vec![1.0, -8.0],
                effort: 1e-3,
                speed: 0.1,
            },
            max_speed: 1.0,
        };
        let alone = Problem {
            model: &crate::dynamics::Still,
            ..problem
        };
        assert!(
            Lanes::new(&alone).is_none(),
            "a model that does not say its cost is linear in copies has no lanes"
        );
        let problem = Problem { model, ..alone };
        let lanes = Lanes::new(&problem).expect("a chain without contacts or bars has lanes");
        let width = problem.width();
        let group: Vec<Controls> = (0..lanes.width)
            .map(|k| {
                let u = (0..3 * width).map(|j| ((k * 7 + j) as f64).sin() * 0.4);
                Controls {
                    steps: 3,
                    width,
                    u: u.collect(),
                }
            })
            .collect();
        let together = lanes
            .together(&problem, &group)
            .expect("the joined rollout runs");
        for (c, t) in group.iter().zip(&together) {
            let alone = problem.cost_of(c).expect("one");
            assert!(
                (alone - t).abs() <= 1e-9 * alone.abs().max(1e-12),
                "lane cost {t} vs alone {alone}"
            );
        }
        assert!(
            together.windows(2).any(|w| w[0] != w[1]),
            "candidates differ"
        );
        assert!(together.iter().all(|c| c.is_finite()), "{together:?}");
    }
}
