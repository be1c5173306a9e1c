//! A graph prepared for learned models: directed message-passing edges and the
//! rigid-bar constraint rows A(q), Ȧq̇. Shared by the candle model and the engine
//! so both read the graph the same way.

use crate::system::{EdgeKind, Endpoint, Graph};

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
}

impl GraphPlan {
    /// Prepares a (validated) graph.
    pub fn new(graph: &Graph) -> Self {
        let pairs: Vec<(usize, usize)> = graph.particle_edges().map(|(a, b, _)| (a, b)).collect();
        let params: Vec<(f64, f64)> = graph
            .particle_edges()
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
        }
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
