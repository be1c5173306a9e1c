//! The forward pass: NODE's flat MLP, and the graph models' encoder,
//! message passing and decoder (one after the other, or fused block by
//! block for MCGNODE's inference), ending in the constraint
//! ([`super::constraints`]).

use super::{widest, Chunk, Model};
use crate::engine::dense::{simd, squareplus_in_place, Out, Simd};
use crate::engine::fused::{BodyBlocks, Branch, EdgeBlocks, EDGE_BLOCK, FUSED_EDGES};
use crate::engine::gather::{add_indexed, edge_differences, gather_rows, scatter_add_rows, Gather};
use crate::engine::split::Scratch;
use crate::gnode::arch::{Block, Decoder};
use crate::gnode::variant::EdgeInput;

impl Chunk {
    pub(super) fn forward_flat(&mut self, m: &Model, th: &[f64], bs: usize) {
        let i = m.ix(Block::Flat).expect("NODE has a flat MLP");
        let nd = m.plan.n * m.plan.dim;
        m.mlp(i).forward(
            th,
            &self.x[..2 * nd * bs],
            &[],
            bs,
            &mut self.tapes[i],
            &mut self.acc[..nd * bs],
        );
        let k = m.arch.norm.out_scale;
        self.acc[..nd * bs].iter_mut().for_each(|a| *a *= k);
    }

    widest! {
        /// The graph models' forward pass, compiled for the widest vectors the
        /// CPU has (the activations and gathers between the MLPs are a third of
        /// an inference step); the same bits on every path.
        pub(super) fn forward_graph => forward_graph_any(m: &Model, th: &[f64])
    }

    // The paper's forward pass, inlined into the vector copies above with
    // its stages (each #[inline(always)] to stay inside them).
    #[inline(always)]
    #[allow(clippy::inline_always)]
    pub(super) fn forward_graph_any(&mut self, m: &Model, th: &[f64]) {
        let a = &m.arch;
        let (d, t, em) = (m.plan.dim, a.types, a.embed);
        let bs = self.laid;
        let nodes = bs * m.plan.n;
        let nf = a.node_features();
        // Encode: nodes from the type (by type) or (one-hot, q, q̇), edges
        // from w_ij = q_i − q_j.
        // The type embeddings and round 0's pair outputs are functions of
        // the parameters alone: kept from the last step when those are the
        // same (inference records no tape that would need them again).
        let kept = m.by_type && !self.record && self.by_type_done && self.same_params;
        self.by_type_done = m.by_type && !self.record;
        let i = m.ix(Block::NodeEmbed).expect("graph model");
        let h0 = &mut self.h[0][..em * nodes];
        let (by_type, nodes_read) = (m.by_type, m.nodes_read);
        if by_type {
            // One embedding per type, the same bits as per node, a sixth of
            // an inference step's square roots fewer.
            let emb = &mut self.type_embed[..em * t];
            if !kept {
                m.mlp(i)
                    .forward(th, &self.eye[..t * t], &[], t, &mut self.tapes[i], emb);
                squareplus_in_place(emb);
            }
            if nodes_read {
                let ty = &self.node_ty[..nodes];
                for k in 0..em {
                    let (hk, ek) = (
                        &mut h0[k * nodes..(k + 1) * nodes],
                        &emb[k * t..(k + 1) * t],
                    );
                    for (h, &y) in hk.iter_mut().zip(ty) {
                        *h = ek[y];
                    }
                }
            }
        } else {
            let (x, tape) = (&self.xn[..nf * nodes], &mut self.tapes[i]);
            m.mlp(i).forward(th, x, &[], nodes, tape, h0);
            squareplus_in_place(h0);
        }
        if by_type && a.rounds > 0 && a.updates_edges(0) {
            self.pair_outputs(m, th, kept);
        }
        // MCGNODE's one round by type at inference: the edges' stages fused
        // block by block, the blocks over both cores on a large graph.
        let fused = m.fusable && !self.record && self.edges >= FUSED_EDGES;
        if fused {
            self.edge_blocks(m, th);
        } else {
            self.edge_stages(m, th);
        }
        self.decode(m, th, fused);
        // Constrain.
        if a.constrained {
            self.constrain(m, th, bs, kept);
        } else {
            self.acc[..d * nodes].copy_from_slice(&self.out[..d * nodes]);
        }
    }

    /// The edges' stages one after the other over all rows: the edge
    /// embedding from w_ij = q_i − q_j, then message passing.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside forward_graph's vector copies
    pub(super) fn edge_stages(&mut self, m: &Model, th: &[f64]) {
        let a = &m.arch;
        let (d, t, em) = (m.plan.dim, a.types, a.embed);
        let nodes = self.laid * m.plan.n;
        let edges = self.edges;
        let (by_type, nodes_read) = (m.by_type, m.nodes_read);
        for c in 0..d {
            let q = &self.x[(t + c) * nodes..(t + c + 1) * nodes];
            let w = &mut self.w_in[c * edges..(c + 1) * edges];
            let pair = (&self.recv[..], &self.send[..]);
            edge_differences(w, q, pair, a.norm.w_scale, m.plan.period(c));
        }
        let i = m.ix(Block::EdgeEmbed).expect("graph model");
        let he0 = &mut self.he[0][..em * edges];
        let w_in = &self.w_in[..a.edge_features() * edges];
        let tape = &mut self.tapes[i];
        (self.split).forward(m.mlp(i), th, (w_in, &[]), edges, tape, he0, true);
        // Message passing.
        for l in 0..a.rounds {
            let (hl, hn) = self.h.split_at_mut(l + 1);
            let (hl, hn) = (&hl[l][..em * nodes], &mut hn[0][..em * nodes]);
            let hel = &self.he[l][..em * edges];
            let (hs, hr) = (&mut self.hs[l][..em * edges], &mut self.hr[l][..em * edges]);
            let by_pair = by_type && l == 0;
            if !by_pair || a.updates_nodes(l) {
                gather_rows(hs, hl, &self.send[..edges], Gather::Set);
                gather_rows(hr, hl, &self.recv[..edges], Gather::Set);
            }
            if a.updates_nodes(l) {
                // h_i ← sqp(h_i + Σ_j W_V(h_j ‖ h_ij)).
                let i = m.ix(Block::Message(l)).expect("round");
                let msg = &mut self.msg[..em * edges];
                let tape = &mut self.tapes[i];
                (self.split).forward(m.mlp(i), th, (hs, hel), edges, tape, msg, false);
                let agg = &mut self.agg[..em * nodes];
                agg.fill(0.0);
                scatter_add_rows(agg, msg, &self.recv[..edges]);
                for ((x, h), g) in hn.iter_mut().zip(hl).zip(agg.iter()) {
                    *x = h + g;
                }
                squareplus_in_place(hn);
            } else if nodes_read {
                hn.copy_from_slice(hl);
            }
            if a.updates_edges(l) {
                self.edge_update(m, th, l);
            } else {
                let (hel, hen) = self.he.split_at_mut(l + 1);
                hen[0][..em * edges].copy_from_slice(&hel[l][..em * edges]);
            }
        }
    }

    /// Round `l`'s edge update h_ij ← sqp(h_ij + W_E(h_i ‖ h_j)), from the
    /// node states before the round (by type pair in round 0 when
    /// [`Model::by_type`]: the pairs' outputs read per edge).
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside forward_graph's vector copies
    fn edge_update(&mut self, m: &Model, th: &[f64], l: usize) {
        let a = &m.arch;
        let (t, em, edges) = (a.types, a.embed, self.edges);
        let (hel, hen) = self.he.split_at_mut(l + 1);
        let (hel, hen) = (&hel[l][..em * edges], &mut hen[0][..em * edges]);
        let (hs, hr) = (&self.hs[l][..em * edges], &self.hr[l][..em * edges]);
        if m.by_type && l == 0 {
            // The same MLP on the types² pairs' inputs, read per edge.
            let (tt, po) = (t * t, &self.pair_out[..em * t * t]);
            let pair = &self.pair[..edges];
            for k in 0..em {
                let (x, old, pk) = (
                    &mut hen[k * edges..(k + 1) * edges],
                    &hel[k * edges..(k + 1) * edges],
                    &po[k * tt..(k + 1) * tt],
                );
                add_indexed(x, old, pk, pair);
            }
            squareplus_in_place(hen);
            return;
        }
        let i = m.ix(Block::EdgeUpdate(l)).expect("round");
        let tape = &mut self.tapes[i];
        let split = &mut self.split;
        match a.edge_input {
            EdgeInput::Concat => split.forward(m.mlp(i), th, (hr, hs), edges, tape, hen, false),
            EdgeInput::Product => {
                let hp = &mut self.hp[l][..em * edges];
                for ((p, r), s) in hp.iter_mut().zip(hr.iter()).zip(hs.iter()) {
                    *p = r * s;
                }
                split.forward(m.mlp(i), th, (hp, &[]), edges, tape, hen, false);
            }
        }
        for (x, old) in hen.iter_mut().zip(hel) {
            *x += old;
        }
        squareplus_in_place(hen);
    }

    /// The body branch and the decoder into `out`; `fused`: the edge
    /// decoder's outputs are already in `f_edge` ([`Chunk::edge_blocks`]).
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside forward_graph's vector copies
    pub(super) fn decode(&mut self, m: &Model, th: &[f64], fused: bool) {
        let a = &m.arch;
        let (d, em) = (m.plan.dim, a.embed);
        let nodes = self.laid * m.plan.n;
        let edges = self.edges;
        let nf = a.node_features();
        // Global (body) embedding of (one-hot, q, q̇) (with the edges' blocks
        // when fused).
        if let (Some(i), false) = (m.ix(Block::GlobalEmbed), fused) {
            let g = &mut self.glob[..em * nodes];
            m.mlp(i).forward(
                th,
                &self.xn[..nf * nodes],
                &[],
                nodes,
                &mut self.tapes[i],
                g,
            );
            squareplus_in_place(g);
        }
        // Decode.
        let (hr_, her_) = (
            &self.h[a.rounds][..em * nodes],
            &self.he[a.rounds][..em * edges],
        );
        let out = &mut self.out[..d * nodes];
        match a.decoder {
            Decoder::Pairwise { body } => {
                // Newton's third law: F_ab = (f_ab − f_ba)/2 on a, −F_ab on b.
                out.fill(0.0);
                let i = m.ix(Block::EdgeDecoder).expect("pairwise decoder");
                let fe = &mut self.f_edge[..d * edges];
                if !fused {
                    let tape = &mut self.tapes[i];
                    (self.split).forward(m.mlp(i), th, (her_, &[]), edges, tape, fe, false);
                }
                let half = edges / 2;
                for c in 0..d {
                    let (oc, fc) = (&mut out[c * nodes..(c + 1) * nodes], &fe[c * edges..]);
                    for e in 0..half {
                        let f = (fc[e] - fc[e + half]) * 0.5;
                        oc[self.recv[e]] += f;
                        oc[self.send[e]] -= f;
                    }
                }
                if body {
                    let i = m.ix(Block::BodyDecoder).expect("body decoder");
                    let fb = &mut self.f_body[..d * nodes];
                    if !fused {
                        let g = &self.glob[..em * nodes];
                        m.mlp(i).forward(th, g, &[], nodes, &mut self.tapes[i], fb);
                    }
                    for (o, f) in out.iter_mut().zip(fb.iter()) {
                        *o += f;
                    }
                }
            }
            Decoder::Node { global } => {
                let i = m.ix(Block::NodeDecoder).expect("node decoder");
                let g: &[f64] = if global {
                    &self.glob[..em * nodes]
                } else {
                    &[]
                };
                m.mlp(i).forward(th, hr_, g, nodes, &mut self.tapes[i], out);
            }
        }
        let k = a.norm.out_scale;
        self.out[..d * nodes].iter_mut().for_each(|o| *o *= k);
    }

    /// Round 0's edge update on the types² pairs' inputs (each edge reads its
    /// pair's row): kept from the pass before when `kept`.
    #[inline(always)]
    #[allow(clippy::inline_always)] // inside forward_graph's vector copies
    pub(super) fn pair_outputs(&mut self, m: &Model, th: &[f64], kept: bool) {
        let a = &m.arch;
        let (t, em) = (a.types, a.embed);
        let i = m.ix(Block::EdgeUpdate(0)).expect("round");
        let (tt, emb) = (t * t, &self.type_embed[..em * t]);
        let (pr, rest) = self.pair_in[..3 * em * tt].split_at_mut(em * tt);
        let (ps, pp) = rest.split_at_mut(em * tt);
        for k in 0..em {
            for p in 0..tt {
                let (r, s) = (emb[k * t + p / t], emb[k * t + p % t]);
                (pr[k * tt + p], ps[k * tt + p], pp[k * tt + p]) = (r, s, r * s);
            }
        }
        let (x, c): (&[f64], &[f64]) = match a.edge_input {
            EdgeInput::Concat => (pr, ps),
            EdgeInput::Product => (pp, &[]),
        };
        let po = &mut self.pair_out[..em * tt];
        if !kept {
            m.mlp(i).forward(th, x, c, tt, &mut self.tapes[i], po);
        }
    }

    /// [`Chunk::edge_stages`] and the edge decoder fused over blocks of edge
    /// rows ([`super::fused`]): inference of MCGNODE's one round by type.
    pub(super) fn edge_blocks(&mut self, m: &Model, th: &[f64]) {
        let a = &m.arch;
        let (d, t, em) = (m.plan.dim, a.types, a.embed);
        let nodes = self.laid * m.plan.n;
        let edges = self.edges;
        let (Some(ie), Some(id)) = (m.ix(Block::EdgeEmbed), m.ix(Block::EdgeDecoder)) else {
            unreachable!("a pairwise graph model has both edge MLPs")
        };
        let features = a.edge_features();
        let work = EdgeBlocks {
            mlps: Branch {
                embed: m.mlp(ie),
                decoder: m.mlp(id),
                th,
                embed_width: em,
            },
            q: &self.x[t * nodes..(t + d) * nodes],
            nodes,
            dim: d,
            w_scale: a.norm.w_scale,
            period: [0, 1, 2].map(|c| m.plan.period(c)),
            recv: &self.recv[..edges],
            send: &self.send[..edges],
            w_in: &self.w_in[..features * edges],
            features,
            edges,
            pair_out: &self.pair_out[..em * t * t],
            pairs: t * t,
            pair: &self.pair[..edges],
        };
        let body = match (m.ix(Block::GlobalEmbed), m.ix(Block::BodyDecoder)) {
            (Some(ig), Some(ib)) => Some(BodyBlocks {
                mlps: Branch {
                    embed: m.mlp(ig),
                    decoder: m.mlp(ib),
                    th,
                    embed_width: em,
                },
                xn: &self.xn[..a.node_features() * nodes],
                features: a.node_features(),
                nodes,
            }),
            _ => None,
        };
        // Edge blocks first, then the particles' from the next whole block.
        let span = edges.next_multiple_of(EDGE_BLOCK);
        let rows = span + if body.is_some() { nodes } else { 0 };
        let f_edge = Out::new(&mut self.f_edge[..d * edges], edges);
        let f_body = Out::new(&mut self.f_body[..d * nodes], nodes);
        let run = |r: std::ops::Range<usize>, s: &mut Scratch| match &body {
            Some(b) if r.start >= span => {
                // SAFETY: `blocks` hands each block of rows to one thread.
                unsafe { b.run(r.start - span..r.end - span, s, f_body) }
            }
            // SAFETY: as above.
            _ => unsafe { work.run(r.start..r.end.min(edges), s, f_edge) },
        };
        (self.split).blocks(rows, EDGE_BLOCK, &mut self.scratch, &run);
    }
}
