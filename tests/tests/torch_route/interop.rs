//! Checkpoints move between the trainers: a checkpoint trained by 2 gloo ranks acts in Rust
//! (`Policy::predict_batch`, what `serve` and `eval` run) as the PyTorch module samples it from
//! the same starting noise, `scaledp eval` runs it in the simulated cell, and the Rust trainer
//! resumes the torch run, which torch resumes again.

use std::collections::HashMap;
use std::path::Path;
use std::time::Duration;

use candle_core::{Device, Tensor};
use scaledp_datasets::{LoaderOptions, Norm};
use scaledp_policy::parity::sampling_noise;
use scaledp_policy::{Observation, Policy};
use scaledp_tests::{read_json, scaledp_bin};
use serde_json::Value;

use super::ddp::reference_runs;
use super::{checkpoint, fixture, py, run_ok, script, train_cmd};

const LIMIT: Duration = Duration::from_secs(300);

/// The 2-rank reference run's last checkpoint.
fn torch_checkpoint() -> std::path::PathBuf {
    checkpoint(&reference_runs().1, 13)
}

#[test]
fn a_torch_trained_checkpoint_acts_in_rust_as_the_torch_module_samples_it() {
    let worst = rust_vs_torch_chunks(&torch_checkpoint());
    assert!(worst <= 1e-4, "{worst}");
}

/// The largest difference (normalized units) between the chunks `Policy::predict_batch` and
/// the PyTorch module's DDIM-10 sample for 4 dataset observations from the same starting noise.
pub(crate) fn rust_vs_torch_chunks(ckpt: &Path) -> f64 {
    let policy = Policy::load(ckpt, &Device::Cpu).unwrap();
    let m = policy.config().model.clone();
    // Raw observations (un-normalized state) of 4 dataset samples.
    let mut loader = LoaderOptions::default()
        .batch_size(4)
        .state_norm(Norm::None)
        .action_norm(Norm::None)
        .seed(11)
        .open(fixture().dataset.to_str().unwrap())
        .unwrap();
    let batch = loader.next_batch().unwrap().unwrap();
    let b = batch.len;
    let per_img = m.obs_horizon * m.cameras.len() * 3 * (m.image_width * m.image_height) as usize;
    let per_state = m.obs_horizon * m.state_dim;
    let obs: Vec<Observation> = (0..b)
        .map(|i| Observation {
            images: batch.images[i * per_img..(i + 1) * per_img].to_vec(),
            state: batch.state[i * per_state..(i + 1) * per_state].to_vec(),
        })
        .collect();
    let seed = 42;
    let rust = policy.predict_batch(&obs, seed).unwrap();
    // The same inputs and starting noise through the PyTorch module.
    let dev = Device::Cpu;
    let (h, w) = (m.image_height as usize, m.image_width as usize);
    let mut case: HashMap<String, Tensor> = HashMap::new();
    let shape = [b, m.obs_horizon, m.cameras.len(), 3, h, w];
    case.insert(
        "images".into(),
        Tensor::from_vec(batch.images.clone(), &shape, &dev).unwrap(),
    );
    let s = Tensor::from_vec(batch.state.clone(), &[b, m.obs_horizon, m.state_dim], &dev);
    case.insert("state".into(), s.unwrap());
    let noise = sampling_noise(&m, b, seed);
    let n = Tensor::from_vec(noise, &[b, m.action_chunk, m.action_dim], &dev).unwrap();
    case.insert("noise".into(), n);
    let path = fixture().dir.join("predict-case.safetensors");
    candle_core::safetensors::save(&case, &path).unwrap();
    let mut cmd = py();
    cmd.arg(script("torch_predict.py")).arg(ckpt).arg(&path);
    let out = run_ok(cmd, LIMIT);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let scale = &policy.config().normalizer.action.scale;
    let mut worst = 0f64;
    for (chunk, t) in rust.iter().zip(v["actions"].as_array().unwrap()) {
        let t: Vec<f64> = t
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(t.len(), chunk.actions.len());
        for (k, (r, t)) in chunk.actions.iter().zip(&t).enumerate() {
            // In normalized units ([-1, 1] over the dataset's range).
            worst = worst.max((f64::from(*r) - t).abs() * scale[k % m.action_dim]);
        }
    }
    eprintln!(
        "{} torch checkpoint, DDIM-10 from the same noise: Rust vs PyTorch chunks differ by at most {worst:.2e} (normalized units) over {b} observations",
        m.denoiser_name()
    );
    worst
}

#[test]
fn scaledp_eval_runs_a_torch_trained_checkpoint() {
    let f = fixture();
    let report = f.dir.join("eval.json");
    let mut cmd = std::process::Command::new(scaledp_bin());
    cmd.arg("eval")
        .arg(torch_checkpoint())
        .arg("--rig")
        .arg(&f.rig_file)
        .args(["--episodes", "1", "--max-seconds", "2", "--report"])
        .arg(&report);
    let out = run_ok(cmd, LIMIT);
    eprintln!(
        "scaledp eval: {}",
        String::from_utf8_lossy(&out.stdout).trim()
    );
    let r = read_json(&report);
    let eps = r["episodes"].as_array().unwrap();
    assert_eq!(eps.len(), 1, "{r}");
    let e = &eps[0];
    assert!(e["commanded_ticks"].as_u64().unwrap() >= 10, "{e}");
    assert!(e["chunks"].as_u64().unwrap() >= 2, "{e}");
    assert!(r["inference_ms_p50"].as_f64().unwrap() > 0.0, "{r}");
}

/// Copies a run directory (its metrics, samples and checkpoints).
pub(crate) fn copy_run(from: &Path, to: &Path) {
    let _ = std::fs::remove_dir_all(to);
    let st = std::process::Command::new("cp")
        .arg("-a")
        .arg(from)
        .arg(to)
        .status()
        .unwrap();
    assert!(st.success());
}

#[test]
fn the_rust_trainer_resumes_a_torch_run_and_torch_resumes_it_back() {
    let f = fixture();
    let run = f.dir.join("handover");
    copy_run(&reference_runs().1, &run);
    let mut rust = std::process::Command::new(scaledp_bin());
    rust.args(["train", "--resume"])
        .arg(&run)
        .args(["--steps", "15"]);
    run_ok(rust, LIMIT);
    let out = run_ok(
        train_cmd(1, &["--resume", run.to_str().unwrap(), "--steps", "17"]),
        LIMIT,
    );
    eprintln!(
        "torch (2 ranks, 13 steps) -> Rust (to 15) -> torch (to 17): {}",
        String::from_utf8_lossy(&out.stdout).trim()
    );
    let text = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    let steps: Vec<u64> = text
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .filter(|v| v["kind"] == "train")
        .map(|v| {
            assert!(v["record"]["loss"].as_f64().unwrap().is_finite(), "{v}");
            v["record"]["step"].as_u64().unwrap()
        })
        .collect();
    assert_eq!(steps, (1..=17).collect::<Vec<_>>());
    // Both trainers wrote checkpoints the other read; the last one is torch's.
    for step in [15, 17] {
        let cfg = read_json(&checkpoint(&run, step).join("config.json"));
        assert_eq!(cfg["step"], step);
        assert_eq!(
            cfg["train"]["denoiser"],
            serde_json::json!([2, 32, 4]),
            "{cfg}"
        );
    }
    Policy::load(&run, &Device::Cpu).unwrap();
}
