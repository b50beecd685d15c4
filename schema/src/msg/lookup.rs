//! Definitions of types scaledp does not know, from `.msg` files, composed the way rosbag2's
//! `LocalMessageDefinitionSource` composes them: the root file's text as it is (comments
//! included), then each dependency not yet written, in sorted order and depth-first, after
//! `"\n" + 80 '=' + "\nMSG: <type as the field names it>\n"`. A dependency no file provides is
//! taken from scaledp's own definitions (`std_msgs/Header` without ROS installed).

use std::collections::{BTreeSet, HashMap, HashSet};
use std::path::{Path, PathBuf};

use super::texts::{definition, own_text, short_name};

/// Field types that are not messages (rosbag2's list, and `wstring`).
const PRIMITIVES: &[&str] = &[
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string", "wstring",
];

/// Deepest nesting followed before a definition is given up as circular.
const MAX_DEPTH: usize = 50;

/// Where `.msg` files are looked for, and the definitions found so far.
///
/// A type `pkg/msg/Name` is looked up as `<dir>/share/<pkg>/msg/Name.msg` and
/// `<dir>/<pkg>/msg/Name.msg` under each directory, in the order they were added: the
/// prefixes of `AMENT_PREFIX_PATH` (an installed ROS 2 and its overlays) and `--msg-path`
/// directories (a prefix, a `share` directory or a source tree of message packages).
#[derive(Debug, Clone, Default)]
pub struct MsgSearch {
    dirs: Vec<PathBuf>,
    cache: HashMap<String, Option<String>>,
}

impl MsgSearch {
    /// No directories: only scaledp's own definitions.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds every prefix of an `AMENT_PREFIX_PATH` value (`:`-separated).
    pub fn ament_prefix_path(mut self, value: &str) -> Self {
        self.dirs.extend(
            value
                .split(':')
                .filter(|p| !p.is_empty())
                .map(PathBuf::from),
        );
        self
    }

    /// Adds a directory to search.
    pub fn dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.dirs.push(dir.into());
        self
    }

    /// The directories searched, in order.
    pub fn dirs(&self) -> &[PathBuf] {
        &self.dirs
    }

    /// The `ros2msg` definition of `type_name` (`pkg/msg/Name` or `pkg/Name`): scaledp's own for
    /// the types it knows, else composed from `.msg` files; `None` when the type or one of its
    /// dependencies is found nowhere.
    pub fn definition(&mut self, type_name: &str) -> Option<String> {
        if let Some(known) = definition(type_name) {
            return Some(known);
        }
        if let Some(found) = self.cache.get(type_name) {
            return found.clone();
        }
        let mut seen = HashSet::new();
        let found = self.full_text(type_name, &mut seen, MAX_DEPTH);
        self.cache.insert(type_name.to_string(), found.clone());
        found
    }

    /// The `.msg` file of a type, if a directory holds one.
    fn file_text(&self, type_name: &str) -> Option<String> {
        let parts: Vec<&str> = type_name.split('/').collect();
        let (pkg, ns, name) = match parts.as_slice() {
            [pkg, name] => (*pkg, "msg", *name),
            [pkg, ns, name] => (*pkg, *ns, *name),
            _ => return None,
        };
        let file = Path::new(pkg).join(ns).join(format!("{name}.msg"));
        self.dirs
            .iter()
            .flat_map(|d| [d.join("share").join(&file), d.join(&file)])
            .find_map(|p| std::fs::read_to_string(p).ok())
    }

    fn full_text(
        &self,
        type_name: &str,
        seen: &mut HashSet<String>,
        depth: usize,
    ) -> Option<String> {
        if depth == 0 {
            return None;
        }
        let text = self
            .file_text(type_name)
            .or_else(|| own_text(type_name).map(str::to_owned))?;
        let package = type_name.split('/').next().unwrap_or_default();
        let mut out = text.clone();
        for dep in dependencies(&text, package) {
            if seen.insert(short_name(&dep)) {
                out.push('\n');
                out.push_str(&"=".repeat(80));
                out.push_str("\nMSG: ");
                out.push_str(&dep);
                out.push('\n');
                out.push_str(&self.full_text(&dep, seen, depth - 1)?);
            }
        }
        Some(out)
    }
}

/// The message types a `.msg` text's fields use, sorted: each line's leading type (an array
/// suffix dropped) when it is followed by whitespace and is not a primitive; a type without a
/// package belongs to `package`. Comment lines start with `#` and name none.
fn dependencies(text: &str, package: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for line in text.lines() {
        let line = line.trim_start();
        let end = line
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '/'))
            .unwrap_or(line.len());
        let (ty, rest) = line.split_at(end);
        let rest = match rest.strip_prefix('[') {
            Some(r) => match r.split_once(']') {
                Some((_, after)) => after,
                None => continue,
            },
            None => rest,
        };
        if ty.is_empty() || !rest.starts_with(char::is_whitespace) || PRIMITIVES.contains(&ty) {
            continue;
        }
        out.insert(if ty.contains('/') {
            ty.to_string()
        } else {
            format!("{package}/{ty}")
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dependencies_are_read_like_rosbag2() {
        let text = "# a comment naming geometry_msgs/Pose\nstd_msgs/Header header  # trailing\n\
                    Inner[] items\nInner[<=3] few\nuint8 A=1\nstring<=8 short\n  float64[9] k\n";
        let deps: Vec<String> = dependencies(text, "my_msgs").into_iter().collect();
        assert_eq!(deps, ["my_msgs/Inner", "std_msgs/Header"]);
    }

    #[test]
    fn unknown_types_come_from_msg_files_with_their_dependencies() {
        let dir = std::env::temp_dir().join(format!("scaledp-msgsearch-{}", std::process::id()));
        let msg = dir.join("share/my_msgs/msg");
        std::fs::create_dir_all(&msg).unwrap();
        std::fs::write(
            msg.join("Outer.msg"),
            "# Outer\nstd_msgs/Header header\nInner[] items\n",
        )
        .unwrap();
        std::fs::write(
            msg.join("Inner.msg"),
            "float64 value\nstd_msgs/Header stamp_too\n",
        )
        .unwrap();
        let mut search =
            MsgSearch::new().ament_prefix_path(&format!("/nonexistent:{}", dir.display()));
        let def = search.definition("my_msgs/msg/Outer").unwrap();
        let line = "=".repeat(80);
        // Sorted dependencies, each once, depth-first; Header (no file here) from scaledp.
        let want = format!(
            "# Outer\nstd_msgs/Header header\nInner[] items\n\n{line}\nMSG: my_msgs/Inner\n\
             float64 value\nstd_msgs/Header stamp_too\n\n{line}\nMSG: std_msgs/Header\n\
             builtin_interfaces/Time stamp\nstring frame_id\n\n{line}\nMSG: builtin_interfaces/Time\n\
             int32 sec\nuint32 nanosec\n"
        );
        assert_eq!(def, want);
        assert_eq!(
            super::super::stamp::StampField::of_definition(&def),
            super::super::stamp::StampField::Leading
        );
        // Known types are scaledp's own; unknown ones (or with a missing dependency) are None.
        assert_eq!(
            search.definition("sensor_msgs/msg/Image"),
            definition("sensor_msgs/msg/Image")
        );
        assert_eq!(search.definition("my_msgs/msg/Missing"), None);
        std::fs::write(msg.join("Broken.msg"), "Missing m\n").unwrap();
        assert_eq!(search.definition("my_msgs/msg/Broken"), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
