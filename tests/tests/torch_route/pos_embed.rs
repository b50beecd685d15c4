//! `--pos-embed sin-cos` on the PyTorch route: a run passing torch (3 steps) → Rust (2) → torch
//! (1) keeps DiT's table, untouched by either trainer's optimizer or EMA, while the learned
//! weights train.

use std::path::Path;
use std::time::Duration;

use candle_core::Device;
use scaledp_policy::{Policy, PosEmbed};
use scaledp_tests::scaledp_bin;

use super::interop::copy_run;
use super::{checkpoint, fixture, run_ok, train_cmd, TINY};

const LIMIT: Duration = Duration::from_secs(300);

/// `name` from the checkpoint `dir`'s EMA weights.
fn tensor(dir: &Path, name: &str) -> Vec<f32> {
    read(dir, "model.safetensors", name)
}

fn read(dir: &Path, file: &str, name: &str) -> Vec<f32> {
    let w = candle_core::safetensors::load(dir.join(file), &Device::Cpu).unwrap();
    w[name].flatten_all().unwrap().to_vec1::<f32>().unwrap()
}

#[test]
fn a_sin_cos_run_passes_torch_rust_torch_with_its_table_fixed() {
    let f = fixture();
    let run = f.dir.join("sincos-torch");
    let _ = std::fs::remove_dir_all(&run);
    let ds = f.dataset.to_str().unwrap().to_string();
    let out = run.to_str().unwrap().to_string();
    let mut args = vec![ds.as_str(), "--pos-embed", "sin-cos", "--steps", "3"];
    args.extend(["--checkpoint-every", "1", "--out", &out]);
    args.extend(TINY);
    run_ok(train_cmd(1, &args), LIMIT);
    let handover = f.dir.join("sincos-handover");
    copy_run(&run, &handover);
    let mut rust = std::process::Command::new(scaledp_bin());
    rust.args(["train", "--resume"])
        .arg(&handover)
        .args(["--steps", "5"]);
    run_ok(rust, LIMIT);
    let h = handover.to_str().unwrap();
    run_ok(train_cmd(1, &["--resume", h, "--steps", "6"]), LIMIT);

    // torch's table (float64, then float32) against DiT's formula, row p = [sin, cos].
    let first = tensor(&checkpoint(&handover, 1), "pos_embed");
    let d = 32;
    let rows = first.len() / d;
    assert_eq!(rows * d, first.len());
    for p in 0..rows {
        for i in 0..d / 2 {
            let a = p as f64 * 10000f64.powf(-(i as f64) / (d / 2) as f64);
            for (got, want) in [
                (first[p * d + i], a.sin()),
                (first[p * d + d / 2 + i], a.cos()),
            ] {
                assert!(
                    (f64::from(got) - want).abs() <= 1e-7,
                    "row {p}, {i}: {got} vs {want}"
                );
            }
        }
    }
    // Both the EMA copy and the trained weights, after every step of both trainers.
    for step in 2..=6 {
        let dir = checkpoint(&handover, step);
        assert_eq!(
            tensor(&dir, "pos_embed"),
            first,
            "step {step} moved the EMA table"
        );
        let trained = read(&dir, "train_state.safetensors", "params.pos_embed");
        assert_eq!(trained, first, "step {step} trained the table");
    }
    assert_ne!(
        tensor(&checkpoint(&handover, 1), "x_embedder.weight"),
        tensor(&checkpoint(&handover, 6), "x_embedder.weight"),
        "the learned weights train"
    );
    let policy = Policy::load(&handover, &Device::Cpu).unwrap();
    assert_eq!(policy.config().model.pos_embed, PosEmbed::SinCos);
    assert_eq!(policy.config().step, 6);
}
