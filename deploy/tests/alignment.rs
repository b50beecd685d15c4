//! The controller builds each tick's observation exactly as `scaledp convert` stored that tick:
//! a rollout recorded by `eval --recordings`, converted, and replayed message by message into a
//! fresh controller ticking on the converter's grid gives the same state rows and the same
//! image bytes.
#![allow(clippy::unwrap_used)]

use crate::common;

use candle_core::Device;
use scaledp_converter::{convert, read_mcap, ConvertOptions, InMemory};
use scaledp_deploy::{run_eval, ControlOptions, Controller, EvalOptions};
use scaledp_policy::Policy;

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

    let ctl_opts = ControlOptions {
        action_steps: 1,
        obs_lag_s: 0.0,
        ..ControlOptions::default()
    };
    let mut ctl = Controller::new(policy.config(), "tiny", &rig, ctl_opts).unwrap();
    let windows = common::replay(&mut ctl, &rig, &rec, 25);
    let (w, h) = (24u32, 24u32);
    let per = 3 * (w * h) as usize;
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

/// The frozen-cameras control: over a demonstration whose arm moves, every window shows the
/// episode's first frames while the state follows the arm; without it the images change.
#[test]
fn frozen_cameras_show_the_first_frames_while_the_state_moves() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.mcap");
    scaledp_sim::write_episode(
        &path,
        &rig,
        3,
        4.0,
        1_700_000_000_000_000_000,
        "cube",
        &mut |_, _, _, _| {},
    )
    .unwrap();
    let rec = read_mcap(&path, &|_| true).unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    for freeze in [false, true] {
        let opts = ControlOptions {
            action_steps: 1,
            obs_lag_s: 0.0,
            freeze_cameras: freeze,
            ..ControlOptions::default()
        };
        let mut ctl = Controller::new(policy.config(), "tiny", &rig, opts).unwrap();
        let windows = common::replay(&mut ctl, &rig, &rec, 35);
        assert!(windows.len() >= 30, "{} windows", windows.len());
        let first = &windows[0].1;
        let same_images = windows
            .iter()
            .filter(|(_, w)| w.images == first.images)
            .count();
        let moved = windows.iter().any(|(_, w)| {
            w.state
                .iter()
                .zip(&first.state)
                .any(|(a, b)| (a - b).abs() > 1e-3)
        });
        assert!(moved, "the arm moves in the demonstration");
        if freeze {
            assert_eq!(
                same_images,
                windows.len(),
                "frozen: every window shows the first frames"
            );
        } else {
            assert!(
                same_images < windows.len() / 2,
                "live cameras: {same_images} of {} windows unchanged",
                windows.len()
            );
        }
    }
}
