//! The report of one `bench load` run: the table of routes, and each goal with its verdict.

use scaledp_testkit::{load_average, Measured};

use super::data::{ACTION_CHUNK, OBS_HORIZON};
use super::runs::{
    Runs, TARGET_DECODE_RATIO, TARGET_LEROBOT_RATIO, TARGET_STREAMING_RSS, TARGET_VIDEO_JPEG_RATIO,
};
use super::worker::EpochReport;
use crate::BenchLoadArgs;

/// One row of the table.
struct Row {
    route: String,
    samples: Option<u64>,
    images: Option<u64>,
    seconds: f64,
    bytes: Option<u64>,
    peak_rss: Option<u64>,
}

pub(super) fn print_report(args: &BenchLoadArgs, runs: &Runs) {
    let threads = runs.threads;
    let report = &runs.ours.1;
    println!(
        "scaledp bench load: {} ({:.0} MB of parquet in {})",
        runs.how,
        runs.data_bytes as f64 / 1e6,
        runs.dataset.display()
    );
    println!(
        "samples: To {OBS_HORIZON}, C {ACTION_CHUNK}, batch {}, shuffled; {}",
        args.batch_size, report.shape
    );
    let load = |l: Option<f64>| l.map_or("n/a".into(), |l| format!("{l:.2}"));
    println!(
        "cores: {} available; loader threads {threads}; pure decode: zune-jpeg on a rayon pool of {threads}; 1-min load average {} before the runs, {} after",
        runs.cores,
        load(runs.load_before),
        load(load_average())
    );
    print_table(&rows(args, runs));
    println!(
        "loader: opened in {:.2} s, then {} batches in {:.2} s; MB/s read = bytes of parquet pages and footers the loader actually read ({:.0} MB) / epoch seconds",
        report.open_s,
        report.batches,
        report.seconds,
        report.bytes_read as f64 / 1e6
    );
    print_decode_verdict(runs);
    print_python_verdicts(args, runs);
    print_video_verdicts(args, runs);
    if let Some((r, bytes, large_how)) = &runs.streaming {
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
}

/// The table's rows: every route that ran.
fn rows(args: &BenchLoadArgs, runs: &Runs) -> Vec<Row> {
    let (threads, pure) = (runs.threads, &runs.pure);
    let decode_row = |route: String, seconds: f64| Row {
        route,
        samples: None,
        images: Some(pure.images),
        seconds,
        bytes: None,
        peak_rss: None,
    };
    let mut rows = vec![
        worker_row("scaledp loader", &runs.ours),
        decode_row(format!("pure JPEG decode ×{threads}"), pure.zune.seconds),
        decode_row(format!("decode + CHW ×{threads}"), pure.chw.seconds),
    ];
    if let Ok(r) = &runs.module {
        rows.push(Row {
            route: "scaledp_data (Python)".into(),
            samples: Some(r.samples),
            images: Some(r.images),
            seconds: r.seconds,
            bytes: None,
            peak_rss: r.m.peak_rss,
        });
    }
    if let Ok(r) = &runs.lerobot {
        rows.push(Row {
            route: "LeRobot DataLoader".into(),
            samples: Some(r.samples),
            images: Some(r.samples * OBS_HORIZON as u64 * cameras(&runs.ours.1)),
            seconds: r.seconds,
            bytes: None,
            peak_rss: r.m.peak_rss,
        });
    }
    if let Some((r, _, _)) = &runs.streaming {
        let route = format!("loader streaming ×{}", args.streaming_factor);
        rows.push(worker_row(&route, r));
    }
    if let Some(Ok(v)) = &runs.video {
        rows.push(worker_row(&format!("scaledp loader {}", v.codec), &v.ours));
        if let Ok(r) = &v.lerobot {
            rows.push(Row {
                route: format!("LeRobot DataLoader {}", v.codec),
                samples: Some(r.samples),
                images: Some(r.samples * OBS_HORIZON as u64 * cameras(&v.ours.1)),
                seconds: r.seconds,
                bytes: None,
                peak_rss: r.m.peak_rss,
            });
        }
        if let Some((r, _, _, _)) = &v.streaming {
            let route = format!("streaming ×{} {}", args.streaming_factor, v.codec);
            rows.push(worker_row(&route, r));
        }
    }
    rows
}

/// The video routes' verdicts: against our JPEG path, against LeRobot, streaming memory.
fn print_video_verdicts(args: &BenchLoadArgs, runs: &Runs) {
    let v = match &runs.video {
        None => return,
        Some(Err(why)) => {
            println!("video routes: not run — {why}");
            return;
        }
        Some(Ok(v)) => v,
    };
    let rate = |r: &EpochReport| r.samples as f64 / r.seconds;
    let video_rate = rate(&v.ours.1);
    println!(
        "video: {} ({:.0} MB of video in {}, vs {:.0} MB of parquet for the JPEG dataset)",
        v.how,
        v.video_bytes as f64 / 1e6,
        v.dataset.display(),
        runs.data_bytes as f64 / 1e6
    );
    verdict(
        &format!("{} vs our JPEG path", v.codec),
        video_rate / rate(&runs.ours.1),
        TARGET_VIDEO_JPEG_RATIO,
        "loader samples/s on the video dataset ÷ on the same frames as JPEG (within 2× = at least 0.5×)",
    );
    match &v.lerobot {
        Ok(r) => verdict(
            &format!("{} vs LeRobot", v.codec),
            video_rate / (r.samples as f64 / r.seconds),
            TARGET_LEROBOT_RATIO,
            &format!(
                "samples/s of ours over lerobot {} on the same video files (pyav backend: torchcodec needs FFmpeg libraries on the system), {} workers, {} batches after a warm-up batch of {:.1} s",
                r.version, runs.threads, args.lerobot_batches, r.warmup_s
            ),
        ),
        Err(why) => println!("LeRobot on video: none, so no ratio — {why}"),
    }
    if let Some((r, bytes, how, raw)) = &v.streaming {
        let rss = r.0.peak_rss;
        println!(
            "streaming video: {how} ({:.1} GB of video, {:.1} GB of frames uncompressed), {} episodes open at most; peak RSS {} vs target ≤ {:.1} GB: {}",
            *bytes as f64 / 1e9,
            *raw as f64 / 1e9,
            args.streaming_buffer,
            rss.map_or("n/a".into(), |b| format!("{:.0} MB", b as f64 / 1e6)),
            TARGET_STREAMING_RSS as f64 / 1e9,
            if rss.is_some_and(|b| b <= TARGET_STREAMING_RSS) { "met" } else { "NOT met" }
        );
    }
}

/// Cameras per sample, from the loader's counts.
fn cameras(r: &EpochReport) -> u64 {
    r.images / (r.samples * OBS_HORIZON as u64).max(1)
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

fn verdict(name: &str, ratio: f64, target: f64, how: &str) {
    println!(
        "{name}: {ratio:.2}× ; target ≥ {target}×: {} — {how}",
        if ratio >= target { "met" } else { "NOT met" }
    );
}

/// Loader images/s over pure decode, and the same on CPU seconds.
fn print_decode_verdict(runs: &Runs) {
    let (report, pure) = (&runs.ours.1, &runs.pure);
    let ours_images_s = report.images as f64 / report.seconds;
    let decode_images_s = pure.images as f64 / pure.zune.seconds;
    verdict(
        "decode ratio",
        ours_images_s / decode_images_s,
        TARGET_DECODE_RATIO,
        &format!(
            "loader images/s {ours_images_s:.0} ÷ pure-decode images/s {decode_images_s:.0} ({} JPEGs, the epoch's To × cams per sample)",
            pure.images
        ),
    );
    if let (Some(loader_cpu), Some(zune_cpu), Some(chw_cpu)) =
        (runs.ours.0.cpu_s, pure.zune.cpu_s, pure.chw.cpu_s)
    {
        // Wall-clock rates suffer from whatever else runs on the machine; CPU seconds much less.
        println!(
            "on CPU seconds (less sensitive to other load; not the target's measure): the loader process spent {loader_cpu:.1} s for these images, pure decode {zune_cpu:.1} s ({:.2}×), the loader's decoder with its channel-first layout {chw_cpu:.1} s ({:.2}×)",
            zune_cpu / loader_cpu,
            chw_cpu / loader_cpu
        );
    }
}

/// The `scaledp_data` line and the LeRobot ratio, or why they did not run.
fn print_python_verdicts(args: &BenchLoadArgs, runs: &Runs) {
    let (report, threads) = (&runs.ours.1, runs.threads);
    let decode_images_s = runs.pure.images as f64 / runs.pure.zune.seconds;
    match &runs.module {
        Ok(r) => println!(
            "from Python: scaledp_data.Loader, each batch dropped before the next, {:.0} images/s = {:.2}× pure decode",
            r.images as f64 / r.seconds,
            r.images as f64 / r.seconds / decode_images_s
        ),
        Err(why) => println!("scaledp_data from Python: not run — {why}"),
    }
    match &runs.lerobot {
        Ok(r) => verdict(
            "vs LeRobot",
            report.samples as f64 / report.seconds / (r.samples as f64 / r.seconds),
            TARGET_LEROBOT_RATIO,
            &format!(
                "samples/s of ours over lerobot {} LeRobotDataset + torch DataLoader ({threads} workers, shuffled, {} batches timed by its own clock after a warm-up batch of {:.1} s; dataset opened in {:.1} s; peak RSS of its main process only, workers not counted)",
                r.version, args.lerobot_batches, r.warmup_s, r.init_s
            ),
        ),
        Err(why) => println!("LeRobot baseline: none, so no ratio — {why}"),
    }
}
