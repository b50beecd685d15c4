//! `bench load`'s video datasets: a generated JPEG dataset copied and its cameras turned into
//! LeRobot video features by `make_video_dataset.py` on the benchmark Python (PyAV with
//! LeRobot 0.4.4's encoder settings; each episode encoded on its own, 100 episodes to a file by
//! stream copy, as LeRobot's writer does), cached beside the source and reused while complete.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use crate::python::{Python, MAKE_VIDEO};

/// Episodes per video file (LeRobot starts a new file at `video_files_size_in_mb`; 100 of our
/// 20-s episodes at 320×240 stay far below its 200 MB).
const EPISODES_PER_FILE: usize = 100;

/// Copies every file under `from` into `to` (which must not exist).
fn copy_dir(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    for entry in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let entry = entry?;
        let (src, dst) = (entry.path(), to.join(entry.file_name()));
        if entry.file_type()?.is_dir() {
            copy_dir(&src, &dst)?;
        } else {
            std::fs::copy(&src, &dst)
                .with_context(|| format!("copying {} to {}", src.display(), dst.display()))?;
        }
    }
    Ok(())
}

/// The camera keys of a dataset's `info.json` stored as images.
fn image_keys(dataset: &Path) -> Result<Vec<String>> {
    let path = dataset.join("meta/info.json");
    let info: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?,
    )
    .with_context(|| format!("parsing {}", path.display()))?;
    let mut keys: Vec<String> = info["features"]
        .as_object()
        .context("info.json without features")?
        .iter()
        .filter(|(_, f)| f["dtype"] == "image")
        .map(|(k, _)| k.clone())
        .collect();
    keys.sort();
    Ok(keys)
}

/// `source` with its cameras as `codec` video (made if absent or incomplete), and how.
pub fn ensure_video(py: &Python, source: &Path, codec: &str) -> Result<(PathBuf, String)> {
    let name = source
        .file_name()
        .and_then(|n| n.to_str())
        .context("a dataset directory name")?;
    let dir = source.with_file_name(format!("{name}-{codec}"));
    let marker = source.with_file_name(format!("{name}-{codec}.complete.json"));
    let how = format!(
        "the same frames as {codec} video features ({}; encoded from the JPEGs by PyAV {EPISODES_PER_FILE} episodes to a file, as LeRobot 0.4.4 writes them)",
        match codec {
            "av1" => "libsvtav1, yuv420p, g=2, crf 30, preset 12",
            _ => "libx264, yuv420p, g=2, crf 23",
        }
    );
    let done = std::fs::read(&marker)
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .is_some_and(|v| v["recipe"] == how.as_str());
    if done && dir.join("meta/info.json").is_file() {
        return Ok((dir, format!("{how}; reused from the cache")));
    }
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("clearing {}", dir.display()))?;
    }
    let t0 = Instant::now();
    copy_dir(source, &dir)?;
    let keys = image_keys(&dir)?.join(",");
    let scratch = tempfile::Builder::new()
        .prefix("scaledp-video-parts")
        .tempdir()
        .context("a scratch directory")?;
    let mut cmd = py
        .command(&MAKE_VIDEO)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    cmd.arg(&dir)
        .arg(scratch.path())
        .args(["--keys", &keys, "--codec", codec, "--no-reference"])
        .args(["--episodes-per-file", &EPISODES_PER_FILE.to_string()]);
    tracing::info!("encoding {} as {codec} video: {cmd:?}", source.display());
    py.run_json(cmd, Duration::from_secs(6 * 3600))
        .map_err(|e| anyhow::anyhow!("making the {codec} video dataset: {e}"))?;
    let seconds = t0.elapsed().as_secs_f64();
    if !dir.join("videos").is_dir() {
        bail!("{}: no videos/ after encoding", dir.display());
    }
    std::fs::write(
        &marker,
        serde_json::json!({ "recipe": how, "seconds": seconds }).to_string(),
    )
    .with_context(|| format!("writing {}", marker.display()))?;
    Ok((dir, format!("{how}; encoded in {seconds:.0} s")))
}
