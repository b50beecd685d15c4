//! What an evaluation reports, and the seed ranges it draws from: the options of a run, one
//! episode's outcome, the whole run's report with its Wilson interval, whichever simulator
//! (built in, behind a bridge, or live) produced it.

use std::path::PathBuf;

use scaledp_schema::Rig;
use serde::Serialize;

use crate::controller::ControlOptions;
use crate::error::{Error, Result};
use crate::stats::{wilson_interval, StageCount};

/// The first validation seed: checkpoints are chosen and recipes tuned on seeds from here.
pub const VALIDATION_SEED: u64 = 1_000_000;
/// The first development seed: the test range until 2026-11-28, when pilots had been scored on
/// it; kept for looking at a recipe's behaviour, never for a reported figure.
pub const DEVELOPMENT_SEED: u64 = 2_000_000;
/// The first test seed: success rates are reported on seeds from here, never used to choose
/// (fresh on 2026-11-28: no pilot or tuning run has seen them).
pub const TEST_SEED: u64 = 3_000_000;
/// The old name of [`VALIDATION_SEED`] (eval's default first seed before the split existed).
pub const HELD_OUT_SEED: u64 = VALIDATION_SEED;

/// Which fixed seed range an evaluation draws from. `scaledp collect` starts at 0 (a
/// collection of up to a million episodes stays below both).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Seeds 1 000 000 …: choosing checkpoints, tuning recipes.
    Val,
    /// Seeds 2 000 000 …: the old test range, seen by pilots; for development only.
    Dev,
    /// Seeds 3 000 000 …: the reported figures.
    Test,
}

impl Split {
    /// The range's first seed.
    pub fn first_seed(self) -> u64 {
        match self {
            Split::Val => VALIDATION_SEED,
            Split::Dev => DEVELOPMENT_SEED,
            Split::Test => TEST_SEED,
        }
    }
    /// The split a seed range starting at `seed` with `n` episodes lies in, if one.
    pub fn of(seed: u64, n: u64) -> Option<Split> {
        let end = seed.saturating_add(n);
        if seed >= TEST_SEED {
            Some(Split::Test)
        } else if seed >= DEVELOPMENT_SEED && end <= TEST_SEED {
            Some(Split::Dev)
        } else if seed >= VALIDATION_SEED && end <= DEVELOPMENT_SEED {
            Some(Split::Val)
        } else {
            None
        }
    }
}

/// Simulated time t is stamped `ORIGIN_NS + t` (an epoch time, as a rig's clock would give).
pub const ORIGIN_NS: u64 = 1_700_000_000_000_000_000;

/// What to run.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// Episodes.
    pub episodes: u64,
    /// First seed (episode i: seed + i).
    pub seed: u64,
    /// Longest episode (simulated s).
    pub max_seconds: f64,
    /// An episode ends early once the task has been a success for this long (s).
    pub settle_s: f64,
    /// The controller's settings.
    pub control: ControlOptions,
    /// Keep each rollout as an MCAP episode here (`episode_<i>.mcap`, i = episode number).
    pub recordings: Option<PathBuf>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            episodes: 50,
            seed: HELD_OUT_SEED,
            max_seconds: 30.0,
            settle_s: 1.0,
            control: ControlOptions::default(),
            recordings: None,
        }
    }
}

/// One episode's outcome.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct EpisodeReport {
    /// The episode's seed.
    pub seed: u64,
    /// Every cube resting within 3 cm of its target at the end.
    pub success: bool,
    /// When the task last became a success (simulated s), if it ended as one.
    pub time_to_success_s: Option<f64>,
    /// Simulated length (s).
    pub duration_s: f64,
    /// Horizontal distance of each cube to its target at the end (m).
    pub cube_distance_m: Vec<f64>,
    /// Chunks predicted.
    pub chunks: u64,
    /// Ticks with commands.
    pub commanded_ticks: u64,
    /// Ticks with a clamped command.
    pub clamped_ticks: u64,
    /// Ticks without an observation (stale or missing streams).
    pub halted_ticks: u64,
    /// Wall-clock time of the episode (s).
    pub wall_s: f64,
    /// The rollout's MCAP file (`--recordings`).
    pub recording: Option<String>,
    /// A staged task (ALOHA's, MetaWorld's): the furthest stage the episode reached
    /// ([`crate::StageCount`]). Read as `highest_reward` too, its name before MetaWorld had stages.
    #[serde(
        default,
        alias = "highest_reward",
        skip_serializing_if = "Option::is_none"
    )]
    pub highest_stage: Option<f64>,
}

/// The run's report (`--report` JSON).
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct EvalReport {
    /// The checkpoint directory.
    pub checkpoint: String,
    /// The rig.
    pub rig: String,
    /// `simulated-time` (inference takes no simulated time) or `live` (sim + serve over
    /// loopback Zenoh in real time).
    pub mode: String,
    /// First seed.
    pub seed: u64,
    /// Actions executed per chunk.
    pub action_steps: usize,
    /// Control rate (Hz).
    pub control_rate_hz: f64,
    /// Per episode.
    pub episodes: Vec<EpisodeReport>,
    /// Successes.
    pub successes: u64,
    /// Successes / episodes.
    pub success_rate: f64,
    /// 95 % Wilson score interval of the success rate.
    pub wilson_95: [f64; 2],
    /// Mean time to success over the successes (s).
    pub mean_time_to_success_s: Option<f64>,
    /// Inference latency per chunk, median (ms, wall clock).
    pub inference_ms_p50: Option<f64>,
    /// Inference latency per chunk, 99th percentile (ms).
    pub inference_ms_p99: Option<f64>,
    /// Live only: median over episodes of serve's newest-frame-to-first-command latency (ms).
    pub e2e_ms_p50: Option<f64>,
    /// Wall-clock time of the whole run (s).
    pub wall_s: f64,
    /// A bridge rig's simulator: its packages' versions (`metaworld`, `mujoco`, …).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulator: Option<std::collections::BTreeMap<String, String>>,
    /// Live on a bridge rig: the median over episodes of the simulation's speed against the
    /// wall clock (1: real time).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub real_time_factor: Option<f64>,
    /// A staged task (ALOHA's): per stage, the episodes that reached it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<StageCount>,
}

impl EpisodeReport {
    /// An episode of `seed` before it ran: nothing happened, not a success.
    pub fn empty(seed: u64) -> Self {
        EpisodeReport {
            seed,
            success: false,
            time_to_success_s: None,
            duration_s: 0.0,
            cube_distance_m: Vec::new(),
            chunks: 0,
            commanded_ticks: 0,
            clamped_ticks: 0,
            halted_ticks: 0,
            wall_s: 0.0,
            recording: None,
            highest_stage: None,
        }
    }
}

impl EvalReport {
    /// Writes the report as pretty JSON.
    pub fn write(&self, path: &std::path::Path) -> Result<()> {
        let io = |source| Error::Io {
            path: path.to_path_buf(),
            source,
        };
        let json = serde_json::to_vec_pretty(self).map_err(|e| io(e.into()))?;
        std::fs::write(path, json).map_err(io)
    }
}

/// The seeds a collection manifest (`collect.jsonl` of `scaledp collect`, one JSON object with a
/// `seed` per line) used.
pub fn collected_seeds(path: &std::path::Path) -> Result<std::collections::HashSet<u64>> {
    let bad = |m: String| Error::Options(format!("{}: {m}", path.display()));
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            let v: serde_json::Value =
                serde_json::from_str(l).map_err(|e| bad(format!("line {}: {e}", i + 1)))?;
            v["seed"]
                .as_u64()
                .ok_or_else(|| bad(format!("line {} has no seed", i + 1)))
        })
        .collect()
}

/// The report of `episodes` (latencies and wall time left for the caller).
pub(crate) fn summarize(
    ckpt: &str,
    rig: &Rig,
    mode: &str,
    opts: &EvalOptions,
    fps: f64,
    episodes: Vec<EpisodeReport>,
) -> EvalReport {
    let n = episodes.len() as u64;
    let successes = episodes.iter().filter(|e| e.success).count() as u64;
    let times: Vec<f64> = episodes
        .iter()
        .filter_map(|e| e.time_to_success_s)
        .collect();
    let (lo, hi) = wilson_interval(successes, n);
    EvalReport {
        checkpoint: ckpt.to_string(),
        rig: rig.name.clone(),
        mode: mode.into(),
        seed: opts.seed,
        action_steps: opts.control.action_steps,
        control_rate_hz: fps,
        successes,
        success_rate: successes as f64 / n.max(1) as f64,
        wilson_95: [lo, hi],
        mean_time_to_success_s: (!times.is_empty())
            .then(|| times.iter().sum::<f64>() / times.len() as f64),
        inference_ms_p50: None,
        inference_ms_p99: None,
        e2e_ms_p50: None,
        wall_s: 0.0,
        simulator: None,
        real_time_factor: None,
        stages: Vec::new(),
        episodes,
    }
}
