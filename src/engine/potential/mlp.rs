//! The MLPs' passes on (value, tangent) pairs, one hidden layer each: the
//! affine maps and their transposes, squareplus's reverse through a pair,
//! and each MLP forward, tangent, input-gradient and dual reverse pass.

use super::App;
use super::{room, slots};
use crate::engine::dense::{
    dot, dots, squareplus_in_place, sum, times_squareplus_grad, Linear, Mlp,
};

/// `y` (`out × r`) = Wᵀx, plus the bias when `bias`; `x` is `inp × r`.
#[inline(always)]
#[allow(clippy::inline_always)]
pub(super) fn affine(th: &[f64], l: &Linear, x: &[f64], r: usize, y: &mut [f64], bias: bool) {
    let y = &mut y[..l.out * r];
    for (j, yj) in y.chunks_exact_mut(r).enumerate() {
        yj.fill(if bias { th[l.b + j] } else { 0.0 });
    }
    for (i, xi) in x[..l.inp * r].chunks_exact(r).enumerate() {
        let wi = &th[l.w + i * l.out..][..l.out];
        for (yj, &wv) in y.chunks_exact_mut(r).zip(wi) {
            for (yv, xv) in yj.iter_mut().zip(xi) {
                *yv += wv * xv;
            }
        }
    }
}

/// `gx` (`inp × r`) = W gy.
#[inline(always)]
#[allow(clippy::inline_always)]
pub(super) fn affine_t(th: &[f64], l: &Linear, gy: &[f64], r: usize, gx: &mut [f64]) {
    for (i, gxi) in gx[..l.inp * r].chunks_exact_mut(r).enumerate() {
        gxi.fill(0.0);
        let wi = &th[l.w + i * l.out..][..l.out];
        for (gyj, &wv) in gy[..l.out * r].chunks_exact(r).zip(wi) {
            for (gv, yv) in gxi.iter_mut().zip(gyj) {
                *gv += wv * yv;
            }
        }
    }
}

/// ∂W += x gyᵀ, and ∂b += Σ_rows gy when `bias`.
#[inline(always)]
#[allow(clippy::inline_always)]
pub(super) fn affine_w(g: &mut [f64], l: &Linear, x: &[f64], gy: &[f64], r: usize, bias: bool) {
    let gy = &gy[..l.out * r];
    if bias {
        for (j, gyj) in gy.chunks_exact(r).enumerate() {
            g[l.b + j] += sum(gyj);
        }
    }
    let gyj = |j: usize| &gy[j * r..(j + 1) * r];
    for (i, xi) in x[..l.inp * r].chunks_exact(r).enumerate() {
        let gw = &mut g[l.w + i * l.out..][..l.out];
        // Eight, then four outputs per pass over x_i (the AVX2 dots).
        let mut j = 0;
        while j + 8 <= l.out {
            let d: [f64; 8] = dots(xi, std::array::from_fn(|o| gyj(j + o)));
            gw[j..j + 8].iter_mut().zip(d).for_each(|(g, d)| *g += d);
            j += 8;
        }
        while j + 4 <= l.out {
            let d: [f64; 4] = dots(xi, std::array::from_fn(|o| gyj(j + o)));
            gw[j..j + 4].iter_mut().zip(d).for_each(|(g, d)| *g += d);
            j += 4;
        }
        for (o, gv) in gw.iter_mut().enumerate().skip(j) {
            *gv += dot(xi, gyj(o));
        }
    }
}

/// Through y = sqp(z) in reverse for a (value, tangent) pair: from the
/// adjoints (ȳ, ẏ̄) in `(g, gt)` to (z̄, ż̄) in place, given y and ẏ:
/// ż̄ = s'·ẏ̄ and z̄ = s'·ȳ + s''·ż·ẏ̄, where ż = ẏ / s' and, from y alone,
/// s' = y²/(1 + y²) and s''/s' = 2y/(1 + y²)².
#[inline(always)]
#[allow(clippy::inline_always)]
pub(super) fn act_reverse(y: &[f64], yt: &[f64], g: &mut [f64], gt: &mut [f64]) {
    for (((&y, &yt), gv), gtv) in y.iter().zip(yt).zip(g.iter_mut()).zip(gt.iter_mut()) {
        let q = 1.0 / (1.0 + y * y);
        let s1 = y * y * q;
        *gv = s1 * *gv + 2.0 * y * q * q * yt * *gtv;
        *gtv *= s1;
    }
}

/// `y = mlp(x)` over `r` rows (none: nothing to do), keeping the hidden
/// activations in `app`.
#[inline(always)]
#[allow(clippy::inline_always)]
pub(super) fn mlp_forward(m: &Mlp, th: &[f64], x: &[f64], r: usize, app: &mut App, y: &mut [f64]) {
    if r == 0 {
        return;
    }
    let k = m.layers.len();
    slots(&mut app.a, k - 1);
    slots(&mut app.at, k - 1);
    for (li, l) in m.layers.iter().enumerate() {
        let (done, rest) = app.a.split_at_mut(li);
        let inp = if li == 0 { x } else { &done[li - 1][..] };
        if li + 1 == k {
            affine(th, l, inp, r, y, true);
        } else {
            let out = room(&mut rest[0], l.out * r);
            affine(th, l, inp, r, out, true);
            squareplus_in_place(out);
        }
    }
}

/// `gx = (∂y/∂x)ᵀ gy` from the activations [`mlp_forward`] kept (inputs
/// only: no parameter gradients). `s` is scratch.
#[inline(always)]
#[allow(clippy::inline_always)]
pub(super) fn mlp_input_grad(
    m: &Mlp,
    th: &[f64],
    app: &App,
    gy: &[f64],
    r: usize,
    gx: &mut [f64],
    s: &mut [Vec<f64>; 4],
) {
    if r == 0 {
        return;
    }
    let [cur, next, ..] = s;
    let mut first = true;
    for li in (1..m.layers.len()).rev() {
        let l = &m.layers[li];
        let g: &[f64] = if first { gy } else { &cur[..l.out * r] };
        let n = room(next, l.inp * r);
        affine_t(th, l, g, r, n);
        times_squareplus_grad(n, &app.a[li - 1][..l.inp * r]);
        std::mem::swap(cur, next);
        first = false;
    }
    let g: &[f64] = if first { gy } else { cur };
    affine_t(th, &m.layers[0], g, r, gx);
}

/// The tangent `ẏ = (∂y/∂x) ẋ`, keeping the hidden tangents in `app`.
#[inline(always)]
#[allow(clippy::inline_always)]
pub(super) fn mlp_tangent(
    m: &Mlp,
    th: &[f64],
    xt: &[f64],
    r: usize,
    app: &mut App,
    yt: &mut [f64],
) {
    if r == 0 {
        return;
    }
    let k = m.layers.len();
    for (li, l) in m.layers.iter().enumerate() {
        let (done, rest) = app.at.split_at_mut(li);
        let inp = if li == 0 { xt } else { &done[li - 1][..] };
        if li + 1 == k {
            affine(th, l, inp, r, yt, false);
        } else {
            let out = room(&mut rest[0], l.out * r);
            affine(th, l, inp, r, out, false);
            times_squareplus_grad(out, &app.a[li][..l.out * r]);
        }
    }
}

/// The reverse pass of the pair (y, ẏ) = (mlp(x), (∂y/∂x) ẋ): from the
/// adjoints (ȳ, ẏ̄) over `r` rows, accumulates every weight's gradient into
/// `g` and, when `gx` is given, writes (x̄, ẋ̄) there. `s` is scratch.
#[inline(always)]
#[allow(clippy::inline_always)]
pub(super) fn mlp_dual_reverse(
    m: &Mlp,
    (th, g): (&[f64], &mut [f64]),
    (x, xt): (&[f64], &[f64]),
    app: &App,
    (gy, gyt, r): (&[f64], &[f64], usize),
    gx: Option<(&mut [f64], &mut [f64])>,
    s: &mut [Vec<f64>; 4],
) {
    if r == 0 {
        // No rows (a graph without edges): nothing flows.
        return;
    }
    let [c, ct, n, nt] = s;
    let mut first = true;
    for li in (0..m.layers.len()).rev() {
        let l = &m.layers[li];
        let (gv, gt): (&[f64], &[f64]) = if first {
            (gy, gyt)
        } else {
            (&c[..l.out * r], &ct[..l.out * r])
        };
        let (xi, xti) = if li == 0 {
            (x, xt)
        } else {
            (&app.a[li - 1][..l.inp * r], &app.at[li - 1][..l.inp * r])
        };
        affine_w(g, l, xi, gv, r, true);
        affine_w(g, l, xti, gt, r, false);
        if li > 0 {
            let (nv, ntv) = (room(n, l.inp * r), room(nt, l.inp * r));
            affine_t(th, l, gv, r, nv);
            affine_t(th, l, gt, r, ntv);
            act_reverse(xi, xti, nv, ntv);
            std::mem::swap(c, n);
            std::mem::swap(ct, nt);
            first = false;
        } else if let Some((gxv, gxt)) = gx {
            affine_t(th, l, gv, r, gxv);
            affine_t(th, l, gt, r, gxt);
            return;
        }
    }
}
