//! The paper's systems (spring rings, n-pendulums and a peridynamic solid):
//! their graphs and random initial states (their ground-truth trajectories:
//! `trajectories.rs`).
//!
//! The peridynamic solid is bond-based peridynamics on a simple-cubic lattice:
//! every pair of particles closer than the horizon δ =
//! [`PERIDYNAMIC_HORIZON`]·r0 in the reference configuration is a bond, and a
//! bond of reference vector ξ and micromodulus c pulls with c·s, s =
//! (|η+ξ| − |ξ|)/|ξ| its stretch. That is exactly a spring of rest length |ξ|
//! and stiffness c/|ξ|, so the solid is an ordinary spring [`Graph`] and the
//! one simulator, Hamiltonian and models all apply unchanged.

use std::f64::consts::PI;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::drive::Drive;
use super::scenes::{self, SceneSpec};
use super::{Field, PhysicsError, SystemKind};
use crate::system::{Edge, EdgeKind, Endpoint, Graph, State, SystemError};

/// Peridynamic horizon δ in units of the lattice spacing r0. 1.5 bonds each
/// particle to its 6 face neighbours (|ξ| = r0) and 12 face diagonals
/// (|ξ| = √2·r0) but not to the body diagonals (√3·r0 > 1.5·r0): the
/// smallest horizon whose bonds resist shear, so the cube holds its shape.
pub const PERIDYNAMIC_HORIZON: f64 = 1.5;

/// k when `n` = k³ with k ≥ 2: the side of a peridynamic cube.
fn cube_side(n: usize) -> Option<usize> {
    let k = (n as f64).cbrt().round() as usize;
    (k >= 2 && k.checked_pow(3) == Some(n)).then_some(k)
}

/// The side of the smallest cube holding `n` lattice sites (at least 1).
fn enclosing_side(n: usize) -> usize {
    let mut k = ((n as f64).cbrt().floor() as usize).max(1);
    while k.saturating_pow(3) < n {
        k += 1;
    }
    k
}

/// Everything needed to generate trajectories of one system.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SystemConfig {
    /// Spring ring, pendulum chain or peridynamic solid.
    pub kind: SystemKind,
    /// Number of particles (balls, bobs or lattice sites; a cube k³ for a
    /// peridynamic solid).
    pub particles: usize,
    /// Spatial dimension, 2 or 3 (always 3 for a peridynamic solid).
    pub dim: usize,
    /// Spring stiffness k (peridynamic: the stiffness of a nearest-neighbour
    /// bond, micromodulus c = k·r0).
    pub stiffness: f64,
    /// Spring rest length r0 (peridynamic: the lattice spacing).
    pub rest_length: f64,
    /// Pendulum bar length l.
    pub bar_length: f64,
    /// Mass of every particle.
    pub mass: f64,
    /// Gravity, drag and external force.
    pub field: Field,
    /// Integration time step.
    pub dt: f64,
    /// Integration steps between saved states.
    pub save_every: usize,
    /// Saved states per trajectory (including the initial one).
    pub states: usize,
    /// Interaction radius R of contacts (0: fixed edges only; the systems that
    /// touch need it). Absent from records written before it existed.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub interaction_radius: f64,
    /// Contact stiffness k_c of the soft-sphere potential ½ k_c (R − r)².
    #[serde(default, skip_serializing_if = "is_zero")]
    pub contact_stiffness: f64,
    /// Factor on every start's velocities (1: the system's own scale; held-out
    /// data outside a model's training range use more). Absent from records
    /// written before it existed, and when 1.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub velocity_scale: f64,
}

fn one() -> f64 {
    1.0
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde passes a reference
fn is_one(x: &f64) -> bool {
    *x == 1.0
}

/// Serde's test for leaving an unused contact parameter out, so records of the
/// paper's systems read and write as before.
#[allow(clippy::trivially_copy_pass_by_ref)] // serde passes a reference
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl SystemConfig {
    /// The paper's setup: unit k, r0, l and m; pendulum g = 10, dt = 1e-5,
    /// saved every 1000 steps; spring and peridynamic g = 0, dt = 1e-3, saved
    /// every 100 steps; 100 saved states; no drag or external force; 2D
    /// ([`SystemKind::default_dim`]: 3D for the peridynamic solid).
    ///
    /// The systems that touch (`SystemConfig::contact_defaults`): soft
    /// spheres R = 1, k_c = 1000, g = 1, dt 1e-3 every 100 steps; colliding
    /// lattices spacing 1, spring k = 10, R = 1, k_c = 100, no field, dt 1e-3
    /// every 100; falling chain bars of 1, R = 0.5, k_c = 1e4, g = 10, dt 1e-4
    /// every 100 steps; held chain springs of rest 1 and k = 500 (the top
    /// one stretched 0.2 by ten links), g = 10, dt 1e-3 every 100 steps, its
    /// gripper on a random smooth path ([`SystemConfig::drive_for`]).
    /// `particles` counts the free particles (balls, sites of both lattices,
    /// chain links); walls, floors and grippers are added to them.
    pub fn new(kind: SystemKind, particles: usize) -> Self {
        let (gravity, dt, save_every) = match kind {
            SystemKind::Spring
            | SystemKind::Peridynamic
            | SystemKind::CollidingLattices
            | SystemKind::PeriodicSpheres => (0.0, 1e-3, 100),
            SystemKind::Pendulum => (10.0, 1e-5, 1000),
            SystemKind::SoftSpheres => (1.0, 1e-3, 100),
            SystemKind::FallingChain => (10.0, 1e-4, 100),
            SystemKind::HeldChain => (10.0, 1e-3, 100),
        };
        let (stiffness, interaction_radius, contact_stiffness) = Self::contact_defaults(kind);
        SystemConfig {
            kind,
            particles,
            dim: kind.default_dim(),
            stiffness,
            rest_length: 1.0,
            bar_length: 1.0,
            mass: 1.0,
            field: Field {
                gravity,
                drag: 0.0,
                force: vec![],
            },
            dt,
            save_every,
            states: 100,
            interaction_radius,
            contact_stiffness,
            velocity_scale: 1.0,
        }
    }

    /// Spring stiffness, interaction radius and contact stiffness of `kind`
    /// by default (see [`SystemConfig::new`]).
    fn contact_defaults(kind: SystemKind) -> (f64, f64, f64) {
        match kind {
            SystemKind::Spring | SystemKind::Pendulum | SystemKind::Peridynamic => (1.0, 0.0, 0.0),
            SystemKind::SoftSpheres | SystemKind::PeriodicSpheres => (1.0, 1.0, 1000.0),
            SystemKind::CollidingLattices => (10.0, 1.0, 100.0),
            SystemKind::FallingChain => (1.0, 0.5, 1e4),
            SystemKind::HeldChain => (500.0, 0.0, 0.0),
        }
    }

    /// What the scenes of [`scenes`] are built from.
    fn scene(&self) -> SceneSpec {
        SceneSpec {
            free: self.particles,
            dim: self.dim,
            radius: self.interaction_radius,
            stiffness: self.stiffness,
            spacing: self.rest_length,
            bar_length: self.bar_length,
            mass: self.mass,
            gravity: self.field.gravity,
        }
    }

    /// Checks every parameter; the error names the offending one.
    pub fn validate(&self) -> Result<(), PhysicsError> {
        let min = match self.kind {
            SystemKind::Spring | SystemKind::FallingChain | SystemKind::PeriodicSpheres => 2,
            SystemKind::HeldChain | SystemKind::Pendulum | SystemKind::SoftSpheres => 1,
            SystemKind::Peridynamic => {
                if cube_side(self.particles).is_none() {
                    return Err(PhysicsError::NotACube(self.particles));
                }
                if self.dim != 3 {
                    return Err(PhysicsError::SolidDimension(self.dim));
                }
                8
            }
            SystemKind::CollidingLattices => {
                if scenes::lattice_side(self.particles, self.dim).is_none() {
                    return Err(PhysicsError::NotTwoLattices {
                        particles: self.particles,
                        dim: self.dim,
                    });
                }
                8
            }
        };
        if self.particles < min {
            return Err(PhysicsError::TooFewParticles {
                kind: self.kind,
                min,
                got: self.particles,
            });
        }
        if self.dim != 2 && self.dim != 3 {
            return Err(SystemError::Dimension(self.dim).into());
        }
        let positive = [
            ("stiffness", self.stiffness),
            ("rest_length", self.rest_length),
            ("bar_length", self.bar_length),
            ("mass", self.mass),
            ("dt", self.dt),
            ("velocity_scale", self.velocity_scale),
        ];
        for (name, x) in positive {
            if !(x.is_finite() && x > 0.0) {
                return Err(PhysicsError::NotPositive { name, value: x });
            }
        }
        self.validate_contacts()?;
        if self.save_every == 0 {
            return Err(PhysicsError::AtLeastOne("save_every"));
        }
        if self.states == 0 {
            return Err(PhysicsError::AtLeastOne("states"));
        }
        self.field.validate(self.dim)
    }

    /// The contact parameters: finite and ≥ 0, and positive for the systems
    /// that touch.
    fn validate_contacts(&self) -> Result<(), PhysicsError> {
        let contact = [
            ("interaction_radius", self.interaction_radius),
            ("contact_stiffness", self.contact_stiffness),
        ];
        for (name, x) in contact {
            let ok = if self.kind.has_contacts() {
                x.is_finite() && x > 0.0
            } else {
                x.is_finite() && x >= 0.0
            };
            if !ok {
                return Err(PhysicsError::ContactParameter {
                    name,
                    value: x,
                    kind: self.kind,
                });
            }
        }
        Ok(())
    }

    /// The system's graph. Spring: a ring of springs i–(i+1 mod n) (a single
    /// spring for n = 2). Pendulum: particle 0 barred to anchor 0 at the
    /// origin, then bars (i−1)–i. All particle types are 0.
    ///
    /// Peridynamic (3D whatever `dim` says): a simple-cubic lattice of k×k×k
    /// sites (n = k³) with spacing r0, centred at the origin, particle
    /// i = x + k·(y + k·z) at ((x, y, z) − (k−1)/2)·r0. A bond joins every pair
    /// whose reference distance |ξ| ≤ δ = [`PERIDYNAMIC_HORIZON`]·r0 (face
    /// neighbours and face diagonals: 780 bonds for k = 5), as a spring of rest
    /// length |ξ| and stiffness c/|ξ| with micromodulus c = k_s·r0, so a
    /// nearest-neighbour bond has stiffness k_s = `stiffness` and a diagonal
    /// one k_s/√2. Bonds are listed with a < b. No anchors. A particle count
    /// that is not a cube (rejected by [`SystemConfig::validate`]) fills the
    /// first n sites of the smallest enclosing cube.
    ///
    /// The systems that touch are described in `scenes`. Every graph has
    /// the configuration's interaction radius (0 for the paper's systems).
    pub fn graph(&self) -> Graph {
        let n = self.particles;
        let mut edges = vec![];
        let mut anchors = vec![];
        let mut dim = self.dim;
        match self.kind {
            SystemKind::Spring => {
                let ring = if n >= 3 { n } else { n.saturating_sub(1) };
                for i in 0..ring {
                    edges.push(Edge {
                        a: i,
                        b: Endpoint::Particle((i + 1) % n),
                        kind: EdgeKind::Spring,
                        rest_length: self.rest_length,
                        stiffness: self.stiffness,
                    });
                }
            }
            SystemKind::Pendulum => {
                anchors.push(vec![0.0; self.dim]);
                for i in 0..n {
                    edges.push(Edge {
                        a: i,
                        b: if i == 0 {
                            Endpoint::Anchor(0)
                        } else {
                            Endpoint::Particle(i - 1)
                        },
                        kind: EdgeKind::Bar,
                        rest_length: self.bar_length,
                        stiffness: 0.0,
                    });
                }
            }
            SystemKind::Peridynamic => {
                dim = 3;
                edges = self.peridynamic_bonds();
            }
            SystemKind::SoftSpheres => return scenes::soft_spheres_graph(&self.scene()),
            SystemKind::PeriodicSpheres => return scenes::periodic_spheres_graph(&self.scene()),
            SystemKind::CollidingLattices => {
                return scenes::colliding_lattices_graph(&self.scene())
            }
            SystemKind::FallingChain => return scenes::falling_chain_graph(&self.scene()),
            SystemKind::HeldChain => return scenes::held_chain_graph(&self.scene()),
        }
        Graph {
            dim,
            types: vec![0; n],
            masses: vec![self.mass; n],
            edges,
            anchors,
            interaction_radius: self.interaction_radius,
            kinematic: vec![],
            periodic_box: None,
        }
    }

    /// A random initial state for `graph` (normally `self.graph()`).
    ///
    /// Spring: a regular polygon of side r0 (two particles: a segment of length
    /// r0) centred at the origin and randomly rotated in the xy-plane; every
    /// position coordinate (z too, in 3D) perturbed by U(−0.2, 0.2)·r0; every
    /// velocity component U(−0.5, 0.5)·r0·√(k/m), then the mean velocity is
    /// removed so the total momentum is zero.
    ///
    /// Pendulum: each bar, walked out from the anchor, points at an angle
    /// θ ~ U(−π/2, π/2) from straight down (3D: polar angle from −y
    /// U(0, π/2), azimuth U(0, 2π)) and turns relative to its parent at
    /// ω ~ U(−0.5, 0.5)·√(g/l) (1 rad/s scale when g = 0); in 3D the relative
    /// velocity is a random vector of that scale projected perpendicular to the
    /// bar. Velocities are thus consistent with the bars (A q̇ = 0). Works for
    /// tree-shaped bar graphs; particles not reached from an anchor stay at
    /// the origin at rest.
    ///
    /// Peridynamic: isotropic compression, then release. The reference
    /// lattice is scaled by (1 − ε), ε ~ U(0.02, 0.08) per trajectory, and
    /// every coordinate perturbed by U(−0.01, 0.01)·r0; every velocity
    /// component is U(−0.05, 0.05)·r0·√(k/m), the mass-weighted mean is
    /// removed and a common drift with components U(−0.01, 0.01)·r0·√(k/m)
    /// added, so the total momentum is small but not zero (the paper remarks
    /// on these systems' low momentum).
    pub fn initial_state(&self, graph: &Graph, rng: &mut impl Rng) -> State {
        match self.kind {
            SystemKind::Spring => self.spring_start(graph, rng),
            SystemKind::Pendulum => self.pendulum_start(graph, rng),
            SystemKind::Peridynamic => self.peridynamic_start(graph, rng),
            SystemKind::SoftSpheres => scenes::soft_spheres_start(&self.scene(), graph, rng),
            SystemKind::PeriodicSpheres => {
                scenes::periodic_spheres_start(&self.scene(), graph, rng)
            }
            SystemKind::CollidingLattices => {
                scenes::colliding_lattices_start(&self.scene(), graph, rng)
            }
            SystemKind::FallingChain => scenes::falling_chain_start(&self.scene(), graph, rng),
            SystemKind::HeldChain => scenes::held_chain_start(&self.scene(), graph, rng),
        }
    }

    /// Reference position of lattice site `i` of a cube of side `k`.
    fn lattice_site(&self, i: usize, k: usize) -> [f64; 3] {
        let half = (k as f64 - 1.0) / 2.0;
        let idx = [i % k, (i / k) % k, i / (k * k)];
        idx.map(|x| (x as f64 - half) * self.rest_length)
    }

    /// The bonds of [`SystemConfig::graph`] for a peridynamic solid.
    fn peridynamic_bonds(&self) -> Vec<Edge> {
        let n = self.particles;
        let k = enclosing_side(n);
        let r0 = self.rest_length;
        let micromodulus = self.stiffness * r0;
        // Integer offsets within the horizon, in lattice units.
        let reach = PERIDYNAMIC_HORIZON.floor() as i64;
        let mut offsets = vec![];
        for dz in -reach..=reach {
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let d2 = dx * dx + dy * dy + dz * dz;
                    // Only offsets to a higher index, so each bond is listed
                    // once; the small slack keeps |ξ| = δ exactly inside.
                    let forward = (dz, dy, dx) > (0, 0, 0);
                    if forward && (d2 as f64) <= PERIDYNAMIC_HORIZON.powi(2) + 1e-9 {
                        offsets.push((dx, dy, dz, (d2 as f64).sqrt() * r0));
                    }
                }
            }
        }
        let mut edges = vec![];
        let ki = k as i64;
        for i in 0..n {
            let (x, y, z) = ((i % k) as i64, ((i / k) % k) as i64, (i / (k * k)) as i64);
            for &(dx, dy, dz, len) in &offsets {
                let (u, v, w) = (x + dx, y + dy, z + dz);
                if !(0..ki).contains(&u) || !(0..ki).contains(&v) || !(0..ki).contains(&w) {
                    continue;
                }
                let j = (u + ki * (v + ki * w)) as usize;
                if j >= n {
                    continue;
                }
                edges.push(Edge {
                    a: i,
                    b: Endpoint::Particle(j),
                    kind: EdgeKind::Spring,
                    rest_length: len,
                    stiffness: micromodulus / len,
                });
            }
        }
        edges
    }

    fn peridynamic_start(&self, graph: &Graph, rng: &mut impl Rng) -> State {
        let (n, d) = (graph.n(), graph.dim);
        let k = enclosing_side(n);
        let r0 = self.rest_length;
        let vscale = r0 * (self.stiffness / self.mass).sqrt();
        let scale = 1.0 - rng.random_range(0.02..0.08);
        let mut q = vec![0.0; n * d];
        let mut v = vec![0.0; n * d];
        for i in 0..n {
            let site = self.lattice_site(i, k);
            for c in 0..d {
                let x = site.get(c).copied().unwrap_or(0.0);
                q[i * d + c] = scale * x + rng.random_range(-0.01..0.01) * r0;
            }
        }
        for x in &mut v {
            *x = rng.random_range(-0.05..0.05) * vscale;
        }
        let mtot: f64 = graph.masses.iter().sum();
        for c in 0..d {
            let mean = (0..n).map(|i| graph.masses[i] * v[i * d + c]).sum::<f64>() / mtot;
            let drift = rng.random_range(-0.01..0.01) * vscale;
            for i in 0..n {
                v[i * d + c] += drift - mean;
            }
        }
        State { q, v }
    }

    fn spring_start(&self, graph: &Graph, rng: &mut impl Rng) -> State {
        let (n, d) = (graph.n(), graph.dim);
        let r0 = self.rest_length;
        let radius = match n {
            0 | 1 => 0.0,
            2 => r0 / 2.0,
            _ => r0 / (2.0 * (PI / n as f64).sin()),
        };
        let phase = rng.random_range(0.0..2.0 * PI);
        let vscale = 0.5 * r0 * (self.stiffness / self.mass).sqrt();
        let mut q = vec![0.0; n * d];
        let mut v = vec![0.0; n * d];
        for i in 0..n {
            let ang = phase + 2.0 * PI * i as f64 / n as f64;
            q[i * d] = radius * ang.cos();
            q[i * d + 1] = radius * ang.sin();
            for c in 0..d {
                q[i * d + c] += rng.random_range(-0.2..0.2) * r0;
                v[i * d + c] = rng.random_range(-1.0..1.0) * vscale;
            }
        }
        let mtot: f64 = graph.masses.iter().sum();
        for c in 0..d {
            let mean = (0..n).map(|i| graph.masses[i] * v[i * d + c]).sum::<f64>() / mtot;
            for i in 0..n {
                v[i * d + c] -= mean;
            }
        }
        State { q, v }
    }

    fn pendulum_start(&self, graph: &Graph, rng: &mut impl Rng) -> State {
        let (n, d) = (graph.n(), graph.dim);
        let mut q = vec![0.0; n * d];
        let mut v = vec![0.0; n * d];
        let mut placed = vec![false; n];
        let g = self.field.gravity.abs();
        let bars: Vec<&Edge> = graph.bars().collect();
        // Repeated sweeps place every particle whose parent is known; a chain
        // listed in order takes one sweep.
        loop {
            let mut progress = false;
            for e in &bars {
                let (child, parent) = match e.b {
                    Endpoint::Anchor(j) if !placed[e.a] => (e.a, Err(j)),
                    Endpoint::Particle(p) if placed[p] && !placed[e.a] => (e.a, Ok(p)),
                    Endpoint::Particle(p) if placed[e.a] && !placed[p] => (p, Ok(e.a)),
                    _ => continue,
                };
                let (pq, pv) = match parent {
                    Err(j) => (graph.anchors[j].clone(), vec![0.0; d]),
                    Ok(p) => (
                        q[p * d..(p + 1) * d].to_vec(),
                        v[p * d..(p + 1) * d].to_vec(),
                    ),
                };
                let l = e.rest_length;
                let wscale = if g > 0.0 { 0.5 * (g / l).sqrt() } else { 0.5 };
                let (u, w) = if d == 2 {
                    let th = rng.random_range(-PI / 2.0..PI / 2.0);
                    let om = rng.random_range(-1.0..1.0) * wscale;
                    (
                        [th.sin(), -th.cos(), 0.0],
                        [l * om * th.cos(), l * om * th.sin(), 0.0],
                    )
                } else {
                    let th = rng.random_range(0.0..PI / 2.0);
                    let ph = rng.random_range(0.0..2.0 * PI);
                    let u = [th.sin() * ph.cos(), -th.cos(), th.sin() * ph.sin()];
                    let mut w = [0.0; 3];
                    for x in &mut w {
                        *x = rng.random_range(-1.0..1.0) * wscale * l;
                    }
                    let dot: f64 = (0..3).map(|c| u[c] * w[c]).sum();
                    for c in 0..3 {
                        w[c] -= dot * u[c];
                    }
                    (u, w)
                };
                for c in 0..d {
                    q[child * d + c] = pq[c] + l * u[c];
                    v[child * d + c] = pv[c] + w[c];
                }
                placed[child] = true;
                progress = true;
            }
            if !progress {
                break;
            }
        }
        State { q, v }
    }

    /// The seed of trajectory `index` of a data set generated with `seed`:
    /// the first 8 bytes of SHA-256("mcgnode-trajectory", seed, index).
    ///
    /// Every (seed, index) pair gets its own ChaCha stream, so a test set
    /// (seed 2) shares no start with a training set (seed 1): distinct seeds
    /// collide with probability ~2⁻⁶⁴, and distinct streams draw independent
    /// continuous positions.
    pub fn trajectory_seed(seed: u64, index: usize) -> u64 {
        let mut h = Sha256::new();
        h.update(b"mcgnode-trajectory");
        h.update(seed.to_le_bytes());
        h.update((index as u64).to_le_bytes());
        let out = h.finalize();
        let mut b = [0u8; 8];
        b.copy_from_slice(&out[..8]);
        u64::from_le_bytes(b)
    }

    /// The initial state of trajectory `index` of the set generated with `seed`.
    pub fn start_for(&self, graph: &Graph, seed: u64, index: usize) -> State {
        let mut rng = ChaCha8Rng::seed_from_u64(Self::trajectory_seed(seed, index));
        let mut s = self.initial_state(graph, &mut rng);
        if self.velocity_scale != 1.0 {
            s.v.iter_mut().for_each(|v| *v *= self.velocity_scale);
        }
        s
    }

    /// The given motion of the kinematic particles of trajectory `index` of
    /// the set generated with `seed`, over the `states` saved states: the
    /// held chain's gripper path (its own random stream, so the start is
    /// drawn as without it); `None` where kinematic particles are held still.
    pub fn drive_for(&self, seed: u64, index: usize) -> Option<Drive> {
        /// Mixed into the trajectory's seed for the drive's stream ("drive").
        const DRIVE_STREAM: u64 = 0x64_7269_7665;
        let steps = self.save_every * self.states.saturating_sub(1);
        let mut rng = ChaCha8Rng::seed_from_u64(Self::trajectory_seed(seed, index) ^ DRIVE_STREAM);
        match self.kind {
            SystemKind::HeldChain => Some(scenes::held_chain_drive(
                &self.scene(),
                &mut rng,
                self.dt,
                steps,
            )),
            _ => None,
        }
    }
}
