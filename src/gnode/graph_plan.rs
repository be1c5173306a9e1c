//! A graph prepared for learned models: directed message-passing edges and the
//! rigid-bar constraint rows A(q), Ȧq̇. Shared by the candle model and the engine
//! so both read the graph the same way.
//!
//! A graph with an interaction radius has, besides its fixed edges, contact
//! edges that depend on the state: [`GraphPlan::contacts`] finds them for
//! one state, and [`GraphPlan::directed_edges`] lays out the directed edges
//! of several states, fixed and contact, in the one order both executors use.

use crate::physics::neighbors::NeighborSearch;
use crate::system::{EdgeKind, Endpoint, Graph, PeriodicBox};

/// Edge-physics input features per edge: rest length and stiffness.
pub const EDGE_PHYSICS: usize = 2;

/// One rigid bar: particle `a` to particle `b`, or to a fixed point.
#[derive(Clone, Debug, PartialEq)]
pub struct Bar {
    /// First particle.
    pub a: usize,
    /// Second end: a particle, or an anchor point (`dim` coordinates).
    pub b: BarEnd,
}

impl Bar {
    /// Component `c` of q_a − q_b and q̇_a − q̇_b (a fixed end has zero velocity).
    #[inline]
    pub fn delta(&self, q: &[f64], v: &[f64], d: usize, c: usize) -> (f64, f64) {
        let (qb, vb) = match &self.b {
            BarEnd::Particle(b) => (q[b * d + c], v[b * d + c]),
            BarEnd::Fixed(p) => (p[c], 0.0),
        };
        (q[self.a * d + c] - qb, v[self.a * d + c] - vb)
    }
}

/// The far end of a bar.
#[derive(Clone, Debug, PartialEq)]
pub enum BarEnd {
    /// Another particle.
    Particle(usize),
    /// A fixed point.
    Fixed(Vec<f64>),
}

/// The graph as the models see it.
#[derive(Clone, Debug, PartialEq)]
pub struct GraphPlan {
    /// Particles.
    pub n: usize,
    /// Spatial dimension.
    pub dim: usize,
    /// Particle types.
    pub types: Vec<usize>,
    /// Directed edges: receiver of edge `e`. Edges `0..E` go a←b, `E..2E` b←a
    /// (the same undirected edge reversed), so `e` and `e + E` are partners.
    pub recv: Vec<usize>,
    /// Directed edges: sender of edge `e`.
    pub send: Vec<usize>,
    /// Rigid bars (rows of A).
    pub bars: Vec<Bar>,
    /// Rest length of each directed edge's spring or bar (both directions alike).
    pub rest: Vec<f64>,
    /// Stiffness of each directed edge (0 for bars).
    pub stiffness: Vec<f64>,
    /// Pairs closer than this interact through contact edges found at each
    /// state (0: the fixed edges above are all).
    pub radius: f64,
    /// Which particles are kinematic (motion given): empty = none.
    pub kinematic: Vec<bool>,
    /// The periodic box every edge vector is a minimum image in (`None`:
    /// open space).
    pub periodic: Option<PeriodicBox>,
}

/// One directed edge of a laid-out set of states: receiver and sender rows
/// (state-offset particle indices), and whether it is a contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Directed {
    /// Receiver row.
    pub recv: usize,
    /// Sender row.
    pub send: usize,
    /// Index into the plan's fixed directed edges, or `None` for a contact.
    pub fixed: Option<usize>,
}

impl GraphPlan {
    /// Prepares a (validated) graph.
    pub fn new(graph: &Graph) -> Self {
        // With a radius, contacts come from positions: a contact edge stored
        // in the graph would be counted twice.
        let edges = || {
            graph
                .particle_edges()
                .filter(|(_, _, e)| !(graph.has_contacts() && e.kind == EdgeKind::Contact))
        };
        let pairs: Vec<(usize, usize)> = edges().map(|(a, b, _)| (a, b)).collect();
        let params: Vec<(f64, f64)> = edges()
            .map(|(_, _, e)| match e.kind {
                // A contact's rest length is the radius, its stiffness 0
                // (see EdgeKind::Contact).
                EdgeKind::Spring | EdgeKind::Contact => (e.rest_length, e.stiffness),
                EdgeKind::Bar => (e.rest_length, 0.0),
            })
            .collect();
        let rest = params.iter().chain(&params).map(|p| p.0).collect();
        let stiffness = params.iter().chain(&params).map(|p| p.1).collect();
        let mut recv: Vec<usize> = pairs.iter().map(|p| p.0).collect();
        let mut send: Vec<usize> = pairs.iter().map(|p| p.1).collect();
        recv.extend(pairs.iter().map(|p| p.1));
        send.extend(pairs.iter().map(|p| p.0));
        let bars = graph
            .edges
            .iter()
            .filter(|e| e.kind == EdgeKind::Bar)
            .map(|e| Bar {
                a: e.a,
                b: match e.b {
                    Endpoint::Particle(b) => BarEnd::Particle(b),
                    Endpoint::Anchor(k) => BarEnd::Fixed(graph.anchors[k].clone()),
                },
            })
            .collect();
        Self {
            n: graph.n(),
            dim: graph.dim,
            types: graph.types.iter().map(|&t| t as usize).collect(),
            recv,
            send,
            bars,
            rest,
            stiffness,
            radius: graph.interaction_radius,
            kinematic: graph.kinematic.clone(),
            periodic: graph.periodic().cloned(),
        }
    }

    /// The period of axis `c` when the plan's box wraps it.
    #[inline]
    pub fn period(&self, c: usize) -> Option<f64> {
        self.periodic.as_ref().and_then(|b| b.period(c))
    }

    /// Whether contact edges are found at each state.
    pub fn has_contacts(&self) -> bool {
        self.radius > 0.0
    }

    /// Whether particle `i` is kinematic.
    pub fn is_kinematic(&self, i: usize) -> bool {
        self.kinematic.get(i).copied().unwrap_or(false)
    }

    /// Generalised coordinates of the particles that are not kinematic: what
    /// losses average over.
    pub fn free_ndof(&self) -> usize {
        (self.n - self.kinematic.iter().filter(|k| **k).count()) * self.dim
    }

    /// A neighbour search that leaves out the pairs of this plan's fixed edges
    /// and pairs of two kinematic particles (reusable: it allocates only
    /// while growing).
    pub fn contact_search(&self) -> NeighborSearch {
        let e = self.n_edges();
        let bonds = (0..e).map(|k| (self.recv[k], self.send[k]));
        NeighborSearch::excluding(self.n, bonds, self.kinematic.clone())
            .in_box(self.periodic.clone())
    }

    /// The contact pairs (i < j, sorted) at positions `q`, appended to `out`
    /// (none without a radius).
    pub fn contacts(&self, search: &mut NeighborSearch, q: &[f64], out: &mut Vec<(usize, usize)>) {
        if self.has_contacts() {
            out.extend_from_slice(search.search(q, self.dim, self.radius));
        }
    }

    /// [`GraphPlan::contacts`] along a rollout, whose positions move a
    /// little between calls: the same pairs, from a Verlet list
    /// ([`NeighborSearch::search_moving`]).
    pub fn contacts_moving(
        &self,
        search: &mut NeighborSearch,
        q: &[f64],
        out: &mut Vec<(usize, usize)>,
    ) {
        if self.has_contacts() {
            out.extend_from_slice(search.search_moving(q, self.dim, self.radius));
        }
    }

    /// The directed edges of `states` states side by side (state `s`'s
    /// particles at rows `s·n..`), whose contact pairs are
    /// `pairs[starts[s]..starts[s + 1]]`: first every state's edges one way
    /// (its fixed edges, then its contacts a←b), then all of them reversed in
    /// the same order, so that edge `k` and `k + half` are one pair's two
    /// directions. `visit(k, edge)` sees each in order.
    pub fn directed_edges(
        &self,
        states: usize,
        pairs: &[(usize, usize)],
        starts: &[usize],
        mut visit: impl FnMut(usize, Directed),
    ) {
        let (n, e) = (self.n, self.n_edges());
        let mut k = 0;
        for half in 0..2 {
            for s in 0..states {
                for j in half * e..(half + 1) * e {
                    let (recv, send) = (s * n + self.recv[j], s * n + self.send[j]);
                    visit(
                        k,
                        Directed {
                            recv,
                            send,
                            fixed: Some(j),
                        },
                    );
                    k += 1;
                }
                if let (Some(&a), Some(&b)) = (starts.get(s), starts.get(s + 1)) {
                    for &(i, j) in &pairs[a..b] {
                        let (recv, send) = if half == 0 { (i, j) } else { (j, i) };
                        let (recv, send) = (s * n + recv, s * n + send);
                        visit(
                            k,
                            Directed {
                                recv,
                                send,
                                fixed: None,
                            },
                        );
                        k += 1;
                    }
                }
            }
        }
    }

    /// The raw edge-physics inputs of a contact edge: the radius as its rest
    /// length, stiffness 0 (the law is learned).
    pub fn contact_physics(&self) -> [f64; EDGE_PHYSICS] {
        [self.radius, 0.0]
    }

    /// The physical inputs of directed edge `e` before scaling: rest length
    /// and stiffness. The one definition of the edge-physics features; their
    /// scales are the architecture's `edge_physics_scale`.
    pub fn edge_physics(&self, e: usize) -> [f64; EDGE_PHYSICS] {
        [self.rest[e], self.stiffness[e]]
    }

    /// Number of undirected particle edges E.
    pub fn n_edges(&self) -> usize {
        self.recv.len() / 2
    }

    /// Number of generalised coordinates.
    pub fn ndof(&self) -> usize {
        self.n * self.dim
    }

    /// Fills the dense constraint rows for one state: `a` is `k × ndof` (A(q),
    /// row r = ∂φ_r/∂q with φ_r = ½(|q_a − q_b|² − l²)) and `adq` is `k` (Ȧq̇ =
    /// |q̇_a − q̇_b|²), so that A q̈ + Ȧ q̇ = 0 along the motion.
    pub fn constraint_rows(&self, q: &[f64], v: &[f64], a: &mut [f64], adq: &mut [f64]) {
        let d = self.dim;
        let nd = self.ndof();
        a.iter_mut().for_each(|x| *x = 0.0);
        for (r, bar) in self.bars.iter().enumerate() {
            let mut s = 0.0;
            for c in 0..d {
                let (dq, dv) = bar.delta(q, v, d, c);
                a[r * nd + bar.a * d + c] = dq;
                if let BarEnd::Particle(b) = bar.b {
                    a[r * nd + b * d + c] = -dq;
                }
                s += dv * dv;
            }
            adq[r] = s;
        }
    }
}
