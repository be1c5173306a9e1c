//! ROS 2 parameter files (nested mappings of scalars), read with the YAML 1.2
//! crate `yaml-rust2` and handed to [`super::params`] as [`Value`]s. Scalars are
//! typed by YAML 1.2's core schema (as rcl types them); lists of scalars are
//! one value (a ROS array parameter); what parameter files do not use here
//! (nested lists, lists of mappings, non-string keys) is an error naming the
//! key; anchors and aliases are resolved by the crate.

use std::fmt;

/// Why a parameter file is not one document of nested mappings of scalars.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum YamlError {
    /// Not YAML.
    #[error("line {line}: {info}")]
    Syntax {
        /// 1-based line of the error.
        line: usize,
        /// The parser's description.
        info: String,
    },
    /// Several documents (`---`).
    #[error("{0} YAML documents; a parameter file has one")]
    Documents(usize),
    /// Valid YAML that parameter files do not use, at `path`.
    #[error("{}: {what}", if path.is_empty() { "the top level" } else { path.as_str() })]
    Unsupported {
        /// Dotted key path ("" for the top level).
        path: String,
        /// What is wrong there.
        what: String,
    },
}

crate::error::typed_errors!(YamlError);

use yaml_rust2::{Yaml, YamlLoader};

/// A parsed YAML scalar, typed the way YAML 1.2's core schema (and rcl) types it.
#[derive(Clone, Debug, PartialEq)]
pub enum Scalar {
    /// `true` / `false` (also `True`, `FALSE`, ...).
    Bool(bool),
    /// An integer literal.
    Int(i64),
    /// A float literal (`1.5`, `1e-3`, `.inf`, `.nan`).
    Float(f64),
    /// Anything else, or any quoted text.
    Str(String),
    /// `~`, `null` or an empty value.
    Null,
    /// A list of scalars (`[0.1, 0.5]`), a ROS array parameter.
    List(Vec<Scalar>),
}

impl Scalar {
    /// YAML's name of the type, for error messages.
    pub fn type_name(&self) -> &'static str {
        match self {
            Scalar::Bool(_) => "bool",
            Scalar::Int(_) => "integer",
            Scalar::Float(_) => "double",
            Scalar::Str(_) => "string",
            Scalar::Null => "null",
            Scalar::List(_) => "list",
        }
    }

    /// Types an unquoted scalar (a `--set` value) as the YAML crate types a
    /// plain scalar.
    pub fn parse_plain(text: &str) -> Scalar {
        let text = text.trim();
        // A flow list (`[0.1, 0.5]`) needs the full parser.
        if text.starts_with('[') {
            if let Ok(docs) = YamlLoader::load_from_str(text) {
                if let [Yaml::Array(items)] = docs.as_slice() {
                    if let Some(list) = items.iter().map(scalar).collect() {
                        return Scalar::List(list);
                    }
                }
            }
        }
        match scalar(&Yaml::from_str(text)) {
            Some(s) => s,
            None => Scalar::Str(text.to_string()),
        }
    }
}

impl fmt::Display for Scalar {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Scalar::Bool(b) => write!(f, "{b}"),
            Scalar::Int(i) => write!(f, "{i}"),
            Scalar::Float(x) => write!(f, "{x}"),
            Scalar::Str(s) => write!(f, "{s:?}"),
            Scalar::Null => f.write_str("null"),
            Scalar::List(items) => {
                let items: Vec<String> = items.iter().map(ToString::to_string).collect();
                write!(f, "[{}]", items.join(", "))
            }
        }
    }
}

/// A YAML node of a parameter file: a scalar or a mapping (keys in file order).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A leaf.
    Scalar(Scalar),
    /// A mapping.
    Map(Vec<(String, Value)>),
}

/// The scalar a YAML node is, if it is one.
fn scalar(y: &Yaml) -> Option<Scalar> {
    Some(match y {
        Yaml::Boolean(b) => Scalar::Bool(*b),
        Yaml::Integer(i) => Scalar::Int(*i),
        Yaml::Real(_) => Scalar::Float(y.as_f64()?),
        Yaml::String(s) => Scalar::Str(s.clone()),
        Yaml::Null => Scalar::Null,
        _ => return None,
    })
}

/// Parses a parameter file: one document of nested mappings of scalars (an
/// empty document is an empty mapping). Syntax errors name the line; nested
/// lists, aliases and non-string keys name the key.
pub fn parse(text: &str) -> Result<Value, YamlError> {
    let docs = YamlLoader::load_from_str(text).map_err(|e| YamlError::Syntax {
        line: e.marker().line(),
        info: e.info().to_string(),
    })?;
    match docs.as_slice() {
        [] => Ok(Value::Map(vec![])),
        [doc] => convert(doc, ""),
        _ => Err(YamlError::Documents(docs.len())),
    }
}

fn convert(y: &Yaml, path: &str) -> Result<Value, YamlError> {
    let at = |what: &str| YamlError::Unsupported {
        path: path.to_string(),
        what: what.to_string(),
    };
    match y {
        Yaml::Hash(h) => {
            let mut out = Vec::with_capacity(h.len());
            for (k, v) in h {
                let key = match k {
                    Yaml::String(s) => s.clone(),
                    other => match scalar(other) {
                        Some(s) => return Err(at(&format!("key {s} is not a string"))),
                        None => return Err(at("a key is not a string")),
                    },
                };
                let sub = if path.is_empty() {
                    key.clone()
                } else {
                    format!("{path}.{key}")
                };
                out.push((key, convert(v, &sub)?));
            }
            Ok(Value::Map(out))
        }
        Yaml::Array(items) => items
            .iter()
            .map(|y| match y {
                Yaml::Array(_) | Yaml::Hash(_) => None,
                other => scalar(other),
            })
            .collect::<Option<Vec<_>>>()
            .map(|list| Value::Scalar(Scalar::List(list)))
            .ok_or_else(|| at("only lists of scalars are supported in parameter files")),
        Yaml::Alias(_) => Err(at("aliases are not supported in parameter files")),
        Yaml::BadValue => Err(at("not a YAML value")),
        other => Ok(Value::Scalar(
            scalar(other).ok_or_else(|| at("not a scalar"))?,
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn get<'a>(v: &'a Value, path: &[&str]) -> Option<&'a Value> {
        path.iter().try_fold(v, |v, k| match v {
            Value::Map(m) => m.iter().find(|(key, _)| key == k).map(|(_, v)| v),
            Value::Scalar(_) => None,
        })
    }

    #[test]
    fn parses_a_ros2_parameter_file() {
        let v = parse(
            "# comment\n/mcgnode:\n  ros__parameters:\n    model: \"truth:spring\" # why\n    \
             horizon: 100\n    dt: 1e-3\n    reliable: True\n    topic: /a/b\n    empty: ''\n    \
             hash: 'a # b'\n    nested:\n      x: -2\n",
        )
        .unwrap();
        let p = ["/mcgnode", "ros__parameters"];
        let s = |k: &str| match get(&v, &[p[0], p[1], k]) {
            Some(Value::Scalar(s)) => s.clone(),
            other => panic!("{k}: {other:?}"),
        };
        assert_eq!(s("model"), Scalar::Str("truth:spring".into()));
        assert_eq!(s("horizon"), Scalar::Int(100));
        assert_eq!(s("dt"), Scalar::Float(1e-3));
        assert_eq!(s("reliable"), Scalar::Bool(true));
        assert_eq!(s("topic"), Scalar::Str("/a/b".into()));
        assert_eq!(s("empty"), Scalar::Str(String::new()));
        assert_eq!(s("hash"), Scalar::Str("a # b".into()));
        assert_eq!(
            get(&v, &[p[0], p[1], "nested", "x"]),
            Some(&Value::Scalar(Scalar::Int(-2)))
        );
    }

    #[test]
    fn typing_follows_yaml_core_schema() {
        assert_eq!(Scalar::parse_plain("0.5"), Scalar::Float(0.5));
        assert_eq!(Scalar::parse_plain("-3"), Scalar::Int(-3));
        assert_eq!(Scalar::parse_plain("inf"), Scalar::Str("inf".into()));
        assert!(matches!(Scalar::parse_plain(".nan"), Scalar::Float(x) if x.is_nan()));
        assert_eq!(Scalar::parse_plain("1.2.3"), Scalar::Str("1.2.3".into()));
        assert_eq!(Scalar::parse_plain("~"), Scalar::Null);
        let list = Scalar::List(vec![Scalar::Float(0.1), Scalar::Int(1)]);
        assert_eq!(Scalar::parse_plain("[0.1, 1]"), list);
        assert_eq!(list.to_string(), "[0.1, 1]");
        assert_eq!(Scalar::parse_plain("[]"), Scalar::List(vec![]));
        let v = parse("a: [0.5, 2]\nb: []\n").unwrap();
        assert_eq!(
            v,
            Value::Map(vec![
                (
                    "a".into(),
                    Value::Scalar(Scalar::List(vec![Scalar::Float(0.5), Scalar::Int(2)]))
                ),
                ("b".into(), Value::Scalar(Scalar::List(vec![]))),
            ])
        );
    }

    #[test]
    fn rejects_what_it_does_not_support_with_the_line() {
        for (text, want) in [
            ("a:\n  - [1]\n", "a: only lists of scalars"),
            ("a:\n  b: [1, {c: 2}]\n", "a.b: only lists of scalars"),
            ("a: 1\na: 2\n", "duplicated key"),
            ("a:\n    b: 1\n  c: 2\n", "line 3"),
            ("a: \"open\n", "quoted scalar"),
            ("a:\n\tb: 1\n", "line 2"),
            ("1: x\n", "key 1 is not a string"),
        ] {
            let e = parse(text).unwrap_err().to_string();
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }
}
