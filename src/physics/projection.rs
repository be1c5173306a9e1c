//! SHAKE/RATTLE: projecting a Verlet step back onto the rigid bars, with any
//! diagonal masses. The simulator uses it with the true masses; learned
//! constrained models use it with their learned masses, so their rollouts keep
//! every bar length exact instead of drifting.

use super::constraints::Bars;
use crate::system::Graph;
use nalgebra::{DMatrix, DVector};

/// Bars of one graph, their masses and scratch buffers: steps do not allocate
/// (except for redundant bars, which fall back to SVD).
#[derive(Clone, Debug)]
pub struct Projector {
    /// The graph with the masses the projection uses.
    graph: Graph,
    bars: Bars,
    dirs_old: Vec<f64>,
    dirs_new: Vec<f64>,
    iterations: u64,
    failures: u64,
}

impl Projector {
    /// Relative bar-length tolerance of the SHAKE iteration.
    pub const TOL: f64 = 1e-13;
    /// Newton iterations allowed per step before giving up (counted in
    /// [`Projector::failures`]).
    pub const MAX_ITER: usize = 50;

    /// A projector for the bars of `graph`, weighting by `graph.masses`.
    pub fn new(graph: &Graph) -> Self {
        let bars = Bars::new(graph);
        let kd = bars.k() * graph.dim;
        Self {
            graph: graph.clone(),
            bars,
            dirs_old: vec![0.0; kd],
            dirs_new: vec![0.0; kd],
            iterations: 0,
            failures: 0,
        }
    }

    /// Whether there is anything to project.
    pub fn has_bars(&self) -> bool {
        self.bars.k() > 0
    }

    /// Remembers the bar directions at the start of a step (SHAKE moves
    /// along them).
    pub fn begin(&mut self, q: &[f64]) {
        if self.has_bars() {
            self.bars.dirs(&self.graph, q, &mut self.dirs_old);
        }
    }

    /// SHAKE: after the drift q' = q + v dt + ½a dt², Newton iterations on γ
    /// move q' −= M⁻¹A(q)ᵀγ until every bar has its length to [`Self::TOL`]
    /// (relative); the half-step velocity gets the same kick (÷ dt).
    pub fn shake(&mut self, q: &mut [f64], v_half: &mut [f64], dt: f64) {
        let (g, k) = (&self.graph, self.bars.k());
        if k == 0 {
            return;
        }
        for _ in 0..Self::MAX_ITER {
            self.bars.dirs(g, q, &mut self.dirs_new);
            let d = g.dim;
            let mut worst = 0.0_f64;
            for j in 0..k {
                let r2: f64 = self.dirs_new[j * d..(j + 1) * d]
                    .iter()
                    .map(|x| x * x)
                    .sum();
                let l = self.bars.len[j];
                worst = worst.max((r2.sqrt() - l).abs() / l);
                self.bars.rhs[j] = 0.5 * (r2 - l * l);
            }
            if worst <= Self::TOL {
                return;
            }
            // dφ/dγ = −A(q') M⁻¹ A(q)ᵀ; solve for the Newton update.
            self.iterations += 1;
            if !self.bars.solve(g, &self.dirs_new, &self.dirs_old) {
                break;
            }
            self.bars.apply_t(g, &self.dirs_old, 1.0, q);
            self.bars.apply_t(g, &self.dirs_old, 1.0 / dt, v_half);
        }
        self.failures += 1;
    }

    /// RATTLE: removes the velocity components along the bars at q,
    /// v −= M⁻¹A(q)ᵀμ with A(q) v = 0 exactly afterwards.
    pub fn rattle(&mut self, q: &[f64], v: &mut [f64]) {
        let g = &self.graph;
        if self.bars.k() == 0 {
            return;
        }
        self.bars.dirs(g, q, &mut self.dirs_new);
        for j in 0..self.bars.k() {
            self.bars.rhs[j] = self.bars.mul(g, &self.dirs_new, v, j);
        }
        if self.bars.solve(g, &self.dirs_new, &self.dirs_new) {
            self.bars.apply_t(g, &self.dirs_new, 1.0, v);
        } else {
            self.failures += 1;
        }
    }

    /// The bar Jacobian A(q), `k × n·d`: bar j's row holds d_j = q_a − q_b
    /// at a and −d_j at b (an anchored bar only at a).
    fn jacobian(&self, q: &[f64]) -> DMatrix<f64> {
        let (g, k) = (&self.graph, self.bars.k());
        let d = g.dim;
        let mut dirs = vec![0.0; k * d];
        self.bars.dirs(g, q, &mut dirs);
        let mut a = DMatrix::zeros(k, g.ndof());
        for j in 0..k {
            for c in 0..d {
                a[(j, self.bars.a[j] * d + c)] = dirs[j * d + c];
                if let Some(b) = self.bars.b[j] {
                    a[(j, b * d + c)] = -dirs[j * d + c];
                }
            }
        }
        a
    }

    /// M⁻¹ per coordinate.
    fn inv_mass(&self) -> DVector<f64> {
        let g = &self.graph;
        DVector::from_fn(g.ndof(), |i, _| 1.0 / g.masses[i / g.dim])
    }

    /// ∂L/∂q of L through a Jacobian's entries: Ā (`k × n·d`) onto each
    /// bar's direction d_j = q_a − q_b, then onto its ends, added to `gq`.
    fn scatter(&self, abar: &DMatrix<f64>, gq: &mut [f64]) {
        let d = self.graph.dim;
        for j in 0..self.bars.k() {
            let a = self.bars.a[j];
            for c in 0..d {
                let mut gd = abar[(j, a * d + c)];
                if let Some(b) = self.bars.b[j] {
                    gd -= abar[(j, b * d + c)];
                }
                gq[a * d + c] += gd;
                if let Some(b) = self.bars.b[j] {
                    gq[b * d + c] -= gd;
                }
            }
        }
    }

    /// Reverse mode through [`Projector::shake`], by the implicit function
    /// theorem at its converged solution: of the positions, `q0` those
    /// [`Projector::begin`] saw, `drifted` those before and `shaken` those
    /// after the projection (q' = q̃ + M⁻¹A(q0)ᵀγ with φ(q') = 0; the
    /// half-step velocity moved by the same ÷ dt). On entry `gq` holds ∂L/∂q'
    /// and `gv` ∂L/∂q̇'; on return `gq` holds ∂L/∂q̃ (∂L/∂ṽ is `gv`
    /// unchanged), and ∂L/∂q0 is added to `gq0`.
    pub fn shake_vjp(
        &self,
        (q0, drifted, shaken): (&[f64], &[f64], &[f64]),
        dt: f64,
        gq: &mut [f64],
        gv: &[f64],
        gq0: &mut [f64],
    ) {
        if !self.has_bars() {
            return;
        }
        let (b, c, minv) = (self.jacobian(q0), self.jacobian(shaken), self.inv_mass());
        let delta =
            DVector::from_iterator(shaken.len(), shaken.iter().zip(drifted).map(|(s, d)| s - d));
        let bmb = &b * DMatrix::from_diagonal(&minv) * b.transpose();
        let gamma = pinv_solve(&bmb, &(&b * &delta));
        let gdelta = DVector::from_iterator(gq.len(), gq.iter().zip(gv).map(|(q, v)| q + v / dt));
        let ggamma = &b * minv.component_mul(&gdelta);
        let s = &c * DMatrix::from_diagonal(&minv) * b.transpose();
        let mu = -pinv_solve(&s.transpose(), &ggamma);
        let ctmu = c.transpose() * &mu;
        for (g, x) in gq.iter_mut().zip(ctmu.iter()) {
            *g += x;
        }
        let bbar = &gamma * minv.component_mul(&(gdelta + ctmu)).transpose();
        self.scatter(&bbar, gq0);
    }

    /// Reverse mode through [`Projector::rattle`] at positions `q`, which
    /// took `v_in` to `v_out` (v' = v − M⁻¹A(q)ᵀμ, A(q)v' = 0): on entry `gv`
    /// holds ∂L/∂v', on return ∂L/∂v; ∂L/∂q is added to `gq`.
    pub fn rattle_vjp(
        &self,
        q: &[f64],
        v_in: &[f64],
        v_out: &[f64],
        gv: &mut [f64],
        gq: &mut [f64],
    ) {
        if !self.has_bars() {
            return;
        }
        let (a, minv) = (self.jacobian(q), self.inv_mass());
        let k = &a * DMatrix::from_diagonal(&minv) * a.transpose();
        let (vin, vout) = (
            DVector::from_column_slice(v_in),
            DVector::from_column_slice(v_out),
        );
        let mu = pinv_solve(&k, &(&a * (&vin - &vout)));
        let w = minv.component_mul(&DVector::from_column_slice(gv));
        let nu = pinv_solve(&k, &(&a * &w));
        let atnu = a.transpose() * &nu;
        for (g, x) in gv.iter_mut().zip(atnu.iter()) {
            *g -= x;
        }
        let abar = -(&mu * w.transpose()) - &nu * vout.transpose()
            + &mu * minv.component_mul(&atnu).transpose();
        self.scatter(&abar, gq);
    }

    /// Newton iterations SHAKE has taken in total (a cost diagnostic).
    pub fn iterations(&self) -> u64 {
        self.iterations
    }

    /// Steps whose SHAKE iteration did not converge, or whose constraint
    /// matrix could not be solved (degenerate bars). 0 for a healthy run.
    pub fn failures(&self) -> u64 {
        self.failures
    }
}

/// x = K⁻¹ b, by LU, or the minimum-norm least-squares solution for
/// redundant bars (as [`Projector::shake`]'s solve falls back to).
fn pinv_solve(k: &DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
    if let Some(x) = k.clone().lu().solve(b) {
        return x;
    }
    k.clone()
        .svd(true, true)
        .solve(b, 1e-12)
        .unwrap_or_else(|_| DVector::from_element(b.len(), f64::NAN))
}
