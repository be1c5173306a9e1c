//! A tiny dense solver for the k×k constraint systems (k = number of bars).
//!
//! Hand-written so the integrator can solve in preallocated buffers without
//! allocating on every step; k is small (one row per bar).

/// Solves `m x = b` in place by Gaussian elimination with partial pivoting.
///
/// `m` is row-major `k×k` and is destroyed; `b` is overwritten with `x`.
/// Returns `false` when the matrix is numerically singular (a redundant set of
/// bars); `b` is then left in an unspecified state.
pub fn solve_in_place(m: &mut [f64], b: &mut [f64], k: usize) -> bool {
    debug_assert_eq!(m.len(), k * k);
    debug_assert_eq!(b.len(), k);
    let scale = m.iter().fold(0.0_f64, |s, x| s.max(x.abs()));
    if scale == 0.0 && k > 0 {
        return false;
    }
    let tiny = scale * 1e-14 * k as f64;
    for col in 0..k {
        let mut piv = col;
        for r in col + 1..k {
            if m[r * k + col].abs() > m[piv * k + col].abs() {
                piv = r;
            }
        }
        if m[piv * k + col].abs() <= tiny {
            return false;
        }
        if piv != col {
            for c in 0..k {
                m.swap(col * k + c, piv * k + c);
            }
            b.swap(col, piv);
        }
        let d = m[col * k + col];
        for r in col + 1..k {
            // Bar matrices are sparse (a chain's is tridiagonal): skip rows
            // with nothing to eliminate, which makes chains O(k²).
            let x = m[r * k + col];
            if x == 0.0 {
                continue;
            }
            let f = x / d;
            for c in col..k {
                m[r * k + c] -= f * m[col * k + c];
            }
            b[r] -= f * b[col];
        }
    }
    for col in (0..k).rev() {
        let mut s = b[col];
        for c in col + 1..k {
            s -= m[col * k + c] * b[c];
        }
        b[col] = s / m[col * k + col];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_pivoting_system() {
        // First pivot is zero, so this needs a row swap.
        let mut m = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let x = [1.0, -2.0, 0.5];
        let mut b: Vec<f64> = (0..3)
            .map(|r| (0..3).map(|c| m[r * 3 + c] * x[c]).sum())
            .collect();
        assert!(solve_in_place(&mut m, &mut b, 3));
        for (got, want) in b.iter().zip(x) {
            assert!((got - want).abs() < 1e-14, "{got} vs {want}");
        }
    }

    #[test]
    fn reports_singular() {
        let mut m = vec![1.0, 2.0, 2.0, 4.0];
        let mut b = vec![1.0, 2.0];
        assert!(!solve_in_place(&mut m, &mut b, 2));
    }
}
