//! `scaledp bench record`: a soak of the recorder at the reference load (see [`load`]) over
//! loopback. The recorder runs as a child process (`worker`), so its resident memory and CPU
//! time are its own; this process publishes the load (`publish`) and drives the episodes,
//! `--episode-seconds` each, back to back for `--minutes` (`episode`): each one's messages
//! sent and recorded per topic, the file checked against both, then deleted unless `--keep`.
//! The recorder's resident memory is sampled every `--sample-seconds`; the report
//! (`report`) prints the load offered, sent and recorded per topic, losses, memory against its
//! value after the first episode, CPU share and MB/s written, and writes them as JSON.
//!
//! Nothing is scaled down behind the user's back: on a machine that cannot carry the load, the
//! publisher falls behind (ticks missed, counted), the recorder's queue drops (counted), or the
//! disk floor ends an episode early (said) — the figures are what was reached.

mod child;
mod episode;
mod figures;
mod load;
mod publish;
mod report;
mod worker;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, ensure, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_recorder::net;
use scaledp_testkit::{
    cpu_seconds, free_port, load_average, loopback_endpoint, workspace_from_current_dir,
};

use crate::{BenchRecordArgs, Outcome};
use child::Worker;
use figures::Soak;
use publish::LoadPublisher;

/// Seconds of load before the first episode (not recorded): the recorder's subscriptions reach
/// the publishers, and every topic is seen to arrive.
const WARM_UP: Duration = Duration::from_secs(2);

/// `--out`, else `target/bench-record` in the workspace holding the current directory, else a
/// directory in the system temp dir; whether it is the default.
fn out_dir(args: &BenchRecordArgs) -> (PathBuf, bool) {
    match (&args.out, workspace_from_current_dir()) {
        (Some(d), _) => (d.clone(), false),
        (None, Ok(root)) => (root.join("target/bench-record"), true),
        (None, Err(_)) => (std::env::temp_dir().join("scaledp-bench-record"), true),
    }
}

/// The episodes' load seconds: `--episode-seconds` each, the last one shorter.
fn plan(minutes: f64, episode_s: f64) -> Vec<f64> {
    let total = minutes * 60.0;
    let n = (total / episode_s - 1e-9).ceil().max(1.0) as usize;
    (0..n)
        .map(|i| (total - i as f64 * episode_s).min(episode_s))
        .collect()
}

/// Prepares `<out>/episodes`: an earlier run's files are cleared from the default directory,
/// refused in one the user named.
fn prepare(out: &Path, default: bool) -> Result<PathBuf> {
    let episodes = out.join("episodes");
    if episodes.is_dir() && std::fs::read_dir(&episodes)?.next().is_some() {
        ensure!(
            default,
            "{} holds files of an earlier run: remove them, or pass another --out",
            episodes.display()
        );
        std::fs::remove_dir_all(&episodes)
            .with_context(|| format!("clearing {}", episodes.display()))?;
    }
    std::fs::create_dir_all(&episodes)
        .with_context(|| format!("creating {}", episodes.display()))?;
    Ok(episodes)
}

/// Opens the load for [`WARM_UP`] and checks that every topic reaches the recorder.
fn warm_up(worker: &Worker, publisher: &LoadPublisher) -> Result<()> {
    let deadline = Instant::now() + Duration::from_secs(30);
    while worker
        .status()
        .and_then(|s| s["links"].as_u64())
        .unwrap_or(0)
        == 0
    {
        ensure!(
            Instant::now() < deadline,
            "the recorder did not connect within 30 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let before = worker
        .status()
        .map(|s| episode::received(&s))
        .unwrap_or_default();
    publisher.open();
    std::thread::sleep(WARM_UP);
    publisher.close(Duration::from_secs(10))?;
    let sent: Vec<u64> = publisher.counts().iter().map(|c| c.0).collect();
    let (all, _) = episode::drain(
        worker,
        publisher.topics(),
        &before,
        &sent,
        Duration::from_secs(30),
    );
    if !all {
        let status = worker.status().unwrap_or_default();
        let silent: Vec<&String> = publisher
            .topics()
            .iter()
            .filter(|t| status["topics"][t.as_str()][0].as_u64().unwrap_or(0) == 0)
            .collect();
        tracing::warn!(
            "warm-up: the recorder has not received everything sent yet (nothing at all of {silent:?})"
        );
    }
    Ok(())
}

/// Runs the soak (or, with `--worker`, the recorder under test).
pub fn run(args: BenchRecordArgs) -> Result<Outcome> {
    if args.worker {
        return worker::run(&args);
    }
    ensure!(
        args.minutes > 0.0 && args.episode_seconds > 0.0 && args.sample_seconds > 0.0,
        "--minutes, --episode-seconds and --sample-seconds must be positive"
    );
    let exe = std::env::current_exe().context("locating the scaledp executable")?;
    let (out, default) = out_dir(&args);
    prepare(&out, default)?;
    let report_path = args
        .report
        .clone()
        .unwrap_or_else(|| out.join("report.json"));
    let load = load::reference(args.load);
    load.rig().context("the soak's rig")?;
    std::fs::write(out.join("rig.toml"), load.rig_toml())?;
    let min_free = (args.min_free_gb * 1e9) as u64;
    if let Some(free) = episode::free_bytes(&out).filter(|&f| f < min_free) {
        bail!(
            "{}: {:.1} GB free, below --min-free-gb {}",
            out.display(),
            free as f64 / 1e9,
            args.min_free_gb
        );
    }
    let endpoint = loopback_endpoint(free_port()?);
    let session = net::open(net::zenoh_config(
        None,
        &[],
        std::slice::from_ref(&endpoint),
    )?)?;
    tracing::info!(
        "building the load: {:.0} MB/s offered",
        load.offered_bytes_per_s() / 1e6
    );
    let publisher = LoadPublisher::start(&session, &load)?;
    let mut worker = Worker::spawn(
        &exe,
        &out,
        &endpoint,
        args.compression,
        args.episode_seconds,
        args.min_free_gb,
    )?;
    worker.wait_event("ready", Duration::from_secs(60))?;
    warm_up(&worker, &publisher)?;

    let durations = plan(args.minutes, args.episode_seconds);
    let total: f64 = durations.iter().sum();
    let bar = ProgressBar::new(total as u64).with_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} s {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut soak = Soak {
        settings: serde_json::json!({
            "minutes": args.minutes, "episode_seconds": args.episode_seconds, "load": args.load,
            "compression": args.compression.flag(), "keep": args.keep,
            "min_free_gb": args.min_free_gb, "sample_seconds": args.sample_seconds,
            "rig": load.rig_toml(),
        }),
        cores: std::thread::available_parallelism().map_or(1, usize::from),
        load_average: (load_average(), None),
        offered_mb_s: load.offered_bytes_per_s() / 1e6,
        offered: load
            .offered()
            .into_iter()
            .map(|o| (o.topic, (o.rate_hz, o.bytes)))
            .collect(),
        ..Soak::default()
    };
    let pid = worker.pid();
    let (t0, cpu0) = (Instant::now(), cpu_seconds(pid));
    let own_cpu0 = cpu_seconds(std::process::id());
    let mut rss = Vec::new();
    let mut ctx = episode::Ctx {
        worker: &mut worker,
        publisher: &publisher,
        out: &out,
        keep: args.keep,
        min_free,
        sample_every: Duration::from_secs_f64(args.sample_seconds),
        t0,
        rss: &mut rss,
        last_sample: None,
        bar: &bar,
    };
    for (i, &seconds) in durations.iter().enumerate() {
        if let Some(free) = episode::free_bytes(&out).filter(|&f| f < min_free) {
            soak.stopped_early = Some(format!(
                "{:.1} GB free on the output disk before episode {}, below --min-free-gb",
                free as f64 / 1e9,
                i + 1
            ));
            break;
        }
        bar.set_message(format!("episode {}/{}", i + 1, durations.len()));
        let e = match episode::run(&mut ctx, i + 1, seconds) {
            Ok(e) => e,
            Err(e) => {
                soak.stopped_early = Some(format!("episode {}: {e:#}", i + 1));
                break;
            }
        };
        let cut = e.cut.clone();
        soak.episodes.push(e);

        if let Some(why) = cut {
            soak.stopped_early = Some(format!(
                "episode {} ended early ({why}); no further episode started",
                i + 1
            ));
            break;
        }
    }
    soak.wall_s = t0.elapsed().as_secs_f64();
    soak.cpu_s = cpu0.zip(cpu_seconds(pid)).map(|(a, b)| b - a);
    soak.publisher_cpu_s = own_cpu0
        .zip(cpu_seconds(std::process::id()))
        .map(|(a, b)| b - a);
    bar.finish_and_clear();
    soak.rss_peak = rss.iter().map(|s| s.1).max();
    soak.rss_after_first = soak.episodes.first().and_then(|e| e.rss_max);
    soak.rss_max_after_first = soak.episodes.iter().skip(1).filter_map(|e| e.rss_max).max();
    soak.rss = rss;
    publisher.stop();
    soak.worker_exit = worker.finish(Duration::from_secs(60)).unwrap_or_else(|e| {
        tracing::warn!("{e:#}");
        None
    });
    soak.load_average.1 = load_average();
    drop(session);
    report::report(&soak, &report_path)?;
    if let Some(why) = &soak.stopped_early {
        bail!(
            "the soak stopped after {} of {} episodes: {why}",
            soak.episodes.len(),
            durations.len()
        );
    }
    Ok(if soak.lost() > 0 || soak.bad_files() > 0 {
        Outcome::DataLost
    } else {
        Outcome::Completed
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episodes_fill_the_minutes_the_last_one_shorter() {
        assert_eq!(plan(60.0, 60.0), vec![60.0; 60]);
        assert_eq!(plan(0.5, 10.0), vec![10.0; 3]);
        assert_eq!(plan(0.25, 10.0), vec![10.0, 5.0]);
        assert_eq!(plan(0.1, 60.0), vec![6.0]);
    }
}
