//! The hand-written reverse pass: NODE's flat MLP, and the graph models'
//! stages in the reverse order of [`super::forward`] (decoder, message
//! passing last round first, embeddings), after the constraint's
//! ([`super::constraints`]).

use super::{widest, Chunk, Model};
use crate::engine::dense::{simd, times_squareplus_grad, Mlp, Simd, Tape};
use crate::engine::gather::{gather_rows, scatter_add_rows, sum_by_index, Gather};
use crate::gnode::arch::{Block, Decoder};
use crate::gnode::variant::EdgeInput;

impl Chunk {
    pub(super) fn backward_flat(&mut self, m: &Model, th: &[f64], bs: usize) {
        let i = m.ix(Block::Flat).expect("NODE has a flat MLP");
        let nd = m.plan.n * m.plan.dim;
        let k = m.arch.norm.out_scale;
        self.gacc[..nd * bs].iter_mut().for_each(|g| *g *= k);
        let gx = self.inputs.then(|| {
            let gx = &mut self.gxn[..2 * nd * bs];
            gx.fill(0.0);
            (gx, &mut [][..])
        });
        m.mlp(i).backward(
            th,
            &mut self.grad,
            &self.x[..2 * nd * bs],
            &[],
            bs,
            &self.tapes[i],
            &self.gacc[..nd * bs],
            gx,
            &mut self.s1,
            &mut self.s2,
        );
    }

    widest! {
        /// The reverse of [`Chunk::forward_graph`], compiled for the widest
        /// vectors the CPU has (its activation derivatives, a division each,
        /// were a tenth of a 5-spring epoch as two-lane SSE2); the same bits on
        /// every path.
        pub(super) fn backward_graph => backward_graph_any(m: &Model, th: &[f64], bs: usize)
    }

    // The reverse of forward_graph_any stage by stage, each stage
    // #[inline(always)] to stay inside the vector copies above, so that the
    // two passes read side by side.
    #[inline(always)]
    #[allow(clippy::inline_always)]
    fn backward_graph_any(&mut self, m: &Model, th: &[f64], bs: usize) {
        let a = &m.arch;
        let (d, nodes, edges) = (m.plan.dim, bs * m.plan.n, self.edges);
        if self.inputs {
            self.gxn[..a.node_features() * nodes].fill(0.0);
            self.gw[..a.edge_features() * edges].fill(0.0);
            self.gqv[..2 * d * nodes].fill(0.0);
        }
        if a.constrained {
            if m.plan.bars.is_empty() {
                self.no_bars_backward(m, th, bs);
            } else {
                self.constrain_backward(m, th, bs);
            }
        } else {
            self.gout[..d * nodes].copy_from_slice(&self.gacc[..d * nodes]);
        }
        let k = a.norm.out_scale;
        self.gout[..d * nodes].iter_mut().for_each(|g| *g *= k);
        self.decode_backward(m, th, nodes);
        // Message passing, last round first.
        for l in (0..a.rounds).rev() {
            let em = a.embed;
            self.gh_prev[..em * nodes].fill(0.0);
            self.ghe_prev[..em * edges].fill(0.0);
            if a.updates_edges(l) {
                self.edge_update_backward(m, th, l, nodes);
            } else {
                let (ghep, ghe) = (&mut self.ghe_prev[..em * edges], &self.ghe[..em * edges]);
                for (x, g) in ghep.iter_mut().zip(ghe.iter()) {
                    *x += g;
                }
            }
            self.message_backward(m, th, l, nodes);
            std::mem::swap(&mut self.gh, &mut self.gh_prev);
            std::mem::swap(&mut self.ghe, &mut self.ghe_prev);
        }
        self.embeddings_backward(m, th, nodes);
    }

    /// The reverse of [`Chunk::decode`]: ∂L/∂ of the last round's node and
    /// edge states into `gh`, `ghe` (zeroed first), through the body branch
    /// into `gglob` and on to the scaled node inputs.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside backward_graph's vector copies
    fn decode_backward(&mut self, m: &Model, th: &[f64], nodes: usize) {
        let a = &m.arch;
        let (d, em, nf) = (m.plan.dim, a.embed, a.node_features());
        let edges = self.edges;
        let (gh, ghe, gglob) = (
            &mut self.gh[..em * nodes],
            &mut self.ghe[..em * edges],
            &mut self.gglob[..em * nodes],
        );
        gh.fill(0.0);
        ghe.fill(0.0);
        gglob.fill(0.0);
        self.g_type.fill(0.0);
        let gout = &self.gout[..d * nodes];
        let (hr_, her_) = (
            &self.h[a.rounds][..em * nodes],
            &self.he[a.rounds][..em * edges],
        );
        let glob = &self.glob[..em * nodes];
        let (s1, s2) = (&mut self.s1, &mut self.s2);
        let grad = &mut self.grad;
        match a.decoder {
            Decoder::Pairwise { body } => {
                let half = edges / 2;
                let gfe = &mut self.gf_edge[..d * edges];
                for c in 0..d {
                    let go = &gout[c * nodes..(c + 1) * nodes];
                    for e in 0..half {
                        let g = 0.5 * (go[self.recv[e]] - go[self.send[e]]);
                        gfe[c * edges + e] = g;
                        gfe[c * edges + e + half] = -g;
                    }
                }
                let i = m.ix(Block::EdgeDecoder).expect("pairwise decoder");
                let (gx, tape) = (Some((&mut ghe[..], &mut [][..])), &self.tapes[i]);
                m.mlp(i)
                    .backward(th, grad, her_, &[], edges, tape, gfe, gx, s1, s2);
                if body {
                    let i = m.ix(Block::BodyDecoder).expect("body decoder");
                    let (gx, tape) = (Some((&mut gglob[..], &mut [][..])), &self.tapes[i]);
                    m.mlp(i)
                        .backward(th, grad, glob, &[], nodes, tape, gout, gx, s1, s2);
                }
            }
            Decoder::Node { global } => {
                let i = m.ix(Block::NodeDecoder).expect("node decoder");
                let (g, gg): (&[f64], &mut [f64]) = if global {
                    (glob, &mut gglob[..])
                } else {
                    (&[], &mut [])
                };
                let (gx, tape) = (Some((&mut gh[..], gg)), &self.tapes[i]);
                m.mlp(i)
                    .backward(th, grad, hr_, g, nodes, tape, gout, gx, s1, s2);
            }
        }
        if let Some(i) = m.ix(Block::GlobalEmbed) {
            times_squareplus_grad(gglob, glob);
            let (x, tape) = (&self.xn[..nf * nodes], &self.tapes[i]);
            let gx = self
                .inputs
                .then(|| (&mut self.gxn[..nf * nodes], &mut [][..]));
            m.mlp(i)
                .backward(th, grad, x, &[], nodes, tape, gglob, gx, s1, s2);
        }
    }

    /// The reverse of round `l`'s edge update: ∂L/∂ of its output (`ghe`)
    /// onto the edge states before it (`ghe_prev`) and, per edge or per type
    /// pair, onto the node states it read (`gh_prev`, or `g_type`).
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside backward_graph's vector copies
    fn edge_update_backward(&mut self, m: &Model, th: &[f64], l: usize, nodes: usize) {
        let a = &m.arch;
        let (em, edges) = (a.embed, self.edges);
        let (ghe, ghep) = (&self.ghe[..em * edges], &mut self.ghe_prev[..em * edges]);
        let gz = &mut self.gz[..em * edges];
        gz.copy_from_slice(ghe);
        times_squareplus_grad(gz, &self.he[l + 1][..em * edges]);
        for (x, g) in ghep.iter_mut().zip(gz.iter()) {
            *x += g;
        }
        if m.by_type && l == 0 {
            self.pair_update_backward(m, th);
            return;
        }
        let i = m.ix(Block::EdgeUpdate(l)).expect("round");
        let (tape, grad) = (&self.tapes[i], &mut self.grad);
        let (hs, hr) = (&self.hs[l][..em * edges], &self.hr[l][..em * edges]);
        let (gs, gr) = (&mut self.gs[..em * edges], &mut self.gr[..em * edges]);
        let hp = &self.hp[l][..em * edges];
        let ends = (&mut gr[..], &mut gs[..], &mut self.gp[..em * edges]);
        let mlp = (m.mlp(i), a.edge_input);
        let x = (hr, hs, hp, edges);
        let s = (&mut self.s1[..], &mut self.s2[..]);
        edge_update_mlp_backward(mlp, th, grad, x, tape, gz, ends, s);
        // Both ends in one pass, edge by edge: two scatter_add_rows would
        // sum each node's terms in another order.
        let ghp = &mut self.gh_prev[..em * nodes];
        for k in 0..em {
            for e in 0..edges {
                ghp[k * nodes + self.recv[e]] += gr[k * edges + e];
                ghp[k * nodes + self.send[e]] += gs[k * edges + e];
            }
        }
    }

    /// Round 0's edge update by type pair ([`Chunk::pair_outputs`]) in
    /// reverse, from ∂L/∂ of its output per edge in `gz`: each pair's is its
    /// edges' sum, and the pairs' inputs' go to the type embeddings.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside backward_graph's vector copies
    fn pair_update_backward(&mut self, m: &Model, th: &[f64]) {
        let a = &m.arch;
        let (t, em, edges) = (a.types, a.embed, self.edges);
        let i = m.ix(Block::EdgeUpdate(0)).expect("round");
        let (tape, grad) = (&self.tapes[i], &mut self.grad);
        let gz = &self.gz[..em * edges];
        let tt = t * t;
        let (gpo, sums) = (&mut self.g_pair_out[..em * tt], &mut self.sums);
        gpo.fill(0.0);
        for k in 0..em {
            let (gk, zk) = (&mut gpo[k * tt..(k + 1) * tt], &gz[k * edges..]);
            sum_by_index(gk, &zk[..edges], &self.pair[..edges], sums);
        }
        let (pr, rest) = self.pair_in[..3 * em * tt].split_at(em * tt);
        let (ps, pp) = rest.split_at(em * tt);
        let (gpr, rest) = self.g_pair_in[..3 * em * tt].split_at_mut(em * tt);
        let (gps, gpp) = rest.split_at_mut(em * tt);
        let ends = (&mut gpr[..], &mut gps[..], &mut gpp[..]);
        let mlp = (m.mlp(i), a.edge_input);
        let x = (pr, ps, pp, tt);
        let s = (&mut self.s1[..], &mut self.s2[..]);
        edge_update_mlp_backward(mlp, th, grad, x, tape, gpo, ends, s);
        let gty = &mut self.g_type[..em * t];
        for k in 0..em {
            for p in 0..tt {
                gty[k * t + p / t] += gpr[k * tt + p];
                gty[k * t + p % t] += gps[k * tt + p];
            }
        }
    }

    /// The reverse of round `l`'s node update (messages and their sum), or
    /// of its copy when the round keeps the node states: ∂L/∂ of its output
    /// (`gh`) onto the node and edge states before it (`gh_prev`,
    /// `ghe_prev`).
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside backward_graph's vector copies
    fn message_backward(&mut self, m: &Model, th: &[f64], l: usize, nodes: usize) {
        let (em, edges) = (m.arch.embed, self.edges);
        let (gh, ghp) = (&self.gh[..em * nodes], &mut self.gh_prev[..em * nodes]);
        if !m.arch.updates_nodes(l) {
            for (x, g) in ghp.iter_mut().zip(gh.iter()) {
                *x += g;
            }
            return;
        }
        let ghep = &mut self.ghe_prev[..em * edges];
        let (hs, hel) = (&self.hs[l][..em * edges], &self.he[l][..em * edges]);
        let gs = &mut self.gs[..em * edges];
        let gz = &mut self.gz[..em * nodes];
        gz.copy_from_slice(gh);
        times_squareplus_grad(gz, &self.h[l + 1][..em * nodes]);
        for (x, g) in ghp.iter_mut().zip(gz.iter()) {
            *x += g;
        }
        let gmsg = &mut self.gmsg[..em * edges];
        gather_rows(gmsg, gz, &self.recv[..edges], Gather::Set);
        gs.fill(0.0);
        let i = m.ix(Block::Message(l)).expect("round");
        let (gx, tape) = (Some((&mut gs[..], &mut ghep[..])), &self.tapes[i]);
        let (s1, s2) = (&mut self.s1, &mut self.s2);
        m.mlp(i)
            .backward(th, &mut self.grad, hs, hel, edges, tape, gmsg, gx, s1, s2);
        scatter_add_rows(ghp, gs, &self.send[..edges]);
    }

    /// The reverse of the embeddings: the node embedding (per type, its
    /// nodes' sum through it once; or per node, on to the scaled inputs)
    /// and the edge embedding (on to the edge inputs w_ij).
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside backward_graph's vector copies
    fn embeddings_backward(&mut self, m: &Model, th: &[f64], nodes: usize) {
        let a = &m.arch;
        let (t, em, nf) = (a.types, a.embed, a.node_features());
        let edges = self.edges;
        let (s1, s2) = (&mut self.s1, &mut self.s2);
        let gh = &mut self.gh[..em * nodes];
        let i = m.ix(Block::NodeEmbed).expect("graph model");
        if m.by_type {
            // Per type: the sum over its nodes, through the embedding once.
            let gty = &mut self.g_type[..em * t];
            if m.nodes_read {
                let ty = &self.node_ty[..nodes];
                for k in 0..em {
                    let gk = &mut gty[k * t..(k + 1) * t];
                    sum_by_index(gk, &gh[k * nodes..(k + 1) * nodes], ty, &mut self.sums);
                }
            }
            times_squareplus_grad(gty, &self.type_embed[..em * t]);
            let (eye, tape) = (&self.eye[..t * t], &self.tapes[i]);
            m.mlp(i)
                .backward(th, &mut self.grad, eye, &[], t, tape, gty, None, s1, s2);
        } else {
            // (One-hot node inputs went by type above: these carry q and q̇.)
            times_squareplus_grad(gh, &self.h[0][..em * nodes]);
            let (x, tape) = (&self.xn[..nf * nodes], &self.tapes[i]);
            let gx = self
                .inputs
                .then(|| (&mut self.gxn[..nf * nodes], &mut [][..]));
            m.mlp(i)
                .backward(th, &mut self.grad, x, &[], nodes, tape, gh, gx, s1, s2);
        }
        let ghe = &mut self.ghe[..em * edges];
        times_squareplus_grad(ghe, &self.he[0][..em * edges]);
        let i = m.ix(Block::EdgeEmbed).expect("graph model");
        let ef = a.edge_features();
        let (w, tape) = (&self.w_in[..ef * edges], &self.tapes[i]);
        let gx = self
            .inputs
            .then(|| (&mut self.gw[..ef * edges], &mut [][..]));
        m.mlp(i)
            .backward(th, &mut self.grad, w, &[], edges, tape, ghe, gx, s1, s2);
    }
}

/// The reverse pass of an edge update W_E over rows whose end states are
/// `hr`, `hs` (and `hp` = hr ⊙ hs): W_E(h_i ‖ h_j) or W_E(h_i ⊙ h_j) as the
/// architecture's edge input says. ∂L/∂θ is added into `grad`; ∂L/∂h_i and
/// ∂L/∂h_j are written into `gr`, `gs` (`gp`: the product's, scratch).
#[allow(clippy::too_many_arguments)]
fn edge_update_mlp_backward(
    (mlp, input): (&Mlp, EdgeInput),
    th: &[f64],
    grad: &mut [f64],
    (hr, hs, hp, r): (&[f64], &[f64], &[f64], usize),
    tape: &Tape,
    gz: &[f64],
    (gr, gs, gp): (&mut [f64], &mut [f64], &mut [f64]),
    (s1, s2): (&mut [f64], &mut [f64]),
) {
    match input {
        EdgeInput::Concat => {
            gr.fill(0.0);
            gs.fill(0.0);
            mlp.backward(th, grad, hr, hs, r, tape, gz, Some((gr, gs)), s1, s2);
        }
        EdgeInput::Product => {
            // ∂(h_i ⊙ h_j): ḡ_i = ḡ ⊙ h_j, ḡ_j = ḡ ⊙ h_i.
            gp.fill(0.0);
            mlp.backward(th, grad, hp, &[], r, tape, gz, Some((gp, &mut [])), s1, s2);
            for (((g, r), s), (x, y)) in gp
                .iter()
                .zip(gr.iter_mut())
                .zip(gs.iter_mut())
                .zip(hs.iter().zip(hr))
            {
                (*r, *s) = (g * x, g * y);
            }
        }
    }
}
