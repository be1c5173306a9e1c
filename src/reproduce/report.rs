//! What `reproduce` writes: result rows (results.json) and the markdown of
//! report.md.

use crate::evaluate::Evaluation;
use crate::metrics::{Averages, Summary, DIVERGED, LOG_FLOOR};
use serde::Serialize;

/// The experiments of `reproduce`, as named in results.json and file names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Experiment {
    /// Each inductive bias in turn: the GNODE family.
    Biases,
    /// MCGNODE against LGN, HGN and GNS at equal epochs.
    Baselines,
    /// MCGNODE against LGN, HGN and GNS at equal wall-clock training time.
    Wallclock,
    /// GNODE and MCGNODE with the paper text's architecture.
    Architecture,
    /// Zero-shot to large rings.
    Large,
    /// The 3D peridynamic solid.
    Peridynamic,
    /// Springs under drag or an external force.
    DragForce,
    /// Training-data noise sweep.
    Noise,
    /// Training-set size sweep (data efficiency).
    Points,
    /// Systems that touch: MCGNODE, GNODE and GNS on contacts.
    Contacts,
}

impl crate::names::Named for Experiment {
    const ALL: &'static [Self] = &[
        Experiment::Biases,
        Experiment::Baselines,
        Experiment::Wallclock,
        Experiment::Architecture,
        Experiment::Large,
        Experiment::Peridynamic,
        Experiment::DragForce,
        Experiment::Noise,
        Experiment::Points,
        Experiment::Contacts,
    ];
    const WHAT: &'static str = "experiment";

    fn name(self) -> &'static str {
        match self {
            Experiment::Biases => "biases",
            Experiment::Baselines => "baselines",
            Experiment::Wallclock => "wallclock",
            Experiment::Architecture => "architecture",
            Experiment::Large => "large",
            Experiment::Peridynamic => "peridynamic",
            Experiment::DragForce => "drag-force",
            Experiment::Noise => "noise",
            Experiment::Points => "points",
            Experiment::Contacts => "contacts",
        }
    }
}

crate::impl_named!(Experiment);

impl Serialize for Experiment {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(crate::names::Named::name(*self))
    }
}

/// One evaluation in results.json.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// Experiment.
    pub experiment: Experiment,
    /// System ("spring", "pendulum", "peridynamic", "spring+drag", ...).
    pub system: String,
    /// Model label.
    pub model: String,
    /// Particles of the test system.
    pub particles: usize,
    /// Swept value (noise %, training points), if any.
    pub x: Option<f64>,
    /// Test trajectories.
    pub trajectories: usize,
    /// Rollouts that diverged.
    pub diverged: usize,
    /// Time averages of the geometric-mean curves.
    pub averages: Averages,
    /// Rollout wall time per trajectory, seconds.
    pub rollout_seconds: f64,
    /// Why the evaluation (or the model's training) failed, if it did.
    pub error: Option<String>,
    /// The curves (not in results.json: the figures show them).
    #[serde(skip)]
    pub summary: Option<Summary>,
}

impl Row {
    /// A row from an evaluation, or from its failure.
    pub fn new(
        experiment: Experiment,
        system: &str,
        model: &str,
        particles: usize,
        x: Option<f64>,
        e: &crate::error::Result<Evaluation>,
    ) -> Row {
        let nan = Averages {
            re: f64::NAN,
            ee: f64::NAN,
            me: f64::NAN,
            me_scaled: f64::NAN,
            re_abs: f64::NAN,
            me_abs: f64::NAN,
        };
        let mut r = Row {
            experiment,
            system: system.into(),
            model: model.into(),
            particles,
            x,
            trajectories: 0,
            diverged: 0,
            averages: nan,
            rollout_seconds: f64::NAN,
            error: None,
            summary: None,
        };
        match e {
            Ok(e) => {
                r.trajectories = e.trajectories;
                r.diverged = e.diverged;
                r.averages = e.averages;
                r.rollout_seconds = e.rollout_seconds / e.trajectories.max(1) as f64;
                r.summary = Some(e.summary.clone());
            }
            Err(err) => r.error = Some(format!("{err:#}")),
        }
        r
    }
}

/// A number for a table: 3 significant digits, "diverged" for the
/// stand-in, "–" for NaN.
pub fn num(x: f64) -> String {
    if x.is_nan() {
        "–".into()
    } else if x >= DIVERGED / 10.0 {
        "diverged".into()
    } else if x <= LOG_FLOOR * 10.0 {
        "0".into()
    } else {
        format!("{x:.2e}")
    }
}

/// A markdown table.
pub fn table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = format!("| {} |\n", header.join(" | "));
    s += &format!("|{}\n", header.iter().map(|_| "---|").collect::<String>());
    for r in rows {
        s += &format!("| {} |\n", r.join(" | "));
    }
    s
}

/// The standard error table of rows: model, particles, RE, EE, ME, ME scaled,
/// diverged, rollout time.
pub fn error_table(rows: &[&Row]) -> String {
    let body: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            let a = &r.averages;
            match &r.error {
                Some(e) => vec![
                    r.model.clone(),
                    r.particles.to_string(),
                    format!("failed: {}", e.replace('|', "/").replace('\n', " ")),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                ],
                None => vec![
                    r.model.clone(),
                    r.particles.to_string(),
                    num(a.re),
                    num(a.ee),
                    num(a.me),
                    num(a.me_scaled),
                    format!("{}/{}", r.diverged, r.trajectories),
                    format!("{:.3}", r.rollout_seconds),
                ],
            }
        })
        .collect();
    table(
        &[
            "model",
            "particles",
            "RE",
            "EE",
            "ME",
            "ME scaled",
            "diverged",
            "rollout s/trajectory",
        ],
        &body,
    )
}
