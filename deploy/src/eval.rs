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

use std::sync::Arc;
use std::time::Instant;

use scaledp_policy::Policy;
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::render::{render, View};
use scaledp_sim::{messages, ArmCommand, Scene, World};

use crate::controller::Controller;
use crate::error::{Error, Result};
use crate::recording::Rollout;
use crate::report::summarize;
pub use crate::report::{
    collected_seeds, EpisodeReport, EvalOptions, EvalReport, Split, DEVELOPMENT_SEED,
    HELD_OUT_SEED, ORIGIN_NS, TEST_SEED, VALIDATION_SEED,
};
use crate::stats::percentile;

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
