//! Named, seeded parameters shared by the candle model (the reference) and
//! the engine (training and inference).

use crate::error::{bail, Context, Result};
use candle_core::{Device, Tensor, Var};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A parameter's values, row-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Array {
    /// Shape; linear layers store weights as `[inputs, outputs]`.
    pub shape: Vec<usize>,
    /// Row-major values.
    pub data: Vec<f64>,
}

/// Plain parameter values by name: what a model file stores and the engine reads.
pub type Weights = BTreeMap<String, Array>;

/// Trainable candle variables by name, in a fixed order.
#[derive(Clone, Debug, Default)]
pub struct ParamStore {
    names: Vec<String>,
    vars: BTreeMap<String, Var>,
}

impl ParamStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a parameter with given values.
    pub fn insert(&mut self, name: &str, shape: &[usize], data: Vec<f64>) -> Result<()> {
        if self.vars.contains_key(name) {
            bail!("parameter {name} defined twice");
        }
        let t = Tensor::from_vec(data, shape, &Device::Cpu)?;
        self.vars.insert(name.to_string(), Var::from_tensor(&t)?);
        self.names.push(name.to_string());
        Ok(())
    }

    /// A linear layer `inputs → outputs` with LeCun-normal weights
    /// (std 1/√inputs, as haiku's default) and zero bias.
    pub fn linear(
        &mut self,
        name: &str,
        inputs: usize,
        outputs: usize,
        rng: &mut impl Rng,
    ) -> Result<()> {
        let normal = Normal::new(0.0, 1.0 / (inputs.max(1) as f64).sqrt())?;
        let w = (0..inputs * outputs).map(|_| normal.sample(rng)).collect();
        self.insert(&format!("{name}.w"), &[inputs, outputs], w)?;
        self.insert(&format!("{name}.b"), &[outputs], vec![0.0; outputs])
    }

    /// The variable of a parameter.
    pub fn get(&self, name: &str) -> Result<&Var> {
        self.vars
            .get(name)
            .with_context(|| format!("model has no parameter {name}"))
    }

    /// The variables in definition order.
    pub fn vars(&self) -> Vec<Var> {
        self.names.iter().map(|n| self.vars[n].clone()).collect()
    }

    /// Parameter names in definition order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Current values as plain arrays.
    pub fn weights(&self) -> Result<Weights> {
        let mut out = Weights::new();
        for n in &self.names {
            let t = self.vars[n].as_tensor();
            let data = t.flatten_all()?.to_vec1::<f64>()?;
            out.insert(
                n.clone(),
                Array {
                    shape: t.dims().to_vec(),
                    data,
                },
            );
        }
        Ok(out)
    }

    /// Overwrites every parameter from plain arrays; names and shapes must
    /// match. (Candle variables have interior mutability, hence `&self`.)
    pub fn load(&self, weights: &Weights) -> Result<()> {
        if weights.len() != self.names.len() {
            bail!(
                "model file has {} parameters, the architecture needs {}",
                weights.len(),
                self.names.len()
            );
        }
        for n in &self.names {
            let a = weights
                .get(n)
                .with_context(|| format!("model file lacks parameter {n}"))?;
            let var = &self.vars[n];
            if a.shape != var.dims() || a.data.len() != a.shape.iter().product::<usize>() {
                bail!(
                    "parameter {n}: shape {:?} ({} values), the architecture needs {:?}",
                    a.shape,
                    a.data.len(),
                    var.dims()
                );
            }
            if a.data.iter().any(|x| !x.is_finite()) {
                bail!("parameter {n} contains NaN or infinite values");
            }
            var.set(&Tensor::from_vec(
                a.data.clone(),
                a.shape.as_slice(),
                &Device::Cpu,
            )?)?;
        }
        Ok(())
    }

    /// Total number of scalar parameters.
    pub fn count(&self) -> usize {
        self.vars.values().map(|v| v.elem_count()).sum()
    }
}
