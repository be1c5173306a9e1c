//! A sweep of one training setting (noise, training-set size) over the
//! models, and its report.

use super::common::{cfg, run_evals, section, EvalJob, Section, TEST_SEED, TRAIN_SEED};
use crate::baselines::Kind;
use crate::error::Result;
use crate::models::ModelKind;
use crate::physics::{SystemConfig, SystemKind};
use crate::plot::{plot_sweep, SweepLine};
use crate::reproduce::lab::{Lab, TrainSpec};
use crate::reproduce::report::{num, table, Experiment, Row};
use crate::reproduce::scale::Scale;
use crate::train::{ModelOptions, Recipe, TrainConfig};
use std::path::PathBuf;

/// Lines of a sweep figure: per model, (x, time-averaged gmean, band) of `pick`.
fn sweep_lines(
    rows: &[Row],
    models: &[&str],
    pick: fn(&crate::metrics::Summary) -> &crate::metrics::Band,
) -> Vec<SweepLine> {
    models
        .iter()
        .map(|m| {
            let mut pts: Vec<(f64, f64, f64, f64)> = rows
                .iter()
                .filter(|r| r.model == *m)
                .filter_map(|r| {
                    let s = r.summary.as_ref()?;
                    let b = pick(s);
                    let avg = |v: &[f64]| {
                        let v = &v[1.min(v.len())..];
                        v.iter().sum::<f64>() / v.len().max(1) as f64
                    };
                    Some((r.x?, avg(&b.gmean), avg(&b.lo), avg(&b.hi)))
                })
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            (m.to_string(), pts)
        })
        .collect()
}

/// A sweep over one training setting on the 5-spring (noise or data size):
/// what to train and how the section shows it.
pub(super) struct Sweep<'a> {
    pub(super) experiment: Experiment,
    pub(super) models: &'a [ModelKind],
    pub(super) xs: &'a [f64],
    pub(super) train_trajectories: usize,
    pub(super) set: fn(&mut TrainConfig, f64),
    pub(super) title: &'a str,
    pub(super) intro: String,
    pub(super) fig: &'a str,
    pub(super) x_label: &'a str,
    pub(super) log_x: bool,
}

/// Trains every model at every setting, evaluates them and writes the
/// section (a sweep figure of RE and EE, and their table).
pub(super) fn sweep(lab: &Lab, sc: &Scale, w: Sweep<'_>) -> Result<Section> {
    let Sweep {
        experiment,
        models,
        xs,
        train_trajectories,
        set,
        ..
    } = w;
    let (train, train_rk4, test) = sweep_bags(lab, sc, experiment, models, train_trajectories)?;
    let mut specs = vec![];
    for &x in xs {
        for &k in models {
            let mut cfg = cfg(sc.sweep_epochs);
            set(&mut cfg, x);
            let bag = match (&train_rk4, k) {
                (Some(b), ModelKind::Baseline(Kind::Hgn)) => b.clone(),
                _ => train.clone(),
            };
            specs.push((
                x,
                TrainSpec {
                    label: format!("{k}-5-spring-{experiment}-{x}"),
                    kind: k,
                    bags: vec![bag],
                    cfg,
                    opts: ModelOptions::for_recipe(Recipe::Paper),
                },
            ));
        }
    }
    let plain: Vec<TrainSpec> = specs.iter().map(|s| s.1.clone()).collect();
    let trained = lab.train_all(&plain);
    let mut jobs = vec![];
    for ((x, s), t) in specs.iter().zip(&trained) {
        let Ok(t) = t else { continue };
        jobs.push(EvalJob {
            experiment,
            system: "spring".into(),
            label: s.kind.name().into(),
            particles: 5,
            x: Some(*x),
            model: t.path.clone(),
            bag: test.clone(),
            dt: None,
            max: sc.sweep_test_trajectories,
        });
    }
    let rows = run_evals(lab, jobs);
    let md = sweep_markdown(lab, &w, &rows);
    Ok(section(md, rows, &plain, trained))
}

/// The sweep's 5-spring training bag (and its RK4 twin when HGN is among the
/// models) and its test bag.
fn sweep_bags(
    lab: &Lab,
    sc: &Scale,
    experiment: Experiment,
    models: &[ModelKind],
    train_trajectories: usize,
) -> Result<(PathBuf, Option<PathBuf>, PathBuf)> {
    let c = SystemConfig::new(SystemKind::Spring, 5);
    let train = lab.bag(
        &format!("train-5-spring-{experiment}"),
        &c,
        train_trajectories,
        TRAIN_SEED,
        false,
    )?;
    let train_rk4 = if models.contains(&ModelKind::Baseline(Kind::Hgn)) {
        Some(lab.bag(
            &format!("train-5-spring-{experiment}-rk4"),
            &c,
            train_trajectories,
            TRAIN_SEED,
            true,
        )?)
    } else {
        None
    };
    let test = sweep_test_bag(lab, sc, &format!("spring-{experiment}"), &c)?;
    Ok((train, train_rk4, test))
}

/// The held-out test bag `test-5-<name>` of a 5-spring case of the sweeps.
pub(super) fn sweep_test_bag(
    lab: &Lab,
    sc: &Scale,
    name: &str,
    c: &SystemConfig,
) -> Result<PathBuf> {
    let mut tc = c.clone();
    tc.states = sc.sweep_states;
    lab.bag(
        &format!("test-5-{name}"),
        &tc,
        sc.sweep_test_trajectories,
        TEST_SEED,
        false,
    )
}

/// The sweep's heading, figure (time-averaged RE and EE against the
/// setting) and table.
fn sweep_markdown(lab: &Lab, w: &Sweep<'_>, rows: &[Row]) -> String {
    let Sweep {
        title,
        intro,
        fig,
        x_label,
        log_x,
        models,
        ..
    } = w;
    let names: Vec<&str> = models.iter().map(|k| k.name()).collect();
    let models = &names[..];
    let mut md = format!("## {title}\n\n{intro}\n\n");
    let panels = vec![
        (
            "5-spring: RE".to_string(),
            "time-averaged RE".to_string(),
            sweep_lines(rows, models, |s| &s.re),
        ),
        (
            "5-spring: EE".to_string(),
            "time-averaged EE".to_string(),
            sweep_lines(rows, models, |s| &s.ee),
        ),
    ];
    match plot_sweep(&lab.dir.join(fig), x_label, *log_x, &panels) {
        Ok(()) => md += &format!("![{fig}]({fig})\n\n"),
        Err(e) => md += &format!("(figure {fig} could not be drawn: {e:#})\n\n"),
    }
    md += &sweep_table(rows, models, x_label);
    md
}

/// RE / EE of each model at each setting of a sweep.
fn sweep_table(rows: &[Row], models: &[&str], x_label: &str) -> String {
    let mut xs: Vec<f64> = rows.iter().filter_map(|r| r.x).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    let header: Vec<String> = std::iter::once(x_label.to_string())
        .chain(models.iter().map(|m| format!("{m} RE / EE")))
        .collect();
    let body: Vec<Vec<String>> = xs
        .iter()
        .map(|x| {
            std::iter::once(format!("{x}"))
                .chain(models.iter().map(|m| {
                    match rows.iter().find(|r| r.model == *m && r.x == Some(*x)) {
                        Some(r) if r.error.is_none() => {
                            format!("{} / {}", num(r.averages.re), num(r.averages.ee))
                        }
                        Some(r) => format!("failed: {}", r.error.clone().unwrap_or_default()),
                        None => "not trained".into(),
                    }
                }))
                .collect()
        })
        .collect();
    table(
        &header
            .iter()
            .map(std::string::String::as_str)
            .collect::<Vec<_>>(),
        &body,
    )
}
