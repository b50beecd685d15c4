//! The datasets `scaledp bench load` reads, generated once into a cache directory and reused
//! while complete: the bimanual rig (2 × UR5 + Robotiq, 3 RealSense cameras) with the cameras
//! rendered by the simulator at 320×240 and at the control rate (10 Hz; the converter keeps one
//! frame per tick anyway), written as recorder-style episodes by `sim::synth` and
//! converted by the converter library (10 Hz, 320×240 JPEG q90), a few episodes at a time so
//! the raw recordings never pile up on disk. The larger dataset for the streaming run is the
//! generated one merged with itself.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_converter::{ConvertOptions, InputResult, JobOptions, Unlabeled};
use scaledp_schema::Rig;

use crate::synth::synthesize;

/// The loader's shape every route samples: observation steps and action chunk.
pub(super) const OBS_HORIZON: usize = 2;
pub(super) const ACTION_CHUNK: usize = 16;

const RIG: &str = "bimanual_ur5_3rs";
const TASK: &str = "hand the cup from the left arm to the right";
/// The stored image size.
pub const WIDTH: u32 = 320;
/// The stored image size.
pub const HEIGHT: u32 = 240;

/// What to generate.
pub struct DataSpec {
    /// Episodes.
    pub episodes: usize,
    /// Seconds per episode.
    pub seconds: f64,
    /// Threads for rendering and converting.
    pub jobs: usize,
}

/// The converter's file layout the cached datasets were written with: bump it when that
/// layout changes (2: a Parquet page per encoded frame), so stale caches are not measured.
const LAYOUT: u32 = 2;

fn name(spec: &DataSpec) -> String {
    format!("{RIG}-{}x{}s-layout{LAYOUT}", spec.episodes, spec.seconds)
}

/// The marker written beside a dataset once it is complete.
fn marker(cache: &Path, name: &str) -> PathBuf {
    cache.join(format!("{name}.complete.json"))
}

/// Whether `cache/name` was completed by the same recipe (`how`).
fn complete(cache: &Path, name: &str, how: &str) -> bool {
    let recipe = std::fs::read(marker(cache, name))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| v["recipe"].as_str().map(str::to_string));
    recipe.as_deref() == Some(how) && cache.join(name).join("meta/info.json").is_file()
}

fn mark(cache: &Path, name: &str, how: &str, seconds: f64) -> Result<()> {
    let path = marker(cache, name);
    std::fs::write(
        &path,
        serde_json::json!({ "recipe": how, "seconds": seconds }).to_string(),
    )
    .with_context(|| format!("writing {}", path.display()))
}

fn bar(len: u64, what: &str) -> ProgressBar {
    let style = ProgressStyle::with_template(&format!(
        "{{spinner}} [{{elapsed_precise}}] {{bar:30}} {{pos}}/{{len}} {what} {{msg}}"
    ))
    .unwrap_or_else(|_| ProgressStyle::default_bar());
    ProgressBar::new(len).with_style(style)
}

/// The generated dataset under `cache` (made if absent or incomplete) and how it was made.
pub fn ensure_dataset(cache: &Path, spec: &DataSpec) -> Result<(PathBuf, String)> {
    let name = name(spec);
    let dir = cache.join(&name);
    let how = format!(
        "{} episodes × {} s of {RIG} (3 RealSense cameras rendered by the simulator at {WIDTH}×{HEIGHT} rgb8 10 Hz, the control rate, 2 UR5 + Robotiq), written by sim::synth as recordings and converted by the converter library at 10 Hz into {WIDTH}×{HEIGHT} JPEG q90",
        spec.episodes, spec.seconds
    );
    if complete(cache, &name, &how) {
        return Ok((dir, format!("{how}; reused from the cache")));
    }
    std::fs::create_dir_all(cache).with_context(|| format!("creating {}", cache.display()))?;
    // Larger datasets merged from an older copy are stale now.
    for entry in std::fs::read_dir(cache).with_context(|| format!("reading {}", cache.display()))? {
        let path = entry?.path();
        let stale = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with(&format!("{name}-x")) && n.ends_with(".complete.json"));
        if stale {
            std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
        }
    }
    let t0 = Instant::now();
    generate(cache, &dir, spec)?;
    let seconds = t0.elapsed().as_secs_f64();
    mark(cache, &name, &how, seconds)?;
    Ok((dir, format!("{how}; generated in {seconds:.0} s")))
}

fn generate(cache: &Path, dir: &Path, spec: &DataSpec) -> Result<()> {
    let mut rig = Rig::load_or_builtin(RIG).with_context(|| format!("loading rig {RIG}"))?;
    let control_rate_hz = rig.control_rate_hz;
    for c in &mut rig.cameras {
        c.width = WIDTH;
        c.height = HEIGHT;
        // One frame per control tick: the converter keeps one per tick anyway.
        c.fps = control_rate_hz;
    }
    let tmp = cache.join("recordings.tmp");
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).with_context(|| format!("clearing {}", tmp.display()))?;
    }
    std::fs::create_dir_all(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    let jobs = spec.jobs.max(1);
    let opts = |overwrite: bool| {
        JobOptions::default()
            .convert(
                ConvertOptions::default()
                    .rig(rig.clone())
                    .size(WIDTH, HEIGHT)
                    // The simulator's recordings hold the training streams only.
                    .depth(false),
            )
            .overwrite(overwrite)
            .jobs(jobs)
            .unlabeled(Unlabeled::Keep)
    };
    let progress = bar(spec.episodes as u64, "episodes generated");
    progress.set_message(format!("into {}", dir.display()));
    let step = 2 * jobs;
    for first in (0..spec.episodes).step_by(step) {
        let ids: Vec<usize> = (first..(first + step).min(spec.episodes)).collect();
        let inputs = synthesize(&tmp, &rig, &ids, spec.seconds, TASK, jobs)?;
        let results = scaledp_converter::run(&inputs, dir, &opts(first == 0), &|_| {})
            .with_context(|| format!("converting into {}", dir.display()))?;
        for (path, outcome) in results {
            match outcome {
                InputResult::Converted(_) => {}
                InputResult::Skipped(why) => bail!("{}: skipped: {why}", path.display()),
                InputResult::Failed(e) => bail!("{}", e.one_line()),
            }
            std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
        }
        progress.inc(ids.len() as u64);
    }
    progress.finish_and_clear();
    std::fs::remove_dir_all(&tmp).ok();
    Ok(())
}

/// `factor` copies of `dataset` merged into one (made if absent or incomplete), and how.
pub fn ensure_larger(
    cache: &Path,
    dataset: &Path,
    spec: &DataSpec,
    factor: usize,
) -> Result<(PathBuf, String)> {
    let name = format!("{}-x{factor}", name(spec));
    let dir = cache.join(&name);
    let how = format!(
        "{} episodes: the dataset merged with itself {factor}× (scaledp dataset merge), each copy under its own episode indices and rows, so every episode is read and decoded from its own rows (contents repeat)",
        spec.episodes * factor
    );
    if complete(cache, &name, &how) {
        return Ok((dir, format!("{how}; reused from the cache")));
    }
    let progress = bar(0, "");
    progress.set_message(format!("merging {factor} copies into {}", dir.display()));
    progress.enable_steady_tick(Duration::from_millis(200));
    let t0 = Instant::now();
    let inputs = vec![dataset.to_path_buf(); factor];
    scaledp_converter::merge(&inputs, &dir, 100)
        .with_context(|| format!("merging into {}", dir.display()))?;
    progress.finish_and_clear();
    let seconds = t0.elapsed().as_secs_f64();
    mark(cache, &name, &how, seconds)?;
    Ok((dir, format!("{how}; merged in {seconds:.0} s")))
}
