//! The Rust encoders and denoiser against an independent numpy forward pass
//! (`tests/py/scaledp_reference.py`) reading the same `model.safetensors`, on random non-zero
//! weights. Needs `.venv` (`bash scripts/setup-python.sh`): without it the test fails.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] functions

use std::path::PathBuf;
use std::process::Command;

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use scaledp_policy::model::{Crop, ScaleDp};
use scaledp_policy::{Attention, ModelConfig, ModelSize};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn encoders_and_denoiser_match_the_numpy_reference() {
    check(Attention::NonCausal);
}

#[test]
fn the_causal_ablation_matches_the_numpy_reference() {
    check(Attention::Causal);
}

/// Images in [−1, 1] (the default range) with the given attention.
fn check(attention: Attention) {
    let python = workspace().join(".venv/bin/python");
    assert!(
        python.exists(),
        "{} is missing: run `bash scripts/setup-python.sh` (the numpy reference needs it)",
        python.display()
    );
    let cams = vec![
        "observation.images.front".to_string(),
        "observation.images.wrist.left".to_string(),
    ];
    // 41×35: odd margins, so the centre crop's rounding is exercised.
    let mut cfg = ModelConfig::new(ModelSize::Ti, cams, (41, 35), 3, 2);
    (cfg.size, cfg.depth, cfg.hidden, cfg.heads) = (None, 2, 32, 4);
    cfg.resnet_width = 16;
    cfg.action_chunk = 5;
    cfg.crop = 0.9;
    cfg.attention = attention;
    let dev = Device::Cpu;
    let model = ScaleDp::random(&cfg, 11, 0.1, &dev).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let weights = dir.path().join("model.safetensors");
    model.save(&weights).unwrap();
    let b = 2;
    let n_img = b * cfg.obs_horizon * 2 * 3 * 41 * 35;
    let images: Vec<u8> = (0..n_img).map(|i| ((i * 7919) % 251) as u8).collect();
    let state: Vec<f32> = (0..b * cfg.obs_horizon * 3)
        .map(|i| (i as f32 * 0.37).sin())
        .collect();
    let x: Vec<f32> = (0..b * 5 * 2).map(|i| (i as f32 * 0.61).cos()).collect();
    let t = [7.0f32, 93.0];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let cond = model
        .encode(&images, &state, b, Crop::Center, &mut rng)
        .unwrap();
    let xt = Tensor::from_slice(&x, (b, 5, 2), &dev).unwrap();
    let eps = model.predict_noise(&xt, &t, &cond).unwrap();
    let case = serde_json::json!({
        "weights": weights, "config": cfg, "batch": b, "images": images, "state": state,
        "x": x, "t": t,
    });
    let case_path = dir.path().join("case.json");
    std::fs::write(&case_path, serde_json::to_vec(&case).unwrap()).unwrap();
    let out = Command::new(&python)
        .arg(workspace().join("tests/py/scaledp_reference.py"))
        .arg(&case_path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reference: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (name, ours) in [("cond", cond), ("eps", eps)] {
        let ours = ours.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let theirs: Vec<f64> = serde_json::from_value(reference[name].clone()).unwrap();
        assert_eq!(ours.len(), theirs.len(), "{name}");
        let worst = ours
            .iter()
            .zip(&theirs)
            .map(|(a, b)| (f64::from(*a) - b).abs() / b.abs().max(1.0))
            .fold(0f64, f64::max);
        assert!(worst <= 1e-4, "{name}: differs from numpy by {worst}");
        // Random weights give outputs that are not trivially zero.
        assert!(theirs.iter().any(|v| v.abs() > 1e-3), "{name} is all zero");
    }
}
