//! ROS bag fixtures written by the Python `rosbags` package (`tests/py/make_bags.py`): ROS 1
//! bags with none / bz2 / lz4 chunks and rosbag2 directories with mcap and sqlite3 storage.

use std::path::Path;
use std::process::Command;

use crate::{python, workspace_root};

/// Writes the fixtures into `dir`, 3 s of messages each (the script's default), and returns
/// what they hold (`expected.json`: per file the topics, types and counts).
///
/// # Panics
/// When the tests' Python is missing or the script fails.
pub fn make_bags(dir: &Path) -> serde_json::Value {
    write(dir, None)
}

/// [`make_bags`] with `seconds` of messages in each fixture.
///
/// # Panics
/// When the tests' Python is missing or the script fails.
pub fn make_bags_lasting(dir: &Path, seconds: f64) -> serde_json::Value {
    write(dir, Some(seconds))
}

fn write(dir: &Path, seconds: Option<f64>) -> serde_json::Value {
    let mut cmd = Command::new(python());
    cmd.arg(workspace_root().join("tests/py/make_bags.py"))
        .arg(dir);
    if let Some(s) = seconds {
        cmd.args(["--seconds", &s.to_string()]);
    }
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("running make_bags.py: {e}"));
    assert!(
        out.status.success(),
        "make_bags.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let expected = dir.join("expected.json");
    let text = std::fs::read_to_string(&expected)
        .unwrap_or_else(|e| panic!("{}: {e}", expected.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", expected.display()))
}
