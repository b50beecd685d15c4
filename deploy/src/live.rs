//! `scaledp eval --live`: the simulator and `serve` in one process over a loopback Zenoh
//! session, in real time — the very path a real rig uses (Zenoh keys, CDR, the wall clock,
//! inference overlapping execution), at the price of real-time episodes. Per episode: the sim
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
use crate::eval::{summarize, EpisodeReport, EvalOptions, EvalReport};
use crate::serve::{ServeOptions, Server};
use crate::stats::percentile;

/// Runs `opts.episodes` live episodes of the checkpoint in `checkpoint` on `rig`'s simulated
/// task, sim and server sharing `session`.
pub fn run_live(
    checkpoint: &Path,
    device: &Device,
    rig: &Rig,
    opts: &EvalOptions,
    session: &zenoh::Session,
    on_episode: &mut dyn FnMut(&EpisodeReport),
) -> Result<EvalReport> {
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
