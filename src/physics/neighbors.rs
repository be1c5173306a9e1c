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
//! put a pair closer than R two cells apart), hashed into a table of about 2n
//! buckets: memory stays O(n) however far apart the particles are, and a
//! bucket shared by two cells only costs distance checks (a candidate is kept
//! only when it lies in the cell being scanned, so no pair is found twice).
//! Pairs come out sorted (i, then j), so the edges are canonical.

use crate::system::{Edge, EdgeKind, Endpoint, Graph};

/// Marks the end of a bucket's list.
const NONE: u32 = u32::MAX;

/// The cell list and every buffer a search needs; reused across calls, so a
/// search allocates nothing once its buffers have grown to the system's size.
#[derive(Clone, Debug, Default)]
pub struct NeighborSearch {
    /// Bonded partners of each particle (CSR: `bond_start[i]..bond_start[i+1]`).
    bond_start: Vec<usize>,
    bond_with: Vec<usize>,
    /// Kinematic flags (empty: none): pairs of two kinematic particles are skipped.
    kinematic: Vec<bool>,
    /// Integer cell of each particle (unused axes 0).
    cell: Vec<[i64; 3]>,
    /// First particle of each bucket, and the next one in the same bucket.
    head: Vec<u32>,
    next: Vec<u32>,
    /// The pairs found by the last [`NeighborSearch::search`].
    pairs: Vec<(usize, usize)>,
}

impl NeighborSearch {
    /// A search excluding the pairs joined by `graph`'s fixed particle edges
    /// and the pairs of two of its kinematic particles.
    pub fn new(graph: &Graph) -> Self {
        let mut s = NeighborSearch {
            kinematic: graph.kinematic.clone(),
            ..NeighborSearch::default()
        };
        s.set_bonds(graph.n(), graph.fixed_edges().filter_map(particle_pair));
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
        self.fill_cells(q, dim, n, radius);
        let r2 = radius * radius;
        let reach: [i64; 3] = [1, 1, i64::from(dim == 3)];
        for i in 0..n {
            let start = self.pairs.len();
            let ci = self.cell[i];
            for dz in -reach[2]..=reach[2] {
                for dy in -reach[1]..=reach[1] {
                    for dx in -reach[0]..=reach[0] {
                        let c = [
                            ci[0].wrapping_add(dx),
                            ci[1].wrapping_add(dy),
                            ci[2].wrapping_add(dz),
                        ];
                        self.scan(i, c, q, dim, r2);
                    }
                }
            }
            self.pairs[start..].sort_unstable();
        }
        &self.pairs
    }

    /// The pairs of the last search.
    pub fn pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// Bins every particle into its cell's bucket.
    fn fill_cells(&mut self, q: &[f64], dim: usize, n: usize, radius: f64) {
        // 1 + 1e-9: a pair closer than R is never two cells apart, whatever
        // the rounding of x / side.
        let side = radius * (1.0 + 1e-9);
        let buckets = (2 * n).next_power_of_two();
        self.head.clear();
        self.head.resize(buckets, NONE);
        self.next.clear();
        self.next.resize(n, NONE);
        self.cell.clear();
        for i in 0..n {
            let mut c = [0i64; 3];
            for (k, ck) in c.iter_mut().enumerate().take(dim.min(3)) {
                // Saturating `as`: far-off or non-finite coordinates still get a cell.
                *ck = (q[i * dim + k] / side).floor() as i64;
            }
            self.cell.push(c);
            let b = bucket(c, buckets);
            self.next[i] = self.head[b];
            self.head[b] = i as u32;
        }
    }

    /// Adds the partners j > i of particle `i` lying in cell `c`.
    fn scan(&mut self, i: usize, c: [i64; 3], q: &[f64], dim: usize, r2: f64) {
        let mut j = self.head[bucket(c, self.head.len())];
        while j != NONE {
            let ju = j as usize;
            j = self.next[ju];
            if ju <= i || self.cell[ju] != c {
                continue;
            }
            let d2: f64 = (0..dim)
                .map(|k| (q[i * dim + k] - q[ju * dim + k]).powi(2))
                .sum();
            if d2 < r2 && !self.excluded(i, ju) {
                self.pairs.push((i, ju));
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

/// Every pair closer than `radius` and not excluded (bonded, or both
/// kinematic), by checking all n(n−1)/2 pairs: the reference the cell list is
/// tested against.
pub fn brute_force_pairs(graph: &Graph, q: &[f64], radius: f64) -> Vec<(usize, usize)> {
    let (n, d) = (graph.n(), graph.dim);
    let search = NeighborSearch::new(graph);
    let mut out = vec![];
    for i in 0..n {
        for j in i + 1..n {
            let d2: f64 = (0..d).map(|k| (q[i * d + k] - q[j * d + k]).powi(2)).sum();
            if d2 < radius * radius && !search.excluded(i, j) {
                out.push((i, j));
            }
        }
    }
    out
}
