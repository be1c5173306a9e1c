//! The bars' constraint both ways: q̈ = M⁻¹(N − Aᵀλ) with λ from the
//! factored K = A M⁻¹ Aᵀ (forward), and its reverse pass into ∂L/∂N,
//! ∂L/∂log m and, for planning, ∂L/∂(q, q̇).

use super::{Chunk, Model};
use crate::gnode::graph_plan::BarEnd;
use crate::gnode::solve::{lu_factor_in_place, lu_solve_one};

impl Chunk {
    /// q̈ = M⁻¹(N − Aᵀλ), λ = (A M⁻¹ Aᵀ)⁻¹(A M⁻¹ N + Ȧq̇), per state, on the
    /// sparse bar incidence. K and λ are kept for the reverse pass.
    pub(super) fn constrain(&mut self, m: &Model, th: &[f64], bs: usize, kept: bool) {
        let (n, d) = (m.plan.n, m.plan.dim);
        let nodes = bs * n;
        let k = m.plan.bars.len();
        let lm = m.log_mass.expect("constrained model has masses");
        // 1/m per type, once per call (not in the per-bar loops), or kept
        // with the by-type values (the parameters have not changed).
        if !kept {
            for (t, x) in self.inv_m.iter_mut().enumerate() {
                *x = (-th[lm + t]).exp();
            }
        }
        if k == 0 {
            self.no_bars(d, bs, nodes);
            return;
        }
        for s in 0..bs {
            let ok = self.solve_bars(m, s, nodes);
            self.solved[s] = ok;
            let (base, k) = (s * n, m.plan.bars.len());
            let (dq, lam) = (&self.dq[s * k * d..], &self.lam[s * k..(s + 1) * k]);
            let (inv_m, out) = (&self.inv_m, &self.out);
            for p in 0..n {
                let mi = inv_m[m.plan.types[p]];
                for c in 0..d {
                    let mut g = out[c * nodes + base + p];
                    if ok {
                        for &(r, sr) in &m.incid[p] {
                            g -= sr * dq[r * d + c] * lam[r];
                        }
                    } else {
                        g = f64::NAN;
                    }
                    self.geq[c * nodes + base + p] = g;
                    self.acc[c * nodes + base + p] = mi * g;
                }
            }
        }
    }

    /// State `s`'s bars: q_a − q_b into `dq`, K = A M⁻¹ Aᵀ LU-factored in
    /// place into `kmat` (pivots in `piv`), and λ solved into `lam`; whether
    /// K factored (a singular K leaves q̈ NaN).
    #[inline(always)]
    #[allow(clippy::inline_always)] // one body with constrain, as it was
    fn solve_bars(&mut self, m: &Model, s: usize, nodes: usize) -> bool {
        let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
        let k = m.plan.bars.len();
        let inv_m = &self.inv_m;
        let minv = |p: usize| inv_m[m.plan.types[p]];
        let (x, out) = (&self.x, &self.out);
        let q = |row: usize, c: usize| x[(t + c) * nodes + row];
        let v = |row: usize, c: usize| x[(t + d + c) * nodes + row];
        let f = |row: usize, c: usize| out[c * nodes + row];
        let base = s * n;
        let (dq, lam) = (
            &mut self.dq[s * k * d..(s + 1) * k * d],
            &mut self.lam[s * k..(s + 1) * k],
        );
        let kmat = &mut self.kmat[s * k * k..(s + 1) * k * k];
        for (r, bar) in m.plan.bars.iter().enumerate() {
            let (mut vv, mut rhs) = (0.0, 0.0);
            let a = base + bar.a;
            for c in 0..d {
                let (qb, vb, fb) = match &bar.b {
                    BarEnd::Particle(bp) => {
                        let b = base + bp;
                        (q(b, c), v(b, c), minv(*bp) * f(b, c))
                    }
                    BarEnd::Fixed(p) => (p[c], 0.0, 0.0),
                };
                let (dqc, dvc) = (q(a, c) - qb, v(a, c) - vb);
                dq[r * d + c] = dqc;
                vv += dvc * dvc;
                rhs += dqc * (minv(bar.a) * f(a, c) - fb);
            }
            lam[r] = rhs + vv;
        }
        kmat.fill(0.0);
        for p in 0..n {
            let mi = minv(p);
            for &(r, sr) in &m.incid[p] {
                for &(r2, s2) in &m.incid[p] {
                    let dot: f64 = (0..d).map(|c| dq[r * d + c] * dq[r2 * d + c]).sum();
                    kmat[r * k + r2] += mi * sr * s2 * dot;
                }
            }
        }
        // Factored in place and kept: the reverse pass solves with the same
        // K again.
        let piv = &mut self.piv[s * k..(s + 1) * k];
        let ok = lu_factor_in_place(kmat, piv, k).is_ok();
        if ok {
            lu_solve_one(kmat, piv, lam, k);
        }
        ok
    }

    /// [`Chunk::constrain`] without bars (springs, contacts): G = N and
    /// q̈ = M⁻¹N, in row order.
    pub(super) fn no_bars(&mut self, d: usize, bs: usize, nodes: usize) {
        let (ty, inv_m) = (&self.node_ty[..nodes], &self.inv_m);
        for c in 0..d {
            let range = c * nodes..(c + 1) * nodes;
            let (f, g) = (&self.out[range.clone()], &mut self.geq[range.clone()]);
            g.copy_from_slice(f);
            for ((a, f), &y) in self.acc[range].iter_mut().zip(f).zip(ty) {
                *a = inv_m[y] * f;
            }
        }
        self.solved[..bs].fill(true);
    }

    /// Reverse pass of [`Chunk::constrain`]: ∂L/∂N into `gout`, ∂L/∂log m into `grad`.
    pub(super) fn constrain_backward(&mut self, m: &Model, th: &[f64], bs: usize) {
        let (n, d) = (m.plan.n, m.plan.dim);
        let nodes = bs * n;
        let k = m.plan.bars.len();
        let lm = m.log_mass.expect("constrained model has masses");
        // 1/m per type, once per call (not in the per-bar loops).
        for (t, x) in self.inv_m.iter_mut().enumerate() {
            *x = (-th[lm + t]).exp();
        }
        for s in 0..bs {
            let base = s * n;
            for p in 0..n {
                let (mi, row) = (self.inv_m[m.plan.types[p]], base + p);
                let mut gm = 0.0;
                for c in 0..d {
                    let ga = self.gacc[c * nodes + row];
                    self.gout[c * nodes + row] = mi * ga;
                    gm += self.geq[c * nodes + row] * ga;
                }
                self.gminv[row] = gm;
            }
            if k > 0 && self.solved[s] {
                self.bars_backward(m, s, nodes);
            }
            // None to add without parameter gradients (planning's pass).
            for p in 0..n * usize::from(!self.grad.is_empty()) {
                let mi = self.inv_m[m.plan.types[p]];
                self.grad[lm + m.plan.types[p]] -= self.gminv[base + p] * mi;
            }
        }
    }

    /// State `s`'s bars in reverse (K factored in the forward pass): λ̄ from
    /// ḡ_G, r̄hs = K⁻¹λ̄, then their terms added into ∂L/∂N (`gout`), the
    /// inverse masses' (`gminv`) and, for planning, ∂L/∂(q, q̇).
    #[inline(always)]
    #[allow(clippy::inline_always)] // one body with constrain_backward, as it was
    fn bars_backward(&mut self, m: &Model, s: usize, nodes: usize) {
        let (n, d) = (m.plan.n, m.plan.dim);
        let (k, base) = (m.plan.bars.len(), s * n);
        let inv_m = &self.inv_m;
        let minv = |p: usize| inv_m[m.plan.types[p]];
        let dq = &self.dq[s * k * d..(s + 1) * k * d];
        let lam = &self.lam[s * k..(s + 1) * k];
        // λ̄ = −A ḡ_G; r̄hs = K⁻ᵀ λ̄ (K is symmetric); K̄ = −r̄hs λᵀ.
        let rbar = &mut self.rhs[..k];
        for (r, bar) in m.plan.bars.iter().enumerate() {
            let mut x = 0.0;
            for c in 0..d {
                let mut gg = self.gout[c * nodes + base + bar.a];
                if let BarEnd::Particle(b) = bar.b {
                    gg -= self.gout[c * nodes + base + b];
                }
                x -= dq[r * d + c] * gg;
                if self.inputs {
                    // G = N − Aᵀλ: ∂/∂(q_a − q_b) = −λ_r ḡ_G.
                    self.gdq[(s * k + r) * d + c] = -lam[r] * gg;
                }
            }
            rbar[r] = x;
        }
        // K's factors from the forward pass (it solved, so they are).
        let (kf, piv) = (
            &self.kmat[s * k * k..(s + 1) * k * k],
            &self.piv[s * k..(s + 1) * k],
        );
        lu_solve_one(kf, piv, rbar, k);
        if self.inputs {
            let into = (&mut self.gdq[s * k * d..(s + 1) * k * d], &mut self.gqv[..]);
            constraint_input_grads(
                m,
                s,
                nodes,
                inv_m,
                (dq, lam, rbar),
                (&self.x, &self.out),
                into,
            );
        }
        for p in 0..n {
            let (mi, row) = (minv(p), base + p);
            let mut gm = 0.0;
            for &(r, sr) in &m.incid[p] {
                let mut dot_f = 0.0;
                for c in 0..d {
                    let dqc = dq[r * d + c];
                    self.gout[c * nodes + row] += rbar[r] * sr * mi * dqc;
                    dot_f += dqc * self.out[c * nodes + row];
                }
                gm += rbar[r] * sr * dot_f;
                for &(r2, s2) in &m.incid[p] {
                    let dot: f64 = (0..d).map(|c| dq[r * d + c] * dq[r2 * d + c]).sum();
                    gm -= rbar[r] * lam[r2] * sr * s2 * dot;
                }
            }
            self.gminv[row] += gm;
        }
    }

    /// [`Chunk::constrain_backward`] without bars, row by row in vectors
    /// where the general loop went particle by particle: the same products
    /// and sums in the same order (each row's mass term summed over the
    /// coordinates in turn, the log-mass gradients row by row), so the same
    /// bits.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside backward_graph's vector copies
    pub(super) fn no_bars_backward(&mut self, m: &Model, th: &[f64], bs: usize) {
        let (d, nodes) = (m.plan.dim, bs * m.plan.n);
        let lm = m.log_mass.expect("constrained model has masses");
        for (t, x) in self.inv_m.iter_mut().enumerate() {
            *x = (-th[lm + t]).exp();
        }
        let (ty, inv_m) = (&self.node_ty[..nodes], &self.inv_m);
        let gm = &mut self.gminv[..nodes];
        gm.fill(0.0);
        for c in 0..d {
            let range = c * nodes..(c + 1) * nodes;
            let (ga, eq) = (&self.gacc[range.clone()], &self.geq[range.clone()]);
            for ((o, &g), &y) in self.gout[range].iter_mut().zip(ga).zip(ty) {
                *o = inv_m[y] * g;
            }
            for ((x, &e), &g) in gm.iter_mut().zip(eq).zip(ga) {
                *x += e * g;
            }
        }
        // None to add without parameter gradients (planning's pass). One
        // running sum per type, in row order, apart from `grad`.
        if self.grad.is_empty() {
            return;
        }
        if let [mi] = inv_m[..] {
            let mut sum = self.grad[lm];
            for &g in gm.iter() {
                sum -= g * mi;
            }
            self.grad[lm] = sum;
            return;
        }
        let sums = &mut self.g_mass;
        sums.clear();
        sums.extend_from_slice(&self.grad[lm..lm + inv_m.len()]);
        for (&g, &y) in gm.iter().zip(ty) {
            sums[y] -= g * inv_m[y];
        }
        self.grad[lm..lm + inv_m.len()].copy_from_slice(sums);
    }
}

/// The constraint's part of ∂L/∂(q, q̇) for state `s`, once `rbar` holds
/// r̄hs = K⁻¹λ̄ and `gdq` the G term: through rhs = A M⁻¹N + Ȧq̇ and
/// K = A M⁻¹Aᵀ (K̄ = −r̄hs λᵀ), then each bar's q_a − q_b and q̇_a − q̇_b
/// onto its ends, into `gqv` (feature-major `2d × nodes`).
fn constraint_input_grads(
    m: &Model,
    s: usize,
    nodes: usize,
    inv_m: &[f64],
    (dq, lam, rbar): (&[f64], &[f64], &[f64]),
    (x, out): (&[f64], &[f64]),
    (gdq, gqv): (&mut [f64], &mut [f64]),
) {
    let (n, d, t) = (m.plan.n, m.plan.dim, m.arch.types);
    let base = s * n;
    let minv = |p: usize| inv_m[m.plan.types[p]];
    let v = |row: usize, c: usize| x[(t + d + c) * nodes + row];
    for (r, bar) in m.plan.bars.iter().enumerate() {
        let a = base + bar.a;
        for c in 0..d {
            let (fb, vb) = match bar.b {
                BarEnd::Particle(b) => (minv(b) * out[c * nodes + base + b], v(base + b, c)),
                BarEnd::Fixed(_) => (0.0, 0.0),
            };
            gdq[r * d + c] += rbar[r] * (minv(bar.a) * out[c * nodes + a] - fb);
            let gdv = 2.0 * rbar[r] * (v(a, c) - vb);
            gqv[(d + c) * nodes + a] += gdv;
            if let BarEnd::Particle(b) = bar.b {
                gqv[(d + c) * nodes + base + b] -= gdv;
            }
        }
    }
    for p in 0..n {
        let mi = minv(p);
        for &(r, sr) in &m.incid[p] {
            for &(r2, s2) in &m.incid[p] {
                let coef = -mi * sr * s2 * rbar[r] * lam[r2];
                for c in 0..d {
                    gdq[r * d + c] += coef * dq[r2 * d + c];
                    gdq[r2 * d + c] += coef * dq[r * d + c];
                }
            }
        }
    }
    for (r, bar) in m.plan.bars.iter().enumerate() {
        for c in 0..d {
            gqv[c * nodes + base + bar.a] += gdq[r * d + c];
            if let BarEnd::Particle(b) = bar.b {
                gqv[c * nodes + base + b] -= gdq[r * d + c];
            }
        }
    }
}
