//! The gradient of a plan's cost with respect to its controls, by reverse
//! mode through the rollout: the cost's gradient at each kept state, back
//! through every velocity-Verlet step (kick, the model's q̈ by the engine's
//! reverse pass, the placing of the driven particles, SHAKE/RATTLE onto the
//! bars, drift) to the driven particles' motion, and through that linear
//! map to the control sequence. [`refine`] takes gradient steps from a
//! search's best candidate.

use super::controls::Controls;
use super::cost::CostKind;
use super::search::{PlanError, Problem};
use crate::dynamics::{DynamicsError, StateGradient};
use crate::physics::{verlet, Projector};
use crate::system::State;
use serde::{Deserialize, Serialize};

/// A cost and its gradient.
#[derive(Clone, Debug, PartialEq)]
pub struct Gradient {
    /// The cost of the controls.
    pub cost: f64,
    /// ∂cost/∂u, laid out as [`Controls::u`].
    pub grad: Vec<f64>,
    /// The predicted trajectory (start, then one state per control step).
    pub predicted: Vec<State>,
}

/// What one integration step keeps for the reverse sweep.
struct Step {
    /// Positions at the start of the step (SHAKE's directions).
    q0: Vec<f64>,
    /// Positions after the drift, before and after SHAKE.
    drifted: Vec<f64>,
    shaken: Vec<f64>,
    /// The state q̈ was evaluated at (driven particles placed).
    q: Vec<f64>,
    v_half: Vec<f64>,
    /// Velocities after the kick, before and after RATTLE.
    kicked: Vec<f64>,
    v: Vec<f64>,
}

impl Problem<'_> {
    /// The model's reverse pass on this graph, or why there is none.
    fn state_gradient(&self) -> Result<Box<dyn StateGradient>, PlanError> {
        self.model.state_gradient(self.graph)?.ok_or_else(|| {
            PlanError::Problem(format!(
                "{} has no gradient: gradients need a model file of the GNODE family (NODE, GNODE, CGNODE, CDGNODE, MCGNODE)",
                self.model.describe()
            ))
        })
    }

    /// The cost of `controls` and its gradient with respect to them, by
    /// reverse mode through the rollout (the same steps, and bits, as
    /// [`Problem::rollout`] on the model's workspace). A rollout that
    /// diverges has no gradient: an error.
    pub fn gradient(&self, controls: &Controls) -> Result<Gradient, PlanError> {
        self.check()?;
        self.gradient_with(self.state_gradient()?.as_mut(), controls)
    }

    /// [`Problem::gradient`] on a reverse pass already built for the graph
    /// (refining takes many gradients of one problem).
    fn gradient_with(
        &self,
        model: &mut dyn StateGradient,
        controls: &Controls,
    ) -> Result<Gradient, PlanError> {
        if controls.steps != self.timing.horizon || controls.width != self.width() {
            return Err(PlanError::Problem(format!(
                "the controls have {} steps of {} numbers, the problem {} of {}",
                controls.steps,
                controls.width,
                self.timing.horizon,
                self.width()
            )));
        }
        let mut proj = model.projector();
        let (tape, predicted) = self.forward(model, proj.as_mut(), controls)?;
        let cost = self
            .cost
            .of(&predicted, self.graph.dim, controls, self.timing);
        let grad = self.backward(model, proj.as_ref(), controls, &tape, &predicted);
        Ok(Gradient {
            cost,
            grad,
            predicted,
        })
    }

    /// The rollout, keeping every step's intermediate states.
    fn forward(
        &self,
        model: &mut dyn StateGradient,
        mut proj: Option<&mut Projector>,
        controls: &Controls,
    ) -> Result<(Vec<Step>, Vec<State>), PlanError> {
        let (dt, sub) = (self.timing.step(), self.timing.substeps());
        let steps = controls.steps * sub;
        let drive = controls.drive(&self.driven(), self.graph.dim, self.start, self.timing);
        let (mut q, mut v) = (self.start.q.clone(), self.start.v.clone());
        drive.place(0, &mut q, &mut v);
        let mut a = vec![0.0; q.len()];
        model.acceleration(&q, &v, &mut a);
        let mut predicted = vec![State {
            q: q.clone(),
            v: v.clone(),
        }];
        let mut tape = Vec::with_capacity(steps);
        for j in 1..=steps {
            let q0 = q.clone();
            if let Some(p) = proj.as_deref_mut() {
                p.begin(&q);
            }
            verlet::drift(&mut q, &mut v, &a, dt);
            let drifted = q.clone();
            if let Some(p) = proj.as_deref_mut() {
                p.shake(&mut q, &mut v, dt);
            }
            let shaken = q.clone();
            drive.place(j, &mut q, &mut v);
            let v_half = v.clone();
            model.acceleration(&q, &v, &mut a);
            verlet::kick(&mut v, &a, dt);
            let kicked = v.clone();
            if let Some(p) = proj.as_deref_mut() {
                p.rattle(&q, &mut v);
            }
            if q.iter().chain(&v).any(|x| !x.is_finite()) {
                return Err(DynamicsError::Diverged(j).into());
            }
            if j % sub == 0 {
                predicted.push(State {
                    q: q.clone(),
                    v: v.clone(),
                });
            }
            tape.push(Step {
                q0,
                drifted,
                shaken,
                q: q.clone(),
                v_half,
                kicked,
                v: v.clone(),
            });
        }
        Ok((tape, predicted))
    }

    /// ∂cost/∂(q, q̇) at kept state `k` (1 ≤ k ≤ control steps), added to
    /// `gq`, `gv`.
    fn cost_grad_at(&self, k: usize, s: &State, gq: &mut [f64], gv: &mut [f64]) {
        let c = &self.cost;
        let w = match c.kind {
            CostKind::Final if k == self.timing.horizon => 1.0,
            CostKind::Final => return,
            CostKind::Along => 1.0 / self.timing.horizon.max(1) as f64,
        };
        let d = self.graph.dim;
        for (t, &p) in c.particles.iter().enumerate() {
            for x in 0..d {
                let i = p * d + x;
                gq[i] += w * 2.0 * (s.q[i] - c.targets[t * d + x]);
                gv[i] += w * 2.0 * c.speed * s.v[i];
            }
        }
    }

    /// The reverse sweep: from the cost back to the controls.
    fn backward(
        &self,
        model: &mut dyn StateGradient,
        proj: Option<&Projector>,
        controls: &Controls,
        tape: &[Step],
        predicted: &[State],
    ) -> Vec<f64> {
        let (dt, sub) = (self.timing.step(), self.timing.substeps());
        let (driven, d) = (self.driven(), self.graph.dim);
        let nd = self.graph.ndof();
        let steps = tape.len();
        let width = controls.width;
        let (mut gq_rows, mut gv_rows) = (
            vec![vec![0.0; width]; steps + 1],
            vec![vec![0.0; width]; steps + 1],
        );
        let (mut gq, mut gv, mut ga) = (vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]);
        let (mut fq, mut fv, mut acc, mut gq0) =
            (vec![0.0; nd], vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]);
        for j in (1..=steps).rev() {
            let t = &tape[j - 1];
            if j % sub == 0 {
                let k = j / sub;
                self.cost_grad_at(k, &predicted[k], &mut gq, &mut gv);
            }
            if let Some(p) = proj {
                p.rattle_vjp(&t.q, &t.kicked, &t.v, &mut gv, &mut gq);
            }
            // Kick: q̇ = q̇½ + ½q̈ dt; q̈ also feeds the next step's drift (ga).
            for (a, v) in ga.iter_mut().zip(&gv) {
                *a += 0.5 * dt * v;
            }
            model.vjp(&t.q, &t.v_half, &ga, &mut acc, &mut fq, &mut fv);
            for i in 0..nd {
                gq[i] += fq[i];
                gv[i] += fv[i];
            }
            // Placing: the driven particles' state is the drive's, not the drift's.
            for (w, &p) in driven.iter().enumerate() {
                for c in 0..d {
                    let (i, f) = (p * d + c, w * d + c);
                    gq_rows[j][f] += gq[i];
                    gv_rows[j][f] += gv[i];
                    gq[i] = 0.0;
                    gv[i] = 0.0;
                }
            }
            gq0.fill(0.0);
            if let Some(p) = proj {
                p.shake_vjp((&t.q0, &t.drifted, &t.shaken), dt, &mut gq, &gv, &mut gq0);
            }
            // Drift: q̃ = q + q̇ dt + ½q̈ dt², ṽ = q̇ + ½q̈ dt.
            for i in 0..nd {
                ga[i] = 0.5 * dt * dt * gq[i] + 0.5 * dt * gv[i];
                gv[i] += dt * gq[i];
                gq[i] += gq0[i];
            }
        }
        let mut grad = controls.drive_vjp(self.timing, &gq_rows, &gv_rows);
        let e = 2.0 * self.cost.effort * self.timing.dt;
        for (g, u) in grad.iter_mut().zip(&controls.u) {
            *g += e * u;
        }
        grad
    }
}

/// One gradient step of [`refine`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RefineStep {
    /// Cost after the step.
    pub cost: f64,
    /// Euclidean norm of the gradient the step followed.
    pub grad_norm: f64,
    /// Step length taken along −gradient.
    pub step: f64,
}

/// The result of [`refine`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Refined {
    /// The refined sequence (never costlier than the start).
    pub best: Controls,
    /// Its cost.
    pub cost: f64,
    /// The cost refining started from.
    pub start_cost: f64,
    /// The steps taken.
    pub steps: Vec<RefineStep>,
    /// ∂cost/∂u at the refined sequence (near 0 at a stationary point).
    pub grad: Vec<f64>,
    /// Its predicted trajectory (start, then one state per control step).
    pub predicted: Vec<State>,
}

/// Gradient steps from `init` (a search's best candidate): each follows
/// −∂cost/∂u, clipped to the speed bound, with a backtracking step length
/// (halved until the cost drops, doubled after a success); stops after
/// `iterations` steps or when no step length lowers the cost.
pub fn refine(problem: &Problem, init: &Controls, iterations: usize) -> Result<Refined, PlanError> {
    let clip = |x: f64| x.clamp(-problem.max_speed, problem.max_speed);
    problem.check()?;
    let mut model = problem.state_gradient()?;
    let mut at = problem.gradient_with(model.as_mut(), init)?;
    let (start_cost, mut u) = (at.cost, init.clone());
    let mut steps = vec![];
    let norm = |g: &[f64]| g.iter().map(|x| x * x).sum::<f64>().sqrt();
    // First step: the largest velocity moves by a tenth of the bound.
    let largest = at.grad.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    let mut len = if largest > 0.0 {
        0.1 * problem.max_speed / largest
    } else {
        0.0
    };
    'outer: for _ in 0..iterations {
        if len == 0.0 || !at.cost.is_finite() {
            break;
        }
        for _ in 0..30 {
            let trial = Controls {
                u: u.u
                    .iter()
                    .zip(&at.grad)
                    .map(|(x, g)| clip(x - len * g))
                    .collect(),
                ..u.clone()
            };
            let cost = problem.cost_of(&trial)?;
            if cost < at.cost {
                let next = problem.gradient_with(model.as_mut(), &trial)?;
                steps.push(RefineStep {
                    cost: next.cost,
                    grad_norm: norm(&at.grad),
                    step: len,
                });
                (u, at) = (trial, next);
                len *= 2.0;
                continue 'outer;
            }
            len *= 0.5;
        }
        break;
    }
    Ok(Refined {
        best: u,
        cost: at.cost,
        start_cost,
        steps,
        grad: at.grad,
        predicted: at.predicted,
    })
}
