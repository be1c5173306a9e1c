//! Our messages (msg/*.msg other than ParticleState, whose struct lives in
//! [`crate::data::msg`]).

use serde::{Deserialize, Serialize};

use crate::data::msg::{to_vec3, Header, ParticleState, Vector3};

#[cfg(doc)]
use super::diagnostics::{DIAGNOSTIC_ERROR, DIAGNOSTIC_OK, DIAGNOSTIC_WARN};

ros_types!("mcgnode_msgs" / "msg":
    PredictedTrajectory = "PredictedTrajectory",
    ParticleForces = "ParticleForces",
    NodeDiagnostics = "NodeDiagnostics",
    LiveAccuracy = "LiveAccuracy",
    ModelSwap = "ModelSwap",
);

/// `mcgnode_msgs/msg/PredictedTrajectory`: the graph once (in `initial`),
/// then positions and velocities per predicted step, `d` numbers a particle
/// (`d` = `initial.dimension`: no z in 2D).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PredictedTrajectory {
    /// Copied from the input state.
    pub header: Header,
    /// The state the prediction starts from, as received.
    pub initial: ParticleState,
    /// Time step between states, seconds.
    pub dt: f64,
    /// Predicted states: state `k` is `k + 1` steps after `initial`.
    pub steps: u32,
    /// `positions[(k * n + i) * d + c]`: component `c` of particle `i` in
    /// state `k`.
    pub positions: Vec<f64>,
    /// `velocities[(k * n + i) * d + c]`, laid out as `positions`.
    pub velocities: Vec<f64>,
    /// An ensemble's spread: `spread[k * n + i]` is particle `i`'s in state
    /// `k` (the members' standard deviation of position); empty for a
    /// single model.
    pub spread: Vec<f64>,
}

impl PredictedTrajectory {
    /// Particles per state.
    pub fn particles(&self) -> usize {
        self.initial.positions.len()
    }

    /// Numbers per particle and vector: the initial state's dimension.
    pub fn dim(&self) -> usize {
        usize::from(self.initial.dimension)
    }

    /// Positions of state `k`, `n·d` numbers (empty when there is no such
    /// state).
    pub fn positions_at(&self, k: usize) -> &[f64] {
        state_slice(&self.positions, k, self.particles() * self.dim())
    }

    /// Velocities of state `k`, as [`Self::positions_at`].
    pub fn velocities_at(&self, k: usize) -> &[f64] {
        state_slice(&self.velocities, k, self.particles() * self.dim())
    }

    /// State `k` as a full message: `initial`'s graph and field, the
    /// predicted positions and velocities, stamped `(k + 1)·dt` after the
    /// input (in integer nanoseconds) with step `initial.step + k + 1`.
    pub fn state(&self, k: usize) -> Option<ParticleState> {
        let (n, d) = (self.particles(), self.dim());
        if k >= self.steps as usize || !(2..=3).contains(&d) {
            return None;
        }
        let (q, v) = (self.positions_at(k), self.velocities_at(k));
        if q.len() != n * d || v.len() != n * d {
            return None;
        }
        let mut s = self.initial.clone();
        s.positions = to_vec3(q, d);
        s.velocities = to_vec3(v, d);
        s.accelerations.clear();
        let k1 = u32::try_from(k + 1).unwrap_or(u32::MAX);
        s.step = self.initial.step.saturating_add(k1);
        // f64 seconds since the epoch would lose sub-microsecond steps.
        let offset = (f64::from(k1) * self.dt * 1e9).round() as i64;
        s.header = Header {
            stamp: crate::data::msg::Time::from_nanos(
                self.header.stamp.as_nanos().saturating_add(offset),
            ),
            frame_id: self.header.frame_id.clone(),
        };
        Some(s)
    }
}

/// The `k`-th run of `len` numbers of `all` (empty when it is not whole).
fn state_slice(all: &[f64], k: usize, len: usize) -> &[f64] {
    k.checked_mul(len)
        .and_then(|start| all.get(start..start.checked_add(len)?))
        .unwrap_or_default()
}

/// `mcgnode_msgs/msg/ParticleForces`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleForces {
    /// Copied from the input state.
    pub header: Header,
    /// Total force per particle.
    pub total: Vec<Vector3>,
    /// Receiving particle of each pairwise force.
    pub edge_a: Vec<u32>,
    /// Exerting particle of each pairwise force.
    pub edge_b: Vec<u32>,
    /// f_ab, when the model has pairwise forces.
    pub edge_force: Vec<Vector3>,
}

/// `mcgnode_msgs/msg/NodeDiagnostics`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NodeDiagnostics {
    /// Stamped with the node's clock.
    pub header: Header,
    /// States received on the input topic.
    pub received: u64,
    /// Of those, rejected.
    pub rejected: u64,
    /// Predictions published.
    pub predicted: u64,
    /// Latest rejection or failure reason.
    pub last_error: String,
    /// Description of the served model.
    pub model: String,
    /// States with an input outside the model's training range.
    pub out_of_range: u64,
    /// Position-only states predicted from estimated velocities.
    pub derived: u64,
    /// Position-only states held as history while their stream warms up.
    pub warming_up: u64,
    /// Times a stream's history started over.
    pub history_resets: u64,
}

/// `mcgnode_msgs/msg/LiveAccuracy`: running accuracy per lead time.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LiveAccuracy {
    /// Stamp and frame of the incoming state compared.
    pub header: Header,
    /// Trajectory of that state.
    pub trajectory_id: u32,
    /// Lead times, seconds.
    pub lead_times: Vec<f64>,
    /// Comparisons so far per lead time.
    pub compared: Vec<u64>,
    /// Latest RE per lead time (NaN: none yet).
    pub re: Vec<f64>,
    /// Mean RE of the window per lead time.
    pub re_mean: Vec<f64>,
    /// Latest EE per lead time (NaN: not computable).
    pub ee: Vec<f64>,
    /// Mean EE of the window per lead time.
    pub ee_mean: Vec<f64>,
    /// Drift alarm level ([`DIAGNOSTIC_OK`], [`DIAGNOSTIC_WARN`] or
    /// [`DIAGNOSTIC_ERROR`]).
    pub level: u8,
    /// Why, or the worst running RE.
    pub message: String,
}

/// `mcgnode_msgs/msg/ModelSwap`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelSwap {
    /// When the swap happened.
    pub header: Header,
    /// Description of the model replaced.
    pub old_model: String,
    /// Description of the new model.
    pub new_model: String,
    /// Why.
    pub reason: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trajectory(dimension: u8, steps: u32, coords: usize) -> PredictedTrajectory {
        PredictedTrajectory {
            initial: ParticleState {
                dimension,
                positions: vec![Vector3::default(); 2],
                ..ParticleState::default()
            },
            dt: 0.5,
            steps,
            positions: (0..coords).map(|i| i as f64).collect(),
            velocities: (0..coords).map(|i| -(i as f64)).collect(),
            ..PredictedTrajectory::default()
        }
    }

    /// State k reads the k-th run of n·d numbers: in 3D every component, in
    /// 2D two a particle and z = 0.
    #[test]
    fn states_read_d_numbers_a_particle() {
        let t = trajectory(3, 2, 12);
        let s = t.state(1).unwrap();
        assert_eq!(t.positions_at(1), &[6.0, 7.0, 8.0, 9.0, 10.0, 11.0]);
        let v = |x, y, z| Vector3 { x, y, z };
        assert_eq!(s.positions, [v(6.0, 7.0, 8.0), v(9.0, 10.0, 11.0)]);
        assert_eq!(s.velocities[1], v(-9.0, -10.0, -11.0));
        let t = trajectory(2, 2, 8);
        assert_eq!(
            t.state(1).unwrap().positions,
            [v(4.0, 5.0, 0.0), v(6.0, 7.0, 0.0)]
        );
        assert_eq!(t.velocities_at(0), &[-0.0, -1.0, -2.0, -3.0]);
    }

    /// A state past the end, a short array or a bad dimension gives nothing
    /// (never a panic or a state of the wrong size).
    #[test]
    fn malformed_trajectories_give_no_state() {
        assert!(trajectory(2, 2, 8).state(2).is_none());
        assert!(trajectory(2, 2, 7).state(1).is_none());
        assert!(trajectory(2, 2, 7).positions_at(1).is_empty());
        assert!(trajectory(0, 2, 8).state(0).is_none());
        assert!(trajectory(4, 1, 8).state(0).is_none());
        assert!(trajectory(2, 2, 8).positions_at(usize::MAX).is_empty());
    }
}
