//! Where the node's parameters come from, in order: defaults, a ROS 2
//! parameter file (`mcgnode: ros__parameters: {...}`), `--set key=value`
//! overrides, then `--ros-args` (`--params-file`, `-p`). Unknown keys and
//! ill-typed or out-of-range values are rejected before the node starts, with
//! a message naming the key, what was given and what is expected (each value
//! checked by [`NodeParams::set`]).

use std::path::Path;

use super::params::{NodeParams, ParamError};
use super::resource_names::{Names, NODE_NAME};
use super::yaml::{self, Scalar, Value};

/// Keys of a parameter file section that are this node's, as rcl matches
/// them: `/**`, `**`, `/**/NAME`, the node's name, and its fully qualified
/// name with or without the leading slash; the default name too (the shipped
/// files use `mcgnode:`).
fn is_our_section(key: &str, names: &Names) -> bool {
    let fqn = names.fqn();
    matches!(key, "/**" | "**")
        || key.trim_start_matches('/') == NODE_NAME
        || key.trim_start_matches('/') == names.node()
        || key.strip_prefix("/**/") == Some(names.node())
        || key == fqn
        || Some(key) == fqn.strip_prefix('/')
}

/// What a parameter file section for another node means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Others {
    /// An error (`--params`: the file is this node's).
    Refuse,
    /// Skipped (`--params-file`: one file may configure many nodes).
    Skip,
}

fn read_file(path: &Path) -> Result<String, ParamError> {
    std::fs::read_to_string(path).map_err(|source| ParamError::Read {
        path: path.to_path_buf(),
        source,
    })
}

impl NodeParams {
    /// Defaults, then the file (if any), then each `key=value` override in order.
    pub fn load(file: Option<&Path>, overrides: &[String]) -> Result<NodeParams, ParamError> {
        Self::load_with(file, overrides, &super::resource_names::RosArgs::default())
    }

    /// [`NodeParams::load`], then what `--ros-args` says: each
    /// `--params-file` in order (sections for other nodes skipped, as rcl
    /// does; a file with none for this node is an error), then each `-p`.
    pub fn load_with(
        file: Option<&Path>,
        overrides: &[String],
        ros: &super::resource_names::RosArgs,
    ) -> Result<NodeParams, ParamError> {
        let names = ros.names()?;
        let mut p = NodeParams::default();
        let in_file = |path: &Path, e: ParamError| ParamError::File {
            path: path.to_path_buf(),
            source: Box::new(e),
        };
        if let Some(path) = file {
            p.apply_sections(&read_file(path)?, &names, Others::Refuse)
                .map_err(|e| in_file(path, e))?;
        }
        for o in overrides {
            p.apply_override(o)?;
        }
        for path in &ros.params_files {
            let matched = p
                .apply_sections(&read_file(path)?, &names, Others::Skip)
                .map_err(|e| in_file(path, e))?;
            if matched == 0 {
                return Err(in_file(path, ParamError::NoSectionFor(names.fqn())));
            }
        }
        for (key, value) in &ros.params {
            p.set(key, &Scalar::parse_plain(value), true)
                .map_err(|e| ParamError::Override {
                    given: format!("-p {key}:={value}"),
                    source: Box::new(e),
                })?;
        }
        p.check_together()?;
        Ok(p)
    }

    /// The topic and service parameters as absolute names, resolved for
    /// `names` (namespace, node name, remaps) as rcl resolves them.
    pub fn resolved(&self, names: &Names) -> Result<NodeParams, ParamError> {
        let mut p = self.clone();
        for name in [
            &mut p.input_topic,
            &mut p.trajectory_topic,
            &mut p.forces_topic,
            &mut p.diagnostics_topic,
            &mut p.rollout_service,
            &mut p.markers_topic,
        ] {
            *name = names.resolve(name)?;
        }
        Ok(p)
    }

    /// Applies the contents of a ROS 2 parameter file.
    pub fn apply_file_text(&mut self, text: &str) -> Result<(), ParamError> {
        self.apply_sections(text, &Names::default(), Others::Refuse)
            .map(|_| ())
    }

    /// Applies the sections of a parameter file that are this node's;
    /// returns how many there were.
    fn apply_sections(
        &mut self,
        text: &str,
        names: &Names,
        others: Others,
    ) -> Result<usize, ParamError> {
        let Value::Map(top) = yaml::parse(text)? else {
            return Err(ParamError::NotAMapping);
        };
        if top.is_empty() {
            return Err(ParamError::NoSection);
        }
        let mut matched = 0;
        for (node, section) in &top {
            if !is_our_section(node, names) {
                if others == Others::Skip {
                    continue;
                }
                return Err(ParamError::OtherNode(node.clone()));
            }
            matched += 1;
            let Value::Map(entries) = section else {
                return Err(ParamError::NoRosParameters(node.clone()));
            };
            for (k, v) in entries {
                if k != "ros__parameters" {
                    return Err(ParamError::UnexpectedKey {
                        node: node.clone(),
                        key: k.clone(),
                    });
                }
                let mut flat = Vec::new();
                flatten("", v, &mut flat);
                for (key, value) in flat {
                    self.set(&key, &value, false)?;
                }
            }
        }
        Ok(matched)
    }

    /// Applies one `key=value` command-line override.
    pub fn apply_override(&mut self, kv: &str) -> Result<(), ParamError> {
        let (k, v) = kv
            .split_once('=')
            .ok_or_else(|| ParamError::NotKeyValue(kv.to_string()))?;
        self.set(k.trim(), &Scalar::parse_plain(v), true)
            .map_err(|e| ParamError::Override {
                given: kv.to_string(),
                source: Box::new(e),
            })
    }
}

/// Nested mappings under `ros__parameters` become dotted names, as in ROS 2.
fn flatten(prefix: &str, v: &Value, out: &mut Vec<(String, Scalar)>) {
    match v {
        Value::Scalar(s) => out.push((prefix.to_string(), s.clone())),
        Value::Map(m) => {
            for (k, v) in m {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, v, out);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_then_overrides() {
        let mut p = NodeParams::default();
        p.apply_file_text(
            "mcgnode:\n  ros__parameters:\n    model: truth:pendulum\n    horizon: 20\n    \
             dt: 1\n    qos_reliable: false\n    input_topic: /robot/state\n",
        )
        .unwrap();
        assert_eq!(p.model, "truth:pendulum");
        assert_eq!(p.horizon, 20);
        assert_eq!(p.dt, 1.0);
        assert!(!p.qos_reliable);
        assert_eq!(p.input_topic, "/robot/state");
        p.apply_override("horizon=7").unwrap();
        p.apply_override("record_dir=123").unwrap();
        assert_eq!(p.horizon, 7);
        assert_eq!(p.record_dir, "123");
    }

    #[test]
    fn every_spec_round_trips_through_to_yaml() {
        let mut p = NodeParams {
            horizon: 3,
            dt: 0.25,
            record_dir: "/tmp/x".into(),
            accuracy_lead_times: vec![0.1, 0.5, 1.0],
            accuracy_warn_re: 0.02,
            accuracy_retrain: true,
            accuracy_retrain_epochs: 7,
            ..NodeParams::default()
        };
        p.qos_reliable = false;
        let mut q = NodeParams::default();
        q.apply_file_text(&p.to_yaml()).unwrap();
        assert_eq!(p, q);
    }

    #[test]
    fn rejects_unknown_ill_typed_and_out_of_range() {
        for (text, want) in [
            (
                "mcgnode:\n  ros__parameters:\n    horizn: 5\n",
                "unknown parameter \"horizn\"",
            ),
            (
                "mcgnode:\n  ros__parameters:\n    horizon: 2.5\n",
                "must be an integer",
            ),
            (
                "mcgnode:\n  ros__parameters:\n    horizon: 0\n",
                "outside 1..=",
            ),
            (
                "mcgnode:\n  ros__parameters:\n    dt: fast\n",
                "must be a number",
            ),
            (
                "mcgnode:\n  ros__parameters:\n    dt: -1\n",
                "must be finite and > 0",
            ),
            (
                "mcgnode:\n  ros__parameters:\n    qos_reliable: 1\n",
                "true or false",
            ),
            (
                "mcgnode:\n  ros__parameters:\n    model: 5\n",
                "must be a string",
            ),
            (
                "mcgnode:\n  ros__parameters:\n    input_topic: x y\n",
                "is not a ROS 2 name",
            ),
            ("other:\n  ros__parameters:\n    dt: 1.0\n", "another node"),
            ("mcgnode:\n  params:\n    dt: 1.0\n", "only ros__parameters"),
            (
                "mcgnode:\n  ros__parameters:\n    a:\n      b: 1\n",
                "unknown parameter \"a.b\"",
            ),
        ] {
            let e = NodeParams::default()
                .apply_file_text(text)
                .unwrap_err()
                .to_string();
            assert!(e.contains(want), "{text:?}: {e}");
        }
        for (set, want) in [
            ("accuracy_lead_times=0.5", "must be a list"),
            (
                "accuracy_lead_times=[0.1, -1]",
                "entry -1 must be finite and > 0",
            ),
            ("accuracy_lead_times=[0.1, x]", "must be a list"),
        ] {
            let e = NodeParams::default()
                .apply_override(set)
                .unwrap_err()
                .to_string();
            assert!(e.contains(want), "{set}: {e}");
        }
        let mut p = NodeParams::default();
        p.apply_override("accuracy_lead_times=[0.1, 1]").unwrap();
        assert_eq!(p.accuracy_lead_times, vec![0.1, 1.0]);
        let e = NodeParams::default()
            .apply_override("horizon")
            .unwrap_err()
            .to_string();
        assert!(e.contains("key=value"), "{e}");
        let e = NodeParams::default()
            .apply_override("nope=1")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown parameter"), "{e}");
    }

    #[test]
    fn wildcard_and_slashed_sections_are_ours() {
        for head in ["/**", "/mcgnode", "mcgnode"] {
            let mut p = NodeParams::default();
            p.apply_file_text(&format!("{head}:\n  ros__parameters:\n    horizon: 9\n"))
                .unwrap();
            assert_eq!(p.horizon, 9, "{head}");
        }
    }

    #[test]
    fn ros_args_params_files_and_p_apply_in_order() {
        use super::super::resource_names::RosArgs;
        let dir = tempfile::tempdir().unwrap();
        let fleet = dir.path().join("fleet.yaml");
        std::fs::write(
            &fleet,
            "/robot1/mcgnode:\n  ros__parameters:\n    horizon: 7\n\
             /robot2/mcgnode:\n  ros__parameters:\n    horizon: 9\n\
             /**:\n  ros__parameters:\n    dt: 0.5\n",
        )
        .unwrap();
        let only1 = dir.path().join("only1.yaml");
        std::fs::write(
            &only1,
            "/robot1/mcgnode:\n  ros__parameters:\n    horizon: 7\n",
        )
        .unwrap();
        let load = |args: &[&str]| {
            let args: Vec<String> = args.iter().map(|a| (*a).to_string()).collect();
            NodeParams::load_with(None, &["horizon=3".into()], &RosArgs::parse(&args).unwrap())
        };
        let f = fleet.to_str().unwrap();
        let p = load(&["-r", "__ns:=/robot2", "--params-file", f, "-p", "dt:=0.25"]).unwrap();
        assert_eq!(
            (p.horizon, p.dt),
            (9, 0.25),
            "file over --set, -p over the file"
        );
        let p = load(&["-r", "__ns:=/robot3", "--params-file", f]).unwrap();
        assert_eq!(
            (p.horizon, p.dt),
            (3, 0.5),
            "only /** is for /robot3/mcgnode"
        );
        let e = load(&[
            "-r",
            "__ns:=/robot3",
            "--params-file",
            only1.to_str().unwrap(),
        ])
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("no section for this node (/robot3/mcgnode)"),
            "{e}"
        );
        let e = load(&["-p", "nope:=1"]).unwrap_err().to_string();
        assert!(
            e.contains("-p nope:=1") && e.contains("unknown parameter"),
            "{e}"
        );
        // Names resolve for the node's namespace.
        let names = RosArgs::parse(&["-r".into(), "__ns:=/robot2".into()])
            .unwrap()
            .names()
            .unwrap();
        let r = NodeParams::default().resolved(&names).unwrap();
        assert_eq!(r.input_topic, "/robot2/particle_state");
        assert_eq!(r.rollout_service, "/robot2/mcgnode/rollout");
        let d = NodeParams::default().resolved(&Names::default()).unwrap();
        assert_eq!(
            d.trajectory_topic, "/mcgnode/predicted_trajectory",
            "unchanged by default"
        );
    }
}
