//! Reverse mode through a trained model's accelerations, for planning
//! gradients: the inference workspace for the forward sweep (the same bits
//! as the model's rollouts) and the engine's [`Reverse`] for the backward one.

use super::{Kernel, Workspace};
use crate::dynamics::StateGradient;
use crate::engine::Reverse;
use crate::gnode::arch::ArchError;
use crate::gnode::graph_plan::GraphPlan;
use crate::physics::Projector;
use crate::system::Graph;

/// A kernel with the buffers of one graph, forward and reverse.
#[derive(Clone, Debug)]
pub struct KernelGradient {
    kernel: Kernel,
    ws: Workspace,
    reverse: Reverse,
}

impl Kernel {
    /// Forward and reverse buffers for `graph`.
    pub fn gradient(&self, graph: &Graph) -> Result<KernelGradient, ArchError> {
        let ws = self.workspace(graph)?;
        Ok(KernelGradient {
            kernel: self.clone(),
            ws,
            reverse: Reverse::new(self.arch.clone(), GraphPlan::new(graph)),
        })
    }
}

impl StateGradient for KernelGradient {
    fn acceleration(&mut self, q: &[f64], v: &[f64], acc: &mut [f64]) {
        self.kernel.acceleration(&mut self.ws, q, v, acc);
    }

    fn vjp(
        &mut self,
        q: &[f64],
        v: &[f64],
        gacc: &[f64],
        acc: &mut [f64],
        gq: &mut [f64],
        gv: &mut [f64],
    ) {
        self.reverse
            .vjp(&self.kernel.theta, q, v, gacc, acc, gq, gv);
    }

    fn projector(&self) -> Option<Projector> {
        self.ws.projector.clone()
    }
}
