//! The cluster scripts (`cluster/`): the Slurm array script and the Kubernetes Indexed
//! Job manifest pass their checkers (ShellCheck and `bash -n`; a YAML parse and Kubernetes
//! 1.31's schemas in strict mode), and run as local processes — one per array task or Job
//! index, with the variables Slurm and Kubernetes set — against a real S3 endpoint, their
//! merged datasets equal one `scaledp convert` run byte for byte (with empty shards when there
//! are more shards than inputs). The Kubernetes init container that waits for the shard Job
//! needs a cluster and is only checked, not run.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::path::{Path, PathBuf};
use std::process::{Child, Command};

use crate::convert_common::KEEP_UNLABELED;
use scaledp_tests::s3::{url, S3Env};
use scaledp_tests::{run_python, scaledp_bin, small_franka, synth_episode, workspace};

/// Waits for every child; panics naming the first that failed.
fn all_succeed(children: Vec<(String, Child)>) {
    for (name, child) in children {
        let out = child.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "{name}: {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// `PATH` with `dir` first.
fn path_with(dir: &Path) -> std::ffi::OsString {
    let mut dirs = vec![dir.to_path_buf()];
    dirs.extend(std::env::split_paths(
        &std::env::var_os("PATH").unwrap_or_default(),
    ));
    std::env::join_paths(dirs).unwrap()
}

#[test]
fn slurm_and_kubernetes_shards_merge_into_one_run() {
    let root = workspace();
    let manifest = root.join("cluster/kubernetes/convert-job.yaml");
    let sbatch = root.join("cluster/slurm/convert.sbatch");
    let checked = run_python("check_cluster.py", &[&manifest, &sbatch]);
    // The checkers do fail on a broken file.
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(&manifest).unwrap();
    let broken = dir.path().join("broken.yaml");
    std::fs::write(&broken, text.replace("completionMode", "completionmode")).unwrap();
    let check = |m: &Path, s: &Path| {
        Command::new(scaledp_tests::python())
            .arg(root.join("tests/py/check_cluster.py"))
            .args([m, s])
            .output()
            .unwrap()
    };
    assert!(
        !check(&broken, &sbatch).status.success(),
        "a misspelt field passed"
    );
    let broken_sh = dir.path().join("broken.sbatch");
    let script = std::fs::read_to_string(&sbatch).unwrap();
    std::fs::write(
        &broken_sh,
        script.replace("\"$(shard_dir \"$i\")\"", "$(shard_dir $i)"),
    )
    .unwrap();
    assert!(
        !check(&manifest, &broken_sh).status.success(),
        "unquoted words passed"
    );

    let s3 = S3Env::start();
    let rec = dir.path().join("rec");
    std::fs::create_dir(&rec).unwrap();
    for seed in 1..=5 {
        synth_episode(
            &rec.join(format!("episode_{seed:06}.mcap")),
            &small_franka(),
            seed,
            2.0,
        );
    }
    s3.upload_dir(&rec, &url("data", "cluster/rec"));
    let input = "s3://data/cluster/rec/";
    let one = url("data", "cluster/one");
    let out = s3
        .scaledp(&s3.endpoint)
        .args(["convert", input, "--out", &one.to_string()])
        .args(KEEP_UNLABELED)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reference = s3.objects(&one);
    assert_eq!(
        reference.keys().filter(|k| k.starts_with("data/")).count(),
        1
    );

    // Slurm: three array tasks; the first submits the merge job (to a stand-in sbatch that
    // records its arguments), which then runs as the dependency would run it.
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let submitted = dir.path().join("sbatch.log");
    std::fs::write(
        bin.join("sbatch"),
        format!("#!/bin/sh\necho \"$@\" >> '{}'\n", submitted.display()),
    )
    .unwrap();
    std::process::Command::new("chmod")
        .args(["+x"])
        .arg(bin.join("sbatch"))
        .status()
        .unwrap();
    let slurm = |extra: &[(&str, &str)]| {
        let mut c = s3.command(Path::new("bash"), &s3.endpoint);
        c.arg(&sbatch)
            .env("PATH", path_with(&bin))
            .env("SCALEDP", scaledp_bin())
            .env("INPUT", input)
            .env("OUT", "s3://data/cluster/slurm")
            .env("SLURM_ARRAY_JOB_ID", "4242")
            .env("SLURM_ARRAY_TASK_COUNT", "3")
            .env("SLURM_ARRAY_TASK_MIN", "0")
            .env("SLURM_CPUS_PER_TASK", "1")
            .env("CONVERT_ARGS", KEEP_UNLABELED.join(" "))
            .envs(extra.iter().copied());
        c
    };
    let tasks = (0..3)
        .map(|i| {
            let id = i.to_string();
            let child = slurm(&[("SLURM_ARRAY_TASK_ID", &id)]).spawn().unwrap();
            (format!("array task {i}"), child)
        })
        .collect();
    all_succeed(tasks);
    let submissions = std::fs::read_to_string(&submitted).unwrap();
    let lines: Vec<&str> = submissions.lines().collect();
    assert_eq!(lines.len(), 1, "{submissions}");
    assert!(
        lines[0].contains("--dependency=afterok:4242")
            && lines[0].contains("--export=ALL,MODE=merge,SHARDS=3"),
        "{submissions}"
    );
    let merge = slurm(&[("MODE", "merge"), ("SHARDS", "3")])
        .spawn()
        .unwrap();
    all_succeed(vec![("merge job".into(), merge)]);
    assert_eq!(s3.objects(&url("data", "cluster/slurm")), reference);

    // Kubernetes: the Job's `completions` pods with JOB_COMPLETION_INDEX (8 shards for 5
    // inputs: three are empty), then the merge Job's container.
    let scratch = dir.path().join("scratch");
    std::fs::create_dir(&scratch).unwrap();
    let scripts_bin = PathBuf::from(scaledp_bin().parent().unwrap());
    let n = checked["completions"].as_u64().unwrap();
    let pod = |script: &str, index: Option<u64>| {
        let mut c = s3.command(Path::new("sh"), &s3.endpoint);
        for (k, v) in checked["env"].as_object().unwrap() {
            c.env(k, v.as_str().unwrap());
        }
        c.env("CONVERT_ARGS", KEEP_UNLABELED.join(" "));
        let script = script.replace("/scratch", scratch.to_str().unwrap());
        c.arg("-c")
            .arg(script)
            .env("PATH", path_with(&scripts_bin))
            .env("INPUT", input)
            .env("OUT", "s3://data/cluster/k8s")
            .env("SHARDS_OUT", "s3://data/cluster/k8s.shards");
        if let Some(i) = index {
            c.env("JOB_COMPLETION_INDEX", i.to_string());
        }
        c.spawn().unwrap()
    };
    let shard = checked["shard"].as_str().unwrap();
    all_succeed(
        (0..n)
            .map(|i| (format!("pod {i}"), pod(shard, Some(i))))
            .collect(),
    );
    let merge = pod(checked["merge"].as_str().unwrap(), None);
    all_succeed(vec![("merge pod".into(), merge)]);
    assert_eq!(s3.objects(&url("data", "cluster/k8s")), reference);
}
