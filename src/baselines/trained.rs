//! A trained baseline serving [`Dynamics`] on the executor's forward pass
//! (GNS; LGN and HGN with their force pass).

use super::file::BaselineFile;
use super::net::{BaselineHyper, BaselineNet, Kind};
use crate::dynamics::{Dynamics, DynamicsError, Forces};
use crate::engine::{BaselineExecutor, ExecutorModel};
use crate::error::{bail, Result};
use crate::gnode::arch::ArchError;
use crate::system::{Graph, State};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use std::sync::Mutex;

/// A trained baseline ready for rollouts.
#[derive(Clone, Debug)]
pub struct TrainedBaseline {
    /// Metadata and weights.
    pub file: BaselineFile,
    /// The network with those weights.
    pub net: BaselineNet,
    /// Its weights as one vector and the executor of the last graph, whose
    /// forward pass serves rollouts (candle's per-call cost is
    /// milliseconds).
    exec: Executor,
}

/// The weights and an executor for the last graph seen.
struct Executor {
    theta: Vec<f64>,
    params: Vec<(String, usize)>,
    last: Mutex<Option<(Graph, BaselineExecutor)>>,
}

impl std::fmt::Debug for Executor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Executor")
            .field("parameters", &self.theta.len())
            .finish_non_exhaustive()
    }
}

impl Clone for Executor {
    fn clone(&self) -> Self {
        Self {
            theta: self.theta.clone(),
            params: self.params.clone(),
            last: Mutex::new(None),
        }
    }
}

impl TrainedBaseline {
    /// Loads a baseline file.
    pub fn load(path: &Path) -> Result<Self> {
        Self::from_file(BaselineFile::load(path)?)
    }

    /// Builds the network of an in-memory file.
    pub fn from_file(file: BaselineFile) -> Result<Self> {
        // Settings read from a file are checked against the weights it holds
        // before the network they define is allocated.
        let stored: usize = file.weights.values().map(|a| a.data.len()).sum();
        match file.hyper.param_count() {
            Some(n) if n <= stored => {}
            n => bail!(
                "the baseline's hyperparameters define {} parameters, more than the {stored} its file holds",
                n.map_or_else(|| "over 2^64".to_string(), |n| n.to_string())
            ),
        }
        let net = BaselineNet::new(file.hyper.clone(), &mut ChaCha8Rng::seed_from_u64(0))?;
        net.store.load(&file.weights)?;
        let exec = Executor {
            theta: crate::train::flat_params(&net.store)?,
            params: net.param_sizes()?,
            last: Mutex::new(None),
        };
        Ok(Self { file, net, exec })
    }

    /// The accelerations of `states` on the executor.
    fn executor_accelerations(
        &self,
        graph: &Graph,
        states: &[State],
    ) -> Result<Vec<Vec<f64>>, DynamicsError> {
        let g = &self.exec;
        let mut last = g
            .last
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let exec = match last.as_mut() {
            Some((kept, exec)) if kept == graph => exec,
            _ => {
                let exec = self
                    .file
                    .hyper
                    .executor(&g.params, graph, 1)
                    .map_err(|e| DynamicsError::Model(e.to_string()))?;
                &mut last.insert((graph.clone(), exec)).1
            }
        };
        let mut acc = exec.accelerations(&g.theta, states);
        for a in &mut acc {
            hold_kinematic(graph, a);
        }
        Ok(acc)
    }

    fn accel(&self, graph: &Graph, state: &State) -> Result<Vec<f64>, DynamicsError> {
        self.supports(graph)?;
        state.validate(graph)?;
        Ok(self
            .executor_accelerations(graph, std::slice::from_ref(state))?
            .remove(0))
    }
}

impl Dynamics for TrainedBaseline {
    fn describe(&self) -> String {
        let t = &self.file.training;
        format!(
            "{} baseline ({} epochs, validation loss {:.3e})",
            self.file.hyper.kind, t.epochs_run, t.validation_loss
        )
    }

    fn supports(&self, graph: &Graph) -> Result<(), DynamicsError> {
        graph.validate()?;
        if let Some(why) = contact_refusal(&self.file.hyper, graph) {
            return Err(DynamicsError::Model(why));
        }
        let h = &self.file.hyper;
        if graph.dim != h.dim {
            return Err(DynamicsError::Dimension {
                model: h.kind.to_string(),
                trained: h.dim,
                graph: graph.dim,
            });
        }
        if let Some(t) = graph.types.iter().find(|&&t| t as usize >= h.types) {
            return Err(ArchError::UnknownType {
                ty: *t,
                types: h.types,
            }
            .into());
        }
        Ok(())
    }

    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        if out.len() != graph.ndof() {
            return Err(DynamicsError::OutputSize {
                got: out.len(),
                need: graph.ndof(),
            });
        }
        out.copy_from_slice(&self.accel(graph, state)?);
        Ok(())
    }

    /// One executor call for all states.
    fn acceleration_batch(
        &self,
        graph: &Graph,
        states: &[State],
        out: &mut [Vec<f64>],
    ) -> Result<(), DynamicsError> {
        crate::dynamics::check_batch(states, out)?;
        if states.is_empty() {
            return Ok(());
        }
        self.supports(graph)?;
        for (o, a) in out
            .iter_mut()
            .zip(self.executor_accelerations(graph, states)?)
        {
            o.copy_from_slice(&a);
        }
        Ok(())
    }

    /// Total force m∘q̈ with the true masses (as for acceleration-predicting
    /// GNODE variants); no pairwise forces.
    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError> {
        let a = self.accel(graph, state)?;
        let total = a
            .iter()
            .enumerate()
            .map(|(i, x)| x * graph.masses[i / graph.dim])
            .collect();
        Ok(Forces {
            total,
            edges: vec![],
        })
    }
}

/// Why a baseline cannot model `graph`, if it cannot: LGN and HGN (energies
/// of a closed set of particles) do not model contacts or kinematic particles
/// and refuse them rather than learn them wrongly; GNS, whose defining
/// setting is a radius graph with walls as particles, does, for the radius it
/// was trained with. No baseline models a periodic box.
pub(crate) fn contact_refusal(hyper: &BaselineHyper, graph: &Graph) -> Option<String> {
    let touches = graph.has_contacts() || graph.n_kinematic() > 0;
    if graph.periodic().is_some() {
        return Some(format!(
            "the {} baseline has no periodic boundaries (its edges would cross the box \
             the long way): train a GNODE-family model (--model mcgnode, gnode, cgnode or \
             cdgnode) on a periodic system",
            hyper.kind
        ));
    }
    match hyper.kind {
        Kind::Gns if graph.interaction_radius != hyper.interaction_radius => Some(format!(
            "the GNS model finds contacts within radius {}, the system's radius is {}: \
             train one on these data (train --model gns{})",
            hyper.interaction_radius,
            graph.interaction_radius,
            if graph.has_contacts() {
                format!(" --radius {}", graph.interaction_radius)
            } else {
                String::new()
            }
        )),
        Kind::Lgn | Kind::Hgn if touches => Some(
            "LGN and HGN do not model contacts or kinematic particles: train GNS or a \
             GNODE-family model (--model gns, mcgnode, gnode, cgnode or cdgnode) on these data"
                .to_string(),
        ),
        _ => None,
    }
}

/// Zeroes the accelerations of `graph`'s kinematic particles in `acc` (one
/// state or several, flat): their motion is given.
fn hold_kinematic(graph: &Graph, acc: &mut [f64]) {
    let (n, d) = (graph.n(), graph.dim);
    for (k, a) in acc.iter_mut().enumerate() {
        if graph.is_kinematic((k / d) % n) {
            *a = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::TrainedBaseline;
    use crate::baselines::{BaselineFile, BaselineHyper, BaselineNet, Kind};
    use crate::gnode::Variant;
    use crate::physics::{SystemConfig, SystemKind};
    use rand::SeedableRng;

    fn net(hyper: BaselineHyper) -> BaselineNet {
        BaselineNet::new(hyper, &mut rand_chacha::ChaCha8Rng::seed_from_u64(4)).expect("net")
    }

    /// The count that guards loading is the count the network declares.
    #[test]
    fn param_count_is_the_networks() {
        for kind in Kind::ALL {
            for (dim, types, hidden, latent, rounds) in
                [(2, 1, 16, 8, 1), (3, 2, 5, 3, 0), (2, 3, 4, 6, 3)]
            {
                let h = BaselineHyper {
                    kind,
                    dim,
                    types,
                    hidden,
                    latent,
                    rounds,
                    interaction_radius: 0.0,
                };
                assert_eq!(h.param_count(), Some(net(h.clone()).store.count()), "{h:?}");
            }
        }
    }

    /// tests/fuzz_readers.rs met a GNS file with a setting of
    /// 18446744073709551615 that never finished loading. Before the count
    /// was checked, each of these panicked on a capacity overflow, took
    /// seconds (a latent of 10^6) or never ended (10^15 rounds); now each is
    /// an error before anything is allocated.
    #[test]
    fn corrupt_sizes_are_errors_not_aborts() {
        let g = SystemConfig::new(SystemKind::Spring, 3).graph();
        let (_, template) = crate::testing::random_model(Variant::Gnode, &g, 3).expect("model");
        type Edit = fn(&mut BaselineHyper);
        let cases: [(Kind, Edit, &str); 4] = [
            (
                Kind::Gns,
                |h| h.hidden = usize::MAX,
                "over 2^64 parameters, more than the 4722",
            ),
            (
                Kind::Gns,
                |h| h.latent = 1_000_000,
                "278000274 parameters, more than the 4722",
            ),
            (
                Kind::Gns,
                |h| h.rounds = 1_000_000_000_000_000,
                "parameters, more than the 4722",
            ),
            (
                Kind::Lgn,
                |h| h.types = usize::MAX,
                "over 2^64 parameters, more than the 1651",
            ),
        ];
        for (kind, edit, want) in cases {
            let n = net(BaselineHyper::new(kind, 2, 1));
            let mut file = BaselineFile {
                format: crate::baselines::file::FORMAT.into(),
                crate_version: env!("CARGO_PKG_VERSION").into(),
                hyper: n.hyper.clone(),
                trained_on: None,
                training: template.file.training.clone(),
                weights: n.store.weights().expect("weights"),
            };
            edit(&mut file.hyper);
            let e = TrainedBaseline::from_file(file)
                .expect_err(want)
                .to_string();
            assert!(e.contains(want), "{kind}: {e:?} does not say {want:?}");
        }
    }
}
