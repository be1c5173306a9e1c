//! Feature-major dense layers. Activations of `r` rows (all nodes, or all
//! edges) are stored as `x[f·r + row]`, so the innermost loop runs over rows,
//! is contiguous and vectorises; the tiny feature widths (5) stay outer.
// `#[inline(always)]` on purpose: the loops must be inlined into the AVX2
// (`target_feature`) copies to be compiled for AVX2 at all.
#![allow(clippy::inline_always)]

use crate::error::{bail, Result};
use crate::model::mlp::squareplus_f64;
use crate::model::params::Weights;

/// One linear layer, weights `[inputs, outputs]` row-major (as the model stores them).
#[derive(Clone, Debug)]
pub(crate) struct Dense {
    w: Vec<f64>,
    b: Vec<f64>,
    pub(crate) inp: usize,
    pub(crate) out: usize,
}

impl Dense {
    /// `y = Wᵀ [a; c] + bias` over `r` rows, where the first `a.len() / r`
    /// input features come from `a` and the rest from `c` (a concatenation
    /// without a copy).
    #[inline(always)]
    fn apply(&self, a: &[f64], c: &[f64], r: usize, y: &mut [f64]) {
        let na = a.len() / r;
        for (j, &bj) in self.b.iter().enumerate() {
            y[j * r..(j + 1) * r].fill(bj);
        }
        for (i, wrow) in self.w.chunks_exact(self.out).enumerate() {
            let xi = if i < na {
                &a[i * r..(i + 1) * r]
            } else {
                &c[(i - na) * r..(i - na + 1) * r]
            };
            for (j, &w) in wrow.iter().enumerate() {
                for (yv, xv) in y[j * r..(j + 1) * r].iter_mut().zip(xi) {
                    *yv += w * xv;
                }
            }
        }
    }
}

/// An MLP with squareplus between layers (none after the last).
#[derive(Clone, Debug)]
pub(crate) struct Mlp {
    layers: Vec<Dense>,
}

impl Mlp {
    /// Reads layers `{name}.l0`, `{name}.l1`, ...; `None` if there are none.
    pub(crate) fn load(w: &Weights, name: &str) -> Result<Option<Self>> {
        let mut layers: Vec<Dense> = vec![];
        loop {
            let i = layers.len();
            let (Some(wt), Some(bs)) = (
                w.get(&format!("{name}.l{i}.w")),
                w.get(&format!("{name}.l{i}.b")),
            ) else {
                break;
            };
            if wt.shape.len() != 2
                || bs.shape != [wt.shape[1]]
                || wt.data.len() != wt.shape[0] * wt.shape[1]
            {
                bail!("parameter {name}.l{i} has inconsistent shapes");
            }
            layers.push(Dense {
                w: wt.data.clone(),
                b: bs.data.clone(),
                inp: wt.shape[0],
                out: wt.shape[1],
            });
        }
        if layers.is_empty() {
            return Ok(None);
        }
        if layers.windows(2).any(|p| p[0].out != p[1].inp) {
            bail!("MLP {name}: layer sizes do not chain");
        }
        Ok(Some(Self { layers }))
    }

    /// Widest layer.
    pub(crate) fn width(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.out.max(l.inp))
            .max()
            .unwrap_or(0)
    }

    /// `y = mlp([a; c])` over `r` rows (feature-major). `t1`, `t2` are scratch
    /// of at least `width() · r`; hidden layers ping-pong between them.
    pub(crate) fn forward(
        &self,
        a: &[f64],
        c: &[f64],
        r: usize,
        y: &mut [f64],
        t1: &mut [f64],
        t2: &mut [f64],
    ) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { self.forward_avx2(a, c, r, y, t1, t2) };
        }
        self.forward_any(a, c, r, y, t1, t2);
    }

    /// [`Mlp::forward`] compiled for AVX2: the same operations in the same
    /// order (no fused multiply-adds), so the same bits, on wider vectors.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn forward_avx2(
        &self,
        a: &[f64],
        c: &[f64],
        r: usize,
        y: &mut [f64],
        t1: &mut [f64],
        t2: &mut [f64],
    ) {
        self.forward_any(a, c, r, y, t1, t2);
    }

    #[inline(always)]
    fn forward_any(
        &self,
        a: &[f64],
        c: &[f64],
        r: usize,
        y: &mut [f64],
        t1: &mut [f64],
        t2: &mut [f64],
    ) {
        if r == 0 {
            return;
        }
        let nl = self.layers.len();
        let (mut prev, mut next) = (t1, t2);
        for (li, l) in self.layers.iter().enumerate() {
            let last = li + 1 == nl;
            let dst: &mut [f64] = if last {
                &mut y[..l.out * r]
            } else {
                &mut next[..l.out * r]
            };
            if li == 0 {
                l.apply(a, c, r, dst);
            } else {
                l.apply(&prev[..l.inp * r], &[], r, dst);
            }
            if !last {
                dst.iter_mut().for_each(|x| *x = squareplus_f64(*x));
                std::mem::swap(&mut prev, &mut next);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dispatched forward pass (AVX2 where the CPU has it) gives the same
    /// bits as the portable build of the same code.
    #[test]
    fn vector_build_gives_the_same_bits() {
        let wave =
            |n: usize, k: f64| -> Vec<f64> { (0..n).map(|i| (k * i as f64 + 0.3).sin()).collect() };
        let layers = [7usize, 16, 5, 3]
            .windows(2)
            .enumerate()
            .map(|(i, s)| Dense {
                w: wave(s[0] * s[1], 0.1 + i as f64),
                b: wave(s[1], 0.7 + i as f64),
                inp: s[0],
                out: s[1],
            })
            .collect();
        let mlp = Mlp { layers };
        let r = 203;
        let (a, c) = (wave(4 * r, 0.11), wave(3 * r, 0.23));
        let w = mlp.width() * r;
        let (mut y1, mut y2) = (vec![0.0; 3 * r], vec![0.0; 3 * r]);
        let (mut t1, mut t2) = (vec![0.0; w], vec![0.0; w]);
        mlp.forward(&a, &c, r, &mut y1, &mut t1, &mut t2);
        mlp.forward_any(&a, &c, r, &mut y2, &mut t1, &mut t2);
        assert!(y1.iter().any(|v| *v != 0.0));
        assert_eq!(y1, y2);
    }
}
