//! The Python routes of the benchmarks, each a child process running a script compiled into
//! this crate (written to a temporary directory at run time, so nothing depends on where the
//! executable sits): for `bench convert`, the usual single-process route from recordings to
//! parquet (`convert_baseline.py`: rosbags + numpy + Pillow + pyarrow, on the tests' Python);
//! for `bench load`, LeRobot's `LeRobotDataset` + torch `DataLoader` (`lerobot_baseline.py`)
//! and our own loader through its Python module `scaledp_data` (`scaledp_data_epoch.py`, with
//! the wheel `scripts/build-python.sh` builds unpacked onto `PYTHONPATH`), both on the
//! benchmark Python; for `bench train`, the training step of the wheel's PyTorch ScaleDP module
//! (`bench_train_torch.py` with `scaledp_data.policy` from the unpacked wheel) on the benchmark
//! Python. The interpreter: `--python`, else the venv's variable, else the venv in the
//! workspace found from the current directory upward (`scaledp_testkit::Venv`). A route that
//! cannot run says why ([`NotRun`]); the benchmark prints that instead of a figure.

use std::fmt;
use std::path::{Path, PathBuf};
use std::process::Command as Process;
use std::time::Duration;

use scaledp_testkit::{measure, scaledp_data_wheel, workspace_from_current_dir, Measured, Venv};

/// A Python route's script, compiled in.
pub struct Script {
    pub(crate) name: &'static str,
    pub(crate) text: &'static str,
}

/// `bench convert`'s baseline: recordings → parquet, one process.
const CONVERT_BASELINE: Script = Script {
    name: "convert_baseline.py",
    text: include_str!("../../tests/py/convert_baseline.py"),
};
/// `bench load`'s LeRobot route.
const LEROBOT_BASELINE: Script = Script {
    name: "lerobot_baseline.py",
    text: include_str!("../../tests/py/lerobot_baseline.py"),
};
/// `bench load`'s video dataset: image features → LeRobot video features (PyAV).
pub(crate) const MAKE_VIDEO: Script = Script {
    name: "make_video_dataset.py",
    text: include_str!("../../tests/py/make_video_dataset.py"),
};
/// `bench load`'s `scaledp_data` route.
const MODULE_EPOCH: Script = Script {
    name: "scaledp_data_epoch.py",
    text: include_str!("../../tests/py/scaledp_data_epoch.py"),
};

/// Why a Python route gave no figure.
#[derive(Clone)]
pub enum NotRun {
    /// `--no-python`.
    Skipped,
    /// The interpreter or the wheel is missing: what is missing and what to run.
    NotSetUp(String),
    /// It ran and failed.
    Failed(String),
}

impl fmt::Display for NotRun {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NotRun::Skipped => write!(f, "--no-python"),
            NotRun::NotSetUp(why) | NotRun::Failed(why) => write!(f, "{why}"),
        }
    }
}

/// A Python interpreter and a temporary directory for the scripts it runs.
pub struct Python {
    exe: PathBuf,
    /// The workspace holding the current directory, if any (for the wheel).
    root: Option<PathBuf>,
    scripts: tempfile::TempDir,
}

impl Python {
    /// `venv`'s interpreter, or `explicit`.
    pub fn locate(venv: &Venv, explicit: Option<&Path>) -> Result<Python, NotRun> {
        let root = workspace_from_current_dir().ok();
        let exe = venv
            .python(explicit, root.as_deref())
            .map_err(|e| NotRun::NotSetUp(format!("{e} (or pass --python)")))?;
        let scripts = tempfile::Builder::new()
            .prefix("scaledp-bench-py")
            .tempdir()
            .map_err(|e| NotRun::Failed(format!("a directory for the scripts: {e}")))?;
        Ok(Python { exe, root, scripts })
    }

    /// Writes `script` into the scripts' directory (once), for a script that imports it from
    /// beside itself; returns its path.
    pub fn install(&self, script: &Script) -> Result<PathBuf, NotRun> {
        let path = self.scripts.path().join(script.name);
        if !path.exists() {
            std::fs::write(&path, script.text)
                .map_err(|e| NotRun::Failed(format!("writing {}: {e}", path.display())))?;
        }
        Ok(path)
    }

    /// A command running `script` (written out on first use).
    pub fn command(&self, script: &Script) -> Result<Process, NotRun> {
        let mut cmd = Process::new(&self.exe);
        cmd.arg(self.install(script)?);
        Ok(cmd)
    }

    /// Runs `cmd` to the end or `timeout` and parses its last stdout line as JSON.
    pub fn run_json(
        &self,
        cmd: Process,
        timeout: Duration,
    ) -> Result<(serde_json::Value, Measured), NotRun> {
        tracing::info!("running {cmd:?} (timeout {timeout:?})");
        let failed = |why: String| NotRun::Failed(format!("{}: {why}", self.exe.display()));
        let m = measure(cmd, Some(timeout)).map_err(|e| NotRun::Failed(e.to_string()))?;
        if !m.status.success() {
            let why = m.stderr.last().map_or(String::new(), |l| format!(": {l}"));
            return Err(failed(format!("exited with {}{why}", m.status)));
        }
        let last = m
            .stdout
            .last()
            .ok_or_else(|| failed("printed nothing".into()))?;
        let v =
            serde_json::from_str(last).map_err(|e| failed(format!("bad output '{last}': {e}")))?;
        Ok((v, m))
    }

    /// The newest `scaledp_data` wheel, unpacked into `site` (a wheel is a zip of the package:
    /// unpacked, it imports from `PYTHONPATH`).
    pub fn unpack_wheel(&self, site: &Path) -> Result<(), NotRun> {
        let wheel = scaledp_data_wheel(None, self.root.as_deref())
            .map_err(|e| NotRun::NotSetUp(e.to_string()))?;
        let _ = std::fs::remove_dir_all(site);
        let unpack = Process::new(&self.exe)
            .args(["-m", "zipfile", "-e"])
            .arg(&wheel)
            .arg(site)
            .output()
            .map_err(|e| NotRun::Failed(format!("{}: {e}", self.exe.display())))?;
        if !unpack.status.success() {
            return Err(NotRun::Failed(format!(
                "unpacking {}: {}",
                wheel.display(),
                String::from_utf8_lossy(&unpack.stderr).trim()
            )));
        }
        Ok(())
    }
}

/// What the convert baseline did.
pub struct ConvertRun {
    pub frames: u64,
    /// Its own timer, from after its imports to the end.
    pub seconds: f64,
    pub m: Measured,
}

/// `convert_baseline.py RECORDINGS OUT`, given 2 minutes + twice the recorded time.
pub fn run_convert_baseline(
    py: &Python,
    recordings: &Path,
    out: &Path,
    recorded_s: f64,
) -> Result<ConvertRun, NotRun> {
    let mut cmd = py.command(&CONVERT_BASELINE)?;
    cmd.arg(recordings).arg(out);
    let timeout = Duration::from_secs_f64(120.0 + 2.0 * recorded_s);
    let (v, m) = py.run_json(cmd, timeout)?;
    match (v["frames"].as_u64(), v["seconds"].as_f64()) {
        (Some(frames), Some(seconds)) if frames > 0 && seconds > 0.0 => {
            Ok(ConvertRun { frames, seconds, m })
        }
        _ => Err(NotRun::Failed(format!("bad baseline output {v}"))),
    }
}

/// Time limit of the `bench load` routes.
const LOAD_TIMEOUT: Duration = Duration::from_secs(1800);

/// What the LeRobot route did.
pub struct LeRobotRun {
    pub version: String,
    pub samples: u64,
    pub seconds: f64,
    pub init_s: f64,
    pub warmup_s: f64,
    pub m: Measured,
}

/// What the `scaledp_data` route did.
pub struct ModuleRun {
    pub samples: u64,
    pub images: u64,
    pub seconds: f64,
    pub m: Measured,
}

/// What `bench load` asks of its Python routes.
pub struct LoadRoute<'a> {
    pub dataset: &'a Path,
    /// Scratch space (the HF home, the unpacked wheel).
    pub cache: &'a Path,
    pub batch_size: usize,
    /// DataLoader workers / loader threads.
    pub threads: usize,
    /// Batches LeRobot's DataLoader is timed over.
    pub lerobot_batches: usize,
}

/// LeRobot's `LeRobotDataset` + torch `DataLoader` with `threads` workers.
pub fn run_lerobot(py: &Python, r: &LoadRoute) -> Result<LeRobotRun, NotRun> {
    let mut cmd = py.command(&LEROBOT_BASELINE)?;
    cmd.arg(r.dataset)
        .args(["--video-backend", "pyav"])
        .args(["--batches", &r.lerobot_batches.to_string()])
        .args(["--batch-size", &r.batch_size.to_string()])
        .args(["--workers", &r.threads.to_string()])
        .env("HF_HOME", r.cache.join("hf-home"))
        .env("HF_HUB_OFFLINE", "1");
    let (v, m) = py.run_json(cmd, LOAD_TIMEOUT)?;
    match (v["samples"].as_u64(), v["seconds"].as_f64()) {
        (Some(samples), Some(seconds)) if samples > 0 && seconds > 0.0 => Ok(LeRobotRun {
            version: v["lerobot"].as_str().unwrap_or("?").to_string(),
            samples,
            seconds,
            init_s: v["init_seconds"].as_f64().unwrap_or(f64::NAN),
            warmup_s: v["warmup_seconds"].as_f64().unwrap_or(f64::NAN),
            m,
        }),
        _ => Err(NotRun::Failed(format!("bad baseline output {v}"))),
    }
}

/// One epoch of `scaledp_data.Loader` from the newest wheel.
pub fn run_module(py: &Python, r: &LoadRoute) -> Result<ModuleRun, NotRun> {
    let site = r.cache.join("py-site");
    py.unpack_wheel(&site)?;
    let mut cmd = py.command(&MODULE_EPOCH)?;
    cmd.arg(r.dataset)
        .args(["--batch-size", &r.batch_size.to_string()])
        .args(["--threads", &r.threads.to_string()])
        .env("PYTHONPATH", &site);
    let (v, m) = py.run_json(cmd, LOAD_TIMEOUT)?;
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
        _ => Err(NotRun::Failed(format!("bad output {v}"))),
    }
}
