//! `mcgnode reproduce`: every experiment of the paper (Bishnoi et al.) from
//! one command, written to `DIR/report.md` with PNG figures, `results.json`,
//! and the bags and model files it made (`DIR/data`, `DIR/models`).
//!
//! Each experiment goes the way a user would: simulate → bag → train → model
//! file → evaluate; [`scale::Scale`] sets how big (full or `--quick`).

pub mod experiments;
pub mod lab;
pub mod mpc;
pub mod report;
pub mod scale;

use crate::baselines::Kind;
use crate::error::{Context, Result};
use crate::model::Variant;
use crate::models::ModelKind;
use crate::names::Named;
use experiments::Section;
use lab::Lab;
use report::Experiment::{Baselines, Biases, DragForce, Noise, Peridynamic, Points, Wallclock};
use report::{num, Experiment, Row};
use scale::Scale;
use std::cell::RefCell;
use std::path::PathBuf;
use std::time::Instant;

/// What to run.
#[derive(Clone, Debug)]
pub struct Options {
    /// Output folder.
    pub out: PathBuf,
    /// Sizes and epochs.
    pub scale: Scale,
    /// Worker threads for independent trainings and evaluations.
    pub threads: usize,
    /// The command line that started the run, for the report (absolute
    /// paths are shortened to their last component: [`shown_command`]).
    pub command: String,
    /// The parts to run, in this order (default: [`Part::ALL`]).
    pub parts: Vec<Part>,
    /// Take up every training from its checkpoint in `checkpoints/` (a run
    /// stopped part-way goes on; finished trainings are not repeated);
    /// without it, checkpoints of earlier runs are removed first.
    pub resume: bool,
}

/// The parts of `reproduce`, each one section of the report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// The 5-spring: biases, baselines, architecture, zero-shot sizes.
    Springs,
    /// The 5-pendulum: the same.
    Pendulums,
    /// The 3D peridynamic solid.
    Peridynamic,
    /// Springs under drag or an external force.
    DragForce,
    /// Training-data noise.
    Noise,
    /// Training-set size.
    DataEfficiency,
    /// Systems that touch (not in the paper): MCGNODE, GNODE and GNS on
    /// contact edges.
    Contacts,
}

impl crate::names::Named for Part {
    const ALL: &'static [Self] = &[
        Part::Springs,
        Part::Pendulums,
        Part::Peridynamic,
        Part::DragForce,
        Part::Noise,
        Part::DataEfficiency,
        Part::Contacts,
    ];
    const WHAT: &'static str = "reproduce part";

    fn name(self) -> &'static str {
        match self {
            Part::Springs => "springs",
            Part::Pendulums => "pendulums",
            Part::Peridynamic => "peridynamic",
            Part::DragForce => "drag-force",
            Part::Noise => "noise",
            Part::DataEfficiency => "data-efficiency",
            Part::Contacts => "contacts",
        }
    }
}

crate::impl_named!(Part);

impl Part {
    /// Runs this part.
    fn run(self, lab: &Lab, sc: &Scale) -> Result<Section> {
        use crate::physics::SystemKind;
        match self {
            Part::Springs => experiments::main_comparison(lab, sc, SystemKind::Spring),
            Part::Pendulums => experiments::main_comparison(lab, sc, SystemKind::Pendulum),
            Part::Peridynamic => experiments::peridynamic(lab, sc),
            Part::DragForce => experiments::drag_and_force(lab, sc),
            Part::Noise => experiments::noise(lab, sc),
            Part::DataEfficiency => experiments::data_efficiency(lab, sc),
            Part::Contacts => experiments::contacts(lab, sc),
        }
    }
}

/// A command line as the report shows it: the program as `mcgnode` and
/// every other absolute path by its last component, so that a report names
/// no folder of the machine it ran on.
pub fn shown_command(args: &[String]) -> String {
    let short = |a: &String| {
        let p = std::path::Path::new(a);
        if p.is_absolute() {
            p.file_name()
                .map_or_else(|| a.clone(), |f| f.to_string_lossy().into_owned())
        } else {
            a.clone()
        }
    };
    args.iter()
        .enumerate()
        .map(|(i, a)| {
            if i == 0 {
                "mcgnode".to_string()
            } else {
                short(a)
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// The outcome of a run.
pub struct Outcome {
    /// The report's path.
    pub report: PathBuf,
    /// Every evaluation.
    pub rows: Vec<Row>,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Runs the chosen parts and writes the report, rewritten after each part
/// so that a long run that is stopped keeps what it finished.
pub fn run(opts: &Options, log: &(dyn Fn(&str) + Sync)) -> Result<Outcome> {
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("creating {}", opts.out.display()))?;
    // LGN and HGN need candle's grad-of-grad; candle fixes the setting per
    // thread at its first backward pass, so it is set before any thread starts.
    crate::baselines::autodiff::request_second_order();
    let lab = Lab {
        dir: opts.out.clone(),
        threads: opts.threads.max(1),
        log,
        t0: Instant::now(),
        resume: opts.resume,
    };
    let mut sections: Vec<Section> = vec![];
    let mut report = opts.out.join("report.md");
    for (i, part) in opts.parts.iter().enumerate() {
        lab.say(&format!("experiment: {part}"));
        sections.push(
            part.run(&lab, &opts.scale)
                .with_context(|| format!("experiment {part}"))?,
        );
        report = write_report(opts, &lab, &sections, &opts.parts[i + 1..])?;
    }
    Ok(Outcome {
        report,
        rows: sections.iter().flat_map(|s| s.rows.clone()).collect(),
        seconds: lab.t0.elapsed().as_secs_f64(),
    })
}

/// The report's title, the run's command, scale and duration, and the metrics' definitions.
fn report_header(opts: &Options, lab: &Lab, seconds: f64, pending: &[Part]) -> String {
    let sc = &opts.scale;
    let names = |ps: &[Part]| {
        ps.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut md = String::from("# mcgnode reproduction report\n\n");
    md += &format!(
        "Command: `{}` — scale **{}**, {} worker threads, {} in {:.0} s \
         ({:.1} min) on {} cores. Parts: {}. Every number below was measured in this run; the \
         bags and model files it made are in `data/` and `models/`, every evaluation in \
         `results.json`.\n\n",
        opts.command,
        sc.name,
        lab.threads,
        if pending.is_empty() {
            "finished"
        } else {
            "so far"
        },
        seconds,
        seconds / 60.0,
        std::thread::available_parallelism().map_or(1, std::num::NonZero::get),
        names(&opts.parts),
    );
    if !pending.is_empty() {
        md += &format!("**Partial report**: still to run: {}.\n\n", names(pending));
    }
    if opts.resume {
        md += "**Resumed** (`--resume`): the duration above is this session's; trainings went \
               on from their checkpoints in `checkpoints/`, and their training seconds (and \
               the time budgets derived from them) count every session.\n\n";
    }
    md += "Metrics (paper's definitions): RE = ‖q̂ − q‖/(‖q̂‖ + ‖q‖), EE the same for the \
           Hamiltonian, ME for the total momentum; ME scaled = ‖P̂ − P‖/(Σm|v̂| + Σm|v|) \
           (meaningful when the true momentum is zero, as for our spring starts). \
           Figures: geometric mean over test trajectories with the band where 95 % of them \
           lie. Tables: the time average of the geometric-mean curve (t > 0). A rollout that \
           diverges scores the worst value from then on (relative errors 1).\n\n";
    md
}

/// Writes report.md and results.json from the sections so far; `pending`
/// are the parts still to run (named in the report while it is partial).
fn write_report(
    opts: &Options,
    lab: &Lab,
    sections: &[Section],
    pending: &[Part],
) -> Result<PathBuf> {
    let sc = &opts.scale;
    let seconds = lab.t0.elapsed().as_secs_f64();
    let rows: Vec<Row> = sections.iter().flat_map(|s| s.rows.clone()).collect();
    let names = |ps: &[Part]| {
        ps.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut md = report_header(opts, lab, seconds, pending);
    md += "## What the paper claims, and what we measured\n\n";
    let trained: Vec<&(String, Result<lab::Trained>)> =
        sections.iter().flat_map(|s| s.trained.iter()).collect();
    md += &claims(&opts.parts, &rows, &trained);
    let left_out: Vec<Part> = Part::ALL
        .iter()
        .filter(|p| !opts.parts.contains(p))
        .copied()
        .collect();
    if !left_out.is_empty() {
        md += &format!(
            "- Not run (`--only`): {}; their claims have no result.\n",
            names(&left_out)
        );
    }
    md += "\n";
    for s in sections {
        md += &s.markdown;
        md += "\n";
    }
    md += "## Settings\n\n```json\n";
    md += &serde_json::to_string_pretty(sc)?;
    md += "\n```\n";
    let report = opts.out.join("report.md");
    std::fs::write(&report, md).with_context(|| format!("writing {}", report.display()))?;
    let training: Vec<serde_json::Value> = sections
        .iter()
        .flat_map(|s| s.trained.iter())
        .map(|(label, t)| match t {
            Ok(t) => serde_json::json!({"model": label, "training": t.report}),
            Err(e) => serde_json::json!({"model": label, "error": format!("{e:#}")}),
        })
        .collect();
    let json = serde_json::json!({
        "scale": sc,
        "parts": opts.parts.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "pending": pending.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "seconds": seconds,
        "evaluations": rows,
        "training": training,
    });
    crate::model::file::write_json_atomic(&opts.out.join("results.json"), &json)?;
    Ok(report)
}

/// The rows the claims read, looked up by experiment, system, model and
/// size. A lookup that finds no result is remembered, and the claims end by
/// naming every missing one instead of silently leaving a claim out.
struct Results<'r> {
    /// The parts this run ran; claims of the others are left out (the
    /// report names those parts once).
    ran: &'r [Part],
    rows: &'r [Row],
    trained: &'r [&'r (String, Result<lab::Trained>)],
    missing: RefCell<Vec<String>>,
}

impl<'r> Results<'r> {
    fn new(
        ran: &'r [Part],
        rows: &'r [Row],
        trained: &'r [&'r (String, Result<lab::Trained>)],
    ) -> Self {
        Self {
            ran,
            rows,
            trained,
            missing: RefCell::new(vec![]),
        }
    }

    /// Whether the part with the 5-`sys` ("spring", "pendulum") ran.
    fn ran_system(&self, sys: &str) -> bool {
        let part = if sys == "pendulum" {
            Part::Pendulums
        } else {
            Part::Springs
        };
        self.ran.contains(&part)
    }

    fn miss(&self, what: String) {
        let mut m = self.missing.borrow_mut();
        if !m.contains(&what) {
            m.push(what);
        }
    }

    /// The successful row of `model` in `exp` on the `n`-particle `sys`.
    fn get(&self, exp: Experiment, sys: &str, model: ModelKind, n: usize) -> Option<&'r Row> {
        let r = self.rows.iter().find(|r| {
            r.experiment == exp
                && r.system == sys
                && r.model == model.name()
                && r.particles == n
                && r.error.is_none()
        });
        if r.is_none() {
            // n = 0: the experiment has no rows at all (e.g. not run).
            let what = if n == 0 {
                sys.to_string()
            } else {
                format!("{n}-{sys}")
            };
            self.miss(format!("{exp}: {model} on the {what}"));
        }
        r
    }

    /// RE of `model` in the sweep `exp` at setting `x` (NaN, and remembered,
    /// when missing).
    fn at(&self, exp: Experiment, model: ModelKind, x: f64) -> f64 {
        let r = self.rows.iter().find(|r| {
            r.experiment == exp && r.model == model.name() && r.x == Some(x) && r.error.is_none()
        });
        if r.is_none() {
            self.miss(format!("{exp}: {model} at {x}"));
        }
        r.map_or(f64::NAN, |r| r.averages.re)
    }

    /// The particle count of `exp`'s first row.
    fn particles(&self, exp: Experiment) -> usize {
        self.rows
            .iter()
            .find(|r| r.experiment == exp)
            .map_or(0, |r| r.particles)
    }
}

/// Orders of magnitude between two errors (positive: `a` is below `b`).
fn orders(a: f64, b: f64) -> f64 {
    (b / a).log10()
}

fn verdict(ok: bool, partly: bool) -> &'static str {
    if ok {
        "**confirmed**"
    } else if partly {
        "**partly** (direction confirmed, smaller gap)"
    } else {
        "**not confirmed**"
    }
}

/// The paper's headline claims, one function each, in the order of the report.
const CLAIMS: [fn(&Results, &mut String); 8] = [
    claim_training_cost,
    claim_energy_error,
    claim_zero_momentum,
    claim_bias_ladder,
    claim_peridynamic,
    claim_drag_force,
    claim_noise,
    claim_data_efficiency,
];

const MCGNODE: ModelKind = ModelKind::Family(Variant::Mcgnode);
const GNODE: ModelKind = ModelKind::Family(Variant::Gnode);
const NODE: ModelKind = ModelKind::Family(Variant::Node);
const LGN: ModelKind = ModelKind::Baseline(Kind::Lgn);
const HGN: ModelKind = ModelKind::Baseline(Kind::Hgn);
const GNS: ModelKind = ModelKind::Baseline(Kind::Gns);

/// The paper's headline claims next to this run's numbers; a claim whose
/// rows are missing is named at the end ([`Results`]).
fn claims(ran: &[Part], rows: &[Row], trained: &[&(String, Result<lab::Trained>)]) -> String {
    let res = Results::new(ran, rows, trained);
    let mut out = String::new();
    for claim in CLAIMS {
        claim(&res, &mut out);
    }
    let missing = res.missing.into_inner();
    if !missing.is_empty() {
        out += &format!(
            "- **No result** for {}: the claims that need them are not checked (failures are \
             listed in the sections below).\n",
            missing.join("; ")
        );
    }
    out
}

/// The training cost per epoch (MCGNODE fastest, LGN slowest).
fn claim_training_cost(res: &Results, out: &mut String) {
    let mut line = |s: String| *out += &format!("- {s}\n");
    for sys in ["pendulum", "spring"] {
        if !res.ran_system(sys) {
            continue;
        }
        let per_epoch = |m: ModelKind| {
            let t = res
                .trained
                .iter()
                .find(|(l, _)| l.starts_with(&format!("{m}-5-{sys}")))
                .and_then(|(_, t)| t.as_ref().ok())
                .map(|t| t.report.seconds / t.report.epochs_run.max(1) as f64);
            if t.is_none() {
                res.miss(format!("training: {m} on the 5-{sys}"));
            }
            t
        };
        let ms: Vec<(ModelKind, Option<f64>)> = [MCGNODE, GNODE, HGN, LGN]
            .iter()
            .map(|&m| (m, per_epoch(m)))
            .collect();
        if ms.iter().all(|(_, t)| t.is_some()) {
            let t = |i: usize| ms[i].1.unwrap_or(f64::NAN);
            let fastest = (1..4).all(|i| t(0) <= t(i));
            let lgn_slowest = (0..3).all(|i| t(3) >= t(i));
            line(format!(
                "Training cost on the 5-{sys} (paper: MCGNODE fastest, LGN slowest): seconds per epoch {} — {}.",
                ms.iter()
                    .map(|(m, v)| format!("{m} {:.2}", v.unwrap_or(f64::NAN)))
                    .collect::<Vec<_>>()
                    .join(", "),
                verdict(fastest && lgn_slowest, fastest || lgn_slowest)
            ));
        }
    }
}

/// MCGNODE's energy error against LGN and HGN.
fn claim_energy_error(res: &Results, out: &mut String) {
    let mut line = |s: String| *out += &format!("- {s}\n");
    for (exp, budget, sys, paper_orders) in [
        (Baselines, "equal epochs", "pendulum", 4.0),
        (Baselines, "equal epochs", "spring", 2.0),
        (Wallclock, "equal wall-clock time", "pendulum", 4.0),
        (Wallclock, "equal wall-clock time", "spring", 2.0),
    ] {
        if !res.ran_system(sys) {
            continue;
        }
        let m = res.get(exp, sys, MCGNODE, 5);
        let l = res.get(exp, sys, LGN, 5);
        let h = res.get(exp, sys, HGN, 5);
        if let (Some(m), Some(l), Some(h)) = (m, l, h) {
            let (ol, oh) = (
                orders(m.averages.ee, l.averages.ee),
                orders(m.averages.ee, h.averages.ee),
            );
            let worst = ol.min(oh);
            line(format!(
                "Energy error of MCGNODE vs LGN/HGN on the 5-{sys} at {budget} (paper: \
                 ~{paper_orders:.0} orders of magnitude lower): EE {} vs {} (LGN) and {} (HGN), i.e. {ol:.1} and \
                 {oh:.1} orders — {}.",
                num(m.averages.ee),
                num(l.averages.ee),
                num(h.averages.ee),
                verdict(worst >= paper_orders - 1.0, worst > 0.0)
            ));
        } else {
            line(format!(
                "Energy error vs LGN/HGN on the 5-{sys} at {budget}: a model failed, see below."
            ));
        }
    }
}

/// MCGNODE's momentum error on springs.
fn claim_zero_momentum(res: &Results, out: &mut String) {
    let mut line = |s: String| *out += &format!("- {s}\n");
    if !res.ran_system("spring") {
        return;
    }
    if let (Some(m), Some(g)) = (
        res.get(Biases, "spring", MCGNODE, 5),
        res.get(Biases, "spring", GNODE, 5),
    ) {
        line(format!(
            "ME of MCGNODE on springs is zero (paper): our spring starts have zero momentum, \
             so the paper's ME is ~1 for any inexact prediction; ME scaled is {} for MCGNODE \
             vs {} for GNODE — {}.",
            num(m.averages.me_scaled),
            num(g.averages.me_scaled),
            verdict(
                m.averages.me_scaled < 1e-10,
                m.averages.me_scaled < g.averages.me_scaled
            )
        ));
    }
}

/// Each inductive bias in turn.
fn claim_bias_ladder(res: &Results, out: &mut String) {
    let mut line = |s: String| *out += &format!("- {s}\n");
    for sys in ["spring", "pendulum"] {
        if !res.ran_system(sys) {
            continue;
        }
        let re = |v: Variant| {
            res.get(Biases, sys, ModelKind::Family(v), 5)
                .map_or(f64::NAN, |r| r.averages.re)
        };
        let ladder: Vec<String> = Variant::ALL
            .iter()
            .map(|&v| format!("{v} {}", num(re(v))))
            .collect();
        let best = Variant::ALL[..4]
            .iter()
            .all(|&v| re(Variant::Mcgnode) <= re(v));
        line(format!(
            "Each bias's effect on the 5-{sys} (paper: each bias helps; MCGNODE best on \
             springs, MCGNODE ≈ CDGNODE on pendulums), RE: {} — MCGNODE lowest: {}.",
            ladder.join(", "),
            if best { "yes" } else { "no" }
        ));
    }
}

/// The peridynamic solid: MCGNODE against GNODE and GNS.
fn claim_peridynamic(res: &Results, out: &mut String) {
    let mut line = |s: String| *out += &format!("- {s}\n");
    if !res.ran.contains(&Part::Peridynamic) {
        return;
    }
    let peri = |m| res.get(Peridynamic, "peridynamic", m, res.particles(Peridynamic));
    if let (Some(m), Some(g), Some(s)) = (peri(MCGNODE), peri(GNODE), peri(GNS)) {
        let ok = m.averages.re < g.averages.re && m.averages.re < s.averages.re;
        line(format!(
            "Peridynamic solid (paper: MCGNODE far better than GNODE and GNS; its absolute \
             momentum error near zero): RE {} vs {} (GNODE), {} (GNS); |P̂ − P| {} vs {} \
             (GNODE), {} (GNS) — {}.",
            num(m.averages.re),
            num(g.averages.re),
            num(s.averages.re),
            num(m.averages.me_abs),
            num(g.averages.me_abs),
            num(s.averages.me_abs),
            verdict(
                ok && m.averages.me_abs < 1e-9,
                ok || m.averages.me_abs < 1e-9
            )
        ));
    }
}

/// Drag and external force: MCGNODE against NODE.
fn claim_drag_force(res: &Results, out: &mut String) {
    let mut line = |s: String| *out += &format!("- {s}\n");
    if !res.ran.contains(&Part::DragForce) {
        return;
    }
    for sys in ["spring+drag", "spring+force"] {
        if let (Some(m), Some(n)) = (
            res.get(DragForce, sys, MCGNODE, 5),
            res.get(DragForce, sys, NODE, 5),
        ) {
            line(format!(
                "{sys} (paper: MCGNODE clearly better than NODE): RE {} vs {} — {}.",
                num(m.averages.re),
                num(n.averages.re),
                verdict(
                    m.averages.re < n.averages.re / 10.0,
                    m.averages.re < n.averages.re
                )
            ));
        }
    }
}

/// Robustness to training noise.
fn claim_noise(res: &Results, out: &mut String) {
    let mut line = |s: String| *out += &format!("- {s}\n");
    if !res.ran.contains(&Part::Noise) {
        return;
    }
    if let Some(top) = res
        .rows
        .iter()
        .filter(|r| r.experiment == Noise)
        .filter_map(|r| r.x)
        .max_by(f64::total_cmp)
    {
        let at: Vec<(ModelKind, f64)> = [GNODE, MCGNODE, LGN, HGN]
            .iter()
            .map(|&m| (m, res.at(Noise, m, top)))
            .collect();
        let mcgnode = res.at(Noise, MCGNODE, top);
        let best = at.iter().all(|(_, v)| mcgnode <= *v || v.is_nan());
        line(format!(
            "Noise (paper: MCGNODE the most robust): RE at {top} % noise: {} — MCGNODE lowest: {}.",
            at.iter()
                .map(|(m, v)| format!("{m} {}", num(*v)))
                .collect::<Vec<_>>()
                .join(", "),
            if best { "yes" } else { "no" }
        ));
    } else {
        res.miss(format!("{Noise}: every row"));
    }
}

/// Data efficiency: MCGNODE against NODE and HGN at every size.
fn claim_data_efficiency(res: &Results, out: &mut String) {
    let mut line = |s: String| *out += &format!("- {s}\n");
    if !res.ran.contains(&Part::DataEfficiency) {
        return;
    }
    let mut xs: Vec<f64> = res
        .rows
        .iter()
        .filter(|r| r.experiment == Points)
        .filter_map(|r| r.x)
        .collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    if xs.is_empty() {
        res.miss(format!("{Points}: every row"));
    } else {
        let wins = xs
            .iter()
            .filter(|&&x| {
                res.at(Points, MCGNODE, x) < res.at(Points, NODE, x)
                    && res.at(Points, MCGNODE, x) < res.at(Points, HGN, x)
            })
            .count();
        line(format!(
            "Data efficiency (paper: MCGNODE orders of magnitude better than NODE and HGN at \
             every size): MCGNODE has the lowest RE at {wins} of {} sizes; at {} points RE is \
             {} (MCGNODE), {} (NODE), {} (HGN).",
            xs.len(),
            xs[0],
            num(res.at(Points, MCGNODE, xs[0])),
            num(res.at(Points, NODE, xs[0])),
            num(res.at(Points, HGN, xs[0]))
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shown_command_names_no_folder_of_the_machine() {
        let args: Vec<String> = [
            "/work/main/target/release/mcgnode",
            "reproduce",
            "--out",
            "/work/runs/repro",
            "--epochs",
            "10",
            "rel/dir",
        ]
        .iter()
        .map(ToString::to_string)
        .collect();
        assert_eq!(
            shown_command(&args),
            "mcgnode reproduce --out repro --epochs 10 rel/dir"
        );
    }

    #[test]
    fn parts_parse_by_name() {
        assert_eq!("drag-force".parse::<Part>().unwrap(), Part::DragForce);
        let e = "spring".parse::<Part>().unwrap_err().to_string();
        assert!(e.contains("springs, pendulums"), "{e}");
    }
}
