//! The node's prediction path allocates nothing: a counting global allocator
//! counts the heap allocations of `predict_served` (compatibility
//! check, training-range check, rollout and forces into the node's kept
//! buffers) state after state of one system, for a model file loaded as the
//! node loads it. The prediction is checked against the model's own rollout
//! and forces computed apart, and the compatibility check against a count
//! of full checks (one per system). Run with
//! `cargo test --release --test alloc_free`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use mcgnode::data::msg::ParticleState;
use mcgnode::dynamics::{Dynamics, Predicted};
use mcgnode::gnode::Variant;
use mcgnode::models::{load_model, ModelRef};
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::ros::NodeParams;
use mcgnode::ros::{predict, predict_served, PredictError};
use mcgnode::ros::{Accepted, Input, Inputs};
use mcgnode::system::{Graph, Sample, State};

/// The system allocator, counting the allocations each thread makes.
struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    // `try_with`: a thread being torn down has no counter left.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

// SAFETY: every call is forwarded to `System` unchanged; counting touches
// only a thread-local integer, which allocates nothing.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made on this thread while `f` runs, and its result.
fn allocations<T>(f: impl FnOnce() -> T) -> (u64, T) {
    let before = ALLOCATIONS.with(Cell::get);
    let out = f();
    (ALLOCATIONS.with(Cell::get) - before, out)
}

/// Parsed inputs (one parse each, as the node's input stage does) of
/// `states` states of one simulated trajectory of `kind`, and the trained
/// model file of `variant` for it, loaded as `serve` loads it.
fn system(
    kind: SystemKind,
    particles: usize,
    variant: Variant,
    states: usize,
) -> (Vec<Input>, std::sync::Arc<dyn Dynamics>, NodeParams) {
    let mut cfg = SystemConfig::new(kind, particles);
    cfg.states = states;
    let graph = cfg.graph();
    let tr = cfg.simulate_one(&graph, cfg.start_for(&graph, 7, 0), 0);
    let states = tr
        .samples
        .iter()
        .map(|s: &Sample| s.state.clone())
        .collect();
    served(&tr.graph, states, variant)
}

/// Parsed inputs of `states` of `graph`, and a model file of `variant` for
/// it, loaded as `serve` loads it.
fn served(
    graph: &Graph,
    states: Vec<State>,
    variant: Variant,
) -> (Vec<Input>, std::sync::Arc<dyn Dynamics>, NodeParams) {
    let params = short_predictions();
    (
        parse(graph, states, &params),
        model_for(graph, variant),
        params,
    )
}

/// Short predictions of untrained weights, which stay finite.
fn short_predictions() -> NodeParams {
    NodeParams {
        horizon: 10,
        dt: 1e-3,
        ..Default::default()
    }
}

/// A random model file of `variant` for `graph`, loaded as `serve` loads it.
fn model_for(graph: &Graph, variant: Variant) -> std::sync::Arc<dyn Dynamics> {
    let (_, mut model) = mcgnode::testing::random_model(variant, graph, 3).expect("random model");
    // As `train` records them: the edges it was trained on.
    model.file.trained_on.edge_params = mcgnode::gnode::EdgeParams::of(graph);
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("model.json");
    model.file.save(&path).expect("saving the model file");
    load_model(&ModelRef::from_path(&path).expect("a model file"))
        .expect("loading the model as serve does")
}

/// `states` of `graph` parsed once each, as the node's input stage does.
fn parse(graph: &Graph, states: Vec<State>, params: &NodeParams) -> Vec<Input> {
    let inputs = Inputs::default();
    states
        .into_iter()
        .enumerate()
        .map(|(k, state)| {
            let s = Sample {
                t: k as f64 * 1e-3,
                state,
                acc: None,
            };
            let msg = ParticleState::from_sample(0, k as u32, "test", graph, &s);
            match inputs.accept(params, msg).expect("a valid state") {
                Accepted::Ready(input) => *input,
                other @ Accepted::WarmingUp { .. } => {
                    panic!("a full state is ready, got {other:?}")
                }
            }
        })
        .collect()
}

/// After one warm-up state, every further state of the system is predicted
/// with zero allocations; the prediction equals the model's rollout and
/// forces computed apart; the compatibility check ran in full once.
fn no_allocation_after_warm_up(kind: SystemKind, particles: usize, variant: Variant) {
    let (inputs, model, params) = system(kind, particles, variant, 12);
    no_allocation_in(&inputs, &model, &params, &format!("{kind:?} {variant}"));
}

/// [`no_allocation_after_warm_up`] on parsed inputs of one system.
fn no_allocation_in(
    inputs: &[Input],
    model: &std::sync::Arc<dyn Dynamics>,
    params: &NodeParams,
    what: &str,
) {
    let passed = mcgnode::compat::Passed::default();
    let mut kept = Predicted::default();
    let served = (model.as_ref(), 1);
    // Warm-up: buffers sized for this system (contact systems: for every
    // state's neighbours). The first call builds them, and is counted.
    let (first, _) = allocations(|| predict_served(served, &passed, &inputs[0], params, &mut kept));
    assert!(first > 0, "{what}: the first call counted {first}");
    for input in inputs {
        predict_served(served, &passed, input, params, &mut kept)
            .unwrap_or_else(|e| panic!("{what}: {e}"));
    }
    for input in inputs {
        let (n, r) = allocations(|| predict_served(served, &passed, input, params, &mut kept));
        r.unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(n, 0, "{what}: {n} allocations in one prediction");
        // The same numbers as the model's own rollout and forces, apart.
        let want = model
            .rollout(
                &input.graph,
                &input.state,
                mcgnode::dynamics::Timing::integration(params.dt, 10, 1),
            )
            .unwrap();
        assert_eq!(kept.states.to_states(), want, "{what}");
        let f = model.forces(&input.graph, &input.state).unwrap();
        assert_eq!(kept.forces.to_forces(input.graph.dim), f);
        assert!(!f.total.is_empty());
    }
    // One graph, one full check.
    assert_eq!(passed.full_checks(), 1, "{what}");
}

#[test]
fn springs_predict_without_allocating() {
    no_allocation_after_warm_up(SystemKind::Spring, 5, Variant::Mcgnode);
    no_allocation_after_warm_up(SystemKind::Spring, 5, Variant::Gnode);
    no_allocation_after_warm_up(SystemKind::Spring, 50, Variant::Mcgnode);
}

#[test]
fn bars_with_shake_predict_without_allocating() {
    no_allocation_after_warm_up(SystemKind::Pendulum, 5, Variant::Mcgnode);
    no_allocation_after_warm_up(SystemKind::HeldChain, 5, Variant::Cdgnode);
}

#[test]
fn contacts_predict_without_allocating() {
    no_allocation_after_warm_up(SystemKind::SoftSpheres, 100, Variant::Mcgnode);
}

/// A contact system large enough that the node's workspace runs its edge
/// MLPs on two cores (a helper thread started in the warm-up) and finds its
/// contacts with a Verlet list: a 1,024-particle packing, six neighbours
/// each, moving a little from state to state. Still nothing allocated per
/// state (the helper's half is the same MLP code; the counter counts this
/// thread).
#[test]
fn large_contact_systems_predict_without_allocating() {
    let (g, s0) = mcgnode::bench::contact_packing(32);
    let states: Vec<State> = (0..12)
        .map(|k| {
            let mut s = s0.clone();
            for (i, x) in s.q.iter_mut().enumerate() {
                *x += 1e-3 * ((k * 7 + i) as f64).sin();
            }
            s
        })
        .collect();
    let mut search = mcgnode::physics::NeighborSearch::new(&g);
    let directed = 2 * search.search(&s0.q, g.dim, g.interaction_radius).len();
    assert!(
        directed >= mcgnode::engine::SPLIT_ROWS,
        "{directed} directed edges: too few to split"
    );
    let (inputs, model, params) = served(&g, states, Variant::Mcgnode);
    no_allocation_in(&inputs, &model, &params, "1,024-particle packing");
}

/// A node serving two systems in turn (two streams, or a large system
/// between small ones) keeps each one's workspace: once both have been seen,
/// no prediction of either allocates.
#[test]
fn two_systems_in_turn_predict_without_allocating() {
    let ring = |n: usize| {
        let mut cfg = SystemConfig::new(SystemKind::Spring, n);
        cfg.states = 6;
        let g = cfg.graph();
        let tr = cfg.simulate_one(&g, cfg.start_for(&g, 7, 0), 0);
        let states: Vec<State> = tr.samples.iter().map(|s| s.state.clone()).collect();
        (tr.graph, states)
    };
    let ((small, s_small), (large, s_large)) = (ring(5), ring(40));
    let model = model_for(&small, Variant::Mcgnode);
    let params = short_predictions();
    let (a, b) = (
        parse(&small, s_small, &params),
        parse(&large, s_large, &params),
    );
    let passed = mcgnode::compat::Passed::default();
    let mut kept = Predicted::default();
    let served = (model.as_ref(), 1);
    for input in [&a[0], &b[0]] {
        predict_served(served, &passed, input, &params, &mut kept).expect("warm-up");
    }
    for (x, y) in a.iter().zip(&b) {
        for (input, what) in [(x, "5 springs"), (y, "40 springs")] {
            let (n, r) = allocations(|| predict_served(served, &passed, input, &params, &mut kept));
            r.unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(
                n, 0,
                "{what}: {n} allocations in one prediction between the other's"
            );
        }
    }
}

/// The counter counts: the allocating form of the same prediction is seen,
/// so a zero above is not a counter that never moves.
#[test]
fn the_counter_sees_allocations() {
    let (inputs, model, params) = system(SystemKind::Spring, 5, Variant::Mcgnode, 3);
    let (n, r) = allocations(|| predict(model.as_ref(), &inputs[1].message, params.timing()));
    r.unwrap();
    assert!(n > 0, "the allocating path counted {n}");
    // And a refusal is still an error, not a panic, on the kept buffers.
    let mut bad = params.clone();
    bad.dt = f64::NAN;
    let e = predict_served(
        (model.as_ref(), 1),
        &Default::default(),
        &inputs[1],
        &bad,
        &mut Predicted::default(),
    )
    .unwrap_err();
    assert!(matches!(e, PredictError::BadStep(_)), "{e}");
}
