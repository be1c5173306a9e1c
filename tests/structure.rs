//! The code's structure, kept so: one error style (thiserror in the library,
//! anyhow only at the command line's edge, no `Result<_, String>`), no two
//! top-level modules that import each other, and no circle of imports
//! between the files of one module.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

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

/// The module a file of `src/` is (`ros/node.rs` → `[ros, node]`,
/// `ros/mod.rs` → `[ros]`, `lib.rs` → `[]`).
fn module_of(path: &Path) -> Vec<String> {
    let mut m: Vec<String> = path
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if matches!(m.last().map(String::as_str), Some("mod" | "lib")) {
        m.pop();
    }
    m
}

/// The paths that start at `at` in `code` (`crate::a::{b, c::{d, self}}`
/// → `[crate, a, b]`, `[crate, a, c, d]`, `[crate, a, c]`).
fn path_tree(code: &[char], at: &mut usize) -> Vec<Vec<String>> {
    let skip_ws = |at: &mut usize| {
        while code.get(*at).is_some_and(|c| c.is_whitespace()) {
            *at += 1;
        }
    };
    let mut segs: Vec<String> = vec![];
    loop {
        skip_ws(at);
        if code.get(*at) == Some(&'{') {
            *at += 1;
            let mut out = vec![];
            loop {
                skip_ws(at);
                match code.get(*at) {
                    None => break,
                    Some('}') => {
                        *at += 1;
                        break;
                    }
                    Some(',') => *at += 1,
                    Some(_) => {
                        let before = *at;
                        for sub in path_tree(code, at) {
                            let sub: Vec<String> =
                                sub.into_iter().filter(|s| s != "self").collect();
                            out.push([segs.clone(), sub].concat());
                        }
                        // `x as y`, or anything unparsed: on to the next member.
                        while code.get(*at).is_some_and(|c| !matches!(c, ',' | '}')) {
                            *at += 1;
                        }
                        if *at == before {
                            *at += 1;
                        }
                    }
                }
            }
            return out;
        }
        let start = *at;
        while code
            .get(*at)
            .is_some_and(|c| c.is_alphanumeric() || *c == '_' || *c == '*')
        {
            *at += 1;
        }
        if *at == start {
            return vec![segs];
        }
        segs.push(code[start..*at].iter().collect());
        if code.get(*at) == Some(&':') && code.get(*at + 1) == Some(&':') {
            *at += 2;
        } else {
            return vec![segs];
        }
    }
}

/// Every path in `code` that starts with one of `starts` (followed by `::`,
/// and not itself the tail of a longer path), expanded.
fn paths_in(code: &str, starts: &BTreeSet<String>) -> Vec<Vec<String>> {
    let chars: Vec<char> = code.chars().collect();
    let mut out = vec![];
    let mut i = 0;
    while i < chars.len() {
        let boundary =
            i == 0 || !(chars[i - 1].is_alphanumeric() || matches!(chars[i - 1], '_' | ':'));
        if boundary && (chars[i].is_alphanumeric() || chars[i] == '_') {
            let mut j = i;
            while chars
                .get(j)
                .is_some_and(|c| c.is_alphanumeric() || *c == '_')
            {
                j += 1;
            }
            let word: String = chars[i..j].iter().collect();
            if starts.contains(&word)
                && chars.get(j) == Some(&':')
                && chars.get(j + 1) == Some(&':')
            {
                let mut at = i;
                out.extend(path_tree(&chars, &mut at));
                i = at.max(i + 1);
                continue;
            }
            i = j;
            continue;
        }
        i += 1;
    }
    out
}

/// `path`, named in the file that is module `me`, as a path from the crate's
/// root (`super::x` in `ros/node.rs` → `[ros, x]`); relative paths are
/// children of `me`.
fn absolute(me: &[String], path: &[String]) -> Vec<String> {
    let mut base = me.to_vec();
    let mut rest = path;
    match rest.first().map(String::as_str) {
        Some("crate") => {
            base.clear();
            rest = &rest[1..];
        }
        Some("self") => rest = &rest[1..],
        _ => {}
    }
    while rest.first().map(String::as_str) == Some("super") {
        base.pop();
        rest = &rest[1..];
    }
    [base, rest.to_vec()].concat()
}

/// `code` without its `pub use` statements, and the paths of all its `use`
/// statements. A folder's mod.rs re-exporting what its files define curates
/// its surface, it does not use them; and a file naming an item that mod.rs
/// imports (`super::Item`) is taken to name the file that defines it.
fn split_uses(code: &str) -> (String, Vec<String>) {
    let (mut kept, mut uses) = (String::new(), vec![]);
    let mut rest = code;
    while let Some(i) = rest.find("use ").filter(|_| !rest.is_empty()) {
        let boundary = rest[..i]
            .chars()
            .next_back()
            .is_none_or(|c| c.is_whitespace() || c == ')' || c == ';' || c == '}');
        if !boundary {
            kept.push_str(&rest[..i + 4]);
            rest = &rest[i + 4..];
            continue;
        }
        let end = rest[i..].find(';').map_or(rest.len(), |e| i + e + 1);
        let public = rest[..i].trim_end().ends_with("pub") || rest[..i].trim_end().ends_with(')');
        uses.push(rest[i + 4..end].trim_end_matches(';').to_string());
        if public {
            let line = rest[..i].rfind('\n').map_or(0, |l| l + 1);
            kept.push_str(&rest[..line]);
        } else {
            kept.push_str(&rest[..end]);
        }
        rest = &rest[end..];
    }
    kept.push_str(rest);
    (kept, uses)
}

/// Per module of `src/` that is a folder, which of its files name which other
/// files of it: the nodes are its files and subfolders (a subfolder stands
/// for every file in it) and its own `mod.rs` (`lib.rs` at the root). Whole
/// files are read, except comment lines and the unit tests' block: tests
/// building their fixtures from a sibling are not a dependency of the code
/// that ships (they compile only under cfg(test)), and excluding them lets a
/// test use whatever it checks against.
fn file_imports() -> BTreeMap<Vec<String>, BTreeMap<String, BTreeSet<String>>> {
    let sources: Vec<(PathBuf, String)> = sources()
        .into_iter()
        .filter(|(p, _)| p != Path::new("main.rs"))
        .collect();
    let mut modules: BTreeSet<Vec<String>> = BTreeSet::new();
    let mut folders: BTreeSet<Vec<String>> = BTreeSet::new();
    for (p, _) in &sources {
        let m = module_of(p);
        if matches!(
            p.file_name().and_then(|f| f.to_str()),
            Some("mod.rs" | "lib.rs")
        ) {
            folders.insert(m.clone());
        }
        for k in 0..=m.len() {
            modules.insert(m[..k].to_vec());
        }
    }
    // The module a path names: its longest prefix that is a module, with a
    // folder's re-export followed to the file that defines the item.
    let mut reexported: BTreeMap<(Vec<String>, String), Vec<String>> = BTreeMap::new();
    let resolve = |abs: &[String]| -> Vec<String> {
        (0..=abs.len())
            .rev()
            .map(|k| abs[..k].to_vec())
            .find(|m| modules.contains(m))
            .unwrap_or_default()
    };
    let starts: BTreeSet<String> = ["crate", "super", "self"].map(String::from).into();
    let mut named: Vec<(Vec<String>, Vec<Vec<String>>)> = vec![];
    for (p, code) in &sources {
        let me = module_of(p);
        let (code, reexports) = if folders.contains(&me) {
            split_uses(code)
        } else {
            (code.clone(), vec![])
        };
        let children: BTreeSet<String> = modules
            .iter()
            .filter(|m| m.len() == me.len() + 1 && m.starts_with(&me))
            .map(|m| m[me.len()].clone())
            .collect();
        for r in &reexports {
            let tree = paths_in(
                &format!(" {r}"),
                &starts.union(&children).cloned().collect(),
            );
            for path in tree {
                let abs = absolute(&me, &path);
                if let Some(item) = abs.last() {
                    reexported.insert((me.clone(), item.clone()), resolve(&abs));
                }
            }
        }
        // A folder's mod.rs names its files without a prefix (`node::serve`),
        // and with `pub use` cut out its remaining `use`s are its own.
        let mut paths = paths_in(&code, &starts);
        if folders.contains(&me) {
            paths.extend(paths_in(&code, &children));
        }
        named.push((me.clone(), paths.iter().map(|p| absolute(&me, p)).collect()));
    }
    let target = |abs: &[String]| -> Vec<String> {
        let m = resolve(abs);
        match abs.get(m.len()) {
            Some(item) if folders.contains(&m) => reexported
                .get(&(m.clone(), item.clone()))
                .cloned()
                .unwrap_or(m),
            _ => m,
        }
    };
    let mut out: BTreeMap<Vec<String>, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    let node = |folder: &[String], m: &[String]| -> Option<String> {
        if !m.starts_with(folder) {
            return None;
        }
        Some(m.get(folder.len()).cloned().unwrap_or_else(|| {
            if folder.is_empty() {
                "lib.rs"
            } else {
                "mod.rs"
            }
            .to_string()
        }))
    };
    for folder in &folders {
        let g = out.entry(folder.clone()).or_default();
        for (me, paths) in &named {
            let Some(from) = node(folder, me) else {
                continue;
            };
            let uses = g.entry(from.clone()).or_default();
            for p in paths {
                if let Some(to) = node(folder, &target(p)) {
                    if to != from {
                        uses.insert(to);
                    }
                }
            }
        }
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
    let ros = &all[&vec!["ros".to_string()]];
    assert!(
        ros.get("node")
            .is_some_and(|u| u.contains("handles") && u.contains("input")),
        "the scan found no imports between files: {ros:?}"
    );
    let cli = &all[&vec!["cli".to_string()]];
    assert!(
        cli.get("mod.rs").is_some_and(|u| u.contains("train")),
        "the scan does not read mod.rs: {cli:?}"
    );
    let repro = &all[&vec!["reproduce".to_string()]];
    assert!(
        repro.contains_key("experiments"),
        "the scan does not see subfolders: {repro:?}"
    );
    let mut g = BTreeMap::new();
    g.insert("a".to_string(), BTreeSet::from(["b".to_string()]));
    g.insert("b".to_string(), BTreeSet::from(["c".to_string()]));
    g.insert("c".to_string(), BTreeSet::from(["a".to_string()]));
    assert_eq!(
        circle(&g),
        Some(vec!["a".into(), "b".into(), "c".into(), "a".into()]),
        "the check finds one"
    );
    let circles: Vec<String> = all
        .iter()
        .filter_map(|(dir, g)| {
            circle(g).map(|c| format!("src/{}: {}", dir.join("/"), c.join(" -> ")))
        })
        .collect();
    assert!(
        circles.is_empty(),
        "files importing each other in a circle:\n{}",
        circles.join("\n")
    );
}

#[test]
fn the_path_scan_expands_groups_and_resolves_super() {
    let starts: BTreeSet<String> = ["crate", "super", "self"].map(String::from).into();
    let got = paths_in(
        "use crate::a::{b, c::{d, self}};\nlet x = super::e::f(Self::g, my::super_h);",
        &starts,
    );
    let want: Vec<Vec<String>> = [
        &["crate", "a", "b"][..],
        &["crate", "a", "c", "d"],
        &["crate", "a", "c"],
        &["super", "e", "f"],
    ]
    .iter()
    .map(|p| p.iter().map(ToString::to_string).collect())
    .collect();
    assert_eq!(got, want);
    let me = ["ros".to_string(), "node".to_string()];
    assert_eq!(absolute(&me, &want[3]), ["ros", "e", "f"]);
    assert_eq!(module_of(Path::new("ros/mod.rs")), ["ros"]);
}

/// `text` with every comment, string and character literal blanked to
/// spaces (line breaks kept, so line numbers hold): what is left of its
/// braces is code. Nested block comments, escapes, raw strings
/// (`r#"…"#`, `br"…"`) and lifetimes (`'a`, not a literal) are told apart.
fn blank_literals(text: &str) -> String {
    let c: Vec<char> = text.chars().collect();
    let mut out: Vec<char> = c.clone();
    let blank = |out: &mut Vec<char>, from: usize, to: usize| {
        for x in &mut out[from..to.min(c.len())] {
            if *x != '\n' {
                *x = ' ';
            }
        }
    };
    let mut i = 0;
    while i < c.len() {
        let next = c.get(i + 1).copied();
        if c[i] == '/' && next == Some('/') {
            let end = (i..c.len()).find(|&k| c[k] == '\n').unwrap_or(c.len());
            blank(&mut out, i, end);
            i = end;
        } else if c[i] == '/' && next == Some('*') {
            let (mut k, mut depth) = (i + 2, 1);
            while k < c.len() && depth > 0 {
                if c[k] == '/' && c.get(k + 1) == Some(&'*') {
                    depth += 1;
                    k += 2;
                } else if c[k] == '*' && c.get(k + 1) == Some(&'/') {
                    depth -= 1;
                    k += 2;
                } else {
                    k += 1;
                }
            }
            blank(&mut out, i, k);
            i = k;
        } else if c[i] == 'r' && matches!(next, Some('"' | '#')) && raw_start(&c, i) {
            // r"…", r#"…"#, br"…"; r#name is an identifier.
            let hashes = (i + 1..c.len()).take_while(|&k| c[k] == '#').count();
            if c.get(i + 1 + hashes) == Some(&'"') {
                let close: Vec<char> = std::iter::once('"')
                    .chain(std::iter::repeat_n('#', hashes))
                    .collect();
                let end = (i + 2 + hashes..c.len())
                    .find(|&k| c[k..].starts_with(&close))
                    .map_or(c.len(), |k| k + close.len());
                blank(&mut out, i, end);
                i = end;
            } else {
                i += 1;
            }
        } else if c[i] == '"' {
            let mut k = i + 1;
            while k < c.len() && c[k] != '"' {
                k += if c[k] == '\\' { 2 } else { 1 };
            }
            blank(&mut out, i, k + 1);
            i = k + 1;
        } else if c[i] == '\'' {
            // A literal: '\…' or 'x' (one character then a quote); else a
            // lifetime or label, left as it is.
            if next == Some('\\') {
                let mut k = i + 2;
                while k < c.len() && c[k] != '\'' {
                    k += 1;
                }
                // '\'' : the escaped quote is the character.
                if k == i + 2 {
                    k = i + 3;
                }
                blank(&mut out, i, k + 1);
                i = k + 1;
            } else if c.get(i + 2) == Some(&'\'') {
                blank(&mut out, i, i + 3);
                i += 3;
            } else {
                i += 1;
            }
        } else {
            i += 1;
        }
    }
    out.into_iter().collect()
}

/// Whether the `r` at `i` starts a raw string: not the tail of a name,
/// unless that name is the `b` of a byte string.
fn raw_start(c: &[char], i: usize) -> bool {
    let ident = |k: usize| c[k].is_alphanumeric() || c[k] == '_';
    i == 0 || !ident(i - 1) || (c[i - 1] == 'b' && (i == 1 || !ident(i - 2)))
}

/// Each function in `code` (literals blanked): its name, the line its `fn`
/// is on (from 1) and its length in lines, from that line to the line of
/// its closing brace, both counted. Declarations without a body (trait
/// methods, `extern` items) and `fn(…)` pointer types are not functions
/// here; functions inside functions count on their own too.
fn functions(code: &str) -> Vec<(String, usize, usize)> {
    let c: Vec<char> = code.chars().collect();
    let ident = |x: char| x.is_alphanumeric() || x == '_';
    let line_at = |k: usize| c[..k].iter().filter(|&&x| x == '\n').count() + 1;
    let mut found = vec![];
    for i in 0..c.len().saturating_sub(2) {
        let word = c[i] == 'f' && c[i + 1] == 'n' && c[i + 2].is_whitespace();
        if !word || (i > 0 && ident(c[i - 1])) {
            continue;
        }
        let mut k = i + 2;
        while k < c.len() && c[k].is_whitespace() {
            k += 1;
        }
        let name: String = c[k..].iter().take_while(|&&x| ident(x)).collect();
        if name.is_empty() {
            continue;
        }
        // The body's `{`: the first at depth 0 of () and [], unless a `;`
        // (a declaration) comes first.
        let mut depth = 0i64;
        let open = loop {
            match c.get(k) {
                None => break None,
                Some('(' | '[') => depth += 1,
                Some(')' | ']') => depth -= 1,
                Some(';' | '}') if depth == 0 => break None,
                Some('{') if depth == 0 => break Some(k),
                _ => {}
            }
            k += 1;
        };
        let Some(open) = open else { continue };
        let mut braces = 0usize;
        let close = (open..c.len()).find(|&k| {
            match c[k] {
                '{' => braces += 1,
                '}' => braces -= 1,
                _ => {}
            }
            braces == 0
        });
        let close = close.unwrap_or_else(|| panic!("`fn {name}` has no closing brace"));
        let first = line_at(i);
        found.push((name, first, line_at(close) - first + 1));
    }
    found
}

/// The most lines a file of `src/` may have, and a function in it (from its
/// `fn` line to its closing brace, both counted, unit tests included): a
/// file one reads in a sitting, a function on one screen.
const MAX_FILE_LINES: usize = 700;
const MAX_FN_LINES: usize = 80;

#[test]
fn no_file_or_function_is_too_long() {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).expect("src/ is readable") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let mut files = vec![];
    walk(&root(), &mut files);
    assert!(files.len() > 50, "found only {} source files", files.len());
    let (mut long, mut fns) = (vec![], 0);
    for p in files {
        let text = std::fs::read_to_string(&p).expect("source is UTF-8");
        let name = p.strip_prefix(root()).unwrap().display().to_string();
        let lines = text.lines().count();
        if lines > MAX_FILE_LINES {
            long.push(format!("src/{name}: {lines} lines"));
        }
        for (f, line, len) in functions(&blank_literals(&text)) {
            fns += 1;
            if len > MAX_FN_LINES {
                long.push(format!("src/{name}:{line}: fn {f} is {len} lines"));
            }
        }
    }
    assert!(fns > 1000, "found only {fns} functions");
    assert!(
        long.is_empty(),
        "more than {MAX_FILE_LINES} lines in a file or {MAX_FN_LINES} in a function \
         (split it by job):\n{}",
        long.join("\n")
    );
}

#[test]
fn the_length_check_counts_code_braces_only() {
    let code = "fn a<'x>(s: &'x str) -> char {\n    let _ = \"}}\\\"}\";\n    // }\n    \
                /* { /* } */ */\n    let _ = (r#\"}\"#, br\"{\", b'}', '\\'');\n    '}'\n}\n\
                fn b() {}\ntrait T {\n    fn c(&self);\n}\ntype F = fn(u8);\n";
    let blanked = blank_literals(code);
    assert_eq!(blanked.lines().count(), code.lines().count());
    let found = functions(&blanked);
    assert_eq!(found, [("a".to_string(), 1, 7), ("b".to_string(), 8, 1)]);
    // One line more than allowed is found.
    let body = "    x();\n".repeat(MAX_FN_LINES - 1);
    let long = format!("impl S {{\n    fn long(&self) {{\n{body}    }}\n}}\n");
    let found = functions(&blank_literals(&long));
    assert_eq!(found, [("long".to_string(), 2, MAX_FN_LINES + 1)]);
}
