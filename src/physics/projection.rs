//! SHAKE/RATTLE: projecting a Verlet step back onto the rigid bars, with any
//! diagonal masses. The simulator uses it with the true masses; learned
//! constrained models use it with their learned masses, so their rollouts keep
//! every bar length exact instead of drifting.

use super::constraints::Bars;
use crate::system::Graph;

/// Bars of one graph, their masses and scratch buffers: steps do not allocate
/// (except for redundant bars, which fall back to SVD).
#[derive(Clone, Debug)]
pub struct Projector {
    /// The graph with the masses the projection uses.
    graph: Graph,
    bars: Bars,
    dirs_old: Vec<f64>,
    dirs_new: Vec<f64>,
    iterations: u64,
    failures: u64,
}

impl Projector {
    /// Relative bar-length tolerance of the SHAKE iteration.
    pub const TOL: f64 = 1e-13;
    /// Newton iterations allowed per step before giving up (counted in
    /// [`Projector::failures`]).
    pub const MAX_ITER: usize = 50;

    /// A projector for the bars of `graph`, weighting by `graph.masses`.
    pub fn new(graph: &Graph) -> Self {
        let bars = Bars::new(graph);
        let kd = bars.k() * graph.dim;
        Self {
            graph: graph.clone(),
            bars,
            dirs_old: vec![0.0; kd],
            dirs_new: vec![0.0; kd],
            iterations: 0,
            failures: 0,
        }
    }

    /// Whether there is anything to project.
    pub fn has_bars(&self) -> bool {
        self.bars.k() > 0
    }

    /// Remembers the bar directions at the start of a step (SHAKE moves
    /// along them).
    pub fn begin(&mut self, q: &[f64]) {
        if self.has_bars() {
            self.bars.dirs(&self.graph, q, &mut self.dirs_old);
        }
    }

    /// SHAKE: after the drift q' = q + v dt + ½a dt², Newton iterations on γ
    /// move q' −= M⁻¹A(q)ᵀγ until every bar has its length to [`Self::TOL`]
    /// (relative); the half-step velocity gets the same kick (÷ dt).
    pub fn shake(&mut self, q: &mut [f64], v_half: &mut [f64], dt: f64) {
        let (g, k) = (&self.graph, self.bars.k());
        if k == 0 {
            return;
        }
        for _ in 0..Self::MAX_ITER {
            self.bars.dirs(g, q, &mut self.dirs_new);
            let d = g.dim;
            let mut worst = 0.0_f64;
            for j in 0..k {
                let r2: f64 = self.dirs_new[j * d..(j + 1) * d]
                    .iter()
                    .map(|x| x * x)
                    .sum();
                let l = self.bars.len[j];
                worst = worst.max((r2.sqrt() - l).abs() / l);
                self.bars.rhs[j] = 0.5 * (r2 - l * l);
            }
            if worst <= Self::TOL {
                return;
            }
            // dφ/dγ = −A(q') M⁻¹ A(q)ᵀ; solve for the Newton update.
            self.iterations += 1;
            if !self.bars.solve(g, &self.dirs_new, &self.dirs_old) {
                break;
            }
            self.bars.apply_t(g, &self.dirs_old, 1.0, q);
            self.bars.apply_t(g, &self.dirs_old, 1.0 / dt, v_half);
        }
        self.failures += 1;
    }

    /// RATTLE: removes the velocity components along the bars at q,
    /// v −= M⁻¹A(q)ᵀμ with A(q) v = 0 exactly afterwards.
    pub fn rattle(&mut self, q: &[f64], v: &mut [f64]) {
        let g = &self.graph;
        if self.bars.k() == 0 {
            return;
        }
        self.bars.dirs(g, q, &mut self.dirs_new);
        for j in 0..self.bars.k() {
            self.bars.rhs[j] = self.bars.mul(g, &self.dirs_new, v, j);
        }
        if self.bars.solve(g, &self.dirs_new, &self.dirs_new) {
            self.bars.apply_t(g, &self.dirs_new, 1.0, v);
        } else {
            self.failures += 1;
        }
    }

    /// Newton iterations SHAKE has taken in total (a cost diagnostic).
    pub fn iterations(&self) -> u64 {
        self.iterations
    }

    /// Steps whose SHAKE iteration did not converge, or whose constraint
    /// matrix could not be solved (degenerate bars). 0 for a healthy run.
    pub fn failures(&self) -> u64 {
        self.failures
    }
}
