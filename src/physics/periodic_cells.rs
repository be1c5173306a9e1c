//! The contact search's cell list in a periodic box: cells of side at least
//! R over the box, neighbour cells wrapped across periodic faces, distances
//! as minimum images (`crate::periodic`).
//!
//! Each axis has `nc ≥ 1` cells of side `L / nc ≥ R` (a periodic axis: the
//! box's length) or of side R over the particles' extent (an open axis).
//! A particle's neighbour cells along an axis are the distinct ones among
//! c − 1, c, c + 1 (wrapped on a periodic axis), so a box only two cells
//! wide never scans a cell twice and each pair is found once. When the grid
//! would hold more than 4n + 16 cells, cells are made coarser (still ≥ R).

use crate::periodic::{min_image_axis, PeriodicBox};

/// Buffers of a periodic search, reused across calls.
#[derive(Clone, Debug, Default)]
pub struct PeriodicCells {
    cell: Vec<[usize; 3]>,
    start: Vec<u32>,
    order: Vec<u32>,
}

impl PeriodicCells {
    /// Appends to `pairs` every pair i < j with a minimum-image distance
    /// below `radius` that `excluded(i, j)` keeps, sorted.
    pub fn search(
        &mut self,
        q: &[f64],
        dim: usize,
        radius: f64,
        bx: &PeriodicBox,
        excluded: impl Fn(usize, usize) -> bool,
        pairs: &mut Vec<(usize, usize)>,
    ) {
        let n = q.len() / dim;
        let side = radius * (1.0 + 1e-9);
        let (origin, size, nc) = grid(q, dim, n, side, bx);
        let total = nc[0] * nc[1] * nc[2];
        self.start.clear();
        self.start.resize(total + 1, 0);
        self.cell.clear();
        for i in 0..n {
            let mut c = [0usize; 3];
            for k in 0..dim {
                let mut x = q[i * dim + k] - origin[k];
                if let Some(l) = bx.period(k) {
                    x = x.rem_euclid(l);
                }
                // Saturating `as`: non-finite coordinates still get a cell.
                c[k] = ((x / size[k]).floor().max(0.0) as usize).min(nc[k] - 1);
            }
            self.cell.push(c);
            self.start[linear(c, nc) + 1] += 1;
        }
        for b in 0..total {
            self.start[b + 1] += self.start[b];
        }
        let mut fill = self.start.clone();
        self.order.clear();
        self.order.resize(n, 0);
        for i in 0..n {
            let b = linear(self.cell[i], nc);
            self.order[fill[b] as usize] = i as u32;
            fill[b] += 1;
        }
        let r2 = radius * radius;
        let from = pairs.len();
        for i in 0..n {
            let near =
                |k: usize| neighbours(self.cell[i][k], nc[k], k < dim && bx.period(k).is_some());
            let (nx, ny, nz) = (near(0), near(1), near(2));
            for &cz in nz.iter().flatten() {
                for &cy in ny.iter().flatten() {
                    for &cx in nx.iter().flatten() {
                        let b = linear([cx, cy, cz], nc);
                        for &j in &self.order[self.start[b] as usize..self.start[b + 1] as usize] {
                            let j = j as usize;
                            if j > i && distance2(q, dim, i, j, bx) < r2 && !excluded(i, j) {
                                pairs.push((i, j));
                            }
                        }
                    }
                }
            }
        }
        pairs[from..].sort_unstable();
    }
}

/// Squared minimum-image distance between particles `i` and `j`.
#[inline]
pub fn distance2(q: &[f64], dim: usize, i: usize, j: usize, bx: &PeriodicBox) -> f64 {
    (0..dim)
        .map(|k| {
            let d = q[i * dim + k] - q[j * dim + k];
            bx.period(k).map_or(d, |l| min_image_axis(d, l)).powi(2)
        })
        .sum()
}

/// The grid's origin, cell sizes and cell counts per axis (unused axes: 1 cell).
fn grid(
    q: &[f64],
    dim: usize,
    n: usize,
    side: f64,
    bx: &PeriodicBox,
) -> ([f64; 3], [f64; 3], [usize; 3]) {
    let (mut origin, mut extent) = ([0.0; 3], [0.0; 3]);
    let mut periodic = [false; 3];
    for k in 0..dim {
        if let Some(l) = bx.period(k) {
            (origin[k], extent[k], periodic[k]) = (bx.lower[k], l, true);
        } else {
            let axis = (0..n).map(|i| q[i * dim + k]).filter(|x| x.is_finite());
            let lo = axis.clone().fold(f64::INFINITY, f64::min);
            let hi = axis.fold(f64::NEG_INFINITY, f64::max);
            (origin[k], extent[k]) = if lo <= hi { (lo, hi - lo) } else { (0.0, 0.0) };
        }
    }
    let mut nc = [1usize; 3];
    for k in 0..dim {
        let cells = if periodic[k] {
            (extent[k] / side).floor()
        } else {
            (extent[k] / side).floor() + 1.0
        };
        nc[k] = (cells.min(1e6) as usize).max(1);
    }
    let cap = 4 * n + 16;
    while nc.iter().product::<usize>() > cap {
        let k = (0..3).max_by_key(|&k| nc[k]).unwrap_or(0);
        nc[k] = nc[k].div_ceil(2);
    }
    let mut size = [1.0; 3];
    for k in 0..dim {
        size[k] = if periodic[k] {
            extent[k] / nc[k] as f64
        } else {
            // Open axis: at least R, and the cells cover the extent.
            side.max(extent[k] / nc[k] as f64 * (1.0 + 1e-12))
        };
    }
    (origin, size, nc)
}

/// The distinct cells next to `c` along one axis (wrapped when periodic).
fn neighbours(c: usize, nc: usize, periodic: bool) -> [Option<usize>; 3] {
    let mut out = [Some(c), None, None];
    let (lo, hi) = if periodic {
        ((c + nc - 1) % nc, (c + 1) % nc)
    } else {
        (c.wrapping_sub(1), c + 1)
    };
    if lo < nc && lo != c {
        out[1] = Some(lo);
    }
    if hi < nc && hi != c && Some(hi) != out[1] {
        out[2] = Some(hi);
    }
    out
}

fn linear(c: [usize; 3], nc: [usize; 3]) -> usize {
    c[0] + nc[0] * (c[1] + nc[1] * c[2])
}
