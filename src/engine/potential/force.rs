//! The potential's forward pass (every MLP's hidden activations kept) and
//! the force f = −∂V/∂q, its reverse pass with respect to the inputs.

use super::mlp::{mlp_forward, mlp_input_grad};
use super::{edge_update_inputs, node_update_inputs, room, slots, Chunk, Net};
use crate::engine::dense::{squareplus_in_place, times_squareplus_grad};
use crate::engine::gather::{gather_rows, scatter_add_rows, Gather};

impl Chunk {
    /// The forward pass, keeping every MLP's hidden activations.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    pub(super) fn forward(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, t, rounds) = net.sizes();
        slots(&mut self.apps, net.mlps.len());
        slots(&mut self.h, rounds + 1);
        slots(&mut self.e, rounds + 1);
        slots(&mut self.ein, rounds);
        slots(&mut self.nin, rounds);
        let x = &self.x.v[..(t + d) * nodes];
        let h0 = room(&mut self.h[0].v, l * nodes);
        mlp_forward(net.node_em(), th, x, nodes, &mut self.apps[0], h0);
        squareplus_in_place(h0);
        let e0 = room(&mut self.e[0].v, l * edges);
        mlp_forward(
            net.edge_em(),
            th,
            &self.w.v[..d * edges],
            edges,
            &mut self.apps[1],
            e0,
        );
        squareplus_in_place(e0);
        for r in 0..rounds {
            let (we, wv) = net.round(r);
            let ein = room(&mut self.ein[r].v, 3 * l * edges);
            let (e, h) = (&self.e[r].v[..l * edges], &self.h[r].v[..l * nodes]);
            edge_update_inputs(ein, e, h, (&self.recv, &self.send));
            let e_new = room(&mut self.e[r + 1].v, l * edges);
            mlp_forward(we, th, ein, edges, &mut self.apps[2 + 2 * r], e_new);
            squareplus_in_place(e_new);
            let nin = room(&mut self.nin[r].v, 2 * l * nodes);
            node_update_inputs(nin, &self.h[r].v[..l * nodes], e_new, &self.recv);
            let h_new = room(&mut self.h[r + 1].v, l * nodes);
            mlp_forward(wv, th, nin, nodes, &mut self.apps[3 + 2 * r], h_new);
            squareplus_in_place(h_new);
        }
        let k = net.readout();
        let energy = room(&mut self.energy, nodes.max(edges));
        let h = &self.h[rounds].v[..l * nodes];
        mlp_forward(
            &net.mlps[k],
            th,
            h,
            nodes,
            &mut self.apps[k],
            &mut energy[..nodes],
        );
        let e = &self.e[rounds].v[..l * edges];
        mlp_forward(
            &net.mlps[k + 1],
            th,
            e,
            edges,
            &mut self.apps[k + 1],
            &mut energy[..edges],
        );
    }

    /// The force f = −∂V/∂q into `f` (`d × N`): the reverse pass of V with
    /// respect to the inputs only.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies of `Chunk::run`
    pub(super) fn force(&mut self, net: &Net, th: &[f64], nodes: usize, edges: usize) {
        let (l, d, t, rounds) = net.sizes();
        let ones = room(&mut self.ones, nodes.max(edges));
        ones.fill(1.0);
        let k = net.readout();
        let s = &mut self.s;
        let gh = room(&mut self.gh.v, l * nodes);
        mlp_input_grad(
            &net.mlps[k],
            th,
            &self.apps[k],
            &ones[..nodes],
            nodes,
            gh,
            s,
        );
        let ge = room(&mut self.ge.v, l * edges);
        mlp_input_grad(
            &net.mlps[k + 1],
            th,
            &self.apps[k + 1],
            &ones[..edges],
            edges,
            ge,
            s,
        );
        for r in (0..rounds).rev() {
            let (we, wv) = net.round(r);
            times_squareplus_grad(gh, &self.h[r + 1].v[..l * nodes]);
            let gnin = room(&mut self.gin.v, 2 * l * nodes);
            mlp_input_grad(wv, th, &self.apps[3 + 2 * r], gh, nodes, gnin, s);
            let (gh_part, gagg) = gnin.split_at(l * nodes);
            gh.copy_from_slice(gh_part);
            gather_rows(ge, gagg, &self.recv, Gather::Add);
            times_squareplus_grad(ge, &self.e[r + 1].v[..l * edges]);
            let gein = room(&mut self.gin.v, 3 * l * edges);
            mlp_input_grad(we, th, &self.apps[2 + 2 * r], ge, edges, gein, s);
            let (ge_part, ghrs) = gein.split_at(l * edges);
            ge.copy_from_slice(ge_part);
            let (ghr, ghs) = ghrs.split_at(l * edges);
            scatter_add_rows(gh, ghr, &self.recv);
            scatter_add_rows(gh, ghs, &self.send);
        }
        times_squareplus_grad(gh, &self.h[0].v[..l * nodes]);
        let gx = room(&mut self.gin.t, (t + d) * nodes);
        mlp_input_grad(net.node_em(), th, &self.apps[0], gh, nodes, gx, s);
        times_squareplus_grad(ge, &self.e[0].v[..l * edges]);
        let gw = room(&mut self.gin.v, d * edges);
        mlp_input_grad(net.edge_em(), th, &self.apps[1], ge, edges, gw, s);
        // ∂V/∂q through the node inputs' q rows and the edges' w = q_recv − q_send.
        let f = room(&mut self.f, d * nodes);
        f.copy_from_slice(&gx[t * nodes..(t + d) * nodes]);
        scatter_add_rows(f, gw, &self.recv);
        gw.iter_mut().for_each(|g| *g = -*g);
        scatter_add_rows(f, gw, &self.send);
        f.iter_mut().for_each(|g| *g = -*g);
    }
}
