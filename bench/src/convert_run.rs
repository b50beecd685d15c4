//! One `scaledp convert` child process, measured (wall time, peak RSS, CPU), for the convert
//! benchmark's routes.

use std::path::Path;
use std::process::Command as Process;

use anyhow::{bail, Context, Result};
use scaledp_testkit::{measure, Measured};

/// Converts `recordings` into `out` (cleared first) with `--jobs jobs` and `extra` arguments.
pub(crate) fn scaledp_convert(
    exe: &Path,
    recordings: &Path,
    out: &Path,
    jobs: usize,
    extra: &[&str],
) -> Result<Measured> {
    if out.exists() {
        std::fs::remove_dir_all(out).with_context(|| format!("clearing {}", out.display()))?;
    }
    let mut c = Process::new(exe);
    c.arg("convert")
        .arg(recordings)
        .arg("--out")
        .arg(out)
        .arg("--jobs")
        .arg(jobs.to_string())
        // The generated recordings are unlabelled (too short for the scripted operator to
        // finish) and hold the training streams only (no depth).
        .args(["--unlabeled", "keep", "--no-depth"])
        .args(extra);
    tracing::info!("running {c:?}");
    let m = measure(c, None).context("running scaledp convert")?;
    if !m.status.success() {
        bail!(
            "scaledp convert {} exited with {}: {}",
            extra.join(" "),
            m.status,
            m.stderr.last().map_or("", String::as_str)
        );
    }
    Ok(m)
}
