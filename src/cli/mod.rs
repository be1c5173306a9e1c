//! The `mcgnode` command line: one subcommand per step of the pipeline.

mod bag;
mod bench;
// Public: the types of `train::Args`' fields.
pub mod choices;
mod demo;
mod evaluate;
mod field;
mod plan;
mod replay;
mod reproduce;
mod rollout;
mod serve;
mod simulate;
mod start;
mod vector;
// Public for the Python package's `mcgnode.train` (python/), which parses its
// options with these Args and trains through `train::train`.
pub mod train;

use clap::{Parser, Subcommand};

pub use vector::Vector;
// For the subcommands' flags (`simulate --force`).
pub(crate) use vector::parse_vector;

/// mcgnode: learn the dynamics of particle systems from trajectories (GNODE,
/// CGNODE, CDGNODE, MCGNODE; Bishnoi et al.) and serve them to robots over ROS 2.
#[derive(Parser)]
#[command(version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate ground-truth trajectories into an MCAP bag of ParticleState messages.
    Simulate(simulate::Args),
    /// Train a model on trajectory bags and write a model file.
    Train(train::Args),
    /// Roll a trained model out from an initial state and write the trajectory as a bag.
    Rollout(rollout::Args),
    /// Plan the motion of the kinematic particles (a gripper) that brings chosen particles to targets: sampled candidates rolled out through a model (JSON out).
    Plan(plan::Args),
    /// Score a model on a test bag: RE, EE and ME over time (table, JSON, PNG).
    Evaluate(evaluate::Args),
    /// The embedded default: simulate, train GNODE and MCGNODE, evaluate on 5/20/50 springs.
    Demo(demo::Args),
    /// Measure training-step and rollout speed.
    Bench(bench::Args),
    /// Replay a bag through a model: RE, EE and ME against lead time for every recorded start state (table, JSON, PNG).
    Replay(replay::Args),
    /// Run every experiment of the paper (biases, baselines, zero-shot, peridynamic solid, drag/force, noise, data efficiency) and write DIR/report.md with figures.
    Reproduce(reproduce::Args),
    /// Run the ROS 2 node.
    Serve(serve::ServeArgs),
    /// Inspect bags (`bag info`) and repair one cut short by a crash (`bag repair`).
    Bag(bag::Args),
}

/// An error as the binary prints it: the message, then each cause that the
/// messages before it do not already state (the library's errors carry their
/// causes in their messages; anyhow's `{:#}` would print those twice).
pub fn error_report(e: &anyhow::Error) -> String {
    let mut out = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !out.contains(&c) {
            out += ": ";
            out += &c;
        }
    }
    out
}

/// A command whose reader goes away (`mcgnode plan --json | head`) ends
/// quietly as Unix tools do, by SIGPIPE, instead of panicking in `println!`.
/// Not for `serve`: the node keeps serving (and recording) whatever happens
/// to its output.
fn quiet_on_closed_pipe() {
    // SAFETY: restores the default action of one signal before any thread
    // that could be writing is started; no handler is installed.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Parses the command line and runs the subcommand.
pub fn run() -> anyhow::Result<()> {
    crate::alloc::prepare_for_candle();
    let cli = Cli::parse();
    if !matches!(cli.command, Command::Serve(_)) {
        quiet_on_closed_pipe();
    }
    match cli.command {
        Command::Simulate(a) => simulate::run(a),
        Command::Train(a) => train::run(a),
        Command::Rollout(a) => rollout::run(a),
        Command::Plan(a) => plan::run(a),
        Command::Evaluate(a) => evaluate::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Replay(a) => replay::run(a),
        Command::Reproduce(a) => reproduce::run(a),
        Command::Serve(a) => serve::run(a),
        Command::Bag(a) => bag::run(a),
    }
}
