//! The launch recipes, checked without a cluster: the Slurm script parses (`bash -n`), its
//! `#SBATCH` lines are well-formed, and run through stand-ins for `srun` and `scontrol` (one
//! node, 2 CPU ranks, c10d rendezvous on 127.0.0.1) it trains, then resumes as a requeued job
//! would; the Kubernetes PyTorchJob parses as YAML with the operator's required shape and a
//! command line the trainer accepts (`tests/py/check_k8s_recipe.py`; no kubectl or cluster).

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use scaledp_tests::workspace;
use serde_json::Value;

use super::{checkpoint, fixture, py, python, run_ok, script, TINY};

const LIMIT: Duration = Duration::from_secs(300);

/// Writes an executable shell script.
fn stand_in(dir: &Path, name: &str, body: &str) {
    use std::os::unix::fs::PermissionsExt;
    let p = dir.join(name);
    std::fs::write(&p, format!("#!/usr/bin/env bash\n{body}\n")).unwrap();
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
}

#[test]
fn the_slurm_script_parses_and_trains_and_resumes_through_stand_ins_for_srun() {
    let sbatch = workspace().join("cluster/slurm/train.sbatch");
    let st = Command::new("bash")
        .arg("-n")
        .arg(&sbatch)
        .status()
        .unwrap();
    assert!(st.success(), "bash -n {}", sbatch.display());
    let text = std::fs::read_to_string(&sbatch).unwrap();
    let directives: Vec<&str> = text.lines().filter(|l| l.starts_with("#SBATCH")).collect();
    assert!(directives.len() >= 5, "{directives:?}");
    for d in &directives {
        // `--name` or `--name=value`, lowercase names.
        let opt = d.trim_start_matches("#SBATCH").trim();
        let (name, value) = opt.split_once('=').unwrap_or((opt, "x"));
        let ok = name.len() > 2
            && name.starts_with("--")
            && name[2..]
                .chars()
                .all(|c| c.is_ascii_lowercase() || c == '-')
            && !value.is_empty()
            && !value.contains(' ');
        assert!(ok, "malformed directive {d:?}");
    }
    // One node standing in for the cluster: srun runs its command here, scontrol names the node.
    let f = fixture();
    let bin = f.dir.join("slurm-bin");
    std::fs::create_dir_all(&bin).unwrap();
    stand_in(
        &bin,
        "srun",
        "while [[ $1 == --* ]]; do shift; done\nexec \"$@\"",
    );
    stand_in(
        &bin,
        "scontrol",
        "[[ \"$1 $2\" == \"show hostnames\" ]] && echo 127.0.0.1",
    );
    let run = f.dir.join("slurm-run");
    let port = scaledp_testkit::free_port().unwrap().to_string();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let job = |extra: &[&str]| {
        let mut cmd = Command::new("bash");
        cmd.arg(&sbatch)
            .stdin(std::process::Stdio::null())
            .args(extra)
            .env("PATH", &path)
            .env("PYTHON", python())
            .env("PYTHONPATH", &f.site)
            .env("GLOO_SOCKET_IFNAME", "lo")
            .env("OMP_NUM_THREADS", "1")
            .env("DATASET", &f.dataset)
            .env("RUN", &run)
            .env("SLURM_JOB_NODELIST", "node1")
            .env("SLURM_NNODES", "1")
            .env("SLURM_JOB_ID", "4242")
            .env("GPUS_PER_NODE", "2")
            .env("MASTER_PORT", &port);
        run_ok(cmd, LIMIT)
    };
    let mut args = vec!["--steps", "2"];
    args.extend_from_slice(TINY);
    let first = job(&args);
    assert!(checkpoint(&run, 2).join("config.json").exists());
    // Requeued: the same job again finds the checkpoint and resumes (already complete: it only
    // writes the final checkpoint again).
    let again = job(&args);
    let (a, b) = (
        String::from_utf8_lossy(&first.stdout),
        String::from_utf8_lossy(&again.stdout),
    );
    eprintln!("sbatch recipe (stand-in srun): {}", a.trim());
    assert!(
        a.contains("1 node(s) x 2 worker(s)") && a.contains("2 steps"),
        "{a}"
    );
    assert!(b.contains("2 steps"), "{b}");
    let cfg: Value =
        serde_json::from_slice(&std::fs::read(checkpoint(&run, 2).join("config.json")).unwrap())
            .unwrap();
    assert_eq!(cfg["train"]["batch_size"], 8);
}

#[test]
fn the_kubernetes_manifest_is_a_pytorchjob_whose_command_the_trainer_takes() {
    let manifest = workspace().join("cluster/kubernetes/pytorchjob.yaml");
    let mut cmd = py();
    cmd.arg(script("check_k8s_recipe.py")).arg(&manifest);
    let out = run_ok(cmd, LIMIT);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["errors"], serde_json::json!([]), "{v}");
    assert!(v["commands"].as_array().unwrap().len() >= 2, "{v}");
}

/// `python -m scaledp_data.train`'s options from `args` (no dataset is opened).
fn python_options(args: &[&str]) -> Value {
    let code = "import argparse, json, sys\n\
                from scaledp_data.policy.options import add_arguments, options_from_args\n\
                p = argparse.ArgumentParser()\n\
                add_arguments(p)\n\
                print(json.dumps(options_from_args(p.parse_args(sys.argv[1:]))))";
    let mut cmd = py();
    cmd.arg("-c").arg(code).args(args);
    let out = run_ok(cmd, LIMIT);
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A command line moves between the trainers unchanged: the defaults and every preset (with a
/// flag overriding it) give the Rust trainer's options, field by field.
#[test]
fn the_defaults_and_the_presets_are_the_rust_trainers() {
    use scaledp_policy::TrainOptions;
    let rust = |o: TrainOptions| serde_json::to_value(o).unwrap();
    let keys = |v: &Value| -> Vec<String> { v.as_object().unwrap().keys().cloned().collect() };
    let def = rust(TrainOptions::default());
    let py_def = python_options(&["ds"]);
    for k in keys(&py_def) {
        assert_eq!(py_def[&k], def[&k], "default of {k}");
    }
    for name in scaledp_policy::PRESETS {
        let preset = rust(TrainOptions::preset(name).unwrap().lr(1e-3));
        let py_preset = python_options(&["ds", "--preset", name, "--lr", "1e-3"]);
        for k in keys(&py_preset) {
            assert_eq!(py_preset[&k], preset[&k], "{name}'s {k}");
        }
        if name != "paper" {
            assert_eq!(py_preset["resnet_width"], 32, "{name}");
        }
        assert_eq!(py_preset["lr"], 1e-3, "{name}");
    }
    // ScaleDP trains causal unless the paper's configuration is asked for, in both trainers.
    assert_eq!(py_def["attention"], "causal");
    let paper = |flags: &[&str]| python_options(&[&["ds", "--preset", "paper"], flags].concat());
    assert_eq!(paper(&[])["attention"], "non_causal");
    assert_eq!(paper(&["--model", "s"])["attention"], "non_causal");
    assert_eq!(paper(&["--model", "dp-t"])["attention"], "causal");
    let fixed = rust(TrainOptions::default().pos_embed(scaledp_policy::PosEmbed::SinCos));
    let py_fixed = python_options(&["ds", "--pos-embed", "sin-cos"]);
    assert_eq!(py_fixed["pos_embed"], "sin_cos");
    assert_eq!(py_fixed["pos_embed"], fixed["pos_embed"]);
}
