//! The ceiling control of an evaluation: the scripted teleoperator that recorded the
//! demonstrations, on the same seeds, scored by the same scorer and ended by the same rule (the
//! task a success for `settle_s`, or `max_seconds`), so a policy's success rate reads against
//! what its teacher achieves on those very scenes.

use std::sync::Arc;
use std::time::Instant;

use scaledp_schema::Rig;
use scaledp_sim::{OfflineRun, Scene};

use crate::error::{Error, Result};
use crate::report::{summarize, EpisodeReport, EvalOptions, EvalReport};

/// Simulated-time step of the expert's episodes (the operator samples its leader at 100 Hz).
const STEP_NS: u64 = 10_000_000;

/// Runs the scripted expert on `opts.episodes` seeds from `opts.seed` of `rig`'s task.
pub fn run_expert(
    rig: &Rig,
    opts: &EvalOptions,
    on_episode: &mut dyn FnMut(&EpisodeReport),
) -> Result<EvalReport> {
    if rig.simulator.is_some() {
        return crate::bridge_eval::run_bridge_expert(rig, opts, on_episode);
    }
    if rig.arms.is_empty() {
        return Err(Error::Options(format!(
            "rig {} has no arm to operate",
            rig.name
        )));
    }
    let scene = Arc::new(Scene::new(rig));
    let started = Instant::now();
    let end_ns = (opts.max_seconds * 1e9) as u64;
    let mut episodes = Vec::new();
    for i in 0..opts.episodes {
        let seed = opts.seed + i;
        let wall = Instant::now();
        let mut run = OfflineRun::new(scene.clone(), seed);
        let mut t = 0;
        while t < end_ns {
            t += STEP_NS;
            run.advance_to(t, &mut |_, _| {});
            let task = run.world().task_state();
            if let Some(ts) = task.time_to_success_s {
                if task.success && run.world().time_s() - ts >= opts.settle_s {
                    break;
                }
            }
        }
        let task = run.world().task_state();
        let ep = EpisodeReport {
            seed,
            success: task.success,
            time_to_success_s: task.success.then_some(task.time_to_success_s).flatten(),
            duration_s: run.world().time_s(),
            cube_distance_m: task.cubes.iter().map(|c| c.distance_m).collect(),
            chunks: 0,
            commanded_ticks: 0,
            clamped_ticks: 0,
            halted_ticks: 0,
            wall_s: wall.elapsed().as_secs_f64(),
            recording: None,
            highest_stage: None,
        };
        on_episode(&ep);
        episodes.push(ep);
    }
    let mut report = summarize(
        "(scripted expert)",
        rig,
        "scripted-expert",
        opts,
        rig.control_rate_hz,
        episodes,
    );
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}
