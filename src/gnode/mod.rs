//! Learned dynamics: the GNODE family and NODE described once ([`arch`]), in
//! candle (the reference the engine is tested against), and the model file
//! that hands trained weights to inference (where
//! [`crate::kernel::TrainedModel`] runs them on the engine).

pub mod arch;
pub mod batch;
pub mod mlp;
pub mod net;
pub mod params;
pub mod plan;
pub mod solve;
pub mod variant;

pub use arch::{Arch, Block};
pub use net::Net;
pub use variant::{ArchPreset, EdgeInput, Hyper, MessageFn, Norm, Variant};
pub mod file;

pub use file::ModelFile;
