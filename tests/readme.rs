//! The README and the guides beside it (`docs/*.md`): every `mcgnode` command
//! they show parses with the binary's own argument parser as written (a renamed
//! flag or subcommand fails here), the quick ones (`simulate`, `bag info`) run
//! as written, every script they show exists, every relative link resolves
//! (anchors included), and the README stays a front door of at most 250 lines.

use clap::Parser;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The documents checked, with the fewest `mcgnode` commands each must show:
/// a guide that loses its examples fails here.
const DOCS: [(&str, usize); 6] = [
    ("README.md", 4),
    ("docs/guide.md", 30),
    ("docs/ros.md", 5),
    ("docs/performance.md", 3),
    ("docs/reproduce.md", 4),
    ("docs/ARCHITECTURE.md", 0),
];

/// The longest the README may grow.
const README_MAX_LINES: usize = 250;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The lines of a markdown text's ```sh blocks, trimmed.
fn sh_lines(text: &str) -> Vec<String> {
    let mut out = vec![];
    let mut in_block = false;
    let mut in_sh = false;
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with("```") {
            in_sh = !in_block && t == "```sh";
            in_block = !in_block;
            continue;
        }
        if in_sh {
            out.push(t.to_string());
        }
    }
    out
}

/// Every `mcgnode …` command line in a text's `sh` blocks, without its trailing
/// comment: lines starting `mcgnode`, `cargo run --release --`, or holding
/// `target/release/mcgnode` (up to a closing quote).
fn commands(text: &str) -> Vec<String> {
    let mut out = vec![];
    for t in sh_lines(text) {
        let t = match t.find(" #") {
            Some(i) => t[..i].trim(),
            None => t.as_str(),
        };
        let cmd = if let Some(rest) = t.strip_prefix("cargo run --release -- ") {
            format!("mcgnode {rest}")
        } else if t.starts_with("mcgnode ") {
            t.to_string()
        } else if let Some(i) = t.find("target/release/mcgnode ") {
            let rest = &t[i + "target/release/".len()..];
            rest.split('\'').next().unwrap_or(rest).trim().to_string()
        } else {
            continue;
        };
        out.push(cmd);
    }
    out
}

/// The words of a command (no quoting is used in the documents' commands);
/// `[--opt x]` marks optional parts and is read as given.
fn words(cmd: &str) -> Vec<String> {
    cmd.split_whitespace()
        .map(|w| w.trim_matches(|c| c == '[' || c == ']').to_string())
        .filter(|w| !w.is_empty())
        .collect()
}

#[test]
fn every_command_in_the_docs_parses_as_written() {
    let mut all = vec![];
    for (doc, min) in DOCS {
        let cmds = commands(&read(doc));
        assert!(
            cmds.len() >= min,
            "{doc} shows only {} mcgnode commands (at least {min} expected): {cmds:?}",
            cmds.len()
        );
        for cmd in &cmds {
            if let Err(e) =
                mcgnode::cli::Cli::try_parse_from(mcgnode::cli::ros_native_argv(words(cmd)))
            {
                panic!("{doc}: command `{cmd}` does not parse:\n{e}");
            }
        }
        all.extend(cmds);
    }
    for sub in [
        "simulate",
        "train",
        "rollout",
        "plan",
        "evaluate",
        "replay",
        "bag info",
        "bag repair",
        "bag observe",
        "bag draw",
        "reproduce",
        "serve",
        "demo",
        "bench",
    ] {
        assert!(
            all.iter().any(|c| c.starts_with(&format!("mcgnode {sub}"))),
            "no document shows a `mcgnode {sub}` command"
        );
    }
}

#[test]
fn simulate_and_bag_info_commands_run_as_written() {
    let mut total = 0;
    for (doc, _) in DOCS {
        // Each document in a folder of its own: its `bag info` lines read the
        // bags its own `simulate` lines wrote.
        let dir = tempfile::tempdir().unwrap();
        let mut ran = 0;
        for cmd in commands(&read(doc)) {
            let w = words(&cmd);
            if !(w[1] == "simulate" || (w[1] == "bag" && w[2] == "info")) {
                continue;
            }
            let o = Command::new(env!("CARGO_BIN_EXE_mcgnode"))
                .args(&w[1..])
                .current_dir(dir.path())
                .output()
                .expect("run mcgnode");
            assert!(
                o.status.success(),
                "{doc}: command `{cmd}` failed:\n{}",
                String::from_utf8_lossy(&o.stderr)
            );
            ran += 1;
        }
        if doc == "README.md" {
            assert!(ran >= 1, "the README runs no simulate/bag info command");
        }
        if doc == "docs/guide.md" {
            assert!(
                ran >= 10,
                "the guide runs only {ran} simulate/bag info commands"
            );
        }
        total += ran;
    }
    assert!(total >= 12, "ran only {total} simulate/bag info commands");
}

/// Every relative link in a markdown text (`](target)`), with its anchor if it
/// has one; web links are left out.
fn relative_links(text: &str) -> Vec<String> {
    text.split("](")
        .skip(1)
        .filter_map(|rest| rest.split(')').next())
        .map(str::to_string)
        .filter(|t| !t.is_empty() && !t.contains("://") && !t.starts_with("mailto:"))
        .collect()
}

/// The anchors of a markdown text's headings, as GitHub makes them: lower
/// case, punctuation but `-` and `_` dropped, spaces as `-`, and `-1`, `-2`, …
/// after a repeated one.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut in_block = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if in_block || !line.starts_with('#') {
            continue;
        }
        let title = line.trim_start_matches('#').trim();
        let slug: String = title
            .chars()
            .filter_map(|c| {
                if c == ' ' {
                    Some('-')
                } else if c.is_alphanumeric() || c == '-' || c == '_' {
                    Some(c.to_lowercase().next().unwrap_or(c))
                } else {
                    None
                }
            })
            .collect();
        let mut unique = slug.clone();
        let mut n = 0;
        while out.contains(&unique) {
            n += 1;
            unique = format!("{slug}-{n}");
        }
        out.insert(unique);
    }
    out
}

/// Where a link from `doc` (a path under the root) leads, and its anchor.
fn resolve(doc: &str, link: &str) -> (PathBuf, Option<String>) {
    let (path, anchor) = match link.split_once('#') {
        Some((p, a)) => (p, Some(a.to_string())),
        None => (link, None),
    };
    let base = root().join(doc);
    let dir = base.parent().unwrap();
    let target = if path.is_empty() {
        base.clone()
    } else {
        dir.join(path)
    };
    (target, anchor)
}

#[test]
fn every_relative_link_in_the_docs_resolves() {
    let mut count = 0;
    for (doc, _) in DOCS {
        let text = read(doc);
        let links = relative_links(&text);
        assert!(
            links.len() >= 5,
            "{doc} has only {} relative links: {links:?}",
            links.len()
        );
        for link in &links {
            let (target, anchor) = resolve(doc, link);
            assert!(
                target.exists(),
                "{doc} links to `{link}`, and {} does not exist",
                target.display()
            );
            if let Some(anchor) = anchor {
                assert!(
                    target.extension().is_some_and(|e| e == "md"),
                    "{doc} links to `{link}`: an anchor into a file that is not markdown"
                );
                let heads = anchors(&std::fs::read_to_string(&target).unwrap());
                assert!(
                    heads.contains(&anchor),
                    "{doc} links to `{link}`, but {} has no heading `#{anchor}`",
                    target.display()
                );
            }
            count += 1;
        }
    }
    assert!(count >= 60, "only {count} relative links in all");
}

#[test]
fn anchors_follow_github() {
    let a = anchors("# mcgnode\n## Where to add a node parameter\n### `mcgnode train`\n## The pipeline\n## The pipeline\n```sh\n# not a heading\n```\n");
    let want: BTreeSet<String> = [
        "mcgnode",
        "where-to-add-a-node-parameter",
        "mcgnode-train",
        "the-pipeline",
        "the-pipeline-1",
    ]
    .into_iter()
    .map(String::from)
    .collect();
    assert_eq!(a, want);
}

/// Every `scripts/…` path a text names (in code, commands or links).
fn script_paths(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (i, _) in text.match_indices("scripts/") {
        if i > 0 {
            let before = text.as_bytes()[i - 1];
            if before.is_ascii_alphanumeric() || before == b'_' || before == b'/' {
                continue;
            }
        }
        let path: String = text[i..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || matches!(c, '/' | '_' | '-' | '.'))
            .collect();
        let path = path.trim_end_matches('.');
        if matches!(
            Path::new(path).extension().and_then(|e| e.to_str()),
            Some("sh" | "py")
        ) {
            out.insert(path.to_string());
        }
    }
    out
}

#[test]
fn every_script_the_docs_show_exists() {
    let mut shown = BTreeSet::new();
    for (doc, _) in DOCS {
        for path in script_paths(&read(doc)) {
            let file = root().join(&path);
            assert!(file.is_file(), "{doc} shows `{path}`, which does not exist");
            if Path::new(&path).extension().is_some_and(|e| e == "sh") {
                use std::os::unix::fs::PermissionsExt;
                let mode = std::fs::metadata(&file).unwrap().permissions().mode();
                assert!(
                    mode & 0o111 != 0,
                    "{doc} shows `{path}`, which is not executable"
                );
            }
            shown.insert(path);
        }
    }
    for must in [
        "scripts/test.sh",
        "scripts/bench_vs_reference.sh",
        "scripts/ros_bench.sh",
        "scripts/ros_bench_large.sh",
        "scripts/ros_bench_plan.sh",
        "scripts/netns.sh",
    ] {
        assert!(shown.contains(must), "no document shows `{must}`");
    }
    let bad = script_paths("see scripts/nope.sh and `scripts/ros/echo.py`, not myscripts/x.sh.");
    assert_eq!(
        bad.into_iter().collect::<Vec<_>>(),
        ["scripts/nope.sh", "scripts/ros/echo.py"]
    );
}

#[test]
fn the_readme_is_a_front_door() {
    let text = read("README.md");
    let lines = text.lines().count();
    assert!(
        lines <= README_MAX_LINES,
        "README.md has {lines} lines, above {README_MAX_LINES}: move the detail to docs/"
    );
    // It opens with the two commands a newcomer runs on a fresh machine.
    let first = sh_lines(&text);
    let first_two: Vec<&str> = first.iter().take(2).map(String::as_str).collect();
    assert!(
        first_two.len() == 2
            && first_two[0].starts_with("cargo run --release -- demo")
            && first_two[1].starts_with("scripts/test.sh"),
        "the README's first sh block should be the demo and scripts/test.sh: {first_two:?}"
    );
    // Its opening paragraph carries no dated measurement.
    let opening: String = text
        .lines()
        .skip_while(|l| l.starts_with('#') || l.trim().is_empty())
        .take_while(|l| !l.trim().is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    assert!(!opening.is_empty(), "the README has no opening paragraph");
    assert!(
        !opening.contains("2026-") && !opening.contains(" minutes"),
        "the README's opening paragraph carries dated timings: {opening}"
    );
    // Every guide is one link away, and so is where to add a node parameter.
    let links = relative_links(&text);
    for guide in [
        "docs/guide.md",
        "docs/ros.md",
        "docs/performance.md",
        "docs/reproduce.md",
        "docs/ARCHITECTURE.md",
        "docs/ARCHITECTURE.md#where-to-add-a-node-parameter",
    ] {
        assert!(
            links.iter().any(|l| l == guide),
            "the README does not link to `{guide}`"
        );
    }
}

#[test]
fn committed_reproduce_reports_hold() {
    // Each committed reproduce report: its links resolve, its command parses as
    // written, and it names no path of the machine it ran on.
    let mut reports = 0;
    for entry in std::fs::read_dir(root().join("docs")).unwrap() {
        let dir = entry.unwrap().path();
        let report = dir.join("report.md");
        if !report.exists() {
            continue;
        }
        reports += 1;
        let text = std::fs::read_to_string(&report).unwrap();
        for link in relative_links(&text) {
            let link = link.split('#').next().unwrap_or(&link);
            assert!(
                dir.join(link).exists(),
                "{} links to missing `{link}`",
                report.display()
            );
        }
        assert!(
            dir.join("results.json").exists(),
            "{} has no results.json beside it",
            report.display()
        );
        let cmd = text
            .lines()
            .find_map(|l| l.strip_prefix("Command: `"))
            .and_then(|l| l.split('`').next())
            .unwrap_or_else(|| panic!("{} states no command", report.display()));
        if let Err(e) = mcgnode::cli::Cli::try_parse_from(mcgnode::cli::ros_native_argv(words(cmd)))
        {
            panic!("{}: command `{cmd}` does not parse:\n{e}", report.display());
        }
        for prefix in ["/work/", "/home/", "/tmp/", "/root/", "/usr/"] {
            assert!(
                !text.contains(prefix),
                "{} names a path of the machine it ran on ({prefix}…)",
                report.display()
            );
        }
    }
    assert!(
        reports >= 3,
        "found only {reports} committed reports under docs/"
    );
}
