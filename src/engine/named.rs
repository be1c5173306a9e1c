//! The baselines' MLPs found by candle's parameter names (`node_em.l0.w`, …)
//! in the flat parameter vector, for the networks written on the executor.

use super::dense::{Linear, Mlp};
use super::EngineError;
use std::collections::HashMap;

/// Each parameter's offset and scalar count in the flat vector.
pub(super) struct Named<'a>(HashMap<&'a str, (usize, usize)>);

impl<'a> Named<'a> {
    /// The offsets of `params` (name and scalar count, in the flat vector's
    /// order).
    pub(super) fn new(params: &'a [(String, usize)]) -> Self {
        let mut at = HashMap::new();
        let mut off = 0;
        for (name, len) in params {
            at.insert(name.as_str(), (off, *len));
            off += len;
        }
        Self(at)
    }

    /// The offset of parameter `key`, which must hold `want` numbers; the
    /// error names `model`.
    pub(super) fn find(&self, model: &str, key: &str, want: usize) -> Result<usize, EngineError> {
        match self.0.get(key) {
            Some(&(o, len)) if len == want => Ok(o),
            _ => Err(EngineError::Parameters(format!(
                "{model} needs parameter {key} of {want} numbers"
            ))),
        }
    }

    /// The MLP `name` of layer sizes `sizes` (`{name}.l{i}.w`, `.b`).
    pub(super) fn mlp(&self, model: &str, name: &str, sizes: &[usize]) -> Result<Mlp, EngineError> {
        let mut layers = vec![];
        for (i, w) in sizes.windows(2).enumerate() {
            layers.push(Linear {
                w: self.find(model, &format!("{name}.l{i}.w"), w[0] * w[1])?,
                b: self.find(model, &format!("{name}.l{i}.b"), w[1])?,
                inp: w[0],
                out: w[1],
            });
        }
        Ok(Mlp { layers })
    }
}
