//! `scaledp eval` in simulated time: a JSON report over two short episodes, deterministic.
#![allow(clippy::unwrap_used)]

mod common;

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
