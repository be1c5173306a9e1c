//! Rigid bars as holonomic constraints |q_a − q_b| = l.
//!
//! Each bar j is written φ_j = ½(|q_a − q_b|² − l²) = 0, so its row of the
//! Jacobian A is d_j = q_a − q_b at particle a and −d_j at particle b (nothing
//! for an anchor), and (Ȧ q̇)_j = |q̇_a − q̇_b|². Works for any graph of bars,
//! not only chains: the k×k systems are solved densely.

use nalgebra::{DMatrix, DVector};

use super::forces::{applied_forces, end_pos};
use super::linalg::solve_in_place;
use super::Field;
use crate::system::{EdgeKind, Endpoint, Graph, State};

/// The bars of a graph plus scratch buffers, so repeated solves do not allocate.
#[derive(Clone, Debug)]
pub(crate) struct Bars {
    /// Particle end of each bar.
    pub a: Vec<usize>,
    /// Particle index of the other end, or `None` for an anchor.
    pub b: Vec<Option<usize>>,
    /// Endpoint of the other end (to read anchor coordinates).
    pub end: Vec<Endpoint>,
    /// Bar lengths.
    pub len: Vec<f64>,
    /// Pairs (i, j, 1/m) of bars sharing particle p (i == j included),
    /// signed: the k×k matrix entry gets sign_i sign_j (d1_i · d2_j) / m_p.
    couplings: Vec<(usize, usize, f64)>,
    /// Scratch k×k matrix and its copy (for the singular fallback).
    mat: Vec<f64>,
    mat_copy: Vec<f64>,
    /// Scratch right-hand side / solution and its copy.
    pub rhs: Vec<f64>,
    rhs_copy: Vec<f64>,
}

impl Bars {
    /// Collects the bars of `graph` (in edge order).
    pub fn new(graph: &Graph) -> Self {
        let mut s = Bars {
            a: vec![],
            b: vec![],
            end: vec![],
            len: vec![],
            couplings: vec![],
            mat: vec![],
            mat_copy: vec![],
            rhs: vec![],
            rhs_copy: vec![],
        };
        for e in graph.edges.iter().filter(|e| e.kind == EdgeKind::Bar) {
            s.a.push(e.a);
            s.b.push(match e.b {
                Endpoint::Particle(j) => Some(j),
                Endpoint::Anchor(_) => None,
            });
            s.end.push(e.b);
            s.len.push(e.rest_length);
        }
        let k = s.k();
        // Particle ends of each bar with their sign in the bar's row of A.
        let ends = |j: usize| {
            let mut v = vec![(s.a[j], 1.0)];
            if let Some(b) = s.b[j] {
                v.push((b, -1.0));
            }
            v
        };
        for i in 0..k {
            for j in 0..k {
                for (p, si) in ends(i) {
                    for (q, sj) in ends(j) {
                        if p == q {
                            s.couplings.push((i, j, si * sj / graph.masses[p]));
                        }
                    }
                }
            }
        }
        s.mat = vec![0.0; k * k];
        s.mat_copy = vec![0.0; k * k];
        s.rhs = vec![0.0; k];
        s.rhs_copy = vec![0.0; k];
        s
    }

    /// Number of bars.
    pub fn k(&self) -> usize {
        self.a.len()
    }

    /// Writes d_j = q_a − q_b for every bar into `dirs` (`k * dim`).
    pub fn dirs(&self, graph: &Graph, q: &[f64], dirs: &mut [f64]) {
        let d = graph.dim;
        for j in 0..self.k() {
            let pb = end_pos(graph, q, self.end[j]);
            for c in 0..d {
                dirs[j * d + c] = q[self.a[j] * d + c] - pb[c];
            }
        }
    }

    /// (A x)_j for the Jacobian whose bar directions are `dirs`.
    pub fn mul(&self, graph: &Graph, dirs: &[f64], x: &[f64], j: usize) -> f64 {
        let d = graph.dim;
        let mut s = 0.0;
        for c in 0..d {
            let xb = self.b[j].map_or(0.0, |b| x[b * d + c]);
            s += dirs[j * d + c] * (x[self.a[j] * d + c] - xb);
        }
        s
    }

    /// x −= scale · M⁻¹ Aᵀ γ, with γ in `self.rhs`.
    pub fn apply_t(&self, graph: &Graph, dirs: &[f64], scale: f64, x: &mut [f64]) {
        let d = graph.dim;
        for j in 0..self.k() {
            let g = scale * self.rhs[j];
            let a = self.a[j];
            let ma = graph.masses[a];
            for c in 0..d {
                x[a * d + c] -= g * dirs[j * d + c] / ma;
            }
            if let Some(b) = self.b[j] {
                let mb = graph.masses[b];
                for c in 0..d {
                    x[b * d + c] += g * dirs[j * d + c] / mb;
                }
            }
        }
    }

    /// Solves (A₁ M⁻¹ A₂ᵀ) γ = rhs in place (`self.rhs` in, γ out), with A₁,
    /// A₂ given by their bar directions. Returns false if even the
    /// least-squares fallback failed.
    pub fn solve(&mut self, graph: &Graph, d1: &[f64], d2: &[f64]) -> bool {
        let k = self.k();
        let d = graph.dim;
        self.mat.fill(0.0);
        for &(i, j, w) in &self.couplings {
            let dot: f64 = (0..d).map(|c| d1[i * d + c] * d2[j * d + c]).sum();
            self.mat[i * k + j] += w * dot;
        }
        self.mat_copy.copy_from_slice(&self.mat);
        self.rhs_copy.copy_from_slice(&self.rhs);
        if solve_in_place(&mut self.mat, &mut self.rhs, k) {
            return true;
        }
        // Redundant bars: take the minimum-norm least-squares multipliers.
        let m = DMatrix::from_row_slice(k, k, &self.mat_copy);
        let b = DVector::from_column_slice(&self.rhs_copy);
        match m.svd(true, true).solve(&b, 1e-12) {
            Ok(x) => {
                self.rhs.copy_from_slice(x.as_slice());
                true
            }
            Err(_) => false,
        }
    }
}

/// Largest bar-length error max_j | |q_a − q_b| − l_j |, 0 without bars.
pub fn constraint_residual(graph: &Graph, state: &State) -> f64 {
    let d = graph.dim;
    graph
        .bars()
        .map(|e| {
            let pb = end_pos(graph, &state.q, e.b);
            let r = (0..d)
                .map(|c| (state.q[e.a * d + c] - pb[c]).powi(2))
                .sum::<f64>()
                .sqrt();
            (r - e.rest_length).abs()
        })
        .fold(0.0, f64::max)
}

/// The bar Jacobian A(q) (k × n·dim, rows as in the module doc) and Ȧq̇ (k).
pub fn bar_jacobian(graph: &Graph, state: &State) -> (DMatrix<f64>, DVector<f64>) {
    let bars = Bars::new(graph);
    let (k, d) = (bars.k(), graph.dim);
    let mut dirs = vec![0.0; k * d];
    bars.dirs(graph, &state.q, &mut dirs);
    let mut a = DMatrix::zeros(k, graph.ndof());
    let mut adot = DVector::zeros(k);
    for j in 0..k {
        for c in 0..d {
            a[(j, bars.a[j] * d + c)] = dirs[j * d + c];
            if let Some(b) = bars.b[j] {
                a[(j, b * d + c)] = -dirs[j * d + c];
            }
            let vb = bars.b[j].map_or(0.0, |b| state.v[b * d + c]);
            adot[j] += (state.v[bars.a[j] * d + c] - vb).powi(2);
        }
    }
    (a, adot)
}

/// Exact constrained acceleration at a state:
/// q̈ = M⁻¹(F − Aᵀλ), λ = (A M⁻¹ Aᵀ)⁻¹(A M⁻¹ F + Ȧq̇).
///
/// Without bars this is simply M⁻¹F. Redundant bars get least-squares
/// multipliers. The state must match the graph (see [`State::validate`]).
///
/// Kinematic particles (held still) get zero.
pub fn acceleration(graph: &Graph, field: &Field, state: &State) -> Vec<f64> {
    let mut out = vec![0.0; graph.ndof()];
    acceleration_with(graph, field, state, &mut out, |_, _| {});
    out
}

/// [`acceleration`] with forces `extra(q, f)` adds to the applied ones
/// (contacts) before the bar multipliers are solved.
pub(crate) fn acceleration_with(
    graph: &Graph,
    field: &Field,
    state: &State,
    out: &mut [f64],
    extra: impl FnOnce(&[f64], &mut [f64]),
) {
    let mut bars = Bars::new(graph);
    let mut dirs = vec![0.0; bars.k() * graph.dim];
    constrained_acceleration(graph, field, state, &mut bars, &mut dirs, out, extra);
}

/// [`acceleration`] with caller-provided scratch space.
pub(crate) fn constrained_acceleration(
    graph: &Graph,
    field: &Field,
    state: &State,
    bars: &mut Bars,
    dirs: &mut [f64],
    out: &mut [f64],
    extra: impl FnOnce(&[f64], &mut [f64]),
) {
    let d = graph.dim;
    applied_forces(graph, field, &state.q, &state.v, out);
    extra(&state.q, out);
    for (i, m) in graph.masses.iter().enumerate() {
        let held = graph.is_kinematic(i);
        for c in 0..d {
            out[i * d + c] = if held { 0.0 } else { out[i * d + c] / m };
        }
    }
    if bars.k() == 0 {
        return;
    }
    bars.dirs(graph, &state.q, dirs);
    for j in 0..bars.k() {
        let mut w2 = 0.0;
        for c in 0..d {
            let vb = bars.b[j].map_or(0.0, |b| state.v[b * d + c]);
            w2 += (state.v[bars.a[j] * d + c] - vb).powi(2);
        }
        bars.rhs[j] = bars.mul(graph, dirs, out, j) + w2;
    }
    bars.solve(graph, dirs, dirs);
    bars.apply_t(graph, dirs, 1.0, out);
}
