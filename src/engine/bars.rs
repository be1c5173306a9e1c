//! Rigid bars on forces from a learned potential (LGN, HGN on the executor):
//! f = −g − Aᵀλ with g = ∂V/∂q and λ = (A M⁻¹ Aᵀ)⁻¹ (Ȧq̇ − A M⁻¹ g), so that
//! A q̈ + Ȧq̇ = 0 with q̈ = M⁻¹ f (as `baselines::net::bar_constrained_force`
//! writes it in candle), and the reverse pass: from ∂L/∂f to ∂L/∂g and to
//! the inverse masses. Dense rows per state (a bar touches two particles;
//! pendulums have a few bars).

use crate::gnode::graph_plan::GraphPlan;
use crate::physics::linalg::solve_in_place;
use crate::system::State;

/// Per state of a chunk: A (`k × n·d`, node-major columns) and λ, kept from
/// [`BarForce::apply`] for [`BarForce::reverse`]; scratch for the solves.
#[derive(Default)]
pub(super) struct BarForce {
    a: Vec<f64>,
    lam: Vec<f64>,
    adq: Vec<f64>,
    s: Vec<f64>,
    y: Vec<f64>,
    aty: Vec<f64>,
}

/// Column `col` (particle `col / d`, coordinate `col % d`) of state `s`'s
/// rows in a feature-major `d × nodes` buffer.
fn at(col: usize, d: usize, s: usize, n: usize, nodes: usize) -> usize {
    (col % d) * nodes + s * n + col / d
}

impl BarForce {
    /// S = A M⁻¹ Aᵀ of state `s` into `self.s`.
    fn gram(&mut self, s: usize, k: usize, nd: usize, minv: &[f64], d: usize) {
        let a = &self.a[s * k * nd..(s + 1) * k * nd];
        for r in 0..k {
            for r2 in 0..k {
                self.s[r * k + r2] = (0..nd)
                    .map(|c| a[r * nd + c] * minv[c / d] * a[r2 * nd + c])
                    .sum();
            }
        }
    }

    /// Turns the forces −g in `f` (`d × nodes`, feature-major) of `states`
    /// into the bars' constrained forces; `minv` holds each particle's
    /// inverse learned mass. Redundant bars (a singular A M⁻¹ Aᵀ) give NaN
    /// forces, not plausible ones.
    pub(super) fn apply<'s>(
        &mut self,
        plan: &GraphPlan,
        states: impl Iterator<Item = &'s State>,
        minv: &[f64],
        f: &mut [f64],
    ) {
        let (n, d, k, nd) = (plan.n, plan.dim, plan.bars.len(), plan.ndof());
        let count = f.len() / nd.max(1);
        let nodes = count * n;
        self.a.resize(count * k * nd, 0.0);
        self.lam.resize(count * k, 0.0);
        self.adq.resize(k, 0.0);
        self.s.resize(k * k, 0.0);
        for (s, st) in states.enumerate() {
            let rows = &mut self.a[s * k * nd..(s + 1) * k * nd];
            plan.constraint_rows(&st.q, &st.v, rows, &mut self.adq);
            self.gram(s, k, nd, minv, d);
            let a = &self.a[s * k * nd..(s + 1) * k * nd];
            let lam = &mut self.lam[s * k..(s + 1) * k];
            // rhs = Ȧq̇ − A M⁻¹ g, with g = −f.
            for (r, l) in lam.iter_mut().enumerate() {
                let amg: f64 = (0..nd)
                    .map(|c| a[r * nd + c] * minv[c / d] * -f[at(c, d, s, n, nodes)])
                    .sum();
                *l = self.adq[r] - amg;
            }
            if !solve_in_place(&mut self.s, lam, k) {
                lam.fill(f64::NAN);
            }
            for c in 0..nd {
                let atl: f64 = (0..k).map(|r| a[r * nd + c] * lam[r]).sum();
                f[at(c, d, s, n, nodes)] -= atl;
            }
        }
    }

    /// The reverse pass of [`BarForce::apply`]: `u` holds ∂L/∂f on entry
    /// and ∂L/∂g on return, −u + M⁻¹Aᵀy with y = (A M⁻¹ Aᵀ)⁻¹ A u; adds
    /// ∂L/∂(M⁻¹) = −(Aᵀy) ∘ f to `gminv` (per coordinate, feature-major like
    /// `f`, the constrained forces).
    pub(super) fn reverse(
        &mut self,
        plan: &GraphPlan,
        minv: &[f64],
        f: &[f64],
        u: &mut [f64],
        gminv: &mut [f64],
    ) {
        let (n, d, k, nd) = (plan.n, plan.dim, plan.bars.len(), plan.ndof());
        let count = f.len() / nd.max(1);
        let nodes = count * n;
        self.y.resize(k, 0.0);
        self.aty.resize(nd, 0.0);
        for s in 0..count {
            self.gram(s, k, nd, minv, d);
            let a = &self.a[s * k * nd..(s + 1) * k * nd];
            for (r, y) in self.y.iter_mut().enumerate() {
                *y = (0..nd)
                    .map(|c| a[r * nd + c] * u[at(c, d, s, n, nodes)])
                    .sum();
            }
            if !solve_in_place(&mut self.s, &mut self.y, k) {
                self.y.fill(f64::NAN);
            }
            for (c, v) in self.aty.iter_mut().enumerate() {
                *v = (0..k).map(|r| a[r * nd + c] * self.y[r]).sum();
            }
            for (c, &aty) in self.aty.iter().enumerate() {
                let i = at(c, d, s, n, nodes);
                gminv[i] -= aty * f[i];
                u[i] = -u[i] + minv[c / d] * aty;
            }
        }
    }
}
