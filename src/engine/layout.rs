//! The flat parameter vector: every parameter of an [`Arch`] at a fixed
//! offset, in definition order (the order candle's store uses), so that one
//! Adam update serves both engines and the same seed gives the same start.

use crate::gnode::arch::{Arch, Block, LOG_MASS};
use crate::gnode::params::{Array, Weights};
use thiserror::Error;

use super::dense::{Linear, Mlp};

/// A parameter vector that does not fit the architecture.
#[derive(Debug, Error)]
pub enum LayoutError {
    /// A parameter is absent.
    #[error("weights lack parameter {0}")]
    Missing(String),
    /// A parameter has the wrong shape.
    #[error("parameter {name}: shape {got:?}, the architecture needs {want:?}")]
    Shape {
        /// Its name.
        name: String,
        /// The shape found.
        got: Vec<usize>,
        /// The shape the architecture defines.
        want: Vec<usize>,
    },
    /// The weights hold parameters the architecture does not have.
    #[error("weights have {got} parameters, the architecture needs {want}")]
    Count {
        /// Parameters found.
        got: usize,
        /// Parameters needed.
        want: usize,
    },
}

crate::error::typed_errors!(LayoutError);

/// Names, shapes and offsets of every parameter.
#[derive(Clone, Debug)]
pub struct Layout {
    entries: Vec<(String, Vec<usize>, usize)>,
    len: usize,
}

impl Layout {
    /// The layout of an architecture.
    pub fn new(arch: &Arch) -> Self {
        let mut entries = vec![];
        let mut len = 0;
        for (name, shape) in arch.params() {
            let size: usize = shape.iter().product();
            entries.push((name, shape, len));
            len += size;
        }
        Self { entries, len }
    }

    /// Number of scalar parameters.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True for an architecture without parameters.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Parameter names in order.
    pub fn names(&self) -> Vec<&str> {
        self.entries.iter().map(|(n, _, _)| n.as_str()).collect()
    }

    /// Offset of a named parameter.
    pub fn offset(&self, name: &str) -> Option<usize> {
        self.entries
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|(_, _, o)| *o)
    }

    /// The MLP of a block, as offsets into the flat vector.
    pub(crate) fn mlp(&self, arch: &Arch, block: Block) -> Option<Mlp> {
        let sizes = arch.sizes(block)?;
        let layers = sizes
            .windows(2)
            .enumerate()
            .map(|(i, w)| {
                let (wn, bn) = block.layer_names(i);
                Linear {
                    w: self.offset(&wn).expect("layout holds every layer"),
                    b: self.offset(&bn).expect("layout holds every layer"),
                    inp: w[0],
                    out: w[1],
                }
            })
            .collect();
        Some(Mlp { layers })
    }

    /// Offset of the log-masses, for constrained architectures.
    pub fn log_mass(&self) -> Option<usize> {
        self.offset(LOG_MASS)
    }

    /// The flat vector of named weights (names and shapes must match).
    pub fn flatten(&self, w: &Weights) -> Result<Vec<f64>, LayoutError> {
        if w.len() != self.entries.len() {
            return Err(LayoutError::Count {
                got: w.len(),
                want: self.entries.len(),
            });
        }
        let mut theta = vec![0.0; self.len];
        for (name, shape, off) in &self.entries {
            let a = w
                .get(name)
                .ok_or_else(|| LayoutError::Missing(name.clone()))?;
            if &a.shape != shape || a.data.len() != shape.iter().product::<usize>() {
                return Err(LayoutError::Shape {
                    name: name.clone(),
                    got: a.shape.clone(),
                    want: shape.clone(),
                });
            }
            theta[*off..*off + a.data.len()].copy_from_slice(&a.data);
        }
        Ok(theta)
    }

    /// Named weights from a flat vector.
    pub fn weights(&self, theta: &[f64]) -> Weights {
        self.entries
            .iter()
            .map(|(name, shape, off)| {
                let size: usize = shape.iter().product();
                (
                    name.clone(),
                    Array {
                        shape: shape.clone(),
                        data: theta[*off..*off + size].to_vec(),
                    },
                )
            })
            .collect()
    }
}
