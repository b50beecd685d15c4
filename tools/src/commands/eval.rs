//! `scaledp eval`: a checkpoint's success rate on seeded episodes of the simulated task, in
//! simulated time (see `scaledp_deploy::eval`). Episode i uses seed `--seed + i`; the default
//! first seed (1 000 000) is far from `scaledp collect`'s (0, 1, …), and `--collected` refuses
//! any seed a collection manifest used.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_deploy::{run_eval, EvalOptions};
use scaledp_policy::Policy;

use super::serve::{rig_for, ControlArgs};
use crate::cli::ExitStatus;

/// `scaledp eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// A checkpoint directory, or a run directory (its latest checkpoint).
    pub checkpoint: PathBuf,
    /// Rig file or shipped rig name with a simulated task (default: the checkpoint's rig).
    #[arg(long)]
    pub rig: Option<String>,
    /// Episodes.
    #[arg(long, default_value_t = 50)]
    pub episodes: u64,
    /// First seed: episode i uses seed + i (held out: collect uses 0, 1, … by default).
    #[arg(long, default_value_t = scaledp_deploy::eval::HELD_OUT_SEED)]
    pub seed: u64,
    /// Longest episode (simulated s).
    #[arg(long, default_value_t = 30.0)]
    pub max_seconds: f64,
    /// End an episode once the task has been a success for this long (s).
    #[arg(long, default_value_t = 1.0)]
    pub settle_s: f64,
    /// Refuse seeds listed in this collection manifest (`collect.jsonl` of `scaledp collect`).
    #[arg(long, value_name = "FILE")]
    pub collected: Option<PathBuf>,
    /// Run the simulator and `serve` over a loopback Zenoh session in real time (the deployed
    /// path, inference overlapping execution) instead of the deterministic simulated time.
    #[arg(long)]
    pub live: bool,
    /// Keep each rollout as an MCAP episode here (episode_<i>.mcap, labelled by the scorer;
    /// `scaledp convert` takes them like recorded demonstrations).
    #[arg(long, value_name = "DIR")]
    pub recordings: Option<PathBuf>,
    /// The JSON report (default: eval-<rig>-seed<S>-n<N>.json in the checkpoint directory).
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// Show every rollout in a rerun viewer once the episodes are done (cameras, the arms in
    /// 3-D, state beside the commanded action, the scorer's label): a new viewer, or the one at
    /// URL. The rollouts go through MCAP files (--recordings, else a temporary directory).
    #[arg(long, value_name = "URL", num_args = 0..=1, conflicts_with = "live")]
    pub view: Option<Option<String>>,
    #[command(flatten)]
    pub control: ControlArgs,
}

/// Runs `scaledp eval`.
pub fn run(a: EvalArgs) -> Result<ExitStatus> {
    let dev = super::train::device(&a.control.device)?;
    let policy = Policy::load(&a.checkpoint, &dev)?;
    let rig = rig_for(&policy, a.rig.as_deref())?;
    if let Some(path) = &a.collected {
        let used = scaledp_deploy::eval::collected_seeds(path)?;
        if let Some(s) = (a.seed..a.seed + a.episodes).find(|s| used.contains(s)) {
            bail!(
                "seed {s} was used to collect demonstrations ({}): evaluate on held-out seeds (--seed)",
                path.display()
            );
        }
    }
    let opts = EvalOptions {
        episodes: a.episodes,
        seed: a.seed,
        max_seconds: a.max_seconds,
        settle_s: a.settle_s,
        control: a.control.options(&rig)?,
        recordings: a.recordings.clone(),
    };
    // With --view and no --recordings, the rollouts go to a temporary directory for the viewer.
    let scratch = match (&a.view, &a.recordings) {
        (Some(_), None) => Some(tempfile::tempdir()?),
        _ => None,
    };
    let mut opts = opts;
    if let Some(dir) = &scratch {
        opts.recordings = Some(dir.path().to_path_buf());
    }
    let bar = ProgressBar::new(a.episodes).with_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} episodes, eta {eta} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut ok = 0u64;
    if a.live && a.recordings.is_some() {
        bail!("--recordings is not available with --live (run `scaledp record` beside it)");
    }
    let mut on_episode = |e: &scaledp_deploy::EpisodeReport| {
        ok += u64::from(e.success);
        let outcome = match e.time_to_success_s {
            Some(t) if e.success => format!("success at {t:.1} s"),
            _ => format!(
                "failure (cube {} m from its target)",
                e.cube_distance_m
                    .iter()
                    .map(|d| format!("{d:.3}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        let line = format!(
            "seed {}: {outcome}, {:.1} s simulated, {} chunks, {} clamped ticks, {:.1} s wall",
            e.seed, e.duration_s, e.chunks, e.clamped_ticks, e.wall_s
        );
        bar.suspend(|| println!("{line}"));
        bar.inc(1);
        bar.set_message(format!("{ok} successes"));
    };
    let report = if a.live {
        // Only this process joins: a session listening on a free loopback port.
        let port = std::net::TcpListener::bind("127.0.0.1:0")?
            .local_addr()?
            .port();
        let config =
            scaledp_recorder::net::zenoh_config(None, &[], &[format!("tcp/127.0.0.1:{port}")])?;
        let session = scaledp_recorder::net::open(config)?;
        let dev = super::train::device(&a.control.device)?;
        let dir = policy.dir().to_path_buf();
        drop(policy);
        scaledp_deploy::run_live(&dir, &dev, &rig, &opts, &session, &mut on_episode)?
    } else {
        run_eval(&policy, &rig, &opts, &mut on_episode)?
    };
    bar.finish_and_clear();
    let path = a.report.clone().unwrap_or_else(|| {
        std::path::Path::new(&report.checkpoint).join(format!(
            "eval-{}-seed{}-n{}.json",
            rig.name, a.seed, a.episodes
        ))
    });
    report.write(&path)?;
    let ms = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.0}"));
    let [lo, hi] = report.wilson_95;
    println!(
        "{} episodes of {} (seeds {}..={}): {} successes ({:.1} %, 95 % Wilson {:.1}–{:.1} %), \
         mean time to success {}, inference p50 {} ms p99 {} ms{}, {:.1} s wall; report {}",
        report.episodes.len(),
        rig.name,
        a.seed,
        a.seed + a.episodes.saturating_sub(1),
        report.successes,
        report.success_rate * 100.0,
        lo * 100.0,
        hi * 100.0,
        report
            .mean_time_to_success_s
            .map_or("–".into(), |t| format!("{t:.1} s")),
        ms(report.inference_ms_p50),
        ms(report.inference_ms_p99),
        report
            .e2e_ms_p50
            .map_or(String::new(), |v| format!(", frame→command p50 {v:.0} ms")),
        report.wall_s,
        path.display()
    );
    if let (Some(url), Some(dir)) = (&a.view, &opts.recordings) {
        let rollouts: Vec<String> = report
            .episodes
            .iter()
            .filter_map(|e| e.recording.clone())
            .collect();
        if rollouts.is_empty() {
            bail!("--view: no rollout was recorded in {}", dir.display());
        }
        super::view::show(&rollouts, url.as_deref())?;
    }
    Ok(ExitStatus::Success)
}
