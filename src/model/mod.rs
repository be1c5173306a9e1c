//! Learned dynamics: the GNODE family and NODE in candle (training), and the
//! model file that hands trained weights to the inference kernel (where
//! [`crate::kernel::TrainedModel`] runs them).

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
