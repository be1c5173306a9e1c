//! The code's structure, kept so: one error style (thiserror in the library,
//! anyhow only at the command line's edge, no `Result<_, String>`), and no
//! two top-level modules that import each other.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every `.rs` file under `src/`, with its code: comment lines and the unit
/// tests at the end of a file left out.
fn sources() -> Vec<(PathBuf, String)> {
    fn walk(dir: &Path, out: &mut Vec<(PathBuf, String)>) {
        for e in std::fs::read_dir(dir).expect("src/ is readable") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let text = std::fs::read_to_string(&p).expect("source is UTF-8");
                let code = text
                    .split("#[cfg(test)]\nmod tests")
                    .next()
                    .unwrap_or_default()
                    .lines()
                    .map(|l| {
                        if l.trim_start().starts_with("//") {
                            ""
                        } else {
                            l
                        }
                    })
                    .collect::<Vec<_>>()
                    .join("\n");
                out.push((p.strip_prefix(root()).unwrap().to_path_buf(), code));
            }
        }
    }
    let mut out = vec![];
    walk(&root(), &mut out);
    assert!(out.len() > 50, "found only {} source files", out.len());
    out
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The top-level module a file belongs to (`ros/node.rs` → `ros`).
fn top(path: &Path) -> String {
    let first = path
        .components()
        .next()
        .unwrap()
        .as_os_str()
        .to_string_lossy();
    first.trim_end_matches(".rs").to_string()
}

#[test]
fn the_library_has_one_error_style() {
    let mut offenders = vec![];
    for (path, code) in sources() {
        let edge = matches!(top(&path).as_str(), "cli" | "main");
        if !edge && code.contains("anyhow") {
            offenders.push(format!("{}: anyhow outside src/cli", path.display()));
        }
        for (i, line) in code.lines().enumerate() {
            if string_error(line) {
                offenders.push(format!("{}:{}: Result<_, String>", path.display(), i + 1));
            }
        }
    }
    assert!(offenders.is_empty(), "{}", offenders.join("\n"));
}

/// Whether a line names a `Result<T, String>`.
fn string_error(line: &str) -> bool {
    let l: String = line.split_whitespace().collect();
    l.match_indices("Result<").any(|(i, m)| {
        // The generic arguments at depth 0, split by commas.
        let (mut depth, mut args, mut arg) = (0, vec![], String::new());
        for c in l[i + m.len()..].chars() {
            match c {
                '<' | '(' | '[' => depth += 1,
                '>' | ')' | ']' if depth == 0 => break,
                '>' | ')' | ']' => depth -= 1,
                ',' if depth == 0 => {
                    args.push(std::mem::take(&mut arg));
                    continue;
                }
                _ => {}
            }
            arg.push(c);
        }
        args.push(arg);
        args.get(1).is_some_and(|e| e == "String")
    })
}

#[test]
fn the_string_error_check_finds_them() {
    assert!(string_error("fn f() -> Result<(), String> {"));
    assert!(string_error(
        "-> std::result::Result<Vec<(u8, u8)>, String>"
    ));
    assert!(!string_error(
        "fn f(m: &BTreeMap<String, String>) -> Result<u8, DataError>"
    ));
    assert!(!string_error("fn f() -> Result<String> {"));
}

/// The modules each top-level module names through `crate::`.
fn imports() -> BTreeMap<String, BTreeSet<String>> {
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (path, code) in sources() {
        let me = top(&path);
        let mut add = |m: &str| {
            if m != me && !m.is_empty() {
                g.entry(me.clone()).or_default().insert(m.to_string());
            }
        };
        for part in code.split("crate::").skip(1) {
            if let Some(rest) = part.strip_prefix('{') {
                // `use crate::{a::x, b, c::{y, z}}`: the first name of each item.
                let mut depth = 0;
                let mut item = String::new();
                for c in rest.chars() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => break,
                        '}' => depth -= 1,
                        ',' if depth == 0 => {
                            add(first_name(&item));
                            item.clear();
                            continue;
                        }
                        _ => {}
                    }
                    item.push(c);
                }
                add(first_name(&item));
            } else {
                add(first_name(part));
            }
        }
    }
    g
}

fn first_name(s: &str) -> &str {
    let s = s.trim_start();
    let end = s
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    &s[..end]
}

#[test]
fn no_two_modules_import_each_other() {
    let g = imports();
    assert!(
        g.get("ros").is_some_and(|m| m.contains("kernel")),
        "the scan found no imports: {g:?}"
    );
    let mut circles = vec![];
    for (a, uses) in &g {
        for b in uses {
            if a < b && g.get(b).is_some_and(|m| m.contains(a)) {
                circles.push(format!("{a} <-> {b}"));
            }
        }
    }
    assert!(
        circles.is_empty(),
        "modules importing each other: {circles:?}"
    );
    // The pipeline's far end is not imported by its start.
    for early in ["system", "physics", "data", "error"] {
        for late in ["cli", "ros", "reproduce"] {
            assert!(
                !g.get(early).is_some_and(|m| m.contains(late)),
                "{early} imports {late}"
            );
        }
    }
}
