//! The `mcgnode` command line: one subcommand per step of the pipeline.

mod bag;
mod bench;
// Public: the types of `train::Args`' fields.
pub mod choices;
mod demo;
mod evaluate;
mod field;
mod import;
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

use std::ffi::OsString;

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

/// As every ROS 2 executable, `mcgnode` with no arguments, or with `--ros-args
/// …` first (what `ros2 run mcgnode mcgnode --ros-args …` and a launch file's
/// `Node(package='mcgnode', executable='mcgnode')` pass), runs the node: it is
/// read as `mcgnode serve --ros-args …`. Every subcommand stays as it is.
/// Public so that tests parse documented commands as the binary does.
pub fn ros_native_argv<T: Into<OsString>>(args: impl IntoIterator<Item = T>) -> Vec<OsString> {
    let mut argv: Vec<OsString> = args.into_iter().map(Into::into).collect();
    match argv.get(1) {
        None => argv.push("serve".into()),
        Some(first) if first == "--ros-args" => argv.insert(1, "serve".into()),
        Some(_) => {}
    }
    argv
}

/// Parses the command line and runs the subcommand.
pub fn run() -> anyhow::Result<()> {
    crate::alloc::prepare_for_candle();
    let cli = Cli::parse_from(ros_native_argv(std::env::args_os()));
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

#[cfg(test)]
mod tests {
    use super::*;

    fn argv(a: &[&str]) -> Vec<String> {
        ros_native_argv(a.iter().copied())
            .into_iter()
            .map(|s| s.into_string().unwrap())
            .collect()
    }

    #[test]
    fn ros_2_style_starts_serve_the_node() {
        assert_eq!(argv(&["mcgnode"]), ["mcgnode", "serve"]);
        assert_eq!(
            argv(&["mcgnode", "--ros-args", "-r", "__ns:=/robot1"]),
            ["mcgnode", "serve", "--ros-args", "-r", "__ns:=/robot1"]
        );
        let cli = Cli::parse_from(ros_native_argv(
            [
                "mcgnode",
                "--ros-args",
                "-r",
                "__ns:=/robot1",
                "--params-file",
                "f.yaml",
            ]
            .map(OsString::from),
        ));
        let Command::Serve(s) = cli.command else {
            panic!("not serve")
        };
        let ros = serve::ros_args(&s).unwrap();
        assert_eq!(ros.namespace.as_deref(), Some("/robot1"));
        assert_eq!(ros.params_files.len(), 1);
    }

    #[test]
    fn subcommands_and_flags_are_left_as_they_are() {
        for a in [
            &["mcgnode", "serve", "--ros-args"][..],
            &["mcgnode", "--help"],
            &["mcgnode", "train", "--data", "b.mcap"],
        ] {
            assert_eq!(argv(a), a);
        }
    }
}
