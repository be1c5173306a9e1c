//! The training step's second half: the loss of the forces and its seed
//! u = ∂L/∂(∂V/∂q), the tangent of the forward pass along u, and the
//! reverse pass of (values, tangents) into ∂L/∂θ.

use super::mlp::{act_reverse, mlp_dual_reverse, mlp_tangent};
use super::{differences, edge_update_inputs, node_update_inputs, room, Chunk, Net, PotentialLoss};
use crate::engine::dense::times_squareplus_grad;
use crate::engine::gather::{gather_rows, scatter_add_rows, Gather};
use crate::engine::samples::Samples;
use crate::gnode::graph_plan::GraphPlan;

impl Chunk {
    /// The loss of the forces in `f` against the targets, ∂L/∂(∂V/∂q) into
    /// `u` (times `scale`) and the log-masses' gradients into `grad` (zeroed
    /// first).
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    pub(super) fn seed(
        &mut self,
        net: &Net,
        (plan, masses): (&GraphPlan, &[f64]),
        th: &[f64],
        (samples, sel): (&Samples, &[usize]),
        scale: Option<f64>,
    ) {
        let (n, d) = (plan.n, plan.dim);
        let nodes = sel.len() * n;
        let sc = scale.unwrap_or(0.0);
        let grad = room(&mut self.grad, th.len());
        grad.fill(0.0);
        let u = room(&mut self.u, d * nodes);
        let mut sse = 0.0;
        for (s, &i) in sel.iter().enumerate() {
            // A record's rows: q, q̇, the target.
            let rec = samples.record(i).expect("packed samples");
            let (v, target) = (&rec[d * n..2 * d * n], &rec[2 * d * n..3 * d * n]);
            for (p, &ty) in plan.types.iter().enumerate() {
                let (lm, m) = (net.log_mass + ty, net.mass(th, ty));
                for c in 0..d {
                    let at = c * nodes + s * n + p;
                    let (f, tv, vv) = (self.f[at], target[c * n + p], v[c * n + p]);
                    match net.spec.loss {
                        PotentialLoss::Acceleration => {
                            let a = f / m;
                            let r = a - tv;
                            sse += r * r;
                            let ga = 2.0 * r * sc;
                            u[at] = ga / m;
                            // ∂a/∂log m = −a.
                            grad[lm] -= ga * a;
                        }
                        PotentialLoss::Hamilton => {
                            let mt = masses[p];
                            let qd = mt * vv / m;
                            let (rq, rp) = (qd - vv, f - mt * tv);
                            sse += 0.5 * (rq * rq + rp * rp);
                            u[at] = rp * sc;
                            grad[lm] -= rq * sc * qd;
                        }
                    }
                }
            }
        }
        self.sse = sse;
        // ∂L/∂f → ∂L/∂g, g = ∂V/∂q: f = −g, or through the bars' multipliers
        // (which depend on the masses too: ∂M⁻¹/∂log m = −M⁻¹).
        if plan.bars.is_empty() {
            u.iter_mut().for_each(|x| *x = -*x);
            return;
        }
        let gminv = room(&mut self.gminv, d * nodes);
        gminv.fill(0.0);
        self.bars
            .reverse(plan, &self.minv, &self.f[..d * nodes], u, gminv);
        for s in 0..sel.len() {
            for (p, &ty) in plan.types.iter().enumerate() {
                for c in 0..d {
                    grad[net.log_mass + ty] -= gminv[c * nodes + s * n + p] * self.minv[p];
                }
            }
        }
    }

    /// The tangent of the forward pass along q̇ = u (= ∂L/∂(∂V/∂q)): every
    /// latent's tangent and every MLP's hidden tangents.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    pub(super) fn tangent(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, t, rounds) = net.sizes();
        let xt = &mut self.x.t[..(t + d) * nodes];
        xt[t * nodes..].copy_from_slice(&self.u[..d * nodes]);
        let wt = room(&mut self.w.t, d * edges);
        differences(wt, &self.u[..d * nodes], &self.recv, &self.send);
        let (h, ht) = self.h[0].tangents(l * nodes);
        mlp_tangent(net.node_em(), th, xt, nodes, &mut self.apps[0], ht);
        times_squareplus_grad(ht, h);
        let (e, et) = self.e[0].tangents(l * edges);
        mlp_tangent(net.edge_em(), th, wt, edges, &mut self.apps[1], et);
        times_squareplus_grad(et, e);
        for r in 0..rounds {
            let (we, wv) = net.round(r);
            let eint = room(&mut self.ein[r].t, 3 * l * edges);
            let (et, ht) = (&self.e[r].t[..l * edges], &self.h[r].t[..l * nodes]);
            edge_update_inputs(eint, et, ht, (&self.recv, &self.send));
            let (e_new, et_new) = self.e[r + 1].tangents(l * edges);
            mlp_tangent(we, th, eint, edges, &mut self.apps[2 + 2 * r], et_new);
            times_squareplus_grad(et_new, e_new);
            let nint = room(&mut self.nin[r].t, 2 * l * nodes);
            node_update_inputs(nint, &self.h[r].t[..l * nodes], et_new, &self.recv);
            let (h_new, ht_new) = self.h[r + 1].tangents(l * nodes);
            mlp_tangent(wv, th, nint, nodes, &mut self.apps[3 + 2 * r], ht_new);
            times_squareplus_grad(ht_new, h_new);
        }
        // The readouts' hidden tangents (their output tangent, u·∂V/∂q, is
        // what the reverse pass starts from, and is not needed itself).
        let k = net.readout();
        let out = room(&mut self.energy, nodes.max(edges));
        let ht = &self.h[rounds].t[..l * nodes];
        mlp_tangent(
            &net.mlps[k],
            th,
            ht,
            nodes,
            &mut self.apps[k],
            &mut out[..nodes],
        );
        let et = &self.e[rounds].t[..l * edges];
        mlp_tangent(
            &net.mlps[k + 1],
            th,
            et,
            edges,
            &mut self.apps[k + 1],
            &mut out[..edges],
        );
    }

    /// The reverse pass of (values, tangents) from the readouts' output
    /// tangents (seeded 1: ∂L/∂θ = ∂(u·∂V/∂q)/∂θ) to every weight,
    /// accumulated into `grad`.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    pub(super) fn reverse(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, t, rounds) = net.sizes();
        let rows = nodes.max(edges);
        room(&mut self.zeros, rows).fill(0.0);
        let seed = room(&mut self.ones, rows);
        seed.fill(1.0);
        let (seed, zeros) = (&self.ones[..rows], &self.zeros[..rows]);
        let (grad, s) = (&mut self.grad[..th.len()], &mut self.s);
        let k = net.readout();
        let (gh, ght) = self.gh.both(l * nodes);
        let (h, e) = (&self.h[rounds], &self.e[rounds]);
        mlp_dual_reverse(
            &net.mlps[k],
            (th, &mut *grad),
            (&h.v[..l * nodes], &h.t[..l * nodes]),
            &self.apps[k],
            (&zeros[..nodes], &seed[..nodes], nodes),
            Some((&mut *gh, &mut *ght)),
            s,
        );
        let (ge, get) = self.ge.both(l * edges);
        mlp_dual_reverse(
            &net.mlps[k + 1],
            (th, &mut *grad),
            (&e.v[..l * edges], &e.t[..l * edges]),
            &self.apps[k + 1],
            (&zeros[..edges], &seed[..edges], edges),
            Some((&mut *ge, &mut *get)),
            s,
        );
        for r in (0..rounds).rev() {
            self.reverse_round(net, th, r, (nodes, edges));
        }
        let (gh, ght) = self.gh.both(l * nodes);
        let (ge, get) = self.ge.both(l * edges);
        let (grad, s) = (&mut self.grad[..th.len()], &mut self.s);
        let h0 = &self.h[0];
        act_reverse(&h0.v[..l * nodes], &h0.t[..l * nodes], gh, ght);
        mlp_dual_reverse(
            net.node_em(),
            (th, &mut *grad),
            (&self.x.v[..(t + d) * nodes], &self.x.t[..(t + d) * nodes]),
            &self.apps[0],
            (gh, ght, nodes),
            None,
            s,
        );
        let e0 = &self.e[0];
        act_reverse(&e0.v[..l * edges], &e0.t[..l * edges], ge, get);
        mlp_dual_reverse(
            net.edge_em(),
            (th, &mut *grad),
            (&self.w.v[..d * edges], &self.w.t[..d * edges]),
            &self.apps[1],
            (ge, get, edges),
            None,
            s,
        );
    }
    /// [`Chunk::reverse`] through round `r`: from the adjoints of its output
    /// latents (in `gh`, `ge`) to those of its inputs.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    pub(super) fn reverse_round(
        &mut self,
        net: &Net,
        th: &[f64],
        r: usize,
        (nodes, edges): (usize, usize),
    ) {
        let l = net.spec.latent;
        let (gh, ght) = self.gh.both(l * nodes);
        let (ge, get) = self.ge.both(l * edges);
        let (grad, s) = (&mut self.grad[..th.len()], &mut self.s);
        let (we, wv) = net.round(r);
        let h1 = &self.h[r + 1];
        act_reverse(&h1.v[..l * nodes], &h1.t[..l * nodes], gh, ght);
        let nin = &self.nin[r];
        let (gn, gnt) = (
            room(&mut self.gin.v, 2 * l * nodes),
            room(&mut self.gin.t, 2 * l * nodes),
        );
        mlp_dual_reverse(
            wv,
            (th, &mut *grad),
            (&nin.v[..2 * l * nodes], &nin.t[..2 * l * nodes]),
            &self.apps[3 + 2 * r],
            (gh, ght, nodes),
            Some((&mut *gn, &mut *gnt)),
            s,
        );
        gh.copy_from_slice(&gn[..l * nodes]);
        ght.copy_from_slice(&gnt[..l * nodes]);
        gather_rows(ge, &gn[l * nodes..], &self.recv, Gather::Add);
        gather_rows(get, &gnt[l * nodes..], &self.recv, Gather::Add);
        let e1 = &self.e[r + 1];
        act_reverse(&e1.v[..l * edges], &e1.t[..l * edges], ge, get);
        let ein = &self.ein[r];
        let (gn, gnt) = (
            room(&mut self.gin.v, 3 * l * edges),
            room(&mut self.gin.t, 3 * l * edges),
        );
        mlp_dual_reverse(
            we,
            (th, &mut *grad),
            (&ein.v[..3 * l * edges], &ein.t[..3 * l * edges]),
            &self.apps[2 + 2 * r],
            (ge, get, edges),
            Some((&mut *gn, &mut *gnt)),
            s,
        );
        ge.copy_from_slice(&gn[..l * edges]);
        get.copy_from_slice(&gnt[..l * edges]);
        let (ghr, ghs) = gn[l * edges..].split_at(l * edges);
        scatter_add_rows(gh, ghr, &self.recv);
        scatter_add_rows(gh, ghs, &self.send);
        let (ghr, ghs) = gnt[l * edges..].split_at(l * edges);
        scatter_add_rows(ght, ghr, &self.recv);
        scatter_add_rows(ght, ghs, &self.send);
    }
}
