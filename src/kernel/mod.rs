//! Inference: a trained model's weights on the engine's forward pass
//! ([`crate::engine::Forward`], the same equations training differentiates,
//! feature-major), with every buffer allocated once per graph in a
//! [`Workspace`]. Rollouts and the ROS node run on this; candle is the
//! reference it is tested against (to 1e-12).

pub mod ensemble;
pub mod gradient;
pub mod trained;

use crate::engine::{Forward, Layout};
use crate::error::{bail, Result};
use crate::gnode::arch::{Arch, ArchError, LOG_MASS};
use crate::gnode::graph_plan::GraphPlan;
use crate::gnode::params::Weights;
use crate::gnode::variant::Hyper;
use crate::physics::Projector;
use crate::system::Graph;
pub use ensemble::Ensemble;
pub use gradient::KernelGradient;
use rand::SeedableRng;
pub use trained::TrainedModel;

use std::sync::Arc;

/// A trained model's forward pass, ready to run.
#[derive(Clone, Debug)]
pub struct Kernel {
    hyper: Hyper,
    arch: Arch,
    /// Every parameter, flat, at the engine's offsets; shared and never
    /// changed, so that a workspace knows them again by their address.
    theta: Arc<[f64]>,
    inv_mass: Option<Vec<f64>>,
    project_bars: bool,
}

/// Buffers for one graph; reused across steps so that the loop allocates nothing.
#[derive(Clone, Debug)]
pub struct Workspace {
    forward: Forward,
    /// Forces of the last evaluation, `n·d` (constrained variants).
    pub force: Vec<f64>,
    /// Antisymmetric pairwise forces of the last evaluation, `E·d`, on `a`
    /// due to `b` of the `e`-th of [`Workspace::edge_pairs`] (MCGNODE): the
    /// fixed edges, then the contacts of that state.
    pub edge_force: Vec<f64>,
    /// SHAKE/RATTLE onto the bars with the learned masses, for rollouts of
    /// constrained models on graphs with bars (see [`Kernel::set_project_bars`]).
    pub projector: Option<Projector>,
    /// A rollout's q, q̇ and q̈, kept so that the next one on this workspace
    /// allocates nothing.
    rollout: [Vec<f64>; 3],
    /// The graph's periodic box, which a rollout wraps positions into.
    periodic: Option<crate::system::PeriodicBox>,
}

impl Workspace {
    /// The graph as the kernel sees it.
    pub fn plan(&self) -> &GraphPlan {
        self.forward.plan()
    }

    /// Runs the edge MLPs of large graphs on two cores from now on (see
    /// [`Forward::split_rows`]): for a workspace that serves one rollout at
    /// a time, not for one per core.
    pub fn split_rows(&mut self) {
        self.forward.split_rows();
    }

    /// The edges of the last evaluation as (a, b) pairs: fixed, then contacts.
    pub fn edge_pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.forward.edge_pairs()
    }
}

/// Checks, before anything is allocated for them, that a file's
/// hyperparameters can describe the weights stored with them: no more layers
/// than (weight, bias) pairs, no more parameters than the file holds, scales
/// that can be used. A corrupt width or count (10^15) would
/// otherwise abort on allocation or build for ever, and a short `q_mean`
/// would index out of bounds in every forward pass.
fn check_sizes(hyper: &Hyper, w: &Weights) -> Result<()> {
    if hyper.dim != 2 && hyper.dim != 3 {
        bail!("model dimension must be 2 or 3, got {}", hyper.dim);
    }
    let Some(arch) = Arch::within(hyper, w.len() / 2) else {
        bail!(
            "the model's hyperparameters define more layers than its {} weight arrays can hold",
            w.len()
        );
    };
    // With no width 0, every size is at least one parameter of some layer,
    // so the count below bounds them all (and the buffers sized by them).
    if let Some((block, _)) = arch.mlps.iter().find(|(_, s)| s.contains(&0)) {
        bail!("the model's hyperparameters give block {block} a layer of width 0");
    }
    let stored: usize = w.values().map(|a| a.data.len()).sum();
    match arch.param_count() {
        Some(n) if n <= stored => {}
        n => bail!(
            "the model's hyperparameters define {} parameters, more than the {stored} its file holds",
            n.map_or_else(|| "over 2^64".to_string(), |n| n.to_string())
        ),
    }
    if let Some(nm) = &hyper.norm {
        if nm.q_mean.len() != hyper.dim {
            bail!(
                "the model's norm.q_mean has {} entries for dimension {}",
                nm.q_mean.len(),
                hyper.dim
            );
        }
        let scales = [
            ("q_scale", nm.q_scale),
            ("v_scale", nm.v_scale),
            ("w_scale", nm.w_scale),
            ("out_scale", nm.out_scale),
            ("k_scale", nm.k_scale),
        ];
        if let Some((name, x)) = scales.iter().find(|(_, x)| !(x.is_finite() && *x > 0.0)) {
            bail!("the model's norm.{name} = {x} is not a finite number > 0");
        }
        if nm.q_mean.iter().any(|x| !x.is_finite()) {
            bail!("the model's norm.q_mean is not finite");
        }
    }
    Ok(())
}

impl Kernel {
    /// Builds the kernel from a model's hyperparameters and weights.
    pub fn new(hyper: &Hyper, w: &Weights) -> Result<Self> {
        check_sizes(hyper, w)?;
        // Names, shapes and finiteness are checked against the architecture that
        // `hyper` defines, so the loops below can trust every size.
        let reference = crate::gnode::Net::new(
            hyper.clone(),
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(0),
        )?;
        reference.store.load(w)?;
        let arch = Arch::new(hyper);
        let theta = Layout::new(&arch).flatten(w)?.into();
        let inv_mass = w
            .get(LOG_MASS)
            .map(|a| a.data.iter().map(|x| (-x).exp()).collect());
        if inv_mass.is_some() != hyper.variant.biases().constrained {
            bail!("weights do not match a {} model", hyper.variant);
        }
        Ok(Self {
            hyper: hyper.clone(),
            arch,
            theta,
            inv_mass,
            project_bars: true,
        })
    }

    /// Whether rollouts project positions and velocities back onto the bars
    /// every step (RATTLE with the learned masses; on by default). Without it
    /// a learned rollout lets bar lengths drift by the integrator's error.
    pub fn set_project_bars(&mut self, on: bool) {
        self.project_bars = on;
    }

    /// Learned masses per particle type (constrained models).
    pub fn learned_masses(&self) -> Option<Vec<f64>> {
        self.inv_mass
            .as_ref()
            .map(|im| im.iter().map(|x| 1.0 / x).collect())
    }

    /// The hyperparameters.
    pub fn hyper(&self) -> &Hyper {
        &self.hyper
    }

    /// Whether the kernel can run on this graph.
    pub fn supports(&self, graph: &Graph) -> Result<(), ArchError> {
        self.arch.supports(graph)
    }

    /// Allocates the buffers for a graph.
    pub fn workspace(&self, graph: &Graph) -> Result<Workspace, ArchError> {
        self.supports(graph)?;
        let plan = GraphPlan::new(graph);
        let (nd, ne, bars) = (plan.n * plan.dim, plan.n_edges(), plan.bars.len());
        let projector = match self.learned_masses() {
            Some(m) if self.project_bars && bars > 0 => {
                let mut g = graph.clone();
                g.masses = g.types.iter().map(|&t| m[t as usize]).collect();
                Some(Projector::new(&g))
            }
            _ => None,
        };
        Ok(Workspace {
            force: vec![0.0; nd],
            edge_force: vec![0.0; ne * plan.dim],
            forward: Forward::new(self.arch.clone(), plan),
            projector,
            rollout: [vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]],
            periodic: graph.periodic().cloned(),
        })
    }

    /// Accelerations at (q, v), written to `acc` (`n·d`); see
    /// [`Kernel::read_forces`] for the forces of the same evaluation.
    pub fn acceleration(&self, ws: &mut Workspace, q: &[f64], v: &[f64], acc: &mut [f64]) {
        ws.forward.run(&self.theta, q, v, acc);
    }

    /// The forces of the last [`Kernel::acceleration`] into `ws.force`
    /// (constrained variants) and `ws.edge_force` (pairwise ones), read off
    /// that evaluation (rollouts do not pay for them).
    pub fn read_forces(&self, ws: &mut Workspace) {
        let b = self.hyper.variant.biases();
        if b.constrained {
            ws.forward.forces(&mut ws.force);
        }
        if b.pairwise {
            ws.forward.edge_forces(&mut ws.edge_force);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::TrainedModel;
    use crate::dynamics::Dynamics;
    use crate::gnode::{ModelFile, Norm, Variant};
    use crate::physics::{SystemConfig, SystemKind};

    /// Builds a kernel from a random model's file after `edit`, as loading
    /// an edited file does; on success runs one acceleration on the
    /// 3-spring ring the model was made for.
    fn load_edited(
        variant: Variant,
        edit: impl FnOnce(&mut ModelFile),
    ) -> Result<Vec<f64>, String> {
        let c = SystemConfig::new(SystemKind::Spring, 3);
        let g = c.graph();
        let s = c.start_for(&g, 1, 0);
        let (_, m) = crate::testing::random_model(variant, &g, 3).expect("model");
        let mut file = m.file;
        edit(&mut file);
        let m = TrainedModel::from_file(file).map_err(|e| e.to_string())?;
        let mut out = vec![0.0; g.ndof()];
        m.acceleration(&g, &s, &mut out)
            .map_err(|e| e.to_string())?;
        Ok(out)
    }

    /// Settings a corrupt model file can hold (tests/fuzz_readers.rs edits
    /// them; each was checked to fail this way before `check_sizes`): they
    /// allocated terabytes (an abort), panicked on a capacity overflow or an
    /// index out of bounds, or never finished loading.
    #[test]
    fn corrupt_sizes_are_errors_not_aborts() {
        type Edit = fn(&mut ModelFile);
        let cases: [(Variant, Edit, &str); 12] = [
            (
                Variant::Mcgnode,
                |f| f.hyper.hidden = 1_000_000,
                "5000055000023 parameters, more than the 423",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.hidden = usize::MAX,
                "over 2^64 parameters",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.embed = 1 << 32,
                "parameters, more than the 423",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.types = usize::MAX,
                "over 2^64 parameters",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.rounds = 1_000_000_000_000_000,
                "more layers than its 31 weight arrays",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.hidden_layers = 1_000_000_000_000_000,
                "more layers than its 31",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.hidden = 0,
                "block node_em a layer of width 0",
            ),
            (
                Variant::Mcgnode,
                |f| f.hyper.dim = 1_000_000_000_000_000,
                "dimension must be 2 or 3",
            ),
            (
                Variant::Node,
                |f| f.hyper.node_hidden = 1_000_000,
                "parameters, more than the 582",
            ),
            (
                Variant::Node,
                |f| f.hyper.node_layers = 1_000_000_000_000_000,
                "more layers than its 6",
            ),
            (
                Variant::Node,
                |f| f.hyper.particles = usize::MAX,
                "over 2^64 parameters",
            ),
            (
                Variant::Gnode,
                |f| {
                    let mut n = Norm::identity(2);
                    n.q_mean = vec![0.0];
                    f.hyper.norm = Some(n);
                },
                "norm.q_mean has 1 entries for dimension 2",
            ),
        ];
        for (variant, edit, want) in cases {
            let e = load_edited(variant, edit).expect_err(want);
            assert!(e.contains(want), "{variant}: {e:?} does not say {want:?}");
        }
    }

    /// A normalisation whose scale is zero is refused on loading.
    #[test]
    fn a_zero_norm_scale_is_an_error() {
        let e = load_edited(Variant::Gnode, |f| {
            let mut n = Norm::identity(2);
            n.q_scale = 0.0;
            f.hyper.norm = Some(n);
        })
        .expect_err("a zero scale makes every output NaN");
        assert!(
            e.contains("norm.q_scale = 0 is not a finite number > 0"),
            "{e}"
        );
    }

    /// Settings that size no weight do not size buffers either: NODE's
    /// `embed` and `types` (tests/fuzz_readers.rs met a NODE file whose
    /// `embed` of 2^32 made the workspace ask for 100 GB, an abort), and a
    /// `types` of 0, which the architecture reads as 1 (the kernel indexed
    /// out of bounds).
    #[test]
    fn settings_that_size_no_weight_are_harmless() {
        let plain = load_edited(Variant::Node, |_| {}).expect("node");
        let odd = load_edited(Variant::Node, |f| {
            f.hyper.embed = 1 << 32;
            f.hyper.types = 1 << 40;
        })
        .expect("NODE ignores embed and types");
        assert_eq!(plain, odd);
        for v in [Variant::Gnode, Variant::Mcgnode] {
            let one = load_edited(v, |_| {}).expect("model");
            let zero = load_edited(v, |f| f.hyper.types = 0).expect("types 0 reads as 1");
            assert_eq!(one, zero, "{v}");
        }
    }
}
