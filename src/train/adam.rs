//! Adam, the optimiser every trainable model shares.

/// Adam (Kingma & Ba) on one flat parameter vector: the same update for
/// both engines and every model kind.
pub struct Adam {
    lr: f64,
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl Adam {
    /// Zero moments for `len` parameters.
    pub fn new(lr: f64, len: usize) -> Self {
        Self {
            lr,
            m: vec![0.0; len],
            v: vec![0.0; len],
            t: 0,
        }
    }

    /// Continues from a saved state (moments flat, in parameter order).
    pub fn resume(lr: f64, step: i32, m: Vec<f64>, v: Vec<f64>) -> Self {
        Self { lr, m, v, t: step }
    }

    /// Sets the learning rate (a schedule's step).
    pub fn set_lr(&mut self, lr: f64) {
        self.lr = lr;
    }

    /// (updates taken, first moments, second moments).
    pub fn state(&self) -> (i32, &[f64], &[f64]) {
        (self.t, &self.m, &self.v)
    }

    /// One update of `theta` from `grad`.
    pub fn step(&mut self, theta: &mut [f64], grad: &[f64]) {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        const EPS: f64 = 1e-8;
        self.t += 1;
        let c1 = 1.0 - B1.powi(self.t);
        let c2 = 1.0 - B2.powi(self.t);
        for (((p, g), m), v) in theta.iter_mut().zip(grad).zip(&mut self.m).zip(&mut self.v) {
            *m = B1 * *m + (1.0 - B1) * g;
            *v = B2 * *v + (1.0 - B2) * g * g;
            *p -= self.lr * (*m / c1) / ((*v / c2).sqrt() + EPS);
        }
    }
}
