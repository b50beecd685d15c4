//! The network: parameter counts against Table 1, adaLN-Zero, non-causal attention.

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use scaledp_policy::model::{Crop, ScaleDp};
use scaledp_policy::{ModelConfig, ModelSize};

fn tiny_config(cameras: usize) -> ModelConfig {
    let cams = (0..cameras)
        .map(|i| format!("observation.images.c{i}"))
        .collect();
    let mut cfg = ModelConfig::new(ModelSize::Ti, cams, (20, 16), 3, 2);
    cfg.depth = 2;
    cfg.hidden = 32;
    cfg.heads = 4;
    cfg.size = None;
    cfg.resnet_width = 8;
    cfg.action_chunk = 6;
    cfg
}

/// Denoiser counts from the shapes alone (no allocation), for the paper's bimanual setup.
#[test]
fn denoiser_parameter_counts_are_within_3_percent_of_table_1() -> scaledp_policy::Result<()> {
    for size in ModelSize::ALL {
        let cfg = ModelConfig::paper(size);
        let n = ScaleDp::count(&cfg)?;
        let (depth, d, _) = size.dims();
        // One block is 18d² + 15d; the rest is the embedders and the final layer.
        let blocks = depth * (18 * d * d + 15 * d);
        let cond = cfg.cond_dim();
        let rest = (14 * d + d)
            + 16 * d
            + (256 * d + d + d * d + d)
            + (cond * d + d)
            + (d * 2 * d + 2 * d)
            + (d * 14 + 14);
        assert_eq!(
            n.denoiser,
            blocks + rest,
            "{size}: counted from the architecture"
        );
        let paper = if size == ModelSize::H {
            0.95e9
        } else {
            size.paper_params()
        };
        let rel = (n.denoiser as f64 - paper).abs() / paper;
        assert!(
            rel < 0.03,
            "{size}: {} parameters vs {paper} ({:.1} %)",
            n.denoiser,
            rel * 100.0
        );
        // ResNet-18 trunk (11.17 M) + keypoint conv + Linear, per camera.
        assert_eq!(
            n.encoder_per_camera,
            11_176_512 + (512 * 32 + 32) + (64 * 64 + 64)
        );
        assert_eq!(n.encoders, 3 * n.encoder_per_camera);
    }
    Ok(())
}

#[test]
fn the_untrained_denoiser_outputs_exactly_zero() -> scaledp_policy::Result<()> {
    let cfg = tiny_config(1);
    let dev = Device::Cpu;
    let model = ScaleDp::new(&cfg, 3, &dev)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let images: Vec<u8> = (0..2 * 2 * 3 * 20 * 16)
        .map(|i| (i * 37 % 251) as u8)
        .collect();
    let state = vec![0.3f32; 2 * 2 * 3];
    let cond = model.encode(&images, &state, 2, Crop::Center, &mut rng)?;
    assert!(
        cond.abs()?.sum_all()?.to_scalar::<f32>()? > 0.0,
        "the condition is not zero"
    );
    let x = Tensor::randn(0f32, 1.0, (2, 6, 2), &dev)?;
    let eps = model.predict_noise(&x, &[5.0, 70.0], &cond)?;
    assert_eq!(eps.dims(), &[2, 6, 2]);
    assert_eq!(eps.abs()?.max_all()?.to_scalar::<f32>()?, 0.0);
    Ok(())
}

/// Changing the last noisy action token changes the first output token: no causal mask.
#[test]
fn attention_is_not_causal() -> scaledp_policy::Result<()> {
    let cfg = tiny_config(0);
    let dev = Device::Cpu;
    let model = ScaleDp::random(&cfg, 7, 0.1, &dev)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let state = vec![0.5f32; 2 * 3];
    let cond = model.encode(&[], &state, 1, Crop::Center, &mut rng)?;
    let x = Tensor::randn(0f32, 1.0, (1, 6, 2), &dev)?;
    let mut v = x.flatten_all()?.to_vec1::<f32>()?;
    let a = model
        .predict_noise(&x, &[40.0], &cond)?
        .flatten_all()?
        .to_vec1::<f32>()?;
    v[5 * 2] += 1.0;
    let x2 = Tensor::from_vec(v, (1, 6, 2), &dev)?;
    let b = model
        .predict_noise(&x2, &[40.0], &cond)?
        .flatten_all()?
        .to_vec1::<f32>()?;
    let first = (a[0] - b[0]).abs() + (a[1] - b[1]).abs();
    assert!(
        first > 1e-4,
        "the first token did not see the last: {first}"
    );
    // And the model is not constant: the changed token itself moved more.
    assert!((a[10] - b[10]).abs() > 0.0);
    Ok(())
}

#[test]
fn configs_that_cannot_work_are_refused() {
    let mut cfg = tiny_config(1);
    cfg.heads = 5;
    assert!(ScaleDp::count(&cfg)
        .unwrap_err()
        .to_string()
        .contains("heads"));
    let mut cfg = tiny_config(1);
    cfg.image_width = 6;
    assert!(ScaleDp::count(&cfg)
        .unwrap_err()
        .to_string()
        .contains("at least 8"));
    assert!("xl".parse::<ModelSize>().is_err());
    assert_eq!("S".parse::<ModelSize>().ok(), Some(ModelSize::S));
}
