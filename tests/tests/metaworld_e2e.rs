//! MetaWorld through the whole stack at toy scale, through the `scaledp` binary: `experiment
//! compare --benchmark metaworld` collects two demonstrations of a task with MetaWorld's
//! scripted expert through the recorder, converts them, trains ScaleDP-Ti and DP-T one step
//! each, scores both on test seeds in simulated time (the simulator stepped once per control
//! tick), runs the controls and rebuilds the table and the plot; a second run resumes from what
//! is there, and a third (`--rescore`) scores every file again, keeping the earlier figures. Needs `.venv-sims` (`scripts/setup-sims.sh`, which `scripts/test.sh` runs).
#![allow(clippy::unwrap_used)]

use scaledp_tests::{cli_ok, live_episode, read_json, run_scaledp};

#[test]
fn a_metaworld_task_collects_converts_trains_and_scores_both_arms() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let args = [
        "experiment",
        "compare",
        "--benchmark",
        "metaworld",
        "--tasks",
        "reach",
        "--arms",
        "ti,dp-t",
        "--demos",
        "2",
        "--steps",
        "1",
        "--checkpoint-every",
        "1",
        "--batch-size",
        "8",
        "--test-episodes",
        "2",
        "--controls-episodes",
        "1",
        "--max-seconds",
        "0.3",
        "--runs",
        "runs",
        "--results",
        "results",
    ];
    let first = cli_ok(
        &run_scaledp(&args, root),
        "experiment compare --benchmark metaworld",
    );
    let res = root.join("results/metaworld");
    for arm in ["ti", "dp-t"] {
        let r = read_json(&res.join(format!("reach--{arm}.json")));
        assert_eq!(r["task"], "reach", "{r}");
        assert_eq!(r["level"], "easy", "{r}");
        assert_eq!(r["steps"], 1, "{r}");
        assert_eq!(r["demonstrations"], 2, "{r}");
        assert_eq!(
            r["test_seeds"],
            serde_json::json!([3_000_000, 3_000_001]),
            "{r}"
        );
        assert_eq!(r["test"]["episodes"], 2, "{r}");
        assert_eq!(r["test"]["stages"].as_array().map(Vec::len), Some(3), "{r}");
        // The audit: who trained and scored it, on what, from which demonstrations, and
        // every episode's outcome.
        let audit = &r["audit"];
        assert!(audit["simulator"]["mujoco"].is_string(), "{r}");
        assert!(audit["trained_by"]["revision"].is_string(), "{r}");
        assert_eq!(
            audit["scored_by"]["sha256"].as_str().map(str::len),
            Some(64),
            "{r}"
        );
        assert!(
            audit["scored_by"]["command"]
                .as_str()
                .unwrap()
                .starts_with("scaledp experiment compare --benchmark metaworld"),
            "{r}"
        );
        assert!(
            audit["collection"]["seeds"].as_array().map_or(0, Vec::len) >= 2,
            "{r}"
        );
        assert_eq!(audit["train_seed"], 0, "{r}");
        let outcomes = r["test"]["outcomes"].as_array().unwrap();
        assert_eq!(outcomes.len(), 2, "{r}");
        assert_eq!(outcomes[1]["seed"], 3_000_001, "{r}");
        assert!(outcomes[0]["highest_stage"].is_string(), "{r}");
        let lo = r["wilson_low"].as_f64().unwrap();
        let hi = r["wilson_high"].as_f64().unwrap();
        assert!(
            lo <= r["test_success_rate"].as_f64().unwrap() && hi <= 1.0,
            "{r}"
        );
    }
    let c = read_json(&res.join("reach--controls.json"));
    let expert = &c["controls"]["scripted_expert"];
    assert_eq!(expert["episodes"], 2, "{c}");
    // Every episode counts MetaWorld's stages (its own flags), the expert's and each arm's.
    assert_eq!(expert["stages"].as_array().map(Vec::len), Some(3), "{c}");
    assert_eq!(
        expert["stages"][2]["stage"], "success",
        "the last stage is the success: {c}"
    );
    assert!(c["controls"]["untrained"]["episodes"] == 1, "{c}");
    assert!(c["controls"]["frozen_cameras"]["episodes"] == 1, "{c}");
    let table = std::fs::read_to_string(res.join("table.md")).unwrap();
    assert!(
        table.contains("| easy | reach |") && table.contains("dp-t"),
        "{table}"
    );
    assert!(res.join("success_by_level.svg").exists());
    // The demonstrations went through the recorder, labelled by MetaWorld's success.
    let manifest =
        std::fs::read_to_string(root.join("runs/metaworld/reach/demos/collect.jsonl")).unwrap();
    assert!(
        manifest
            .lines()
            .filter(|l| l.contains("\"success\""))
            .count()
            >= 2
    );
    // The same checkpoint live: the simulator on its own /clock, serve following it.
    let r = live_episode(root, "runs/metaworld/reach/ti", "0.5", &[]);
    let ep = &r["episodes"][0];
    assert!(ep["duration_s"].as_f64().unwrap() >= 0.5, "{r}");
    assert!(ep["commanded_ticks"].as_u64().unwrap() >= 5, "{r}");
    assert!(r["real_time_factor"].as_f64().unwrap() > 0.05, "{r}");
    simulator_dying_live_is_an_error(root);
    // A second run finds every result there and redoes nothing.
    let again = cli_ok(&run_scaledp(&args, root), "compare again");
    assert!(
        !again.contains("test "),
        "nothing re-scored: {again}\n(first: {first})"
    );
    // `--rescore` scores every finished file again (after a bridge change), keeping the old.
    let rescore = [&args[..], &["--rescore"]].concat();
    let out = cli_ok(&run_scaledp(&rescore, root), "compare --rescore");
    assert_eq!(out.matches("(was ").count(), 2 + 3, "{out}");
    for arm in ["ti", "dp-t"] {
        let r = read_json(&res.join(format!("reach--{arm}.json")));
        assert_eq!(r["earlier_scores"].as_array().map(Vec::len), Some(1), "{r}");
        let before = &r["earlier_scores"][0];
        assert_eq!(before["figures"]["episodes"], 2, "{r}");
        assert!(before["audit"]["simulator"]["mujoco"].is_string(), "{r}");
        assert!(
            r["test"]["bridge"].is_string(),
            "the bridge's behaviour: {r}"
        );
        assert!(
            r["rescore_command"]
                .as_str()
                .unwrap()
                .ends_with("--rescore"),
            "{r}"
        );
    }
    let c = read_json(&res.join("reach--controls.json"));
    assert_eq!(c["earlier_scores"].as_array().map(Vec::len), Some(1), "{c}");
    assert_eq!(c["controls"]["untrained"]["episodes"], 1, "{c}");
    assert_eq!(c["controls"]["scripted_expert"]["episodes"], 2, "{c}");
    let table = std::fs::read_to_string(res.join("table.md")).unwrap();
    assert!(
        !table.contains('†'),
        "one bridge behaviour throughout: {table}"
    );
}

/// A simulator process that dies during a live evaluation ends `eval --live` with the bridge's
/// error, soon, where it used to wait for ever. It is killed 8 s after it starts: MetaWorld's
/// import takes ~2.6 s, and three episodes of 6.25 simulated seconds (500 steps), never ahead of
/// real time, take the rest, so the kill lands in a reset or a step of the loop, never after
/// the last episode.
fn simulator_dying_live_is_an_error(root: &std::path::Path) {
    use std::os::unix::fs::PermissionsExt;
    let python = scaledp_sim::bridge::python().unwrap();
    let dying = root.join("dying-python");
    std::fs::write(
        &dying,
        format!(
            "#!/bin/sh\n( sleep 8; kill -9 $$ ) &\nexec '{}' \"$@\"\n",
            python.display()
        ),
    )
    .unwrap();
    std::fs::set_permissions(&dying, std::fs::Permissions::from_mode(0o755)).unwrap();
    let child = std::process::Command::new(scaledp_tests::scaledp_bin())
        .args([
            "eval",
            "runs/metaworld/reach/ti",
            "--live",
            "--episodes",
            "3",
            "--split",
            "val",
            "--report",
            "dying.json",
        ])
        .env(scaledp_sim::bridge::PYTHON_ENV, &dying)
        .current_dir(root)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let out =
        scaledp_tests::child::Reap::new(child).output_within(std::time::Duration::from_secs(50));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    // The loop's error (a step's or a reset's), not one from starting the simulator.
    assert!(
        stderr.contains("metaworld/reach: ") && stderr.contains("the bridge exited"),
        "{stderr}"
    );
    assert!(!stderr.contains("metaworld/reach: starting"), "{stderr}");
    assert!(!root.join("dying.json").exists(), "{stderr}");
}
