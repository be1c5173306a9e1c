//! Dense layers and MLPs on a flat parameter vector, feature-major
//! (`x[f·r + row]`, rows innermost), with the forward pass recording the
//! hidden activations it needs and a hand-written reverse pass.
// `#[inline(always)]` on purpose: the loops must be inlined into the AVX2
// (`target_feature`) copies to be compiled for AVX2 at all.
#![allow(clippy::inline_always)]

mod linear;
mod vector;

use linear::dense_tile;
pub(crate) use linear::Linear;
use vector::squareplus_slice;
#[cfg(test)]
use vector::{chosen, chosen_root, dot4, sqrt_via_f32, squareplus_by, squareplus_fast, Root};
pub(crate) use vector::{dot, dots, simd, squareplus_in_place, sum, times_squareplus_grad, Simd};

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
