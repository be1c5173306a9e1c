//! Live streams as sensors give them: positions with a stamp, some noise, an
//! uneven rate, now and then a gap, rarely a velocity. A [`History`] keeps the
//! last positions of one stream and estimates the newest state's velocity
//! from them, causally (only what has arrived so far), the way the node and
//! `replay --positions-only` both do:
//!
//! - [`Smoother::None`]: the three-point difference for uneven steps,
//!   one-sided at the newest state ([`three_point`] with [`At::Last`], the
//!   bag reader's rule at a trajectory's end). Exact for quadratics; needs 3
//!   states. Noise σ in the positions becomes about 2.5 σ / h in the velocity.
//! - [`Smoother::Poly`]: a least-squares polynomial of degree `order` over the
//!   last `window` states, evaluated at the newest stamp (position and
//!   velocity). No lag: the estimate is for the newest state, so predictions
//!   are not delayed; the price is a warm-up of `window` states and a bias for
//!   motion that a degree-`order` polynomial does not follow over the window's
//!   span (keep the span well under a period of the fastest motion).
//!
//! A stream starts over (the history is emptied, [`Reset`] says why) when its
//! graph changes, a stamp is before the previous one, or the gap since the
//! previous state exceeds `max_gap`. A state stamped like the previous one
//! replaces it (a repeat or a correction of the same instant).

use std::collections::{HashMap, VecDeque};

use nalgebra::DMatrix;

use super::dataset::{three_point, At};
use super::DataError;
use crate::system::{Graph, State};

/// Time in nanoseconds (a ROS stamp): differences stay exact where f64
/// seconds since 1970 would round to 0.2 µs.
pub type Nanos = i64;

/// How a stream's velocities are estimated from its positions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Smoother {
    /// Three-point difference at the newest state (3 states of history).
    None,
    /// Local polynomial fit over the last `window` states.
    Poly {
        /// States in the fit (at least `order + 2`, so noise is averaged).
        window: usize,
        /// Degree of the polynomial (1 to 4).
        order: usize,
    },
    /// The start of the last `window` states fitted through the model's own
    /// rollout (`crate::estimate`). The history holds the window; its own
    /// estimate is a degree-2 poly fit's, which the model's fit replaces
    /// where a model is at hand (`replay`, the node).
    Model {
        /// States in the fit (3 to 1000).
        window: usize,
    },
}

/// Smoother names, as the `velocity_smoother` parameter and `--smoother` take them.
pub const SMOOTHERS: &[&str] = &["none", "poly", "model"];

impl Smoother {
    /// `name` ("none", "poly" or "model") with a fit's `window` (and a poly
    /// fit's `order`); the error names what is accepted.
    pub fn new(name: &str, window: usize, order: usize) -> Result<Smoother, DataError> {
        let bad = |m: String| Err(DataError::Invalid(m));
        match name {
            "none" => Ok(Smoother::None),
            "poly" => {
                if !(1..=4).contains(&order) {
                    return bad(format!("smoother order {order} must be 1 to 4"));
                }
                if window < order + 2 || window > 1000 {
                    return bad(format!(
                        "smoother window {window} must be {} to 1000 states (order {order} + 2 \
                         at least, so the fit averages noise)",
                        order + 2
                    ));
                }
                Ok(Smoother::Poly { window, order })
            }
            "model" => {
                if !(4..=1000).contains(&window) {
                    return bad(format!(
                        "model smoother window {window} must be 4 to 1000 states"
                    ));
                }
                Ok(Smoother::Model { window })
            }
            other => bad(format!(
                "unknown velocity smoother {other:?}; one of {}",
                SMOOTHERS.join(", ")
            )),
        }
    }

    /// States of history before the first estimate.
    pub fn needs(&self) -> usize {
        match self {
            Smoother::None => 3,
            Smoother::Poly { window, .. } | Smoother::Model { window } => *window,
        }
    }
}

/// How a stream is followed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamOptions {
    /// Velocity estimate.
    pub smoother: Smoother,
    /// A gap longer than this (seconds) starts the stream over (0: never).
    pub max_gap: f64,
}

impl Default for StreamOptions {
    fn default() -> Self {
        StreamOptions {
            smoother: Smoother::None,
            max_gap: 0.0,
        }
    }
}

/// Why a stream's history was emptied.
#[derive(Clone, Debug, PartialEq)]
pub enum Reset {
    /// The graph (types, masses, edges, anchors) changed.
    Graph,
    /// A stamp before the previous one (a new run, a replayed bag).
    Earlier {
        /// The previous stamp.
        last: Nanos,
        /// This one.
        now: Nanos,
    },
    /// A gap longer than `max_gap`.
    Gap {
        /// Seconds since the previous state.
        gap: f64,
        /// The limit.
        max_gap: f64,
    },
}

impl std::fmt::Display for Reset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Reset::Graph => write!(f, "the graph changed"),
            Reset::Earlier { last, now } => write!(
                f,
                "stamp {:.6} s is before the previous {:.6} s (a new run?)",
                *now as f64 * 1e-9,
                *last as f64 * 1e-9
            ),
            Reset::Gap { gap, max_gap } => {
                write!(f, "a gap of {gap:.3} s, longer than max gap {max_gap} s")
            }
        }
    }
}

/// What a stream gives for its newest positions.
#[derive(Clone, Debug, PartialEq)]
pub enum Estimate {
    /// The state at the newest stamp: positions (smoothed by a poly fit) and
    /// estimated velocities.
    Ready(State),
    /// Not enough history yet.
    WarmingUp {
        /// States in the history now.
        have: usize,
        /// States needed.
        needs: usize,
    },
}

/// The recent positions of one stream.
#[derive(Clone, Debug, Default)]
pub struct History {
    graph: Option<Graph>,
    stamps: VecDeque<Nanos>,
    positions: VecDeque<Vec<f64>>,
}

impl History {
    /// States held now.
    pub fn len(&self) -> usize {
        self.stamps.len()
    }

    /// Whether nothing is held.
    pub fn is_empty(&self) -> bool {
        self.stamps.is_empty()
    }

    /// The held stamps and positions, oldest first.
    pub fn window(&self) -> (Vec<Nanos>, Vec<&[f64]>) {
        (
            self.stamps.iter().copied().collect(),
            self.positions.iter().map(Vec::as_slice).collect(),
        )
    }

    /// Adds the positions `q` of `graph` at `t` and estimates the state there.
    /// Returns why the history was emptied first, if it was.
    pub fn push(
        &mut self,
        opts: &StreamOptions,
        graph: &Graph,
        t: Nanos,
        q: &[f64],
    ) -> (Option<Reset>, Estimate) {
        let reset = self.reset_for(opts, graph, t);
        if reset.is_some() || self.graph.is_none() {
            self.stamps.clear();
            self.positions.clear();
            self.graph = Some(graph.clone());
        }
        if reset.is_none() && self.stamps.back() == Some(&t) {
            // The same instant again: its positions replace the last ones.
            if let Some(last) = self.positions.back_mut() {
                last.clear();
                last.extend_from_slice(q);
            }
            return (None, self.estimate(opts));
        }
        let keep = opts.smoother.needs().max(3);
        let mut spare = None;
        while self.stamps.len() >= keep {
            self.stamps.pop_front();
            spare = self.positions.pop_front();
        }
        // The oldest buffer is reused for the newest positions.
        let mut buf = spare.unwrap_or_default();
        buf.clear();
        buf.extend_from_slice(q);
        self.positions.push_back(buf);
        self.stamps.push_back(t);
        (reset, self.estimate(opts))
    }

    fn reset_for(&self, opts: &StreamOptions, graph: &Graph, t: Nanos) -> Option<Reset> {
        let last = *self.stamps.back()?;
        if self.graph.as_ref() != Some(graph) {
            return Some(Reset::Graph);
        }
        if t < last {
            return Some(Reset::Earlier { last, now: t });
        }
        let gap = (t - last) as f64 * 1e-9;
        (opts.max_gap > 0.0 && gap > opts.max_gap).then_some(Reset::Gap {
            gap,
            max_gap: opts.max_gap,
        })
    }

    fn estimate(&self, opts: &StreamOptions) -> Estimate {
        let (have, needs) = (self.stamps.len(), opts.smoother.needs());
        if have < needs {
            return Estimate::WarmingUp { have, needs };
        }
        let m = have;
        let newest = self.stamps[m - 1];
        let secs = |k: usize| (newest - self.stamps[k]) as f64 * 1e-9;
        let q = &self.positions;
        let (wq, wv) = match opts.smoother {
            Smoother::None => {
                let (h1, h2) = (secs(m - 3) - secs(m - 2), secs(m - 2));
                let w = three_point(h1, h2, At::Last);
                let mut wq = vec![0.0; 3];
                wq[2] = 1.0;
                (wq, w.to_vec())
            }
            Smoother::Poly { window, order } => poly_weights(
                &(m - window..m).map(|k| -secs(k)).collect::<Vec<_>>(),
                order,
            ),
            Smoother::Model { window } => {
                poly_weights(&(m - window..m).map(|k| -secs(k)).collect::<Vec<_>>(), 2)
            }
        };
        let first = m - wq.len();
        let n = q[m - 1].len();
        let combine = |w: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|i| w.iter().enumerate().map(|(j, a)| a * q[first + j][i]).sum())
                .collect()
        };
        Estimate::Ready(State {
            q: combine(&wq),
            v: combine(&wv),
        })
    }
}

/// Weights giving the value and the first derivative at τ = 0 of the
/// least-squares polynomial of degree `order` through samples at times `tau`
/// (seconds, ≤ 0, the last 0). Times are scaled by their span so the fit is
/// well conditioned at any rate.
fn poly_weights(tau: &[f64], order: usize) -> (Vec<f64>, Vec<f64>) {
    let span = -tau[0];
    let a = DMatrix::from_fn(tau.len(), order + 1, |k, j| (tau[k] / span).powi(j as i32));
    // Rows of the pseudo-inverse: coefficient j as a combination of the samples.
    let pinv = a
        .svd(true, true)
        .pseudo_inverse(1e-12)
        .unwrap_or_else(|_| DMatrix::zeros(order + 1, tau.len()));
    let row = |j: usize, scale: f64| (0..tau.len()).map(|k| pinv[(j, k)] * scale).collect();
    (row(0, 1.0), row(1, 1.0 / span))
}

/// Per-stream values (histories, live accuracy) keyed by trajectory id,
/// keeping at most `capacity`: the stream seen least recently is dropped
/// first, so a publisher that changes ids every run cannot grow memory.
#[derive(Clone, Debug)]
pub struct Streams<V> {
    capacity: usize,
    tick: u64,
    map: HashMap<u32, (u64, V)>,
}

impl<V> Streams<V> {
    /// At most `capacity` (≥ 1) streams.
    pub fn new(capacity: usize) -> Self {
        Streams {
            capacity: capacity.max(1),
            tick: 0,
            map: HashMap::new(),
        }
    }

    /// The capacity.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The value of stream `id`, made by `new` when it is not held (dropping
    /// the least recently used one when full).
    pub fn get_or_insert_with(&mut self, id: u32, new: impl FnOnce() -> V) -> &mut V {
        self.tick += 1;
        if !self.map.contains_key(&id) && self.map.len() >= self.capacity {
            if let Some(oldest) = self
                .map
                .iter()
                .min_by_key(|(_, (t, _))| *t)
                .map(|(k, _)| *k)
            {
                self.map.remove(&oldest);
            }
        }
        let tick = self.tick;
        let entry = self.map.entry(id).or_insert_with(|| (tick, new()));
        entry.0 = tick;
        &mut entry.1
    }

    /// The value of stream `id`, if held (not counted as a use).
    pub fn get(&self, id: u32) -> Option<&V> {
        self.map.get(&id).map(|(_, v)| v)
    }

    /// Every value held, in no particular order.
    pub fn values(&self) -> impl Iterator<Item = &V> {
        self.map.values().map(|(_, v)| v)
    }

    /// Streams held.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// Whether none is held.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{SystemConfig, SystemKind};

    const MS: Nanos = 1_000_000;

    fn graph() -> Graph {
        SystemConfig::new(SystemKind::Spring, 2).graph()
    }

    /// q_i(t) = a_i + b_i t + c_i t² at uneven stamps: every estimate is exact.
    #[test]
    fn quadratics_are_followed_exactly_at_uneven_stamps() {
        let g = graph();
        let d = g.ndof();
        let q = |t: f64| -> Vec<f64> {
            (0..d)
                .map(|i| 0.3 * i as f64 + (1.0 - 0.2 * i as f64) * t - 0.7 * t * t)
                .collect()
        };
        let v = |t: f64| -> Vec<f64> { (0..d).map(|i| (1.0 - 0.2 * i as f64) - 1.4 * t).collect() };
        for smoother in [
            Smoother::None,
            Smoother::new("poly", 7, 2).unwrap(),
            Smoother::new("poly", 12, 3).unwrap(),
        ] {
            let opts = StreamOptions {
                smoother,
                max_gap: 0.0,
            };
            let mut h = History::default();
            let mut t: Nanos = 1_700_000_000_000_000_000;
            let t0 = t;
            for k in 0..30 {
                t += (10 + (k * 7) % 5) * MS;
                let secs = (t - t0) as f64 * 1e-9;
                let (reset, e) = h.push(&opts, &g, t, &q(secs));
                assert!(reset.is_none());
                match e {
                    Estimate::WarmingUp { have, needs } => {
                        assert_eq!((have, needs), (k as usize + 1, smoother.needs()));
                    }
                    Estimate::Ready(s) => {
                        assert!(k as usize + 1 >= smoother.needs());
                        for (a, b) in s.q.iter().zip(q(secs)) {
                            assert!((a - b).abs() < 1e-9, "{smoother:?} q {a} vs {b}");
                        }
                        for (a, b) in s.v.iter().zip(v(secs)) {
                            assert!((a - b).abs() < 1e-7, "{smoother:?} v {a} vs {b}");
                        }
                    }
                }
            }
            assert_eq!(h.len(), smoother.needs().max(3));
        }
    }

    /// The three-point rule is the bag reader's at a trajectory's end.
    #[test]
    fn no_smoother_matches_the_bag_readers_last_velocity() {
        let g = graph();
        let tr = crate::system::Trajectory {
            id: 1,
            system: String::new(),
            graph: g.clone(),
            samples: [0.0, 0.011, 0.019, 0.032]
                .iter()
                .map(|&t: &f64| crate::system::Sample {
                    t,
                    state: State {
                        q: (0..g.ndof()).map(|i| (3.0 * t + i as f64).sin()).collect(),
                        v: vec![0.0; g.ndof()],
                    },
                    acc: None,
                })
                .collect(),
        };
        let bag = super::super::dataset::finite_difference_velocities(&tr).unwrap();
        let mut h = History::default();
        let mut last = None;
        for s in &tr.samples {
            let ns = (s.t * 1e9).round() as Nanos + 5_000_000_000;
            last = Some(h.push(&StreamOptions::default(), &g, ns, &s.state.q).1);
        }
        let Some(Estimate::Ready(s)) = last else {
            panic!("no estimate: {last:?}");
        };
        for (a, b) in s.v.iter().zip(bag.last().unwrap()) {
            assert!((a - b).abs() < 1e-6 * b.abs().max(1.0), "{a} vs {b}");
        }
    }

    /// On a sine with position noise, the poly fit's velocity error is several
    /// times below the three-point rule's.
    #[test]
    fn poly_smoother_averages_noise() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let g = graph();
        let d = g.ndof();
        let noise = Normal::new(0.0, 1e-3).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let omega = 2.0;
        let rms = |smoother: Smoother, rng: &mut rand_chacha::ChaCha8Rng| {
            let opts = StreamOptions {
                smoother,
                max_gap: 0.0,
            };
            let mut h = History::default();
            let (mut sum, mut n) = (0.0, 0);
            for k in 0..400 {
                let t = k as f64 * 0.01;
                let q: Vec<f64> = (0..d)
                    .map(|i| (omega * t + i as f64).sin() + noise.sample(rng))
                    .collect();
                if let (_, Estimate::Ready(s)) = h.push(&opts, &g, k * 10 * MS, &q) {
                    for (i, v) in s.v.iter().enumerate() {
                        sum += (v - omega * (omega * t + i as f64).cos()).powi(2);
                        n += 1;
                    }
                }
            }
            (sum / f64::from(n)).sqrt()
        };
        let plain = rms(Smoother::None, &mut rng);
        let poly = rms(Smoother::new("poly", 15, 2).unwrap(), &mut rng);
        println!("velocity RMS error: three-point {plain:.3e}, poly(15, 2) {poly:.3e}");
        // σ = 1e-3 at h = 0.01: about 2.5 σ / h = 0.25 for the three-point rule.
        assert!((0.15..0.4).contains(&plain), "{plain}");
        assert!(poly < plain / 5.0, "{poly} vs {plain}");
    }

    #[test]
    fn graph_changes_backward_stamps_and_gaps_start_over() {
        let g = graph();
        let opts = StreamOptions {
            smoother: Smoother::None,
            max_gap: 0.5,
        };
        let mut h = History::default();
        let q = vec![0.0; g.ndof()];
        for k in 0..3 {
            assert_eq!(h.push(&opts, &g, k * 10 * MS, &q).0, None);
        }
        assert!(matches!(
            h.push(&opts, &g, 30 * MS, &q).1,
            Estimate::Ready(_)
        ));
        let (r, e) = h.push(&opts, &g, 20 * MS, &q);
        assert!(matches!(r, Some(Reset::Earlier { .. })), "{r:?}");
        assert!(r.unwrap().to_string().contains("before the previous"));
        assert_eq!(e, Estimate::WarmingUp { have: 1, needs: 3 });
        // The same instant again replaces the last state: no reset.
        let moved = vec![0.5; g.ndof()];
        let (r, e) = h.push(&opts, &g, 20 * MS, &moved);
        assert_eq!(r, None);
        assert_eq!((h.len(), e), (1, Estimate::WarmingUp { have: 1, needs: 3 }));
        assert_eq!(h.positions[0], moved);
        let (r, _) = h.push(&opts, &g, 900 * MS, &q);
        assert!(matches!(r, Some(Reset::Gap { .. })), "{r:?}");
        let other = SystemConfig::new(SystemKind::Spring, 3).graph();
        let (r, _) = h.push(&opts, &other, 910 * MS, &vec![0.0; other.ndof()]);
        assert_eq!(r, Some(Reset::Graph));
        assert_eq!(h.len(), 1);
    }

    #[test]
    fn smoother_settings_are_checked() {
        assert_eq!(Smoother::new("none", 0, 0).unwrap(), Smoother::None);
        for (name, w, o, want) in [
            ("poly", 3, 2, "window 3"),
            ("poly", 9, 7, "order 7"),
            ("kalman", 9, 2, "one of none, poly"),
        ] {
            let e = Smoother::new(name, w, o).unwrap_err().to_string();
            assert!(e.contains(want), "{e}");
        }
    }

    #[test]
    fn streams_keep_the_most_recent_ones() {
        let mut s: Streams<u32> = Streams::new(2);
        *s.get_or_insert_with(1, || 10) += 1;
        s.get_or_insert_with(2, || 20);
        s.get_or_insert_with(1, || 0);
        s.get_or_insert_with(3, || 30);
        assert_eq!(s.len(), 2);
        assert_eq!(s.get(1), Some(&11));
        assert_eq!(s.get(2), None, "least recently used dropped");
        assert_eq!(s.get(3), Some(&30));
    }
}
