//! `scaledp eval`: a checkpoint's success rate on seeded episodes of the simulated task, in
//! simulated time (see `scaledp_deploy::eval`). Episode i uses seed `first + i`, the first seed
//! of the chosen split (`--split val`: 1 000 000, for choosing checkpoints and tuning; `dev`:
//! 2 000 000, the old test range, seen by pilots; `test`: 3 000 000, for reporting) or `--seed`;
//! all are far from `scaledp collect`'s (0, 1, …).
//! The seeds of the demonstrations a checkpoint was trained on are refused: those listed in
//! `--collected`, and those of the `collect.jsonl` manifests beside the recordings its dataset
//! was converted from (found through the dataset's `meta/info.json`). The controls: `--expert`
//! (the scripted teleoperator on the same seeds) and `--freeze-cameras` (the policy seeing only
//! each episode's first frames).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_deploy::{run_eval, run_expert, EpisodeReport, EvalOptions, EvalReport, Split};
use scaledp_policy::Policy;

use crate::shared::{self, rig_for, ControlArgs};

/// `--split`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum SplitArg {
    /// Validation seeds (1 000 000 …).
    Val,
    /// Development seeds (2 000 000 …: the test range until 2026-11-28, seen by pilots).
    Dev,
    /// Test seeds (3 000 000 …).
    Test,
}

impl From<SplitArg> for Split {
    fn from(s: SplitArg) -> Split {
        match s {
            SplitArg::Val => Split::Val,
            SplitArg::Dev => Split::Dev,
            SplitArg::Test => Split::Test,
        }
    }
}
use crate::cli::ExitStatus;

/// `scaledp eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// A checkpoint directory, or a run directory (its latest checkpoint); not with --expert.
    #[arg(required_unless_present = "expert")]
    pub checkpoint: Option<PathBuf>,
    /// Rig file or shipped rig name with a simulated task (default: the checkpoint's rig).
    #[arg(long)]
    pub rig: Option<String>,
    /// Episodes.
    #[arg(long, default_value_t = 50)]
    pub episodes: u64,
    /// The seed range: val (from 1 000 000: choose checkpoints and tune on it), dev (from
    /// 2 000 000: the old test range, seen by pilots) or test (from 3 000 000: report it).
    #[arg(long, value_enum, default_value = "test")]
    pub split: SplitArg,
    /// First seed instead of the split's: episode i uses seed + i.
    #[arg(long)]
    pub seed: Option<u64>,
    /// The ceiling control: score the scripted teleoperator that recorded the demonstrations on
    /// the same seeds (needs --rig, takes no checkpoint).
    #[arg(long, conflicts_with_all = ["live", "recordings", "view", "freeze_cameras"])]
    pub expert: bool,
    /// The vision control: the policy sees each episode's first camera frames throughout (the
    /// state stays live).
    #[arg(long)]
    pub freeze_cameras: bool,
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
    let seed = a.seed.unwrap_or(Split::from(a.split).first_seed());
    if a.expert {
        return expert(&a, seed);
    }
    let Some(checkpoint) = &a.checkpoint else {
        bail!("name a CHECKPOINT (or --expert)");
    };
    let dev = shared::device(&a.control.device)?;
    let policy = Policy::load(checkpoint, &dev)?;
    let rig = rig_for(&policy, a.rig.as_deref())?;
    let mut manifests: Vec<PathBuf> = a.collected.iter().cloned().collect();
    manifests.extend(shared::training_manifests(&policy.config().dataset));
    for path in &manifests {
        let used = scaledp_deploy::eval::collected_seeds(path)?;
        if let Some(s) = (seed..seed + a.episodes).find(|s| used.contains(s)) {
            bail!(
                "seed {s} was used to collect demonstrations ({}): evaluate on held-out seeds (--split, --seed)",
                path.display()
            );
        }
    }
    let opts = EvalOptions {
        episodes: a.episodes,
        seed,
        max_seconds: a.max_seconds,
        settle_s: a.settle_s,
        control: scaledp_deploy::ControlOptions {
            freeze_cameras: a.freeze_cameras,
            ..a.control
                .options(&rig, policy.config().model.action_chunk)?
        },
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
    if a.live && a.recordings.is_some() {
        bail!("--recordings is not available with --live (run `scaledp record` beside it)");
    }
    let report = with_progress(a.episodes, |on_episode| {
        Ok(if a.live {
            let session = scaledp_recorder::net::open_private()?;
            let dev = shared::device(&a.control.device)?;
            scaledp_deploy::run_live(policy.dir(), &dev, &rig, &opts, &session, on_episode)?
        } else {
            run_eval(&policy, &rig, &opts, on_episode)?
        })
    })?;
    let dir = std::path::Path::new(&report.checkpoint);
    finish(&a, &report, &rig, seed, dir)?;
    if let (Some(url), Some(dir)) = (&a.view, &opts.recordings) {
        let rollouts: Vec<String> = report
            .episodes
            .iter()
            .filter_map(|e| e.recording.clone())
            .collect();
        if rollouts.is_empty() {
            bail!("--view: no rollout was recorded in {}", dir.display());
        }
        shared::viewer::show(&rollouts, url.as_deref())?;
    }
    Ok(ExitStatus::Success)
}

/// `--expert`: the scripted teleoperator on the same seeds.
fn expert(a: &EvalArgs, seed: u64) -> Result<ExitStatus> {
    let Some(name) = &a.rig else {
        bail!("--expert needs --rig (the simulated rig whose operator to score)");
    };
    let rig = scaledp_schema::Rig::load_or_builtin(name)?;
    let opts = EvalOptions {
        episodes: a.episodes,
        seed,
        max_seconds: a.max_seconds,
        settle_s: a.settle_s,
        ..EvalOptions::default()
    };
    let report = with_progress(a.episodes, |on_episode| {
        Ok(run_expert(&rig, &opts, on_episode)?)
    })?;
    finish(a, &report, &rig, seed, std::path::Path::new("."))?;
    Ok(ExitStatus::Success)
}

/// Runs `f` with a progress bar and one printed line per episode.
fn with_progress(
    episodes: u64,
    f: impl FnOnce(&mut dyn FnMut(&EpisodeReport)) -> Result<EvalReport>,
) -> Result<EvalReport> {
    let bar = ProgressBar::new(episodes).with_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} episodes, eta {eta} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut ok = 0u64;
    let mut on_episode = |e: &EpisodeReport| {
        ok += u64::from(e.success);
        let outcome = match e.time_to_success_s {
            Some(t) if e.success => format!("success at {t:.1} s"),
            _ if e.cube_distance_m.is_empty() => "failure".to_string(),
            _ => format!(
                "failure (cube {} m from its target)",
                e.cube_distance_m
                    .iter()
                    .map(|d| format!("{d:.3}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        let stage = e
            .highest_stage
            .map_or(String::new(), |r| format!(", furthest stage {r}"));
        let line = format!(
            "seed {}: {outcome}{stage}, {:.1} s simulated, {} chunks, {} clamped ticks, {:.1} s wall",
            e.seed, e.duration_s, e.chunks, e.clamped_ticks, e.wall_s
        );
        bar.suspend(|| println!("{line}"));
        bar.inc(1);
        bar.set_message(format!("{ok} successes"));
    };
    let report = f(&mut on_episode);
    bar.finish_and_clear();
    report
}

/// Writes the JSON report (`--report`, else `eval-<rig>-seed<S>-n<N>[-expert|-frozen].json` in
/// `dir`) and prints the summary line.
fn finish(
    a: &EvalArgs,
    report: &EvalReport,
    rig: &scaledp_schema::Rig,
    seed: u64,
    dir: &std::path::Path,
) -> Result<()> {
    let suffix = match (a.expert, a.freeze_cameras, a.live) {
        (true, _, _) => "-expert",
        (_, true, _) => "-frozen",
        (_, _, true) => "-live",
        _ => "",
    };
    let path = a.report.clone().unwrap_or_else(|| {
        dir.join(format!(
            "eval-{}-seed{seed}-n{}{suffix}.json",
            rig.name.replace('/', "_"),
            a.episodes
        ))
    });
    report.write(&path)?;
    let ms = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.0}"));
    let [lo, hi] = report.wilson_95;
    println!(
        "{} episodes of {} ({}, seeds {}..={}): {} successes ({:.1} %, 95 % Wilson {:.1}–{:.1} %), \
         mean time to success {}, inference p50 {} ms p99 {} ms{}, {:.1} s wall; report {}",
        report.episodes.len(),
        rig.name,
        report.mode,
        seed,
        seed + a.episodes.saturating_sub(1),
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
    if !report.stages.is_empty() {
        let stages: Vec<String> = report
            .stages
            .iter()
            .map(|s| format!("{} {}/{}", s.stage, s.episodes, report.episodes.len()))
            .collect();
        println!(
            "stages reached (furthest stage ≥ 1, 2, …): {}",
            stages.join(", ")
        );
    }
    Ok(())
}
