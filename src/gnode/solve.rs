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

/// A singular (or non-finite) matrix met by [`lu_factor_in_place`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("singular constraint matrix")]
pub struct Singular;

/// Factors `k` (`n×n` row-major) in place by LU with partial pivoting:
/// `piv[c]` is the row swapped into row `c` at step `c`, and the multipliers
/// lie below the diagonal as they were at their step (a later swap moves
/// only columns `c..`), so that [`lu_solve_factored`] replays the
/// elimination on a right-hand side operation for operation: a forward pass
/// and its reverse solve with one factorization, and get the bits that
/// factoring twice would give.
pub fn lu_factor_in_place(
    k: &mut [f64],
    piv: &mut [usize],
    n: usize,
) -> std::result::Result<(), Singular> {
    for c in 0..n {
        let mut p = c;
        for r in c + 1..n {
            if k[r * n + c].abs() > k[p * n + c].abs() {
                p = r;
            }
        }
        let pv = k[p * n + c];
        if pv == 0.0 || !pv.is_finite() {
            return Err(Singular);
        }
        piv[c] = p;
        if p != c {
            for j in c..n {
                k.swap(c * n + j, p * n + j);
            }
        }
        for r in c + 1..n {
            let f = k[r * n + c] / pv;
            if f != 0.0 {
                for j in c + 1..n {
                    k[r * n + j] -= f * k[c * n + j];
                }
            }
            k[r * n + c] = f;
        }
    }
    Ok(())
}

/// Solves `k x = b` in place (`b` is `n×m`) with `k` and `piv` from
/// [`lu_factor_in_place`].
pub fn lu_solve_factored(k: &[f64], piv: &[usize], b: &mut [f64], n: usize, m: usize) {
    for c in 0..n {
        let p = piv[c];
        if p != c {
            for j in 0..m {
                b.swap(c * m + j, p * m + j);
            }
        }
        for r in c + 1..n {
            let f = k[r * n + c];
            if f != 0.0 {
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
}

/// [`lu_solve_factored`] for one right-hand side (`m` = 1), the same
/// operations in the same order (the same bits): a constrained training
/// step solves twice per state, and the general loops over `m` cost a
/// 5-pendulum epoch more than the arithmetic.
#[inline]
pub fn lu_solve_one(k: &[f64], piv: &[usize], b: &mut [f64], n: usize) {
    let (k, piv, b) = (&k[..n * n], &piv[..n], &mut b[..n]);
    for c in 0..n {
        b.swap(c, piv[c]);
        let bc = b[c];
        for (br, row) in b[c + 1..].iter_mut().zip(k[(c + 1) * n..].chunks_exact(n)) {
            let f = row[c];
            if f != 0.0 {
                *br -= f * bc;
            }
        }
    }
    for c in (0..n).rev() {
        let row = &k[c * n..(c + 1) * n];
        let mut s = b[c];
        for (kr, br) in row[c + 1..].iter().zip(&b[c + 1..]) {
            s -= kr * br;
        }
        b[c] = s / row[c];
    }
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
        let (mut work, mut piv) = (vec![0.0; k * k], vec![0; k]);
        for i in 0..bk {
            work.copy_from_slice(&kk[i * k * k..(i + 1) * k * k]);
            lu_factor_in_place(&mut work, &mut piv, k).map_err(|e| Error::Msg(e.to_string()))?;
            lu_solve_factored(&work, &piv, &mut x[i * k * m..(i + 1) * k * m], k, m);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6×6 system that needs pivoting (zeros on the diagonal), two
    /// right-hand sides: the residual of the solution is round-off, a second
    /// solve with the kept factors gives the bits of a fresh factorization,
    /// and a singular matrix is refused.
    #[test]
    fn factored_solves_are_exact_and_repeatable() {
        let n = 6;
        let k: Vec<f64> = (0..n * n)
            .map(|i| {
                let (r, c) = (i / n, i % n);
                if r == c {
                    0.0
                } else {
                    ((r * 7 + c * 3) as f64 * 0.61).sin() + if c == (r + 1) % n { 4.0 } else { 0.0 }
                }
            })
            .collect();
        let b: Vec<f64> = (0..2 * n).map(|i| (i as f64 * 0.37).cos()).collect();
        let (mut f, mut piv) = (k.clone(), vec![0; n]);
        lu_factor_in_place(&mut f, &mut piv, n).expect("regular");
        assert!(
            piv.iter().enumerate().any(|(c, &p)| p != c),
            "no pivoting tested"
        );
        let mut x = b.clone();
        lu_solve_factored(&f, &piv, &mut x, n, 2);
        for r in 0..n {
            for j in 0..2 {
                let kx: f64 = (0..n).map(|c| k[r * n + c] * x[c * 2 + j]).sum();
                assert!(
                    (kx - b[r * 2 + j]).abs() < 1e-12,
                    "residual {}",
                    kx - b[r * 2 + j]
                );
            }
        }
        let (mut f2, mut piv2) = (k.clone(), vec![0; n]);
        lu_factor_in_place(&mut f2, &mut piv2, n).expect("regular");
        let mut again = b.clone();
        lu_solve_factored(&f2, &piv2, &mut again, n, 2);
        let mut reused = b.clone();
        lu_solve_factored(&f, &piv, &mut reused, n, 2);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&again), bits(&x));
        assert_eq!(bits(&reused), bits(&x));
        // One right-hand side: the specialised solve gives the general one's bits.
        for j in 0..2 {
            let mut one: Vec<f64> = (0..n).map(|r| b[r * 2 + j]).collect();
            let mut general = one.clone();
            lu_solve_one(&f, &piv, &mut one, n);
            lu_solve_factored(&f, &piv, &mut general, n, 1);
            assert_eq!(bits(&one), bits(&general));
            let column: Vec<f64> = (0..n).map(|r| x[r * 2 + j]).collect();
            assert_eq!(bits(&one), bits(&column));
        }
        let mut singular = k.clone();
        singular[n..2 * n].copy_from_slice(&k[..n]);
        assert_eq!(
            lu_factor_in_place(&mut singular, &mut piv, n),
            Err(Singular)
        );
    }
}
