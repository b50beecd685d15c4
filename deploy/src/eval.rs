//! `scaledp eval`: seeded episodes of the simulated task in simulated time. The world is
//! stepped event by event (camera captures at each camera's fps, joint samples at each arm's
//! and gripper's rate, control ticks at the checkpoint's fps), the cameras rendered and wrapped
//! in the messages the live simulator publishes, and the same [`Controller`] called
//! synchronously: inference takes no simulated time, so a run is deterministic and as fast as
//! the CPU allows, whatever the model's latency.
//!
//! Seeds: episode i uses seed `seed + i`. `scaledp collect` records episode i with seed
//! `--seed + i` (default 0, so 100 demonstrations use seeds 0–99); eval's default first seed is
//! [`HELD_OUT_SEED`], far from any collection run's, so evaluation scenes are never training
//! scenes.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use scaledp_policy::Policy;
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::render::{render, View};
use scaledp_sim::{messages, ArmCommand, Scene, World};
use serde::Serialize;

use crate::controller::{ControlOptions, Controller};
use crate::error::{Error, Result};
use crate::recording::Rollout;
use crate::stats::{percentile, wilson_interval, StageCount};

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

/// A stream of the simulated rig: what it is and when it next samples.
enum Source {
    Camera { rig_index: usize, view: View },
    Arm(usize),
    Gripper(usize),
}

/// Runs `opts.episodes` episodes of `policy` on `rig`'s simulated task (the built-in cell, or
/// the rig's bridge simulator: [`crate::bridge_eval`]); `on_episode` sees each outcome as it
/// comes.
pub fn run_eval(
    policy: &Policy,
    rig: &Rig,
    opts: &EvalOptions,
    on_episode: &mut dyn FnMut(&EpisodeReport),
) -> Result<EvalReport> {
    if rig.simulator.is_some() {
        return crate::bridge_eval::run_bridge_eval(policy, rig, opts, on_episode);
    }
    let ckpt = policy.dir().display().to_string();
    let mut ctl = Controller::new(policy.config(), &ckpt, rig, opts.control.clone())?;
    if !(opts.max_seconds > 0.0 && opts.max_seconds.is_finite()) {
        return Err(Error::Options(format!(
            "--max-seconds {}",
            opts.max_seconds
        )));
    }
    let scene = Arc::new(Scene::new(rig));
    let started = Instant::now();
    let mut latencies_ms = Vec::new();
    let mut episodes = Vec::new();
    for i in 0..opts.episodes {
        let seed = opts.seed + i;
        let mut rollout = match &opts.recordings {
            Some(dir) => Some(Rollout::create(dir, i, rig, seed, &ckpt, ORIGIN_NS)?),
            None => None,
        };
        let mut ep = episode(
            policy,
            rig,
            &scene,
            &mut ctl,
            seed,
            opts,
            &mut latencies_ms,
            rollout.as_mut(),
        )?;
        if let Some(r) = rollout {
            let end = ORIGIN_NS + (ep.duration_s * 1e9) as u64;
            let path = r.finish(ep.success, end, ep.duration_s)?;
            ep.recording = Some(path.display().to_string());
        }
        on_episode(&ep);
        episodes.push(ep);
    }
    let mut report = summarize(
        &ckpt,
        rig,
        "simulated-time",
        opts,
        policy.config().fps,
        episodes,
    );
    report.inference_ms_p50 = percentile(&latencies_ms, 0.5);
    report.inference_ms_p99 = percentile(&latencies_ms, 0.99);
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
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

#[allow(clippy::too_many_arguments)]
fn episode(
    policy: &Policy,
    rig: &Rig,
    scene: &Arc<Scene>,
    ctl: &mut Controller,
    seed: u64,
    opts: &EvalOptions,
    latencies_ms: &mut Vec<f64>,
    mut rollout: Option<&mut Rollout>,
) -> Result<EpisodeReport> {
    let wall = Instant::now();
    let mut world = World::with_scene(scene.clone(), seed);
    ctl.reset();
    let mut sources: Vec<(Source, u64, u64)> = Vec::new(); // (source, period ns, next ns)
    let period = |hz: f64| (1e9 / hz).round().max(1.0) as u64;
    // Every camera when recording (a converted rollout needs them all), else the checkpoint's.
    let cameras: Vec<usize> = match rollout {
        Some(_) => (0..rig.cameras.len()).collect(),
        None => ctl.cameras().to_vec(),
    };
    for c in cameras {
        let cam = &rig.cameras[c];
        let view = View::for_camera(scene, cam, c);
        sources.push((Source::Camera { rig_index: c, view }, period(cam.fps), 0));
    }
    for (a, arm) in rig.arms.iter().enumerate() {
        sources.push((Source::Arm(a), period(arm.rate_hz), 0));
        if let Some(g) = &arm.gripper {
            sources.push((Source::Gripper(a), period(g.rate_hz), 0));
        }
    }
    let tick_period = ctl.period_ns();
    let mut next_tick = tick_period;
    let end_ns = (opts.max_seconds * 1e9) as u64;
    let mut pixels = Vec::new();
    let mut rep = EpisodeReport::empty(seed);
    loop {
        let next_sample = sources.iter().map(|s| s.2).min().unwrap_or(u64::MAX);
        let t = next_sample.min(next_tick);
        if t > end_ns {
            break;
        }
        world.step(t.saturating_sub(world.time_ns()) as f64 * 1e-9, &[]);
        let abs = ORIGIN_NS + t;
        for (src, per, next) in sources.iter_mut().filter(|s| s.2 == t) {
            *next += *per;
            match src {
                Source::Camera { rig_index, view } => {
                    let cam = &rig.cameras[*rig_index];
                    render(scene, view, &world.state(), cam.encoding(), &mut pixels);
                    let cdr = messages::image(cam, pixels.clone(), abs).to_cdr();
                    if let Some(r) = rollout.as_deref_mut() {
                        r.write(&cam.topic, abs, &cdr)?;
                    }
                    ctl.on_image(*rig_index, abs, abs, "sensor_msgs/msg/Image", cdr);
                }
                Source::Arm(a) => {
                    let s = world.arm_state(*a);
                    if let Some(r) = rollout.as_deref_mut() {
                        let arm = &rig.arms[*a];
                        let js = messages::joint_state(arm, &s, abs).to_cdr();
                        r.write(&arm.joint_state_topic, abs, &js)?;
                    }
                    ctl.on_arm_joints(*a, abs, abs, s.q);
                }
                Source::Gripper(a) => {
                    let s = world.arm_state(*a);
                    if let Some(g) = &rig.arms[*a].gripper {
                        if let Some(r) = rollout.as_deref_mut() {
                            let js = messages::gripper_state(g, s.gripper_width_m, abs).to_cdr();
                            r.write(&g.topic, abs, &js)?;
                        }
                        let q = g
                            .model
                            .positions_for_width(s.gripper_width_m, g.joint_names.len());
                        ctl.on_gripper_joints(*a, abs, abs, q);
                    }
                }
            }
        }
        if t == next_tick {
            next_tick += tick_period;
            let tick = ctl.tick(abs);
            if tick.halted.is_some() {
                rep.halted_ticks += 1;
            }
            if let Some(req) = tick.request {
                let started = Instant::now();
                let chunk =
                    policy.predict(&req.observation, seed.wrapping_mul(1_000_003) ^ req.index)?;
                latencies_ms.push(started.elapsed().as_secs_f64() * 1e3);
                rep.chunks += 1;
                ctl.install(req.index, &chunk);
            }
            if let Ok(cmds) = ctl.command() {
                rep.commanded_ticks += 1;
                rep.clamped_ticks += u64::from(cmds.iter().any(|c| c.clamped.any()));
                if let Some(r) = rollout.as_deref_mut() {
                    for c in &cmds {
                        let arm = &rig.arms[c.arm];
                        let m = messages::arm_command_cdr(arm, &ArmCommand::from(c), abs);
                        if let (Some(topic), Some(m)) = (&arm.command_topic, m) {
                            r.write(topic, abs, &m)?;
                        }
                        if let (Some(g), Some(w)) = (&arm.gripper, c.gripper_width_m) {
                            if let Some(topic) = &g.command_topic {
                                let m = messages::gripper_command(g, w, abs);
                                r.write(topic, abs, &m.to_cdr())?;
                            }
                        }
                    }
                }
                let arm_cmds: Vec<ArmCommand> = cmds.iter().map(ArmCommand::from).collect();
                world.step(0.0, &arm_cmds);
            }
            let task = world.task_state();
            if let Some(ts) = task.time_to_success_s {
                if task.success && world.time_s() - ts >= opts.settle_s {
                    break;
                }
            }
        }
    }
    let task = world.task_state();
    rep.success = task.success;
    rep.time_to_success_s = task.success.then_some(task.time_to_success_s).flatten();
    rep.duration_s = world.time_s();
    rep.cube_distance_m = task.cubes.iter().map(|c| c.distance_m).collect();
    rep.wall_s = wall.elapsed().as_secs_f64();
    Ok(rep)
}
