//! The README's commands: every `mcgnode` command it shows parses with the
//! binary's own argument parser as written (a renamed flag or subcommand fails
//! here), and the quick ones (`simulate`, `bag info`) run as written.

use clap::Parser;
use std::path::Path;
use std::process::Command;

/// Every `mcgnode …` command line in the README's `sh` blocks, without its
/// trailing comment: lines starting `mcgnode`, `cargo run --release --`, or
/// holding `target/release/mcgnode` (up to a closing quote).
fn readme_commands() -> Vec<String> {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md"))
        .expect("README.md at the repository root");
    let mut out = vec![];
    let mut in_sh = false;
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with("```") {
            in_sh = !in_sh && t == "```sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        let t = match t.find(" #") {
            Some(i) => t[..i].trim(),
            None => t,
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

/// The words of a command (no quoting is used in the README's commands);
/// `[--opt x]` marks optional parts and is read as given.
fn words(cmd: &str) -> Vec<String> {
    cmd.split_whitespace()
        .map(|w| w.trim_matches(|c| c == '[' || c == ']').to_string())
        .filter(|w| !w.is_empty())
        .collect()
}

#[test]
fn every_readme_command_parses_as_written() {
    let cmds = readme_commands();
    assert!(
        cmds.len() >= 20,
        "found only {} commands: {cmds:?}",
        cmds.len()
    );
    for sub in [
        "simulate",
        "train",
        "rollout",
        "evaluate",
        "bag",
        "reproduce",
        "serve",
        "demo",
    ] {
        assert!(
            cmds.iter()
                .any(|c| c.starts_with(&format!("mcgnode {sub}"))),
            "the README shows no `mcgnode {sub}` command"
        );
    }
    for cmd in &cmds {
        if let Err(e) = mcgnode::cli::Cli::try_parse_from(words(cmd)) {
            panic!("README command `{cmd}` does not parse:\n{e}");
        }
    }
}

#[test]
fn readme_simulate_and_bag_info_commands_run_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let mut ran = 0;
    for cmd in readme_commands() {
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
            "README command `{cmd}` failed:\n{}",
            String::from_utf8_lossy(&o.stderr)
        );
        ran += 1;
    }
    assert!(ran >= 8, "ran only {ran} simulate/bag info commands");
}

/// Every relative link target in a markdown text (`](target)`), without an
/// anchor; web links are left out.
fn relative_links(text: &str) -> Vec<String> {
    text.split("](")
        .skip(1)
        .filter_map(|rest| rest.split(')').next())
        .map(|t| t.split('#').next().unwrap_or(t).to_string())
        .filter(|t| !t.is_empty() && !t.contains("://"))
        .collect()
}

#[test]
fn readme_links_and_committed_reports_hold() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let links = relative_links(&readme);
    assert!(
        links.len() >= 5,
        "found only {} links: {links:?}",
        links.len()
    );
    for link in &links {
        assert!(
            root.join(link).exists(),
            "the README links to `{link}`, which does not exist"
        );
    }
    // Each committed reproduce report: its links resolve, its command parses as
    // written, and it names no path of the machine it ran on.
    let mut reports = 0;
    for entry in std::fs::read_dir(root.join("docs")).unwrap() {
        let dir = entry.unwrap().path();
        let report = dir.join("report.md");
        if !report.exists() {
            continue;
        }
        reports += 1;
        let text = std::fs::read_to_string(&report).unwrap();
        for link in relative_links(&text) {
            assert!(
                dir.join(&link).exists(),
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
        if let Err(e) = mcgnode::cli::Cli::try_parse_from(words(cmd)) {
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
