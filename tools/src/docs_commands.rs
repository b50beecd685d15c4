//! Every `scaledp` command a reader meets in `README.md` and `docs/` parses with this CLI, and
//! the rigs, presets and arms it names exist: a renamed flag fails the tests, not a reader.
//! (`docs/results/historical/` is a frozen record and is left out.) The cheap commands also
//! run end to end in the tests that exercise them (`tests/tests/cycle_cli.rs` and others);
//! this check reaches every one.

use std::path::{Path, PathBuf};

use clap::Parser;

use crate::cli::Cli;

/// One command as written: where, and its arguments after `scaledp`.
#[derive(Debug)]
pub(crate) struct DocCommand {
    pub file: PathBuf,
    pub line: usize,
    pub args: Vec<String>,
    /// The arguments as written, shell variables and all.
    pub raw: Vec<String>,
}

/// The Markdown files a reader meets: the README and `docs/` (but `docs/results/historical/`).
fn documents(root: &Path) -> Vec<PathBuf> {
    let mut out = vec![root.join("README.md")];
    let mut stack = vec![root.join("docs")];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                if !p.ends_with("results/historical") {
                    stack.push(p);
                }
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The `scaledp …` commands in the ```sh / ```bash blocks of `text` (continuation lines
/// joined; `cargo run … --bin scaledp -- ARGS` counts as `scaledp ARGS`; several commands on a
/// line, split at `&&`, `||`, `|` and `;`).
pub(crate) fn commands_in(file: &Path, text: &str) -> Vec<DocCommand> {
    let mut out = Vec::new();
    let mut in_shell = false;
    let mut pending = String::new();
    let mut pending_line = 0;
    for (i, line) in text.lines().enumerate() {
        let fence = line.trim_start();
        if let Some(lang) = fence.strip_prefix("```") {
            in_shell = !in_shell && matches!(lang.trim(), "sh" | "bash" | "shell" | "console");
            pending.clear();
            continue;
        }
        if !in_shell {
            continue;
        }
        let code = line.trim();
        let code = code.strip_prefix("$ ").unwrap_or(code);
        if pending.is_empty() {
            pending_line = i + 1;
        }
        if let Some(head) = code.strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        pending.push_str(code);
        let joined = std::mem::take(&mut pending);
        // Comments after the command.
        let joined = match joined.find(" #") {
            Some(k) => &joined[..k],
            None => joined.as_str(),
        };
        let Some(tokens) = shlex::split(joined) else {
            continue;
        };
        for part in tokens.split(|t| matches!(t.as_str(), "&&" | "||" | "|" | ";")) {
            let part: Vec<String> = part
                .iter()
                .map(|t| t.trim_end_matches(';').to_string())
                .collect();
            let cargo = part.first().is_some_and(|t| t == "cargo");
            let bin = part
                .windows(2)
                .any(|w| w[0] == "--bin" && w[1] == "scaledp");
            let start = if cargo {
                bin.then(|| part.iter().position(|t| t == "--").map(|k| k + 1))
                    .flatten()
            } else {
                part.iter().position(|t| t == "scaledp").map(|k| k + 1)
            };
            if let Some(start) = start {
                out.push(DocCommand {
                    file: file.to_path_buf(),
                    line: pending_line,
                    args: part[start..].iter().map(|t| placeholders(t)).collect(),
                    raw: part[start..].to_vec(),
                });
            }
        }
    }
    out
}

/// A shell variable (`$e`, `${T}`) stands for a value the reader sets: `1`, which every
/// numeric flag takes and a path may be. Flags naming a rig, preset or arm through a variable
/// are parsed but not looked up.
fn placeholders(token: &str) -> String {
    if !token.contains('$') {
        return token.to_string();
    }
    let mut out = String::new();
    let mut chars = token.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '$' {
            out.push(c);
            continue;
        }
        if chars.peek() == Some(&'{') {
            for d in chars.by_ref() {
                if d == '}' {
                    break;
                }
            }
        } else {
            while chars
                .peek()
                .is_some_and(|d| d.is_ascii_alphanumeric() || *d == '_')
            {
                chars.next();
            }
        }
        out.push('1');
    }
    out
}

/// What is wrong with one command, if anything.
pub(crate) fn check(c: &DocCommand, root: &Path) -> Option<String> {
    let argv = std::iter::once("scaledp".to_string()).chain(c.args.iter().cloned());
    if let Err(e) = Cli::try_parse_from(argv) {
        use clap::error::ErrorKind::{DisplayHelp, DisplayVersion};
        if !matches!(e.kind(), DisplayHelp | DisplayVersion) {
            let first = e.to_string();
            let first = first.lines().next().unwrap_or_default().to_string();
            return Some(first);
        }
        return None;
    }
    let value = |flag: &str| -> Vec<&str> {
        c.raw
            .windows(2)
            .filter(|w| w[0] == flag)
            .map(|w| w[1].as_str())
            .filter(|v| !v.contains('$'))
            .collect()
    };
    for rig in value("--rig") {
        let path = root.join(rig);
        let looks_like_a_path = rig.contains(".toml");
        if !looks_like_a_path
            && !path.exists()
            && scaledp_schema::Rig::load_or_builtin(rig).is_err()
        {
            return Some(format!("--rig {rig}: no shipped rig of that name"));
        }
    }
    for preset in value("--preset") {
        if !scaledp_policy::PRESETS.contains(&preset) {
            return Some(format!("--preset {preset}: no such preset"));
        }
    }
    for arms in value("--arms") {
        for arm in arms.split(',') {
            if scaledp_experiment::ARMS.iter().all(|a| a.name != arm) {
                return Some(format!("--arms {arm}: no such arm"));
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn root() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
    }

    #[test]
    fn every_command_in_the_readme_and_docs_parses() {
        let root = root();
        let mut all = Vec::new();
        for doc in documents(&root) {
            let text = std::fs::read_to_string(&doc).unwrap();
            all.extend(commands_in(&doc, &text));
        }
        let readme = all.iter().filter(|c| c.file.ends_with("README.md")).count();
        assert!(
            readme >= 10 && all.len() >= 40,
            "only {readme} commands in the README and {} in all: is the extraction broken?",
            all.len()
        );
        let faults: Vec<String> = all
            .iter()
            .filter_map(|c| {
                check(c, &root).map(|why| {
                    let file = c.file.strip_prefix(&root).unwrap_or(&c.file);
                    format!(
                        "{}:{}: scaledp {}: {why}",
                        file.display(),
                        c.line,
                        c.args.join(" ")
                    )
                })
            })
            .collect();
        assert!(
            faults.is_empty(),
            "{} of {} documented commands fail:\n{}",
            faults.len(),
            all.len(),
            faults.join("\n")
        );
    }

    #[test]
    fn the_extraction_reads_shell_blocks_only_and_joins_lines() {
        let text = "```sh\nscaledp convert a \\\n  --out b   # a comment\ncd x && scaledp view b\n\
                    cargo run --release --bin scaledp -- demo\n```\n\
                    ```text\nscaledp not-a-command\n```\nscaledp prose\n";
        let cs = commands_in(Path::new("x.md"), text);
        let args: Vec<String> = cs.iter().map(|c| c.args.join(" ")).collect();
        assert_eq!(args, ["convert a --out b", "view b", "demo"]);
        assert_eq!(cs[0].line, 2);
        let command = |args: &[&str]| DocCommand {
            file: "x.md".into(),
            line: 1,
            args: args.iter().map(|t| placeholders(t)).collect(),
            raw: args.iter().map(|t| t.to_string()).collect(),
        };
        assert!(check(&command(&["convert", "--no-such-flag"]), &root()).is_some());
        assert!(check(&command(&["predict", "r", "d", "--episode", "$e"]), &root()).is_none());
        assert!(check(&command(&["predict", "r", "d", "--episode", "e"]), &root()).is_some());
        let rig = command(&["sim", "--rig", "no_such_rig"]);
        assert!(check(&rig, &root()).unwrap().contains("no shipped rig"));
    }
}
