//! Training-data noise.

use super::common::Section;
use super::sweep::{sweep, Sweep};
use crate::baselines::Kind;
use crate::error::Result;
use crate::gnode::Variant;
use crate::models::ModelKind;
use crate::reproduce::lab::Lab;
use crate::reproduce::report::Experiment;
use crate::reproduce::scale::Scale;

/// Robustness to noise on the training accelerations (paper "Robustness to Noise").
pub fn noise(lab: &Lab, sc: &Scale) -> Result<Section> {
    let models = [
        ModelKind::Family(Variant::Gnode),
        ModelKind::Family(Variant::Mcgnode),
        ModelKind::Baseline(Kind::Lgn),
        ModelKind::Baseline(Kind::Hgn),
    ];
    let intro = format!(
        "5-spring, {} training trajectories whose target accelerations carry Gaussian noise \
         of the given % of their standard deviation; {} epochs; {} test trajectories over {:.0} s \
         (clean truth).",
        sc.sweep_train_trajectories,
        sc.sweep_epochs,
        sc.sweep_test_trajectories,
        (sc.sweep_states - 1) as f64 * 0.1
    );
    sweep(
        lab,
        sc,
        Sweep {
            experiment: Experiment::Noise,
            models: &models,
            xs: &sc.noise,
            train_trajectories: sc.sweep_train_trajectories,
            set: |c, x| c.noise = x,
            title: "Robustness to noise (paper Section \"Robustness to Noise\")",
            intro,
            fig: "noise.png",
            x_label: "noise (% of std)",
            log_x: false,
        },
    )
}
