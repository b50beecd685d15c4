//! DP-T, the paper's baseline, on the PyTorch route: one training step equal to PyTorch's with
//! dropout off, and a DP-T run (dropout 0.3, its causal masks) passing torch → Rust → torch
//! with its checkpoints sampling the same chunks in both.

use std::time::Duration;

use candle_core::Device;
use scaledp_policy::{Architecture, Attention, LossSpec, Policy};
use scaledp_tests::{read_json, scaledp_bin};
use serde_json::Value;

use super::interop::{copy_run, rust_vs_torch_chunks};
use super::parity::case_of;
use super::{checkpoint, fixture, run_ok, train_cmd, TINY};

const LIMIT: Duration = Duration::from_secs(300);

fn dpt(cfg: &mut scaledp_policy::ModelConfig) {
    (cfg.arch, cfg.attention, cfg.dropout) = (Architecture::DpT, Attention::Causal, 0.0);
}

fn dpt_non_causal(cfg: &mut scaledp_policy::ModelConfig) {
    dpt(cfg);
    cfg.attention = Attention::NonCausal;
}

#[test]
fn dpt_one_step_loss_and_gradients_equal_pytorchs() {
    let v = case_of(dpt, LossSpec::default(), None);
    // Encoders (2 groups) and the 6 of DP-T, every one reached.
    assert_eq!(v["groups"].as_object().unwrap().len(), 8, "{v}");
}

#[test]
fn dpt_without_masks_several_noise_draws_and_micro_batches_equal_pytorchs() {
    let spec = LossSpec {
        noise_samples: 2,
        mask_padding: true,
    };
    case_of(dpt_non_causal, spec, Some(4));
}

#[test]
fn a_dpt_run_passes_torch_rust_torch_and_samples_alike_in_both() {
    let f = fixture();
    let run = f.dir.join("dpt-torch");
    let _ = std::fs::remove_dir_all(&run);
    let ds = f.dataset.to_str().unwrap().to_string();
    let out = run.to_str().unwrap().to_string();
    let mut args = vec![ds.as_str(), "--model", "dp-t", "--steps", "3"];
    args.extend(["--checkpoint-every", "3", "--out", &out]);
    args.extend(TINY);
    run_ok(train_cmd(1, &args), LIMIT);
    let handover = f.dir.join("dpt-handover");
    copy_run(&run, &handover);
    let mut rust = std::process::Command::new(scaledp_bin());
    rust.args(["train", "--resume"])
        .arg(&handover)
        .args(["--steps", "5"]);
    run_ok(rust, LIMIT);
    let h = handover.to_str().unwrap();
    run_ok(train_cmd(1, &["--resume", h, "--steps", "7"]), LIMIT);
    let text = std::fs::read_to_string(handover.join("metrics.jsonl")).unwrap();
    let steps: Vec<u64> = text
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .filter(|v| v["kind"] == "train")
        .map(|v| v["record"]["step"].as_u64().unwrap())
        .collect();
    assert_eq!(steps, (1..=7).collect::<Vec<_>>());
    for step in [3, 5, 7] {
        let cfg = read_json(&checkpoint(&handover, step).join("config.json"));
        assert_eq!(cfg["model"]["arch"], "dp_t", "{cfg}");
        assert_eq!(cfg["model"]["attention"], "causal", "{cfg}");
        assert_eq!(cfg["model"]["dropout"], 0.3, "{cfg}");
    }
    let policy = Policy::load(&handover, &Device::Cpu).unwrap();
    assert_eq!(policy.config().step, 7);
    let worst = rust_vs_torch_chunks(&checkpoint(&handover, 7));
    assert!(worst <= 1e-4, "{worst}");
}
