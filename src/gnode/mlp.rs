//! Multilayer perceptrons with squareplus activations, on candle tensors.

use super::params::ParamStore;
use crate::error::Result;
use candle_core::Tensor;
use rand::Rng;

/// squareplus(x) = (x + √(x² + 4)) / 2: a smooth ReLU (Barron 2021, b = 4 as in jax).
pub fn squareplus(x: &Tensor) -> candle_core::Result<Tensor> {
    (x + (x.sqr()? + 4.0)?.sqrt()?)? * 0.5
}

/// squareplus'(x) = (1 + x / √(x² + 4)) / 2, for backward passes written as
/// candle ops (which candle can then differentiate once more).
pub fn squareplus_grad(x: &Tensor) -> candle_core::Result<Tensor> {
    ((x / (x.sqr()? + 4.0)?.sqrt()?)? + 1.0)? * 0.5
}

/// Scalar squareplus, for the engine.
#[inline]
pub fn squareplus_f64(x: f64) -> f64 {
    0.5 * (x + (x * x + 4.0).sqrt())
}

/// An MLP: linear layers named `{name}.l{i}`, squareplus between them, linear output.
#[derive(Clone, Debug)]
pub struct Mlp {
    /// Parameter-name prefix.
    pub name: String,
    /// Layer sizes, input first, output last.
    pub sizes: Vec<usize>,
    /// (weight, bias) names per layer, formed once (not on every forward).
    names: Vec<(String, String)>,
}

impl Mlp {
    /// Declares the MLP's parameters in the store.
    pub fn new(
        store: &mut ParamStore,
        name: &str,
        sizes: &[usize],
        rng: &mut impl Rng,
    ) -> Result<Self> {
        for (i, w) in sizes.windows(2).enumerate() {
            store.linear(&format!("{name}.l{i}"), w[0], w[1], rng)?;
        }
        let names = (0..sizes.len().saturating_sub(1))
            .map(|i| (format!("{name}.l{i}.w"), format!("{name}.l{i}.b")))
            .collect();
        Ok(Self {
            name: name.to_string(),
            sizes: sizes.to_vec(),
            names,
        })
    }

    /// Parameter names of layer `i`: (weight, bias).
    pub fn layer_names(&self, i: usize) -> (&str, &str) {
        let (w, b) = &self.names[i];
        (w, b)
    }

    /// Number of linear layers.
    pub fn layers(&self) -> usize {
        self.sizes.len() - 1
    }

    /// Forward pass on rows of `x` (`(N, sizes[0])` → `(N, sizes.last())`).
    pub fn forward(&self, store: &ParamStore, x: &Tensor) -> Result<Tensor> {
        Ok(self.forward_keep(store, x)?.0)
    }

    /// Forward pass that also returns the hidden layers' pre-activations,
    /// which [`Mlp::input_grad`] needs.
    pub fn forward_keep(&self, store: &ParamStore, x: &Tensor) -> Result<(Tensor, Vec<Tensor>)> {
        let mut h = x.clone();
        let mut pre = Vec::with_capacity(self.layers().saturating_sub(1));
        for i in 0..self.layers() {
            let (wn, bn) = self.layer_names(i);
            h = h
                .matmul(store.get(wn)?.as_tensor())?
                .broadcast_add(store.get(bn)?.as_tensor())?;
            if i + 1 < self.layers() {
                pre.push(h.clone());
                h = squareplus(&h)?;
            }
        }
        Ok((h, pre))
    }

    /// The backward pass with respect to the input only: given `dout` =
    /// ∂s/∂out for a scalar s, returns ∂s/∂x, written as candle ops so that
    /// it stays differentiable in the weights. `pre` comes from
    /// [`Mlp::forward_keep`] on the same input.
    pub fn input_grad(&self, store: &ParamStore, pre: &[Tensor], dout: &Tensor) -> Result<Tensor> {
        let mut g = dout.clone();
        for i in (0..self.layers()).rev() {
            let (wn, _) = self.layer_names(i);
            g = g.matmul(&store.get(wn)?.as_tensor().t()?)?;
            if i > 0 {
                g = (g * squareplus_grad(&pre[i - 1])?)?;
            }
        }
        Ok(g)
    }
}
