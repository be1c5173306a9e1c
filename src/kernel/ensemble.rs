//! An ensemble of GNODE-family models from one model file
//! (`train --ensemble K`): it predicts the members' mean and reports their
//! spread, per particle and kept state the members' standard deviation of
//! position (the root of the mean over axes of the variance).

use super::TrainedModel;
use crate::dynamics::{
    fill_prediction, Dynamics, DynamicsError, Forces, Predicted, Rollout, Spread, Timing,
};
use crate::error::Result;
use crate::gnode::file::ModelFile;
use crate::physics::Drive;
use crate::system::{Graph, State};

/// K trained models of one architecture and data, from different seeds.
#[derive(Clone, Debug)]
pub struct Ensemble {
    /// The members, the file's own weights first.
    pub members: Vec<TrainedModel>,
}

impl Ensemble {
    /// The members of `file` ([`ModelFile::member_files`]), each on its kernel.
    pub fn from_file(file: &ModelFile) -> Result<Self> {
        let members = file
            .member_files()
            .into_iter()
            .map(TrainedModel::from_file)
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { members })
    }

    fn each<T>(
        &self,
        f: impl Fn(&TrainedModel) -> Result<T, DynamicsError>,
    ) -> Result<Vec<T>, DynamicsError> {
        self.members.iter().map(f).collect()
    }

    /// [`Ensemble::each`] with the members shared among the cores when the
    /// job (`work` particle-steps per member) is long enough to pay for
    /// starting threads ([`PARALLEL_WORK`]); results in member order.
    fn each_parallel<T: Send>(
        &self,
        work: usize,
        f: impl Fn(&TrainedModel) -> Result<T, DynamicsError> + Sync,
    ) -> Result<Vec<T>, DynamicsError> {
        // Short jobs first: the core count is not even asked for them.
        let lanes = if work < PARALLEL_WORK {
            1
        } else {
            crate::engine::all_cores().min(self.members.len())
        };
        if lanes < 2 {
            return self.each(f);
        }
        let per = self.members.len().div_ceil(lanes);
        let f = &f;
        std::thread::scope(|s| {
            let jobs: Vec<_> = self
                .members
                .chunks(per)
                .map(|chunk| s.spawn(move || chunk.iter().map(f).collect::<Vec<_>>()))
                .collect();
            let mut out = Vec::with_capacity(self.members.len());
            for j in jobs {
                let results = j
                    .join()
                    .map_err(|_| DynamicsError::Model("an ensemble member panicked".into()))?;
                for r in results {
                    out.push(r?);
                }
            }
            Ok(out)
        })
    }
}

/// Particle-steps of one member's rollout above which the members run on
/// all cores: below it (the node's 5 particles × 25 steps) starting threads
/// costs more than it saves.
pub const PARALLEL_WORK: usize = 20_000;

/// The mean of equally long vectors.
fn mean_of(rows: &[&[f64]]) -> Vec<f64> {
    let k = rows.len().max(1) as f64;
    let mut out = vec![0.0; rows.first().map_or(0, |r| r.len())];
    for r in rows {
        for (o, x) in out.iter_mut().zip(r.iter()) {
            *o += x;
        }
    }
    out.iter_mut().for_each(|o| *o /= k);
    out
}

/// The members' mean trajectory over their common length and, per kept
/// state, each particle's spread: √(mean over the `dim` axes of the
/// members' variance of position).
pub fn mean_and_spread(dim: usize, runs: &[&[State]]) -> (Vec<State>, Spread) {
    let len = runs.iter().map(|r| r.len()).min().unwrap_or(0);
    let k = runs.len().max(1) as f64;
    let mut states = Vec::with_capacity(len);
    let mut spread = Vec::with_capacity(len);
    for t in 0..len {
        let qs: Vec<&[f64]> = runs.iter().map(|r| r[t].q.as_slice()).collect();
        let vs: Vec<&[f64]> = runs.iter().map(|r| r[t].v.as_slice()).collect();
        let q = mean_of(&qs);
        let v = mean_of(&vs);
        let d = dim.max(1);
        let per_particle = q
            .chunks(d)
            .enumerate()
            .map(|(i, mean)| {
                let var: f64 = qs
                    .iter()
                    .map(|m| {
                        m[i * d..(i + 1) * d]
                            .iter()
                            .zip(mean)
                            .map(|(x, mu)| (x - mu) * (x - mu))
                            .sum::<f64>()
                    })
                    .sum::<f64>()
                    / k;
                (var / d as f64).sqrt()
            })
            .collect();
        states.push(State { q, v });
        spread.push(per_particle);
    }
    (states, spread)
}

impl Dynamics for Ensemble {
    fn describe(&self) -> String {
        let first = self
            .members
            .first()
            .map_or(String::new(), Dynamics::describe);
        format!("ensemble of {} × {first}", self.members.len())
    }

    fn steps_copies_together(&self) -> bool {
        self.members.iter().all(Dynamics::steps_copies_together)
    }

    fn supports(&self, graph: &Graph) -> Result<(), DynamicsError> {
        self.each(|m| m.supports(graph)).map(|_| ())
    }

    fn members(&self) -> usize {
        self.members.len()
    }

    fn acceleration(
        &self,
        graph: &Graph,
        state: &State,
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        let accs = self.each(|m| {
            let mut a = vec![0.0; out.len()];
            m.acceleration(graph, state, &mut a)?;
            Ok(a)
        })?;
        let rows: Vec<&[f64]> = accs.iter().map(Vec::as_slice).collect();
        out.copy_from_slice(&mean_of(&rows));
        Ok(())
    }

    fn forces(&self, graph: &Graph, state: &State) -> Result<Forces, DynamicsError> {
        let all = self.each(|m| m.forces(graph, state))?;
        let mut out = all[0].clone();
        let totals: Vec<&[f64]> = all.iter().map(|f| f.total.as_slice()).collect();
        out.total = mean_of(&totals);
        for (e, edge) in out.edges.iter_mut().enumerate() {
            let rows: Vec<&[f64]> = all
                .iter()
                .filter_map(|f| f.edges.get(e).map(|x| x.force.as_slice()))
                .collect();
            edge.force = mean_of(&rows);
        }
        Ok(out)
    }

    fn rollout(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
    ) -> Result<Vec<State>, DynamicsError> {
        Ok(self.rollout_spread(graph, start, timing, None)?.0)
    }

    fn rollout_driven(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: &Drive,
    ) -> Result<Vec<State>, DynamicsError> {
        Ok(self.rollout_spread(graph, start, timing, Some(drive))?.0)
    }

    fn rollout_spread(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        drive: Option<&Drive>,
    ) -> Result<(Vec<State>, Spread), DynamicsError> {
        let work = graph.n() * timing.steps();
        let runs = self.each_parallel(work, |m| match drive {
            Some(d) => m.rollout_driven(graph, start, timing, d),
            None => m.rollout(graph, start, timing),
        })?;
        let refs: Vec<&[State]> = runs.iter().map(Vec::as_slice).collect();
        Ok(mean_and_spread(graph.dim, &refs))
    }

    /// The members' mean and spread, and their mean forces at `start`.
    fn predict_into(
        &self,
        graph: &Graph,
        start: &State,
        timing: Timing,
        out: &mut Predicted,
    ) -> Result<(), DynamicsError> {
        let (states, spread) = self.rollout_spread(graph, start, timing, None)?;
        fill_prediction(self, graph, start, &states, out)?;
        out.spread.clear();
        spread.iter().for_each(|s| out.spread.extend_from_slice(s));
        Ok(())
    }

    fn rollout_many(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: Timing,
    ) -> Result<Vec<Rollout>, DynamicsError> {
        Ok(self
            .rollout_many_spread(graph, starts, timing)?
            .into_iter()
            .map(|(r, _)| r)
            .collect())
    }

    /// Every member's rollouts, averaged start by start; a start on which a
    /// member diverged keeps the common states and the earliest divergence.
    fn rollout_many_spread(
        &self,
        graph: &Graph,
        starts: &[State],
        timing: Timing,
    ) -> Result<Vec<(Rollout, Spread)>, DynamicsError> {
        let work = graph.n() * timing.steps() * starts.len();
        let runs = self.each_parallel(work, |m| m.rollout_many(graph, starts, timing))?;
        Ok((0..starts.len())
            .map(|s| {
                let refs: Vec<&[State]> = runs.iter().map(|r| r[s].states.as_slice()).collect();
                let (states, spread) = mean_and_spread(graph.dim, &refs);
                let diverged_at = runs.iter().filter_map(|r| r[s].diverged_at).min();
                (
                    Rollout {
                        states,
                        diverged_at,
                    },
                    spread,
                )
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn st(q: &[f64]) -> State {
        State {
            q: q.to_vec(),
            v: vec![0.0; q.len()],
        }
    }

    #[test]
    fn the_spread_is_the_members_standard_deviation_of_position() {
        // Two members, one 2D particle: at t = 1 they sit at (0, 0) and
        // (2, 4): mean (1, 2), variances 1 and 4, spread √((1 + 4) / 2).
        let a = vec![st(&[0.0, 0.0]), st(&[0.0, 0.0])];
        let b = vec![st(&[0.0, 0.0]), st(&[2.0, 4.0]), st(&[9.0, 9.0])];
        let (mean, spread) = mean_and_spread(2, &[&a, &b]);
        assert_eq!(mean.len(), 2, "the common length");
        assert_eq!(mean[1].q, vec![1.0, 2.0]);
        assert_eq!(spread[0], vec![0.0]);
        assert!((spread[1][0] - 2.5f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn one_member_has_no_spread() {
        let a = vec![st(&[1.0, 2.0, 3.0, 4.0])];
        let (mean, spread) = mean_and_spread(2, &[&a]);
        assert_eq!(mean, a);
        assert_eq!(spread, vec![vec![0.0, 0.0]]);
    }
}
