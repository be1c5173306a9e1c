//! The systems that touch: their graphs and random initial states.
//!
//! * soft spheres: free balls (type 0) in a closed box whose walls are rows
//!   (2D) or sheets (3D) of kinematic particles (type 1), under gravity;
//! * colliding lattices: two square/cubic spring lattices thrown at each
//!   other, nothing else acting (a closed system);
//! * falling chain: free particles joined by rigid bars, dropped onto a floor
//!   of kinematic particles (type 1).
//!
//! Contacts act between every pair closer than the interaction radius R;
//! wall and floor particles are spaced R/2, so a wall is a nearly flat
//! repulsive surface and no ball fits between two of its particles.
//! Free particles come first (indices 0..free), kinematic ones after.

use rand::Rng;

use crate::system::{Edge, EdgeKind, Endpoint, Graph, PeriodicBox, State};

/// What a scene is made of, from the system configuration.
#[derive(Clone, Copy, Debug)]
pub struct SceneSpec {
    /// Free particles (balls, lattice sites of both lattices, chain links).
    pub free: usize,
    /// 2 or 3.
    pub dim: usize,
    /// Interaction radius R.
    pub radius: f64,
    /// Spring stiffness (lattices).
    pub stiffness: f64,
    /// Lattice spacing.
    pub spacing: f64,
    /// Bar length (chain).
    pub bar_length: f64,
    /// Every particle's mass.
    pub mass: f64,
    /// Gravity (scales initial speeds where the scene falls).
    pub gravity: f64,
}

/// Wall particles per unit length: two per radius.
fn wall_step(radius: f64) -> f64 {
    radius / 2.0
}

/// Balls per side of the grid the soft spheres start on.
fn balls_per_side(free: usize, dim: usize) -> usize {
    let side = if dim == 3 {
        (free as f64).cbrt()
    } else {
        (free as f64).sqrt()
    };
    (side.ceil() as usize).max(1)
}

/// Grid spacing of the soft spheres' start: a little more than R, so they
/// start apart and collide soon.
const BALL_GAP: f64 = 1.2;

/// The soft spheres' box: inner size along each axis (x, y, z). The box is
/// twice as tall as wide, so the balls have room to fall.
fn box_size(s: &SceneSpec) -> [f64; 3] {
    let w = (balls_per_side(s.free, s.dim) as f64 + 1.0) * BALL_GAP * s.radius;
    [w, 2.0 * w, w]
}

/// Points every `step` along [0, len], both ends included.
fn ticks(len: f64, step: f64) -> Vec<f64> {
    let k = (len / step).round().max(1.0) as usize;
    // The last point is `len` itself, so the faces' tests below are exact.
    (0..=k)
        .map(|i| {
            if i == k {
                len
            } else {
                len * i as f64 / k as f64
            }
        })
        .collect()
}

/// The surface of the box [0, size] (2D: its four sides; 3D: its six faces),
/// every point once.
fn box_walls(size: [f64; 3], dim: usize, step: f64) -> Vec<[f64; 3]> {
    let t: Vec<Vec<f64>> = size.iter().map(|l| ticks(*l, step)).collect();
    let mut out = vec![];
    if dim == 2 {
        for &x in &t[0] {
            for &y in &t[1] {
                let on_edge = x == 0.0 || x == size[0] || y == 0.0 || y == size[1];
                if on_edge {
                    out.push([x, y, 0.0]);
                }
            }
        }
        return out;
    }
    for &x in &t[0] {
        for &y in &t[1] {
            for &z in &t[2] {
                let face = [x, y, z]
                    .iter()
                    .zip(size)
                    .any(|(c, l)| *c == 0.0 || *c == l);
                if face {
                    out.push([x, y, z]);
                }
            }
        }
    }
    out
}

/// A graph of `free` free particles (type 0) and the kinematic `fixed` ones
/// (type 1), with `edges` between free ones.
fn with_kinematic(s: &SceneSpec, fixed: usize, edges: Vec<Edge>) -> Graph {
    let n = s.free + fixed;
    Graph {
        dim: s.dim,
        types: (0..n).map(|i| u32::from(i >= s.free)).collect(),
        masses: vec![s.mass; n],
        edges,
        anchors: vec![],
        interaction_radius: s.radius,
        kinematic: if fixed == 0 {
            vec![]
        } else {
            (0..n).map(|i| i >= s.free).collect()
        },
        periodic_box: None,
    }
}

/// Soft spheres: `free` balls and the box's wall particles.
pub fn soft_spheres_graph(s: &SceneSpec) -> Graph {
    let walls = box_walls(box_size(s), s.dim, wall_step(s.radius)).len();
    with_kinematic(s, walls, vec![])
}

/// Soft spheres' start: balls on a grid of spacing 1.2 R in the lower half of
/// the box, each jittered by U(−0.05, 0.05)·R per coordinate, velocities
/// U(−0.5, 0.5)·√(gR) per component (√(k/m)·R/10 scale without gravity);
/// wall particles on the box's surface, at rest.
pub fn soft_spheres_start(s: &SceneSpec, graph: &Graph, rng: &mut impl Rng) -> State {
    let (d, r) = (s.dim, s.radius);
    let size = box_size(s);
    let side = balls_per_side(s.free, d);
    let vscale = if s.gravity > 0.0 {
        (s.gravity * r).sqrt()
    } else {
        0.1 * r * (s.stiffness / s.mass).sqrt()
    };
    let mut q = vec![0.0; graph.ndof()];
    let mut v = vec![0.0; graph.ndof()];
    for i in 0..s.free {
        let idx = [i % side, (i / side) % side, i / (side * side)];
        for c in 0..d {
            q[i * d + c] = (idx[c] as f64 + 1.0) * BALL_GAP * r + rng.random_range(-0.05..0.05) * r;
            v[i * d + c] = rng.random_range(-0.5..0.5) * vscale;
        }
    }
    for (k, p) in box_walls(size, d, wall_step(r)).iter().enumerate() {
        let i = s.free + k;
        q[i * d..(i + 1) * d].copy_from_slice(&p[..d]);
    }
    State { q, v }
}

/// The periodic spheres' box: `side` balls per axis, 1.2 R apart, tile it
/// exactly (at least two per axis, so that each side exceeds 2R).
fn periodic_box(s: &SceneSpec) -> PeriodicBox {
    let side = balls_per_side(s.free, s.dim).max(2) as f64;
    let w = side * BALL_GAP * s.radius;
    PeriodicBox::all_periodic(vec![0.0; s.dim], vec![w; s.dim])
}

/// Periodic spheres: `free` balls in a box periodic on every axis.
pub fn periodic_spheres_graph(s: &SceneSpec) -> Graph {
    let mut g = with_kinematic(s, 0, vec![]);
    g.periodic_box = Some(periodic_box(s));
    g
}

/// Periodic spheres' start: balls on the grid of spacing 1.2 R that tiles
/// the box (cell centres), each jittered by U(−0.05, 0.05)·R per
/// coordinate, velocities U(−0.5, 0.5)·R per unit time and component less
/// their mean (zero total momentum).
pub fn periodic_spheres_start(s: &SceneSpec, graph: &Graph, rng: &mut impl Rng) -> State {
    let (d, r) = (s.dim, s.radius);
    let side = balls_per_side(s.free, d).max(2);
    let vscale = r;
    let mut q = vec![0.0; graph.ndof()];
    let mut v = vec![0.0; graph.ndof()];
    for i in 0..s.free {
        let idx = [i % side, (i / side) % side, i / (side * side)];
        for c in 0..d {
            q[i * d + c] = (idx[c] as f64 + 0.5) * BALL_GAP * r + rng.random_range(-0.05..0.05) * r;
            v[i * d + c] = rng.random_range(-0.5..0.5) * vscale;
        }
    }
    for c in 0..d {
        let mean = (0..s.free).map(|i| v[i * d + c]).sum::<f64>() / s.free as f64;
        (0..s.free).for_each(|i| v[i * d + c] -= mean);
    }
    if let Some(b) = &graph.periodic_box {
        b.wrap(&mut q);
    }
    State { q, v }
}

/// Sites per lattice side of the colliding lattices: each lattice holds
/// free/2 = side^dim particles.
pub fn lattice_side(free: usize, dim: usize) -> Option<usize> {
    let half = free / 2;
    let side = (half as f64).powf(1.0 / dim as f64).round() as usize;
    (free % 2 == 0 && side >= 2 && side.checked_pow(dim as u32) == Some(half)).then_some(side)
}

/// The springs of one square/cubic lattice of `side`^dim sites starting at
/// index `first`: nearest neighbours (rest = spacing) and face diagonals
/// (rest = √2·spacing, stiffness k/√2, as the peridynamic solid's bonds).
fn lattice_springs(s: &SceneSpec, side: usize, first: usize) -> Vec<Edge> {
    let d = s.dim;
    let count = side.pow(d as u32);
    let coord = |i: usize| [i % side, (i / side) % side, i / (side * side)];
    let mut edges = vec![];
    for i in 0..count {
        for j in i + 1..count {
            let (a, b) = (coord(i), coord(j));
            let d2: usize = (0..d).map(|c| a[c].abs_diff(b[c]).pow(2)).sum();
            if d2 == 1 || d2 == 2 {
                let len = (d2 as f64).sqrt() * s.spacing;
                edges.push(Edge {
                    a: first + i,
                    b: Endpoint::Particle(first + j),
                    kind: EdgeKind::Spring,
                    rest_length: len,
                    stiffness: s.stiffness * s.spacing / len,
                });
            }
        }
    }
    edges
}

/// Colliding lattices: two lattices of free/2 sites each (see
/// [`lattice_side`]; the caller checks the count), no kinematic particle.
pub fn colliding_lattices_graph(s: &SceneSpec) -> Graph {
    let side = lattice_side(s.free, s.dim).unwrap_or(2);
    let half = side.pow(s.dim as u32);
    let mut edges = lattice_springs(s, side, 0);
    edges.extend(lattice_springs(s, side, half));
    let mut g = with_kinematic(s, 0, edges);
    g.types = vec![0; g.n()];
    g
}

/// Colliding lattices' start: the lattices side by side along x, a gap of 1.5
/// spacings between their faces, the second shifted across by
/// U(−0.3, 0.3) of its width; each moves towards the other at
/// U(0.2, 0.5)·spacing·√(k/m), plus a thermal U(−0.02, 0.02) of that scale per
/// component; sites jittered by U(−0.02, 0.02)·spacing.
pub fn colliding_lattices_start(s: &SceneSpec, graph: &Graph, rng: &mut impl Rng) -> State {
    let d = s.dim;
    let side = lattice_side(s.free, d).unwrap_or(2);
    let half = side.pow(d as u32);
    let a = s.spacing;
    let width = (side - 1) as f64 * a;
    let vscale = a * (s.stiffness / s.mass).sqrt();
    let speed = rng.random_range(0.2..0.5) * vscale;
    let shift: Vec<f64> = (0..d)
        .map(|_| rng.random_range(-0.3..0.3) * width)
        .collect();
    let mut q = vec![0.0; graph.ndof()];
    let mut v = vec![0.0; graph.ndof()];
    for i in 0..graph.n() {
        let (lat, k) = (i / half, i % half);
        let idx = [k % side, (k / side) % side, k / (side * side)];
        for c in 0..d {
            let mut x = idx[c] as f64 * a + rng.random_range(-0.02..0.02) * a;
            if lat == 1 {
                x += if c == 0 { width + 1.5 * a } else { shift[c] };
            }
            q[i * d + c] = x - if c == 0 { width + 0.75 * a } else { 0.0 };
            v[i * d + c] = rng.random_range(-0.02..0.02) * vscale;
        }
        v[i * d] += if lat == 0 { speed } else { -speed };
    }
    State { q, v }
}

/// Floor of the falling chain: x ∈ [−w, w] (3D also z ∈ [−2l, 2l]) at y = 0,
/// with w half the chain's length plus two bars.
fn floor_points(s: &SceneSpec) -> Vec<[f64; 3]> {
    let l = s.bar_length;
    let w = s.free as f64 * l / 2.0 + 2.0 * l;
    let step = wall_step(s.radius);
    let xs: Vec<f64> = ticks(2.0 * w, step).iter().map(|x| x - w).collect();
    if s.dim == 2 {
        return xs.iter().map(|&x| [x, 0.0, 0.0]).collect();
    }
    let zs: Vec<f64> = ticks(4.0 * l, step).iter().map(|z| z - 2.0 * l).collect();
    xs.iter()
        .flat_map(|&x| zs.iter().map(move |&z| [x, 0.0, z]))
        .collect()
}

/// Falling chain: bars (i−1)–i between the free particles and the floor.
pub fn falling_chain_graph(s: &SceneSpec) -> Graph {
    let edges = (1..s.free)
        .map(|i| Edge {
            a: i,
            b: Endpoint::Particle(i - 1),
            kind: EdgeKind::Bar,
            rest_length: s.bar_length,
            stiffness: 0.0,
        })
        .collect();
    with_kinematic(s, floor_points(s).len(), edges)
}

/// Falling chain's start: the chain laid along x, each bar tilted by
/// U(−0.3, 0.3) rad out of the horizontal (3D: also turned about y by
/// U(−0.3, 0.3)), its lowest particle one bar length above the floor, at
/// rest but for a random spin of the whole chain about z of
/// U(−0.2, 0.2)·√(g/l) (velocities consistent with the bars).
pub fn falling_chain_start(s: &SceneSpec, graph: &Graph, rng: &mut impl Rng) -> State {
    let (d, l, n) = (s.dim, s.bar_length, s.free);
    let mut pts = vec![[0.0; 3]; n];
    for i in 1..n {
        let tilt: f64 = rng.random_range(-0.3..0.3);
        let turn: f64 = if d == 3 {
            rng.random_range(-0.3..0.3)
        } else {
            0.0
        };
        let u = [tilt.cos() * turn.cos(), tilt.sin(), tilt.cos() * turn.sin()];
        for c in 0..3 {
            pts[i][c] = pts[i - 1][c] + l * u[c];
        }
    }
    let centre: Vec<f64> = (0..3)
        .map(|c| pts.iter().map(|p| p[c]).sum::<f64>() / n as f64)
        .collect();
    let low = pts.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    let spin = rng.random_range(-0.2..0.2) * (s.gravity.max(1.0) / l).sqrt();
    let mut q = vec![0.0; graph.ndof()];
    let mut v = vec![0.0; graph.ndof()];
    for (i, p) in pts.iter().enumerate() {
        let (x, y) = (p[0] - centre[0], p[1] - centre[1]);
        let pos = [x, p[1] - low + l, p[2] - centre[2]];
        // ω ẑ × r: a rigid rotation, so every bar keeps its length.
        let vel = [-spin * y, spin * x, 0.0];
        q[i * d..(i + 1) * d].copy_from_slice(&pos[..d]);
        v[i * d..(i + 1) * d].copy_from_slice(&vel[..d]);
    }
    for (k, p) in floor_points(s).iter().enumerate() {
        let i = n + k;
        q[i * d..(i + 1) * d].copy_from_slice(&p[..d]);
    }
    State { q, v }
}

/// Held chain: `free` links (type 0) joined by springs (i−1)–i of rest
/// `spacing` and stiffness `stiffness`, link 0 joined the same way to a
/// kinematic gripper (type 1, the last particle) whose motion is given: what
/// a robot holding a rope, a cable or a chain of beads sees. No contacts.
pub fn held_chain_graph(s: &SceneSpec) -> Graph {
    let gripper = s.free;
    let spring = |a: usize, b: usize| Edge {
        a,
        b: Endpoint::Particle(b),
        kind: EdgeKind::Spring,
        rest_length: s.spacing,
        stiffness: s.stiffness,
    };
    let mut edges = vec![spring(0, gripper)];
    edges.extend((1..s.free).map(|i| spring(i, i - 1)));
    with_kinematic(s, 1, edges)
}

/// Held chain's start: the gripper at the origin, the links hanging straight
/// down from it at their static equilibrium under gravity (spring i carries
/// the weight of the links below it), each link given a velocity of
/// U(−0.1, 0.1)·√(g·spacing) per component, the gripper at rest.
pub fn held_chain_start(s: &SceneSpec, graph: &Graph, rng: &mut impl Rng) -> State {
    let (d, n) = (s.dim, s.free);
    let mut q = vec![0.0; graph.ndof()];
    let mut v = vec![0.0; graph.ndof()];
    let vscale = (s.gravity.max(1.0) * s.spacing).sqrt();
    let mut y = 0.0;
    for i in 0..n {
        let below = (n - i) as f64 * s.mass * s.gravity;
        y -= s.spacing + below / s.stiffness;
        q[i * d + 1] = y;
        for c in 0..d {
            v[i * d + c] = rng.random_range(-0.1..0.1) * vscale;
        }
    }
    State { q, v }
}

/// The gripper's random smooth motion over `steps` steps of `dt`: along each
/// axis Σ_j A_j (1 − cos ω_j t) over three terms, A_j ~ U(−0.4, 0.4)·spacing,
/// ω_j ~ U(0.5, 3) rad/s, so it starts where the start put it, at rest, and
/// moves smoothly (velocities exact).
pub fn held_chain_drive(
    s: &SceneSpec,
    rng: &mut impl Rng,
    dt: f64,
    steps: usize,
) -> super::drive::Drive {
    let d = s.dim;
    let terms: Vec<[(f64, f64); 3]> = (0..d)
        .map(|_| {
            std::array::from_fn(|_| {
                (
                    rng.random_range(-0.4..0.4) * s.spacing,
                    rng.random_range(0.5..3.0),
                )
            })
        })
        .collect();
    super::drive::Drive::from_path(vec![s.free], d, dt, steps, |t, q, v| {
        for c in 0..d {
            q[c] = terms[c]
                .iter()
                .map(|(a, w)| a * (1.0 - (w * t).cos()))
                .sum();
            v[c] = terms[c].iter().map(|(a, w)| a * w * (w * t).sin()).sum();
        }
    })
}
