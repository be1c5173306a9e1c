//! The one entry point of every baseline, [`BaselineNet::acceleration`] and
//! [`BaselineNet::loss`], dispatching to LGN, HGN or GNS (which build on
//! [`BaselineNet`] and do not import this module).

use super::net::{BaselineNet, Kind};
use super::{gns, hgn, lgn};
use crate::error::Result;
use crate::gnode::batch::Batch;
use candle_core::Tensor;

impl BaselineNet {
    /// Predicted accelerations `(B·n, d)`.
    pub fn acceleration(&self, b: &Batch) -> Result<Tensor> {
        self.check(b)?;
        match self.hyper.kind {
            Kind::Lgn => lgn::acceleration(self, b),
            Kind::Hgn => hgn::acceleration(self, b),
            Kind::Gns => gns::acceleration(self, b),
        }
    }

    /// Training loss: MSE on accelerations (LGN, GNS) or on (q̇, ṗ) (HGN,
    /// targets derived from the batch's velocities and accelerations with the
    /// true `masses`, one per particle).
    pub fn loss(&self, b: &Batch, masses: &[f64]) -> Result<Tensor> {
        self.check(b)?;
        match self.hyper.kind {
            Kind::Hgn => hgn::loss(self, b, masses),
            _ => b.mse(&self.acceleration(b)?),
        }
    }
}
