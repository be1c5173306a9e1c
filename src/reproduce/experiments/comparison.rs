//! The main comparison on the 5-spring or 5-pendulum: the GNODE family's
//! biases, the baselines, architectures, zero-shot sizes and wall-clock time.

use super::common::{
    cfg, failures, figure, panels, run_evals, EvalJob, Section, TrainedList, BASELINES, FAMILY,
    TEST_SEED, TRAIN_SEED,
};
use crate::baselines::Kind;
use crate::error::Result;
use crate::gnode::{ArchPreset, Variant};
use crate::models::ModelKind;
use crate::physics::{SystemConfig, SystemKind};
use crate::plot::Metric;
use crate::reproduce::lab::{Lab, TrainSpec, Trained};
use crate::reproduce::report::{error_table, num, table, Experiment, Row};
use crate::reproduce::scale::Scale;
use crate::train::{ModelOptions, Recipe, TrainConfig};
use std::path::PathBuf;

/// Biases, baselines, zero-shot sizes and timing on one system family
/// (paper Figs. 1–4, the zero-shot figure and the timing tables).
pub fn main_comparison(lab: &Lab, sc: &Scale, kind: SystemKind) -> Result<Section> {
    let c = Comparison::simulate(lab, sc, kind)?;
    let mut specs = c.specs(sc);
    let plain: Vec<TrainSpec> = specs.iter().map(|s| s.1.clone()).collect();
    let mut trained = lab.train_all(&plain);
    // Equal wall-clock time, a user's real budget: the baselines get the
    // seconds MCGNODE's bias-ladder training took.
    let mcgnode = specs
        .iter()
        .zip(&trained)
        .find(|((e, s), _)| {
            *e == Experiment::Biases && s.kind == ModelKind::Family(Variant::Mcgnode)
        })
        .and_then(|(_, t)| t.as_ref().ok())
        .cloned();
    if let Some(m) = &mcgnode {
        let wall = c.wallclock_specs(m.report.seconds);
        trained.extend(lab.train_all(&wall));
        specs.extend(wall.into_iter().map(|s| (Experiment::Wallclock, s)));
    }
    lab.say(&format!("{}: trained {} models", c.sys, specs.len()));
    let mut jobs = c.jobs(sc, &specs, &trained);
    if let Some(m) = &mcgnode {
        jobs.extend(c.wallclock_mcgnode_jobs(sc, m));
    }
    let mut rows = run_evals(lab, jobs);
    let mut md = c.results(lab, sc, &rows, mcgnode.as_ref());
    let section_trained: TrainedList = specs
        .iter()
        .map(|s| s.1.label.clone())
        .zip(trained)
        .collect();
    md += &failures(&section_trained);
    if kind == SystemKind::Spring && !sc.large_springs.is_empty() {
        let large = c.zero_shot_large(lab, sc, &specs, &section_trained)?;
        md += "### Zero-shot to large rings (beyond the paper)\n\n";
        md += "Trained on 5 springs, run unchanged on hundreds and thousands; rollout time \
                is the wall time of one trajectory on the hand-written kernel (one core).\n\n";
        md += &error_table(&large.iter().collect::<Vec<_>>());
        md += "\n";
        rows.extend(large);
    }
    md += &timing_table(lab, c.sys, &specs, &section_trained, &rows);
    Ok(Section {
        markdown: md,
        rows,
        trained: section_trained,
    })
}

/// One system's comparison (GNODE family, baselines, zero-shot sizes): its
/// simulated bags and the sizes and settings it is evaluated at.
struct Comparison<'s> {
    kind: SystemKind,
    sys: &'static str,
    base: SystemConfig,
    train_bag: PathBuf,
    hgn_bag: PathBuf,
    sizes: &'s Vec<usize>,
    bsizes: &'s Vec<usize>,
    states: usize,
    dt: Option<f64>,
    test_bags: Vec<(usize, PathBuf)>,
}

impl<'s> Comparison<'s> {
    /// Simulates the training bags (HGN's on RK4) and a test bag per size.
    fn simulate(lab: &Lab, sc: &'s Scale, kind: SystemKind) -> Result<Self> {
        let sys = kind.name();
        let base = SystemConfig::new(kind, 5);
        let train_bag = lab.bag(
            &format!("train-5-{sys}"),
            &base,
            sc.train_trajectories,
            TRAIN_SEED,
            false,
        )?;
        // HGN learns from RK4 data on (q, p), as in the paper.
        let hgn_bag = lab.bag(
            &format!("train-5-{sys}-rk4"),
            &base,
            sc.train_trajectories,
            TRAIN_SEED,
            true,
        )?;
        let (sizes, bsizes, states, dt) = match kind {
            SystemKind::Pendulum => (
                &sc.pendulum_sizes,
                &sc.baseline_pendulum_sizes,
                sc.pendulum_states,
                Some(sc.pendulum_dt),
            ),
            _ => (
                &sc.spring_sizes,
                &sc.baseline_spring_sizes,
                sc.spring_states,
                None,
            ),
        };
        let mut all_sizes: Vec<usize> = sizes.iter().chain(bsizes.iter()).copied().collect();
        all_sizes.sort_unstable();
        all_sizes.dedup();
        let mut test_bags = vec![];
        for &n in &all_sizes {
            let mut c = SystemConfig::new(kind, n);
            c.states = states;
            test_bags.push((
                n,
                lab.bag(
                    &format!("test-{n}-{sys}"),
                    &c,
                    sc.test_trajectories,
                    TEST_SEED,
                    false,
                )?,
            ));
        }
        lab.say(&format!("{sys}: simulated training and test bags"));
        Ok(Self {
            kind,
            sys,
            base,
            train_bag,
            hgn_bag,
            sizes,
            bsizes,
            states,
            dt,
            test_bags,
        })
    }

    /// What to train, with the experiment each belongs to.
    fn specs(&self, sc: &Scale) -> Vec<(Experiment, TrainSpec)> {
        let (sys, train_bag, hgn_bag) = (self.sys, &self.train_bag, &self.hgn_bag);
        // The GNODE family gets `family_epochs` (the bias ladder); MCGNODE and
        // the baselines meet at `epochs` each (the baseline comparison): the
        // candle baselines cost 10–50× more per epoch.
        let mut specs: Vec<(Experiment, TrainSpec)> = FAMILY
            .iter()
            .map(|&v| {
                (
                    Experiment::Biases,
                    TrainSpec {
                        label: format!("{v}-5-{sys}"),
                        kind: ModelKind::Family(v),
                        bags: vec![train_bag.clone()],
                        cfg: cfg(sc.family_epochs),
                        opts: ModelOptions::for_recipe(Recipe::Paper),
                    },
                )
            })
            .collect();
        for k in std::iter::once(ModelKind::Family(Variant::Mcgnode))
            .chain(BASELINES.iter().map(|&k| ModelKind::Baseline(k)))
        {
            specs.push((
                Experiment::Baselines,
                TrainSpec {
                    label: format!("{k}-5-{sys}-{}ep", sc.epochs),
                    kind: k,
                    bags: vec![if k == ModelKind::Baseline(Kind::Hgn) {
                        hgn_bag.clone()
                    } else {
                        train_bag.clone()
                    }],
                    cfg: cfg(sc.epochs),
                    opts: ModelOptions::for_recipe(Recipe::Paper),
                },
            ));
        }
        // The ablation of the architecture: the paper text's (one hidden
        // layer, linear messages, h_i ‖ h_j) against the authors' default.
        for v in [Variant::Gnode, Variant::Mcgnode] {
            specs.push((
                Experiment::Architecture,
                TrainSpec {
                    label: format!("{v}-5-{sys}-paper-text"),
                    kind: ModelKind::Family(v),
                    bags: vec![train_bag.clone()],
                    cfg: cfg(sc.family_epochs),
                    opts: ModelOptions {
                        arch: ArchPreset::Paper,
                        ..ModelOptions::for_recipe(Recipe::Paper)
                    },
                },
            ));
        }
        specs
    }

    /// The baselines trained for `budget` seconds (as long as MCGNODE took).
    fn wallclock_specs(&self, budget: f64) -> Vec<TrainSpec> {
        BASELINES
            .iter()
            .map(|&k| TrainSpec {
                label: format!("{k}-5-{}-equal-time", self.sys),
                kind: ModelKind::Baseline(k),
                bags: vec![if k == Kind::Hgn {
                    self.hgn_bag.clone()
                } else {
                    self.train_bag.clone()
                }],
                cfg: TrainConfig {
                    time_budget: Some(budget),
                    ..cfg(usize::MAX / 2)
                },
                opts: ModelOptions::for_recipe(Recipe::Paper),
            })
            .collect()
    }

    /// MCGNODE's bias-ladder model beside the wall-clock baselines.
    fn wallclock_mcgnode_jobs(&self, sc: &Scale, m: &Trained) -> Vec<EvalJob> {
        self.bsizes
            .iter()
            .map(|&n| EvalJob {
                experiment: Experiment::Wallclock,
                system: self.sys.into(),
                label: Variant::Mcgnode.name().into(),
                particles: n,
                x: None,
                model: m.path.clone(),
                bag: self.test_bag(n),
                dt: self.dt,
                max: sc.baseline_test_trajectories,
            })
            .collect()
    }

    /// The test bag of the `n`-particle system.
    fn test_bag(&self, n: usize) -> PathBuf {
        self.test_bags
            .iter()
            .find(|b| b.0 == n)
            .expect("bag simulated")
            .1
            .clone()
    }

    /// The evaluations of the trained models: the family at every size,
    /// MCGNODE and the baselines at the baseline sizes, NODE on its own.
    fn jobs(
        &self,
        sc: &Scale,
        specs: &[(Experiment, TrainSpec)],
        trained: &[Result<Trained>],
    ) -> Vec<EvalJob> {
        let (sys, sizes, bsizes, dt, test_bags) =
            (self.sys, self.sizes, self.bsizes, self.dt, &self.test_bags);
        let mut jobs = vec![];
        for ((experiment, spec), t) in specs.iter().zip(trained) {
            let Ok(t) = t else { continue };
            let k = spec.kind;
            let (evals, max): (Vec<usize>, usize) = match (*experiment, k) {
                (_, ModelKind::Family(Variant::Node)) => (vec![5], sc.test_trajectories),
                (Experiment::Biases | Experiment::Architecture, _) => {
                    (sizes.clone(), sc.test_trajectories)
                }
                _ => (bsizes.clone(), sc.baseline_test_trajectories),
            };
            for n in evals {
                let bag = &test_bags
                    .iter()
                    .find(|b| b.0 == n)
                    .expect("bag simulated")
                    .1;
                jobs.push(EvalJob {
                    experiment: *experiment,
                    system: sys.into(),
                    label: k.name().into(),
                    particles: n,
                    x: None,
                    model: t.path.clone(),
                    bag: bag.clone(),
                    dt,
                    max,
                });
            }
        }
        jobs
    }

    /// The section's text, figures and error tables; `mcgnode` is the
    /// bias-ladder model whose training time the wall-clock baselines got.
    fn results(&self, lab: &Lab, sc: &Scale, rows: &[Row], mcgnode: Option<&Trained>) -> String {
        let mut md = self.intro(sc);
        md += &self.figures(lab, rows, mcgnode);
        md += &architecture_tables(rows);
        md += &average_tables(rows);
        md
    }

    /// The heading and what was trained and evaluated how.
    fn intro(&self, sc: &Scale) -> String {
        let sys = self.sys;
        let horizon = (self.states - 1) as f64
            * match self.kind {
                SystemKind::Pendulum => 0.01,
                _ => 0.1,
            };
        format!(
            "## {sys}: inductive biases, baselines, zero-shot sizes\n\n\
             Trained on {} trajectories of the 5-{sys} ({} states): the GNODE family for {} \
             epochs, and MCGNODE, LGN, HGN and GNS for {} epochs each (HGN on RK4 data). \
             Evaluated from held-out starts (seed {TEST_SEED}) over {horizon} s with rollout step \
             {} s ({} test trajectories for the GNODE family; the baseline comparison uses the \
             first {} of them for every model). NODE is transductive: it runs only on the size \
             it was trained on.\n\n",
            sc.train_trajectories,
            sc.train_trajectories * self.base.states,
            sc.family_epochs,
            sc.epochs,
            self.dt.unwrap_or(self.base.dt),
            sc.test_trajectories,
            sc.baseline_test_trajectories,
        )
    }

    /// The bias ladder, the baselines at equal epochs and (when MCGNODE
    /// trained) at equal wall-clock time.
    fn figures(&self, lab: &Lab, rows: &[Row], mcgnode: Option<&Trained>) -> String {
        let sys = self.sys;
        let metrics = [Metric::Re, Metric::Ee, Metric::Me, Metric::MeScaled];
        let fam: Vec<String> = FAMILY.iter().map(|v| v.name().to_string()).collect();
        let bl: Vec<String> = ["mcgnode", "lgn", "hgn", "gns"]
            .iter()
            .map(std::string::ToString::to_string)
            .collect();
        let fig = |exp: Experiment, file: &str, sizes: &[usize], labels: &[String]| {
            figure(
                lab,
                &format!("{file}-{sys}.png"),
                &panels(rows, exp, sys, sizes, labels),
                &metrics,
            )
        };
        let mut md = format!(
            "### Each bias in turn (paper Figs. 1 and 4)\n\n{}",
            fig(Experiment::Biases, "biases", self.sizes, &fam)
        );
        md += &format!(
            "### MCGNODE against LGN, HGN and GNS (paper Figs. 2–3)\n\n{}",
            fig(Experiment::Baselines, "baselines", self.bsizes, &bl)
        );
        if let Some(m) = mcgnode {
            md += &format!(
                "### MCGNODE against LGN, HGN and GNS at equal wall-clock time\n\n\
                 Each baseline trained for the {:.0} s MCGNODE's {} epochs took (the epochs \
                 this bought are in the timing table below).\n\n{}",
                m.report.seconds,
                m.report.epochs_run,
                fig(Experiment::Wallclock, "wallclock", self.bsizes, &bl)
            );
        }
        md
    }
    /// The 5-spring models of the family, run unchanged on large rings.
    fn zero_shot_large(
        &self,
        lab: &Lab,
        sc: &Scale,
        specs: &[(Experiment, TrainSpec)],
        section_trained: &TrainedList,
    ) -> Result<Vec<Row>> {
        let (kind, sys, states, dt) = (self.kind, self.sys, self.states, self.dt);
        let mut jobs = vec![];
        for &(n, t) in &sc.large_springs {
            let mut c = SystemConfig::new(kind, n);
            c.states = states;
            let bag = lab.bag(&format!("test-{n}-{sys}"), &c, t, TEST_SEED, false)?;
            for ((exp, spec), (_, tr)) in specs.iter().zip(section_trained) {
                let Ok(tr) = tr else { continue };
                let k = spec.kind;
                let zero_shot = [Variant::Mcgnode, Variant::Gnode].map(ModelKind::Family);
                if *exp == Experiment::Biases && zero_shot.contains(&k) {
                    jobs.push(EvalJob {
                        experiment: Experiment::Large,
                        system: sys.into(),
                        label: k.name().into(),
                        particles: n,
                        x: None,
                        model: tr.path.clone(),
                        bag: bag.clone(),
                        dt,
                        max: t,
                    });
                }
            }
        }
        Ok(run_evals(lab, jobs))
    }
}

/// Training and forward-simulation time of every model of a comparison.
fn timing_table(
    lab: &Lab,
    sys: &str,
    specs: &[(Experiment, TrainSpec)],
    section_trained: &TrainedList,
    rows: &[Row],
) -> String {
    let mut md = String::new();
    md += &format!("### Training and forward-simulation time ({sys}; paper Tables 3–4)\n\n");
    let mut timing = vec![];
    for ((exp, spec), (label, t)) in specs.iter().zip(section_trained) {
        let Ok(t) = t else { continue };
        let name = spec.kind.name();
        let fwd = rows
            .iter()
            .find(|r| r.model == name && r.particles == 5 && r.experiment == *exp)
            .map_or(f64::NAN, |r| r.rollout_seconds);
        let r = &t.report;
        timing.push(vec![
            label.clone(),
            r.epochs_run.to_string(),
            format!("{:.1}", r.seconds),
            format!("{:.1}", 1e3 * r.seconds / r.epochs_run.max(1) as f64),
            format!("{fwd:.3}"),
            num(r.validation_loss),
        ]);
    }
    md += &table(
        &[
            "model",
            "epochs",
            "training s",
            "ms/epoch",
            "forward simulation s per 5-particle trajectory",
            "best validation MSE",
        ],
        &timing,
    );
    md += &format!(
        "\nTraining ran {} models at a time on this machine's cores, so times include \
         contention. Forward simulation covers the whole test horizon; the GNODE family \
         runs one trajectory at a time on the kernel, LGN/HGN/GNS step all their test \
         trajectories together in one candle call per step (time divided by their number).\n\n",
        lab.threads
    );
    md
}

/// GNODE and MCGNODE with the authors' architecture against the paper text's.
fn architecture_tables(rows: &[Row]) -> String {
    let arch_rows = |exp: Experiment| {
        let mut r: Vec<&Row> = rows
            .iter()
            .filter(|r| r.experiment == exp && ["gnode", "mcgnode"].contains(&r.model.as_str()))
            .collect();
        r.sort_by_key(|r| r.particles);
        r
    };
    format!(
        "### The architecture: the authors' code against the paper's text\n\n\
         GNODE and MCGNODE as above (the authors' code: two hidden layers of 5 per MLP, MLP \
         message functions, h_i ⊙ h_j in the edge update) and with the paper text's \
         architecture (one hidden layer, linear message functions, h_i ‖ h_j), same data, \
         epochs and seed. Default:\n\n{}\nPaper text:\n\n{}\n",
        error_table(&arch_rows(Experiment::Biases)),
        error_table(&arch_rows(Experiment::Architecture)),
    )
}

/// The time-averaged errors of the family and of both baseline comparisons.
fn average_tables(rows: &[Row]) -> String {
    let mut md = String::new();
    for (exp, what) in [
        (Experiment::Biases, "the GNODE family"),
        (
            Experiment::Baselines,
            "MCGNODE and the baselines at equal epochs",
        ),
        (
            Experiment::Wallclock,
            "MCGNODE and the baselines at equal wall-clock time",
        ),
    ] {
        let mut sorted: Vec<&Row> = rows.iter().filter(|r| r.experiment == exp).collect();
        sorted.sort_by_key(|r| r.particles);
        md += &format!("Time-averaged geometric means (t > 0), {what}:\n\n");
        md += &error_table(&sorted);
        md += "\n";
    }
    md
}
