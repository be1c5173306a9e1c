//! Batched linear solve x = K⁻¹ b as a candle custom op, with its own backward:
//! ḡ_b = K⁻ᵀ ḡ_x and ḡ_K = −ḡ_b xᵀ. Candle has no linear solve; the constrained
//! equation of motion (CGNODE and later) needs one per sample.

use candle_core::{CpuStorage, CustomOp2, Error, Layout, Result, Shape, Tensor};

/// The op: inputs K `(B, k, k)` and b `(B, k, m)`, output x `(B, k, m)`.
pub struct BatchedSolve;

fn f64_slice<'a>(s: &'a CpuStorage, l: &Layout) -> Result<&'a [f64]> {
    let data = match s {
        CpuStorage::F64(v) => v.as_slice(),
        _ => return Err(Error::Msg("batched solve needs f64 tensors".into())),
    };
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&data[a..b]),
        None => Err(Error::Msg("batched solve needs contiguous inputs".into())),
    }
}

/// A singular (or non-finite) matrix met by [`lu_solve_in_place`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("singular constraint matrix")]
pub struct Singular;

/// Solves `k x = b` in place (b overwritten by x) by LU with partial pivoting.
/// `k` is `n×n` row-major and is destroyed; `b` is `n×m`.
pub fn lu_solve_in_place(
    k: &mut [f64],
    b: &mut [f64],
    n: usize,
    m: usize,
) -> std::result::Result<(), Singular> {
    for c in 0..n {
        let mut p = c;
        for r in c + 1..n {
            if k[r * n + c].abs() > k[p * n + c].abs() {
                p = r;
            }
        }
        let piv = k[p * n + c];
        if piv == 0.0 || !piv.is_finite() {
            return Err(Singular);
        }
        if p != c {
            for j in 0..n {
                k.swap(c * n + j, p * n + j);
            }
            for j in 0..m {
                b.swap(c * m + j, p * m + j);
            }
        }
        for r in c + 1..n {
            let f = k[r * n + c] / piv;
            if f != 0.0 {
                for j in c..n {
                    k[r * n + j] -= f * k[c * n + j];
                }
                for j in 0..m {
                    b[r * m + j] -= f * b[c * m + j];
                }
            }
        }
    }
    for c in (0..n).rev() {
        for j in 0..m {
            let mut s = b[c * m + j];
            for r in c + 1..n {
                s -= k[c * n + r] * b[r * m + j];
            }
            b[c * m + j] = s / k[c * n + c];
        }
    }
    Ok(())
}

impl CustomOp2 for BatchedSolve {
    fn name(&self) -> &'static str {
        "batched-solve"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (bk, k, k2) = l1.shape().dims3()?;
        let (bb, kb, m) = l2.shape().dims3()?;
        if k != k2 || bk != bb || kb != k {
            return Err(Error::Msg(format!(
                "batched solve: K {:?} and b {:?} do not match",
                l1.shape(),
                l2.shape()
            )));
        }
        let kk = f64_slice(s1, l1)?;
        let b = f64_slice(s2, l2)?;
        let mut x = b.to_vec();
        let mut work = vec![0.0; k * k];
        for i in 0..bk {
            work.copy_from_slice(&kk[i * k * k..(i + 1) * k * k]);
            lu_solve_in_place(&mut work, &mut x[i * k * m..(i + 1) * k * m], k, m)
                .map_err(|e| Error::Msg(e.to_string()))?;
        }
        Ok((CpuStorage::F64(x), l2.shape().clone()))
    }

    fn bwd(
        &self,
        k: &Tensor,
        _b: &Tensor,
        x: &Tensor,
        grad_x: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        // The backward is itself built from this op, so it is differentiable again.
        let kt = k.transpose(1, 2)?.contiguous()?;
        let grad_b = solve(&kt, grad_x)?;
        let grad_k = grad_b.matmul(&x.transpose(1, 2)?.contiguous()?)?.neg()?;
        Ok((Some(grad_k), Some(grad_b)))
    }
}

/// x = K⁻¹ b for a batch: K `(B, k, k)`, b `(B, k, m)`.
pub fn solve(k: &Tensor, b: &Tensor) -> Result<Tensor> {
    k.contiguous()?.apply_op2(&b.contiguous()?, BatchedSolve)
}
