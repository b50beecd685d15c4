//! The loader epoch `bench load` measures: `scaledp bench load --worker MODE --dataset DIR`
//! runs it in its own process (re-executing the current binary) and prints a JSON line, which
//! the benchmark reads back with the child's peak memory and CPU time.

use std::path::Path;
use std::process::Command as Process;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use scaledp_datasets::LoaderOptions;
use scaledp_testkit::{measure, Measured};

use super::data::{ACTION_CHUNK, OBS_HORIZON};
use crate::{BenchLoadArgs, Outcome, WorkerMode};

/// What a worker (one loader epoch) reports on its last stdout line.
#[derive(serde::Deserialize)]
pub struct EpochReport {
    pub samples: u64,
    pub batches: u64,
    pub images: u64,
    pub open_s: f64,
    pub seconds: f64,
    pub bytes_read: u64,
    pub shape: String,
}

fn loader_options(args: &BenchLoadArgs, threads: usize) -> LoaderOptions {
    LoaderOptions::default()
        .obs_horizon(OBS_HORIZON)
        .action_chunk(ACTION_CHUNK)
        .batch_size(args.batch_size)
        .shuffle(true)
        .seed(0)
        .threads(threads)
}

/// The hidden `--worker MODE`: one epoch in this process, a JSON line on stdout.
pub fn run(
    mode: WorkerMode,
    dataset: &Path,
    args: &BenchLoadArgs,
    threads: usize,
) -> Result<Outcome> {
    let mut opts = loader_options(args, threads);
    if mode == WorkerMode::Streaming {
        opts = opts.streaming(args.streaming_buffer);
    }
    let location = dataset.to_string_lossy();
    let t0 = Instant::now();
    let mut loader = opts
        .open(&location)
        .with_context(|| format!("opening {}", dataset.display()))?;
    let open_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let (mut samples, mut batches, mut images, mut shape) = (0u64, 0u64, 0u64, String::new());
    while let Some(batch) = loader.next_batch() {
        let b = batch?;
        let cams = b.cameras.len();
        if shape.is_empty() {
            shape = format!(
                "images [{}, {}, {cams}, 3, {}, {}] u8, state [{}, {}, {}] f32, action [{}, {}, {}] f32",
                b.len, b.obs_horizon, b.height, b.width, b.len, b.obs_horizon, b.state_dim, b.len,
                b.action_chunk, b.action_dim
            );
        }
        let plane = 3 * b.height as usize * b.width as usize;
        if b.images.len() != b.len * b.obs_horizon * cams * plane {
            bail!(
                "batch {batches}: {} image bytes for {} samples",
                b.images.len(),
                b.len
            );
        }
        samples += b.len as u64;
        images += (b.len * b.obs_horizon * cams) as u64;
        batches += 1;
        // What a Rust trainer does once the batch is on the device.
        loader.recycle(b);
    }
    let seconds = t1.elapsed().as_secs_f64();
    println!(
        "{}",
        serde_json::json!({
            "samples": samples, "batches": batches, "images": images, "open_s": open_s,
            "seconds": seconds, "bytes_read": loader.bytes_read(), "shape": shape,
        })
    );
    Ok(Outcome::Completed)
}

/// Runs a worker as a child process (the current executable, which must be `scaledp`) and
/// measures it.
pub fn spawn(
    mode: WorkerMode,
    dataset: &Path,
    args: &BenchLoadArgs,
    threads: usize,
) -> Result<(Measured, EpochReport)> {
    let exe = std::env::current_exe().context("locating the scaledp executable")?;
    let mode = mode.flag();
    let mut cmd = Process::new(exe);
    cmd.args(["bench", "load", "--worker", mode, "--dataset"])
        .arg(dataset)
        .args(["--batch-size", &args.batch_size.to_string()])
        .args(["--threads", &threads.to_string()])
        .args(["--streaming-buffer", &args.streaming_buffer.to_string()]);
    tracing::info!("running {cmd:?}");
    let m = measure(cmd, None).with_context(|| format!("running the {mode} loader epoch"))?;
    if !m.status.success() {
        bail!(
            "the {mode} loader epoch exited with {}: {}",
            m.status,
            m.stderr.last().map_or("", String::as_str)
        );
    }
    let last = m
        .stdout
        .last()
        .context("the loader epoch printed nothing")?;
    let report: EpochReport =
        serde_json::from_str(last).with_context(|| format!("bad worker output '{last}'"))?;
    if report.samples == 0 || report.seconds <= 0.0 {
        bail!("the {mode} loader epoch yielded no samples");
    }
    Ok((m, report))
}
