//! The small YAML subset that ROS 2 parameter files use: nested block mappings
//! of scalars, comments, quoted strings. No YAML crate is among our
//! dependencies, and parameter files need no more than this; anything outside
//! the subset (lists, anchors, multi-line strings) is an error naming the line.

use std::fmt;

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
        }
    }

    /// Types an unquoted scalar (quoted ones are always strings).
    pub fn parse_plain(text: &str) -> Scalar {
        let t = text.trim();
        match t {
            "" | "~" | "null" | "Null" | "NULL" => return Scalar::Null,
            "true" | "True" | "TRUE" => return Scalar::Bool(true),
            "false" | "False" | "FALSE" => return Scalar::Bool(false),
            ".inf" | ".Inf" | ".INF" | "+.inf" | "+.Inf" | "+.INF" => {
                return Scalar::Float(f64::INFINITY)
            }
            "-.inf" | "-.Inf" | "-.INF" => return Scalar::Float(f64::NEG_INFINITY),
            ".nan" | ".NaN" | ".NAN" => return Scalar::Float(f64::NAN),
            _ => {}
        }
        let digits = t.strip_prefix(['+', '-']).unwrap_or(t);
        if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
            if let Ok(i) = t.parse::<i64>() {
                return Scalar::Int(i);
            }
        }
        // Only things that look like numbers: Rust also parses "inf" and "NaN",
        // which YAML treats as strings.
        let numeric = digits
            .bytes()
            .all(|b| b.is_ascii_digit() || matches!(b, b'.' | b'e' | b'E' | b'+' | b'-'))
            && digits.bytes().any(|b| b.is_ascii_digit());
        if numeric {
            if let Ok(f) = t.parse::<f64>() {
                return Scalar::Float(f);
            }
        }
        Scalar::Str(t.to_string())
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
        }
    }
}

/// A YAML node in the subset: a scalar or a mapping (keys kept in file order).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A leaf.
    Scalar(Scalar),
    /// A block mapping.
    Map(Vec<(String, Value)>),
}

/// One meaningful line: indentation, key, and the text after the colon.
struct Line<'a> {
    no: usize,
    indent: usize,
    key: String,
    rest: &'a str,
}

/// Parses a document of nested block mappings of scalars.
pub fn parse(text: &str) -> Result<Value, String> {
    let mut lines = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let no = i + 1;
        let content = strip_comment(raw);
        if content.trim().is_empty() || content.trim() == "---" {
            continue;
        }
        if content.trim() == "..." {
            break;
        }
        let lead = &raw[..raw.len() - raw.trim_start().len()];
        if lead.contains('\t') {
            return Err(format!("line {no}: tabs are not allowed for indentation"));
        }
        let indent = content.len() - content.trim_start().len();
        let body = content.trim();
        if body.starts_with("- ") || body == "-" {
            return Err(format!(
                "line {no}: lists are not supported in parameter files"
            ));
        }
        let (key, rest) = split_key(body)
            .ok_or_else(|| format!("line {no}: expected `key: value`, found {:?}", body.trim()))?;
        lines.push(Line {
            no,
            indent,
            key,
            rest,
        });
    }
    let mut pos = 0;
    let root = parse_map(&lines, &mut pos, 0)?;
    if let Some(l) = lines.get(pos) {
        return Err(format!("line {}: unexpected indentation", l.no));
    }
    Ok(root)
}

/// Parses consecutive lines at exactly `indent` into a mapping.
fn parse_map(lines: &[Line], pos: &mut usize, indent: usize) -> Result<Value, String> {
    let mut entries: Vec<(String, Value)> = Vec::new();
    while let Some(l) = lines.get(*pos) {
        if l.indent < indent {
            break;
        }
        if l.indent > indent {
            return Err(format!("line {}: unexpected indentation", l.no));
        }
        if entries.iter().any(|(k, _)| *k == l.key) {
            return Err(format!("line {}: duplicate key {:?}", l.no, l.key));
        }
        *pos += 1;
        let value = if l.rest.trim().is_empty() {
            match lines.get(*pos) {
                Some(next) if next.indent > indent => parse_map(lines, pos, next.indent)?,
                _ => Value::Scalar(Scalar::Null),
            }
        } else {
            Value::Scalar(parse_scalar(l.rest, l.no)?)
        };
        entries.push((l.key.clone(), value));
    }
    Ok(Value::Map(entries))
}

/// Parses the text after `key:` (a plain or quoted scalar).
fn parse_scalar(text: &str, no: usize) -> Result<Scalar, String> {
    let t = text.trim();
    if let Some(inner) = t.strip_prefix('"') {
        let inner = inner
            .strip_suffix('"')
            .ok_or_else(|| format!("line {no}: unterminated double-quoted string"))?;
        return unescape_double(inner).map_err(|e| format!("line {no}: {e}"));
    }
    if let Some(inner) = t.strip_prefix('\'') {
        let inner = inner
            .strip_suffix('\'')
            .ok_or_else(|| format!("line {no}: unterminated single-quoted string"))?;
        return Ok(Scalar::Str(inner.replace("''", "'")));
    }
    if t.starts_with(['[', '{', '&', '*', '!', '|', '>']) {
        return Err(format!(
            "line {no}: {t:?}: lists, maps in flow style, anchors, tags and block strings \
             are not supported in parameter files"
        ));
    }
    Ok(Scalar::parse_plain(t))
}

fn unescape_double(s: &str) -> Result<Scalar, String> {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c != '\\' {
            out.push(c);
            continue;
        }
        match chars.next() {
            Some('n') => out.push('\n'),
            Some('t') => out.push('\t'),
            Some('\\') => out.push('\\'),
            Some('"') => out.push('"'),
            Some('/') => out.push('/'),
            Some('0') => out.push('\0'),
            other => return Err(format!("unsupported escape \\{}", other.unwrap_or(' '))),
        }
    }
    Ok(Scalar::Str(out))
}

/// Drops a `#` comment that is outside quotes and starts a word.
fn strip_comment(line: &str) -> &str {
    let mut quote: Option<char> = None;
    let mut prev = ' ';
    for (i, c) in line.char_indices() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '"' || c == '\'' => quote = Some(c),
            None if c == '#' && prev.is_whitespace() => return &line[..i],
            None => {}
        }
        prev = c;
    }
    line
}

/// Splits `key: rest` at the first `: ` (or trailing `:`) outside quotes.
fn split_key(body: &str) -> Option<(String, &str)> {
    let (key, rest) = if let Some(q) = body.chars().next().filter(|c| *c == '"' || *c == '\'') {
        let end = body[1..].find(q)? + 1;
        let after = body[end + 1..].trim_start();
        let rest = after.strip_prefix(':')?;
        (body[1..end].to_string(), rest)
    } else {
        let i = body
            .match_indices(':')
            .map(|(i, _)| i)
            .find(|&i| body[i + 1..].is_empty() || body[i + 1..].starts_with(' '))?;
        (body[..i].trim().to_string(), &body[i + 1..])
    };
    if key.is_empty() || !(rest.is_empty() || rest.starts_with(' ')) {
        return None;
    }
    Some((key, rest))
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
    }

    #[test]
    fn rejects_what_it_does_not_support_with_the_line() {
        for (text, want) in [
            ("a:\n  - 1\n", "line 2: lists"),
            ("a: [1, 2]\n", "line 1"),
            ("a: 1\na: 2\n", "line 2: duplicate key"),
            ("a:\n    b: 1\n  c: 2\n", "line 3: unexpected indentation"),
            ("just text\n", "line 1: expected `key: value`"),
            ("a: \"open\n", "line 1: unterminated"),
            ("a:\n\tb: 1\n", "line 2: tabs"),
        ] {
            let e = parse(text).unwrap_err();
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }
}
