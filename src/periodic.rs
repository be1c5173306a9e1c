//! Periodic boxes: the one home of the minimum image and of wrapping.
//!
//! A box has lower and upper bounds per axis and a periodic flag per axis.
//! On a periodic axis of length L a particle leaving through one face comes
//! back through the other, and the vector between two particles is the
//! shortest of its images, `d − L·round(d / L)` (the minimum image). Every
//! edge vector and contact distance of a graph with a box goes through
//! [`PeriodicBox::min_image`] or [`min_image_axis`]; every step's positions
//! through [`PeriodicBox::wrap`]. Non-periodic axes of a box are left alone
//! (the bounds only document them).

use serde::{Deserialize, Serialize};

/// An axis-aligned box with periodic flags per axis (`dim` entries each).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PeriodicBox {
    /// Lower bound of each axis.
    pub lower: Vec<f64>,
    /// Upper bound of each axis (> lower).
    pub upper: Vec<f64>,
    /// Whether each axis wraps around.
    pub periodic: Vec<bool>,
}

/// Component `d` of a difference on an axis of length `period`, as its
/// shortest image.
#[inline]
pub fn min_image_axis(d: f64, period: f64) -> f64 {
    d - period * (d / period).round()
}

impl PeriodicBox {
    /// A box periodic on every axis.
    pub fn all_periodic(lower: Vec<f64>, upper: Vec<f64>) -> Self {
        let periodic = vec![true; lower.len()];
        PeriodicBox {
            lower,
            upper,
            periodic,
        }
    }

    /// Number of axes.
    pub fn dim(&self) -> usize {
        self.lower.len()
    }

    /// Length of axis `k`.
    pub fn length(&self, k: usize) -> f64 {
        self.upper[k] - self.lower[k]
    }

    /// The period of axis `k`: its length when it is periodic, else `None`.
    #[inline]
    pub fn period(&self, k: usize) -> Option<f64> {
        (self.periodic.get(k).copied().unwrap_or(false)).then(|| self.length(k))
    }

    /// Whether any axis wraps.
    pub fn any_periodic(&self) -> bool {
        self.periodic.iter().any(|p| *p)
    }

    /// Replaces the difference vector `delta` (`dim` components) by its
    /// minimum image.
    #[inline]
    pub fn min_image(&self, delta: &mut [f64]) {
        for (k, d) in delta.iter_mut().enumerate() {
            if let Some(l) = self.period(k) {
                *d = min_image_axis(*d, l);
            }
        }
    }

    /// Wraps flat positions (`dim` per particle) into the box on its
    /// periodic axes: each coordinate ends in `[lower, upper)`.
    pub fn wrap(&self, q: &mut [f64]) {
        let d = self.dim();
        if d == 0 {
            return;
        }
        for p in q.chunks_exact_mut(d) {
            for (k, x) in p.iter_mut().enumerate() {
                if let Some(l) = self.period(k) {
                    let lo = self.lower[k];
                    if *x < lo || *x >= lo + l {
                        let mut r = (*x - lo).rem_euclid(l);
                        if r >= l {
                            r -= l;
                        }
                        *x = lo + r;
                    }
                }
            }
        }
    }

    /// A one-line description: `periodic box [0, 1) × [0, 1) (periodic x, y)`.
    pub fn describe(&self) -> String {
        let axes = ["x", "y", "z"];
        let sides: Vec<String> = (0..self.dim())
            .map(|k| format!("[{}, {})", self.lower[k], self.upper[k]))
            .collect();
        let flags: Vec<&str> = (0..self.dim())
            .filter(|&k| self.periodic.get(k).copied().unwrap_or(false))
            .map(|k| axes.get(k).copied().unwrap_or("?"))
            .collect();
        format!("box {} (periodic {})", sides.join(" x "), flags.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pair_across_the_boundary_has_the_short_vector() {
        let b = PeriodicBox::all_periodic(vec![0.0, -1.0], vec![1.0, 1.0]);
        let mut d = [0.95 - 0.05, -0.9 - 0.9];
        b.min_image(&mut d);
        assert!(
            (d[0] + 0.1).abs() < 1e-12 && (d[1] - 0.2).abs() < 1e-12,
            "{d:?}"
        );
        let mut inside = [0.3, -0.4];
        b.min_image(&mut inside);
        assert_eq!(inside, [0.3, -0.4]);
    }

    #[test]
    fn wrapping_puts_positions_in_the_box_and_leaves_open_axes() {
        let b = PeriodicBox {
            lower: vec![0.0, 0.0],
            upper: vec![2.0, 2.0],
            periodic: vec![true, false],
        };
        let mut q = vec![-0.5, 3.0, 4.25, -1.0, 1e-17 - 1e-16, 0.5];
        b.wrap(&mut q);
        assert!((q[0] - 1.5).abs() < 1e-12 && q[1] == 3.0);
        assert!((q[2] - 0.25).abs() < 1e-12 && q[3] == -1.0);
        assert!((0.0..2.0).contains(&q[4]));
    }
}
