//! Candidates stepped together: `L` copies of the system side by side as one
//! graph of `L · n` particles (no edge joins two copies), each copy driven by
//! its own candidate, rolled out in one call. The model sees one larger graph,
//! so its MLPs run on `L` times the rows per call (full SIMD tiles instead of
//! a 20-particle graph's padded ones) and the per-rollout overhead is paid
//! once per `L` candidates.
//!
//! Exact only when the copies cannot interact and cost what they are: no
//! contact radius (contacts would be found between copies lying on top of
//! each other), no bars (one constraint solve over all copies costs
//! O((L · bars)³)), and a model that says its cost is linear in copies
//! ([`Dynamics::steps_copies_together`]). Otherwise, or when a group
//! diverges or the model refuses the larger graph, the planner runs its
//! candidates one by one as before: the costs never depend on the lanes.

use crate::dynamics::{Dynamics, Spread, Timing};
use crate::physics::Drive;
use crate::system::{Edge, Endpoint, Graph, State};

/// Particles per lane group the lanes aim at: enough rows for full tiles in
/// every MLP, few enough that a group's edge MLPs stay below the rows at
/// which a workspace hands half of them to the second core (busy already
/// with its own share of the candidates).
const LANE_PARTICLES: usize = 320;

/// A system copied `width` times into one graph, from one start.
pub(crate) struct Lanes {
    /// Copies per group.
    pub width: usize,
    graph: Graph,
    start: State,
}

impl Lanes {
    /// The lanes for `graph` from `start` under `model`, or `None` when
    /// candidates must run one by one (see the module's conditions, or a
    /// system already large enough).
    pub fn new(model: &dyn Dynamics, graph: &Graph, start: &State) -> Option<Self> {
        let width = LANE_PARTICLES / graph.n().max(1);
        let exact = graph.interaction_radius == 0.0 && graph.n_bars() == 0;
        if width < 2 || !exact || !model.steps_copies_together() {
            return None;
        }
        Some(Lanes {
            width,
            graph: copies(graph, width),
            start: State {
                q: start.q.repeat(width),
                v: start.v.repeat(width),
            },
        })
    }

    /// Each copy's kept states under its own drive (`drives`: one per copy,
    /// `width` of them), from one joined rollout, with each copy's spread
    /// when `spread` asks for it (an ensemble's, [`Dynamics::rollout_spread`];
    /// else empty); `None` for another count, a diverged copy, or a graph
    /// the model refuses at this size.
    pub fn rollouts(
        &self,
        model: &dyn Dynamics,
        timing: Timing,
        drives: &[Drive],
        spread: bool,
    ) -> Option<Vec<(Vec<State>, Spread)>> {
        if drives.len() != self.width {
            return None;
        }
        let n = self.graph.n() / self.width;
        let drive = joined(drives, n);
        let (states, all) = if spread {
            model
                .rollout_spread(&self.graph, &self.start, timing, Some(&drive))
                .ok()?
        } else {
            let states = model
                .rollout_driven(&self.graph, &self.start, timing, &drive)
                .ok()?;
            (states, Vec::new())
        };
        let ndof = n * self.graph.dim;
        let part = |k: usize| -> Spread {
            all.iter()
                .map(|s| {
                    s.get(k * n..(k + 1) * n)
                        .map_or_else(Vec::new, <[f64]>::to_vec)
                })
                .collect()
        };
        Some(
            (0..self.width)
                .map(|k| (lane(&states, k, ndof), part(k)))
                .collect(),
        )
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
        periodic_box: g.periodic_box.clone(),
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
    use crate::physics::{SystemConfig, SystemKind};
    use crate::plan::Controls;

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

    /// Each copy of the held chain moves in the joined rollout as it does
    /// alone under its drive (the copies do not see each other): for the
    /// exact simulator and for an MCGNODE on the kernel; a model that does
    /// not say its cost is linear in copies gets no lanes.
    #[test]
    fn each_lane_moves_as_it_does_alone() {
        let cfg = SystemConfig::new(SystemKind::HeldChain, 9);
        let g = cfg.graph();
        let start = cfg.start_for(&g, 5, 0);
        assert!(Lanes::new(&crate::dynamics::Still, &g, &start).is_none());
        let (_, net) = crate::testing::random_model(crate::gnode::Variant::Mcgnode, &g, 3)
            .expect("a random MCGNODE");
        let truth = crate::models::truth::truth(SystemKind::HeldChain);
        for model in [truth.as_ref(), &net as &dyn Dynamics] {
            same_motion(model, &cfg, &g, &start);
        }
    }

    fn same_motion(model: &dyn Dynamics, cfg: &SystemConfig, g: &Graph, start: &State) {
        let lanes = Lanes::new(model, g, start).expect("a chain without contacts or bars");
        let timing = Timing::of_step(cfg.dt, 4, 3);
        let driven: Vec<usize> = (0..g.n()).filter(|&i| g.is_kinematic(i)).collect();
        let width = driven.len() * g.dim;
        let drives: Vec<Drive> = (0..lanes.width)
            .map(|k| {
                let u = (0..3 * width).map(|j| ((k * 7 + j) as f64).sin() * 0.4);
                let c = Controls {
                    steps: 3,
                    width,
                    u: u.collect(),
                };
                c.drive(&driven, g.dim, start, timing)
            })
            .collect();
        let together = lanes
            .rollouts(model, timing, &drives, false)
            .expect("the joined rollout runs");
        let together: Vec<Vec<State>> = together.into_iter().map(|(s, _)| s).collect();
        for (d, states) in drives.iter().zip(&together) {
            let alone = model.rollout_driven(g, start, timing, d).expect("alone");
            assert_eq!(alone.len(), states.len());
            for (a, b) in alone.iter().zip(states) {
                for (x, y) in a.q.iter().chain(&a.v).zip(b.q.iter().chain(&b.v)) {
                    assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{x} vs {y}");
                }
            }
        }
        let last = |s: &Vec<State>| s.last().map(|x| x.q.clone());
        assert_ne!(last(&together[0]), last(&together[1]), "lanes differ");
    }
}
