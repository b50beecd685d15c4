//! The Python routes of the benchmarks, each a child process: for `bench load`, LeRobot's
//! `LeRobotDataset` + torch `DataLoader` (`tests/py/lerobot_baseline.py`) and our own loader
//! through its Python module `scaledp_data` (`tests/py/scaledp_data_epoch.py`, with the wheel
//! `scripts/build-python.sh` leaves in `target/wheels` unpacked onto `PYTHONPATH`), both run by
//! the benchmark Python (`.venv-bench`, from `scripts/setup-bench-python.sh`, or
//! `SCALEDP_BENCH_PYTHON`); for `bench convert`, the helpers that find a Python and run a
//! script. A route that cannot run returns `Err` with the reason, which the benchmark prints.

use std::path::{Path, PathBuf};
use std::process::Command as Process;
use std::time::Duration;

use crate::convert::{measure, Measured};
use crate::BenchLoadArgs;

const LEROBOT_SCRIPT: &str = "tests/py/lerobot_baseline.py";
const MODULE_SCRIPT: &str = "tests/py/scaledp_data_epoch.py";
const TIMEOUT: Duration = Duration::from_secs(1800);

/// What the LeRobot route did.
pub(crate) struct LeRobotRun {
    pub version: String,
    pub samples: u64,
    pub seconds: f64,
    pub init_s: f64,
    pub warmup_s: f64,
    pub m: Measured,
}

/// What the `scaledp_data` route did.
pub(crate) struct ModuleRun {
    pub samples: u64,
    pub images: u64,
    pub seconds: f64,
    pub m: Measured,
}

/// Where a route finds its Python: `env` if set, else `venv` (relative to the workspace),
/// whose absence `hint` explains.
pub(crate) struct PythonFor {
    pub env: &'static str,
    pub venv: &'static str,
    pub hint: &'static str,
}

const BENCH_PYTHON: PythonFor = PythonFor {
    env: "SCALEDP_BENCH_PYTHON",
    venv: ".venv-bench/bin/python",
    hint: "run scripts/setup-bench-python.sh, or set SCALEDP_BENCH_PYTHON",
};

/// The workspace (the directory holding `script`) and the Python to run it with.
pub(crate) fn python(
    exe: &Path,
    script: &str,
    which: &PythonFor,
) -> Result<(PathBuf, PathBuf), String> {
    let cwd = std::env::current_dir().unwrap_or_default();
    let workspace = exe
        .ancestors()
        .chain(cwd.ancestors())
        .find(|d| d.join(script).is_file())
        .ok_or_else(|| {
            format!(
                "{script} not found above {} or the current directory",
                exe.display()
            )
        })?
        .to_path_buf();
    let python = match std::env::var_os(which.env) {
        Some(p) => PathBuf::from(p),
        None => {
            let venv = workspace.join(which.venv);
            if !venv.exists() {
                return Err(format!("no {} ({})", venv.display(), which.hint));
            }
            venv
        }
    };
    Ok((workspace, python))
}

/// Runs `cmd` (a script of `python`) to the end or `timeout`, and parses its last stdout line
/// as JSON.
pub(crate) fn run_json(
    python: &Path,
    cmd: Process,
    timeout: Duration,
) -> Result<(serde_json::Value, Measured), String> {
    tracing::info!("running {cmd:?} (timeout {timeout:?})");
    let m = measure(cmd, Some(timeout)).map_err(|e| format!("{}: {e:#}", python.display()))?;
    if !m.status.success() {
        let why = m.stderr.last().map_or(String::new(), |l| format!(": {l}"));
        return Err(format!(
            "{} exited with {}{why}",
            python.display(),
            m.status
        ));
    }
    let last = m.stdout.last().ok_or("it printed nothing")?;
    let v = serde_json::from_str(last).map_err(|e| format!("bad output '{last}': {e}"))?;
    Ok((v, m))
}

/// Runs `tests/py/lerobot_baseline.py` with `workers` DataLoader workers.
pub(crate) fn run_lerobot(
    exe: &Path,
    dataset: &Path,
    cache: &Path,
    args: &BenchLoadArgs,
    workers: usize,
) -> Result<LeRobotRun, String> {
    let (workspace, python) = python(exe, LEROBOT_SCRIPT, &BENCH_PYTHON)?;
    let mut cmd = Process::new(&python);
    cmd.arg(workspace.join(LEROBOT_SCRIPT))
        .arg(dataset)
        .args(["--batches", &args.lerobot_batches.to_string()])
        .args(["--batch-size", &args.batch_size.to_string()])
        .args(["--workers", &workers.to_string()])
        .env("HF_HOME", cache.join("hf-home"))
        .env("HF_HUB_OFFLINE", "1");
    let (v, m) = run_json(&python, cmd, TIMEOUT)?;
    match (v["samples"].as_u64(), v["seconds"].as_f64()) {
        (Some(samples), Some(seconds)) if samples > 0 && seconds > 0.0 => Ok(LeRobotRun {
            version: v["lerobot"].as_str().unwrap_or("?").to_string(),
            samples,
            seconds,
            init_s: v["init_seconds"].as_f64().unwrap_or(f64::NAN),
            warmup_s: v["warmup_seconds"].as_f64().unwrap_or(f64::NAN),
            m,
        }),
        _ => Err(format!("bad baseline output {v}")),
    }
}

/// Runs one epoch of `scaledp_data.Loader` from the newest wheel in `target/wheels`.
pub(crate) fn run_module(
    exe: &Path,
    dataset: &Path,
    cache: &Path,
    args: &BenchLoadArgs,
    threads: usize,
) -> Result<ModuleRun, String> {
    let (workspace, python) = python(exe, MODULE_SCRIPT, &BENCH_PYTHON)?;
    let wheel = newest_wheel(&workspace.join("target/wheels")).ok_or_else(|| {
        format!(
            "no scaledp_data wheel in {} (run scripts/build-python.sh)",
            workspace.join("target/wheels").display()
        )
    })?;
    // A wheel is a zip of the package: unpacked, it imports from PYTHONPATH.
    let site = cache.join("py-site");
    let _ = std::fs::remove_dir_all(&site);
    let unpack = Process::new(&python)
        .args(["-m", "zipfile", "-e"])
        .arg(&wheel)
        .arg(&site)
        .output()
        .map_err(|e| format!("{}: {e}", python.display()))?;
    if !unpack.status.success() {
        return Err(format!(
            "unpacking {}: {}",
            wheel.display(),
            String::from_utf8_lossy(&unpack.stderr).trim()
        ));
    }
    let mut cmd = Process::new(&python);
    cmd.arg(workspace.join(MODULE_SCRIPT))
        .arg(dataset)
        .args(["--batch-size", &args.batch_size.to_string()])
        .args(["--threads", &threads.to_string()])
        .env("PYTHONPATH", &site);
    let (v, m) = run_json(&python, cmd, TIMEOUT)?;
    match (
        v["samples"].as_u64(),
        v["images"].as_u64(),
        v["seconds"].as_f64(),
    ) {
        (Some(samples), Some(images), Some(seconds)) if samples > 0 && seconds > 0.0 => {
            Ok(ModuleRun {
                samples,
                images,
                seconds,
                m,
            })
        }
        _ => Err(format!("bad output {v}")),
    }
}

/// The most recently written `scaledp_data-*.whl` in `dir`.
fn newest_wheel(dir: &Path) -> Option<PathBuf> {
    std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok())
        .filter(|e| {
            let n = e.file_name();
            let n = n.to_string_lossy();
            n.starts_with("scaledp_data-") && n.ends_with(".whl")
        })
        .max_by_key(|e| e.metadata().and_then(|m| m.modified()).ok())
        .map(|e| e.path())
}
