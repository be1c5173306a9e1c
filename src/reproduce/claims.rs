//! The paper's headline claims next to a run's numbers, for the report: one
//! function per claim, reading the rows through [`Results`], which names
//! every result a claim needed and did not find.

use super::lab;
use super::part::Part;
use super::report::Experiment::{
    Baselines, Biases, DragForce, Noise, Peridynamic, Points, Wallclock,
};
use super::report::{num, Experiment, Row};
use crate::baselines::Kind;
use crate::error::Result;
use crate::gnode::Variant;
use crate::models::ModelKind;
use std::cell::RefCell;

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
pub(super) fn claims(
    ran: &[Part],
    rows: &[Row],
    trained: &[&(String, Result<lab::Trained>)],
) -> String {
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
