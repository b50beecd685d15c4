//! `scaledp convert` interrupted and spread: a job killed mid-run leaves a valid dataset (as it
//! lies on disk, unrepaired) and its rerun finishes it; shards merged equal one run.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::convert_common::{convert_cli, KEEP_UNLABELED};
use scaledp_tests::{check_dataset, scaledp_bin, small_franka, synth_episode};
#[test]
fn a_killed_conversion_leaves_a_valid_dataset_and_the_rerun_finishes_it() {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("in");
    std::fs::create_dir_all(&inp).unwrap();
    let rig = small_franka();
    for i in 0..8 {
        synth_episode(&inp.join(format!("episode_{i:06}.mcap")), &rig, i, 4.0);
    }
    let ds = dir.path().join("ds");
    let mut child = Command::new(scaledp_bin())
        .args(["convert", "-q", "--jobs", "1", "--file-size-mb", "1"])
        .args(KEEP_UNLABELED)
        .arg(&inp)
        .arg("--out")
        .arg(&ds)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let record = ds.join("meta/scaledp.json");
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let done = std::fs::read(&record)
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok());
        if done.is_some_and(|v| v["episodes"].as_array().map_or(0, Vec::len) >= 2) {
            break;
        }
        assert!(Instant::now() < deadline, "no progress");
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    // Opening repairs whatever the kill interrupted; then the dataset is consistent.
    let rerun_dir = dir.path().join("empty");
    std::fs::create_dir_all(&rerun_dir).unwrap();
    let out = convert_cli(&[
        rerun_dir.as_os_str(),
        inp.as_os_str(),
        "--out".as_ref(),
        ds.as_os_str(),
        "--jobs".as_ref(),
        "1".as_ref(),
        "--file-size-mb".as_ref(),
        "1".as_ref(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    let v = check_dataset(&ds);
    assert_eq!(v["episodes"], 8, "{stdout}");
    assert!(
        !stdout.contains(" 0 skipped"),
        "the episodes committed before the kill are skipped: {stdout}"
    );
}

#[test]
fn a_killed_dataset_is_valid_before_any_repair() {
    // Kill after 1, 2 and 3 committed episodes, a little later each time (so the kill lands
    // while the next episode is being converted), and check the dataset as it lies on disk,
    // unrepaired, as LeRobot would read it. Only a kill inside a commit's burst of renames (a few
    // syscalls, which the settle time steps past) could leave rows no metadata lists; the next
    // scaledp run repairs that (previous test).
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("in");
    std::fs::create_dir_all(&inp).unwrap();
    let rig = small_franka();
    // Episodes long enough that converting one takes longer than the longest settle time, so
    // the kill lands while the next episode converts and not inside the commit after it (3 s
    // episodes converted in ~50 ms each, and a kill 140 ms late met a later commit's renames).
    for i in 0..5 {
        synth_episode(&inp.join(format!("episode_{i:06}.mcap")), &rig, i, 12.0);
    }
    for (target, settle_ms) in [(1usize, 20u64), (2, 60), (3, 140)] {
        let ds = dir.path().join(format!("ds{target}"));
        let mut child = Command::new(scaledp_bin())
            .args(["convert", "-q", "--jobs", "1"])
            .args(KEEP_UNLABELED)
            .arg(&inp)
            .arg("--out")
            .arg(&ds)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let record = ds.join("meta/scaledp.json");
        let deadline = Instant::now() + Duration::from_secs(60);
        let committed = || {
            std::fs::read(&record)
                .ok()
                .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
                .map_or(0, |v| v["episodes"].as_array().map_or(0, Vec::len))
        };
        while committed() < target {
            assert!(Instant::now() < deadline, "no episode {target} within 60 s");
            assert!(child.try_wait().unwrap().is_none(), "convert exited early");
            std::thread::sleep(Duration::from_millis(2));
        }
        std::thread::sleep(Duration::from_millis(settle_ms));
        child.kill().unwrap();
        child.wait().unwrap();
        let on_disk = committed();
        assert!(on_disk >= target);
        let v = check_dataset(&ds);
        assert_eq!(v["episodes"], on_disk, "killed after {target}");
    }
}

#[test]
fn shards_merged_equal_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("in");
    std::fs::create_dir_all(&inp).unwrap();
    let rig = small_franka();
    for i in 0..5 {
        synth_episode(
            &inp.join(format!("episode_{i:06}.mcap")),
            &rig,
            i,
            2.0 + i as f64 * 0.5,
        );
    }
    let run = |name: &str, extra: &[&str]| {
        let ds = dir.path().join(name);
        let mut args: Vec<&std::ffi::OsStr> =
            vec![inp.as_os_str(), "--out".as_ref(), ds.as_os_str()];
        args.extend(extra.iter().map(std::ffi::OsStr::new));
        let out = convert_cli(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
        ds
    };
    let one = run("one", &[]);
    let a = run("a", &["--shard", "0/2"]);
    let b = run("b", &["--shard", "1/2"]);
    let merged = dir.path().join("merged");
    let out = Command::new(scaledp_bin())
        .args(["dataset", "merge"])
        .arg(&a)
        .arg(&b)
        .arg("--out")
        .arg(&merged)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    check_dataset(&merged);
    for f in [
        "meta/info.json",
        "meta/stats.json",
        "meta/tasks.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "data/chunk-000/file-000.parquet",
    ] {
        assert_eq!(
            std::fs::read(one.join(f)).unwrap(),
            std::fs::read(merged.join(f)).unwrap(),
            "{f} differs"
        );
    }
}
