//! Dense layers and MLPs on a flat parameter vector, feature-major
//! (`x[f·r + row]`, rows innermost), with the forward pass recording the
//! hidden activations it needs and a hand-written reverse pass.
// `#[inline(always)]` on purpose: the loops must be inlined into the AVX2
// (`target_feature`) copies to be compiled for AVX2 at all.
#![allow(clippy::inline_always)]

use std::sync::atomic::{AtomicU8, Ordering};

/// The widest vectors this CPU offers the passes below, with fused
/// multiply-adds (the forward layers use them on every path, so every path
/// gives the same bits; without FMA hardware the portable path's `mul_add`
/// is a slow library call, on x86-64 CPUs older than 2013 only).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Simd {
    /// AVX-512F and FMA.
    Avx512,
    /// AVX2 and FMA.
    Avx2,
    /// Whatever the target was compiled for.
    Portable,
}

/// The [`Simd`] path for this CPU, or a narrower one named by the
/// environment variable `MCGNODE_SIMD` (`avx2`, `portable`): every path
/// gives the same bits, so this only compares their speeds on one machine.
#[inline(always)]
pub(crate) fn simd() -> Simd {
    static PATH: AtomicU8 = AtomicU8::new(0);
    let chosen = once(&PATH, || {
        chosen(detected(), std::env::var("MCGNODE_SIMD").ok().as_deref()) as u8
    });
    match chosen {
        c if c == Simd::Avx512 as u8 => Simd::Avx512,
        c if c == Simd::Avx2 as u8 => Simd::Avx2,
        _ => Simd::Portable,
    }
}

/// A choice made once per process and kept in `cell` (0: not made yet, else
/// the choice plus one). A relaxed load per call (every layer asks); racing
/// first calls make the same choice.
#[inline(always)]
fn once(cell: &AtomicU8, choose: impl FnOnce() -> u8) -> u8 {
    match cell.load(Ordering::Relaxed) {
        0 => {
            let c = choose();
            cell.store(c + 1, Ordering::Relaxed);
            c
        }
        c => c - 1,
    }
}

/// The path `MCGNODE_SIMD` asks for on a CPU whose widest is `best`; a
/// value it does not know is said on stderr, not ignored silently.
fn chosen(best: Simd, asked: Option<&str>) -> Simd {
    match asked {
        None | Some("" | "avx512") => best,
        Some("avx2") if best == Simd::Portable => best,
        Some("avx2") => Simd::Avx2,
        Some("portable") => Simd::Portable,
        Some(other) => {
            eprintln!(
                "warning: MCGNODE_SIMD={other:?} is not one of avx512, avx2, portable; \
                 using the widest path this CPU has"
            );
            best
        }
    }
}

/// The widest [`Simd`] path this CPU supports.
fn detected() -> Simd {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("fma") {
            if std::is_x86_feature_detected!("avx512f") {
                return Simd::Avx512;
            }
            if std::is_x86_feature_detected!("avx2") {
                return Simd::Avx2;
            }
        }
    }
    Simd::Portable
}

/// How squareplus takes its square root √(x² + 4). Chosen once per process
/// from the CPU, never from the vector path, so that every path of one
/// machine gives the same bits (the roots of the two kinds may differ in the
/// last bit; both are within an ulp of the exact root).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Root {
    /// The correctly rounded f64 root: one instruction. Faster where the
    /// divider takes f64 roots at about its f32 rate (AMD Zen 2 with AVX2:
    /// the 500-spring rollout 13.1k → 18.4k steps/s, interleaved,
    /// 2026-12-04).
    Exact,
    /// [`sqrt_via_f32`]: faster where f64 vector roots are much slower than
    /// f32 roots and divisions (the Intel Xeon with AVX-512, where it was
    /// measured).
    ViaF32,
}

/// The [`Root`] for this CPU: [`Root::ViaF32`] on CPUs with AVX-512F,
/// [`Root::Exact`] elsewhere, or the one named by the environment variable
/// `MCGNODE_ROOT` (`exact`, `f32`) to compare them on one machine.
#[inline(always)]
pub(crate) fn root() -> Root {
    static ROOT: AtomicU8 = AtomicU8::new(0);
    let chosen = once(&ROOT, || {
        let best = if detected() == Simd::Avx512 {
            Root::ViaF32
        } else {
            Root::Exact
        };
        chosen_root(best, std::env::var("MCGNODE_ROOT").ok().as_deref()) as u8
    });
    if chosen == Root::Exact as u8 {
        Root::Exact
    } else {
        Root::ViaF32
    }
}

/// The root `MCGNODE_ROOT` asks for, else `best`; a value it does not know
/// is said on stderr, not ignored silently.
fn chosen_root(best: Root, asked: Option<&str>) -> Root {
    match asked {
        None | Some("") => best,
        Some("exact") => Root::Exact,
        Some("f32") => Root::ViaF32,
        Some(other) => {
            eprintln!(
                "warning: MCGNODE_ROOT={other:?} is not one of exact, f32; \
                 using this CPU's choice ({best:?})"
            );
            best
        }
    }
}

/// squareplus'(z) from the activation y = squareplus(z): since
/// z = y − 1/y and √(z² + 4) = y + 1/y, the derivative ½(1 + z/√(z²+4)) is
/// y²/(1 + y²). Saves storing pre-activations.
#[inline(always)]
pub(crate) fn squareplus_grad_from_output(y: f64) -> f64 {
    let y2 = y * y;
    y2 / (1.0 + y2)
}

/// Applies squareplus in place, compiled for the widest vectors the CPU has
/// (its fused multiply-adds are library calls otherwise). Within an ulp of
/// [`crate::gnode::mlp::squareplus_f64`]: the root is [`root`]'s.
pub(crate) fn squareplus_in_place(x: &mut [f64]) {
    match simd() {
        // SAFETY: the CPU supports AVX-512F and FMA (`simd` checked).
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => unsafe { squareplus_avx512(x) },
        // SAFETY: the CPU supports AVX2 and FMA (`simd` checked).
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { squareplus_avx2(x) },
        _ => squareplus_slice(x),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
unsafe fn squareplus_avx512(x: &mut [f64]) {
    squareplus_slice(x);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn squareplus_avx2(x: &mut [f64]) {
    squareplus_slice(x);
}

/// [`squareplus_in_place`] for callers already compiled for their vectors.
#[inline(always)]
fn squareplus_slice(x: &mut [f64]) {
    // A plain loop per root kind: `for_each`'s closure was compiled out of
    // line, without the caller's FMA, into library calls; the kind is
    // matched once per slice, not per value.
    match root() {
        Root::Exact => {
            for v in x.iter_mut() {
                *v = squareplus_by(Root::Exact, *v);
            }
        }
        Root::ViaF32 => {
            for v in x.iter_mut() {
                *v = squareplus_by(Root::ViaF32, *v);
            }
        }
    }
}

/// squareplus(x) = (x + √(x² + 4)) / 2 with [`root`]'s root.
#[cfg(test)]
pub(crate) fn squareplus_fast(x: f64) -> f64 {
    squareplus_by(root(), x)
}

/// squareplus(x) = (x + √(x² + 4)) / 2 with the root of kind `root`
/// (|x| ≥ 1e15: √(x² + 4) is |x| in f64, and x² may overflow).
#[inline(always)]
fn squareplus_by(root: Root, x: f64) -> f64 {
    let ax = x.abs();
    let r = if ax < 1e15 {
        let y = x * x + 4.0;
        match root {
            Root::Exact => y.sqrt(),
            Root::ViaF32 => sqrt_via_f32(y),
        }
    } else {
        ax
    };
    // Halves first (exact), so that x near f64::MAX does not overflow.
    x.mul_add(0.5, 0.5 * r)
}

/// √y for 1 ≤ y < 1e30, within an ulp of `y.sqrt()`: the f32 root refined by
/// two Newton steps in f64 (each squares the relative error, 2⁻²⁴ → 2⁻⁴⁸ →
/// rounding) with an f32 reciprocal. Square roots were most of an inference
/// step with 16-wide layers, and on the Intel Xeon f64 vector roots were
/// several times slower than f32 roots and divisions ([`Root::ViaF32`]).
/// Every operation is an IEEE one (rounded exactly), so every vector width
/// gives the same bits.
#[inline(always)]
fn sqrt_via_f32(y: f64) -> f64 {
    #[allow(clippy::cast_possible_truncation)] // the f32 estimate, on purpose
    let yf = y as f32;
    let rf = yf.sqrt();
    let (r0, half_inv) = (f64::from(rf), f64::from(0.5 / rf));
    let r1 = (-r0).mul_add(r0, y).mul_add(half_inv, r0);
    (-r1).mul_add(r1, y).mul_add(half_inv, r1)
}

/// `g ← g ⊙ squareplus'` given the activations `y` of the same shape.
#[inline(always)]
pub(crate) fn times_squareplus_grad(g: &mut [f64], y: &[f64]) {
    for (gv, yv) in g.iter_mut().zip(y) {
        *gv *= squareplus_grad_from_output(*yv);
    }
}

/// Σ a_i b_i with four partial sums, so the loop vectorises (a fixed order:
/// results are reproducible), in fused multiply-adds (exactly rounded, so
/// every path gives the same bits; one instruction where a multiply and an
/// add took two of the two floating-point ports' slots).
#[inline(always)]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail = dot_tail(ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            acc[k] = x[k].mul_add(y[k], acc[k]);
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// The last (fewer than four) products of a [`dot`].
#[inline(always)]
fn dot_tail(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |t, (x, y)| x.mul_add(*y, t))
}

/// [`dot`] of `a` with `N` vectors at once (4 or 8): each result is
/// computed as `dot` computes it (the same bits); the sums run side by side,
/// so a pass over `a` feeds `N` independent chains. Eight chains hide the
/// adds' latency that four leave exposed (4-cycle adds, one per chain per
/// pass).
#[inline(always)]
pub(crate) fn dots<const N: usize>(a: &[f64], b: [&[f64]; N]) -> [f64; N] {
    #[cfg(target_arch = "x86_64")]
    if simd() != Simd::Portable {
        // SAFETY: the CPU supports AVX2 and FMA (`simd` checked).
        return unsafe { dots_avx2(a, b) };
    }
    const { assert!(N % 4 == 0, "dots takes 4 or 8 vectors") };
    let mut out = [0.0; N];
    for k in (0..N).step_by(4) {
        out[k..k + 4].copy_from_slice(&dot4_any(a, [b[k], b[k + 1], b[k + 2], b[k + 3]]));
    }
    out
}

/// [`dots`] of four vectors.
#[cfg(test)]
fn dot4(a: &[f64], b: [&[f64]; 4]) -> [f64; 4] {
    dots(a, b)
}

/// [`dots`] in AVX2 registers: the same fused multiply-adds in the same
/// order as [`dot4_any`], so the same bits. The compiler vectorised the
/// portable form into 2-wide registers and lane shuffles, about half of a
/// GNS reverse pass.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn dots_avx2<const N: usize>(a: &[f64], b: [&[f64]; N]) -> [f64; N] {
    use std::arch::x86_64::{__m256d, _mm256_storeu_pd};
    use std::arch::x86_64::{_mm256_fmadd_pd, _mm256_loadu_pd, _mm256_setzero_pd};
    let n = a.len();
    let m = n - n % 4;
    let b = b.map(|v| &v[..n]);
    let mut s = [_mm256_setzero_pd(); N];
    let mut i = 0;
    while i < m {
        // SAFETY: i + 4 <= m <= n, the length of `a` and of each `b`.
        unsafe {
            let x = _mm256_loadu_pd(a.as_ptr().add(i));
            for (acc, v) in s.iter_mut().zip(b) {
                *acc = _mm256_fmadd_pd(x, _mm256_loadu_pd(v.as_ptr().add(i)), *acc);
            }
        }
        i += 4;
    }
    let lanes = |v: __m256d| {
        let mut l = [0.0; 4];
        // SAFETY: `l` holds four f64.
        unsafe { _mm256_storeu_pd(l.as_mut_ptr(), v) };
        l
    };
    let mut out = [0.0; N];
    for (o, (acc, v)) in s.into_iter().zip(b).enumerate() {
        let acc = lanes(acc);
        out[o] = (acc[0] + acc[1]) + (acc[2] + acc[3]) + dot_tail(&a[m..], &v[m..]);
    }
    out
}

/// Four [`dot`]s side by side, portably.
#[inline(always)]
fn dot4_any(a: &[f64], b: [&[f64]; 4]) -> [f64; 4] {
    let m = a.len() - a.len() % 4;
    // Four accumulators of their own (an array of them compiled to lane
    // shuffles: 5-spring GNS epoch 135 ms against 120 ms this way).
    let (mut s0, mut s1, mut s2, mut s3) = ([0.0; 4], [0.0; 4], [0.0; 4], [0.0; 4]);
    let chunks = a[..m]
        .chunks_exact(4)
        .zip(b[0][..m].chunks_exact(4))
        .zip(b[1][..m].chunks_exact(4))
        .zip(b[2][..m].chunks_exact(4))
        .zip(b[3][..m].chunks_exact(4));
    for ((((x, y0), y1), y2), y3) in chunks {
        for k in 0..4 {
            s0[k] = x[k].mul_add(y0[k], s0[k]);
            s1[k] = x[k].mul_add(y1[k], s1[k]);
            s2[k] = x[k].mul_add(y2[k], s2[k]);
            s3[k] = x[k].mul_add(y3[k], s3[k]);
        }
    }
    let mut out = [0.0; 4];
    for (o, (acc, v)) in [s0, s1, s2, s3].iter().zip(b).enumerate() {
        out[o] = (acc[0] + acc[1]) + (acc[2] + acc[3]) + dot_tail(&a[m..], &v[m..]);
    }
    out
}

/// Σ a_i, as [`dot`].
#[inline(always)]
pub(crate) fn sum(a: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let ca = a.chunks_exact(4);
    let tail: f64 = ca.remainder().iter().sum();
    for x in ca {
        for k in 0..4 {
            acc[k] += x[k];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

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
    fn forward(&self, th: &[f64], a: &[f64], c: &[f64], r: usize, y: &mut [f64]) {
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
    fn backward(
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
            // Eight (then four) outputs per pass over the row: each sum is
            // the one `dot` forms, in its order (the same bits).
            if params {
                let gw = &mut g[self.w + i * self.out..self.w + (i + 1) * self.out];
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
            if let Some((ga, gc)) = gx.as_mut() {
                let gxi = if i < na {
                    &mut ga[i * r..(i + 1) * r]
                } else {
                    &mut gc[(i - na) * r..(i - na + 1) * r]
                };
                let w = &th[self.w + i * self.out..self.w + (i + 1) * self.out];
                // Eight outputs per pass over ∂L/∂x_i, then the rest in one
                // pass; each element added to in the order of one output at
                // a time (the same bits).
                let (mut j, mut set) = (0, set);
                while j + 8 <= self.out {
                    add_outputs::<8>(gxi, &w[j..], |o| gyj(j + o), set);
                    (j, set) = (j + 8, false);
                }
                let rest = |o| gyj(j + o);
                match self.out - j {
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
fn dense_tile<const TILE: usize, const OUTS: usize>(
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

/// An MLP's output, feature-major (`y[j·r + row]`), written tile by tile
/// through a pointer, so that two threads can fill disjoint row ranges of
/// one buffer ([`Mlp::forward_part`]); it borrows the buffer for `'a`.
#[derive(Clone, Copy)]
pub(crate) struct Out<'a> {
    ptr: *mut f64,
    len: usize,
    r: usize,
    /// Row of `y` that the MLP's row 0 goes to (a block of rows computed
    /// from block-sized inputs, [`super::fused`]).
    off: usize,
    _buffer: std::marker::PhantomData<&'a mut [f64]>,
}

// SAFETY: an `Out` is a mutable borrow of an f64 buffer handed to threads
// that write disjoint rows of it (each row range has one writer; see
// `Mlp::forward_part`), and the borrow outlives them (scoped joins).
unsafe impl Send for Out<'_> {}
// SAFETY: as for Send: shared, it is only written at disjoint rows.
unsafe impl Sync for Out<'_> {}

impl<'a> Out<'a> {
    /// The output buffer `y` of `r` rows per feature.
    pub(crate) fn new(y: &'a mut [f64], r: usize) -> Self {
        Self {
            ptr: y.as_mut_ptr(),
            len: y.len(),
            r,
            off: 0,
            _buffer: std::marker::PhantomData,
        }
    }

    /// The same buffer with the MLP's row `t` written at row `off + t`.
    pub(crate) fn shifted(self, off: usize) -> Self {
        Self { off, ..self }
    }

    /// Writes `src` (at most `T` values) at rows `t0..` of feature `j`.
    #[inline(always)]
    fn put<const T: usize>(self, j: usize, t0: usize, src: &[f64]) {
        let at = j * self.r + self.off + t0;
        assert!(
            at + src.len() <= self.len && src.len() <= T,
            "an MLP output out of its buffer"
        );
        // SAFETY: in bounds (checked); no other thread writes these rows
        // (`Mlp::forward_part`'s contract), and the buffer is borrowed.
        unsafe {
            // A full tile's length known when compiling: moves in registers,
            // not a memcpy call per 16 values.
            if src.len() == T {
                self.ptr.add(at).copy_from_nonoverlapping(src.as_ptr(), T);
            } else {
                // Value by value: a memcpy call costs a short copy more.
                for (k, &x) in src.iter().enumerate() {
                    self.ptr.add(at + k).write_volatile(x);
                }
            }
        };
    }
}

/// An MLP with squareplus between layers and a linear output.
#[derive(Clone, Debug)]
pub(crate) struct Mlp {
    pub(crate) layers: Vec<Linear>,
}

/// The hidden activations of one MLP application (one buffer per hidden
/// layer), or, for inference, none: then only a tile's scratch.
#[derive(Clone, Debug, Default)]
pub(crate) struct Tape {
    hidden: Vec<Vec<f64>>,
    /// Two tiles of `width × TILE` (inference only).
    tile: Vec<f64>,
}

/// Rows an inference pass keeps in registers at once: two 8-lane vectors.
const TILE: usize = 16;

/// The tile for the `rest` rows left: full tiles while more than 8 are
/// left, then 8 or 4 rows, so that a 5-body graph's nodes fill 8 lanes and
/// not 16 (a third of a 16-row tile's square roots were spent on padding).
/// 9–12 rows take one 12-row tile, not an 8- and a 4-row one: one pass
/// through the layers instead of two (the 5-spring rollout's 10 edges: 16.5
/// → 13.9 ms with a 16-row tile, interleaved runs, 2026-12-03), and a
/// quarter fewer padded lanes than 16 (29.4 → 26.2 ms on AMD Zen 2,
/// 2026-12-04).
fn tile_for(rest: usize) -> usize {
    match rest {
        13.. => TILE,
        9..=12 => 12,
        5..=8 => 8,
        _ => 4,
    }
}
/// `dst` (`T` long) ← `src` (at most `T` long), zero-padded. A full tile's
/// length is known when compiling, so it copies in registers: a memcpy and a
/// memset call per input feature and tile cost a GNS epoch 10 %.
#[inline(always)]
fn copy_padded<const T: usize>(dst: &mut [f64], src: &[f64]) {
    let dst: &mut [f64; T] = dst.try_into().expect("a tile");
    if let Ok(full) = <&[f64; T]>::try_from(src) {
        *dst = *full;
    } else {
        // Lane by lane: a memcpy and a memset call per feature cost a small
        // graph's step more than the copy.
        for (k, x) in dst.iter_mut().enumerate() {
            *x = src.get(k).copied().unwrap_or(0.0);
        }
    }
}

/// `dst` ← the first `dst.len()` (at most `T`) values of `src`, as
/// [`copy_padded`] copies.
#[inline(always)]
fn copy_tile<const T: usize>(dst: &mut [f64], src: &[f64]) {
    if let Ok(full) = <&mut [f64; T]>::try_from(&mut *dst) {
        *full = src[..T].try_into().expect("a tile");
    } else {
        dst.copy_from_slice(&src[..dst.len()]);
    }
}

/// Outputs computed together, so that each input tile loaded serves four
/// independent accumulator chains (a chain alone waits on its adds): with
/// 32 vector registers (AVX-512) or the portable path.
const OUTS_WIDE: usize = 4;

/// [`OUTS_WIDE`] for AVX2, whose 16 registers four outputs of a 16-row tile
/// fill with accumulators alone (they spilled to the stack). Two outputs
/// measured on the Zen 2 EPYC, one core, interleaved (2026-12-04): the
/// 16-wide contact rollout 1,247–1,267 → 1,395–1,443 steps/s, the 5-spring
/// epoch 14.0–14.4 → 13.4–14.4 ms; three outputs 1,212–1,249.
const OUTS_AVX2: usize = 2;

/// Tiles of up to this many rows take [`OUTS_WIDE`] outputs on every path:
/// on AVX2 four outputs of 12 rows are 12 accumulators, which fit (the
/// 5-spring rollout, whose 10 edges fill a 12-row tile, 19.1–19.2 →
/// 18.0–18.2 ms with four there; 8 as the bound: 18.9–19.1 ms).
const SMALL_WIDE: usize = 12;

impl Mlp {
    /// Widest layer.
    pub(crate) fn width(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.inp.max(l.out))
            .max()
            .unwrap_or(0)
    }

    /// A tape for up to `rows` rows.
    pub(crate) fn tape(&self, rows: usize) -> Tape {
        let n = self.layers.len().saturating_sub(1);
        Tape {
            hidden: self.layers[..n]
                .iter()
                .map(|l| vec![0.0; l.out * rows])
                .collect(),
            ..self.inference_tape()
        }
    }

    /// A tape that records nothing (inference): only a tile's scratch.
    pub(crate) fn inference_tape(&self) -> Tape {
        let mut tape = Tape::default();
        tape.fit(self);
        tape
    }

    /// `y = mlp([a; c])` over `r` rows, recording hidden activations in
    /// `tape` unless it is an [`Mlp::inference_tape`], compiled for the
    /// widest vectors the CPU has. Every path gives the same bits: each
    /// output is the same sums in the same order (exactly rounded fused
    /// multiply-adds on every path).
    pub(crate) fn forward(
        &self,
        th: &[f64],
        a: &[f64],
        c: &[f64],
        r: usize,
        tape: &mut Tape,
        y: &mut [f64],
    ) {
        // SAFETY: one writer, the whole of `y`, borrowed for the call.
        unsafe { self.forward_part(th, (a, c), r, 0..r, tape, Out::new(y, r), false) };
    }

    /// [`Mlp::forward`] of the rows `rows` of `r` only, into their rows of
    /// `y`, with squareplus applied to the outputs too when `activate` is
    /// set (the same bits as applying it afterwards). Two threads may run
    /// disjoint row ranges of one output at once (`engine::split`) when
    /// neither records and each has its own tape; `rows` must then start
    /// on a multiple of 16, so that the tiles are those of the whole pass.
    ///
    /// # Safety
    /// No other thread writes `rows` of `y` during the call.
    #[allow(clippy::too_many_arguments)]
    pub(crate) unsafe fn forward_part(
        &self,
        th: &[f64],
        ac: (&[f64], &[f64]),
        r: usize,
        rows: std::ops::Range<usize>,
        tape: &mut Tape,
        y: Out<'_>,
        activate: bool,
    ) {
        let at = (r, rows, activate);
        match simd() {
            // SAFETY: the CPU supports AVX-512F and FMA (`simd` checked).
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { self.forward_avx512(th, ac, at, tape, y) },
            // SAFETY: the CPU supports AVX2 and FMA (`simd` checked).
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { self.forward_avx2(th, ac, at, tape, y) },
            _ => self.forward_any::<OUTS_WIDE>(th, ac, at, tape, y),
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,fma")]
    unsafe fn forward_avx512(
        &self,
        th: &[f64],
        ac: (&[f64], &[f64]),
        at: (usize, std::ops::Range<usize>, bool),
        tape: &mut Tape,
        y: Out<'_>,
    ) {
        self.forward_any::<OUTS_WIDE>(th, ac, at, tape, y);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn forward_avx2(
        &self,
        th: &[f64],
        ac: (&[f64], &[f64]),
        at: (usize, std::ops::Range<usize>, bool),
        tape: &mut Tape,
        y: Out<'_>,
    ) {
        self.forward_any::<OUTS_AVX2>(th, ac, at, tape, y);
    }

    /// [`Mlp::forward_part`] a tile of [`TILE`] rows at a time: the tile's
    /// inputs are gathered (zero-padded at the end) and pass through every
    /// layer in the tape's scratch; the valid rows of each hidden layer go
    /// to the tape (when it records), those of the output to `y`. Layer by
    /// layer over all rows ([`Mlp::layerwise`]) would stream every hidden
    /// row through memory once per weight instead.
    #[inline(always)]
    fn forward_any<const OUTS: usize>(
        &self,
        th: &[f64],
        (a, c): (&[f64], &[f64]),
        (r, rows, activate): (usize, std::ops::Range<usize>, bool),
        tape: &mut Tape,
        y: Out<'_>,
    ) {
        if self.layers.is_empty() || r == 0 {
            return;
        }
        let na = a.len() / r;
        let mut t0 = rows.start;
        while t0 < rows.end {
            let rest = rows.end - t0;
            let at = (r, t0, rest, activate);
            t0 += match tile_for(rest) {
                TILE => self.tile::<TILE, OUTS>(th, (a, c, na), at, tape, y),
                12 => self.tile::<12, OUTS>(th, (a, c, na), at, tape, y),
                8 => self.tile::<8, OUTS>(th, (a, c, na), at, tape, y),
                _ => self.tile::<4, OUTS>(th, (a, c, na), at, tape, y),
            };
        }
    }

    /// One tile of up to `T` rows from row `t0` (of `r`, `rest` left in the
    /// range) through every layer (see [`Mlp::forward_any`]); returns the
    /// rows done.
    #[inline(always)]
    fn tile<const T: usize, const OUTS: usize>(
        &self,
        th: &[f64],
        (a, c, na): (&[f64], &[f64], usize),
        (r, t0, rest, activate): (usize, usize, usize, bool),
        tape: &mut Tape,
        y: Out<'_>,
    ) -> usize {
        let len = T.min(rest);
        let record = !tape.hidden.is_empty();
        let half = tape.tile.len() / 2;
        let (mut x, mut h) = tape.tile.split_at_mut(half);
        let first = &self.layers[0];
        for i in 0..first.inp {
            let src = if i < na {
                &a[i * r + t0..i * r + t0 + len]
            } else {
                &c[(i - na) * r + t0..(i - na) * r + t0 + len]
            };
            copy_padded::<T>(&mut x[i * T..(i + 1) * T], src);
        }
        let layers = self.layers.len();
        // Full tiles take squareplus block by block (see `dense_tile`);
        // smaller ones in one pass after the layer, as the per-block loops
        // on 4- and 8-row tiles cost more than they overlap (the 5-pendulum
        // rollout stepped 11 % slower).
        let by_block = T == TILE;
        for (li, l) in self.layers.iter().enumerate() {
            let hidden = li + 1 < layers;
            let act = hidden || activate;
            // The path's count of outputs a pass, or four where they fit.
            if T <= SMALL_WIDE {
                dense_tile::<T, OUTS_WIDE>(l, th, x, h, act && by_block);
            } else {
                dense_tile::<T, OUTS>(l, th, x, h, act && by_block);
            }
            if act && !by_block {
                squareplus_slice(&mut h[..l.out * T]);
            }
            if hidden && record {
                let kept = &mut tape.hidden[li];
                for j in 0..l.out {
                    copy_tile::<T>(&mut kept[j * r + t0..j * r + t0 + len], &h[j * T..]);
                }
            }
            std::mem::swap(&mut x, &mut h);
        }
        let last = &self.layers[layers - 1];
        for j in 0..last.out {
            y.put::<T>(j, t0, &x[j * T..j * T + len]);
        }
        len
    }

    /// The layer-by-layer pass over all rows: the reference the tiled pass
    /// is tested against, bit for bit.
    #[cfg(test)]
    fn layerwise(
        &self,
        th: &[f64],
        a: &[f64],
        c: &[f64],
        r: usize,
        tape: &mut Tape,
        y: &mut [f64],
    ) {
        if r == 0 {
            return;
        }
        let nl = self.layers.len();
        for (li, l) in self.layers.iter().enumerate() {
            let (done, rest) = tape.hidden.split_at_mut(li);
            let dst: &mut [f64] = if li + 1 == nl {
                &mut y[..l.out * r]
            } else {
                &mut rest[0][..l.out * r]
            };
            if li == 0 {
                l.forward(th, a, c, r, dst);
            } else {
                l.forward(th, &done[li - 1][..l.inp * r], &[], r, dst);
            }
            if li + 1 < nl {
                squareplus_in_place(dst);
            }
        }
    }

    /// Reverse pass of [`Mlp::forward`]: `gy` (`out × r`) is ∂L/∂y; accumulates
    /// parameter gradients into `g` (none when `g` is empty) and, when `gx` is
    /// given, ∂L/∂[a; c] into its two parts. `s1`, `s2` are scratch of at least `width() · r`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn backward(
        &self,
        th: &[f64],
        g: &mut [f64],
        a: &[f64],
        c: &[f64],
        r: usize,
        tape: &Tape,
        gy: &[f64],
        gx: Option<(&mut [f64], &mut [f64])>,
        s1: &mut [f64],
        s2: &mut [f64],
    ) {
        #[cfg(target_arch = "x86_64")]
        if simd() != Simd::Portable {
            // SAFETY: the CPU supports AVX2 and FMA (`simd` checked).
            return unsafe { self.backward_avx2(th, g, a, c, r, tape, gy, gx, s1, s2) };
        }
        self.backward_any(th, g, a, c, r, tape, gy, gx, s1, s2);
    }

    /// [`Mlp::backward`] compiled for AVX2 and FMA (its fused multiply-adds
    /// are library calls otherwise), as [`Mlp::forward_avx2`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn backward_avx2(
        &self,
        th: &[f64],
        g: &mut [f64],
        a: &[f64],
        c: &[f64],
        r: usize,
        tape: &Tape,
        gy: &[f64],
        gx: Option<(&mut [f64], &mut [f64])>,
        s1: &mut [f64],
        s2: &mut [f64],
    ) {
        self.backward_any(th, g, a, c, r, tape, gy, gx, s1, s2);
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn backward_any(
        &self,
        th: &[f64],
        g: &mut [f64],
        a: &[f64],
        c: &[f64],
        r: usize,
        tape: &Tape,
        gy: &[f64],
        gx: Option<(&mut [f64], &mut [f64])>,
        s1: &mut [f64],
        s2: &mut [f64],
    ) {
        if r == 0 {
            return;
        }
        let nl = self.layers.len();
        // `cur` holds ∂L/∂(output of layer li); the last layer's is `gy`.
        let (mut cur, mut next) = (s1, s2);
        let mut gx = gx;
        for li in (0..nl).rev() {
            let l = &self.layers[li];
            let gyl: &[f64] = if li + 1 == nl {
                &gy[..l.out * r]
            } else {
                &cur[..l.out * r]
            };
            if li == 0 {
                l.backward(th, g, a, c, r, gyl, gx.take(), false);
            } else {
                let x = &tape.hidden[li - 1][..l.inp * r];
                let gxl = &mut next[..l.inp * r];
                l.backward(th, g, x, &[], r, gyl, Some((gxl, &mut [])), true);
                times_squareplus_grad(gxl, x);
                std::mem::swap(&mut cur, &mut next);
            }
        }
    }
}

/// An MLP of these layer sizes over one flat parameter vector, and that
/// vector's length (tests).
#[cfg(test)]
pub(crate) fn mlp_of_sizes(sizes: &[usize]) -> (Mlp, usize) {
    let mut off = 0;
    let layers = sizes
        .windows(2)
        .map(|s| {
            let l = Linear {
                w: off,
                b: off + s[0] * s[1],
                inp: s[0],
                out: s[1],
            };
            off += s[0] * s[1] + s[1];
            l
        })
        .collect();
    (Mlp { layers }, off)
}

impl Tape {
    /// Whether the forward pass records into this tape.
    pub(crate) fn records(&self) -> bool {
        !self.hidden.is_empty()
    }

    /// Makes the tile scratch big enough for `mlp` (allocates only when
    /// growing).
    pub(crate) fn fit(&mut self, mlp: &Mlp) {
        let want = 2 * mlp.width() * TILE;
        if self.tile.len() < want {
            self.tile.resize(want, 0.0);
        }
    }
}

#[cfg(test)]
#[path = "dense_tests.rs"]
mod tests;
