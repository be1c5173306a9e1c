//! Given motion of kinematic particles: a gripper that moves, a wall that is
//! pushed. A [`Drive`] holds the driven particles' positions and velocities
//! at every integration step of a rollout; the velocity-Verlet step places
//! them there before each evaluation ([`super::verlet::step_placed`]), so the
//! free particles feel them where they are, and nothing predicts them.
//!
//! It comes from a path known in closed form ([`Drive::from_path`], the
//! simulator's random smooth motions), from positions alone (velocities by
//! central differences, [`Drive::from_positions`]: a planner's candidate
//! actions), or from a recording sampled more coarsely than the integration
//! step ([`Drive::from_samples`]: cubic Hermite interpolation of the recorded
//! positions and velocities, exact for cubic motion).

use crate::system::{Graph, Sample};
use thiserror::Error;

/// A drive that does not fit its rollout.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum DriveError {
    /// The rollout asks for more steps than the drive covers.
    #[error("the kinematic particles' motion covers {have} steps, the rollout asks for {want}: give their motion over the whole horizon")]
    TooShort {
        /// Steps the drive covers.
        have: usize,
        /// Steps asked for.
        want: usize,
    },
    /// Rows of the wrong length, or a particle out of range or not kinematic.
    #[error("kinematic motion: {0}")]
    Shape(String),
    /// A non-finite position or velocity.
    #[error("kinematic motion holds NaN or infinite values")]
    NonFinite,
}

crate::error::typed_errors!(DriveError);

/// Positions and velocities of the driven particles at every step `0..=steps`.
#[derive(Clone, Debug, PartialEq)]
pub struct Drive {
    /// The driven particles (kinematic ones of the graph).
    pub particles: Vec<usize>,
    /// Spatial dimension.
    pub dim: usize,
    /// Positions per step, `particles.len() · dim` each.
    pub q: Vec<Vec<f64>>,
    /// Velocities per step, the same shape.
    pub v: Vec<Vec<f64>>,
}

impl Drive {
    /// `particles` following `path(t, q, v)` (writing their positions and
    /// velocities, `particles.len() · dim` each) at t = k·dt, k = 0..=steps.
    pub fn from_path(
        particles: Vec<usize>,
        dim: usize,
        dt: f64,
        steps: usize,
        mut path: impl FnMut(f64, &mut [f64], &mut [f64]),
    ) -> Self {
        let w = particles.len() * dim;
        let (mut q, mut v) = (Vec::with_capacity(steps + 1), Vec::with_capacity(steps + 1));
        for k in 0..=steps {
            let (mut qk, mut vk) = (vec![0.0; w], vec![0.0; w]);
            path(k as f64 * dt, &mut qk, &mut vk);
            q.push(qk);
            v.push(vk);
        }
        Drive {
            particles,
            dim,
            q,
            v,
        }
    }

    /// `particles` at positions `q` (one row per step, `dt` apart), with
    /// velocities by central differences (one-sided at both ends; zero for a
    /// single row).
    pub fn from_positions(particles: Vec<usize>, dim: usize, dt: f64, q: Vec<Vec<f64>>) -> Self {
        let m = q.len();
        let v = (0..m)
            .map(|k| {
                let (a, b) = (k.saturating_sub(1), (k + 1).min(m - 1));
                if a == b {
                    return vec![0.0; q[k].len()];
                }
                let h = (b - a) as f64 * dt;
                q[b].iter().zip(&q[a]).map(|(x, y)| (x - y) / h).collect()
            })
            .collect();
        Drive {
            particles,
            dim,
            q,
            v,
        }
    }

    /// The kinematic particles of `graph` as recorded in `samples` (times
    /// `t`, positions and velocities), interpolated to every step of `dt`
    /// over `steps` steps from the first sample's time by cubic Hermite
    /// interpolation (positions and velocities continuous; exact for motion
    /// cubic in time between samples).
    pub fn from_samples(
        graph: &Graph,
        samples: &[Sample],
        dt: f64,
        steps: usize,
    ) -> Result<Self, DriveError> {
        let d = graph.dim;
        let particles: Vec<usize> = (0..graph.n()).filter(|&i| graph.is_kinematic(i)).collect();
        let Some(first) = samples.first() else {
            return Err(DriveError::Shape("no recorded states".into()));
        };
        let t0 = first.t;
        let pick = |x: &[f64]| -> Vec<f64> {
            particles
                .iter()
                .flat_map(|&i| x[i * d..(i + 1) * d].iter().copied())
                .collect()
        };
        let (mut q, mut v) = (Vec::with_capacity(steps + 1), Vec::with_capacity(steps + 1));
        let mut seg = 0;
        for k in 0..=steps {
            let t = t0 + k as f64 * dt;
            while seg + 2 < samples.len() && samples[seg + 1].t <= t {
                seg += 1;
            }
            let a = &samples[seg];
            let Some(b) = samples.get(seg + 1) else {
                // One sample: held where it is, at its velocity.
                q.push(pick(&a.state.q));
                v.push(pick(&a.state.v));
                continue;
            };
            let h = b.t - a.t;
            if h.is_nan() || h <= 0.0 {
                return Err(DriveError::Shape(format!(
                    "recorded times {} and {} do not increase",
                    a.t, b.t
                )));
            }
            let s = ((t - a.t) / h).clamp(0.0, 1.0);
            let (qa, qb, va, vb) = (
                pick(&a.state.q),
                pick(&b.state.q),
                pick(&a.state.v),
                pick(&b.state.v),
            );
            let (s2, s3) = (s * s, s * s * s);
            let (h00, h10, h01, h11) = (
                2.0 * s3 - 3.0 * s2 + 1.0,
                s3 - 2.0 * s2 + s,
                -2.0 * s3 + 3.0 * s2,
                s3 - s2,
            );
            let (d00, d10, d01, d11) = (
                6.0 * s2 - 6.0 * s,
                3.0 * s2 - 4.0 * s + 1.0,
                -6.0 * s2 + 6.0 * s,
                3.0 * s2 - 2.0 * s,
            );
            let w = qa.len();
            q.push(
                (0..w)
                    .map(|f| h00 * qa[f] + h10 * h * va[f] + h01 * qb[f] + h11 * h * vb[f])
                    .collect(),
            );
            v.push(
                (0..w)
                    .map(|f| (d00 * qa[f] + d01 * qb[f]) / h + d10 * va[f] + d11 * vb[f])
                    .collect(),
            );
        }
        let drive = Drive {
            particles,
            dim: d,
            q,
            v,
        };
        drive.check(graph, steps)?;
        Ok(drive)
    }

    /// The steps it covers.
    pub fn steps(&self) -> usize {
        self.q.len().saturating_sub(1)
    }

    /// Whether any driven particle moves (a drive that holds everything
    /// still is what a rollout does without one).
    pub fn moves(&self) -> bool {
        let Some(first) = self.q.first() else {
            return false;
        };
        self.q.iter().any(|r| r != first) || self.v.iter().flatten().any(|x| *x != 0.0)
    }

    /// Checks it against `graph` and a rollout of `steps` steps.
    pub fn check(&self, graph: &Graph, steps: usize) -> Result<(), DriveError> {
        if let Some(&i) = self
            .particles
            .iter()
            .find(|&&i| i >= graph.n() || !graph.is_kinematic(i))
        {
            return Err(DriveError::Shape(format!(
                "particle {i} is not a kinematic particle of the system"
            )));
        }
        if self.dim != graph.dim || self.q.len() != self.v.len() {
            return Err(DriveError::Shape(format!(
                "{}D motion of {} steps with velocities for {}, for a {}D system",
                self.dim,
                self.q.len(),
                self.v.len(),
                graph.dim
            )));
        }
        let w = self.particles.len() * self.dim;
        if let Some(k) = (0..self.q.len()).find(|&k| self.q[k].len() != w || self.v[k].len() != w) {
            return Err(DriveError::Shape(format!(
                "step {k} has {} positions and {} velocities, {w} needed",
                self.q[k].len(),
                self.v[k].len()
            )));
        }
        if self
            .q
            .iter()
            .chain(&self.v)
            .flatten()
            .any(|x| !x.is_finite())
        {
            return Err(DriveError::NonFinite);
        }
        if self.steps() < steps {
            return Err(DriveError::TooShort {
                have: self.steps(),
                want: steps,
            });
        }
        Ok(())
    }

    /// Writes step `k`'s positions and velocities of the driven particles
    /// into the flat state (`dim` per particle).
    pub fn place(&self, k: usize, q: &mut [f64], v: &mut [f64]) {
        let d = self.dim;
        let (qk, vk) = (&self.q[k], &self.v[k]);
        for (j, &i) in self.particles.iter().enumerate() {
            q[i * d..(i + 1) * d].copy_from_slice(&qk[j * d..(j + 1) * d]);
            v[i * d..(i + 1) * d].copy_from_slice(&vk[j * d..(j + 1) * d]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::system::State;

    /// Hermite interpolation of a recording of cubic motion is exact at
    /// every step between the recorded states; central differences of
    /// quadratic motion are exact inside.
    #[test]
    fn interpolation_is_exact_for_cubic_motion() {
        let graph = Graph {
            dim: 2,
            types: vec![0, 1],
            masses: vec![1.0, 1.0],
            edges: vec![],
            anchors: vec![],
            interaction_radius: 0.0,
            kinematic: vec![false, true],
            periodic_box: None,
        };
        let path = |t: f64| {
            (
                [1.0 + t - 2.0 * t * t * t, 0.5 * t * t],
                [1.0 - 6.0 * t * t, t],
            )
        };
        let samples: Vec<Sample> = (0..5)
            .map(|k| {
                let t = 0.25 * f64::from(k);
                let (p, w) = path(t);
                Sample {
                    t,
                    state: State {
                        q: vec![9.0, 9.0, p[0], p[1]],
                        v: vec![0.0, 0.0, w[0], w[1]],
                    },
                    acc: None,
                }
            })
            .collect();
        let drive = Drive::from_samples(&graph, &samples, 0.01, 100).unwrap();
        assert_eq!((drive.particles.clone(), drive.steps()), (vec![1], 100));
        for k in 0..=100 {
            let (p, w) = path(0.01 * k as f64);
            for c in 0..2 {
                assert!((drive.q[k][c] - p[c]).abs() < 1e-12, "q at step {k}");
                assert!((drive.v[k][c] - w[c]).abs() < 1e-12, "v at step {k}");
            }
        }
        assert!(drive.moves());
        let (mut q, mut v) = (vec![0.0; 4], vec![0.0; 4]);
        drive.place(100, &mut q, &mut v);
        assert_eq!(&q[..2], &[0.0, 0.0]);
        assert_eq!(&q[2..], &drive.q[100][..]);
        let e = drive.check(&graph, 101).unwrap_err().to_string();
        assert!(
            e.contains("covers 100 steps, the rollout asks for 101"),
            "{e}"
        );
        let rows = (0..6).map(|k| vec![0.3 * f64::from(k).powi(2)]).collect();
        let fd = Drive::from_positions(vec![0], 1, 1.0, rows);
        assert_eq!(fd.v[2], vec![1.2]);
        assert_eq!(fd.v[0], vec![0.3]);
    }
}
