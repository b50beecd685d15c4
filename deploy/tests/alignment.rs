//! The controller builds each tick's observation exactly as `scaledp convert` stored that tick:
//! a rollout recorded by `eval --recordings`, converted, and replayed message by message into a
//! fresh controller ticking on the converter's grid gives the same state rows and the same
//! image bytes.
#![allow(clippy::unwrap_used)]

mod common;

use candle_core::Device;
use scaledp_converter::{convert, read_mcap, ConvertOptions, InMemory};
use scaledp_deploy::{run_eval, ControlOptions, Controller, EvalOptions};
use scaledp_policy::{ActionChunk, Policy};
use scaledp_schema::msg::{Image, JointState};
use scaledp_schema::RosMessage;

#[test]
fn a_replayed_rollout_gives_the_observations_the_converter_stored() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let opts = EvalOptions {
        episodes: 1,
        max_seconds: 2.0,
        recordings: Some(dir.path().join("rollouts")),
        ..EvalOptions::default()
    };
    let report = run_eval(&policy, &rig, &opts, &mut |_| {}).unwrap();
    let path = std::path::PathBuf::from(report.episodes[0].recording.clone().unwrap());
    let rec = read_mcap(&path, &|_| true).unwrap();
    let ep = convert(
        &path,
        &rec,
        &InMemory(&rec),
        &ConvertOptions::default().size(24, 24),
    )
    .unwrap();
    assert!(ep.len() >= 15);

    // Replay: ticks on the converter's grid, each called once the clock is the controller's lag
    // past it with every message stamped until then in (receive = capture in simulated time);
    // a chunk after every tick, so that every tick asks for one and shows its window.
    let ctl_opts = ControlOptions {
        action_steps: 1,
        obs_lag_s: 0.0,
        ..ControlOptions::default()
    };
    let mut ctl = Controller::new(policy.config(), "tiny", &rig, ctl_opts).unwrap();
    let mut msgs: Vec<(u64, &scaledp_converter::RawMessage)> = rec
        .messages
        .iter()
        .filter_map(|m| {
            let stamp = if m.message_type.ends_with("Image") {
                Image::from_cdr(&m.data).ok()?.header.stamp.as_ns()
            } else if m.message_type.ends_with("JointState") {
                JointState::from_cdr(&m.data).ok()?.header.stamp.as_ns()
            } else {
                return None;
            };
            Some((stamp, m))
        })
        .collect();
    msgs.sort_by_key(|m| m.0);
    let first_frame = msgs
        .iter()
        .find(|m| m.1.message_type.ends_with("Image"))
        .unwrap()
        .0;
    // The converter's grid: a quarter frame period after the first frame (all streams start
    // together here), one control period apart.
    let origin = first_frame + (1e9 / 30.0 / 4.0_f64).round() as u64;
    let step = 100_000_000u64;
    let (w, h) = (24u32, 24u32);
    let per = 3 * (w * h) as usize;
    let mut next = 0;
    let mut windows = Vec::new();
    for k in 0..25u64 {
        let t = origin + k * step;
        while next < msgs.len() && msgs[next].0 <= t + ctl.obs_lag_ns() {
            let (stamp, m) = msgs[next];
            next += 1;
            if let Some(c) = rig.cameras.iter().position(|c| c.topic == m.topic) {
                ctl.on_image(c, stamp, stamp, &m.message_type, m.data.clone());
            } else if let Some(a) = rig.arms.iter().position(|a| a.joint_state_topic == m.topic) {
                ctl.on_joint_state(a, false, stamp, &JointState::from_cdr(&m.data).unwrap());
            } else if let Some(a) = rig
                .arms
                .iter()
                .position(|a| a.gripper.as_ref().is_some_and(|g| g.topic == m.topic))
            {
                ctl.on_joint_state(a, true, stamp, &JointState::from_cdr(&m.data).unwrap());
            }
        }
        let tick = ctl.tick(t + ctl.obs_lag_ns());
        if let Some(req) = tick.request {
            windows.push((k, req.observation.clone()));
            let chunk = ActionChunk {
                actions: vec![0.0; 8 * 7],
                chunk: 8,
                dim: 7,
            };
            ctl.install(req.index, &chunk);
        }
    }
    assert!(windows.len() >= 14, "{} windows", windows.len());
    let mut compared = 0;
    for (k, obs) in &windows {
        let row = *k as usize;
        if row >= ep.len() {
            continue;
        }
        // The window's newest step is tick k.
        let state = &obs.state[7..14];
        let stored = &ep.state[row * 7..(row + 1) * 7];
        assert!(
            state.iter().zip(stored).all(|(a, b)| (a - b).abs() <= 1e-5),
            "tick {k}: state {state:?} vs stored {stored:?}"
        );
        for (c, frames) in ep.cameras.iter().enumerate() {
            let mut want = vec![0u8; per];
            scaledp_datasets::decode_image(&frames.jpeg[row], w, h, &mut want).unwrap();
            let got = &obs.images[(2 + c) * per..(3 + c) * per];
            assert!(got == want.as_slice(), "tick {k}: camera {c} differs");
        }
        compared += 1;
    }
    assert!(compared >= 14, "{compared} ticks compared");
}
