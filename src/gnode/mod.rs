//! Learned dynamics: the GNODE family and NODE described once (`arch`), in
//! candle (the reference the engine is tested against), and the model file
//! that hands trained weights to inference (where
//! [`crate::kernel::TrainedModel`] runs them on the engine).

pub(crate) mod arch;
pub(crate) mod batch;
pub(crate) mod graph_plan;
pub(crate) mod mlp;
pub(crate) mod net;
pub(crate) mod params;
pub(crate) mod solve;
pub(crate) mod variant;

pub use arch::{Arch, Block};
pub use batch::Batch;
pub use file::{EdgeParams, ModelFileError};
pub use graph_plan::{Bar, GraphPlan};
pub use mlp::squareplus_f64;
pub use net::Net;
pub use params::ParamStore;
pub use solve::solve;
pub use variant::{ArchPreset, EdgeInput, Hyper, MessageFn, Norm, Variant};
pub(crate) mod file;

pub use file::{Member, ModelFile};
