//! Systems that touch (not in the paper; issue 21): MCGNODE, GNODE and GNS on
//! contact edges found at every state, on a soft-sphere box with kinematic
//! walls under gravity and on two colliding spring lattices (closed), at equal
//! epochs and at equal wall-clock time (GNS for the seconds MCGNODE took),
//! and zero-shot on each system with 4x the free particles.

use super::common::{
    diverged, rows_table, run_evals, section, training_rows, EvalJob, Section, TEST_SEED,
    TRAIN_SEED,
};
use crate::baselines::Kind;
use crate::error::Result;
use crate::gnode::Variant;
use crate::models::ModelKind;
use crate::physics::{SystemConfig, SystemKind};
use crate::reproduce::lab::{Lab, TrainSpec, Trained};
use crate::reproduce::report::{num, table, Experiment};
use crate::reproduce::scale::Scale;
use crate::train::recipe::Auto;
use crate::train::{ModelOptions, TrainConfig};

/// Every model trains with the default recipe but the epochs (given), on
/// one core each (trainings run side by side).
fn contact_cfg(epochs: usize) -> TrainConfig {
    TrainConfig {
        epochs,
        patience: epochs,
        seed: 0,
        threads: 1,
        auto: Auto::GIVEN_EPOCHS,
        ..TrainConfig::default()
    }
}

/// The models of one system: MCGNODE and GNODE, then GNS at equal epochs
/// and GNS for the seconds MCGNODE took (its time budget is set later).
fn specs(system: &str, bag: &std::path::Path, sc: &Scale, edge_physics: bool) -> Vec<TrainSpec> {
    // The default recipe's options (`mcgnode train`'s).
    let opts = ModelOptions {
        edge_physics,
        ..ModelOptions::default()
    };
    let spec = |label: &str, kind: ModelKind| TrainSpec {
        label: format!("{label}-{system}"),
        kind,
        bags: vec![bag.to_path_buf()],
        cfg: contact_cfg(sc.contact_epochs),
        opts: opts.clone(),
    };
    vec![
        spec("mcgnode", ModelKind::Family(Variant::Mcgnode)),
        spec("gnode", ModelKind::Family(Variant::Gnode)),
        spec("gns", ModelKind::Baseline(Kind::Gns)),
        spec("gns-equal-time", ModelKind::Baseline(Kind::Gns)),
    ]
}

/// Trains a system's models: the family and GNS at equal epochs side by
/// side, then GNS again for at most MCGNODE's seconds.
fn train(lab: &Lab, specs: &mut [TrainSpec]) -> Vec<Result<Trained>> {
    let mut trained = lab.train_all(&specs[..3]);
    let budget = trained[0].as_ref().ok().map(|t| t.report.seconds);
    specs[3].cfg.time_budget = budget;
    specs[3].cfg.epochs = specs[3].cfg.epochs.max(1) * 100;
    specs[3].cfg.patience = specs[3].cfg.epochs;
    trained.extend(lab.train_all(&specs[3..]));
    trained
}

/// MCGNODE, GNODE and GNS on the soft-sphere box and the colliding lattices.
pub fn contacts(lab: &Lab, sc: &Scale) -> Result<Section> {
    let mut box_cfg = SystemConfig::new(SystemKind::SoftSpheres, sc.contact_balls);
    box_cfg.states = 31;
    let mut lat_cfg = SystemConfig::new(SystemKind::CollidingLattices, 32);
    lat_cfg.states = 31;
    let n = (sc.contact_train_trajectories, sc.contact_test_trajectories);
    let systems = [
        ("soft-spheres", &box_cfg, false),
        ("colliding-lattices", &lat_cfg, true),
    ];
    // Zero-shot in size: every system again with 4x the free particles (a
    // box of 4x the balls; two lattices of twice the side).
    let four_times = |cfg: &SystemConfig| {
        let mut big = cfg.clone();
        big.particles = 4 * cfg.particles;
        big
    };
    let (mut all_specs, mut all_trained, mut jobs) = (vec![], vec![], vec![]);
    let mut test_bags = vec![];
    for (name, cfg, edge_physics) in systems {
        let train_bag = lab.bag(&format!("train-{name}"), cfg, n.0, TRAIN_SEED, false)?;
        let test_bag = lab.bag(&format!("test-{name}"), cfg, n.1, TEST_SEED, false)?;
        let mut s = specs(name, &train_bag, sc, edge_physics);
        let trained = train(lab, &mut s);
        let big_cfg = four_times(cfg);
        let big = lab.bag(&format!("test-{name}-4x"), &big_cfg, n.1, TEST_SEED, false)?;
        let tests = vec![(cfg.particles, test_bag), (big_cfg.particles, big)];
        test_bags.extend(tests.iter().map(|(p, b)| (name, *p, b.clone())));
        for (spec, t) in s.iter().zip(&trained) {
            let Ok(t) = t else { continue };
            for (particles, bag) in &tests {
                jobs.push(EvalJob {
                    experiment: Experiment::Contacts,
                    system: name.into(),
                    label: spec
                        .label
                        .split(&format!("-{name}"))
                        .next()
                        .unwrap_or("")
                        .into(),
                    particles: *particles,
                    x: None,
                    model: t.path.clone(),
                    bag: bag.clone(),
                    dt: None,
                    max: n.1,
                });
            }
        }
        all_specs.extend(s);
        all_trained.extend(trained);
    }
    let rows = run_evals(lab, jobs);
    let mut md = intro(sc, n);
    md += &training_table(&all_specs, &all_trained);
    md += "\nTime averages over the rollouts (RE still: predicting that nothing moves):\n\n";
    md += &rows_table(
        &rows,
        &[
            ("system", |r| r.system.clone()),
            ("particles", |r| r.particles.to_string()),
            ("model", |r| r.model.clone()),
            ("RE", |r| num(r.averages.re)),
            ("ME scaled", |r| num(r.averages.me_scaled)),
            ("diverged", diverged),
        ],
    );
    md += &still_table(&test_bags)?;
    Ok(section(md, rows, &all_specs, all_trained))
}

/// The section's opening: the systems, the models and how they are scored.
fn intro(sc: &Scale, n: (usize, usize)) -> String {
    format!(
        "## Systems that touch (not in the paper)\n\nContact edges found at every state \
         (pairs closer than the radius, no fixed edge between them, not both kinematic): a box \
         of {} soft spheres (R = 1, k_c = 1000, g = 1) whose walls are kinematic particles, and \
         two colliding 4×4 spring lattices (closed; the models read edge physics). {} training \
         and {} test trajectories of 3 s; MCGNODE, GNODE and GNS {} epochs each with the default \
         recipe, and GNS again for at most the seconds MCGNODE took (`gns-equal-time`); every model \
         is also rolled out on its system with 4x the free particles (zero-shot in size: a box of \
         {} balls, two 8×8 lattices). Kinematic particles are left out of every loss and held in \
         every rollout.\n\n",
        sc.contact_balls,
        n.0,
        n.1,
        sc.contact_epochs,
        4 * sc.contact_balls
    )
}

/// Epochs and seconds each model trained.
fn training_table(specs: &[TrainSpec], trained: &[Result<Trained>]) -> String {
    let body = training_rows(specs, trained, |s, r| {
        vec![
            s.label.clone(),
            r.epochs_run.to_string(),
            format!("{:.1}", r.seconds),
            r.explained
                .map_or_else(|| "-".into(), |x| format!("{:.2} %", 100.0 * x)),
        ]
    });
    table(&["model", "epochs", "training s", "explained"], &body)
}

/// Standing still on each test bag, for scale.
fn still_table(bags: &[(&str, usize, std::path::PathBuf)]) -> Result<String> {
    let mut body = vec![];
    for (system, particles, bag) in bags {
        let still = crate::evaluate::evaluate(
            &crate::dynamics::Still,
            &[],
            &crate::data::bag::read_trajectories(bag)?,
            &crate::evaluate::EvalOptions::default(),
        )?;
        body.push(vec![
            (*system).to_string(),
            particles.to_string(),
            num(still.averages.re),
        ]);
    }
    Ok(format!(
        "\nStanding still on the same test bags:\n\n{}",
        table(&["system", "particles", "RE still"], &body)
    ))
}
