//! The code's structure, kept so: one error style (thiserror in the library,
//! anyhow only at the command line's edge, no `Result<_, String>`), no two
//! top-level modules that import each other, and no circle of imports
//! between the files of one module.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The unit tests' `mod tests { ... }` block cut out of `text` (by matching
/// braces), the code after it kept.
fn without_tests(text: &str) -> String {
    let Some(start) = text.find("#[cfg(test)]\nmod tests {") else {
        return text.to_string();
    };
    let open = start + text[start..].find('{').unwrap_or(0);
    let mut depth = 0usize;
    for (i, c) in text[open..].char_indices() {
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    let rest = &text[open + i + 1..];
                    return format!("{}{}", &text[..start], without_tests(rest));
                }
            }
            _ => {}
        }
    }
    text[..start].to_string()
}

#[test]
fn cutting_the_tests_keeps_what_follows() {
    let t = "a\n#[cfg(test)]\nmod tests {\n fn f() { g({ 1 }) }\n}\nb\n";
    assert_eq!(without_tests(t), "a\n\nb\n");
}

/// Every `.rs` file under `src/`, whole, with its code: comment lines and the
/// unit tests' block left out (code after that block is kept).
fn sources() -> Vec<(PathBuf, String)> {
    fn walk(dir: &Path, out: &mut Vec<(PathBuf, String)>) {
        for e in std::fs::read_dir(dir).expect("src/ is readable") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let text = std::fs::read_to_string(&p).expect("source is UTF-8");
                let code = without_tests(&text)
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
        let uses = names_after(&code, "crate::");
        g.entry(me.clone())
            .or_default()
            .extend(uses.into_iter().filter(|m| *m != me));
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

/// The names `prefix` is followed by in `code`: `prefix a::x`, and each
/// first name of a group `prefix {a::x, b, c::{y, z}}`.
fn names_after(code: &str, prefix: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for part in code.split(prefix).skip(1) {
        if let Some(rest) = part.strip_prefix('{') {
            let mut depth = 0;
            let mut item = String::new();
            for c in rest.chars() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        out.insert(first_name(&item).to_string());
                        item.clear();
                        continue;
                    }
                    _ => {}
                }
                item.push(c);
            }
            out.insert(first_name(&item).to_string());
        } else {
            out.insert(first_name(part).to_string());
        }
    }
    out.remove("");
    out
}

/// Per folder of `src/`, which of its files name which other files of it
/// (`super::x` from a file beside `x.rs`, or `crate::folder::x`).
fn file_imports() -> BTreeMap<PathBuf, BTreeMap<String, BTreeSet<String>>> {
    let mut out: BTreeMap<PathBuf, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (path, code) in sources() {
        let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) else {
            continue;
        };
        let me = path.file_stem().unwrap().to_string_lossy().to_string();
        if me == "mod" {
            continue;
        }
        let sibling = |n: &str| {
            root().join(dir).join(format!("{n}.rs")).exists() || root().join(dir).join(n).is_dir()
        };
        let module = dir.to_string_lossy().replace('/', "::");
        let mut names = names_after(&code, "super::");
        names.extend(names_after(&code, &format!("crate::{module}::")));
        let uses: BTreeSet<String> = names
            .into_iter()
            .filter(|n| *n != me && sibling(n))
            .collect();
        out.entry(dir.to_path_buf()).or_default().insert(me, uses);
    }
    out
}

/// A circle in `g`, if there is one, as the files along it.
fn circle(g: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        g: &BTreeMap<String, BTreeSet<String>>,
        n: &str,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == n) {
            let mut c = path[i..].to_vec();
            c.push(n.to_string());
            return Some(c);
        }
        if done.contains(n) {
            return None;
        }
        path.push(n.to_string());
        for m in g.get(n).into_iter().flatten() {
            if let Some(c) = visit(g, m, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(n.to_string());
        None
    }
    let mut done = BTreeSet::new();
    g.keys()
        .find_map(|n| visit(g, n, &mut Vec::new(), &mut done))
}

#[test]
fn no_circle_between_the_files_of_a_module() {
    let all = file_imports();
    let ros = &all[Path::new("ros")];
    assert!(
        ros.get("node")
            .is_some_and(|u| u.contains("handles") && u.contains("input")),
        "the scan found no imports between files: {ros:?}"
    );
    let mut g = BTreeMap::new();
    g.insert("a".to_string(), BTreeSet::from(["b".to_string()]));
    g.insert("b".to_string(), BTreeSet::from(["a".to_string()]));
    assert_eq!(
        circle(&g),
        Some(vec!["a".into(), "b".into(), "a".into()]),
        "the check finds one"
    );
    let circles: Vec<String> = all
        .iter()
        .filter_map(|(dir, g)| {
            circle(g).map(|c| format!("src/{}: {}", dir.display(), c.join(" -> ")))
        })
        .collect();
    assert!(
        circles.is_empty(),
        "files importing each other in a circle:\n{}",
        circles.join("\n")
    );
}
