//! The contact-pair search (`physics::neighbors`): the cell list against the
//! O(n²) brute force on random, clustered, tiny and boundary cases, bonded
//! pairs left out, and no heap allocation per call once warm (counted by this
//! binary's allocator). Run with `cargo test --release --test neighbors`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use mcgnode::physics::{brute_force_pairs, edges_with_contacts, ContactEdges, NeighborSearch};
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Counts the allocations of the current thread (tests run on several).
struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract, passed on.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: the caller's contract, passed on.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

fn graph(dim: usize, n: usize, radius: f64, edges: Vec<Edge>) -> Graph {
    Graph {
        dim,
        types: vec![0; n],
        masses: vec![1.0; n],
        edges,
        anchors: vec![],
        interaction_radius: radius,
        kinematic: vec![],
        periodic_box: None,
    }
}

fn spring(a: usize, b: usize) -> Edge {
    Edge {
        a,
        b: Endpoint::Particle(b),
        kind: EdgeKind::Spring,
        rest_length: 1.0,
        stiffness: 1.0,
    }
}

/// Uniform in a cube of side `side`, or in `clusters` tight balls of it.
fn points(rng: &mut impl Rng, n: usize, dim: usize, side: f64, clusters: usize) -> Vec<f64> {
    let centres: Vec<f64> = (0..clusters.max(1) * dim)
        .map(|_| rng.random_range(0.0..side))
        .collect();
    let mut q = Vec::with_capacity(n * dim);
    for _ in 0..n {
        let c = rng.random_range(0..clusters.max(1));
        for k in 0..dim {
            q.push(if clusters == 0 {
                rng.random_range(-side / 2.0..side / 2.0)
            } else {
                centres[c * dim + k] + rng.random_range(-0.3..0.3)
            });
        }
    }
    q
}

#[test]
fn cell_list_finds_exactly_the_brute_force_pairs() {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let mut checked = 0;
    for dim in [2, 3] {
        for (n, side, clusters) in [
            (0, 1.0, 0),
            (1, 1.0, 0),
            (2, 0.5, 0),
            (50, 3.0, 0),
            (1000, 20.0, 0),
            (1000, 20.0, 5),
            (300, 1e6, 3),
        ] {
            let radius = 1.0;
            // Some random springs, whose pairs must be left out.
            let edges: Vec<Edge> = (0..n / 3)
                .map(|_| {
                    let a = rng.random_range(0..n);
                    let b = (a + 1 + rng.random_range(0..n - 1)) % n;
                    spring(a, b)
                })
                .collect();
            let mut g = graph(dim, n, radius, edges);
            // A quarter of the particles kinematic: pairs of two are left out.
            if n > 2 {
                g.kinematic = (0..n).map(|_| rng.random_range(0..4) == 0).collect();
            }
            let q = points(&mut rng, n, dim, side, clusters);
            let mut s = NeighborSearch::new(&g);
            let got = s.search(&q, dim, radius).to_vec();
            let want = brute_force_pairs(&g, &q, radius);
            assert_eq!(
                got, want,
                "dim {dim}, n {n}, side {side}, clusters {clusters}"
            );
            checked += want.len();
            for &(i, j) in &got {
                assert!(i < j && !s.bonded(i, j));
                assert!(!(g.is_kinematic(i) && g.is_kinematic(j)));
            }
        }
    }
    // The sets were dense enough to test something.
    assert!(checked > 5000, "only {checked} pairs checked");
}

#[test]
fn bonded_pairs_keep_their_bond_and_get_no_contact() {
    let q = [0.0, 0.0, 0.5, 0.0, 1.0, 0.0];
    let g = graph(2, 3, 1.2, vec![spring(1, 0)]);
    let mut s = NeighborSearch::new(&g);
    assert_eq!(s.search(&q, 2, 1.2), &[(0, 2), (1, 2)]);
    assert!(s.bonded(0, 1) && s.bonded(1, 0) && !s.bonded(0, 2));
}

#[test]
fn two_kinematic_particles_never_touch() {
    let q = [0.0, 0.0, 0.1, 0.0, 0.2, 0.0];
    let mut g = graph(2, 3, 1.0, vec![]);
    g.kinematic = vec![true, true, false];
    let mut s = NeighborSearch::new(&g);
    assert_eq!(s.search(&q, 2, 1.0), &[(0, 2), (1, 2)]);
    assert!(s.excluded(0, 1) && !s.excluded(0, 2));
}

#[test]
fn a_pair_exactly_at_the_radius_is_not_in_contact() {
    // 0.75 and 0.25 are exact in binary, so the distance is exactly 0.5.
    for dim in [2, 3] {
        let mut q = vec![0.0; 2 * dim];
        q[0] = 0.25;
        q[dim] = 0.75;
        let g = graph(dim, 2, 0.5, vec![]);
        let mut s = NeighborSearch::new(&g);
        assert!(s.search(&q, dim, 0.5).is_empty(), "r = R counts as apart");
        assert_eq!(s.search(&q, dim, 0.5 + 1e-15), &[(0, 1)]);
        assert_eq!(brute_force_pairs(&g, &q, 0.5), vec![]);
        // Pairs straddling cell boundaries at every multiple of the radius.
        let line: Vec<f64> = (0..40)
            .flat_map(|i| {
                let mut p = vec![0.0; dim];
                p[0] = f64::from(i) * 0.5 - 10.0;
                p
            })
            .collect();
        let g = graph(dim, 40, 0.5, vec![]);
        assert!(NeighborSearch::new(&g).search(&line, dim, 0.5).is_empty());
        let want: Vec<_> = (0..39).map(|i| (i, i + 1)).collect();
        assert_eq!(
            NeighborSearch::new(&g).search(&line, dim, 0.500_000_1),
            want
        );
    }
}

#[test]
fn no_radius_means_no_pairs() {
    let q = [0.0, 0.0, 0.1, 0.0];
    let g = graph(2, 2, 0.0, vec![]);
    let mut s = NeighborSearch::new(&g);
    assert!(s.search(&q, 2, 0.0).is_empty());
    assert!(s.search(&q, 2, f64::NAN).is_empty());
    let mut e = ContactEdges::new(&g);
    assert!(e.update(&g, &q).is_empty());
}

#[test]
fn searches_allocate_nothing_once_warm() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for dim in [2, 3] {
        let n = 1000;
        let g = graph(dim, n, 1.0, vec![spring(0, 1), spring(2, 3)]);
        let mut q = points(&mut rng, n, dim, 12.0, 0);
        let mut edges = ContactEdges::new(&g);
        let mut search = NeighborSearch::new(&g);
        // Warm: the buffers grow to the largest contact count they will see.
        let mut most = 0;
        for _ in 0..3 {
            most = most.max(edges.update(&g, &q).len());
            search.search(&q, dim, 1.0);
        }
        // The same positions again: exactly nothing allocated.
        let before = allocations();
        for _ in 0..10 {
            edges.update(&g, &q);
            search.search(&q, dim, 1.0);
        }
        assert_eq!(
            allocations() - before,
            0,
            "allocated at unchanged positions ({dim}D)"
        );
        let before = allocations();
        let mut found = 0;
        for _ in 0..50 {
            // Jiggle by much less than the spacing: the contact count stays near.
            for x in &mut q {
                *x += rng.random_range(-1e-4..1e-4);
            }
            found += edges.update(&g, &q).len();
            found += search.search(&q, dim, 1.0).len();
        }
        let during = allocations() - before;
        assert!(found > 1000, "too few contacts ({found}) to test anything");
        assert!(
            edges.edges().len() <= most + 50,
            "contact count changed too much to rely on warm buffers"
        );
        // A few regrowths are allowed if the count exceeded the warm maximum.
        assert!(
            during <= 2,
            "{during} allocations in 50 warm searches ({dim}D)"
        );
    }
}

#[test]
fn contact_edges_follow_the_fixed_edges() {
    let q = [0.0, 0.0, 0.3, 0.0, 0.6, 0.0, 5.0, 5.0];
    let g = graph(2, 4, 0.5, vec![spring(0, 1), spring(2, 3)]);
    let mut buf = Vec::new();
    let pairs = NeighborSearch::new(&g).search(&q, 2, 0.5).to_vec();
    assert_eq!(pairs, vec![(1, 2)]);
    edges_with_contacts(&g, &pairs, &mut buf);
    assert_eq!(&buf[..2], &g.edges[..]);
    assert_eq!(
        buf[2],
        Edge {
            a: 1,
            b: Endpoint::Particle(2),
            kind: EdgeKind::Contact,
            rest_length: 0.5,
            stiffness: 0.0,
        }
    );
    // The contact graph is a valid graph, and its fixed edges are the bag's.
    let with = Graph {
        edges: buf.clone(),
        ..g.clone()
    };
    with.validate().unwrap();
    assert_eq!(with.fixed_edges().count(), 2);
    let cap = buf.capacity();
    edges_with_contacts(&g, &pairs, &mut buf);
    assert_eq!(
        (buf.len(), buf.capacity()),
        (3, cap),
        "the buffer is reused"
    );
}

#[test]
fn a_thousand_particles_with_six_neighbours_each() {
    // A jittered triangular lattice (spacing 1) and R = 1.1: about six
    // contacts per particle, the 1,000-particle contact rollout.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let side = 32;
    let n = side * side;
    let q: Vec<f64> = (0..n)
        .flat_map(|i| {
            let (r, c) = ((i / side) as f64, (i % side) as f64);
            let x = c + 0.5 * (r % 2.0) + rng.random_range(-0.02..0.02);
            let y = r * 3f64.sqrt() / 2.0 + rng.random_range(-0.02..0.02);
            [x, y]
        })
        .collect();
    let g = graph(2, n, 1.1, vec![]);
    let mut s = NeighborSearch::new(&g);
    let pairs = s.search(&q, 2, 1.1).len();
    assert_eq!(pairs, brute_force_pairs(&g, &q, 1.1).len());
    let per = 2.0 * pairs as f64 / n as f64;
    assert!((5.0..=6.0).contains(&per), "{per} neighbours per particle");
    let t0 = std::time::Instant::now();
    let reps = 2000;
    for _ in 0..reps {
        assert_eq!(s.search(&q, 2, 1.1).len(), pairs);
    }
    let us = t0.elapsed().as_secs_f64() / f64::from(reps) * 1e6;
    println!("{n} particles, {per:.2} neighbours each: {us:.1} µs per search");
}

/// The Verlet list gives, call after call along a moving system, exactly the
/// pairs (and order) of a fresh search: small steps that reuse its
/// candidates, jumps that rebuild them, a changed radius, a diverged (NaN)
/// state, in 2D and 3D with bonds and kinematic particles; once warm it
/// allocates nothing while it reuses its candidates.
#[test]
fn the_verlet_list_finds_what_a_fresh_search_finds() {
    let mut rng = ChaCha8Rng::seed_from_u64(33);
    let mut compared = 0;
    for dim in [2, 3] {
        let n = 600;
        let edges: Vec<Edge> = (0..n / 3).map(|a| spring(3 * a, 3 * a + 1)).collect();
        let mut g = graph(dim, n, 1.0, edges);
        g.kinematic = (0..n).map(|i| i % 7 == 0).collect();
        let mut q = points(&mut rng, n, dim, 9.0, 0);
        let v: Vec<f64> = (0..n * dim).map(|_| rng.random_range(-1.0..1.0)).collect();
        let (mut moving, mut fresh) = (NeighborSearch::new(&g), NeighborSearch::new(&g));
        for step in 0..400 {
            let radius = if step >= 300 { 1.1 } else { 1.0 };
            // Small steps (0.005 per call at most), a jump now and then.
            let h = if step % 97 == 50 { 0.3 } else { 0.005 };
            for (x, dx) in q.iter_mut().zip(&v) {
                *x += h * dx;
            }
            let want = fresh.search(&q, dim, radius).to_vec();
            let got = moving.search_moving(&q, dim, radius);
            assert_eq!(got, &want[..], "{dim}D, step {step}");
            compared += want.len();
        }
        // Warm and moving slowly: the candidates serve, nothing allocated.
        let before = allocations();
        for _ in 0..20 {
            for (x, dx) in q.iter_mut().zip(&v) {
                *x += 1e-4 * dx;
            }
            moving.search_moving(&q, dim, 1.1);
        }
        assert_eq!(allocations() - before, 0, "{dim}D");
        // A diverged state: no stale candidates, the search's answer.
        q[0] = f64::NAN;
        let want = fresh.search(&q, dim, 1.1).to_vec();
        assert_eq!(moving.search_moving(&q, dim, 1.1), &want[..]);
    }
    assert!(compared > 100_000, "only {compared} pairs compared");
}
