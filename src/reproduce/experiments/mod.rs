//! The paper's experiments, one file each, writing its figures and
//! returning its section of the report and its result rows; what they share
//! is in `common`.

mod common;
mod comparison;
mod contacts;
mod data_efficiency;
mod drag_force;
mod noise;
mod peridynamic;
mod sweep;

pub use common::Section;
pub use comparison::main_comparison;
pub use contacts::contacts;
pub use data_efficiency::data_efficiency;
pub use drag_force::drag_and_force;
pub use noise::noise;
pub use peridynamic::peridynamic;
