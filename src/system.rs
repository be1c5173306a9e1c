//! The particle system as a graph: what every other module speaks.
//!
//! A system is a set of particles (nodes) with a type, a mass, a position and a
//! velocity, joined by edges that are either springs or rigid bars. Fixed anchor
//! points (a pendulum's pivot) can be the far end of an edge. Positions and
//! velocities are stored flat, `dim` numbers per particle (2 or 3).
//!
//! Systems that touch add an interaction radius (every pair of particles
//! closer than it interacts through a contact edge rebuilt from positions,
//! `crate::physics::neighbors`) and kinematic particles (walls, floors,
//! pushers: their motion is given, never predicted). Both default to off, and
//! a graph without them behaves, serialises and validates exactly as before.

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

pub use crate::periodic::PeriodicBox;

/// What an edge is physically.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum EdgeKind {
    /// Elastic: potential ½ k (|q_a − q_b| − rest)².
    Spring,
    /// Rigid: holonomic constraint |q_a − q_b| = rest.
    Bar,
    /// Contact between two particles closer than [`Graph::interaction_radius`]:
    /// rebuilt from positions at every step, never one of a bag's fixed edges
    /// (`rest_length` is the radius, `stiffness` 0: the law is the model's or
    /// the simulator's, not the graph's).
    Contact,
}

/// One end of an edge: a particle, or a fixed anchor point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Endpoint {
    /// Index of a particle.
    Particle(usize),
    /// Index into [`Graph::anchors`].
    Anchor(usize),
}

/// An undirected edge. `a` is always a particle; `b` may be an anchor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Edge {
    /// First end, a particle.
    pub a: usize,
    /// Second end.
    pub b: Endpoint,
    /// Spring or bar.
    pub kind: EdgeKind,
    /// Rest length of a spring, or the length of a bar.
    pub rest_length: f64,
    /// Spring stiffness k (unused for bars).
    pub stiffness: f64,
}

/// The static description of a system: everything but the state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Graph {
    /// Spatial dimension, 2 or 3. 2D systems are stored with z = 0 on the wire.
    pub dim: usize,
    /// Particle type ids (index into the model's one-hot encoding).
    pub types: Vec<u32>,
    /// Particle masses.
    pub masses: Vec<f64>,
    /// Edges; each undirected edge appears once.
    pub edges: Vec<Edge>,
    /// Fixed points, `dim` coordinates each.
    pub anchors: Vec<Vec<f64>>,
    /// Pairs of particles closer than this interact through contact edges
    /// (strictly closer: a pair exactly at the radius does not); 0 = fixed
    /// edges only. Absent from files written before it existed.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub interaction_radius: f64,
    /// Which particles are kinematic (motion given, never predicted): empty =
    /// none, else one entry per particle.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub kinematic: Vec<bool>,
    /// The box whose periodic axes wrap positions and make every edge vector
    /// and contact distance a minimum image (`crate::periodic`); `None` (and
    /// absent from older files): no box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub periodic_box: Option<PeriodicBox>,
}

/// Serde's test for leaving a radius of 0 out, so that a graph without
/// contacts serialises exactly as before the field existed.
#[allow(clippy::trivially_copy_pass_by_ref)] // serde passes a reference
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Graph {
    /// Number of particles.
    pub fn n(&self) -> usize {
        self.types.len()
    }

    /// The one-hot width its particle types need: the largest type id plus
    /// one (1 without particles).
    pub fn type_count(&self) -> usize {
        self.types
            .iter()
            .map(|&t| t as usize + 1)
            .max()
            .unwrap_or(1)
    }

    /// Number of generalised coordinates, `n * dim`.
    pub fn ndof(&self) -> usize {
        self.n() * self.dim
    }

    /// Edges between two particles (the ones a GNN passes messages over).
    pub fn particle_edges(&self) -> impl Iterator<Item = (usize, usize, &Edge)> {
        self.edges.iter().filter_map(|e| match e.b {
            Endpoint::Particle(b) => Some((e.a, b, e)),
            Endpoint::Anchor(_) => None,
        })
    }

    /// Rigid bars (constraints), including bars to anchors.
    pub fn bars(&self) -> impl Iterator<Item = &Edge> {
        self.edges.iter().filter(|e| e.kind == EdgeKind::Bar)
    }

    /// Number of rigid bars, i.e. rows of the constraint matrix A(q).
    pub fn n_bars(&self) -> usize {
        self.bars().count()
    }

    /// Whether particle `i` is kinematic (its motion is given).
    pub fn is_kinematic(&self, i: usize) -> bool {
        self.kinematic.get(i).copied().unwrap_or(false)
    }

    /// Number of kinematic particles.
    pub fn n_kinematic(&self) -> usize {
        self.kinematic.iter().filter(|k| **k).count()
    }

    /// The box when one of its axes is periodic.
    pub fn periodic(&self) -> Option<&PeriodicBox> {
        self.periodic_box.as_ref().filter(|b| b.any_periodic())
    }

    /// Whether contact edges are rebuilt from positions (a radius > 0).
    pub fn has_contacts(&self) -> bool {
        self.interaction_radius > 0.0
    }

    /// The fixed edges: every edge but contacts (which are rebuilt from
    /// positions and appended after them, `crate::physics::neighbors`).
    pub fn fixed_edges(&self) -> impl Iterator<Item = &Edge> + Clone {
        self.edges.iter().filter(|e| e.kind != EdgeKind::Contact)
    }

    /// Checks indices, lengths and finiteness; the error says what is wrong.
    pub fn validate(&self) -> Result<(), SystemError> {
        if self.dim != 2 && self.dim != 3 {
            return Err(SystemError::Dimension(self.dim));
        }
        let n = self.n();
        if n == 0 {
            return Err(SystemError::NoParticles);
        }
        if self.masses.len() != n {
            return Err(SystemError::Masses {
                masses: self.masses.len(),
                particles: n,
            });
        }
        if let Some(m) = self.masses.iter().find(|m| !(m.is_finite() && **m > 0.0)) {
            return Err(SystemError::Mass(*m));
        }
        for (i, a) in self.anchors.iter().enumerate() {
            if a.len() != self.dim || a.iter().any(|x| !x.is_finite()) {
                return Err(SystemError::Anchor {
                    index: i,
                    dim: self.dim,
                });
            }
        }
        for (k, e) in self.edges.iter().enumerate() {
            if e.a >= n {
                return Err(SystemError::Edge {
                    edge: k,
                    problem: format!("particle index {} out of range (n = {n})", e.a),
                });
            }
            match e.b {
                Endpoint::Particle(b) if b >= n => {
                    return Err(SystemError::Edge {
                        edge: k,
                        problem: format!("particle index {b} out of range (n = {n})"),
                    })
                }
                Endpoint::Particle(b) if b == e.a => {
                    return Err(SystemError::Edge {
                        edge: k,
                        problem: format!("joins particle {b} to itself"),
                    })
                }
                Endpoint::Anchor(_) if e.kind == EdgeKind::Contact => {
                    return Err(SystemError::Edge {
                        edge: k,
                        problem: "a contact edge joins two particles, not an anchor".into(),
                    })
                }
                Endpoint::Anchor(b) if b >= self.anchors.len() => {
                    return Err(SystemError::Edge {
                        edge: k,
                        problem: format!(
                            "anchor index {b} out of range ({} anchors)",
                            self.anchors.len()
                        ),
                    })
                }
                _ => {}
            }
            let rest_ok = e.rest_length.is_finite() && e.rest_length >= 0.0;
            if !rest_ok || !e.stiffness.is_finite() {
                return Err(SystemError::Edge {
                    edge: k,
                    problem: "rest length must be finite and ≥ 0, stiffness finite".into(),
                });
            }
        }
        self.validate_contacts()
    }

    /// The interaction radius and the kinematic flags.
    fn validate_contacts(&self) -> Result<(), SystemError> {
        let r = self.interaction_radius;
        if !(r.is_finite() && r >= 0.0) {
            return Err(SystemError::Radius(r));
        }
        let n = self.n();
        if !self.kinematic.is_empty() && self.kinematic.len() != n {
            return Err(SystemError::Kinematic {
                flags: self.kinematic.len(),
                particles: n,
            });
        }
        self.validate_box()
    }

    /// The box: one bound and flag per axis, lengths above twice the
    /// interaction radius on periodic axes, no bars or anchors with it.
    fn validate_box(&self) -> Result<(), SystemError> {
        let Some(b) = &self.periodic_box else {
            return Ok(());
        };
        let bad = |problem: String| Err(SystemError::Box(problem));
        if b.lower.len() != self.dim || b.upper.len() != self.dim || b.periodic.len() != self.dim {
            return bad(format!(
                "give {} lower bounds, upper bounds and periodic flags (one per axis)",
                self.dim
            ));
        }
        for k in 0..self.dim {
            let (lo, hi) = (b.lower[k], b.upper[k]);
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return bad(format!(
                    "axis {k}: bounds [{lo}, {hi}] must be finite with upper > lower"
                ));
            }
            let r = self.interaction_radius;
            if b.periodic[k] && b.length(k) <= 2.0 * r {
                return bad(format!(
                    "axis {k} is {} long, not more than twice the interaction radius {r}: \
                     enlarge the box or lower the radius",
                    b.length(k)
                ));
            }
        }
        if b.any_periodic() && (self.n_bars() > 0 || !self.anchors.is_empty()) {
            return bad(
                "rigid bars and anchors are not supported in a periodic box: \
                 use springs, or make the axes non-periodic"
                    .into(),
            );
        }
        Ok(())
    }
}

/// Positions and velocities of all particles, flat (`n * dim` each).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// Positions.
    pub q: Vec<f64>,
    /// Velocities.
    pub v: Vec<f64>,
}

impl State {
    /// Checks lengths against a graph and that every number is finite.
    pub fn validate(&self, graph: &Graph) -> Result<(), SystemError> {
        let d = graph.ndof();
        if self.q.len() != d || self.v.len() != d {
            return Err(SystemError::StateShape {
                positions: self.q.len(),
                velocities: self.v.len(),
                needed: d,
            });
        }
        if self.q.iter().chain(&self.v).any(|x| !x.is_finite()) {
            return Err(SystemError::NonFinite);
        }
        Ok(())
    }

    /// Total linear momentum, `dim` components.
    pub fn momentum(&self, graph: &Graph) -> Vec<f64> {
        let mut p = vec![0.0; graph.dim];
        for (i, m) in graph.masses.iter().enumerate() {
            for (c, pc) in p.iter_mut().enumerate() {
                *pc += m * self.v[i * graph.dim + c];
            }
        }
        p
    }
}

/// A state at a time, with accelerations when they are known.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Time since the start of the trajectory, seconds.
    pub t: f64,
    /// The state.
    pub state: State,
    /// Accelerations, `n * dim`, when known.
    pub acc: Option<Vec<f64>>,
}

/// A trajectory: one graph, a sequence of samples.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    /// Trajectory id (unique within a bag).
    pub id: u32,
    /// Name of the system that produced it ("spring", "pendulum", or "" when unknown).
    pub system: String,
    /// The graph, shared by all samples.
    pub graph: Graph,
    /// The samples, in time order.
    pub samples: Vec<Sample>,
}

/// A fingerprint of a state (SHA-256 of its numbers, rounded to 1e-9), used to
/// detect test trajectories that start where training ones did.
pub fn fingerprint(s: &State) -> String {
    let mut h = Sha256::new();
    for x in s.q.iter().chain(&s.v) {
        h.update(((x * 1e9).round() as i64).to_le_bytes());
    }
    h.finalize()
        .iter()
        .take(12)
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// A graph or state that does not describe a valid system; the message says
/// what is wrong.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SystemError {
    /// The dimension is neither 2 nor 3.
    #[error("dimension must be 2 or 3, got {0}")]
    Dimension(usize),
    /// The graph has no particles.
    #[error("system has no particles")]
    NoParticles,
    /// Not one mass per particle.
    #[error("{masses} masses for {particles} particles")]
    Masses {
        /// Masses given.
        masses: usize,
        /// Particles in the graph.
        particles: usize,
    },
    /// A mass is zero, negative or not finite.
    #[error("mass {0} is not a positive finite number")]
    Mass(f64),
    /// An anchor has the wrong length or a non-finite coordinate.
    #[error("anchor {index} is not a finite {dim}-vector")]
    Anchor {
        /// Which anchor.
        index: usize,
        /// The graph's dimension.
        dim: usize,
    },
    /// An edge joins what it cannot, or has invalid parameters.
    #[error("edge {edge}: {problem}")]
    Edge {
        /// Which edge.
        edge: usize,
        /// What is wrong with it.
        problem: String,
    },
    /// A state's lengths do not fit the graph.
    #[error("state has {positions} positions and {velocities} velocities, the graph needs {needed} each")]
    StateShape {
        /// Positions given.
        positions: usize,
        /// Velocities given.
        velocities: usize,
        /// What the graph needs (n · dim).
        needed: usize,
    },
    /// A state holds NaN or infinite values.
    #[error("state contains NaN or infinite values")]
    NonFinite,
    /// The interaction radius is negative or not finite.
    #[error("interaction radius {0} must be a finite number ≥ 0 (0: fixed edges only)")]
    Radius(f64),
    /// The periodic box does not fit the graph.
    #[error("periodic box: {0}")]
    Box(String),
    /// Not one kinematic flag per particle.
    #[error(
        "{flags} kinematic flags for {particles} particles: give one per particle, \
         or none when no particle is kinematic"
    )]
    Kinematic {
        /// Flags given.
        flags: usize,
        /// Particles in the graph.
        particles: usize,
    },
}

crate::error::typed_errors!(SystemError);
