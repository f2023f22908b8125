//! Every `ellipso` command the README and `docs/` quote for a user to type, checked against the
//! command line itself: the README's shell blocks and command table, every `sh`/`bash` block of
//! `docs/*.md`, and `ellipso model --help`'s examples.
//!
//! Contract (tests only): each quoted command parses with this build's flags (a renamed flag, a
//! missing required argument or a bad value fails the test, naming the file and the command);
//! the ones that only compute and print (`ellipso model fresnel|dop|mueller`) also run and
//! must succeed. Placeholders in upper case are values a user fills in: paths stay as written,
//! the numeric ones are given a value here ([`PLACEHOLDERS`]); `[optional]` parts are included,
//! and of alternatives (`a|b`, `a \| b` in a table) each is checked.
//! Fragments inside prose (`` `ellipso fit --json` ``) are not commands and are not checked.

use std::path::{Path, PathBuf};

use clap::Parser;

use super::Cli;

/// Numeric placeholders and the value each is checked with.
const PLACEHOLDERS: &[(&str, &str)] = &[
    ("N", "100"),
    ("I", "0"),
    ("S", "1"),
    ("X", "0.001"),
    ("P", "10"),
    ("T", "100"),
    ("I/N", "0/2"),
    ("R,X,Y,Z", "0.02,0,0,0.02"),
];

/// A quoted command: where it is, and its words after `ellipso`.
#[derive(Debug)]
struct Quoted {
    at: String,
    words: Vec<String>,
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("host/ has a parent")
        .to_path_buf()
}

/// The README and every `docs/*.md`, with their paths.
fn markdown_files() -> Vec<(PathBuf, String)> {
    let root = repo_root();
    let mut paths = vec![root.join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .map(|e| e.expect("docs entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    paths.extend(docs);
    paths
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p).expect("read markdown");
            (p, text)
        })
        .collect()
}

/// The words after `ellipso` (or `cargo run --release --`) of one shell line, `None` when the
/// line runs something else.
fn ellipso_words(line: &str) -> Option<Vec<String>> {
    let line = line.trim().trim_start_matches("$ ");
    // a trailing comment is the doc's, not the shell's
    let line = match line.find(" #") {
        Some(i) => &line[..i],
        None => line,
    };
    let words = shlex::split(line)?;
    let rest = match words.first().map(String::as_str) {
        Some("ellipso") => &words[1..],
        Some("cargo")
            if words.get(1..4) == Some(&["run".into(), "--release".into(), "--".into()]) =>
        {
            &words[4..]
        }
        _ => return None,
    };
    Some(rest.to_vec())
}

/// The commands of the shell blocks (`sh`, `bash`, `console`, `shell` fences) of `text`:
/// `\` continuations joined, `&&` chains split.
fn fenced_commands(file: &str, text: &str) -> Vec<Quoted> {
    let mut out = Vec::new();
    let mut shell: Option<bool> = None;
    let mut pending = String::new();
    for (n, line) in text.lines().enumerate() {
        if let Some(tag) = line.trim_start().strip_prefix("```") {
            shell = match shell {
                Some(_) => None,
                None => Some(matches!(tag.trim(), "sh" | "bash" | "console" | "shell")),
            };
            continue;
        }
        if shell != Some(true) {
            continue;
        }
        if let Some(head) = line.strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        pending.push_str(line);
        let joined = std::mem::take(&mut pending);
        for part in joined.split("&&") {
            if let Some(words) = ellipso_words(part) {
                out.push(Quoted {
                    at: format!("{file}:{}", n + 1),
                    words,
                });
            }
        }
    }
    out
}

/// The commands of the README's command table (its first column's code span).
fn table_commands(file: &str, text: &str) -> Vec<Quoted> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let Some(rest) = line.strip_prefix("| `ellipso ") else {
            continue;
        };
        let span = rest.split('`').next().unwrap_or_default();
        // a table cell escapes `|`; each alternative is its own command
        let span = span.replace("\\|", "|");
        for words in expand(&format!("ellipso {span}")) {
            out.push(Quoted {
                at: format!("{file}:{}", n + 1),
                words: words[1..].to_vec(),
            });
        }
    }
    out
}

/// A synopsis expanded: `[…]` included, each alternative of `a|b` words (and of a
/// `[x | y]` group's first choice) as its own command, placeholders filled.
fn expand(synopsis: &str) -> Vec<Vec<String>> {
    // an optional group with alternatives inside keeps its first choice
    let mut text = String::new();
    let mut rest = synopsis;
    while let Some(open) = rest.find('[') {
        text.push_str(&rest[..open]);
        let close = rest[open..].find(']').map_or(rest.len(), |c| open + c);
        let group = &rest[open + 1..close];
        text.push_str(group.split(" | ").next().unwrap_or_default());
        rest = rest.get(close + 1..).unwrap_or_default();
    }
    text.push_str(rest);
    let words: Vec<&str> = text.split_whitespace().collect();
    // the alternatives of the first word with `|` (a subcommand list), the first elsewhere
    let variants: Vec<Vec<String>> = match words.iter().position(|w| w.contains('|')) {
        Some(i) if i <= 2 => words[i]
            .split('|')
            .map(|alt| {
                let mut v: Vec<&str> = words.clone();
                v[i] = alt;
                v.iter().map(|w| w.to_string()).collect()
            })
            .collect(),
        _ => vec![words.iter().map(|w| w.to_string()).collect()],
    };
    variants
        .into_iter()
        .map(|v| v.into_iter().map(|w| fill(&w)).collect())
        .collect()
}

/// A placeholder's value ([`PLACEHOLDERS`]); of `a|b`, the first; any other word as written.
fn fill(word: &str) -> String {
    if let Some((_, value)) = PLACEHOLDERS.iter().find(|(p, _)| *p == word) {
        return (*value).to_string();
    }
    match word.split_once('|') {
        Some((first, _)) if !word.starts_with('-') => first.to_string(),
        _ => word.to_string(),
    }
}

/// Every quoted command of the README, `docs/` and `ellipso model --help`.
fn quoted() -> Vec<Quoted> {
    let root = repo_root();
    let mut all = Vec::new();
    for (path, text) in markdown_files() {
        let file = path
            .strip_prefix(&root)
            .unwrap_or(&path)
            .display()
            .to_string();
        for mut q in fenced_commands(&file, &text) {
            q.words = q.words.iter().map(|w| fill(w)).collect();
            all.push(q);
        }
        if file == "README.md" {
            all.extend(table_commands(&file, &text));
        }
    }
    let examples = crate::cli::model::EXAMPLES.replace("\\\n", " ");
    for line in examples.lines().skip(1) {
        if let Some(words) = ellipso_words(line) {
            all.push(Quoted {
                at: "ellipso model --help".into(),
                words,
            });
        }
    }
    all
}

#[test]
fn every_quoted_command_parses_and_the_model_ones_run() {
    let all = quoted();
    // the README's table alone quotes some twenty commands: an extraction that finds few is broken
    assert!(all.len() > 40, "only {} quoted commands found", all.len());
    let mut failures = Vec::new();
    let mut ran = 0;
    for q in &all {
        let argv = std::iter::once("ellipso".to_string()).chain(q.words.iter().cloned());
        match Cli::try_parse_from(argv) {
            Err(e) => failures.push(format!(
                "{}: `ellipso {}`: {}",
                q.at,
                q.words.join(" "),
                e.render().to_string().lines().next().unwrap_or_default()
            )),
            Ok(cli) => {
                if q.words.first().is_some_and(|w| w == "model")
                    && q.words.get(1).is_some_and(|w| w != "plot")
                {
                    ran += 1;
                    if let Err(e) = super::run(cli.command) {
                        failures.push(format!("{}: `ellipso {}`: {e:#}", q.at, q.words.join(" ")));
                    }
                }
            }
        }
    }
    assert!(ran >= 3, "only {ran} model commands ran");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_extraction_follows_continuations_chains_and_tables() {
    let text = "```sh\nellipso fit S --mesh M \\\n    --out O   # comment\nls && ellipso view D\n```\n\
                ```yaml\nellipso nothing\n```\n| `ellipso model a\\|b` | x |\n";
    let fenced = fenced_commands("t.md", text);
    let words: Vec<String> = fenced.iter().map(|q| q.words.join(" ")).collect();
    assert_eq!(words, ["fit S --mesh M --out O", "view D"]);
    let table: Vec<String> = table_commands("t.md", text)
        .iter()
        .map(|q| q.words.join(" "))
        .collect();
    assert_eq!(table, ["model a", "model b"]);
    assert_eq!(
        expand("ellipso mesh DIR --out m.ply [--vertices N] [--frames N | --frame I]"),
        [[
            "ellipso",
            "mesh",
            "DIR",
            "--out",
            "m.ply",
            "--vertices",
            "100",
            "--frames",
            "100"
        ]]
    );
}
