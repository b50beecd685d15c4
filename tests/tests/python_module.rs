//! The Python module `scaledp_data` (the wheel `scripts/build-python.sh` builds) installed into
//! a fresh venv: its batches are byte-equal to the Rust loader's for the same options (shuffled
//! train split, a sharded val split, streaming), epochs / state_dict / resume, the normalizer,
//! errors, the GIL released while a batch is awaited. The fresh venv has no torch: the torch
//! adapter (DataLoader with 0 and 2 workers, resume, two DDP ranks over gloo) runs when
//! `SCALEDP_TORCH_PYTHON` names an interpreter with torch and numpy (the wheel is put on its
//! `PYTHONPATH`, its site-packages are left alone); otherwise the test says it skipped it.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::convert_common::convert_ok;
use scaledp_datasets::{Batch, LoaderOptions, Norm, Split};
use scaledp_tests::{f32_rows, python, small_franka, synth_episode, workspace, write_rig_file};
use serde_json::{json, Value};

/// Four episodes of different lengths, two 64×48 cameras.
fn dataset(dir: &Path) -> PathBuf {
    let rig = small_franka();
    let bags = dir.join("bags");
    for (seed, seconds) in [(1u64, 2.0), (2, 2.6), (3, 1.7), (4, 3.1)] {
        let path = bags.join(format!("episode_{seed:06}.mcap"));
        std::fs::create_dir_all(&bags).unwrap();
        synth_episode(&path, &rig, seed, seconds);
    }
    let rig_path = write_rig_file(dir, &rig);
    let ds = dir.join("ds");
    convert_ok(
        &[
            bags.as_os_str(),
            "--rig".as_ref(),
            rig_path.as_os_str(),
            "--out".as_ref(),
            ds.as_os_str(),
        ],
        "converted",
    );
    ds
}

/// The loader options of `kwargs` (the Python keyword arguments), so both sides get the same.
fn options(kwargs: &Value) -> LoaderOptions {
    let mut o = LoaderOptions::default();
    for (k, v) in kwargs.as_object().unwrap() {
        let n = || v.as_u64().unwrap() as usize;
        let norm = || match v.as_str().unwrap() {
            "min_max" => Norm::MinMax,
            "mean_std" => Norm::MeanStd,
            _ => Norm::None,
        };
        o = match k.as_str() {
            "obs_horizon" => o.obs_horizon(n()),
            "action_chunk" => o.action_chunk(n()),
            "action_offset" => o.action_offset(n()),
            "cameras" => o.cameras(serde_json::from_value(v.clone()).unwrap()),
            "image_size" => {
                o.image_size(v[0].as_u64().unwrap() as u32, v[1].as_u64().unwrap() as u32)
            }
            "drop_first" => o.drop_first(n()),
            "drop_last" => o.drop_last(n()),
            "split" => o.split(match v.as_str().unwrap() {
                "train" => Split::Train,
                "val" => Split::Val,
                _ => Split::All,
            }),
            "val_ratio" => o.val_ratio(v.as_f64().unwrap()),
            "split_seed" => o.split_seed(v.as_u64().unwrap()),
            "max_episodes" => o.max_episodes(n()),
            "state_norm" => o.state_norm(norm()),
            "action_norm" => o.action_norm(norm()),
            "batch_size" => o.batch_size(n()),
            "drop_incomplete_batch" => o.drop_incomplete_batch(v.as_bool().unwrap()),
            "shuffle" => o.shuffle(v.as_bool().unwrap()),
            "seed" => o.seed(v.as_u64().unwrap()),
            "threads" => o.threads(n()),
            "prefetch" => o.prefetch(n()),
            "streaming" => o.streaming(n()),
            "rank" | "world_size" => o,
            other => panic!("no option {other}"),
        };
    }
    let rank = kwargs
        .get("rank")
        .map_or(0, |v| v.as_u64().unwrap() as usize);
    let world = kwargs
        .get("world_size")
        .map_or(1, |v| v.as_u64().unwrap() as usize);
    o.rank(rank, world)
}

fn write<T: Copy>(
    dir: &Path,
    name: &str,
    v: &[T],
    shape: &[usize],
    dtype: &str,
    le: impl Fn(T) -> Vec<u8>,
) -> Value {
    assert_eq!(v.len(), shape.iter().product::<usize>(), "{name}");
    let bytes: Vec<u8> = v.iter().flat_map(|&x| le(x)).collect();
    std::fs::write(dir.join(name), bytes).unwrap();
    json!({"file": name, "shape": shape, "dtype": dtype})
}

/// Writes a batch's arrays as raw little-endian files; returns their manifest.
fn dump(dir: &Path, prefix: &str, b: &Batch) -> Value {
    let (n, to, c) = (b.len, b.obs_horizon, b.action_chunk);
    let (h, w) = (b.height as usize, b.width as usize);
    let u8s = |x: u8| vec![x];
    let f32s = |x: f32| x.to_le_bytes().to_vec();
    let bools = |x: bool| vec![u8::from(x)];
    let i64s = |x: i64| x.to_le_bytes().to_vec();
    json!({
        "observation.images": write(dir, &format!("{prefix}_images.bin"), &b.images, &[n, to, b.cameras.len(), 3, h, w], "uint8", u8s),
        "observation.state": write(dir, &format!("{prefix}_state.bin"), &b.state, &[n, to, b.state_dim], "float32", f32s),
        "action": write(dir, &format!("{prefix}_action.bin"), &b.action, &[n, c, b.action_dim], "float32", f32s),
        "obs_is_pad": write(dir, &format!("{prefix}_obs_is_pad.bin"), &b.obs_is_pad, &[n, to], "bool", bools),
        "action_is_pad": write(dir, &format!("{prefix}_action_is_pad.bin"), &b.action_is_pad, &[n, c], "bool", bools),
        "episode_index": write(dir, &format!("{prefix}_episode_index.bin"), &b.episode_index, &[n], "int64", i64s),
        "frame_index": write(dir, &format!("{prefix}_frame_index.bin"), &b.frame_index, &[n], "int64", i64s),
    })
}

/// Runs one configuration through the Rust loader: epochs 0 and 1 in full, and the state after
/// `resume_after` batches of epoch 1.
fn rust_side(ds: &Path, out: &Path, name: &str, kwargs: Value, resume_after: usize) -> Value {
    let mut loader = options(&kwargs).open(ds.to_str().unwrap()).unwrap();
    let mut epochs = Vec::new();
    let mut resume = Value::Null;
    for epoch in 0..2u64 {
        loader.set_epoch(epoch);
        let mut batches = Vec::new();
        let mut i = 0;
        while let Some(b) = loader.next_batch() {
            batches.push(dump(out, &format!("{name}_e{epoch}_b{i}"), &b.unwrap()));
            i += 1;
            if epoch == 1 && i == resume_after {
                let s = loader.state();
                resume = json!({"state": {"epoch": s.epoch, "position": s.position}, "after": i});
            }
        }
        assert!(
            batches.len() > resume_after,
            "{name}: too few batches for the test"
        );
        assert_eq!(batches.len(), loader.batches_per_epoch(), "{name}");
        epochs.push(json!({"epoch": epoch, "batches": batches}));
    }
    let info = loader.info();
    json!({
        "name": name,
        "kwargs": kwargs,
        "epochs": epochs,
        "resume": resume,
        "num_samples": loader.len(),
        "info": {"cameras": info.cameras, "episodes": info.episodes, "fps": info.fps,
                 "state_names": info.state_names, "action_names": info.action_names},
    })
}

/// The wheel directory and the scaledp_data wheel in it (`SCALEDP_WHEEL_DIR`, else target/wheels).
fn wheel() -> (PathBuf, PathBuf) {
    let wheel = scaledp_testkit::scaledp_data_wheel(None, Some(&workspace()))
        .unwrap_or_else(|e| panic!("{e} (scripts/test.sh does)"));
    let wheels = wheel.parent().unwrap().to_path_buf();
    (wheels, wheel)
}

/// A fresh venv with numpy and the wheel (offline, from target/wheels); returns its python.
fn fresh_venv(dir: &Path) -> PathBuf {
    let (wheels, wheel) = wheel();
    // A wheel older than the sources it is built from would test old code.
    let built = std::fs::metadata(&wheel).unwrap().modified().unwrap();
    for src in ["python/src", "python/python/scaledp_data", "datasets/src"] {
        for e in std::fs::read_dir(workspace().join(src)).unwrap() {
            let p = e.unwrap().path();
            assert!(
                std::fs::metadata(&p).unwrap().modified().unwrap() <= built,
                "{} is newer than {}: run scripts/build-python.sh",
                p.display(),
                wheel.display()
            );
        }
    }
    let venv = dir.join("venv");
    let run = |cmd: &mut Command| {
        let out = cmd.output().unwrap();
        assert!(
            out.status.success(),
            "{cmd:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    run(Command::new(python()).args(["-m", "venv"]).arg(&venv));
    let py = venv.join("bin/python");
    run(Command::new(&py)
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--no-index",
            "--find-links",
        ])
        .arg(wheels.join("deps"))
        .arg(&wheel));
    py
}

fn check(py: &Path, manifest: &Path, env: &[(&str, &Path)]) -> Value {
    let mut cmd = Command::new(py);
    cmd.arg(workspace().join("tests/py/check_python_module.py"))
        .arg(manifest);
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "check_python_module.py with {}:\n{}",
        py.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    // The report is the last line: torch's gloo backend prints to stdout from C++ before it.
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("no JSON: {e}: {stdout}"))
}

#[test]
fn python_batches_equal_the_rust_loaders_and_the_torch_adapter_works() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    let out = dir.path().join("rust");
    std::fs::create_dir_all(&out).unwrap();
    let configs = vec![
        rust_side(
            &ds,
            &out,
            "train",
            json!({"obs_horizon": 2, "action_chunk": 8, "split": "train", "val_ratio": 0.25,
                   "split_seed": 3, "batch_size": 5, "seed": 7, "threads": 2,
                   "image_size": [32, 24], "prefetch": 3}),
            2,
        ),
        rust_side(
            &ds,
            &out,
            "val_rank1_of_2",
            json!({"obs_horizon": 3, "action_chunk": 4, "action_offset": 1, "split": "val",
                   "val_ratio": 0.5, "split_seed": 3, "batch_size": 3, "shuffle": false,
                   "drop_incomplete_batch": true, "drop_first": 1, "drop_last": 2,
                   "cameras": ["wrist"], "state_norm": "none", "action_norm": "mean_std",
                   "rank": 1, "world_size": 2, "threads": 2}),
            1,
        ),
        rust_side(
            &ds,
            &out,
            "streaming",
            json!({"batch_size": 4, "seed": 5, "threads": 2, "streaming": 2,
                   "max_episodes": 3, "action_chunk": 6}),
            3,
        ),
    ];
    // The normalizer on raw rows of the dataset, as the Rust side computes it.
    let loader = options(&configs[0]["kwargs"])
        .open(ds.to_str().unwrap())
        .unwrap();
    let raw_action: Vec<f32> = f32_rows(&ds, "action")
        .into_iter()
        .take(12)
        .flatten()
        .collect();
    let raw_state: Vec<f32> = f32_rows(&ds, "observation.state")
        .into_iter()
        .take(12)
        .flatten()
        .collect();
    let (mut na, mut ns) = (raw_action.clone(), raw_state.clone());
    loader.normalizer().normalize_action(&mut na);
    loader.normalizer().normalize_state(&mut ns);
    let (ad, sd) = (raw_action.len() / 12, raw_state.len() / 12);
    let f32s = |x: f32| x.to_le_bytes().to_vec();
    let normalizer = json!({
        "raw_action": write(&out, "raw_action.bin", &raw_action, &[12, ad], "float32", f32s),
        "action": write(&out, "norm_action.bin", &na, &[12, ad], "float32", f32s),
        "raw_state": write(&out, "raw_state.bin", &raw_state, &[12, sd], "float32", f32s),
        "state": write(&out, "norm_state.bin", &ns, &[12, sd], "float32", f32s),
    });
    let manifest = out.join("manifest.json");
    let m = json!({"dataset": ds, "dir": out, "configs": configs, "normalizer": normalizer});
    std::fs::write(&manifest, serde_json::to_vec_pretty(&m).unwrap()).unwrap();

    let py = fresh_venv(dir.path());
    let v = check(&py, &manifest, &[]);
    eprintln!("scaledp_data in a fresh venv: {v}");
    for c in &configs {
        let name = c["name"].as_str().unwrap();
        let want: usize = c["epochs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["batches"].as_array().unwrap().len())
            .sum();
        assert_eq!(v["configs"][name]["batches_equal"], want, "{name}: {v}");
        let resumed = c["epochs"][1]["batches"].as_array().unwrap().len()
            - c["resume"]["after"].as_u64().unwrap() as usize;
        assert_eq!(
            v["configs"][name]["resumed_batches_equal"], resumed,
            "{name}: {v}"
        );
    }
    assert_eq!(v["normalizer"]["byte_equal"], true, "{v}");
    assert_eq!(v["errors_checked"], 7, "{v}");
    assert!(
        v["gil_released"]["other_thread_ran_ms"].as_u64().unwrap() > 0,
        "{v}"
    );
    assert_eq!(
        v["imports_torch"], false,
        "importing scaledp_data imported torch: {v}"
    );
    // The fresh venv has no torch; SCALEDP_TORCH_PYTHON names an interpreter that has it.
    match v["torch"].as_str() {
        Some(s) if s.starts_with("torch not installed") => eprintln!("fresh venv: {s}"),
        _ => panic!("torch in a fresh venv? {v}"),
    }
    match std::env::var_os("SCALEDP_TORCH_PYTHON") {
        None => eprintln!("SCALEDP_TORCH_PYTHON not set: torch adapter test skipped"),
        Some(tpy) => {
            let target = dir.path().join("site");
            let st = Command::new(&tpy)
                .args([
                    "-m",
                    "pip",
                    "install",
                    "--quiet",
                    "--disable-pip-version-check",
                    "--no-deps",
                    "--target",
                ])
                .arg(&target)
                .arg(wheel().1)
                .status()
                .unwrap();
            assert!(st.success());
            let v = check(Path::new(&tpy), &manifest, &[("PYTHONPATH", &target)]);
            assert!(
                v["torch"]["dataloader_batches_equal"].as_u64().unwrap() > 0,
                "{v}"
            );
            eprintln!("torch adapter: {}", v["torch"]);
        }
    }
}
