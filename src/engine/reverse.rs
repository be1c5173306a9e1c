//! Reverse mode through one state's accelerations with respect to the state
//! itself (∂q̈/∂q, ∂q̈/∂q̇ applied to a vector): the training engine's
//! backward pass carried down to its inputs. Planning gradients chain it
//! through a rollout ([`crate::plan::gradient`]).

use super::chunk::{Chunk, Model};
use crate::gnode::arch::Arch;
use crate::gnode::graph_plan::GraphPlan;

/// One graph's reverse pass and its buffers (a training chunk of one state).
#[derive(Clone, Debug)]
pub struct Reverse {
    model: Model,
    chunk: Chunk,
}

impl Reverse {
    /// Buffers for `plan` under `arch` (whose support of the graph the caller
    /// has checked).
    pub fn new(arch: Arch, plan: GraphPlan) -> Self {
        Self {
            model: Model::new(arch, plan),
            chunk: Chunk::default(),
        }
    }

    /// The graph as the engine sees it.
    pub fn plan(&self) -> &GraphPlan {
        &self.model.plan
    }

    /// q̈ at (q, q̇) under `theta` into `acc`, and, with L = Σ ḡ·q̈ for
    /// ḡ = `gacc`, ∂L/∂q into `gq` and ∂L/∂q̇ into `gv`; all node-major
    /// `n·d`. Kinematic particles' q̈ is 0 and their rows of `gacc` count
    /// for nothing, as in [`super::Forward::run`].
    #[allow(clippy::too_many_arguments)]
    pub fn vjp(
        &mut self,
        theta: &[f64],
        q: &[f64],
        v: &[f64],
        gacc: &[f64],
        acc: &mut [f64],
        gq: &mut [f64],
        gv: &mut [f64],
    ) {
        self.chunk
            .input_vjp(&self.model, theta, q, v, gacc, acc, gq, gv);
    }
}
