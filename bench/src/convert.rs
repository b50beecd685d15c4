//! `scaledp bench convert`: generates a fixed set of recorder-style episodes, converts them in a
//! `scaledp convert` child process (so its wall time and peak memory are its own), then runs the
//! usual single-process Python route (`tests/py/convert_baseline.py`: rosbags + numpy + Pillow +
//! pyarrow) on the same recordings and compares frames/s.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use scaledp_schema::Rig;
use scaledp_testkit::{load_average, Measured, TEST_VENV};

use crate::convert_run::scaledp_convert;
use crate::convert_s3::{self, Route};
use crate::disk::dir_bytes;
use crate::python::{run_convert_baseline, ConvertRun, NotRun, Python};
use crate::synth::synthesize;
use crate::{BenchConvertArgs, Outcome};

/// Frames/s of ours over the Python route that the issue asks for.
const TARGET_RATIO: f64 = 10.0;

/// Where the run's files go: `--out`, else a temporary directory removed at the end.
struct Dirs {
    _tmp: tempfile::TempDir,
    root: PathBuf,
    recordings: PathBuf,
    dataset: PathBuf,
    python: PathBuf,
}

/// The generated input.
struct Input {
    bytes: u64,
    camera_frames: u64,
}

/// What `scaledp convert` did.
struct Ours {
    m: Measured,
    frames: u64,
    output_bytes: u64,
}

pub fn run(args: BenchConvertArgs) -> Result<Outcome> {
    if args.episodes == 0 || !args.seconds.is_finite() || args.seconds <= 0.0 {
        bail!("need --episodes >= 1 and --seconds > 0");
    }
    // Before our own work (generating the recordings) adds to it.
    let load_before = load_average();
    let rig =
        Rig::load_or_builtin(&args.rig).with_context(|| format!("loading rig {}", args.rig))?;
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let jobs = args.jobs.unwrap_or(cores).max(1);
    let dirs = Dirs::prepare(args.out.as_deref())?;
    let input = generate(&dirs, &rig, &args, jobs)?;
    let ours = convert(&dirs, jobs)?;
    let s3 = if args.no_s3 {
        Err(anyhow::anyhow!("skipped (--no-s3)"))
    } else {
        convert_s3::s3_route(&dirs.recordings, jobs, &TEST_VENV)
    };
    // Output frames per camera frame: a 30 Hz camera at a 10 Hz control rate keeps every third.
    let camera_hz = rig.cameras.first().map_or(rig.control_rate_hz, |c| c.fps);
    let stride = (camera_hz / rig.control_rate_hz).round().max(1.0) as usize;
    let floor = convert_s3::floor_route(&dirs.recordings, rig.cameras.len(), stride, jobs);
    let python = if args.no_python {
        Err(NotRun::Skipped)
    } else {
        Python::locate(&TEST_VENV, args.python.as_deref()).and_then(|py| {
            let recorded_s = args.episodes as f64 * args.seconds;
            run_convert_baseline(&py, &dirs.recordings, &dirs.python, recorded_s)
        })
    };

    print_header(&args, &rig, &input, cores, jobs);
    print_routes(&input, &ours, &python, &dirs.python)?;
    print_s3_and_floor(&input, &ours, &s3, &floor);
    if !args.video.is_empty() {
        let exe = std::env::current_exe().context("locating the scaledp executable")?;
        crate::convert_video::run(&exe, &dirs.recordings, &dirs.root, jobs, &args.video)?;
    }
    println!(
        "machine load (1-minute average, {cores} cores): {} before this benchmark, {} after",
        load_before.map_or("n/a".into(), |l| format!("{l:.2}")),
        load_average().map_or("n/a".into(), |l| format!("{l:.2}"))
    );
    if args.out.is_some() {
        println!(
            "recordings, dataset and python output kept in {}",
            dirs.root.display()
        );
    } else {
        println!("(generated data removed; pass --out DIR to keep it)");
    }
    Ok(Outcome::Completed)
}

impl Dirs {
    /// `recordings/` (created), `dataset/` and `python/` under `out` or a temporary directory,
    /// cleared of an earlier run's files.
    fn prepare(out: Option<&Path>) -> Result<Dirs> {
        let tmp = tempfile::tempdir().context("creating a temporary directory")?;
        let root = out.map_or_else(|| tmp.path().to_path_buf(), Path::to_path_buf);
        let dirs = Dirs {
            _tmp: tmp,
            recordings: root.join("recordings"),
            dataset: root.join("dataset"),
            python: root.join("python"),
            root,
        };
        for dir in [&dirs.recordings, &dirs.dataset, &dirs.python] {
            if dir.exists() {
                std::fs::remove_dir_all(dir)
                    .with_context(|| format!("clearing {}", dir.display()))?;
            }
        }
        std::fs::create_dir_all(&dirs.recordings)
            .with_context(|| format!("creating {}", dirs.recordings.display()))?;
        Ok(dirs)
    }
}

/// The recordings, rendered by the simulator `jobs` at a time.
fn generate(dirs: &Dirs, rig: &Rig, args: &BenchConvertArgs, jobs: usize) -> Result<Input> {
    let t0 = Instant::now();
    let ids: Vec<usize> = (0..args.episodes).collect();
    synthesize(
        &dirs.recordings,
        rig,
        &ids,
        args.seconds,
        "bench convert",
        jobs,
    )?;
    let bytes = dir_bytes(&dirs.recordings)?;
    let per_episode: u64 = rig
        .cameras
        .iter()
        .map(|c| (args.seconds * c.fps) as u64)
        .sum();
    tracing::info!(
        "generated {} episodes ({:.0} MB) in {:.1} s",
        args.episodes,
        bytes as f64 / 1e6,
        t0.elapsed().as_secs_f64()
    );
    Ok(Input {
        bytes,
        camera_frames: per_episode * args.episodes as u64,
    })
}

/// `scaledp convert` over the recordings, measured as a child process.
fn convert(dirs: &Dirs, jobs: usize) -> Result<Ours> {
    let exe = std::env::current_exe().context("locating the scaledp executable")?;
    let m = scaledp_convert(&exe, &dirs.recordings, &dirs.dataset, jobs, &[])?;
    let info_path = dirs.dataset.join("meta").join("info.json");
    let info: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&info_path).with_context(|| format!("reading {}", info_path.display()))?,
    )
    .with_context(|| format!("parsing {}", info_path.display()))?;
    let frames = info["total_frames"]
        .as_u64()
        .with_context(|| format!("no total_frames in {}", info_path.display()))?;
    let output_bytes = dir_bytes(&dirs.dataset.join("data"))?;
    Ok(Ours {
        m,
        frames,
        output_bytes,
    })
}

fn print_header(args: &BenchConvertArgs, rig: &Rig, input: &Input, cores: usize, jobs: usize) {
    let cams: Vec<String> = rig
        .cameras
        .iter()
        .map(|c| format!("{}×{} {} @ {} Hz", c.width, c.height, c.encoding(), c.fps))
        .collect();
    println!(
        "scaledp bench convert: {} episodes × {:.1} s of {} ({}), {:.0} MB of MCAP",
        args.episodes,
        args.seconds,
        rig.name,
        cams.join(", "),
        input.bytes as f64 / 1e6
    );
    println!(
        "input: {} camera frames; output at {} Hz, 320×240 JPEG q90",
        input.camera_frames, rig.control_rate_hz
    );
    println!(
        "cores: {cores} available; scaledp convert --jobs {jobs}; Python baseline: one process"
    );
    println!(
        "{:<16} {:>7} {:>8} {:>9} {:>8} {:>9} {:>12} {:>7}",
        "route", "frames", "seconds", "frames/s", "in MB/s", "out MB/s", "peak RSS MB", "CPU s"
    );
}

/// A row per route, then ours over the Python route, or why that did not run.
fn print_routes(
    input: &Input,
    ours: &Ours,
    python: &Result<ConvertRun, NotRun>,
    python_out: &Path,
) -> Result<()> {
    let row = |name: &str, frames: u64, secs: f64, out_bytes: u64, m: &Measured| {
        println!(
            "{name:<16} {frames:>7} {secs:>8.2} {:>9.1} {:>8.1} {:>9.2} {:>12} {:>7}",
            frames as f64 / secs,
            input.bytes as f64 / 1e6 / secs,
            out_bytes as f64 / 1e6 / secs,
            m.peak_rss
                .map_or("n/a".into(), |b| format!("{:.0}", b as f64 / 1e6)),
            m.cpu_s.map_or("n/a".into(), |c| format!("{c:.1}"))
        );
    };
    row(
        "scaledp convert",
        ours.frames,
        ours.m.wall_s,
        ours.output_bytes,
        &ours.m,
    );
    match python {
        Ok(py) => {
            let out_bytes = dir_bytes(python_out)?;
            row("python baseline", py.frames, py.seconds, out_bytes, &py.m);
            print_comparison(ours, py);
        }
        Err(why) => println!("Python baseline skipped: {why}"),
    }
    Ok(())
}

/// Ours over the Python route: frames/s (the target) and frames per CPU second.
fn print_comparison(ours: &Ours, py: &ConvertRun) {
    let ratio = (ours.frames as f64 / ours.m.wall_s) / (py.frames as f64 / py.seconds);
    println!(
        "python seconds: its own timer, from after its imports to the end (process wall time {:.2} s)",
        py.m.wall_s
    );
    println!(
        "ratio: {ratio:.1}× the Python frames/s; target ≥ {TARGET_RATIO:.0}×: {}",
        if ratio >= TARGET_RATIO {
            "met"
        } else {
            "NOT met"
        }
    );
    // Frames per CPU second hardly depend on what else runs on the machine; wall time does
    // (the Python route is one thread, ours uses every core it gets).
    if let (Some(a), Some(b)) = (ours.m.cpu_s, py.m.cpu_s) {
        if a > 0.0 && b > 0.0 {
            let (ours_cpu, py_cpu) = (ours.frames as f64 / a, py.frames as f64 / b);
            println!(
                "frames per CPU second: ours {ours_cpu:.1}, Python {py_cpu:.1} ({:.1}×)",
                ours_cpu / py_cpu
            );
        }
    }
}

/// The S3 row, the floor row and the converter over its floor (or why a row did not run).
fn print_s3_and_floor(
    input: &Input,
    ours: &Ours,
    s3: &Result<Route>,
    floor: &Result<(f64, Option<f64>, u64)>,
) {
    let row = |name: &str,
               frames: u64,
               secs: f64,
               out: Option<u64>,
               rss: Option<u64>,
               cpu: Option<f64>| {
        println!(
            "{name:<16} {frames:>7} {secs:>8.2} {:>9.1} {:>8.1} {:>9} {:>12} {:>7}",
            frames as f64 / secs,
            input.bytes as f64 / 1e6 / secs,
            out.map_or("n/a".into(), |b| format!("{:.2}", b as f64 / 1e6 / secs)),
            rss.map_or("n/a".into(), |b| format!("{:.0}", b as f64 / 1e6)),
            cpu.map_or("n/a".into(), |c| format!("{c:.1}"))
        );
    };
    match s3 {
        Ok(r) => {
            row(
                "scaledp S3→S3",
                r.frames,
                r.m.wall_s,
                Some(r.output_bytes),
                r.m.peak_rss,
                r.m.cpu_s,
            );
            println!(
                "S3: recordings and dataset in a loopback moto server (Python, on the same cores; \
                 its CPU is not in the row): {:.2}× the local frames/s",
                (r.frames as f64 / r.m.wall_s) / (ours.frames as f64 / ours.m.wall_s)
            );
        }
        Err(e) => println!("S3 row skipped: {e:#}"),
    }
    match floor {
        Ok((secs, cpu, frames)) => {
            row("floor", *frames, *secs, None, None, *cpu);
            let ratio = (ours.frames as f64 / ours.m.wall_s) / (*frames as f64 / secs);
            println!(
                "floor: every chunk decompressed + each kept frame resized and encoded, nothing \
                 else, in this process; converter / floor: {ratio:.2} (goal ≥ 0.8: {})",
                if ratio >= 0.8 { "met" } else { "NOT met" }
            );
            // Per CPU second the ratio hardly depends on what else runs on the machine.
            if let (Some(c), Some(f)) = (ours.m.cpu_s, cpu) {
                let per_cpu = (ours.frames as f64 / c) / (*frames as f64 / f);
                println!("per CPU second: converter / floor {per_cpu:.2}");
            }
        }
        Err(e) => println!("floor row failed: {e:#}"),
    }
}
