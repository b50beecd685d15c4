//! `scaledp bench load`: the training-data loader over a generated bimanual dataset (3 cameras
//! stored as 320×240 JPEG, To 2, C 16, batch 64). One loader epoch runs in a child process (so
//! its wall time and peak memory are its own); then the very JPEGs of that epoch's samples are
//! decoded with nothing else around them on a pool of the same size (the physical limit; and
//! once more with the loader's own decoder, which also lays pixels out channel-first); then
//! our loader from Python (`scaledp_data`) and LeRobot's `LeRobotDataset` + torch `DataLoader`
//! read the same files; then a streaming epoch runs over a dataset several times larger, for
//! its peak memory. With `--video av1|h264` (default av1) the same frames stored as video
//! features go through our loader, LeRobot's DataLoader and a streaming epoch too.

mod data;
mod decode;
mod report;
mod runs;
mod video;
mod worker;

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use scaledp_testkit::{load_average, workspace_from_current_dir, BENCH_VENV};

use crate::disk::dir_bytes;
use crate::python::{run_lerobot, run_module, LeRobotRun, LoadRoute, ModuleRun, NotRun, Python};
use crate::{BenchLoadArgs, Outcome, WorkerMode};
use data::{ensure_dataset, ensure_larger, DataSpec, OBS_HORIZON};
use decode::pure_decode;
use report::print_report;
use runs::{Runs, VideoRuns};

pub fn run(args: BenchLoadArgs) -> Result<Outcome> {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let threads = args.threads.unwrap_or(cores).max(1);
    if let Some(mode) = args.worker {
        let dataset = args
            .dataset
            .as_deref()
            .context("--worker needs --dataset")?;
        return worker::run(mode, dataset, &args, threads);
    }
    if args.episodes == 0 || !args.seconds.is_finite() || args.seconds <= 0.0 {
        bail!("need --episodes >= 1 and --seconds > 0");
    }
    if args.batch_size == 0 {
        bail!("need --batch-size >= 1");
    }
    let runs = measure_all(&args, cores, threads)?;
    print_report(&args, &runs);
    Ok(Outcome::Completed)
}

/// `--dir`, else `target/bench-load` in the workspace holding the current directory, else a
/// directory in the system's temp dir.
fn cache_dir(args: &BenchLoadArgs) -> PathBuf {
    match (&args.dir, workspace_from_current_dir()) {
        (Some(d), _) => d.clone(),
        (None, Ok(root)) => root.join("target/bench-load"),
        (None, Err(_)) => std::env::temp_dir().join("scaledp-bench-load"),
    }
}

/// Generates (or reuses) the datasets and runs every route.
fn measure_all(args: &BenchLoadArgs, cores: usize, threads: usize) -> Result<Runs> {
    let cache = cache_dir(args);
    let spec = DataSpec {
        episodes: args.episodes,
        seconds: args.seconds,
        jobs: cores,
    };
    let (dataset, how) = ensure_dataset(&cache, &spec)?;
    let data_bytes = dir_bytes(&dataset.join("data"))?;
    // 1. One random-access epoch in a child process.
    let load_before = load_average();
    let ours = worker::spawn(WorkerMode::Random, &dataset, args, threads)?;
    // 2. The same JPEGs, decoded with nothing else around them.
    tracing::info!("decoding the epoch's JPEGs on {threads} threads");
    let pure = pure_decode(&dataset, OBS_HORIZON, threads)?;
    // 3. Our loader from Python, and LeRobot, on the same files.
    let (module, lerobot) = python_routes(args, &dataset, &cache, threads);
    // 4. Streaming over a larger dataset.
    let larger = if args.streaming_factor == 0 {
        None
    } else {
        Some(ensure_larger(
            &cache,
            &dataset,
            &spec,
            args.streaming_factor,
        )?)
    };
    let streaming = match &larger {
        None => None,
        Some((large, large_how)) => {
            let r = worker::spawn(WorkerMode::Streaming, large, args, threads)?;
            Some((r, dir_bytes(&large.join("data"))?, large_how.clone()))
        }
    };
    // 5. The same frames as video.
    let video = args.video.codec().map(|codec| {
        video_routes(
            args,
            codec,
            &dataset,
            &cache,
            larger.as_ref().map(|l| l.0.as_path()),
            threads,
        )
    });
    Ok(Runs {
        threads,
        cores,
        how,
        dataset,
        data_bytes,
        load_before,
        ours,
        pure,
        module,
        lerobot,
        streaming,
        video,
    })
}

/// Frames × video cameras × H × W × 3 of a dataset (`info.json`): its frames uncompressed.
fn uncompressed_bytes(dataset: &Path) -> Result<u64> {
    let path = dataset.join("meta/info.json");
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(&path)?)
        .with_context(|| format!("parsing {}", path.display()))?;
    let frames = info["total_frames"].as_u64().context("total_frames")?;
    let per_frame: u64 = info["features"]
        .as_object()
        .context("features")?
        .values()
        .filter(|f| f["dtype"] == "video")
        .map(|f| {
            f["shape"]
                .as_array()
                .map_or(0, |s| s.iter().filter_map(|v| v.as_u64()).product())
        })
        .sum();
    Ok(frames * per_frame)
}

/// Makes (or reuses) the video datasets and runs our loader and LeRobot's on them.
fn video_routes(
    args: &BenchLoadArgs,
    codec: &'static str,
    dataset: &Path,
    cache: &Path,
    larger: Option<&Path>,
    threads: usize,
) -> Result<VideoRuns, String> {
    let py = Python::locate(&BENCH_VENV, args.python.as_deref()).map_err(|e| e.to_string())?;
    let fail = |e: anyhow::Error| format!("{e:#}");
    let (video_ds, how) = video::ensure_video(&py, dataset, codec).map_err(fail)?;
    let video_bytes = dir_bytes(&video_ds.join("videos")).map_err(fail)?;
    let ours = worker::spawn(WorkerMode::Random, &video_ds, args, threads).map_err(fail)?;
    let lerobot = if args.no_python {
        Err(NotRun::Skipped)
    } else {
        let route = LoadRoute {
            dataset: &video_ds,
            cache,
            batch_size: args.batch_size,
            threads,
            lerobot_batches: args.lerobot_batches,
        };
        run_lerobot(&py, &route)
    };
    let streaming = match larger {
        None => None,
        Some(large) => {
            let (large_video, large_how) = video::ensure_video(&py, large, codec).map_err(fail)?;
            let r =
                worker::spawn(WorkerMode::Streaming, &large_video, args, threads).map_err(fail)?;
            let bytes = dir_bytes(&large_video.join("videos")).map_err(fail)?;
            let raw = uncompressed_bytes(&large_video).map_err(fail)?;
            Some((r, bytes, large_how, raw))
        }
    };
    Ok(VideoRuns {
        codec,
        how,
        dataset: video_ds,
        video_bytes,
        ours,
        lerobot,
        streaming,
    })
}

/// The `scaledp_data` and LeRobot routes on the benchmark Python.
fn python_routes(
    args: &BenchLoadArgs,
    dataset: &Path,
    cache: &Path,
    threads: usize,
) -> (Result<ModuleRun, NotRun>, Result<LeRobotRun, NotRun>) {
    if args.no_python {
        return (Err(NotRun::Skipped), Err(NotRun::Skipped));
    }
    let py = match Python::locate(&BENCH_VENV, args.python.as_deref()) {
        Ok(py) => py,
        Err(why) => return (Err(why.clone()), Err(why)),
    };
    let route = LoadRoute {
        dataset,
        cache,
        batch_size: args.batch_size,
        threads,
        lerobot_batches: args.lerobot_batches,
    };
    (run_module(&py, &route), run_lerobot(&py, &route))
}
