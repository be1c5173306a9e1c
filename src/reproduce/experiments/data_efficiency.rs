//! Training-set size.

use super::common::Section;
use super::sweep::{sweep, Sweep};
use crate::baselines::Kind;
use crate::error::Result;
use crate::gnode::Variant;
use crate::models::ModelKind;
use crate::reproduce::lab::Lab;
use crate::reproduce::report::Experiment;
use crate::reproduce::scale::Scale;

/// Data efficiency: training points 100 … 10,000 (paper appendix "Training efficiency").
pub fn data_efficiency(lab: &Lab, sc: &Scale) -> Result<Section> {
    let models = [
        ModelKind::Family(Variant::Mcgnode),
        ModelKind::Family(Variant::Node),
        ModelKind::Baseline(Kind::Hgn),
    ];
    let max = sc.points.iter().copied().max().unwrap_or(100);
    let xs: Vec<f64> = sc.points.iter().map(|&p| p as f64).collect();
    let intro = format!(
        "5-spring; each model sees the given number of training states, drawn at random \
         from {} trajectories (75 % of them train, 25 % validate); {} epochs; {} test \
         trajectories over {:.0} s.",
        max.div_ceil(100),
        sc.sweep_epochs,
        sc.sweep_test_trajectories,
        (sc.sweep_states - 1) as f64 * 0.1
    );
    sweep(
        lab,
        sc,
        Sweep {
            experiment: Experiment::Points,
            models: &models,
            xs: &xs,
            train_trajectories: max.div_ceil(100),
            set: |c, x| c.points = Some(x as usize),
            title: "Data efficiency (paper appendix \"Training efficiency\")",
            intro,
            fig: "data-efficiency.png",
            x_label: "training points",
            log_x: true,
        },
    )
}
