//! One training step in Rust and in PyTorch from the same weights, batch and random draws: the
//! same loss, and every gradient within a stated float32 tolerance.
//!
//! The Rust trainer draws each step's crops, timesteps and noise from its own ChaCha8 stream;
//! `scaledp_policy::parity::step_draws` replays that stream in the trainer's order and hands the
//! numbers to the PyTorch module (`DenoisingLoss` takes draws as inputs). A wrong replay cannot
//! pass: the losses would differ. Weights are random and non-zero everywhere (a fresh
//! adaLN-Zero model has zero gradients almost everywhere), the batch is a real loader batch
//! holding padded action steps, the images 80×45 cropped to 72×41 (non-square, odd).

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor};
use scaledp_datasets::{Batch, LoaderOptions, Norm};
use scaledp_policy::model::ScaleDp;
use scaledp_policy::parity::{step_draws, step_loss_and_grads};
use scaledp_policy::{LossSpec, ModelConfig, ModelSize};
use serde_json::{json, Value};

use super::{fixture, py, run_ok, script};

/// Relative tolerance on each parameter group: max |g_rust − g_torch| ≤ TOL · max |g| (float32
/// on both sides; this machine measured ≤ 1.4e-6, summation orders differ between the engines).
const TOL: f32 = 1e-4;

/// A batch of 6 samples of the fixture's dataset that holds padded action steps.
fn padded_batch() -> Batch {
    let mut loader = LoaderOptions::default()
        .batch_size(6)
        .state_norm(Norm::MinMax)
        .action_norm(Norm::MinMax)
        .seed(3)
        .open(fixture().dataset.to_str().unwrap())
        .unwrap();
    for _ in 0..200 {
        let b = loader
            .next_batch()
            .expect("a batch with padding in the first epoch")
            .unwrap();
        let pads = b.action_is_pad.iter().filter(|p| **p).count();
        if pads > 0 && pads < b.action_is_pad.len() / 2 {
            return b;
        }
    }
    panic!("no batch with padded action steps");
}

fn tiny_model(b: &Batch) -> ModelConfig {
    let mut cfg = ModelConfig::new(
        ModelSize::Ti,
        b.cameras.clone(),
        (b.width, b.height),
        b.state_dim,
        b.action_dim,
    );
    (cfg.size, cfg.depth, cfg.hidden, cfg.heads) = (None, 2, 32, 4);
    cfg.resnet_width = 8;
    cfg
}

/// Runs one parity case of the tiny model and returns the PyTorch side's report.
fn case(spec: LossSpec, micro: Option<usize>) -> Value {
    case_of(|_| {}, spec, micro)
}

/// Runs one parity case of the tiny model as `edit` changes it (DP-T, say).
pub(crate) fn case_of(edit: fn(&mut ModelConfig), spec: LossSpec, micro: Option<usize>) -> Value {
    let batch = padded_batch();
    let mut cfg = tiny_model(&batch);
    edit(&mut cfg);
    let model = ScaleDp::random(&cfg, 5, 0.1, &Device::Cpu).unwrap();
    let (seed, step) = (7u64, 3u64);
    let draws = step_draws(&cfg, 100, batch.len, spec, micro, seed, step);
    let (loss, grads) = step_loss_and_grads(&model, 100, &batch, spec, micro, seed, step).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    model.save(&d.join("model.safetensors")).unwrap();
    let dev = Device::Cpu;
    let (b, to, ch, a) = (batch.len, cfg.obs_horizon, cfg.action_chunk, cfg.action_dim);
    let (cams, k) = (cfg.cameras.len(), spec.noise_samples.max(1));
    let (w, h) = (batch.width as usize, batch.height as usize);
    let u8s = |v: Vec<u8>, s: &[usize]| Tensor::from_vec(v, s, &dev).unwrap();
    let i64s = |v: Vec<i64>, s: &[usize]| Tensor::from_vec(v, s, &dev).unwrap();
    let f32s = |v: Vec<f32>, s: &[usize]| Tensor::from_vec(v, s, &dev).unwrap();
    let mut t: HashMap<String, Tensor> = HashMap::new();
    t.insert(
        "images".into(),
        u8s(batch.images.clone(), &[b, to, cams, 3, h, w]),
    );
    t.insert(
        "state".into(),
        f32s(batch.state.clone(), &[b, to, batch.state_dim]),
    );
    t.insert("action".into(), f32s(batch.action.clone(), &[b, ch, a]));
    let pad: Vec<u8> = batch.action_is_pad.iter().map(|p| u8::from(*p)).collect();
    t.insert("action_is_pad".into(), u8s(pad, &[b, ch]));
    let crops: Vec<i64> = draws
        .crops
        .iter()
        .flat_map(|c| c.map(|v| v as i64))
        .collect();
    t.insert("crops".into(), i64s(crops, &[cams, b, to, 2]));
    let ts: Vec<i64> = draws.timesteps.iter().map(|v| *v as i64).collect();
    t.insert("timesteps".into(), i64s(ts, &[b, k]));
    t.insert("noise".into(), f32s(draws.noise.clone(), &[b, k, ch, a]));
    candle_core::safetensors::save(&t, d.join("case.safetensors")).unwrap();
    let weights: HashMap<String, Tensor> = model.weights().iter().cloned().collect();
    let g: HashMap<String, Tensor> = grads
        .into_iter()
        .map(|(n, v)| {
            let shape = weights[&n].dims().to_vec();
            (
                n,
                Tensor::from_vec(v, shape, &dev)
                    .unwrap()
                    .to_dtype(DType::F32)
                    .unwrap(),
            )
        })
        .collect();
    candle_core::safetensors::save(&g, d.join("grads.safetensors")).unwrap();
    let info = json!({"model": cfg, "loss": spec, "train_steps": 100, "loss_rust": loss});
    std::fs::write(d.join("case.json"), info.to_string()).unwrap();
    let mut cmd = py();
    cmd.arg(script("torch_parity.py")).arg(d);
    let out = run_ok(cmd, std::time::Duration::from_secs(300));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let v: Value = serde_json::from_str(stdout.lines().last().unwrap_or("")).unwrap();
    report(&v, spec, micro);
    v
}

/// Prints the figures and checks them against the tolerance.
fn report(v: &Value, spec: LossSpec, micro: Option<usize>) {
    let (lr, lt) = (
        v["loss_rust"].as_f64().unwrap(),
        v["loss_torch"].as_f64().unwrap(),
    );
    eprintln!(
        "one step, K {} mask_padding {} micro {micro:?}: loss rust {lr:.7} torch {lt:.7} (|diff| {:.2e}; torch {})",
        spec.noise_samples,
        spec.mask_padding,
        (lr - lt).abs(),
        v["torch"]
    );
    assert!(
        (lr - lt).abs() <= 1e-5 * lr.abs() + 1e-7,
        "losses differ: {v}"
    );
    for (name, g) in v["groups"].as_object().unwrap() {
        let (diff, top) = (
            g["max_abs_diff"].as_f64().unwrap(),
            g["max_abs_grad"].as_f64().unwrap(),
        );
        eprintln!(
            "  {name:<28} max |grad| {top:.3e}  max |diff| {diff:.3e}  ({:.1e} of max)",
            diff / top.max(1e-30)
        );
        assert!(top > 0.0, "{name}: no gradient at all: {v}");
        assert!(
            diff <= f64::from(TOL) * top,
            "{name}: gradients differ beyond {TOL}: {v}"
        );
    }
}

#[test]
fn one_step_loss_and_gradients_equal_pytorchs() {
    let v = case(LossSpec::default(), None);
    assert_eq!(v["groups"].as_object().unwrap().len(), 7, "{v}");
}

#[test]
fn several_noise_draws_masked_padding_and_micro_batches_equal_pytorchs() {
    let spec = LossSpec {
        noise_samples: 2,
        mask_padding: true,
    };
    case(spec, Some(4));
}
