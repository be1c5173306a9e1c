//! The field flags shared by `evaluate` and `replay` (for bags that do not
//! state what acts on their particles), and the check that a model fits a bag.

use crate::compat::{check_bag, TrainedFor};
use crate::data::field::bag_field;
use crate::data::Bag;
use crate::physics::Field;
use anyhow::{bail, Result};

/// `--gravity`, `--drag`, `--closed`.
#[derive(clap::Args, Debug, Clone)]
pub struct FieldArgs {
    /// Gravity g along −y for the energy error (with --drag, replaces the
    /// bag's field; the one not given is 0). Default: what the bag's messages
    /// or system_config state, else a closed system when the data show one,
    /// else refused.
    #[arg(long)]
    pub gravity: Option<f64>,
    /// Linear drag for the energy error (see --gravity).
    #[arg(long)]
    pub drag: Option<f64>,
    /// The system is closed (no gravity, drag or force): for bags that do
    /// not state their field and whose data do not show it.
    #[arg(long)]
    pub closed: bool,
}

impl FieldArgs {
    /// What the flags say about the field: `--gravity`/`--drag` (either one
    /// states the whole field, the other being 0 when not given) or `--closed`.
    pub fn field(&self) -> Result<Option<Field>> {
        let (gravity, drag) = (self.gravity, self.drag);
        if self.closed && (gravity.is_some_and(|g| g != 0.0) || drag.is_some_and(|d| d != 0.0)) {
            bail!("--closed means no gravity and no drag: it contradicts --gravity/--drag");
        }
        if self.closed || gravity.is_some() || drag.is_some() {
            Ok(Some(Field {
                gravity: gravity.unwrap_or(0.0),
                drag: drag.unwrap_or(0.0),
                force: vec![],
            }))
        } else {
            Ok(None)
        }
    }
}

/// Refuses a bag the model was not trained for (dimension, edges, and the
/// field its data state, the flags' `field` first).
pub fn check_fits(trained: &TrainedFor, bag: &Bag, field: Option<&Field>) -> Result<()> {
    let data_field = bag_field(bag, field)?.map(|o| o.field);
    Ok(check_bag(trained, bag, data_field.as_ref())?)
}

/// Warns on stderr when states of `bag` (`what`: "test", "recorded") lie
/// outside the model's training range ([`crate::compat::InputRange`]).
pub fn warn_out_of_range(trained: &TrainedFor, bag: &Bag, what: &str) {
    let Some(range) = &trained.range else {
        return;
    };
    let limit = crate::compat::OUT_OF_RANGE_SIGMAS;
    let (count, total, first) = crate::compat::count_out_of_range(range, bag, limit);
    if count > 0 {
        eprintln!(
            "warning: {count} of {total} {what} states lie outside the model's training range \
             (more than {limit} training scales): its predictions there are extrapolations; \
             first: {}",
            first.unwrap_or_default()
        );
    }
}
