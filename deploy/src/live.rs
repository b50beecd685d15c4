//! `scaledp eval --live`: the simulator and `serve` in one process over a loopback Zenoh
//! session, in real time — the very path a real rig uses (Zenoh keys, CDR, the wall clock,
//! inference overlapping execution), at the price of real-time episodes. A bridge rig's
//! simulator runs on its own `/clock` instead, which `serve` follows ([`run_bridge_live`]). Per episode: the sim
//! is reset to the seed, half a second passes so every stream shows the new scene, a fresh
//! [`Server`] drives the arms until the task has been a success for `settle_s` or `max_seconds`
//! pass, and the scorer's verdict is read. Times are counted from the server's start.

use std::path::Path;
use std::time::{Duration, Instant};

use candle_core::Device;
use scaledp_policy::Policy;
use scaledp_schema::Rig;
use scaledp_sim::SimOptions;

use crate::error::Result;
use crate::report::{summarize, EpisodeReport, EvalOptions, EvalReport};
use crate::serve::{ServeOptions, Server};
use crate::stats::percentile;

/// Runs `opts.episodes` live episodes of the checkpoint in `checkpoint` on `rig`'s simulated
/// task, sim and server sharing `session` (a bridge rig: [`run_bridge_live`]).
pub fn run_live(
    checkpoint: &Path,
    device: &Device,
    rig: &Rig,
    opts: &EvalOptions,
    session: &zenoh::Session,
    on_episode: &mut dyn FnMut(&EpisodeReport),
) -> Result<EvalReport> {
    if rig.simulator.is_some() {
        return run_bridge_live(checkpoint, device, rig, opts, session, on_episode);
    }
    let started = Instant::now();
    let first = Policy::load(checkpoint, device)?;
    let ckpt = first.dir().display().to_string();
    let fps = first.config().fps;
    // Refuse a misfit before the sim starts.
    crate::check::check(first.config(), &ckpt, rig)?;
    let sim = SimOptions::new(rig.clone())
        .seed(opts.seed)
        .spawn(session)?;
    let mut policy = Some(first);
    let (mut p50s, mut p99s, mut e2e) = (Vec::new(), Vec::new(), Vec::new());
    let mut episodes = Vec::new();
    for i in 0..opts.episodes {
        let seed = opts.seed + i;
        sim.reset(seed);
        std::thread::sleep(Duration::from_millis(500));
        let p = match policy.take() {
            Some(p) => p,
            None => Policy::load(checkpoint, device)?,
        };
        let mut so = ServeOptions::new(rig.clone());
        so.control = opts.control.clone();
        so.status_key = format!("scaledp/eval/{}/status", std::process::id());
        so.seed = seed;
        let wall = Instant::now();
        let server = Server::start(p, so, session)?;
        let task = loop {
            std::thread::sleep(Duration::from_millis(50));
            let t = sim.task();
            let held = t
                .time_to_success_s
                .is_some_and(|ts| t.success && t.t_s - ts >= opts.settle_s);
            if held || wall.elapsed().as_secs_f64() >= opts.max_seconds {
                break t;
            }
        };
        let st = server.stop();
        let offset = t_offset(&task, wall.elapsed().as_secs_f64());
        p50s.extend(st.inference_ms_p50);
        p99s.extend(st.inference_ms_p99);
        e2e.extend(st.e2e_ms_p50);
        let ep = EpisodeReport {
            seed,
            success: task.success,
            time_to_success_s: task
                .success
                .then_some(task.time_to_success_s)
                .flatten()
                .map(|t| (t - offset).max(0.0)),
            duration_s: wall.elapsed().as_secs_f64(),
            cube_distance_m: task.cubes.iter().map(|c| c.distance_m).collect(),
            chunks: st.chunks,
            commanded_ticks: st.commanded_ticks,
            clamped_ticks: st.clamped_ticks,
            halted_ticks: st.halted_ticks,
            wall_s: wall.elapsed().as_secs_f64(),
            recording: None,
            highest_stage: None,
        };
        on_episode(&ep);
        episodes.push(ep);
    }
    sim.stop();
    let mut report = summarize(&ckpt, rig, "live", opts, fps, episodes);
    report.inference_ms_p50 = percentile(&p50s, 0.5);
    report.inference_ms_p99 = p99s.iter().copied().reduce(f64::max);
    report.e2e_ms_p50 = percentile(&e2e, 0.5);
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// Seconds between the sim's reset and the server's start: the task's clock minus the time the
/// server ran.
fn t_offset(task: &scaledp_sim::TaskState, served_s: f64) -> f64 {
    (task.t_s - served_s).max(0.0)
}

/// `eval --live` on a bridge rig (`metaworld/<task>`): the simulator live on the session with
/// its `/clock` ([`scaledp_sim::bridge::live`]), stepping as fast as it renders (never ahead of
/// real time), and a fresh [`Server`] per episode following that clock — inference on its own
/// thread, overlapping execution, its latency costing simulated time. An episode is a success
/// when the simulator reports one; it ends there, at the simulator's last step, or after
/// `max_seconds` of simulated time.
pub fn run_bridge_live(
    checkpoint: &Path,
    device: &Device,
    rig: &Rig,
    opts: &EvalOptions,
    session: &zenoh::Session,
    on_episode: &mut dyn FnMut(&EpisodeReport),
) -> Result<EvalReport> {
    use scaledp_sim::bridge::live::{LiveBridge, LiveOptions, STALL};
    let started = Instant::now();
    let first = Policy::load(checkpoint, device)?;
    let ckpt = first.dir().display().to_string();
    let fps = first.config().fps;
    crate::check::check(first.config(), &ckpt, rig)?;
    let prefix = format!("scaledp/eval/{}/sim", std::process::id());
    let mut lo = LiveOptions::new(rig.clone());
    lo.seed = opts.seed;
    lo.control_prefix = prefix;
    lo.clock_topic = format!("/scaledp_eval_{}/clock", std::process::id());
    let clock_topic = lo.clock_topic.clone();
    let mut sim = LiveBridge::spawn(lo, session)?;
    let mut policy = Some(first);
    let (mut p50s, mut p99s, mut e2e, mut rtfs) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut episodes = Vec::new();
    for i in 0..opts.episodes {
        let seed = opts.seed + i;
        // The bridge starts on the first seed's episode (resetting it again cost a reset for
        // nothing: ALOHA's plans the expert's 400 steps). From the second on, reset it and wait
        // for the new episode's first steps, so the server starts on its scene.
        if i > 0 {
            sim.reset(seed);
            let wait = Instant::now();
            while !(sim.task().seed == seed && sim.task().step < 4)
                && wait.elapsed() < Duration::from_secs(10)
            {
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        let p = match policy.take() {
            Some(p) => p,
            None => Policy::load(checkpoint, device)?,
        };
        let mut so = ServeOptions::new(rig.clone());
        so.control = opts.control.clone();
        so.status_key = format!("scaledp/eval/{}/status", std::process::id());
        so.seed = seed;
        so.clock = Some(clock_topic.clone());
        let wall = Instant::now();
        let server = Server::start(p, so, session)?;
        let task = loop {
            std::thread::sleep(Duration::from_millis(20));
            let t = sim.task();
            if t.time_to_success_s.is_some() || t.done || t.t_s >= opts.max_seconds {
                break t;
            }
            if let Err(e) = sim.check(STALL) {
                let _ = server.stop();
                return Err(e.into());
            }
        };
        let st = server.stop();
        p50s.extend(st.inference_ms_p50);
        p99s.extend(st.inference_ms_p99);
        e2e.extend(st.e2e_ms_p50);
        rtfs.push(task.real_time_factor);
        let mut ep = EpisodeReport::empty(seed);
        ep.success = task.time_to_success_s.is_some();
        ep.time_to_success_s = task.time_to_success_s;
        ep.duration_s = task.t_s;
        ep.highest_stage = task.highest_stage;
        ep.chunks = st.chunks;
        ep.commanded_ticks = st.commanded_ticks;
        ep.clamped_ticks = st.clamped_ticks;
        ep.halted_ticks = st.halted_ticks;
        ep.wall_s = wall.elapsed().as_secs_f64();
        on_episode(&ep);
        episodes.push(ep);
    }
    let hello = sim.hello().clone();
    sim.stop()?;
    let report = summarize(&ckpt, rig, "live", opts, fps, episodes);
    let mut report = crate::bridge_eval::with_simulator(&hello, report);
    report.inference_ms_p50 = percentile(&p50s, 0.5);
    report.inference_ms_p99 = p99s.iter().copied().reduce(f64::max);
    report.e2e_ms_p50 = percentile(&e2e, 0.5);
    report.real_time_factor = percentile(&rtfs, 0.5);
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}
