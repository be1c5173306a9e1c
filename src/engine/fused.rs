//! MCGNODE's edge work at inference, fused block by block: for a block of
//! directed edges, w_ij = (q_i − q_j)/σ_w, the edge embedding, round 0's
//! edge update read from its type pair's row, and the edge decoder, with the
//! block's intermediate rows in a thread's scratch; then, for blocks of
//! particles, the body branch (its embedding and decoder). One pass over
//! the rows instead of one per stage: they stay in cache, and a large
//! graph's blocks go to both cores in one hand-over a step
//! ([`super::split::Split::blocks`]) with the stages between the MLPs
//! inside it. The same operations in the same order as the stage-by-stage
//! pass, so the same bits.

use std::ops::Range;

use super::dense::{simd, squareplus_in_place, Mlp, Out, Simd};
use super::gather::{add_indexed, edge_differences};
use super::split::Scratch;

/// Edge rows per block (a multiple of the 16-row tile): a block's 16-wide
/// intermediate rows are 32 KB, and a 1,000-particle contact state's 6,000
/// edges make 24 blocks for the two cores to share.
pub(crate) const EDGE_BLOCK: usize = 256;

/// Directed edges from which the fused pass is taken: below, its set-up
/// per block costs more than the cache it saves (fused, the 5-spring ring's
/// 10 edges stepped about 10 % slower; the 500-spring ring's 1,000 edges
/// 21.4–28.7k against 21.0–26.7k steps/s, six interleaved runs of `bench`
/// on one core, 2026-12-03).
pub(crate) const FUSED_EDGES: usize = 128;

/// An embedding, the decoder after it, their parameters and the
/// embedding's width.
pub(crate) struct Branch<'a> {
    pub(crate) embed: &'a Mlp,
    pub(crate) decoder: &'a Mlp,
    pub(crate) th: &'a [f64],
    pub(crate) embed_width: usize,
}

impl Branch<'_> {
    /// Makes a thread's tile scratch big enough for both MLPs.
    fn fit(&self, s: &mut Scratch) {
        s.tape.fit(self.embed);
        s.tape.fit(self.decoder);
    }
}

/// What every edge block reads.
pub(crate) struct EdgeBlocks<'a> {
    /// The edge embedding and the edge decoder.
    pub(crate) mlps: Branch<'a>,
    /// Raw positions, feature-major `dim × nodes`.
    pub(crate) q: &'a [f64],
    pub(crate) nodes: usize,
    pub(crate) dim: usize,
    pub(crate) w_scale: f64,
    /// The period of each axis a periodic box wraps (minimum images).
    pub(crate) period: [Option<f64>; 3],
    /// Receiver and sender of each directed edge.
    pub(crate) recv: &'a [usize],
    pub(crate) send: &'a [usize],
    /// Every edge's inputs, feature-major `features × edges`: the rows after
    /// the first `dim` (the constant inputs) are read.
    pub(crate) w_in: &'a [f64],
    pub(crate) features: usize,
    pub(crate) edges: usize,
    /// Round 0's edge update of each type pair (`embed × pairs`), and each
    /// edge's pair.
    pub(crate) pair_out: &'a [f64],
    pub(crate) pairs: usize,
    pub(crate) pair: &'a [usize],
}

/// The body branch's work: its embedding of the scaled node inputs and its
/// decoder, per particle.
pub(crate) struct BodyBlocks<'a> {
    pub(crate) mlps: Branch<'a>,
    /// Scaled node inputs, feature-major `features × nodes`.
    pub(crate) xn: &'a [f64],
    pub(crate) features: usize,
    pub(crate) nodes: usize,
}

/// Rows a block's features are laid out apart for `len` rows: 64 bytes
/// more than a multiple of the tile, so never a multiple of 2 KB (at 256
/// rows, 2 KB, a tile's 16 input features fell into the same few cache
/// sets and a block's MLPs ran 10 % slower than over all rows).
fn stride(len: usize) -> usize {
    len.next_multiple_of(16) + 8
}

impl BodyBlocks<'_> {
    /// The body decoder's output for the particles `rows`, into those rows
    /// of `f_body` (`dim × nodes`).
    ///
    /// # Safety
    /// No other thread writes these rows of `f_body` meanwhile.
    pub(crate) unsafe fn run(&self, rows: Range<usize>, s: &mut Scratch, f_body: Out<'_>) {
        let (lo, len, b) = (rows.start, rows.len(), &self.mlps);
        b.fit(s);
        let st = stride(len);
        let [x, g, _] = &mut s.rows;
        let x = at_least(x, self.features * st);
        for f in 0..self.features {
            let at = f * self.nodes + lo;
            x[f * st..f * st + len].copy_from_slice(&self.xn[at..at + len]);
        }
        let g = at_least(g, b.embed_width * st);
        // SAFETY: `g` is this thread's own; these rows of `f_body` are this
        // call's alone (the caller's contract).
        unsafe {
            let out = Out::new(g, st);
            (b.embed).forward_part(b.th, (x, &[]), st, 0..len, &mut s.tape, out, true);
            let out = f_body.shifted(lo);
            (b.decoder).forward_part(b.th, (g, &[]), st, 0..len, &mut s.tape, out, false);
        }
    }
}

/// `v` at least `len` long (allocates only while growing).
fn at_least(v: &mut Vec<f64>, len: usize) -> &mut [f64] {
    if v.len() < len {
        v.resize(len, 0.0);
    }
    &mut v[..len]
}

impl EdgeBlocks<'_> {
    /// The edge decoder's output for the edges `rows`, into those rows of
    /// `f_edge` (`dim × edges`).
    ///
    /// # Safety
    /// No other thread writes these rows of `f_edge` meanwhile.
    pub(crate) unsafe fn run(&self, rows: Range<usize>, s: &mut Scratch, f_edge: Out<'_>) {
        match simd() {
            // SAFETY: the CPU supports AVX-512F and FMA (`simd` checked);
            // the rows are the caller's.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { self.run_avx512(rows, s, f_edge) },
            // SAFETY: the CPU supports AVX2 and FMA (`simd` checked).
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { self.run_avx2(rows, s, f_edge) },
            // SAFETY: the caller's contract.
            _ => unsafe { self.run_any(rows, s, f_edge) },
        }
    }

    // The loops between the MLPs in the widest vectors (the MLPs and the
    // activation choose theirs themselves).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,fma")]
    unsafe fn run_avx512(&self, rows: Range<usize>, s: &mut Scratch, f_edge: Out<'_>) {
        // SAFETY: the caller's contract.
        unsafe { self.run_any(rows, s, f_edge) }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn run_avx2(&self, rows: Range<usize>, s: &mut Scratch, f_edge: Out<'_>) {
        // SAFETY: the caller's contract.
        unsafe { self.run_any(rows, s, f_edge) }
    }

    #[inline(always)]
    #[allow(clippy::inline_always)] // inside the vector copies above
    unsafe fn run_any(&self, rows: Range<usize>, s: &mut Scratch, f_edge: Out<'_>) {
        let (lo, len, b) = (rows.start, rows.len(), &self.mlps);
        let em = b.embed_width;
        b.fit(s);
        let st = stride(len);
        let [w, he, hn] = &mut s.rows;
        let w = at_least(w, self.features * st);
        let (recv, send) = (&self.recv[rows.clone()], &self.send[rows]);
        for c in 0..self.dim {
            let q = &self.q[c * self.nodes..(c + 1) * self.nodes];
            let w = &mut w[c * st..c * st + len];
            edge_differences(w, q, (recv, send), self.w_scale, self.period[c]);
        }
        for f in self.dim..self.features {
            let at = f * self.edges + lo;
            w[f * st..f * st + len].copy_from_slice(&self.w_in[at..at + len]);
        }
        let (he, hn) = (at_least(he, em * st), at_least(hn, em * st));
        let th = b.th;
        // SAFETY: `he` is this thread's own.
        unsafe {
            let out = Out::new(he, st);
            (b.embed).forward_part(th, (w, &[]), st, 0..len, &mut s.tape, out, true);
        }
        let pair = &self.pair[lo..lo + len];
        for k in 0..em {
            let pk = &self.pair_out[k * self.pairs..(k + 1) * self.pairs];
            let (x, old) = (&mut hn[k * st..k * st + len], &he[k * st..k * st + len]);
            add_indexed(x, old, pk, pair);
            squareplus_in_place(x);
        }
        // SAFETY: these rows of `f_edge` are this call's alone (the
        // caller's contract).
        unsafe {
            let out = f_edge.shifted(lo);
            (b.decoder).forward_part(th, (hn, &[]), st, 0..len, &mut s.tape, out, false);
        }
    }
}
