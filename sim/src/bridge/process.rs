//! Starting the bridge's Python process: its sources (embedded in this binary, written once to
//! a content-named directory so a build never runs another build's bridge) and the interpreter
//! that has the simulators installed.

use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// The bridge package's files, as `sim/bridges/scaledp_bridge/` holds them.
const SOURCES: &[(&str, &str)] = &[
    (
        "__init__.py",
        include_str!("../../bridges/scaledp_bridge/__init__.py"),
    ),
    (
        "__main__.py",
        include_str!("../../bridges/scaledp_bridge/__main__.py"),
    ),
    (
        "protocol.py",
        include_str!("../../bridges/scaledp_bridge/protocol.py"),
    ),
    (
        "cameras.py",
        include_str!("../../bridges/scaledp_bridge/cameras.py"),
    ),
    (
        "metaworld_env.py",
        include_str!("../../bridges/scaledp_bridge/metaworld_env.py"),
    ),
    (
        "aloha_env.py",
        include_str!("../../bridges/scaledp_bridge/aloha_env.py"),
    ),
];

/// The environment variable naming the Python to run the bridge with.
pub const PYTHON_ENV: &str = "SCALEDP_SIM_PYTHON";
/// Where `scripts/setup-sims.sh` puts its Python, under the repository root.
pub const VENV: &str = ".venv-sims";

fn bad(what: &str, reason: impl std::fmt::Display) -> Error {
    Error::Bridge {
        what: what.to_string(),
        reason: reason.to_string(),
    }
}

/// The directory holding `scaledp_bridge/` (written on first use).
pub(crate) fn sources_dir() -> Result<PathBuf> {
    let mut h = blake3::Hasher::new();
    for (name, text) in SOURCES {
        h.update(name.as_bytes());
        h.update(text.as_bytes());
    }
    let tag = h.finalize().to_hex();
    let root = std::env::temp_dir().join(format!("scaledp-bridge-{}", &tag[..16]));
    let pkg = root.join("scaledp_bridge");
    if pkg.join("__main__.py").exists() {
        return Ok(root);
    }
    // Written aside and renamed, so two processes starting at once never see half a package.
    static WRITERS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = WRITERS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = std::env::temp_dir().join(format!(
        "scaledp-bridge-{}.{}.{n}.partial",
        &tag[..16],
        std::process::id()
    ));
    let io = |e: std::io::Error| {
        bad(
            "writing the bridge's sources",
            format!("{}: {e}", tmp.display()),
        )
    };
    std::fs::create_dir_all(tmp.join("scaledp_bridge")).map_err(io)?;
    for (name, text) in SOURCES {
        std::fs::write(tmp.join("scaledp_bridge").join(name), text).map_err(io)?;
    }
    match std::fs::rename(&tmp, &root) {
        Ok(()) => Ok(root),
        // Another process got there first: its copy is the same bytes.
        Err(_) if pkg.join("__main__.py").exists() => {
            let _ = std::fs::remove_dir_all(&tmp);
            Ok(root)
        }
        Err(e) => Err(io(e)),
    }
}

/// The Python with the simulators: `$SCALEDP_SIM_PYTHON`, else `.venv-sims/bin/python` in the
/// working directory, one of its parents, or a parent of this executable (a build in
/// `target/release/` of a checkout).
pub fn python() -> Result<PathBuf> {
    if let Some(p) = std::env::var_os(PYTHON_ENV).filter(|p| !p.is_empty()) {
        let p = PathBuf::from(p);
        return if p.exists() {
            Ok(p)
        } else {
            Err(bad(
                "the simulator's Python",
                format!("{PYTHON_ENV}={} does not exist", p.display()),
            ))
        };
    }
    let mut starts: Vec<PathBuf> = Vec::new();
    if let Ok(d) = std::env::current_dir() {
        starts.push(d);
    }
    if let Some(d) = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(Path::to_path_buf))
    {
        starts.push(d);
    }
    for start in &starts {
        for dir in start.ancestors() {
            let p = dir.join(VENV).join("bin/python");
            if p.exists() {
                return Ok(p);
            }
        }
    }
    Err(bad(
        "the simulator's Python",
        format!(
            "no {VENV}/bin/python here or above, and {PYTHON_ENV} is not set: run \
             `bash scripts/setup-sims.sh` in the scaledp checkout (MetaWorld, MuJoCo and \
             gym-aloha into {VENV}), or point {PYTHON_ENV} at a Python that has them"
        ),
    ))
}

#[cfg(test)]
mod tests {
    /// Every module of the bridge package is embedded: one left out fails only when the bridge
    /// imports it, in a process the tests see as "the bridge exited".
    #[test]
    fn every_bridge_module_is_embedded() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/bridges/scaledp_bridge");
        let mut on_disk: Vec<String> = std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("{dir}: {e}"))
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| n.ends_with(".py"))
            .collect();
        on_disk.sort();
        let mut embedded: Vec<String> = super::SOURCES.iter().map(|(n, _)| n.to_string()).collect();
        embedded.sort();
        assert_eq!(on_disk, embedded);
    }
}
