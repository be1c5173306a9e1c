//! The baseline models' hyperparameters and parameters. The one entry point
//! (`acceleration`, `loss`) that dispatches to LGN, HGN or GNS is in
//! [`super::forward`], above the three.

use super::graphnet::{GraphNet, GraphNetSpec};
use crate::error::{bail, Result};
use crate::gnode::batch::Batch;
use crate::gnode::mlp::Mlp;
use crate::gnode::params::ParamStore;
use candle_core::{DType, Device, Tensor};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Which baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// Lagrangian graph network.
    Lgn,
    /// Hamiltonian graph network.
    Hgn,
    /// Graph network simulator.
    Gns,
}

impl Kind {
    /// All baselines.
    pub const ALL: [Kind; 3] = [Kind::Lgn, Kind::Hgn, Kind::Gns];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Lgn => "lgn",
            Kind::Hgn => "hgn",
            Kind::Gns => "gns",
        }
    }
}

impl crate::names::Named for Kind {
    const ALL: &'static [Self] = &Kind::ALL;
    const WHAT: &'static str = "baseline";

    fn name(self) -> &'static str {
        Kind::name(self)
    }
}

crate::impl_named!(Kind);

/// Architecture of a baseline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaselineHyper {
    /// Which baseline.
    pub kind: Kind,
    /// Spatial dimension.
    pub dim: usize,
    /// Particle types (one-hot width).
    pub types: usize,
    /// Hidden units per MLP (paper, LGN/HGN: 16).
    pub hidden: usize,
    /// Node/edge latent width (paper, LGN/HGN: 8).
    pub latent: usize,
    /// Message-passing rounds (paper, LGN/HGN: 1; GNS processor steps).
    pub rounds: usize,
    /// GNS: pairs closer than this interact through edges found at each
    /// state (its radius graph); 0 (and absent from older files): fixed
    /// edges only. A model serves only graphs of its radius.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub interaction_radius: f64,
}

/// Serde's test for leaving a radius of 0 out (files as before it existed).
#[allow(clippy::trivially_copy_pass_by_ref)] // serde passes a reference
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl BaselineHyper {
    /// Defaults: LGN/HGN as the paper's table (embeddings 8, hidden 16, one
    /// round); GNS small (latent 16, hidden 16, 2 processor steps; the original
    /// uses 128 and 10).
    pub fn new(kind: Kind, dim: usize, types: usize) -> Self {
        let (latent, rounds) = match kind {
            Kind::Lgn | Kind::Hgn => (8, 1),
            Kind::Gns => (16, 2),
        };
        Self {
            kind,
            dim,
            types: types.max(1),
            hidden: 16,
            latent,
            rounds,
            interaction_radius: 0.0,
        }
    }

    /// The executor's description of a GNS of these settings.
    pub fn gns_spec(&self) -> crate::engine::GnsSpec {
        crate::engine::GnsSpec {
            dim: self.dim,
            types: self.types,
            hidden: self.hidden,
            latent: self.latent,
            rounds: self.rounds,
        }
    }

    /// The executor's description of an LGN or HGN of these settings
    /// (`None` for GNS).
    pub fn potential_spec(&self) -> Option<crate::engine::PotentialSpec> {
        use crate::engine::PotentialLoss;
        let loss = match self.kind {
            Kind::Lgn => PotentialLoss::Acceleration,
            Kind::Hgn => PotentialLoss::Hamilton,
            Kind::Gns => return None,
        };
        Some(crate::engine::PotentialSpec {
            dim: self.dim,
            types: self.types,
            hidden: self.hidden,
            latent: self.latent,
            rounds: self.rounds,
            loss,
        })
    }

    /// This baseline on the executor for `graph`, its parameters laid out as
    /// `params`, over `threads` threads.
    pub fn executor(
        &self,
        params: &[(String, usize)],
        graph: &crate::system::Graph,
        threads: usize,
    ) -> Result<crate::engine::BaselineExecutor, crate::engine::EngineError> {
        use crate::engine::{BaselineExecutor, Gns, Potential};
        Ok(match self.potential_spec() {
            None => BaselineExecutor::Gns(Gns::new(self.gns_spec(), params, graph, threads)?),
            Some(spec) => {
                BaselineExecutor::Potential(Potential::new(spec, params, graph, threads)?)
            }
        })
    }

    /// Scalar parameters of the network these settings define, counted as
    /// [`BaselineNet::new`] declares them but without building it; `None` if
    /// the count overflows. For refusing a file whose settings need more
    /// parameters than it holds before allocating them (a corrupt width of
    /// 10^15 would abort, 10^15 rounds would never end).
    pub fn param_count(&self) -> Option<usize> {
        let (d, t, h, l) = (self.dim, self.types, self.hidden, self.latent);
        let energy = self.kind != Kind::Gns;
        // An MLP inp → h → out, with biases.
        let mlp = |inp: usize, out: usize| -> Option<usize> {
            inp.checked_mul(h)?
                .checked_add(h)?
                .checked_add(h.checked_mul(out)?)?
                .checked_add(out)
        };
        let node_in = t.checked_add(if energy { d } else { d.checked_mul(2)? })?;
        let edge_in = d.checked_add(usize::from(!energy))?;
        let round = mlp(l.checked_mul(3)?, l)?.checked_add(mlp(l.checked_mul(2)?, l)?)?;
        let mut n = mlp(node_in, l)?
            .checked_add(mlp(edge_in, l)?)?
            .checked_add(round.checked_mul(self.rounds)?)?
            .checked_add(mlp(l, if energy { 1 } else { d })?)?;
        if energy {
            n = n.checked_add(mlp(l, 1)?)?.checked_add(t)?;
        }
        Some(n)
    }
}

/// A baseline's parameters and networks.
#[derive(Clone, Debug)]
pub struct BaselineNet {
    /// Architecture.
    pub hyper: BaselineHyper,
    /// Parameters.
    pub store: ParamStore,
    /// The graph network.
    pub graph: GraphNet,
    /// LGN/HGN: per-node energy readout; GNS: acceleration decoder.
    pub node_out: Mlp,
    /// LGN/HGN: per-edge energy readout.
    pub edge_out: Option<Mlp>,
}

impl BaselineNet {
    /// A freshly initialised model (seeded by `rng`).
    pub fn new(hyper: BaselineHyper, rng: &mut impl Rng) -> Result<Self> {
        if hyper.dim != 2 && hyper.dim != 3 {
            bail!("baseline dimension must be 2 or 3, got {}", hyper.dim);
        }
        if hyper.hidden == 0 || hyper.latent == 0 {
            bail!("hidden and latent widths must be positive");
        }
        let (d, t, h, l) = (hyper.dim, hyper.types, hyper.hidden, hyper.latent);
        let mut store = ParamStore::new();
        let energy = hyper.kind != Kind::Gns;
        let spec = GraphNetSpec {
            // LGN/HGN: a potential V(q), inputs type and position; GNS: type,
            // position and velocity (as GNODE; position stands in for the
            // original's distance-to-boundary features, needed for anchors).
            node_in: if energy { t + d } else { t + 2 * d },
            dim: d,
            hidden: h,
            latent: l,
            rounds: hyper.rounds,
            residual: !energy,
            edge_distance: !energy,
        };
        let graph = GraphNet::new(&mut store, spec, rng)?;
        let out = if energy { 1 } else { d };
        let node_out = Mlp::new(&mut store, "node_out", &[l, h, out], rng)?;
        let edge_out = if energy {
            Some(Mlp::new(&mut store, "edge_out", &[l, h, 1], rng)?)
        } else {
            None
        };
        if energy {
            store.insert("log_mass", &[t], vec![0.0; t])?;
        }
        Ok(Self {
            hyper,
            store,
            graph,
            node_out,
            edge_out,
        })
    }

    /// Every parameter's name and scalar count, in the flat vector's order
    /// (what [`crate::engine::Gns`] reads its weights by).
    pub fn param_sizes(&self) -> Result<Vec<(String, usize)>> {
        self.store
            .names()
            .iter()
            .map(|n| Ok((n.clone(), self.store.get(n)?.elem_count())))
            .collect()
    }

    /// Learned masses per row of the batch, `(B·n, 1)` (LGN/HGN).
    pub fn row_masses(&self, b: &Batch) -> Result<Tensor> {
        let m = self.store.get("log_mass")?.as_tensor().exp()?;
        Ok(m.index_select(&b.types, 0)?.unsqueeze(1)?)
    }

    /// The learned potential V(q) summed over the batch (LGN/HGN): per-node
    /// plus per-directed-edge energies from the graph network.
    pub fn potential(&self, b: &Batch, q: &Tensor) -> Result<Tensor> {
        let x = Tensor::cat(&[&b.onehot, q], 1)?;
        let (h, e) = self.graph.run(&self.store, b, q, &x)?;
        let mut v = self.node_out.forward(&self.store, &h)?.sum_all()?;
        if let (Some(e), Some(eo)) = (e, &self.edge_out) {
            v = (v + eo.forward(&self.store, &e)?.sum_all()?)?;
        }
        Ok(v)
    }

    /// ∂V/∂q `(B·n, d)` of the learned potential ([`BaselineNet::potential`])
    /// by a backward pass written as candle ops
    /// ([`GraphNet::input_grads`]): a function of the weights that candle
    /// differentiates once in training, where a first autodiff pass would
    /// make it differentiate twice.
    pub fn potential_grad(&self, b: &Batch, q: &Tensor) -> Result<Tensor> {
        let x = Tensor::cat(&[&b.onehot, q], 1)?;
        let t = self.graph.run_traced(&self.store, b, q, &x)?;
        let ones = |rows: usize| Tensor::ones((rows, 1), DType::F64, &Device::Cpu);
        let (_, pre) = self.node_out.forward_keep(&self.store, &t.h)?;
        let dh = self
            .node_out
            .input_grad(&self.store, &pre, &ones(t.h.dim(0)?)?)?;
        let de = match (&t.e, &self.edge_out) {
            (Some(e), Some(eo)) => {
                let (_, pre) = eo.forward_keep(&self.store, e)?;
                Some(eo.input_grad(&self.store, &pre, &ones(e.dim(0)?)?)?)
            }
            _ => None,
        };
        let (gx, gq) = self
            .graph
            .input_grads(&self.store, b, &t, &dh, de.as_ref())?;
        let gx = gx.narrow(1, self.hyper.types, self.hyper.dim)?;
        Ok(match gq {
            Some(gq) => (gx + gq)?,
            None => gx,
        })
    }

    /// The force −∂V/∂q − Aᵀλ on every particle `(B·n, d)`, the bars'
    /// multipliers keeping A q̈ + Ȧq̇ = 0 with q̈ = M⁻¹ f:
    /// λ = (A M⁻¹ Aᵀ)⁻¹ (Ȧq̇ − A M⁻¹ ∂V/∂q). With a diagonal learned mass this
    /// is HGN's ṗ and LGN's M q̈ alike (Hamilton's and Euler–Lagrange's
    /// equations agree), and M is never formed as a matrix.
    pub fn bar_constrained_force(&self, b: &Batch) -> Result<Tensor> {
        let gq = self.potential_grad(b, &b.q)?;
        let Some((a, at, adq)) = &b.constraint else {
            return Ok(gq.neg()?);
        };
        let dd = b.n * b.dim;
        let minv = self
            .row_masses(b)?
            .recip()?
            .broadcast_as((b.b * b.n, b.dim))?
            .reshape((b.b, dd, 1))?;
        let gq3 = gq.reshape((b.b, dd, 1))?;
        let s = a.matmul(&at.broadcast_mul(&minv)?)?;
        let rhs = (adq - a.matmul(&(&gq3 * &minv)?)?)?;
        let lambda = crate::gnode::solve::solve(&s, &rhs)?;
        Ok((gq3.neg()? - at.matmul(&lambda)?)?.reshape(b.q.dims())?)
    }

    /// Refuses a batch of another dimension.
    pub(super) fn check(&self, b: &Batch) -> Result<()> {
        if b.dim != self.hyper.dim {
            bail!(
                "{} was built for {}D systems, got {}D",
                self.hyper.kind,
                self.hyper.dim,
                b.dim
            );
        }
        Ok(())
    }
}
