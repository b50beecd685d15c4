//! `scaledp eval` in simulated time: a JSON report over two short episodes, deterministic.
#![allow(clippy::unwrap_used)]

use crate::common;

use candle_core::Device;
use scaledp_deploy::{run_eval, EvalOptions};
use scaledp_policy::Policy;

#[test]
fn eval_reports_two_short_episodes_the_same_way_twice() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let opts = EvalOptions {
        episodes: 2,
        seed: 1_000_000,
        max_seconds: 2.0,
        ..EvalOptions::default()
    };
    let mut seen = Vec::new();
    let report = run_eval(&policy, &rig, &opts, &mut |e| seen.push(e.seed)).unwrap();
    assert_eq!(seen, [1_000_000, 1_000_001]);
    let path = dir.path().join("eval.json");
    report.write(&path).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let eps = json["episodes"].as_array().unwrap();
    assert_eq!(eps.len(), 2);
    assert_eq!(json["rig"], "franka_sim");
    assert_eq!(json["mode"], "simulated-time");
    for (i, e) in eps.iter().enumerate() {
        assert_eq!(e["seed"], 1_000_000 + i as u64);
        // A policy that holds the rest pose never places the cube.
        assert_eq!(e["success"], false);
        assert!(e["time_to_success_s"].is_null());
        assert!(
            (e["duration_s"].as_f64().unwrap() - 2.0).abs() < 1e-6,
            "{e}"
        );
        // 20 ticks at 10 Hz: a command from the second tick on, a chunk every 8 ticks.
        let (ticks, chunks) = (
            e["commanded_ticks"].as_u64().unwrap(),
            e["chunks"].as_u64().unwrap(),
        );
        assert!((18..=20).contains(&ticks), "{e}");
        assert!((3..=4).contains(&chunks), "{e}");
        assert_eq!(e["halted_ticks"], 0);
        let d = e["cube_distance_m"].as_array().unwrap();
        assert_eq!(d.len(), 1);
        assert!(d[0].as_f64().unwrap() > 0.03, "{e}");
    }
    assert_eq!(json["successes"], 0);
    assert_eq!(json["success_rate"], 0.0);
    let w = json["wilson_95"].as_array().unwrap();
    assert_eq!(w[0].as_f64().unwrap(), 0.0);
    assert!((w[1].as_f64().unwrap() - 0.6576).abs() < 1e-3, "{w:?}");
    assert!(json["inference_ms_p50"].as_f64().unwrap() > 0.0);
    assert!(
        json["inference_ms_p99"].as_f64().unwrap() >= json["inference_ms_p50"].as_f64().unwrap()
    );
    // Simulated time: the same seeds give the same episodes.
    let again = run_eval(&policy, &rig, &opts, &mut |_| {}).unwrap();
    for (a, b) in report.episodes.iter().zip(&again.episodes) {
        assert_eq!(a.cube_distance_m, b.cube_distance_m);
        assert_eq!((a.chunks, a.commanded_ticks), (b.chunks, b.commanded_ticks));
    }
}

#[test]
fn a_recorded_rollout_converts_into_an_episode_whose_actions_are_the_commands() {
    use scaledp_converter::{convert, read_mcap, ConvertOptions, InMemory};
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let opts = EvalOptions {
        episodes: 1,
        seed: 1_000_000,
        max_seconds: 2.0,
        recordings: Some(dir.path().join("rollouts")),
        ..EvalOptions::default()
    };
    let report = run_eval(&policy, &rig, &opts, &mut |_| {}).unwrap();
    let path = std::path::PathBuf::from(report.episodes[0].recording.clone().unwrap());
    assert!(path.ends_with("rollouts/episode_000000.mcap"), "{path:?}");
    let rec = read_mcap(&path, &|_| true).unwrap();
    let ep = convert(
        &path,
        &rec,
        &InMemory(&rec),
        &ConvertOptions::default().size(24, 24),
    )
    .unwrap();
    // 2 s at 10 Hz, the first command at the second tick; the action is the command topic's
    // pose (the rest pose ± 1 cm) and the gripper command (clamped to the hand's 8 cm).
    assert!((14..=20).contains(&ep.len()), "{} frames", ep.len());
    let home = common::home_action(&rig);
    for row in ep.action.chunks(7) {
        for d in 0..3 {
            assert!(
                (f64::from(row[d]) - home[d]).abs() < 0.011,
                "{row:?} vs {home:?}"
            );
        }
        assert!((f64::from(row[6]) - 0.04).abs() < 0.011, "{row:?}");
    }
    let label = rec
        .metadata
        .get(scaledp_schema::episode::END_RECORD)
        .and_then(|m| m.get(scaledp_schema::episode::keys::OUTCOME))
        .cloned();
    assert_eq!(
        label.as_deref(),
        Some("failure"),
        "{:?}",
        rec.metadata.keys().collect::<Vec<_>>()
    );
}

#[test]
fn the_bimanual_cell_is_driven_through_the_14_d_action_path() {
    let rig = scaledp_schema::Rig::builtin("bimanual_ur5_sim")
        .unwrap()
        .with_image_size(64, 48);
    let dir = tempfile::tempdir().unwrap();
    let spec = common::Spec::at_home(&rig);
    assert_eq!(spec.dim, 14);
    let ckpt = common::write(dir.path(), &spec);
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let opts = EvalOptions {
        episodes: 1,
        max_seconds: 1.5,
        ..EvalOptions::default()
    };
    let report = run_eval(&policy, &rig, &opts, &mut |_| {}).unwrap();
    let e = &report.episodes[0];
    assert_eq!(e.cube_distance_m.len(), 2, "two cubes");
    assert!(e.commanded_ticks >= 12 && e.halted_ticks == 0, "{e:?}");
    assert_eq!(
        e.clamped_ticks, 0,
        "commands near both rest poses need no clamping: {e:?}"
    );
}

#[test]
fn a_live_episode_runs_the_sim_and_serve_over_loopback() {
    use zenoh::Wait;
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let cfg =
        scaledp_recorder::net::zenoh_config(None, &[], &[format!("tcp/127.0.0.1:{port}")]).unwrap();
    let session = zenoh::open(cfg).wait().unwrap();
    let opts = EvalOptions {
        episodes: 1,
        max_seconds: 2.5,
        ..EvalOptions::default()
    };
    let report =
        scaledp_deploy::run_live(&ckpt, &Device::Cpu, &rig, &opts, &session, &mut |_| {}).unwrap();
    assert_eq!(report.mode, "live");
    let e = &report.episodes[0];
    assert!(!e.success && e.time_to_success_s.is_none(), "{e:?}");
    assert!((2.5..4.0).contains(&e.duration_s), "{e:?}");
    // About 10 Hz for 2.5 s, less the first chunk's latency.
    assert!((15..=26).contains(&e.commanded_ticks), "{e:?}");
    assert!(e.chunks >= 3 && e.halted_ticks <= 2, "{e:?}");
    assert!(report.e2e_ms_p50.unwrap() >= report.inference_ms_p50.unwrap());
}

/// The ceiling control: the scripted teleoperator on the evaluation's seeds, scored by the same
/// scorer, succeeds and reports the same way twice.
#[test]
fn the_scripted_expert_scores_on_the_same_seeds() {
    let rig = common::light_rig();
    let opts = EvalOptions {
        episodes: 3,
        seed: scaledp_deploy::Split::Test.first_seed(),
        ..EvalOptions::default()
    };
    let a = scaledp_deploy::run_expert(&rig, &opts, &mut |_| {}).unwrap();
    let b = scaledp_deploy::run_expert(&rig, &opts, &mut |_| {}).unwrap();
    assert_eq!(a.mode, "scripted-expert");
    assert_eq!(
        a.episodes.iter().map(|e| e.seed).collect::<Vec<_>>(),
        [3_000_000, 3_000_001, 3_000_002]
    );
    assert_eq!(a.successes, 3, "{:?}", a.episodes);
    for (x, y) in a.episodes.iter().zip(&b.episodes) {
        assert_eq!(
            (x.success, x.time_to_success_s, x.duration_s),
            (y.success, y.time_to_success_s, y.duration_s)
        );
        // The episode ends once the task has been a success for settle_s.
        let t = x.time_to_success_s.unwrap();
        assert!((x.duration_s - t - opts.settle_s).abs() < 0.02, "{x:?}");
    }
    assert_eq!(
        scaledp_deploy::Split::of(3_000_000, 50),
        Some(scaledp_deploy::Split::Test)
    );
    assert_eq!(
        scaledp_deploy::Split::of(2_000_000, 50),
        Some(scaledp_deploy::Split::Dev)
    );
    // A range that runs from development into test seeds is neither.
    assert_eq!(scaledp_deploy::Split::of(2_999_990, 50), None);
    assert_eq!(
        scaledp_deploy::Split::of(1_000_000, 50),
        Some(scaledp_deploy::Split::Val)
    );
    assert_eq!(scaledp_deploy::Split::of(999_990, 50), None);
}
