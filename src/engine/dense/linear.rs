//! One linear layer on the flat parameter vector: the tiled forward kernel
//! ([`dense_tile`]) and the reverse pass into ∂L/∂W, ∂L/∂b and ∂L/∂x.

use super::{dot, dots, squareplus_slice, sum};

/// One linear layer: offsets of its weight `[inp, out]` (row-major) and bias
/// in the flat parameter vector.
#[derive(Clone, Debug)]
pub(crate) struct Linear {
    pub(crate) w: usize,
    pub(crate) b: usize,
    pub(crate) inp: usize,
    pub(crate) out: usize,
}

impl Linear {
    /// `y = Wᵀ [a; c] + b` over `r` rows; the first `a.len() / r` input
    /// features come from `a`, the rest from `c` (a concatenation without a
    /// copy). The reference of [`dense_tile`].
    #[cfg(test)]
    pub(super) fn forward(&self, th: &[f64], a: &[f64], c: &[f64], r: usize, y: &mut [f64]) {
        let na = a.len() / r;
        let w = &th[self.w..self.w + self.inp * self.out];
        for (j, &bj) in th[self.b..self.b + self.out].iter().enumerate() {
            y[j * r..(j + 1) * r].fill(bj);
        }
        for (i, wrow) in w.chunks_exact(self.out).enumerate() {
            let xi = if i < na {
                &a[i * r..(i + 1) * r]
            } else {
                &c[(i - na) * r..(i - na + 1) * r]
            };
            for (j, &wv) in wrow.iter().enumerate() {
                for (yv, xv) in y[j * r..(j + 1) * r].iter_mut().zip(xi) {
                    *yv = wv.mul_add(*xv, *yv);
                }
            }
        }
    }

    /// Reverse pass: accumulates ∂L/∂W and ∂L/∂b into `g` from `gy` (`out × r`)
    /// and the inputs `[a; c]`; when `gx` is given, accumulates ∂L/∂[a; c]
    /// into its two parts, or with `set` writes it there (the bits of
    /// accumulating into zeros, without zeroing first).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(super) fn backward(
        &self,
        th: &[f64],
        g: &mut [f64],
        a: &[f64],
        c: &[f64],
        r: usize,
        gy: &[f64],
        mut gx: Option<(&mut [f64], &mut [f64])>,
        set: bool,
    ) {
        debug_assert!(self.out > 0, "a layer has outputs");
        let na = a.len() / r;
        // An empty `g`: input gradients only (planning's reverse pass).
        let params = !g.is_empty();
        if params {
            for j in 0..self.out {
                g[self.b + j] += sum(&gy[j * r..(j + 1) * r]);
            }
        }
        let gyj = |j: usize| &gy[j * r..(j + 1) * r];
        let x = |i: usize| {
            if i < na {
                &a[i * r..(i + 1) * r]
            } else {
                &c[(i - na) * r..(i - na + 1) * r]
            }
        };
        // Outputs in blocks of four per input row; the rest below.
        let blocked = self.out - self.out % 4;
        for i in 0..self.inp {
            let xi = x(i);
            if params {
                let gw = &mut g[self.w + i * self.out..self.w + (i + 1) * self.out];
                blocked_weight_grads(gw, xi, gyj, blocked);
            }
            if let Some((ga, gc)) = gx.as_mut() {
                let gxi = if i < na {
                    &mut ga[i * r..(i + 1) * r]
                } else {
                    &mut gc[(i - na) * r..(i - na + 1) * r]
                };
                let w = &th[self.w + i * self.out..self.w + (i + 1) * self.out];
                input_grad_row(gxi, w, gyj, set);
            }
        }
        // The outputs past the blocks of four (the fifth of a 5-wide layer):
        // four input rows per pass over the output's gradient. A product is
        // the same either way round, so each sum is still `dot`'s bits.
        if params {
            for j in blocked..self.out {
                let at = |i: usize| self.w + i * self.out + j;
                let mut i = 0;
                while i + 4 <= self.inp {
                    let d: [f64; 4] = dots(gyj(j), std::array::from_fn(|o| x(i + o)));
                    for (o, dv) in d.iter().enumerate() {
                        g[at(i + o)] += dv;
                    }
                    i += 4;
                }
                for i in i..self.inp {
                    g[at(i)] += dot(x(i), gyj(j));
                }
            }
        }
    }
}

/// ∂L/∂W of one input row `xi` for the first `blocked` outputs (a multiple
/// of four) into `gw`: eight (then four) outputs per pass over the row, each
/// sum the one `dot` forms, in its order (the same bits).
#[inline(always)]
fn blocked_weight_grads<'a>(
    gw: &mut [f64],
    xi: &[f64],
    gyj: impl Fn(usize) -> &'a [f64] + Copy,
    blocked: usize,
) {
    let mut j = 0;
    while j + 8 <= blocked {
        let d: [f64; 8] = dots(xi, std::array::from_fn(|o| gyj(j + o)));
        for (o, dv) in d.iter().enumerate() {
            gw[j + o] += dv;
        }
        j += 8;
    }
    while j + 4 <= blocked {
        let d: [f64; 4] = dots(xi, std::array::from_fn(|o| gyj(j + o)));
        for (o, dv) in d.iter().enumerate() {
            gw[j + o] += dv;
        }
        j += 4;
    }
}

/// ∂L/∂x_i of one input row from the row `w` of its weights (one per
/// output): eight outputs per pass over `gxi`, then the rest in one pass;
/// each element added to in the order of one output at a time (the same
/// bits). With `set`, written, not added to.
#[inline(always)]
fn input_grad_row<'a>(
    gxi: &mut [f64],
    w: &[f64],
    gyj: impl Fn(usize) -> &'a [f64] + Copy,
    set: bool,
) {
    let out = w.len();
    let (mut j, mut set) = (0, set);
    while j + 8 <= out {
        add_outputs::<8>(gxi, &w[j..], |o| gyj(j + o), set);
        (j, set) = (j + 8, false);
    }
    let rest = |o| gyj(j + o);
    match out - j {
        1 => add_outputs::<1>(gxi, &w[j..], rest, set),
        2 => add_outputs::<2>(gxi, &w[j..], rest, set),
        3 => add_outputs::<3>(gxi, &w[j..], rest, set),
        4 => add_outputs::<4>(gxi, &w[j..], rest, set),
        5 => add_outputs::<5>(gxi, &w[j..], rest, set),
        6 => add_outputs::<6>(gxi, &w[j..], rest, set),
        7 => add_outputs::<7>(gxi, &w[j..], rest, set),
        _ => {}
    }
}

/// `gx[k] += Σ_o w[o]·gy(o)[k]` for `N` outputs in one pass, adding output
/// by output in their order (the bits of one pass per output); with `set`,
/// `gx[k]` is taken as zero, not read.
#[inline(always)]
fn add_outputs<'a, const N: usize>(
    gx: &mut [f64],
    w: &[f64],
    gy: impl Fn(usize) -> &'a [f64],
    set: bool,
) {
    let gs: [&[f64]; N] = std::array::from_fn(|o| &gy(o)[..gx.len()]);
    let ws: [f64; N] = std::array::from_fn(|o| w[o]);
    for (k, gv) in gx.iter_mut().enumerate() {
        let mut v = if set { 0.0 } else { *gv };
        for o in 0..N {
            v = ws[o].mul_add(gs[o][k], v);
        }
        *gv = v;
    }
}

/// One layer on a tile: `y[j] = b[j] + Σ_i w[i][j]·x[i]`, summed in the
/// order of [`Linear::forward`] (bias, then inputs in turn), `OUTS`
/// outputs at a time (the path's [`OUTS_WIDE`] or [`OUTS_AVX2`]: any count
/// gives the same bits, since each output's sum keeps its order), then
/// squareplus on each block of outputs when `act` is set: its square roots
/// overlap the next block's multiply-adds, where a pass over the whole tile
/// after the layer left the divider and the FMA units each waiting on the
/// other. The blocked loop and the one-output tail are written out apart on
/// purpose: folded into one const-generic helper, the
/// 500-spring rollout ran at half the speed (4.6–6.3k against 9.0–11.9k
/// steps/s, interleaved, 2026-12-02).
#[inline(always)]
pub(super) fn dense_tile<const TILE: usize, const OUTS: usize>(
    l: &Linear,
    th: &[f64],
    x: &[f64],
    y: &mut [f64],
    act: bool,
) {
    let w = &th[l.w..l.w + l.inp * l.out];
    let b = &th[l.b..l.b + l.out];
    let lane = |x: &[f64], i: usize| -> [f64; TILE] {
        x[i * TILE..(i + 1) * TILE].try_into().expect("a tile")
    };
    let mut j = 0;
    while j + OUTS <= l.out {
        let mut acc = [[0.0; TILE]; OUTS];
        for (o, row) in acc.iter_mut().enumerate() {
            *row = [b[j + o]; TILE];
        }
        for i in 0..l.inp {
            let xi = lane(x, i);
            for (o, row) in acc.iter_mut().enumerate() {
                let wv = w[i * l.out + j + o];
                for k in 0..TILE {
                    row[k] = wv.mul_add(xi[k], row[k]);
                }
            }
        }
        for (o, row) in acc.iter().enumerate() {
            y[(j + o) * TILE..(j + o + 1) * TILE].copy_from_slice(row);
        }
        if act {
            squareplus_slice(&mut y[j * TILE..(j + OUTS) * TILE]);
        }
        j += OUTS;
    }
    for j in j..l.out {
        let mut row = [b[j]; TILE];
        for i in 0..l.inp {
            let (xi, wv) = (lane(x, i), w[i * l.out + j]);
            for k in 0..TILE {
                row[k] = wv.mul_add(xi[k], row[k]);
            }
        }
        y[j * TILE..(j + 1) * TILE].copy_from_slice(&row);
        if act {
            squareplus_slice(&mut y[j * TILE..(j + 1) * TILE]);
        }
    }
}
