//! Edge-indexed moves between feature-major node and edge buffers: a
//! node feature gathered onto each edge's end, an edge feature summed into
//! its end node. Every engine's graph pass is made of these.

use super::dense::sum;

/// Whether [`gather_rows`] overwrites or adds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Gather {
    /// `dst = src[idx]`.
    Set,
    /// `dst += src[idx]`.
    Add,
}

/// The node count per feature row of feature-major buffers of `per_edge`
/// and `per_node` values with one edge per index, every index checked to
/// be below it; None without edges.
fn nodes_per_row(idx: &[usize], per_edge: usize, per_node: usize) -> Option<usize> {
    if idx.is_empty() {
        return None;
    }
    let n = per_node / (per_edge / idx.len()).max(1);
    assert!(idx.iter().all(|&i| i < n), "an edge end outside the nodes");
    Some(n)
}

/// Per feature row: `dst[k][j] (=|+=) src[k][idx[j]]`, feature-major
/// (`dst`: rows × idx.len(), `src`: rows × its own width; rows from
/// `dst`'s length). The indices are checked once, not at every element:
/// the checks made these loops a fifth of a GNS epoch.
pub(crate) fn gather_rows(dst: &mut [f64], src: &[f64], idx: &[usize], how: Gather) {
    let Some(n) = nodes_per_row(idx, dst.len(), src.len()) else {
        return;
    };
    for (d, s) in dst.chunks_exact_mut(idx.len()).zip(src.chunks_exact(n)) {
        for (dv, &i) in d.iter_mut().zip(idx) {
            // SAFETY: i < n = s.len(), checked above.
            let v = unsafe { *s.get_unchecked(i) };
            *dv = if how == Gather::Add { *dv + v } else { v };
        }
    }
}

/// Per feature row: `dst[k][idx[j]] += src[k][j]`, in `j` order (as
/// [`gather_rows`] lays rows out; indices checked once).
pub(crate) fn scatter_add_rows(dst: &mut [f64], src: &[f64], idx: &[usize]) {
    let Some(n) = nodes_per_row(idx, src.len(), dst.len()) else {
        return;
    };
    for (d, s) in dst.chunks_exact_mut(n).zip(src.chunks_exact(idx.len())) {
        for (&v, &i) in s.iter().zip(idx) {
            // SAFETY: i < n = d.len(), checked above.
            unsafe { *d.get_unchecked_mut(i) += v };
        }
    }
}

/// One coordinate of the edge vectors: `w[e] = (q[recv[e]] − q[send[e]]) / scale`,
/// gathered first and divided apart, so that the divisions run in vectors
/// (the same bits as dividing each in turn). On an axis of a periodic box
/// (`period`: its length) the difference is its minimum image; the image's
/// shift is constant between steps, so gradients through w are unchanged.
#[inline(always)]
#[allow(clippy::inline_always)] // inside the callers' vector copies
pub(crate) fn edge_differences(
    w: &mut [f64],
    q: &[f64],
    (recv, send): (&[usize], &[usize]),
    scale: f64,
    period: Option<f64>,
) {
    for ((wv, &i), &j) in w.iter_mut().zip(recv).zip(send) {
        *wv = q[i] - q[j];
    }
    if let Some(l) = period {
        w.iter_mut()
            .for_each(|wv| *wv = crate::periodic::min_image_axis(*wv, l));
    }
    w.iter_mut().for_each(|wv| *wv /= scale);
}

/// `out[e] = table[idx[e]] + old[e]`: a row computed once per index (a
/// type pair's edge update) read by every edge and added to its state.
#[inline(always)]
#[allow(clippy::inline_always)] // inside the callers' vector copies
pub(crate) fn add_indexed(out: &mut [f64], old: &[f64], table: &[f64], idx: &[usize]) {
    if let [only] = table {
        // One row (one particle type): the same adds, in vectors, without
        // the per-edge index (a scalar loop was a tenth of a 5-spring
        // rollout's graph pass).
        for (x, old) in out.iter_mut().zip(old) {
            *x = only + old;
        }
        return;
    }
    for ((x, old), &p) in out.iter_mut().zip(old).zip(idx) {
        *x = table[p] + old;
    }
}

/// Reused buffers of [`sum_by_index`]: allocated once, at the first call.
#[derive(Clone, Debug, Default)]
pub(crate) struct IndexSums {
    counts: Vec<usize>,
    seen: Vec<usize>,
    /// Four partial sums and the tail per index (`5 × out.len()`).
    acc: Vec<f64>,
}

/// `out[p] += Σ z[e] over the e with idx[e] = p`, each index's terms summed
/// as [`super::dense::sum`] sums them in `e` order (four partial sums, the
/// tail last). Adding edge by edge into `out` made one chain of adds through
/// memory per index: with one pair of types, a tenth of a 5-spring epoch.
pub(crate) fn sum_by_index(out: &mut [f64], z: &[f64], idx: &[usize], s: &mut IndexSums) {
    assert!(
        idx.iter().all(|&p| p < out.len()),
        "an index outside the sums"
    );
    if let [only] = out {
        // One index: its terms are `z` itself, summed in vectors.
        *only += sum(&z[..idx.len()]);
        return;
    }
    let m = out.len();
    s.counts.clear();
    s.counts.resize(m, 0);
    for &p in idx {
        s.counts[p] += 1;
    }
    s.seen.clear();
    s.seen.resize(m, 0);
    s.acc.clear();
    s.acc.resize(5 * m, 0.0);
    for (&p, &v) in idx.iter().zip(z) {
        let k = s.seen[p];
        s.seen[p] += 1;
        // The first 4⌊n/4⌋ terms go to partial sum k mod 4, the rest to the tail.
        let slot = if k < s.counts[p] - s.counts[p] % 4 {
            k % 4
        } else {
            4
        };
        s.acc[slot * m + p] += v;
    }
    for (p, o) in out.iter_mut().enumerate() {
        let a = |l: usize| s.acc[l * m + p];
        *o += (a(0) + a(1)) + (a(2) + a(3)) + a(4);
    }
}

/// `to.copy_from_slice(from)` for short rows (a state's few particles),
/// inline: a call to the C library's `memmove` per 5-number row cost more
/// than the copy (7 % of a 5-spring epoch).
#[inline(always)]
#[allow(clippy::inline_always)] // inside the callers' vector builds
pub(crate) fn copy_row(to: &mut [f64], from: &[f64]) {
    assert_eq!(to.len(), from.len(), "rows of one length");
    let mut t = to.chunks_exact_mut(4);
    let mut f = from.chunks_exact(4);
    for (a, b) in (&mut t).zip(&mut f) {
        let b: &[f64; 4] = b.try_into().expect("blocks of four");
        let a: &mut [f64; 4] = a.try_into().expect("blocks of four");
        *a = *b;
    }
    // Spelled out: a loop here may be compiled back into a `memmove` call.
    match (t.into_remainder(), f.remainder()) {
        ([a], [x]) => *a = *x,
        ([a, b], [x, y]) => (*a, *b) = (*x, *y),
        ([a, b, c], [x, y, z]) => (*a, *b, *c) = (*x, *y, *z),
        _ => {}
    }
}

/// Asks the CPU to bring `x` into cache ahead of its use (a no-op off
/// x86-64). A batch's states are shuffled over the heap, a few small
/// buffers each: read one after another, each waited on its own cache miss.
#[inline]
pub(crate) fn prefetch(x: &[f64]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // One request per 64-byte line, the last value's line included.
        let p = x.as_ptr().cast::<i8>();
        let bytes = std::mem::size_of_val(x);
        let mut at = 0;
        while at < bytes {
            // SAFETY: a prefetch never faults, and `p + at` stays inside `x`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.add(at)) };
            at += 64;
        }
        if bytes > 0 {
            // SAFETY: as above; the last byte of `x`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.add(bytes - 1)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The helpers against plain indexed loops, two feature rows of 5 nodes
    /// and 7 edges (ends repeated, one node never an end).
    #[test]
    fn gathers_and_scatters_match_indexed_loops() {
        let (n, idx) = (5, [3usize, 0, 3, 1, 4, 0, 3]);
        let e = idx.len();
        let nodes: Vec<f64> = (0..2 * n).map(|i| i as f64 * 1.5 - 2.0).collect();
        let edges: Vec<f64> = (0..2 * e).map(|i| (i as f64 * 0.7).sin()).collect();
        let mut set = vec![9.0; 2 * e];
        gather_rows(&mut set, &nodes, &idx, Gather::Set);
        let mut add = edges.clone();
        gather_rows(&mut add, &nodes, &idx, Gather::Add);
        let mut sum = vec![0.5; 2 * n];
        scatter_add_rows(&mut sum, &edges, &idx);
        let mut want_sum = vec![0.5; 2 * n];
        for k in 0..2 {
            for (j, &i) in idx.iter().enumerate() {
                assert_eq!(set[k * e + j], nodes[k * n + i]);
                assert_eq!(add[k * e + j], edges[k * e + j] + nodes[k * n + i]);
                want_sum[k * n + i] += edges[k * e + j];
            }
        }
        assert_eq!(sum, want_sum);
        // No edges: nothing moves.
        gather_rows(&mut [], &nodes, &[], Gather::Set);
        scatter_add_rows(&mut sum, &[], &[]);
        assert_eq!(sum, want_sum);
    }

    /// Each index's sum is `sum` of its terms gathered in order (the same
    /// bits), for index counts below, at and past multiples of four, one
    /// index alone, and an index with no terms; and within rounding of the
    /// plain running sum.
    #[test]
    fn sums_by_index_are_sums_of_the_gathered_terms() {
        let mut s = IndexSums::default();
        for (m, len) in [(1usize, 37usize), (1, 3), (3, 41), (4, 8), (7, 5), (2, 100)] {
            let idx: Vec<usize> = (0..len).map(|e| (e * e + 3 * e) % m).collect();
            let z: Vec<f64> = (0..len).map(|e| (e as f64 * 0.77).sin() * 1e3).collect();
            let mut out: Vec<f64> = (0..m).map(|p| p as f64 * 0.25).collect();
            let before = out.clone();
            sum_by_index(&mut out, &z, &idx, &mut s);
            for p in 0..m {
                let terms: Vec<f64> = idx
                    .iter()
                    .zip(&z)
                    .filter(|(&q, _)| q == p)
                    .map(|(_, &v)| v)
                    .collect();
                let want = before[p] + sum(&terms);
                assert_eq!(
                    out[p].to_bits(),
                    want.to_bits(),
                    "{m} indices, {len} terms, index {p}"
                );
                let plain = terms.iter().fold(before[p], |t, v| t + v);
                assert!((out[p] - plain).abs() <= 1e-9 * (1.0 + plain.abs()));
            }
        }
    }

    #[test]
    #[should_panic(expected = "an index outside the sums")]
    fn an_index_outside_the_sums_is_refused() {
        sum_by_index(&mut [0.0; 2], &[1.0], &[2], &mut IndexSums::default());
    }

    #[test]
    #[should_panic(expected = "an edge end outside the nodes")]
    fn an_end_outside_the_nodes_is_refused() {
        let mut dst = vec![0.0; 2];
        gather_rows(&mut dst, &[1.0, 2.0], &[0, 2], Gather::Set);
    }
}
