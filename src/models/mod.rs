//! Models of every kind, one home: the kinds ([`ModelKind`]: the GNODE family
//! of [`crate::gnode`] and the [`crate::baselines`]), loading what a
//! [`ModelRef`] names (a model file of either kind, `still`, or the ground
//! truth `truth:<system>`, [`truth`]), and training
//! any kind from bags into a model file.
//!
//! The CLI, `reproduce` and the ROS node reach models through here, never
//! through `baselines` or `ros`.

mod checked;
mod kind;
mod load;
mod reference;
mod train;
pub mod truth;

pub use checked::Checked;
pub use kind::ModelKind;
pub use load::{load_any_model, load_model, trained_for, LoadedModel};
pub use reference::ModelRef;
pub use train::{train_any_from_bags, train_ensemble_from_bags, train_from_bags, TrainedFile};
pub use truth::Truth;
