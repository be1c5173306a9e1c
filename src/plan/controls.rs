//! A candidate action: the velocity every driven (kinematic) particle
//! reaches at the end of each control step, and the smooth motion it gives
//! them (velocity ramped linearly between those knots).

use crate::dynamics::Timing;
use crate::physics::Drive;
use crate::system::State;
use serde::{Deserialize, Serialize};

/// A control sequence: `u[k·width..(k+1)·width]` is the velocity the
/// driven particles (`dim` per particle, in their order) reach at the end of
/// control step `k`, for `steps` steps (see [`Controls::drive`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Controls {
    /// Control steps.
    pub steps: usize,
    /// Numbers per step: driven particles × dimension.
    pub width: usize,
    /// The velocities, step-major.
    pub u: Vec<f64>,
}

impl Controls {
    /// Holding still: every velocity 0.
    pub fn zeros(steps: usize, width: usize) -> Self {
        Controls {
            steps,
            width,
            u: vec![0.0; steps * width],
        }
    }

    /// The velocities of control step `k`.
    pub fn row(&self, k: usize) -> &[f64] {
        &self.u[k * self.width..(k + 1) * self.width]
    }

    /// The sequence one step on: its steps 1.. then its last step again (the
    /// warm start of the next control step's plan).
    pub fn shifted(&self) -> Self {
        let mut u = self.u[self.width.min(self.u.len())..].to_vec();
        if self.steps > 0 {
            u.extend_from_slice(self.row(self.steps - 1));
        }
        Controls { u, ..self.clone() }
    }

    /// Σ_k |u_k|² · T: the control effort, in (m/s)²·s (T the control
    /// step, `timing.dt`).
    pub fn effort(&self, timing: Timing) -> f64 {
        self.u.iter().map(|x| x * x).sum::<f64>() * timing.dt
    }

    /// The motion of `particles` (driven, `dim` each) from where and how
    /// fast `start` has them: their velocity ramps linearly over control
    /// step k from the previous step's value (the start's for step 0) to
    /// u_k, and their position is its exact integral. The motion is smooth
    /// (no jump in velocity), as the motions a model learns from are. One
    /// row per integration step, `steps × substeps` steps.
    pub fn drive(&self, particles: &[usize], dim: usize, start: &State, timing: Timing) -> Drive {
        let (sub, dt) = (timing.substeps(), timing.step());
        let total = self.steps * sub;
        let pick = |x: &[f64]| -> Vec<f64> {
            particles
                .iter()
                .flat_map(|&i| x[i * dim..(i + 1) * dim].iter().copied())
                .collect()
        };
        let (mut q, v0) = (pick(&start.q), pick(&start.v));
        // Velocity at integration step j.
        let vel = |j: usize| -> Vec<f64> {
            if j == 0 {
                return v0.clone();
            }
            let k = (j - 1) / sub;
            let s = ((j - 1) % sub + 1) as f64 / sub as f64;
            let from = if k == 0 { &v0[..] } else { self.row(k - 1) };
            from.iter()
                .zip(self.row(k))
                .map(|(a, b)| a + (b - a) * s)
                .collect()
        };
        let (mut rows_q, mut rows_v) =
            (Vec::with_capacity(total + 1), Vec::with_capacity(total + 1));
        let mut prev = vel(0);
        rows_q.push(q.clone());
        rows_v.push(prev.clone());
        for j in 1..=total {
            let next = vel(j);
            for ((x, a), b) in q.iter_mut().zip(&prev).zip(&next) {
                *x += 0.5 * (a + b) * dt;
            }
            rows_q.push(q.clone());
            rows_v.push(next.clone());
            prev = next;
        }
        Drive {
            particles: particles.to_vec(),
            dim,
            q: rows_q,
            v: rows_v,
        }
    }

    /// Reverse mode through [`Controls::drive`]: given ∂L/∂ of the driven
    /// particles' positions and velocities at every integration step
    /// (`gq[j]`, `gv[j]`, `width` numbers each, steps 0..=steps·substeps),
    /// ∂L/∂u, laid out as `u`. The map is linear in u: the velocity at step
    /// j ≥ 1 of control step k is (1 − s)·u_{k−1} + s·u_k (u_{−1} the
    /// start's), and q_j = q_{j−1} + ½(q̇_{j−1} + q̇_j)·dt.
    pub fn drive_vjp(&self, timing: Timing, gq: &[Vec<f64>], gv: &[Vec<f64>]) -> Vec<f64> {
        let (sub, dt) = (timing.substeps(), timing.step());
        let total = self.steps * sub;
        let w = self.width;
        let mut gu = vec![0.0; self.u.len()];
        // S_i = Σ_{j ≥ i} ∂L/∂q_j, carried from the end.
        let (mut s_next, mut s) = (vec![0.0; w], vec![0.0; w]);
        for j in (1..=total).rev() {
            for f in 0..w {
                s[f] = s_next[f] + gq[j][f];
            }
            let k = (j - 1) / sub;
            let frac = ((j - 1) % sub + 1) as f64 / sub as f64;
            for f in 0..w {
                let gvel = gv[j][f] + 0.5 * dt * (s[f] + s_next[f]);
                gu[k * w + f] += frac * gvel;
                if k > 0 {
                    gu[(k - 1) * w + f] += (1.0 - frac) * gvel;
                }
            }
            std::mem::swap(&mut s, &mut s_next);
        }
        gu
    }
}
