//! What the experiments share: seeds, the models compared, evaluation jobs,
//! figures and report sections.

use crate::baselines::Kind;
use crate::evaluate::Evaluation;
use crate::gnode::Variant;
use crate::plot::{plot_metrics, Metric};
use crate::reproduce::lab::{Job, Lab, TrainSpec, Trained};
use crate::reproduce::report::{table, Experiment, Row};
use crate::train::TrainConfig;
use std::path::PathBuf;

/// Seed of every training set; test sets use [`TEST_SEED`] (disjoint starts).
pub(super) const TRAIN_SEED: u64 = 1;

/// Seed of every test set.
pub(super) const TEST_SEED: u64 = 1001;

/// Trained models by label, failures kept.
pub type TrainedList = Vec<(String, crate::error::Result<Trained>)>;

/// A section of the report.
pub struct Section {
    /// Markdown, starting with its `##` heading.
    pub markdown: String,
    /// Result rows.
    pub rows: Vec<Row>,
    /// Trained models (for the timing tables).
    pub trained: TrainedList,
}

pub(super) const FAMILY: [Variant; 5] = [
    Variant::Node,
    Variant::Gnode,
    Variant::Cgnode,
    Variant::Cdgnode,
    Variant::Mcgnode,
];

pub(super) const BASELINES: [Kind; 3] = [Kind::Lgn, Kind::Hgn, Kind::Gns];

pub(super) fn cfg(epochs: usize) -> TrainConfig {
    TrainConfig {
        epochs,
        patience: epochs,
        seed: 0,
        // Trainings already run side by side, one per core.
        threads: 1,
        ..TrainConfig::default()
    }
}

/// An evaluation job description: (row experiment, system, label, particles, x, model, bag, dt, max).
pub(super) struct EvalJob {
    pub(super) experiment: Experiment,
    pub(super) system: String,
    pub(super) label: String,
    pub(super) particles: usize,
    pub(super) x: Option<f64>,
    pub(super) model: PathBuf,
    pub(super) bag: PathBuf,
    pub(super) dt: Option<f64>,
    pub(super) max: usize,
}

pub(super) fn run_evals(lab: &Lab, jobs: Vec<EvalJob>) -> Vec<Row> {
    let work: Vec<Job<'_, Evaluation>> = jobs
        .iter()
        .map(|j| {
            Box::new(move || {
                let e = lab.evaluate(&j.model, &j.bag, j.dt, j.max);
                if let Ok(e) = &e {
                    lab.say(&format!(
                        "evaluated {} on {}-particle {}: RE {:.2e}, EE {:.2e} ({:.1} s)",
                        j.label,
                        j.particles,
                        j.system,
                        e.averages.re,
                        e.averages.ee,
                        e.rollout_seconds
                    ));
                }
                e
            }) as Job<'_, Evaluation>
        })
        .collect();
    let results = lab.pool(work);
    jobs.iter()
        .zip(results)
        .map(|(j, e)| Row::new(j.experiment, &j.system, &j.label, j.particles, j.x, &e))
        .collect()
}

/// Panels for [`plot_metrics`]: one per particle count, the given models.
pub(super) fn panels(
    rows: &[Row],
    experiment: Experiment,
    system: &str,
    sizes: &[usize],
    models: &[String],
) -> Vec<(String, Vec<(String, crate::metrics::Summary)>)> {
    sizes
        .iter()
        .map(|&n| {
            let curves = models
                .iter()
                .filter_map(|m| {
                    rows.iter()
                        .find(|r| {
                            r.particles == n
                                && &r.model == m
                                && r.system == system
                                && r.experiment == experiment
                        })
                        .and_then(|r| r.summary.clone().map(|s| (m.clone(), s)))
                })
                .collect();
            (format!("{n}-{system}"), curves)
        })
        .filter(|p: &(String, Vec<_>)| !p.1.is_empty())
        .collect()
}

pub(super) fn figure(
    lab: &Lab,
    name: &str,
    panels: &[(String, Vec<(String, crate::metrics::Summary)>)],
    rows: &[Metric],
) -> String {
    let path = lab.dir.join(name);
    match plot_metrics(&path, panels, rows) {
        Ok(()) => format!("![{name}]({name})\n\n"),
        Err(e) => format!("(figure {name} could not be drawn: {e:#})\n\n"),
    }
}

/// One table row per model that trained, `cells(spec, report)`; failed
/// trainings are left out (the section lists them).
pub(super) fn training_rows(
    specs: &[TrainSpec],
    trained: &[crate::error::Result<Trained>],
    cells: impl Fn(&TrainSpec, &crate::gnode::file::TrainingReport) -> Vec<String>,
) -> Vec<Vec<String>> {
    specs
        .iter()
        .zip(trained)
        .filter_map(|(s, t)| Some(cells(s, &t.as_ref().ok()?.report)))
        .collect()
}

/// A table of rows: one column per (header, cell) pair.
type Column = (&'static str, fn(&Row) -> String);

pub(super) fn rows_table(rows: &[Row], columns: &[Column]) -> String {
    let header: Vec<&str> = columns.iter().map(|c| c.0).collect();
    let body: Vec<Vec<String>> = rows
        .iter()
        .map(|r| columns.iter().map(|c| c.1(r)).collect())
        .collect();
    table(&header, &body)
}

pub(super) fn diverged(r: &Row) -> String {
    format!("{}/{}", r.diverged, r.trajectories)
}

/// Closes a section: the failures of its trainings after its markdown.
pub(super) fn section(
    mut md: String,
    rows: Vec<Row>,
    specs: &[TrainSpec],
    trained: Vec<crate::error::Result<Trained>>,
) -> Section {
    let trained: TrainedList = specs.iter().map(|s| s.label.clone()).zip(trained).collect();
    md += "\n";
    md += &failures(&trained);
    Section {
        markdown: md,
        rows,
        trained,
    }
}

pub(super) fn failures(trained: &[(String, crate::error::Result<Trained>)]) -> String {
    let mut s = String::new();
    for (label, t) in trained {
        if let Err(e) = t {
            s += &format!("- training {label} failed: {e:#}\n");
        }
    }
    if !s.is_empty() {
        s = format!("Failures:\n\n{s}\n");
    }
    s
}
