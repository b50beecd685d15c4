//! Recordings written straight to disk, faster than real time: the scripted operator's episode
//! on the simulated world, rendered at the rig's rates with the same stamps, jitter and latency
//! model as the live simulator, through the recorder's own episode writer. Benchmarks and tests
//! use it for a fixed set of inputs.
//!
//! Byte-reproducible: everything follows from the seed and `start_ns`. The world advances event
//! by event in simulated time (leader samples, their delivery, captures); each message is built
//! from the world at its capture stamp and written in receive-time (`log_time`) order.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::path::Path;
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scaledp_recorder::EpisodeOptions;
use scaledp_schema::rig::Rig;
use scaledp_schema::{EpisodeMetadata, Label, RosMessage};

use crate::headless::{EpisodeResult, OfflineRun};
use crate::messages;
use crate::render::{self, View};
use crate::scene::Scene;
use crate::world::ArmCommand;
use crate::{Error, Result};

/// Changes one message before it is written: (topic, index within the topic, stamp in ns,
/// payload). Tests use it to plant faults.
pub type Mutate<'a> = dyn FnMut(&str, u64, &mut u64, &mut Vec<u8>) + 'a;

/// What a topic index stands for.
#[derive(Debug, Clone, Copy)]
enum Source {
    Camera(usize),
    Joints(usize),
    Gripper(usize),
    ArmCommand(usize),
    GripperCommand(usize),
}

fn sources(rig: &Rig) -> Result<Vec<Source>> {
    rig.training_topics()
        .iter()
        .map(|t| {
            if let Some(i) = rig.cameras.iter().position(|c| c.topic == t.topic) {
                return Ok(Source::Camera(i));
            }
            for (i, a) in rig.arms.iter().enumerate() {
                let g = a.gripper.as_ref();
                if a.joint_state_topic == t.topic {
                    return Ok(Source::Joints(i));
                }
                if g.is_some_and(|g| g.topic == t.topic) {
                    return Ok(Source::Gripper(i));
                }
                if a.command_topic.as_ref() == Some(&t.topic) {
                    return Ok(Source::ArmCommand(i));
                }
                if g.and_then(|g| g.command_topic.as_ref()) == Some(&t.topic) {
                    return Ok(Source::GripperCommand(i));
                }
            }
            Err(Error::UnknownTopic {
                rig: rig.name.clone(),
                topic: t.topic.clone(),
            })
        })
        .collect()
}

/// A message waiting for its receive time: (log time, topic, index, stamp, payload).
type Pending = Reverse<(u64, usize, u64, u64, Vec<u8>)>;

/// Writes one episode of `seconds` of `rig` under `seed` to `path` (an `episode_*.mcap` like
/// the recorder's, with `scaledp.episode` metadata naming `task`), starting at `start_ns`.
/// The rig's command topics, if any, carry the operator's leader samples; what a rig records
/// beside its training streams (depth, `camera_info`, `/tf`) is left out. The episode is
/// labelled by the task's scorer when the operator finished within `seconds` (success or
/// failure), else left unlabeled. Returns how the task went.
pub fn write_episode(
    path: &Path,
    rig: &Rig,
    seed: u64,
    seconds: f64,
    start_ns: u64,
    task: &str,
    mutate: &mut Mutate<'_>,
) -> Result<EpisodeResult> {
    let scene = Arc::new(Scene::new(rig));
    let mut run = OfflineRun::new(scene.clone(), seed);
    // The training streams only: depth, camera_info and tf come from the live simulator.
    let topics = rig.training_topics();
    let sources = sources(rig)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Captures (stamp, topic, k, latency) of every non-command topic, in stamp order.
    let mut plan: Vec<(u64, usize, u64, u64)> = Vec::new();
    for (ti, t) in topics.iter().enumerate() {
        if matches!(
            sources[ti],
            Source::ArmCommand(_) | Source::GripperCommand(_)
        ) {
            continue;
        }
        let period = 1e9 / t.rate_hz;
        for k in 0..(seconds * t.rate_hz) as u64 {
            let jitter = rng.random_range(-0.5e6..0.5e6) * if t.is_image { 1.0 } else { 0.04 };
            let stamp = start_ns + (k as f64 * period + jitter).max(0.0) as u64;
            let latency = if t.is_image {
                rng.random_range(25e6..35e6)
            } else {
                rng.random_range(3e5..7e5)
            } as u64;
            plan.push((stamp, ti, k, latency));
        }
    }
    plan.sort_unstable();
    let views: Vec<Option<View>> = sources
        .iter()
        .map(|s| match s {
            Source::Camera(i) => Some(View::for_camera(&scene, &rig.cameras[*i], *i)),
            _ => None,
        })
        .collect();
    let command_topics: Vec<(Option<usize>, Option<usize>)> = (0..rig.arms.len())
        .map(|a| {
            let find = |want: fn(&Source, usize) -> bool| sources.iter().position(|s| want(s, a));
            (
                find(|s, a| matches!(s, Source::ArmCommand(i) if *i == a)),
                find(|s, a| matches!(s, Source::GripperCommand(i) if *i == a)),
            )
        })
        .collect();

    let meta = EpisodeMetadata {
        task: task.to_string(),
        rig_name: rig.name.clone(),
        rig_toml: Some(toml::to_string(rig).map_err(|source| Error::Rig {
            rig: rig.name.clone(),
            source,
        })?),
        operator: "scripted-expert".into(),
        start_time_ns: Some(start_ns),
        synthetic: Some(format!("seed {seed}")),
        ..EpisodeMetadata::default()
    };
    let mut w = EpisodeOptions::new().create(path, &topics, meta.start_record())?;
    let mut heap: BinaryHeap<Pending> = BinaryHeap::new();
    let mut counts = vec![0u64; topics.len()];
    let mut cmd_rng = ChaCha8Rng::seed_from_u64(seed ^ 0xC0_3A4D);
    let mut buf = Vec::new();
    let mut encoders = crate::video::encoders(&rig.cameras)?;
    let mut write_due = |heap: &mut BinaryHeap<Pending>, upto: u64| -> Result<()> {
        while heap.peek().is_some_and(|Reverse(p)| p.0 <= upto) {
            let Some(Reverse((log, ti, k, mut stamp, mut payload))) = heap.pop() else {
                break;
            };
            mutate(&topics[ti].topic, k, &mut stamp, &mut payload);
            w.write(ti, log, stamp, &payload)?;
        }
        Ok(())
    };
    let mut on_sample = |heap: &mut BinaryHeap<Pending>, stamp_rel: u64, cmds: &[ArmCommand]| {
        let stamp = start_ns + stamp_rel;
        for (a, cmd) in cmds.iter().enumerate() {
            let arm = &rig.arms[a];
            let (arm_topic, grip_topic) = command_topics[a];
            let mut push = |ti: usize, payload: Vec<u8>, rng: &mut ChaCha8Rng| {
                let log = stamp + rng.random_range(300_000..700_000);
                heap.push(Reverse((log, ti, counts[ti], stamp, payload)));
                counts[ti] += 1;
            };
            if let (Some(ti), Some(p)) = (arm_topic, cmd.pose) {
                push(
                    ti,
                    messages::pose_command(arm, &p, stamp).to_cdr(),
                    &mut cmd_rng,
                );
            }
            if let (Some(ti), Some(g), Some(width)) =
                (grip_topic, &arm.gripper, cmd.gripper_width_m)
            {
                push(
                    ti,
                    messages::gripper_command(g, width, stamp).to_cdr(),
                    &mut cmd_rng,
                );
            }
        }
    };
    let end_rel = (seconds * 1e9) as u64;
    for (stamp, ti, k, latency) in plan {
        let rel = stamp - start_ns;
        let mut samples: Vec<(u64, Vec<ArmCommand>)> = Vec::new();
        run.advance_to(rel, &mut |t, c| samples.push((t, c.to_vec())));
        for (t, c) in samples.iter().filter(|(t, _)| *t < end_rel) {
            on_sample(&mut heap, *t, c);
        }
        let state = run.world().state();
        let payload = match sources[ti] {
            Source::Camera(i) => {
                let cam = &rig.cameras[i];
                if let Some(view) = &views[ti] {
                    let raw = crate::video::raw_encoding(cam);
                    render::render(&scene, view, &state, raw, &mut buf);
                }
                if let Some(enc) = &mut encoders[i] {
                    crate::video::video_message(cam, enc, &buf, stamp)
                } else {
                    let img = messages::image(cam, std::mem::take(&mut buf), stamp);
                    let out = img.to_cdr();
                    buf = img.data;
                    out
                }
            }
            Source::Joints(a) => {
                messages::joint_state(&rig.arms[a], &state.arms[a], stamp).to_cdr()
            }
            Source::Gripper(a) => match &rig.arms[a].gripper {
                Some(g) => {
                    messages::gripper_state(g, state.arms[a].gripper_width_m, stamp).to_cdr()
                }
                None => continue,
            },
            Source::ArmCommand(_) | Source::GripperCommand(_) => continue,
        };
        heap.push(Reverse((stamp + latency, ti, k, stamp, payload)));
        write_due(&mut heap, rel + start_ns)?;
    }
    let mut samples: Vec<(u64, Vec<ArmCommand>)> = Vec::new();
    run.advance_to(end_rel, &mut |t, c| samples.push((t, c.to_vec())));
    for (t, c) in samples.iter().filter(|(t, _)| *t < end_rel) {
        on_sample(&mut heap, *t, c);
    }
    write_due(&mut heap, u64::MAX)?;

    let result = EpisodeResult {
        task: run.world().task_state(),
        operator_done: run.operator_done(),
        duration_s: seconds,
    };
    let label = match (result.operator_done, result.task.success) {
        (true, true) => Label::Success,
        (true, false) => Label::Failure,
        (false, _) => Label::Unlabeled,
    };
    let meta = EpisodeMetadata {
        end_time_ns: Some(start_ns + end_rel),
        duration_s: Some(seconds),
        label: Some(label),
        message_counts: topics
            .iter()
            .zip(w.message_counts())
            .map(|(t, n)| (t.topic.clone(), *n))
            .collect(),
        ..meta
    };
    w.finish(meta.end_record(), None)?;
    Ok(result)
}

#[cfg(test)]
mod tests;
