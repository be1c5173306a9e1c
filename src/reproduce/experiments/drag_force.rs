//! Springs under drag or an external force.

use super::common::{
    cfg, diverged, figure, panels, rows_table, run_evals, section, EvalJob, Section, TRAIN_SEED,
};
use super::sweep::sweep_test_bag;
use crate::error::Result;
use crate::gnode::Variant;
use crate::models::ModelKind;
use crate::physics::{SystemConfig, SystemKind};
use crate::plot::Metric;
use crate::reproduce::lab::{Lab, TrainSpec};
use crate::reproduce::report::{num, Experiment, Row};
use crate::reproduce::scale::Scale;
use crate::train::{ModelOptions, Recipe};
use std::path::PathBuf;

/// Drag −0.1 q̇ and a constant external force on the 5-spring: MCGNODE vs
/// NODE (paper appendix "Drag and external force").
pub fn drag_and_force(lab: &Lab, sc: &Scale) -> Result<Section> {
    let cases = drag_force_bags(lab, sc)?;
    let mut specs = vec![];
    for (name, train, _) in &cases {
        for v in [Variant::Mcgnode, Variant::Node] {
            specs.push(TrainSpec {
                label: format!("{v}-5-{name}"),
                kind: ModelKind::Family(v),
                bags: vec![train.clone()],
                cfg: cfg(sc.family_epochs),
                opts: ModelOptions::for_recipe(Recipe::Paper),
            });
        }
    }
    let trained = lab.train_all(&specs);
    let mut jobs = vec![];
    for (s, t) in specs.iter().zip(&trained) {
        let Ok(t) = t else { continue };
        let case = cases.iter().find(|c| s.bags[0] == c.1).expect("case");
        jobs.push(EvalJob {
            experiment: Experiment::DragForce,
            system: case.0.into(),
            label: s.kind.name().into(),
            particles: 5,
            x: None,
            model: t.path.clone(),
            bag: case.2.clone(),
            dt: None,
            max: sc.sweep_test_trajectories,
        });
    }
    let rows = run_evals(lab, jobs);
    let md = drag_force_markdown(lab, sc, &rows);
    Ok(section(md, rows, &specs, trained))
}

/// The 5-spring under drag and under a constant force: (name, training bag,
/// test bag) each.
fn drag_force_bags(lab: &Lab, sc: &Scale) -> Result<Vec<(&'static str, PathBuf, PathBuf)>> {
    let mut cases = vec![];
    for (name, drag, force) in [
        ("spring+drag", 0.1, vec![]),
        ("spring+force", 0.0, vec![0.5, 0.0]),
    ] {
        let mut c = SystemConfig::new(SystemKind::Spring, 5);
        c.field.drag = drag;
        c.field.force = force;
        let train = lab.bag(
            &format!("train-5-{name}"),
            &c,
            sc.sweep_train_trajectories,
            TRAIN_SEED,
            false,
        )?;
        let test = sweep_test_bag(lab, sc, name, &c)?;
        cases.push((name, train, test));
    }
    Ok(cases)
}

/// The drag/force section's text, figure and table.
fn drag_force_markdown(lab: &Lab, sc: &Scale, rows: &[Row]) -> String {
    let mut md = "## Drag and external force (paper appendix)\n\n".to_string();
    md += &format!(
        "5-spring with drag −0.1 q̇, and with a constant force (0.5, 0) on every particle; \
         {} training trajectories, {} epochs; MCGNODE learns the field with its body-force \
         branch. {} test trajectories over {:.0} s.\n\n",
        sc.sweep_train_trajectories,
        sc.family_epochs,
        sc.sweep_test_trajectories,
        (sc.sweep_states - 1) as f64 * 0.1
    );
    let names = vec!["mcgnode".to_string(), "node".to_string()];
    let mut p = panels(rows, Experiment::DragForce, "spring+drag", &[5], &names);
    p.extend(panels(
        rows,
        Experiment::DragForce,
        "spring+force",
        &[5],
        &names,
    ));
    md += &figure(
        lab,
        "drag-force.png",
        &p,
        &[Metric::Re, Metric::Ee, Metric::Me],
    );
    md += &rows_table(
        rows,
        &[
            ("system", |r| r.system.clone()),
            ("model", |r| r.model.clone()),
            ("RE", |r| num(r.averages.re)),
            ("EE", |r| num(r.averages.ee)),
            ("ME", |r| num(r.averages.me)),
            ("diverged", diverged),
        ],
    );
    md
}
