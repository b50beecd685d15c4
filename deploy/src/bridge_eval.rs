//! `scaledp eval` on a rig whose simulator runs behind the bridge protocol (`metaworld/<task>`):
//! the simulator advances only when the controller has acted, one step per control tick, so a
//! seed fixes the result whatever the model's latency. Per tick: the step's observation goes
//! to the [`Controller`] as the CDR messages the bridge publishes live (stamped on the
//! simulation's clock), the controller ticks at that very instant ([`ControlOptions`]'s
//! lockstep: every stream's sample for the tick is in before it), the policy runs when asked,
//! and the tick's commands (or none: the simulator holds its last target) step the simulator.
//! An episode is a success when the simulator reports success at any step (MetaWorld's
//! `info["success"]`), and ends there or at the simulator's last step. The scripted expert
//! (the ceiling control) runs the same loop with the simulator's own expert instead. A task
//! whose simulator names stages (ALOHA's rewards, MetaWorld's flags) also reports each episode's
//! furthest stage and, per stage, how many episodes reached it.

use std::time::Instant;

use scaledp_policy::Policy;
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::bridge::{Bridge, Hello, Observation};
use scaledp_sim::{messages, ArmCommand};

use crate::controller::{ControlOptions, Controller};
use crate::error::{Error, Result};
use crate::recording::Rollout;
use crate::report::{summarize, EpisodeReport, EvalOptions, EvalReport, ORIGIN_NS};
use crate::stats::{percentile, stage_counts};

/// Hands one observation to the controller (and the rollout), stamped `t_ns`.
fn feed(
    rig: &Rig,
    obs: &Observation,
    t_ns: u64,
    ctl: &mut Controller,
    mut rollout: Option<&mut Rollout>,
) -> Result<()> {
    for (i, (cam, px)) in rig.cameras.iter().zip(&obs.images).enumerate() {
        let cdr = messages::image(cam, px.clone(), t_ns).to_cdr();
        if let Some(r) = rollout.as_deref_mut() {
            r.write(&cam.topic, t_ns, &cdr)?;
        }
        ctl.on_image(i, t_ns, t_ns, cam.message_type(), cdr);
    }
    for (a, (arm, reading)) in rig.arms.iter().zip(&obs.arms).enumerate() {
        if let Some(r) = rollout.as_deref_mut() {
            let js = messages::joint_state_of(arm, &reading.q, t_ns);
            r.write(&arm.joint_state_topic, t_ns, &js.to_cdr())?;
            if let Some(g) = &arm.gripper {
                let mut m = messages::gripper_state(g, 0.0, t_ns);
                m.position = reading.gripper_q.clone();
                r.write(&g.topic, t_ns, &m.to_cdr())?;
            }
        }
        ctl.on_arm_joints(a, t_ns, t_ns, reading.q.clone());
        ctl.on_gripper_joints(a, t_ns, t_ns, reading.gripper_q.clone());
    }
    Ok(())
}

/// Writes a tick's commands into the rollout.
fn record_commands(rig: &Rig, cmds: &[ArmCommand], t_ns: u64, r: &mut Rollout) -> Result<()> {
    for (arm, c) in rig.arms.iter().zip(cmds) {
        if let (Some(topic), Some(m)) =
            (&arm.command_topic, messages::arm_command_cdr(arm, c, t_ns))
        {
            r.write(topic, t_ns, &m)?;
        }
        if let Some(g) = &arm.gripper {
            if let (Some(topic), Some(w)) = (&g.command_topic, c.gripper_width_m) {
                r.write(topic, t_ns, &messages::gripper_command(g, w, t_ns).to_cdr())?;
            }
        }
    }
    Ok(())
}

/// What the simulator adds to a report: its versions, and the stage counts of the episodes
/// when it names stages.
pub(crate) fn with_simulator(hello: &Hello, mut report: EvalReport) -> EvalReport {
    report.simulator = Some(hello.versions.clone());
    let names = &hello.stages;
    if !names.is_empty() {
        let highest: Vec<Option<f64>> = report.episodes.iter().map(|e| e.highest_stage).collect();
        report.stages = stage_counts(names, &highest);
    }
    report
}

/// The furthest stage so far, for a simulator that names stages.
fn track(bridge: &Bridge, highest: &mut Option<f64>, obs: &Observation) {
    if !bridge.hello().stages.is_empty() {
        *highest = Some(highest.map_or(obs.stage, |h| h.max(obs.stage)));
    }
}

/// The last step of an episode: the simulator's, or fewer within `max_seconds`.
fn last_step(bridge: &Bridge, opts: &EvalOptions) -> u64 {
    let by_time = (opts.max_seconds / bridge.hello().step_s).floor() as u64;
    bridge.hello().max_steps.min(by_time.max(1))
}

/// Runs `opts.episodes` episodes of `policy` on `rig`'s simulator in simulated time.
pub fn run_bridge_eval(
    policy: &Policy,
    rig: &Rig,
    opts: &EvalOptions,
    on_episode: &mut dyn FnMut(&EpisodeReport),
) -> Result<EvalReport> {
    let ckpt = policy.dir().display().to_string();
    let control = ControlOptions {
        lockstep: true,
        ..opts.control.clone()
    };
    let mut ctl = Controller::new(policy.config(), &ckpt, rig, control)?;
    let mut bridge = Bridge::spawn(rig)?;
    let dt = bridge.step_ns();
    if ctl.period_ns().abs_diff(dt) > 1_000 {
        return Err(Error::Incompatible(format!(
            "{ckpt} acts at {} Hz, the simulator of {} steps at {:.1} Hz: convert the \
             demonstrations at the simulator's rate",
            policy.config().fps,
            rig.name,
            1.0 / bridge.hello().step_s
        )));
    }
    let started = Instant::now();
    let mut latencies_ms = Vec::new();
    let mut episodes = Vec::new();
    for i in 0..opts.episodes {
        let seed = opts.seed + i;
        let wall = Instant::now();
        let mut rollout = match &opts.recordings {
            Some(dir) => Some(Rollout::create(dir, i, rig, seed, &ckpt, ORIGIN_NS)?),
            None => None,
        };
        ctl.reset();
        let mut obs = bridge.reset(seed, true)?;
        let end = last_step(&bridge, opts);
        let mut rep = EpisodeReport::empty(seed);
        let mut success_at = None;
        loop {
            let t = ORIGIN_NS + obs.step * dt;
            track(&bridge, &mut rep.highest_stage, &obs);
            feed(rig, &obs, t, &mut ctl, rollout.as_mut())?;
            if obs.success {
                success_at = Some(obs.step);
                break;
            }
            if obs.done || obs.step >= end {
                break;
            }
            let tick = ctl.tick(t);
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
            let cmds: Vec<ArmCommand> = match ctl.command() {
                Ok(cmds) => {
                    rep.commanded_ticks += 1;
                    rep.clamped_ticks += u64::from(cmds.iter().any(|c| c.clamped.any()));
                    cmds.iter().map(ArmCommand::from).collect()
                }
                // Filling the window or halted: the simulator holds the last target.
                Err(_) => vec![ArmCommand::default(); rig.arms.len()],
            };
            if let Some(r) = rollout.as_mut() {
                record_commands(rig, &cmds, t, r)?;
            }
            obs = bridge.step(&cmds, true)?;
        }
        let s = dt as f64 * 1e-9;
        rep.success = success_at.is_some();
        rep.time_to_success_s = success_at.map(|k| k as f64 * s);
        rep.duration_s = obs.step as f64 * s;
        rep.wall_s = wall.elapsed().as_secs_f64();
        if let Some(r) = rollout {
            let end_ns = ORIGIN_NS + obs.step * dt;
            rep.recording = Some(
                r.finish(rep.success, end_ns, rep.duration_s)?
                    .display()
                    .to_string(),
            );
        }
        on_episode(&rep);
        episodes.push(rep);
    }
    let mut report = with_simulator(
        bridge.hello(),
        summarize(
            &ckpt,
            rig,
            "simulated-time",
            opts,
            policy.config().fps,
            episodes,
        ),
    );
    report.inference_ms_p50 = percentile(&latencies_ms, 0.5);
    report.inference_ms_p99 = percentile(&latencies_ms, 0.99);
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The ceiling control on a bridge rig: the simulator's scripted expert on the same seeds,
/// ended by the same rule.
pub fn run_bridge_expert(
    rig: &Rig,
    opts: &EvalOptions,
    on_episode: &mut dyn FnMut(&EpisodeReport),
) -> Result<EvalReport> {
    let mut bridge = Bridge::spawn(rig)?;
    let s = bridge.hello().step_s;
    let started = Instant::now();
    let mut episodes = Vec::new();
    for i in 0..opts.episodes {
        let seed = opts.seed + i;
        let wall = Instant::now();
        let mut obs = bridge.reset(seed, false)?;
        let end = last_step(&bridge, opts);
        let mut rep = EpisodeReport::empty(seed);
        track(&bridge, &mut rep.highest_stage, &obs);
        while !obs.success && !obs.done && obs.step < end {
            obs = bridge.expert_step(false)?;
            track(&bridge, &mut rep.highest_stage, &obs);
        }
        rep.success = obs.success;
        rep.time_to_success_s = obs.success.then_some(obs.step as f64 * s);
        rep.duration_s = obs.step as f64 * s;
        rep.wall_s = wall.elapsed().as_secs_f64();
        on_episode(&rep);
        episodes.push(rep);
    }
    let mut report = with_simulator(
        bridge.hello(),
        summarize(
            "(scripted expert)",
            rig,
            "scripted-expert",
            opts,
            1.0 / s,
            episodes,
        ),
    );
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}
