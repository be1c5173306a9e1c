//! The vector kernels under the layers: which SIMD path and which square
//! root this CPU takes (chosen once per process), squareplus and its
//! derivative, and the dot products and sums every path computes in the
//! same order (the same bits).

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
pub(super) fn chosen(best: Simd, asked: Option<&str>) -> Simd {
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
pub(super) fn chosen_root(best: Root, asked: Option<&str>) -> Root {
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
pub(super) fn squareplus_slice(x: &mut [f64]) {
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
pub(super) fn squareplus_by(root: Root, x: f64) -> f64 {
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
pub(super) fn sqrt_via_f32(y: f64) -> f64 {
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
pub(super) fn dot4(a: &[f64], b: [&[f64]; 4]) -> [f64; 4] {
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
