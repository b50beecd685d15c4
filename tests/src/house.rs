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
    // Inline `mod name { … }` blocks: the brace depth each opened at. Inside one, `super::`
    // is this file's own module.
    let mut inline: Vec<i64> = Vec::new();
    let mut nesting = 0i64;
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
        let t = code.trim_start();
        let t = t
            .strip_prefix("pub(crate) ")
            .or_else(|| t.strip_prefix("pub "))
            .unwrap_or(t);
        if t.starts_with("mod ") && t.trim_end().ends_with('{') {
            inline.push(nesting);
        }
        nesting += code.matches('{').count() as i64 - code.matches('}').count() as i64;
        let line = if inline.is_empty() {
            code.to_string()
        } else {
            code.replacen("super::", "self::", 1)
        };
        while inline.last().is_some_and(|d| nesting <= *d) {
            inline.pop();
        }
        out.push_str(&line);
        out.push('\n');
    }
    out
}

/// The paths a `use` tree names, expanded (`a::{b, c::d as e}` → `a::b`, `a::c::d`).
fn expand_use(prefix: &[String], tree: &str, out: &mut Vec<Vec<String>>) {
    let tree = tree.trim();
    if tree.is_empty() {
        return;
    }
    if let Some(open) = tree.find('{') {
        let head: Vec<String> = tree[..open]
            .split("::")
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(String::from)
            .collect();
        let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
        let base: Vec<String> = prefix.iter().cloned().chain(head).collect();
        // Split the group on top-level commas.
        let (mut depth, mut start) = (0, 0);
        for (i, c) in inner.char_indices() {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    expand_use(&base, &inner[start..i], out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        expand_use(&base, &inner[start..], out);
        return;
    }
    let path = tree.split(" as ").next().unwrap_or(tree);
    let mut full: Vec<String> = prefix.to_vec();
    full.extend(
        path.split("::")
            .map(str::trim)
            .filter(|s| !s.is_empty() && *s != "self")
            .map(String::from),
    );
    out.push(full);
}

/// A file's `use` statements (expanded), each with whether it is re-exported (`pub use`), and
/// its code with the `use` statements taken out.
fn split_uses(text: &str) -> (Vec<(bool, Vec<String>)>, String) {
    let mut uses = Vec::new();
    let mut code = String::new();
    let mut rest = text;
    while let Some(pos) = find_use(rest) {
        code.push_str(&rest[..pos]);
        let stmt_start = pos;
        let after = &rest[stmt_start..];
        let end = after.find(';').unwrap_or(after.len());
        let stmt = &after[..end];
        let public = stmt.trim_start().starts_with("pub");
        let tree = &stmt[stmt.find("use ").map_or(0, |u| u + 4)..];
        let mut paths = Vec::new();
        expand_use(&[], tree, &mut paths);
        uses.extend(paths.into_iter().map(|p| (public, p)));
        rest = &after[(end + 1).min(after.len())..];
    }
    code.push_str(rest);
    (uses, code)
}

/// Where the next `use` statement (with its visibility) starts.
fn find_use(text: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(i) = text[from..].find("use ") {
        let at = from + i;
        let line_start = text[..at].rfind('\n').map_or(0, |n| n + 1);
        let before = text[line_start..at].trim();
        if before.is_empty() || before.starts_with("pub") {
            return Some(
                line_start + text[line_start..].len() - text[line_start..].trim_start().len(),
            );
        }
        from = at + 4;
    }
    None
}

/// One file as the graph sees it: its module path, its uses and its code.
struct File {
    uses: Vec<(bool, Vec<String>)>,
    code: String,
}

/// The module a path names from inside `own`, through re-exports (`pub use`) to the module
/// that defines the item; `None` for paths outside the crate.
fn resolve(
    own: &[String],
    path: &[String],
    files: &BTreeMap<String, File>,
    depth: usize,
) -> Option<String> {
    let mut base: Vec<String> = Vec::new();
    let mut k = 0;
    match path.first().map(String::as_str) {
        Some("crate") => k = 1,
        Some("self") => {
            base = own.to_vec();
            k = 1;
        }
        Some("super") => {
            base = own.to_vec();
            while path.get(k).map(String::as_str) == Some("super") {
                base.pop();
                k += 1;
            }
        }
        Some(first) => {
            let child: Vec<String> = own.iter().cloned().chain([first.to_string()]).collect();
            if !files.contains_key(&child.join("::")) {
                return None;
            }
            base = own.to_vec();
        }
        None => return None,
    }
    let mut module = base.clone();
    let mut j = k;
    while j < path.len() {
        let mut next = module.clone();
        next.push(path[j].clone());
        if files.contains_key(&next.join("::")) {
            module = next;
            j += 1;
        } else {
            break;
        }
    }
    let name = module.join("::");
    // The item after the module: follow the module's re-export of it, if any.
    if let (Some(item), Some(file), true) = (path.get(j), files.get(&name), depth < 6) {
        for (public, used) in &file.uses {
            if *public && used.last() == Some(item) {
                if let Some(m) = resolve(&module, used, files, depth + 1) {
                    return Some(m);
                }
            }
        }
    }
    files.contains_key(&name).then_some(name)
}

/// The paths with `::` in a file's code (outside its `use` statements).
fn code_paths(code: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b':';
    let mut i = 0;
    while i < bytes.len() {
        if !code.is_char_boundary(i) || (i > 0 && ident(bytes[i - 1])) {
            i += 1;
            continue;
        }
        let rest = &code[i..];
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
            .unwrap_or(rest.len());
        if end > 0 && rest[..end].contains("::") {
            out.push(
                rest[..end]
                    .split("::")
                    .filter(|s| !s.is_empty())
                    .map(String::from)
                    .collect(),
            );
        }
        i += end.max(1);
    }
    out
}

/// Whether paths written inline in code (`crate::a::f()`) count as imports too.
const INLINE_PATHS: bool = false;

/// Each file's modules it refers to (itself and the crate root's declarations aside).
fn graph(known: &BTreeMap<String, PathBuf>) -> BTreeMap<String, BTreeSet<String>> {
    let files: BTreeMap<String, File> = known
        .iter()
        .map(|(m, p)| {
            let text = main_path_text(&std::fs::read_to_string(p).unwrap_or_default());
            let (uses, code) = split_uses(&text);
            (m.clone(), File { uses, code })
        })
        .collect();
    files
        .iter()
        .map(|(m, f)| {
            let own: Vec<String> = if m.is_empty() {
                vec![]
            } else {
                m.split("::").map(String::from).collect()
            };
            let inline = if INLINE_PATHS {
                code_paths(&f.code)
            } else {
                Vec::new()
            };
            let refs = f
                .uses
                .iter()
                .map(|(_, p)| p.clone())
                .chain(inline)
                .filter_map(|p| resolve(&own, &p, &files, 0))
                .filter(|t| t != m)
                .collect();
            (m.clone(), refs)
        })
        .collect()
}

/// The strongly connected groups (more than one file) of a crate's import graph.
fn circles(src: &Path) -> Vec<Vec<String>> {
    let graph = graph(&modules(src));
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

/// Each circle of imports between the files of a crate's main path, as `crate: a ↔ b ↔ c`,
/// with the imports that make it (`a → b`).
pub fn import_circles(root: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for krate in crates(root) {
        let name = krate
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let src = krate.join("src");
        let g = graph(&modules(&src));
        let file = |m: &str| {
            if m.is_empty() {
                "lib".to_string()
            } else {
                m.replace("::", "/")
            }
        };
        for group in circles(&src) {
            let files: Vec<String> = group.iter().map(|m| file(m)).collect();
            let edges: Vec<String> = group
                .iter()
                .flat_map(|a| {
                    g.get(a)
                        .into_iter()
                        .flatten()
                        .filter(|b| group.contains(b))
                        .map(move |b| format!("{} → {}", file(a), file(b)))
                })
                .collect();
            out.push(format!(
                "{name}: {} ({})",
                files.join(" ↔ "),
                edges.join(", ")
            ));
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
        std::fs::write(src.join("lib.rs"), "mod a;\nmod b;\nmod d;\nuse d::Top;\n").unwrap();
        std::fs::write(src.join("d.rs"), "use crate::b::Z;\n").unwrap();
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
        // `a ↔ b` through `crate::` and `super::`; the root reaches `d` by a relative path,
        // and `d` reaches `b`, which is no circle.
        assert_eq!(circles(&src), vec![vec!["a".to_string(), "b".to_string()]]);
        std::fs::write(src.join("b.rs"), "pub use super::a::Y;\nuse crate::Top;\n").unwrap();
        assert_eq!(
            circles(&src),
            vec![vec![
                "".to_string(),
                "a".to_string(),
                "b".to_string(),
                "d".to_string()
            ]]
        );
    }
}
