//! `mcgnode bag import`: other projects' datasets written as bags.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use crate::data::import::{
    read_gns, read_lagrangebench, write_gns_bag, write_lagrangebench_bag, GnsSource,
};
use crate::physics::Field;

/// The formats `bag import` reads.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImportFormat {
    /// GNS (Sanchez-Gonzalez et al. 2020): `{split}.tfrecord` of
    /// SequenceExamples beside `metadata.json`.
    Gns,
    /// LagrangeBench: `{split}.h5` beside `metadata.json`.
    Lagrangebench,
}

/// The dataset splits.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Split {
    /// `train`.
    Train,
    /// `valid`.
    Valid,
    /// `test`.
    Test,
}

impl Split {
    fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Valid => "valid",
            Split::Test => "test",
        }
    }
}

/// Options of `bag import`.
#[derive(clap::Args, Debug, Clone)]
pub struct ImportArgs {
    /// The dataset's format.
    #[arg(long = "from", value_enum)]
    pub from: ImportFormat,
    /// A dataset directory (holding `metadata.json` and `{split}.tfrecord`
    /// or `{split}.h5`), or one records file (with --metadata when its
    /// metadata.json is not beside it).
    pub src: PathBuf,
    /// The split read from a directory.
    #[arg(long, value_enum, default_value = "train")]
    pub split: Split,
    /// The dataset's metadata.json (default: the one beside the records).
    #[arg(long)]
    pub metadata: Option<PathBuf>,
    /// Time between stored steps, seconds: replaces the metadata's `dt`
    /// (needed when it has none).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Gravity g along −y, stated in every message as the whole field (the
    /// datasets do not say it). Default: the field is left unknown, and
    /// training MCGNODE then asks for --body-force.
    #[arg(long, conflicts_with = "closed")]
    pub gravity: Option<f64>,
    /// State in every message that nothing acts besides the particles (no
    /// gravity, drag or force).
    #[arg(long)]
    pub closed: bool,
    /// The MCAP bag to write.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `bag import`.
pub fn run(a: &ImportArgs) -> Result<()> {
    match a.from {
        ImportFormat::Gns => gns(a),
        ImportFormat::Lagrangebench => lagrangebench(a),
    }
}

/// The field `--gravity` / `--closed` state, if either.
fn stated_field(a: &ImportArgs) -> Option<Field> {
    (a.closed || a.gravity.is_some()).then(|| Field {
        gravity: a.gravity.unwrap_or(0.0),
        drag: 0.0,
        force: vec![],
    })
}

fn lagrangebench(a: &ImportArgs) -> Result<()> {
    if !a.src.is_dir() || a.metadata.is_some() {
        bail!(
            "--from lagrangebench reads a dataset directory holding {{train,valid,test}}.h5 and \
             metadata.json (no --metadata): {} is not one",
            a.src.display()
        );
    }
    let imp = read_lagrangebench(&a.src, a.split.name(), a.dt)?;
    let states = write_lagrangebench_bag(&imp, &a.out, stated_field(a).as_ref())
        .with_context(|| format!("writing {}", a.out.display()))?;
    let n = imp.trajectories.first().map_or(0, |t| t.graph.n());
    let kin = imp
        .trajectories
        .first()
        .map_or(0, |t| t.graph.n_kinematic());
    let periodic = match imp.meta.periodic_box() {
        Some(_) => "periodic",
        None => "not periodic",
    };
    println!(
        "wrote {}: {} trajectories from {}, {states} states, {n} particles ({kin} kinematic), \
         dim {}, frame dt {}, interaction radius {}, {periodic}; velocities by finite differences",
        a.out.display(),
        imp.trajectories.len(),
        imp.file.display(),
        imp.meta.dim,
        imp.meta.frame_dt,
        imp.meta.radius
    );
    Ok(())
}

fn gns(a: &ImportArgs) -> Result<()> {
    let imp = read_gns(&GnsSource {
        src: a.src.clone(),
        split: a.split.name().to_string(),
        metadata: a.metadata.clone(),
        dt: a.dt,
    })?;
    let states = write_gns_bag(&imp, &a.out, stated_field(a).as_ref())
        .with_context(|| format!("writing {}", a.out.display()))?;
    let n: Vec<usize> = imp.trajectories.iter().map(|t| t.graph.n()).collect();
    let kin: usize = imp.trajectories.iter().map(|t| t.graph.n_kinematic()).sum();
    println!(
        "wrote {}: {} trajectories from {}, {states} states, {}-{} particles ({kin} kinematic in \
         all), dim {}, dt {}, interaction radius {}; velocities by finite differences",
        a.out.display(),
        imp.trajectories.len(),
        imp.records.display(),
        n.iter().min().unwrap_or(&0),
        n.iter().max().unwrap_or(&0),
        imp.meta.dim,
        imp.meta.dt,
        imp.meta.radius
    );
    Ok(())
}
