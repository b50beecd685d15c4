//! What can go wrong in the helpers the benchmarks use at run time.

use std::path::PathBuf;

/// A helper's failure, naming the file, program or setting at fault.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The current directory cannot be read.
    #[error("reading the current directory: {0}")]
    CurrentDir(#[source] std::io::Error),
    /// No directory at or above `start` holds a `Cargo.toml` with a `[workspace]` table.
    #[error("no Cargo workspace (a Cargo.toml with [workspace]) in {} or above it", start.display())]
    NoWorkspace {
        /// Where the search started.
        start: PathBuf,
    },
    /// A venv's interpreter is missing, or the workspace that would hold it.
    #[error(
        "no Python with {provides}: {}; run `bash {setup}` in the scaledp checkout, or set {env} to a Python that has them",
        missing(.path, .venv)
    )]
    NoPython {
        /// The interpreter looked for; None when no workspace was found to look in.
        path: Option<PathBuf>,
        /// The venv's directory in the workspace.
        venv: &'static str,
        /// The script that makes the venv.
        setup: &'static str,
        /// What the venv holds.
        provides: &'static str,
        /// The variable that overrides the interpreter.
        env: &'static str,
    },
    /// No `scaledp_data-*.whl` in the wheel directory.
    #[error(
        "no scaledp_data wheel {}: run `bash scripts/build-python.sh` in the scaledp checkout, or set SCALEDP_WHEEL_DIR to a directory holding one",
        .dir.as_ref().map_or("(not inside the scaledp checkout, so no target/wheels)".into(), |d| format!("in {}", d.display()))
    )]
    NoWheel {
        /// The directory searched; None when no workspace was found to look in.
        dir: Option<PathBuf>,
    },
    /// No loopback port could be bound.
    #[error("binding a free loopback port: {0}")]
    Port(#[source] std::io::Error),
    /// A child process could not be started or waited for.
    #[error("{program}: {source}")]
    Process {
        /// The program run.
        program: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A child process ran past its time limit and was killed.
    #[error("{program}: killed after {seconds:.0} s, its time limit")]
    TimedOut {
        /// The program run.
        program: String,
        /// Seconds it ran.
        seconds: f64,
    },
}

/// The helpers' result.
pub type Result<T, E = Error> = std::result::Result<T, E>;

fn missing(path: &Option<PathBuf>, venv: &str) -> String {
    match path {
        Some(p) => format!("{} is missing", p.display()),
        None => format!("not inside the scaledp checkout, so no {venv}"),
    }
}
