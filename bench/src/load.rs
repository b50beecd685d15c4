//! `scaledp bench load`: the training-data loader over a generated bimanual dataset (3 cameras
//! stored as 320×240 JPEG, To 2, C 16, batch 64). One loader epoch runs in a child process (so
//! its wall time and peak memory are its own); then the very JPEGs of that epoch's samples are
//! decoded with nothing else around them on a pool of the same size (the physical limit; and
//! once more with the loader's own decoder, which also lays pixels out channel-first); then
//! LeRobot's `LeRobotDataset` + torch `DataLoader` reads the same files
//! (`tests/py/lerobot_baseline.py`); then a streaming epoch runs over a dataset several times
//! larger, for its peak memory.

use std::path::Path;
use std::process::Command as Process;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use scaledp_datasets::LoaderOptions;

mod data;

use crate::convert::{dir_bytes, measure, Measured};
use crate::python::{run_lerobot, run_module};
use crate::{BenchLoadArgs, Outcome};
use data::{ensure_dataset, ensure_larger, pure_decode, DataSpec};

const OBS_HORIZON: usize = 2;
const ACTION_CHUNK: usize = 16;
/// Loader images/s over pure-decode images/s.
const TARGET_DECODE_RATIO: f64 = 0.8;
/// Loader samples/s over LeRobot's.
const TARGET_LEROBOT_RATIO: f64 = 5.0;
/// Peak resident memory of the streaming run (bytes).
const TARGET_STREAMING_RSS: u64 = 2_000_000_000;

/// What a worker (one loader epoch) reports on its last stdout line.
#[derive(serde::Deserialize)]
struct EpochReport {
    samples: u64,
    batches: u64,
    images: u64,
    open_s: f64,
    seconds: f64,
    bytes_read: u64,
    shape: String,
}

/// One row of the table.
struct Row {
    route: String,
    samples: Option<u64>,
    images: Option<u64>,
    seconds: f64,
    bytes: Option<u64>,
    peak_rss: Option<u64>,
}

pub fn run(args: BenchLoadArgs) -> Result<Outcome> {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let threads = args.threads.unwrap_or(cores).max(1);
    if let Some(mode) = &args.worker {
        let dataset = args
            .dataset
            .as_deref()
            .context("--worker needs --dataset")?;
        return worker(mode, dataset, &args, threads);
    }
    if args.episodes == 0 || !args.seconds.is_finite() || args.seconds <= 0.0 {
        bail!("need --episodes >= 1 and --seconds > 0");
    }
    if args.batch_size == 0 {
        bail!("need --batch-size >= 1");
    }
    let exe = std::env::current_exe().context("locating the scaledp executable")?;
    let cache = match &args.dir {
        Some(d) => d.clone(),
        None => exe
            .ancestors()
            .find(|d| d.file_name().is_some_and(|n| n == "target"))
            .map_or_else(std::env::temp_dir, Path::to_path_buf)
            .join("bench-load"),
    };
    let spec = DataSpec {
        episodes: args.episodes,
        seconds: args.seconds,
        jobs: cores,
    };
    let (dataset, how) = ensure_dataset(&cache, &spec)?;
    let data_bytes = dir_bytes(&dataset.join("data"))?;

    // 1. One random-access epoch in a child process.
    let load_before = load_average();
    let ours = run_worker(&exe, "random", &dataset, &args, threads)?;
    // 2. The same JPEGs, decoded with nothing else around them.
    tracing::info!("decoding the epoch's JPEGs on {threads} threads");
    let pure = pure_decode(&dataset, OBS_HORIZON, threads)?;
    let (decoded, decode_s) = (pure.images, pure.zune.seconds);
    // 3. Our loader from Python, and LeRobot, on the same files.
    let (module, lerobot) = if args.no_python {
        let no = "--no-python".to_string();
        (Err(no.clone()), Err(no))
    } else {
        (
            run_module(&exe, &dataset, &cache, &args, threads),
            run_lerobot(&exe, &dataset, &cache, &args, threads),
        )
    };
    // 4. Streaming over a larger dataset.
    let streaming = if args.streaming_factor == 0 {
        None
    } else {
        let (large, large_how) = ensure_larger(&cache, &dataset, &spec, args.streaming_factor)?;
        let r = run_worker(&exe, "streaming", &large, &args, threads)?;
        Some((r, dir_bytes(&large.join("data"))?, large_how))
    };

    println!(
        "scaledp bench load: {} ({:.0} MB of parquet in {})",
        how,
        data_bytes as f64 / 1e6,
        dataset.display()
    );
    println!(
        "samples: To {OBS_HORIZON}, C {ACTION_CHUNK}, batch {}, shuffled; {}",
        args.batch_size, ours.1.shape
    );
    println!(
        "cores: {cores} available; loader threads {threads}; pure decode: zune-jpeg on a rayon pool of {threads}; 1-min load average {load_before} before the runs, {} after",
        load_average()
    );
    let cams = ours.1.images / (ours.1.samples * OBS_HORIZON as u64).max(1);
    let mut rows = vec![worker_row("scaledp loader", &ours)];
    rows.push(Row {
        route: format!("pure JPEG decode ×{threads}"),
        samples: None,
        images: Some(decoded),
        seconds: decode_s,
        bytes: None,
        peak_rss: None,
    });
    rows.push(Row {
        route: format!("decode + CHW ×{threads}"),
        samples: None,
        images: Some(decoded),
        seconds: pure.chw.seconds,
        bytes: None,
        peak_rss: None,
    });
    if let Ok(r) = &module {
        rows.push(Row {
            route: "scaledp_data (Python)".into(),
            samples: Some(r.samples),
            images: Some(r.images),
            seconds: r.seconds,
            bytes: None,
            peak_rss: r.m.peak_rss,
        });
    }
    let lerobot_rate = match &lerobot {
        Ok(r) => {
            rows.push(Row {
                route: "LeRobot DataLoader".into(),
                samples: Some(r.samples),
                images: Some(r.samples * OBS_HORIZON as u64 * cams),
                seconds: r.seconds,
                bytes: None,
                peak_rss: r.m.peak_rss,
            });
            Some(r.samples as f64 / r.seconds)
        }
        Err(_) => None,
    };
    if let Some((r, _, _)) = &streaming {
        let route = format!("loader streaming ×{}", args.streaming_factor);
        rows.push(worker_row(&route, r));
    }
    print_table(&rows);

    let report = &ours.1;
    let ours_images_s = report.images as f64 / report.seconds;
    let decode_images_s = decoded as f64 / decode_s;
    println!(
        "loader: opened in {:.2} s, then {} batches in {:.2} s; MB/s read = bytes of parquet pages and footers the loader actually read ({:.0} MB) / epoch seconds",
        report.open_s,
        report.batches,
        report.seconds,
        report.bytes_read as f64 / 1e6
    );
    verdict(
        "decode ratio",
        ours_images_s / decode_images_s,
        TARGET_DECODE_RATIO,
        &format!(
            "loader images/s {ours_images_s:.0} ÷ pure-decode images/s {decode_images_s:.0} ({decoded} JPEGs, the epoch's To × cams per sample)"
        ),
    );
    if let (Some(loader_cpu), Some(zune_cpu), Some(chw_cpu)) =
        (ours.0.cpu_s, pure.zune.cpu_s, pure.chw.cpu_s)
    {
        // Wall-clock rates suffer from whatever else runs on the machine; CPU seconds much less.
        println!(
            "on CPU seconds (less sensitive to other load; not the target's measure): the loader process spent {loader_cpu:.1} s for these images, pure decode {zune_cpu:.1} s ({:.2}×), the loader's decoder with its channel-first layout {chw_cpu:.1} s ({:.2}×)",
            zune_cpu / loader_cpu,
            chw_cpu / loader_cpu
        );
    }
    match &module {
        Ok(r) => println!(
            "from Python: scaledp_data.Loader, each batch dropped before the next, {:.0} images/s = {:.2}× pure decode",
            r.images as f64 / r.seconds,
            r.images as f64 / r.seconds / decode_images_s
        ),
        Err(why) => println!("scaledp_data from Python: not run — {why}"),
    }
    match (&lerobot, lerobot_rate) {
        (Ok(r), Some(rate)) => verdict(
            "vs LeRobot",
            report.samples as f64 / report.seconds / rate,
            TARGET_LEROBOT_RATIO,
            &format!(
                "samples/s of ours over lerobot {} LeRobotDataset + torch DataLoader ({threads} workers, shuffled, {} batches timed by its own clock after a warm-up batch of {:.1} s; dataset opened in {:.1} s; peak RSS of its main process only, workers not counted)",
                r.version, args.lerobot_batches, r.warmup_s, r.init_s
            ),
        ),
        (Err(why), _) => println!("LeRobot baseline: none, so no ratio — {why}"),
        (Ok(_), None) => {}
    }
    if let Some((r, bytes, large_how)) = &streaming {
        let rss = r.0.peak_rss;
        let met = rss.is_some_and(|b| b <= TARGET_STREAMING_RSS);
        println!(
            "streaming: {large_how} ({:.1} GB of parquet), {} episodes open at most; peak RSS {} vs target ≤ {:.1} GB: {}",
            *bytes as f64 / 1e9,
            args.streaming_buffer,
            rss.map_or("n/a".into(), |b| format!("{:.0} MB", b as f64 / 1e6)),
            TARGET_STREAMING_RSS as f64 / 1e9,
            if met { "met" } else { "NOT met" }
        );
    }
    Ok(Outcome::Completed)
}

fn verdict(name: &str, ratio: f64, target: f64, how: &str) {
    println!(
        "{name}: {ratio:.2}× ; target ≥ {target}×: {} — {how}",
        if ratio >= target { "met" } else { "NOT met" }
    );
}

fn worker_row(route: &str, r: &(Measured, EpochReport)) -> Row {
    Row {
        route: route.into(),
        samples: Some(r.1.samples),
        images: Some(r.1.images),
        seconds: r.1.seconds,
        bytes: Some(r.1.bytes_read),
        peak_rss: r.0.peak_rss,
    }
}

fn print_table(rows: &[Row]) {
    println!(
        "{:<22} {:>8} {:>8} {:>10} {:>10} {:>10} {:>12}",
        "route", "samples", "seconds", "samples/s", "images/s", "MB/s read", "peak RSS MB"
    );
    let opt = |v: Option<f64>, digits: usize| v.map_or("-".into(), |x| format!("{x:.digits$}"));
    for r in rows {
        println!(
            "{:<22} {:>8} {:>8.2} {:>10} {:>10} {:>10} {:>12}",
            r.route,
            r.samples.map_or("-".into(), |s| s.to_string()),
            r.seconds,
            opt(r.samples.map(|s| s as f64 / r.seconds), 0),
            opt(r.images.map(|s| s as f64 / r.seconds), 0),
            opt(r.bytes.map(|b| b as f64 / 1e6 / r.seconds), 1),
            opt(r.peak_rss.map(|b| b as f64 / 1e6), 0),
        );
    }
}

/// The 1-minute load average, as text.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "n/a".into())
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
fn worker(mode: &str, dataset: &Path, args: &BenchLoadArgs, threads: usize) -> Result<Outcome> {
    let mut opts = loader_options(args, threads);
    match mode {
        "random" => {}
        "streaming" => opts = opts.streaming(args.streaming_buffer),
        other => bail!("unknown worker mode {other} (random, streaming)"),
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

/// Runs a worker as a child process and measures it.
fn run_worker(
    exe: &Path,
    mode: &str,
    dataset: &Path,
    args: &BenchLoadArgs,
    threads: usize,
) -> Result<(Measured, EpochReport)> {
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
