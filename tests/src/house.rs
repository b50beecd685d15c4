//! The house rules a reader relies on, checked on the source tree: no circle of imports
//! between the files of a crate's main path (test code aside), and no file much over 500
//! lines. Plain text analysis (comments and test modules stripped, `crate::`, `super::` and
//! `self::` paths resolved to the files that define the modules), so it needs no compiler.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// One crate's source files by module path (`""` for the crate root, `a::b`).
fn modules(src: &Path) -> BTreeMap<String, PathBuf> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            if p.extension().is_none_or(|x| x != "rs") || is_test_file(&p) {
                continue;
            }
            let rel = p.strip_prefix(src).unwrap_or(&p).with_extension("");
            let mut parts: Vec<String> = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if matches!(
                parts.last().map(String::as_str),
                Some("mod" | "lib" | "main")
            ) {
                parts.pop();
            }
            if parts.first().is_some_and(|p| p == "bin") {
                continue;
            }
            out.insert(parts.join("::"), p);
        }
    }
    out
}

fn is_test_file(p: &Path) -> bool {
    let name = p
        .file_stem()
        .map(|s| s.to_string_lossy())
        .unwrap_or_default();
    name == "tests" || name.ends_with("_tests") || name == "fuzz"
}

/// The text with comments and `#[cfg(test)]` items removed.
fn main_path_text(text: &str) -> String {
    let mut out = String::new();
    let mut skip_test_item = false;
    let mut depth = 0i64;
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or("");
        if line.trim_start().starts_with("#[cfg(test)]") {
            skip_test_item = true;
            depth = 0;
            continue;
        }
        if skip_test_item {
            depth += code.matches('{').count() as i64 - code.matches('}').count() as i64;
            // `mod tests;` (no braces) or a braced item that closed.
            if depth <= 0 && (code.contains(';') || code.contains('}')) {
                skip_test_item = false;
            }
            continue;
        }
        out.push_str(code);
        out.push('\n');
    }
    out
}

/// The modules a file's code refers to, resolved against the modules that exist.
fn references(own: &str, text: &str, known: &BTreeMap<String, PathBuf>) -> BTreeSet<String> {
    let own_parts: Vec<&str> = if own.is_empty() {
        vec![]
    } else {
        own.split("::").collect()
    };
    let mut out = BTreeSet::new();
    let bytes = text.as_bytes();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b':';
    let mut i = 0;
    while i < bytes.len() {
        if !text.is_char_boundary(i) {
            i += 1;
            continue;
        }
        let rest = &text[i..];
        let start = ["crate::", "super::", "self::"]
            .iter()
            .find(|p| rest.starts_with(**p) && (i == 0 || !ident(bytes[i - 1])));
        let Some(_) = start else {
            i += 1;
            continue;
        };
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
            .unwrap_or(rest.len());
        let path: Vec<&str> = rest[..end].split("::").filter(|s| !s.is_empty()).collect();
        i += end.max(1);
        let mut base: Vec<&str> = Vec::new();
        let mut k = 0;
        match path.first() {
            Some(&"crate") => k = 1,
            Some(&"self") => {
                base = own_parts.clone();
                k = 1;
            }
            Some(&"super") => {
                base = own_parts.clone();
                while path.get(k) == Some(&"super") {
                    base.pop();
                    k += 1;
                }
            }
            _ => continue,
        }
        // The longest prefix that names a module file.
        let mut target = base.join("::");
        let mut cur = base.clone();
        for seg in &path[k..] {
            cur.push(seg);
            let name = cur.join("::");
            if known.contains_key(&name) {
                target = name;
            } else {
                break;
            }
        }
        if target != own && known.contains_key(&target) {
            out.insert(target);
        }
    }
    out
}

/// The strongly connected groups (more than one file) of a crate's import graph.
fn circles(src: &Path) -> Vec<Vec<String>> {
    let known = modules(src);
    let graph: BTreeMap<String, BTreeSet<String>> = known
        .iter()
        .map(|(m, p)| {
            let text = std::fs::read_to_string(p).unwrap_or_default();
            (m.clone(), references(m, &main_path_text(&text), &known))
        })
        .collect();
    // Kosaraju: two depth-first passes.
    fn visit(
        n: &str,
        g: &BTreeMap<String, BTreeSet<String>>,
        seen: &mut BTreeSet<String>,
        out: &mut Vec<String>,
    ) {
        if !seen.insert(n.to_string()) {
            return;
        }
        for m in g.get(n).into_iter().flatten() {
            visit(m, g, seen, out);
        }
        out.push(n.to_string());
    }
    let mut order = Vec::new();
    let mut seen = BTreeSet::new();
    for n in graph.keys() {
        visit(n, &graph, &mut seen, &mut order);
    }
    let mut reverse: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (a, bs) in &graph {
        for b in bs {
            reverse.entry(b.clone()).or_default().insert(a.clone());
        }
    }
    let mut seen = BTreeSet::new();
    let mut groups = Vec::new();
    for n in order.iter().rev() {
        let mut group = Vec::new();
        visit(n, &reverse, &mut seen, &mut group);
        if group.len() > 1 {
            group.sort();
            groups.push(group);
        }
    }
    groups
}

/// Every crate directory of the workspace (those with a `src/`).
fn crates(root: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(root)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("Cargo.toml").exists() && p.join("src").is_dir())
        .collect();
    out.sort();
    out
}

/// Each circle of imports between the files of a crate's main path, as `crate: a ↔ b ↔ c`.
pub fn import_circles(root: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for krate in crates(root) {
        let name = krate
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        for group in circles(&krate.join("src")) {
            let files: Vec<String> = group
                .iter()
                .map(|m| {
                    if m.is_empty() {
                        "lib".to_string()
                    } else {
                        m.replace("::", "/")
                    }
                })
                .collect();
            out.push(format!("{name}: {}", files.join(" ↔ ")));
        }
    }
    out
}

/// Source files (tests included) over `limit` lines, with their length.
pub fn long_files(root: &Path, limit: usize) -> Vec<String> {
    let mut out = Vec::new();
    for krate in crates(root) {
        let mut stack = vec![krate.clone()];
        while let Some(dir) = stack.pop() {
            for e in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
                let p = e.path();
                if p.is_dir() && p.file_name().is_some_and(|n| n != "target") {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| x == "rs") {
                    let n = std::fs::read_to_string(&p).map_or(0, |t| t.lines().count());
                    if n > limit {
                        let rel = p.strip_prefix(root).unwrap_or(&p);
                        out.push(format!("{} ({n} lines)", rel.display()));
                    }
                }
            }
        }
    }
    out.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_circle_between_two_files_is_found_and_test_code_is_not_counted() {
        let dir = tempfile::tempdir().unwrap();
        let src = dir.path().join("src");
        std::fs::create_dir_all(src.join("a")).unwrap();
        std::fs::write(src.join("lib.rs"), "mod a;\nmod b;\n").unwrap();
        std::fs::write(
            src.join("a/mod.rs"),
            "mod c;\nuse crate::b::X; // crate::c\n",
        )
        .unwrap();
        std::fs::write(src.join("b.rs"), "pub use super::a::Y;\n").unwrap();
        std::fs::write(
            src.join("a/c.rs"),
            "use super::Z;\n#[cfg(test)]\nmod tests {\n    use crate::b::Q;\n}\n",
        )
        .unwrap();
        assert_eq!(circles(&src), vec![vec!["a".to_string(), "b".to_string()]]);
    }
}
