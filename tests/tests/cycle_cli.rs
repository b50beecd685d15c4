//! The whole cycle through the `scaledp` binary at toy scale: scripted demonstrations with a
//! collection manifest, `convert`, `train --preset … --dry-run`, `experiment compare` (two arms,
//! two steps each, every checkpoint in closed loop, the controls, the table and plot rebuilt,
//! the rerun resuming from the caches), and `eval` refusing the demonstrations' seeds.
#![allow(clippy::unwrap_used)]

use scaledp_tests::{cli_ok, run_scaledp, synth_episode};

#[test]
fn a_toy_experiment_runs_end_to_end_resumes_and_eval_refuses_training_seeds() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let mut rig = scaledp_schema::Rig::builtin("franka_sim").unwrap();
    for c in &mut rig.cameras {
        (c.width, c.height) = (48, 27);
    }
    let demos = root.join("demos");
    std::fs::create_dir_all(&demos).unwrap();
    let mut manifest = String::new();
    // A collection that (wrongly) used a test seed: eval must notice it through the dataset.
    for (i, seed) in [0u64, 1, 3_000_001].into_iter().enumerate() {
        synth_episode(&demos.join(format!("episode_{i:06}.mcap")), &rig, seed, 4.0);
        manifest.push_str(&format!("{{\"seed\": {seed}}}\n"));
    }
    std::fs::write(demos.join("collect.jsonl"), manifest).unwrap();
    cli_ok(
        &run_scaledp(
            &[
                "convert",
                "demos",
                "--out",
                "ds",
                "--size",
                "24x20",
                "--unlabeled",
                "keep",
                "-q",
            ],
            root,
        ),
        "convert",
    );
    let dry = cli_ok(
        &run_scaledp(&["train", "ds", "--preset", "cpu-sim", "--dry-run"], root),
        "train --dry-run",
    );
    assert!(
        dry.contains("ScaleDP-ti") && dry.contains("denoiser parameters"),
        "{dry}"
    );

    let compare = [
        "experiment",
        "compare",
        "--dataset",
        "ds",
        "--name",
        "toy",
        "--arms",
        "ti,ti-causal",
        "--steps",
        "2",
        "--checkpoint-every",
        "1",
        "--batch-size",
        "8",
        "--val-episodes",
        "1",
        "--test-episodes",
        "2",
        "--live-episodes",
        "0",
        // Long enough for the scripted expert to place the cube (its control must succeed).
        "--max-seconds",
        "12",
        "--runs",
        "runs",
        "--results",
        "results",
    ];
    cli_ok(&run_scaledp(&compare, root), "experiment compare");
    let res = root.join("results/toy");
    for f in [
        "ti.json",
        "ti-causal.json",
        "table.md",
        "success_vs_step.svg",
    ] {
        assert!(res.join(f).exists(), "{f} missing");
    }
    let ti: serde_json::Value =
        serde_json::from_slice(&std::fs::read(res.join("ti.json")).unwrap()).unwrap();
    let steps: Vec<u64> = ti["validation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["step"].as_u64().unwrap())
        .collect();
    assert_eq!(
        steps,
        [0, 1, 2],
        "every checkpoint, the untrained one included, on the validation seeds"
    );
    assert_eq!(ti["steps"], 2);
    assert_eq!(ti["test_seeds"], serde_json::json!([3_000_000, 3_000_001]));
    for k in [
        "test_success_rate",
        "wilson_low",
        "wilson_high",
        "train_hours",
    ] {
        assert!(ti[k].as_f64().is_some(), "{k}");
    }
    assert!(ti["command"]
        .as_str()
        .unwrap()
        .starts_with("scaledp experiment compare"));
    let c = &ti["controls"];
    assert_eq!(c["scripted_expert"]["mode"], "scripted-expert");
    assert_eq!(
        c["scripted_expert"]["successes"], 2,
        "the expert places the cube: {c}"
    );
    assert_eq!(c["untrained"]["successes"], 0, "{c}");
    assert!(c["frozen_cameras"]["episodes"].as_u64() == Some(2));
    let causal: serde_json::Value =
        serde_json::from_slice(&std::fs::read(res.join("ti-causal.json")).unwrap()).unwrap();
    assert!(
        causal["controls"]["untrained"].is_null(),
        "controls belong to the recipe's arm"
    );
    let cfg: serde_json::Value = serde_json::from_slice(
        &std::fs::read(root.join("runs/toy/ti-causal/checkpoints/step_00000002/config.json"))
            .unwrap(),
    )
    .unwrap();
    assert_eq!(cfg["model"]["attention"], "causal");
    let table = std::fs::read_to_string(res.join("table.md")).unwrap();
    assert!(
        table.contains("causal attention") && table.contains("scripted expert"),
        "{table}"
    );

    // A second run finds everything done: nothing trains or evaluates again.
    let before = std::fs::read(res.join("ti.json")).unwrap();
    let t0 = std::time::Instant::now();
    cli_ok(&run_scaledp(&compare, root), "experiment compare, again");
    let after: serde_json::Value =
        serde_json::from_slice(&std::fs::read(res.join("ti.json")).unwrap()).unwrap();
    let before: serde_json::Value = serde_json::from_slice(&before).unwrap();
    assert_eq!(before["validation"], after["validation"]);
    assert_eq!(before["test"], after["test"]);
    assert!(t0.elapsed().as_secs_f64() < 60.0);

    // eval: the test split holds seed 3 000 001, which the demonstrations used.
    let refused = run_scaledp(
        &["eval", "runs/toy/ti", "--split", "test", "--episodes", "3"],
        root,
    );
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("seed 3000001") && err.contains("collect.jsonl"),
        "{err}"
    );
    let val = [
        "eval",
        "runs/toy/ti",
        "--split",
        "val",
        "--episodes",
        "1",
        // Long enough for the scripted expert to place the cube (its control must succeed).
        "--max-seconds",
        "12",
    ];
    cli_ok(&run_scaledp(&val, root), "eval --split val");
}
