//! Contact pairs: every pair of particles closer than a radius, found by a
//! cell list in O(n) per call, and the contact edges they become.
//!
//! A pair (i, j), i < j, is in contact when |q_i − q_j| < R (strictly: a pair
//! exactly at the radius is not), no fixed edge joins them (a bonded pair
//! keeps its bond, which already carries their interaction) and they are not
//! both kinematic (two wall particles never move each other: their contact
//! would only cost time, and a wall spaced R/2 has many).
//!
//! Why hand-written: the maintained spatial crates do not fit a search rebuilt
//! every step that must not allocate. kiddo's k-d tree is rebuilt in
//! O(n log n), fixes the dimension as a const generic (two instantiations for
//! 2D/3D) and its radius iterator runs on a `generator` coroutine with its
//! own stack; rstar's `bulk_load` returns a new tree (a fresh allocation)
//! every step. A cell list is the textbook structure for a fixed radius
//! (Allen & Tildesley; GNS and LagrangeBench use one): ~40 lines here.
//!
//! Cells are cubes of side R (a hair larger, so that rounding in x/R can never
//! put a pair closer than R two cells apart). When the particles' bounding box
//! holds at most 4n + 16 cells, they are a dense grid over it; otherwise (a few
//! particles far apart) the cells are hashed into a table of about 2n buckets,
//! so memory stays O(n) however far apart the particles are: a bucket shared
//! by two cells only costs distance checks (a candidate is kept only when it
//! lies in the cell being scanned, so no pair is found twice).
//! Particles are counting-sorted by bucket, with copies of their positions
//! and cells in that order, so a bucket's candidates are contiguous in memory.
//! Pairs come out sorted (i, then j), so the edges are canonical.
//!
//! In a periodic box ([`crate::periodic`]) distances are minimum images and
//! the cells wrap across periodic faces (`super::periodic_cells`).

use super::periodic_cells::{distance2, PeriodicCells};
use crate::system::{Edge, EdgeKind, Endpoint, Graph, PeriodicBox};

/// The cell list and every buffer a search needs; reused across calls, so a
/// search allocates nothing once its buffers have grown to the system's size.
#[derive(Clone, Debug, Default)]
pub struct NeighborSearch {
    /// Bonded partners of each particle (CSR: `bond_start[i]..bond_start[i+1]`).
    bond_start: Vec<usize>,
    bond_with: Vec<usize>,
    /// Kinematic flags (empty: none): pairs of two kinematic particles are skipped.
    kinematic: Vec<bool>,
    /// Integer cell of each particle (unused axes 0), and its bucket.
    cell: Vec<[i64; 3]>,
    bucket: Vec<u32>,
    /// Where each bucket's particles start in the sorted arrays (`buckets + 1`).
    start: Vec<u32>,
    /// The dense grid's cells per axis, or `None` when cells are hashed.
    grid: Option<[i64; 3]>,
    /// Particles sorted by bucket: index, position (unused axes 0) and cell.
    order: Vec<u32>,
    sorted_q: Vec<[f64; 3]>,
    sorted_cell: Vec<[i64; 3]>,
    /// The pairs found by the last [`NeighborSearch::search`].
    pairs: Vec<(usize, usize)>,
    /// [`NeighborSearch::search_moving`]'s pairs within R + skin, the
    /// positions they were found at, and R (0: none yet).
    candidates: Vec<(usize, usize)>,
    built_at: Vec<f64>,
    built_radius: f64,
    /// The periodic box distances are minimum images in (`None`: open space).
    periodic: Option<PeriodicBox>,
    periodic_cells: PeriodicCells,
}

/// The skin of [`NeighborSearch::search_moving`], as a share of the radius:
/// candidates within 1.2 R (1.44x the pairs in 2D, 1.73x in 3D) serve until a
/// particle has moved 0.1 R.
pub const SKIN: f64 = 0.2;

impl NeighborSearch {
    /// A search excluding the pairs joined by `graph`'s fixed particle edges
    /// and the pairs of two of its kinematic particles.
    pub fn new(graph: &Graph) -> Self {
        let bonds = graph.fixed_edges().filter_map(particle_pair);
        Self::excluding(graph.n(), bonds, graph.kinematic.clone()).in_box(graph.periodic().cloned())
    }

    /// This search with distances as minimum images in `periodic` (`None`:
    /// open space).
    #[must_use]
    pub fn in_box(mut self, periodic: Option<PeriodicBox>) -> Self {
        self.periodic = periodic.filter(PeriodicBox::any_periodic);
        self
    }

    /// q_i − q_j into `out[..dim]`: a minimum image in a periodic box.
    #[inline]
    pub fn delta(&self, q: &[f64], dim: usize, (i, j): (usize, usize), out: &mut [f64; 3]) {
        for c in 0..dim.min(3) {
            out[c] = q[i * dim + c] - q[j * dim + c];
        }
        if let Some(b) = &self.periodic {
            b.min_image(&mut out[..dim.min(3)]);
        }
    }

    /// Squared distance between particles `i` and `j` of `q`: a minimum
    /// image in a periodic box.
    #[inline]
    fn distance2(&self, q: &[f64], dim: usize, i: usize, j: usize) -> f64 {
        match &self.periodic {
            Some(b) => distance2(q, dim, i, j, b),
            None => (0..dim)
                .map(|k| (q[i * dim + k] - q[j * dim + k]).powi(2))
                .sum(),
        }
    }

    /// A search over `n` particles leaving out the `bonds` pairs and pairs of
    /// two `kinematic` ones (empty: none kinematic).
    pub fn excluding(
        n: usize,
        bonds: impl Iterator<Item = (usize, usize)> + Clone,
        kinematic: Vec<bool>,
    ) -> Self {
        let mut s = NeighborSearch {
            kinematic,
            ..NeighborSearch::default()
        };
        s.set_bonds(n, bonds);
        s
    }

    /// Whether the pair is left out though close: bonded, or both kinematic.
    pub fn excluded(&self, i: usize, j: usize) -> bool {
        let held = |k: usize| self.kinematic.get(k).copied().unwrap_or(false);
        (held(i) && held(j)) || self.bonded(i, j)
    }

    /// Sets the pairs to exclude (bonded pairs, either order) for `n` particles.
    pub fn set_bonds(&mut self, n: usize, bonds: impl Iterator<Item = (usize, usize)> + Clone) {
        let mut count = vec![0usize; n + 1];
        for (a, b) in bonds.clone() {
            count[a + 1] += 1;
            count[b + 1] += 1;
        }
        for i in 0..n {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        self.bond_with = vec![0; count[n]];
        for (a, b) in bonds {
            self.bond_with[fill[a]] = b;
            fill[a] += 1;
            self.bond_with[fill[b]] = a;
            fill[b] += 1;
        }
        self.bond_start = count;
    }

    /// Whether a fixed edge joins particles `i` and `j`.
    pub fn bonded(&self, i: usize, j: usize) -> bool {
        match (self.bond_start.get(i), self.bond_start.get(i + 1)) {
            (Some(&s), Some(&e)) => self.bond_with[s..e].contains(&j),
            _ => false,
        }
    }

    /// Finds every unbonded pair i < j with |q_i − q_j| < `radius` among the
    /// particles of `q` (flat, `dim` per particle), sorted; see
    /// [`NeighborSearch::pairs`]. A radius ≤ 0 (or not finite) finds none.
    pub fn search(&mut self, q: &[f64], dim: usize, radius: f64) -> &[(usize, usize)] {
        self.pairs.clear();
        let n = q.len().checked_div(dim).unwrap_or(0);
        if n < 2 || !(radius.is_finite() && radius > 0.0) {
            return &self.pairs;
        }
        if let Some(b) = self.periodic.take() {
            let mut cells = std::mem::take(&mut self.periodic_cells);
            let mut pairs = std::mem::take(&mut self.pairs);
            cells.search(q, dim, radius, &b, |i, j| self.excluded(i, j), &mut pairs);
            (self.periodic, self.periodic_cells, self.pairs) = (Some(b), cells, pairs);
            return &self.pairs;
        }
        self.fill_cells(q, dim, n, radius);
        let r2 = radius * radius;
        let reach: [i64; 3] = [1, 1, i64::from(dim == 3)];
        for i in 0..n {
            let start = self.pairs.len();
            let ci = self.cell[i];
            let mut qi = [0.0; 3];
            qi[..dim.min(3)].copy_from_slice(&q[i * dim..i * dim + dim.min(3)]);
            for dz in -reach[2]..=reach[2] {
                for dy in -reach[1]..=reach[1] {
                    for dx in -reach[0]..=reach[0] {
                        let c = [
                            ci[0].wrapping_add(dx),
                            ci[1].wrapping_add(dy),
                            ci[2].wrapping_add(dz),
                        ];
                        self.scan(i, qi, c, r2);
                    }
                }
            }
            self.pairs[start..].sort_unstable();
        }
        &self.pairs
    }

    /// [`NeighborSearch::search`] for positions that move a little from
    /// one call to the next (a rollout's steps): the same pairs in the same
    /// order, found among candidates within R + s (s = `SKIN`·R) that are
    /// searched again only once a particle has moved s/2 since (a Verlet
    /// list: a pair closer than R now was closer than R + s then). The
    /// distance test is the search's own arithmetic. A step then costs a
    /// pass over the candidates instead of a cell list.
    pub fn search_moving(&mut self, q: &[f64], dim: usize, radius: f64) -> &[(usize, usize)] {
        let skin = SKIN * radius;
        // A hair under s/2, so that rounding cannot let a pair slip past.
        let limit = (0.5 * skin * (1.0 - 1e-9)).powi(2);
        let stale = self.built_radius != radius
            || self.built_at.len() != q.len()
            || dim == 0
            || q.chunks(dim).zip(self.built_at.chunks(dim)).any(|(a, b)| {
                let d2: f64 = (0..a.len())
                    .map(|k| {
                        let d = a[k] - b[k];
                        let p = self.periodic.as_ref().and_then(|bx| bx.period(k));
                        p.map_or(d, |l| crate::periodic::min_image_axis(d, l))
                            .powi(2)
                    })
                    .sum();
                // NaN (a diverged state) is stale too.
                d2 >= limit || d2.is_nan()
            });
        if stale {
            self.search(q, dim, radius + skin);
            std::mem::swap(&mut self.pairs, &mut self.candidates);
            self.built_at.clear();
            self.built_at.extend_from_slice(q);
            self.built_radius = radius;
        }
        self.pairs.clear();
        let (r2, k) = (radius * radius, dim.min(3));
        if self.periodic.is_some() {
            for c in 0..self.candidates.len() {
                let (i, j) = self.candidates[c];
                if self.distance2(q, dim, i, j) < r2 {
                    self.pairs.push((i, j));
                }
            }
            return &self.pairs;
        }
        for &(i, j) in &self.candidates {
            let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
            a[..k].copy_from_slice(&q[i * dim..i * dim + k]);
            b[..k].copy_from_slice(&q[j * dim..j * dim + k]);
            let d2 = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2);
            if d2 < r2 {
                self.pairs.push((i, j));
            }
        }
        &self.pairs
    }

    /// The pairs of the last search.
    pub fn pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// Bins every particle into its cell's bucket and sorts them by bucket.
    fn fill_cells(&mut self, q: &[f64], dim: usize, n: usize, radius: f64) {
        // 1 + 1e-9: a pair closer than R is never two cells apart, whatever
        // the rounding of x / side.
        let side = radius * (1.0 + 1e-9);
        let origin = self.choose_grid(q, dim, n, side);
        let buckets = match self.grid {
            Some(g) => (g[0] * g[1] * g[2]) as usize,
            None => (2 * n).next_power_of_two(),
        };
        self.start.clear();
        self.start.resize(buckets + 1, 0);
        self.cell.clear();
        self.bucket.clear();
        for i in 0..n {
            let mut c = [0i64; 3];
            for (k, ck) in c.iter_mut().enumerate().take(dim.min(3)) {
                // Saturating `as`: far-off or non-finite coordinates still get a cell.
                *ck = ((q[i * dim + k] - origin[k]) / side).floor() as i64;
            }
            let b = self.slot(c).unwrap_or(0);
            self.cell.push(c);
            self.bucket.push(b as u32);
            self.start[b + 1] += 1;
        }
        for b in 0..buckets {
            self.start[b + 1] += self.start[b];
        }
        self.order.clear();
        self.order.resize(n, 0);
        self.sorted_q.clear();
        self.sorted_q.resize(n, [0.0; 3]);
        self.sorted_cell.clear();
        self.sorted_cell.resize(n, [0; 3]);
        // Fill each bucket from its end down, so `start[b]` ends at its first slot.
        for i in (0..n).rev() {
            let b = self.bucket[i] as usize;
            self.start[b + 1] -= 1;
            let k = self.start[b + 1] as usize;
            self.order[k] = i as u32;
            self.sorted_cell[k] = self.cell[i];
            let mut p = [0.0; 3];
            p[..dim.min(3)].copy_from_slice(&q[i * dim..i * dim + dim.min(3)]);
            self.sorted_q[k] = p;
        }
        // `start[b + 1]` now holds bucket b's first slot; shift to start[b].
        self.start.copy_within(1.., 0);
        self.start[buckets] = n as u32;
    }

    /// Picks a dense grid over the bounding box when it is small enough
    /// (else hashing) and returns the origin cells are counted from.
    fn choose_grid(&mut self, q: &[f64], dim: usize, n: usize, side: f64) -> [f64; 3] {
        let (mut lo, mut hi) = ([0.0_f64; 3], [0.0_f64; 3]);
        for k in 0..dim.min(3) {
            let axis = (0..n).map(|i| q[i * dim + k]);
            lo[k] = axis.clone().fold(f64::INFINITY, f64::min);
            hi[k] = axis.fold(f64::NEG_INFINITY, f64::max);
        }
        self.grid = None;
        if lo.iter().chain(&hi).all(|x| x.is_finite()) {
            let cells = |k: usize| ((hi[k] - lo[k]) / side).floor() + 1.0;
            let total = cells(0) * cells(1) * cells(2);
            if total <= 4.0 * n as f64 + 16.0 {
                self.grid = Some([0, 1, 2].map(|k| cells(k) as i64));
            }
            return lo;
        }
        [0.0; 3]
    }

    /// The bucket of cell `c`: its index in the dense grid (`None` outside
    /// it), or its hash.
    fn slot(&self, c: [i64; 3]) -> Option<usize> {
        match self.grid {
            Some(g) => {
                let inside = (0..3).all(|k| (0..g[k]).contains(&c[k]));
                inside.then(|| (c[0] + g[0] * (c[1] + g[1] * c[2])) as usize)
            }
            None => Some(bucket(c, self.start.len() - 1)),
        }
    }

    /// Adds the partners j > i of particle `i` (at `qi`) lying in cell `c`.
    fn scan(&mut self, i: usize, qi: [f64; 3], c: [i64; 3], r2: f64) {
        let Some(b) = self.slot(c) else {
            return;
        };
        let (from, to) = (self.start[b] as usize, self.start[b + 1] as usize);
        for k in from..to {
            let j = self.order[k] as usize;
            if j <= i || self.sorted_cell[k] != c {
                continue;
            }
            let p = self.sorted_q[k];
            let d2 = (qi[0] - p[0]).powi(2) + (qi[1] - p[1]).powi(2) + (qi[2] - p[2]).powi(2);
            if d2 < r2 && !self.excluded(i, j) {
                self.pairs.push((i, j));
            }
        }
    }
}

/// The bucket of a cell: a multiplicative hash of its coordinates.
fn bucket(c: [i64; 3], buckets: usize) -> usize {
    let h = (c[0] as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (c[1] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (c[2] as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    // `buckets` is a power of two; the high bits mix best.
    (h >> 20) as usize & (buckets - 1)
}

/// The two particles of a particle–particle edge.
fn particle_pair(e: &Edge) -> Option<(usize, usize)> {
    match e.b {
        Endpoint::Particle(b) => Some((e.a, b)),
        Endpoint::Anchor(_) => None,
    }
}

/// A contact edge between particles `a` < `b`: rest length = the radius,
/// stiffness 0 (the contact law belongs to the model or the simulator).
pub fn contact_edge(a: usize, b: usize, radius: f64) -> Edge {
    Edge {
        a,
        b: Endpoint::Particle(b),
        kind: EdgeKind::Contact,
        rest_length: radius,
        stiffness: 0.0,
    }
}

/// Writes into `edges` the fixed edges of `graph` followed by one contact edge
/// per pair, reusing its allocation: with the same `Vec` every step, this
/// allocates only when the number of contacts exceeds every earlier count.
pub fn edges_with_contacts(graph: &Graph, pairs: &[(usize, usize)], edges: &mut Vec<Edge>) {
    edges.clear();
    edges.extend(graph.fixed_edges().copied());
    let r = graph.interaction_radius;
    edges.extend(pairs.iter().map(|&(a, b)| contact_edge(a, b, r)));
}

/// A graph's edges at a configuration: its fixed edges and the contacts at
/// `q`, kept in reusable buffers (one per rolled-out system).
#[derive(Clone, Debug)]
pub struct ContactEdges {
    search: NeighborSearch,
    edges: Vec<Edge>,
}

impl ContactEdges {
    /// Buffers for `graph` (its bonded pairs are excluded from contacts).
    pub fn new(graph: &Graph) -> Self {
        ContactEdges {
            search: NeighborSearch::new(graph),
            edges: graph.fixed_edges().copied().collect(),
        }
    }

    /// The fixed edges followed by the contact edges at `q` (none when the
    /// graph's radius is 0).
    pub fn update(&mut self, graph: &Graph, q: &[f64]) -> &[Edge] {
        let pairs = self.search.search(q, graph.dim, graph.interaction_radius);
        edges_with_contacts(graph, pairs, &mut self.edges);
        &self.edges
    }

    /// The edges of the last [`ContactEdges::update`].
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// The contact pairs of the last update.
    pub fn pairs(&self) -> &[(usize, usize)] {
        self.search.pairs()
    }
}

/// Every pair closer than `radius` (a minimum image in the graph's periodic
/// box) and not excluded (bonded, or both kinematic), by checking all n(n−1)/2 pairs: the reference the cell list is
/// tested against.
pub fn brute_force_pairs(graph: &Graph, q: &[f64], radius: f64) -> Vec<(usize, usize)> {
    let (n, d) = (graph.n(), graph.dim);
    let search = NeighborSearch::new(graph);
    let mut out = vec![];
    for i in 0..n {
        for j in i + 1..n {
            let d2 = search.distance2(q, d, i, j);
            if d2 < radius * radius && !search.excluded(i, j) {
                out.push((i, j));
            }
        }
    }
    out
}
