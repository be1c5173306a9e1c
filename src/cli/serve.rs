//! `mcgnode serve`: the ROS 2 node's options, parsed into its parameters.

use std::path::{Path, PathBuf};

use crate::ros::resource_names::{NameError, RosArgs};
use crate::ros::{domain_id_from_env, serve, NodeParams, ParamError};

/// Options of `mcgnode serve`.
#[derive(clap::Args, Debug, Clone)]
pub struct ServeArgs {
    /// Parameter file in the ROS 2 format (`mcgnode: ros__parameters: ...`);
    /// see launch_params/.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Model to serve (overrides the `model` parameter): a trained model file,
    /// or `truth:spring` / `truth:pendulum` for the ground-truth physics.
    #[arg(long)]
    pub model: Option<String>,
    /// Override one parameter, `key=value` (repeatable; applied after --params).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Print the effective parameters as a parameter file and exit.
    #[arg(long)]
    pub print_params: bool,
    /// ROS 2 arguments, as rcl takes them, to the end of the command line:
    /// `-r __ns:=/robot1`, `-r __node:=NAME`, `-r FROM:=TO`, `-p NAME:=VALUE`,
    /// `--params-file FILE` (repeatable), `--log-level LEVEL`. Applied after
    /// --params and --set; others are refused with the reason.
    #[arg(long = "ros-args", num_args = 0.., allow_hyphen_values = true, value_name = "ARG")]
    pub ros_args: Option<Vec<String>>,
}

/// Runs the node until SIGINT/SIGTERM.
pub fn run(args: ServeArgs) -> anyhow::Result<()> {
    // The library's errors, converted once (as every subcommand reports them).
    Ok(run_node(args)?)
}

fn run_node(args: ServeArgs) -> crate::error::Result<()> {
    let params = effective_params(&args)?;
    if args.print_params {
        print!("{}", params.to_yaml());
        return Ok(());
    }
    let ros = ros_args(&args)?;
    let reference: crate::models::ModelRef = params.model.parse()?;
    let model = crate::models::load_model(&reference)?;
    let domain_id = domain_id_from_env()?;
    let file = reference.file().map(Path::to_path_buf);
    serve(params, &ros, (model, file), domain_id)
}

/// What follows `--ros-args`.
pub fn ros_args(args: &ServeArgs) -> Result<RosArgs, NameError> {
    RosArgs::parse(args.ros_args.as_deref().unwrap_or_default())
}

/// Parameters from the file, `--set` overrides, `--ros-args` (parameter
/// files, `-p`) and `--model`, in that order.
pub fn effective_params(args: &ServeArgs) -> Result<NodeParams, ParamError> {
    let ros = ros_args(args)?;
    let mut p = NodeParams::load_with(args.params.as_deref(), &args.set, &ros)?;
    if let Some(m) = &args.model {
        p.model.clone_from(m);
    }
    if p.model.is_empty() {
        return Err(ParamError::NoModel);
    }
    Ok(p)
}
