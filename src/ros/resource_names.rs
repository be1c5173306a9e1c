//! ROS 2 names and command-line arguments as rcl reads them, so the node
//! fits a fleet: `mcgnode serve --ros-args -r __ns:=/robot1 -r __node:=dyn3
//! -r particle_state:=/tracker/state -p horizon:=20 --params-file f.yaml
//! --log-level debug`.
//!
//! - A name is absolute (`/a/b`), relative to the node's namespace
//!   (`particle_state` → `/robot1/particle_state`) or private to the node
//!   (`~/rollout` → `/robot1/mcgnode/rollout`).
//! - A remap `from:=to` (both expanded first) replaces a name that expands to
//!   `from`; `node:from:=to` applies only to the node named `node`.
//! - `__ns:=` and `__node:=` set the namespace and the node's name.

use std::path::PathBuf;

use ros2_client::log::LogLevel;

/// The node's default name, also the key of its section in parameter files.
pub const NODE_NAME: &str = "mcgnode";

/// Why a name or a ROS argument was refused; each says what is accepted.
#[derive(Debug, thiserror::Error)]
pub enum NameError {
    /// Not a ROS 2 name.
    #[error(
        "{0:?} is not a ROS 2 name: tokens of letters, digits and _ (not starting with a \
         digit, no __) separated by single slashes; absolute (/a/b), relative (a/b) or \
         private (~/a)"
    )]
    Invalid(String),
    /// A namespace that is not absolute.
    #[error("namespace {0:?} must be absolute, like /robot1")]
    Namespace(String),
    /// A node name that is not one token.
    #[error("node name {0:?} must be one token of letters, digits and _ (like dyn3)")]
    Node(String),
    /// An argument `--ros-args` does not know, or one mcgnode does not support.
    #[error(
        "--ros-args: {0}; supported: -r/--remap FROM:=TO (also __ns:=, __node:=, \
         NODE:FROM:=TO), -p/--param NAME:=VALUE, --params-file FILE, --log-level LEVEL"
    )]
    Argument(String),
}

crate::error::typed_errors!(NameError);

/// The node's names: namespace, node name and remaps.
#[derive(Clone, Debug, PartialEq)]
pub struct Names {
    namespace: String,
    node: String,
    /// Expanded `from` → expanded `to`.
    remaps: Vec<(String, String)>,
}

impl Default for Names {
    fn default() -> Self {
        Names {
            namespace: "/".into(),
            node: NODE_NAME.into(),
            remaps: Vec::new(),
        }
    }
}

/// Whether `t` is one name token.
fn is_token(t: &str) -> bool {
    !t.is_empty()
        && !t.starts_with(|c: char| c.is_ascii_digit())
        && !t.contains("__")
        && t.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Whether `s` is a ROS 2 name: absolute, relative, or private (`~`, `~/a`).
pub fn is_ros_name(s: &str) -> bool {
    let rest = if let Some(r) = s.strip_prefix("~/") {
        r
    } else if s == "~" {
        return true;
    } else {
        s.strip_prefix('/').unwrap_or(s)
    };
    !rest.is_empty() && rest.split('/').all(is_token)
}

impl Names {
    /// The names of a node called `node` in `namespace`, with `remaps`
    /// (`from`, `to`, and the node a rule is limited to).
    pub fn new(
        namespace: &str,
        node: &str,
        remaps: &[(Option<String>, String, String)],
    ) -> Result<Names, NameError> {
        let ns = if namespace.len() > 1 {
            namespace.trim_end_matches('/')
        } else {
            namespace
        };
        if !(ns == "/" || (ns.starts_with('/') && is_ros_name(ns))) {
            return Err(NameError::Namespace(namespace.into()));
        }
        if !is_token(node) {
            return Err(NameError::Node(node.into()));
        }
        let mut names = Names {
            namespace: ns.into(),
            node: node.into(),
            remaps: Vec::new(),
        };
        let mut rules = Vec::new();
        for (only, from, to) in remaps {
            if only.as_deref().is_some_and(|n| n != NODE_NAME && n != node) {
                continue;
            }
            rules.push((names.expand(from)?, names.expand(to)?));
        }
        names.remaps = rules;
        Ok(names)
    }

    /// The namespace (`/` or `/a/b`).
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// The node's name.
    pub fn node(&self) -> &str {
        &self.node
    }

    /// The node's fully qualified name (`/mcgnode`, `/robot1/mcgnode`).
    pub fn fqn(&self) -> String {
        self.join(&self.namespace, &self.node)
    }

    fn join(&self, base: &str, rest: &str) -> String {
        if base == "/" {
            format!("/{rest}")
        } else {
            format!("{base}/{rest}")
        }
    }

    /// `name` made absolute: `~` is the node, a relative name is in the
    /// namespace.
    pub fn expand(&self, name: &str) -> Result<String, NameError> {
        if !is_ros_name(name) {
            return Err(NameError::Invalid(name.into()));
        }
        Ok(if name == "~" {
            self.fqn()
        } else if let Some(rest) = name.strip_prefix("~/") {
            self.join(&self.fqn(), rest)
        } else if name.starts_with('/') {
            name.into()
        } else {
            self.join(&self.namespace, name)
        })
    }

    /// `name` expanded, then remapped by the first rule that matches.
    pub fn resolve(&self, name: &str) -> Result<String, NameError> {
        let full = self.expand(name)?;
        Ok(self
            .remaps
            .iter()
            .find(|(from, _)| *from == full)
            .map_or(full, |(_, to)| to.clone()))
    }
}

/// What `--ros-args` said.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RosArgs {
    /// `-r __ns:=NS`.
    pub namespace: Option<String>,
    /// `-r __node:=NAME`.
    pub node: Option<String>,
    /// `-r [NODE:]FROM:=TO`, in order.
    pub remaps: Vec<(Option<String>, String, String)>,
    /// `-p NAME:=VALUE`, in order (the value as YAML text).
    pub params: Vec<(String, String)>,
    /// `--params-file FILE`, in order.
    pub params_files: Vec<PathBuf>,
    /// `--log-level [NAME:=]LEVEL`.
    pub log_level: Option<LogLevel>,
}

/// A log level's name as rcl takes it (any case).
fn log_level(s: &str) -> Option<LogLevel> {
    Some(match s.to_ascii_lowercase().as_str() {
        "debug" => LogLevel::Debug,
        "info" => LogLevel::Info,
        "warn" | "warning" => LogLevel::Warn,
        "error" => LogLevel::Error,
        "fatal" => LogLevel::Fatal,
        _ => return None,
    })
}

/// The severity of `level` as rcl numbers it (higher is more severe).
pub fn severity(level: LogLevel) -> u8 {
    match level {
        LogLevel::Debug => 10,
        LogLevel::Info => 20,
        LogLevel::Warn => 30,
        LogLevel::Error => 40,
        LogLevel::Fatal => 50,
    }
}

impl RosArgs {
    /// Parses what follows `--ros-args` (further `--ros-args` are accepted
    /// and ignored; a lone `--` ends them, and nothing may follow it).
    pub fn parse(args: &[String]) -> Result<RosArgs, NameError> {
        let bad = |m: String| Err(NameError::Argument(m));
        let mut out = RosArgs::default();
        let mut it = args.iter();
        while let Some(a) = it.next() {
            let mut value = |flag: &str| {
                it.next()
                    .cloned()
                    .ok_or_else(|| NameError::Argument(format!("{flag} needs a value")))
            };
            match a.as_str() {
                "--ros-args" => {}
                // `--` ends a `--ros-args` block; rcl allows another after it.
                "--" => match it.next() {
                    None => {}
                    Some(next) if next == "--ros-args" => {}
                    Some(extra) => return bad(format!("unexpected {extra:?} after --")),
                },
                "-r" | "--remap" => {
                    let rule = value(a)?;
                    let Some((lhs, to)) = rule.split_once(":=") else {
                        return bad(format!("remap {rule:?} is not FROM:=TO"));
                    };
                    let (only, from) = match lhs.split_once(':') {
                        Some((n, f)) => (Some(n.to_string()), f),
                        None => (None, lhs),
                    };
                    match from {
                        "__ns" => out.namespace = Some(to.into()),
                        "__node" | "__name" => out.node = Some(to.into()),
                        _ if from.starts_with("__") => {
                            return bad(format!("remap of {from} is not supported"))
                        }
                        _ => out.remaps.push((only, from.into(), to.into())),
                    }
                }
                "-p" | "--param" => {
                    let p = value(a)?;
                    let Some((name, v)) = p.split_once(":=") else {
                        return bad(format!("parameter {p:?} is not NAME:=VALUE"));
                    };
                    out.params.push((name.into(), v.into()));
                }
                "--params-file" => out.params_files.push(value(a)?.into()),
                "--log-level" => {
                    let l = value(a)?;
                    // `NAME:=LEVEL` sets a logger's level; ours is the node's.
                    let level = l.rsplit(":=").next().unwrap_or(&l);
                    out.log_level = Some(log_level(level).ok_or_else(|| {
                        NameError::Argument(format!(
                            "log level {level:?}; one of debug, info, warn, error, fatal"
                        ))
                    })?);
                }
                other => {
                    return bad(format!(
                        "{other:?} is not supported by mcgnode serve (rcl's enclaves, log \
                         files and configs, external loggers have no meaning here)"
                    ))
                }
            }
        }
        Ok(out)
    }

    /// The node's names from these arguments.
    pub fn names(&self) -> Result<Names, NameError> {
        Names::new(
            self.namespace.as_deref().unwrap_or("/"),
            self.node.as_deref().unwrap_or(NODE_NAME),
            &self.remaps,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn names_resolve_as_rcl_resolves_them() {
        let d = Names::default();
        assert_eq!(d.resolve("particle_state").unwrap(), "/particle_state");
        assert_eq!(d.resolve("~/rollout").unwrap(), "/mcgnode/rollout");
        assert_eq!(d.resolve("/diagnostics").unwrap(), "/diagnostics");
        let r = RosArgs::parse(&args(
            "-r __ns:=/robot1 -r particle_state:=/tracker/state -r other:a:=b -p horizon:=20",
        ))
        .unwrap();
        let n = r.names().unwrap();
        assert_eq!(n.fqn(), "/robot1/mcgnode");
        assert_eq!(n.resolve("particle_state").unwrap(), "/tracker/state");
        assert_eq!(
            n.resolve("~/predicted_trajectory").unwrap(),
            "/robot1/mcgnode/predicted_trajectory"
        );
        assert_eq!(
            n.resolve("a").unwrap(),
            "/robot1/a",
            "a rule for another node"
        );
        assert_eq!(r.params, vec![("horizon".into(), "20".into())]);
        let n = RosArgs::parse(&args("-r __node:=dyn3"))
            .unwrap()
            .names()
            .unwrap();
        assert_eq!(
            n.resolve("~/predicted_trajectory").unwrap(),
            "/dyn3/predicted_trajectory"
        );
        // A rule naming the node by its default name still applies after a rename.
        let n = RosArgs::parse(&args("-r __node:=dyn3 -r mcgnode:~/rollout:=/r"))
            .unwrap()
            .names()
            .unwrap();
        assert_eq!(n.resolve("~/rollout").unwrap(), "/r");
        // Two `--ros-args … --` blocks, as rcl takes them.
        let r = RosArgs::parse(&args(
            "--ros-args -r __ns:=/a -- --ros-args -p horizon:=3 --",
        ))
        .unwrap();
        assert_eq!(r.namespace.as_deref(), Some("/a"));
        assert_eq!(r.params, vec![("horizon".into(), "3".into())]);
    }

    #[test]
    fn bad_arguments_say_what_is_supported() {
        for (a, want) in [
            ("-r __ns:=robot1", "must be absolute"),
            ("-r __node:=a/b", "one token"),
            ("-r x", "not FROM:=TO"),
            ("-p horizon", "not NAME:=VALUE"),
            ("--enclave /e", "not supported"),
            ("--log-level loud", "one of debug"),
            ("-r", "needs a value"),
            ("-r a:=b -- extra", "after --"),
            ("-r 9a:=b", "not a ROS 2 name"),
        ] {
            let e = RosArgs::parse(&args(a))
                .and_then(|r| r.names())
                .unwrap_err()
                .to_string();
            assert!(e.contains(want), "{a}: {e}");
        }
        let r = RosArgs::parse(&args("--log-level mcgnode:=WARN --params-file f.yaml --")).unwrap();
        assert_eq!(r.log_level.map(severity), Some(30));
        assert_eq!(r.params_files, vec![PathBuf::from("f.yaml")]);
    }
}
