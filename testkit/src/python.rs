//! The project's Python interpreters and the `scaledp_data` wheel, looked up in one place: an
//! explicit path (a flag), else the venv's variable, else the venv in the workspace root.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::{workspace_root, Error, Result};

/// A venv of the project: where it lives, what makes it, what overrides it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Venv {
    /// Its directory, relative to the workspace root.
    pub dir: &'static str,
    /// The variable naming an interpreter to use instead.
    pub env: &'static str,
    /// The script that makes it, relative to the workspace root.
    pub setup: &'static str,
    /// What it holds, for messages.
    pub provides: &'static str,
}

/// `.venv`: the Python peers of the tests (rosbags, mcap, mcap_ros2, pyarrow, Pillow, moto).
pub const TEST_VENV: Venv = Venv {
    dir: ".venv",
    env: "SCALEDP_PYTHON",
    setup: "scripts/setup-python.sh",
    provides: "rosbags, mcap, pyarrow, Pillow and moto",
};

/// `.venv-bench`: LeRobot and torch (several GB), for the benchmarks and the LeRobot video
/// conformance tests.
pub const BENCH_VENV: Venv = Venv {
    dir: ".venv-bench",
    env: "SCALEDP_BENCH_PYTHON",
    setup: "scripts/setup-bench-python.sh",
    provides: "LeRobot and torch",
};

impl Venv {
    /// The interpreter: `explicit` if given, else `$env` if set (either may be a command on
    /// `PATH`, used as given), else `<root>/<dir>/bin/python`, which must exist (`root`: the
    /// workspace root, None when there is none).
    pub fn python(&self, explicit: Option<&Path>, root: Option<&Path>) -> Result<PathBuf> {
        if let Some(p) = explicit {
            return Ok(p.to_path_buf());
        }
        if let Some(p) = std::env::var_os(self.env).filter(|p| !p.is_empty()) {
            return Ok(p.into());
        }
        let path = root.map(|r| r.join(self.dir).join("bin/python"));
        match path {
            Some(p) if p.exists() => Ok(p),
            path => Err(Error::NoPython {
                path,
                venv: self.dir,
                setup: self.setup,
                provides: self.provides,
                env: self.env,
            }),
        }
    }
}

/// The newest `scaledp_data-*.whl` in `dir`, else in `$SCALEDP_WHEEL_DIR`, else in
/// `<root>/target/wheels` (where `scripts/build-python.sh` leaves it; `root`: the workspace
/// root, None when there is none).
pub fn scaledp_data_wheel(dir: Option<&Path>, root: Option<&Path>) -> Result<PathBuf> {
    let dir = dir
        .map(Path::to_path_buf)
        .or_else(|| {
            std::env::var_os("SCALEDP_WHEEL_DIR")
                .filter(|d| !d.is_empty())
                .map(PathBuf::from)
        })
        .or_else(|| root.map(|r| r.join("target/wheels")));
    let Some(dir) = dir else {
        return Err(Error::NoWheel { dir: None });
    };
    let wheels = std::fs::read_dir(&dir).into_iter().flatten().flatten();
    wheels
        .filter(|e| {
            let name = e.file_name();
            let name = name.to_string_lossy();
            name.starts_with("scaledp_data-") && name.ends_with(".whl")
        })
        .max_by_key(|e| e.metadata().and_then(|m| m.modified()).ok())
        .map(|e| e.path())
        .ok_or(Error::NoWheel { dir: Some(dir) })
}

/// The tests' Python ([`TEST_VENV`]).
///
/// # Panics
/// When it is missing, saying to run `scripts/setup-python.sh`.
pub fn python() -> PathBuf {
    TEST_VENV
        .python(None, Some(&workspace_root()))
        .unwrap_or_else(|e| panic!("{e} (scripts/test.sh does)"))
}

/// Runs `tests/py/<script>` with `args` on the tests' Python and returns its stdout parsed as
/// JSON.
///
/// # Panics
/// When the script cannot run, fails, or prints something else than one JSON value.
pub fn run_python(script: &str, args: &[&Path]) -> serde_json::Value {
    let out = Command::new(python())
        .arg(workspace_root().join("tests/py").join(script))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("running {script}: {e}"));
    assert!(
        out.status.success(),
        "{script} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{script} printed no JSON: {e}"))
}

/// Runs `tests/py/lerobot_video.py` with `args` on LeRobot 0.4.4's Python ([`BENCH_VENV`]),
/// with `HF_HOME` at `home` and the Hub offline; the last line it prints, parsed as JSON.
///
/// # Panics
/// When the venv is missing (saying what to run), or the script fails or prints no JSON.
pub fn lerobot_video(args: &[&str], home: &Path) -> serde_json::Value {
    let root = workspace_root();
    let py = BENCH_VENV
        .python(None, Some(&root))
        .unwrap_or_else(|e| panic!("{e} (scripts/test.sh does)"));
    let out = Command::new(py)
        .arg(root.join("tests/py/lerobot_video.py"))
        .args(args)
        .env("HF_HOME", home)
        .env("HF_HUB_OFFLINE", "1")
        .output()
        .unwrap_or_else(|e| panic!("running lerobot_video.py: {e}"));
    assert!(
        out.status.success(),
        "lerobot_video.py {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(last)
        .unwrap_or_else(|e| panic!("lerobot_video.py {args:?} printed no JSON ({e}): {stdout}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_explicit_interpreter_wins_and_a_missing_venv_says_what_to_run() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let explicit = Path::new("/opt/python");
        assert_eq!(
            BENCH_VENV
                .python(Some(explicit), Some(dir.path()))
                .ok()
                .as_deref(),
            Some(explicit)
        );
        if std::env::var_os(BENCH_VENV.env).is_none() {
            let e = BENCH_VENV
                .python(None, Some(dir.path()))
                .expect_err("no venv in an empty directory");
            let text = e.to_string();
            assert!(
                text.contains("bash scripts/setup-bench-python.sh")
                    && text.contains("SCALEDP_BENCH_PYTHON"),
                "{text}"
            );
            let e = BENCH_VENV.python(None, None).expect_err("no workspace");
            assert!(
                e.to_string().contains("not inside the scaledp checkout"),
                "{e}"
            );
        }
    }

    #[test]
    fn the_newest_wheel_is_picked_and_none_is_an_error() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let e = scaledp_data_wheel(Some(dir.path()), None).expect_err("no wheel");
        assert!(e.to_string().contains("scripts/build-python.sh"), "{e}");
        let old = dir
            .path()
            .join("scaledp_data-0.1.0-cp311-abi3-linux_x86_64.whl");
        std::fs::write(&old, b"old").expect("a file");
        std::fs::write(dir.path().join("numpy-2.0.whl"), b"other").expect("a file");
        assert_eq!(scaledp_data_wheel(Some(dir.path()), None).ok(), Some(old));
    }
}
