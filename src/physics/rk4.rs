//! Classical RK4 on Hamilton's equations in (q, p) of the true system: the
//! paper's training data for HGN (`simulate --integrator rk4`). The baseline
//! itself is [`crate::baselines::hgn`].

use super::{acceleration as true_acceleration, PhysicsError, SystemConfig};
use crate::system::{Graph, Sample, State, Trajectory};

/// One RK4 step of the true Hamiltonian system on (q, p): q̇ = p/m,
/// ṗ = m·q̈ with q̈ the exact constrained acceleration (for springs this is
/// ṗ = −∂H/∂q; for pendulums it adds the bar forces, so the Cartesian
/// constrained Hamiltonian flow is integrated by RK4 and constraint drift is
/// left to the small step, as with any unprojected RK4).
fn rk4_step(c: &SystemConfig, g: &Graph, q: &mut [f64], p: &mut [f64], dt: f64) {
    let d = g.dim;
    let deriv = |q: &[f64], p: &[f64]| -> (Vec<f64>, Vec<f64>) {
        let v: Vec<f64> = p
            .iter()
            .enumerate()
            .map(|(k, x)| x / g.masses[k / d])
            .collect();
        let s = State { q: q.to_vec(), v };
        let a = true_acceleration(g, &c.field, &s);
        let pd = a
            .iter()
            .enumerate()
            .map(|(k, x)| x * g.masses[k / d])
            .collect();
        (s.v, pd)
    };
    let add = |x: &[f64], k: &[f64], h: f64| -> Vec<f64> {
        x.iter().zip(k).map(|(a, b)| a + h * b).collect()
    };
    let (k1q, k1p) = deriv(q, p);
    let (k2q, k2p) = deriv(&add(q, &k1q, dt / 2.0), &add(p, &k1p, dt / 2.0));
    let (k3q, k3p) = deriv(&add(q, &k2q, dt / 2.0), &add(p, &k2p, dt / 2.0));
    let (k4q, k4p) = deriv(&add(q, &k3q, dt), &add(p, &k3p, dt));
    for i in 0..q.len() {
        q[i] += dt / 6.0 * (k1q[i] + 2.0 * k2q[i] + 2.0 * k3q[i] + k4q[i]);
        p[i] += dt / 6.0 * (k1p[i] + 2.0 * k2p[i] + 2.0 * k3p[i] + k4p[i]);
    }
}

/// HGN training data: `trajectories` trajectories of the system integrated
/// with RK4 on (q, p) (same starts, step, sampling and sample count as
/// [`SystemConfig::simulate`]). Samples store v = p/m and the exact
/// accelerations, so ṗ = m∘acc; the format is the same as everywhere else.
pub fn rk4_trajectories(
    c: &SystemConfig,
    trajectories: usize,
    seed: u64,
) -> Result<Vec<Trajectory>, PhysicsError> {
    c.validate()?;
    let g = c.graph();
    // The (q, p) flow here knows no contacts and would move kinematic walls.
    if g.has_contacts() || g.n_kinematic() > 0 {
        return Err(PhysicsError::Rk4Contacts(c.kind));
    }
    let d = g.dim;
    let mut out = Vec::with_capacity(trajectories);
    for i in 0..trajectories {
        let start = c.start_for(&g, seed, i);
        let mut q = start.q.clone();
        let mut p: Vec<f64> = start
            .v
            .iter()
            .enumerate()
            .map(|(k, v)| v * g.masses[k / d])
            .collect();
        let mut samples = Vec::with_capacity(c.states);
        for k in 0..c.states {
            if k > 0 {
                for _ in 0..c.save_every {
                    rk4_step(c, &g, &mut q, &mut p, c.dt);
                }
            }
            let v = p
                .iter()
                .enumerate()
                .map(|(j, x)| x / g.masses[j / d])
                .collect();
            let state = State { q: q.clone(), v };
            state
                .validate(&g)
                .map_err(|cause| PhysicsError::Rk4Diverged {
                    id: i,
                    sample: k,
                    cause,
                })?;
            samples.push(Sample {
                t: (k * c.save_every) as f64 * c.dt,
                acc: Some(true_acceleration(&g, &c.field, &state)),
                state,
            });
        }
        out.push(Trajectory {
            id: i as u32,
            system: c.kind.name().to_string(),
            graph: g.clone(),
            samples,
        });
    }
    Ok(out)
}
